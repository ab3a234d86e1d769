//! The pipeline's pre-pass on the device (`jit::prepass`, then with `keep`
//! `jit::spread`, with `keep=surface` its surface kernel): one pipeline each
//! per device, run once per scene when its buffers are prepared.

use std::sync::OnceLock;

use wgpu::util::DeviceExt;

use super::{Gpu, GpuError, Pipeline};
use crate::jit::{
    written_before, BindingInterface, Input, PrepassParams, Role, SpreadParams, SpreadSource, SpreadTarget,
    ValidatedModule, WORKGROUP,
};
use crate::lang::ScalarVar;
use crate::pipeline::{FilterPipeline, Keep};

impl Gpu {
    fn prepass_pipeline(&self) -> Result<&Pipeline, GpuError> {
        static MODULE: OnceLock<Result<ValidatedModule, String>> = OnceLock::new();
        let validate = || crate::jit::prepass_module(None).map_err(|e| e.to_string());
        self.built_in(&self.prepass, &MODULE, "<pre-pass>", validate, || crate::jit::prepass_wgsl(None))
    }

    fn spread_pipeline(&self, keep: Keep) -> Result<&Pipeline, GpuError> {
        static EVEN: OnceLock<Result<ValidatedModule, String>> = OnceLock::new();
        static SURFACE: OnceLock<Result<ValidatedModule, String>> = OnceLock::new();
        match keep {
            Keep::Even => {
                let validate = || crate::jit::spread_module(None).map_err(|e| e.to_string());
                self.built_in(&self.spread, &EVEN, "<spread>", validate, || crate::jit::spread_wgsl(None))
            }
            Keep::Surface => {
                let validate = || crate::jit::spread_surface_module(None).map_err(|e| e.to_string());
                let wgsl = || crate::jit::spread_surface_wgsl(None);
                self.built_in(&self.spread_surface, &SURFACE, "<surface spread>", validate, wgsl)
            }
        }
    }

    /// Run `pipeline`'s pre-pass on `color` (RGBA per pixel; `albedo` the raw
    /// albedo when demodulating): the colour the form filters, the
    /// modulation (1 without demodulation), and what the outlier rule
    /// measured (`ScalarVar::FROM_PREPASS`, in that order; 0 without it). All
    /// stay on the device. `normals`: the scene's, which `keep=surface` reads.
    pub(super) fn prepass(
        &self,
        pipeline: &FilterPipeline,
        color: &wgpu::Buffer,
        albedo: Option<&[[f32; 4]]>,
        normals: Option<&[[f32; 4]]>,
        width: u32,
        height: u32,
    ) -> Result<Prepared, GpuError> {
        let kernel = self.prepass_pipeline()?;
        let spread = match pipeline.keep() {
            Some(keep) => Some((keep, self.spread_pipeline(keep)?)),
            None => None,
        };
        let _turn = self.gl_turn();
        let device = self.device();
        let params = PrepassParams::of(pipeline, width, height);
        let uniform = self.params_buffer(
            BindingInterface::prepass(None).params(),
            "pre-pass params",
            bytemuck::bytes_of(&params),
        );
        let albedo = albedo.map(|a| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("albedo"),
                contents: bytemuck::cast_slice(a),
                usage: wgpu::BufferUsages::STORAGE,
            })
        });
        let make = |label| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: (width * height) as u64 * 16,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            })
        };
        let (mut prepared, modulation) = (make("prepared colour"), make("modulation"));
        let local = ScalarVar::FROM_PREPASS.map(|_| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("pre-pass measure"),
                size: (width * height) as u64 * 4,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            })
        });
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        // Without demodulation the albedo is never read: the colour stands in for it.
        let interface = BindingInterface::prepass(None);
        let bind_group = self.bind_in_slot_order(
            kernel,
            interface
                .bindings
                .iter()
                .map(|b| match b.role {
                    Role::Params => uniform.as_entire_binding(),
                    Role::Color => color.as_entire_binding(),
                    Role::Albedo => albedo.as_ref().unwrap_or(color).as_entire_binding(),
                    Role::Output => prepared.as_entire_binding(),
                    Role::Modulation => modulation.as_entire_binding(),
                    Role::Input(Input::Variance(v)) if v.from_prepass() => {
                        let k = ScalarVar::FROM_PREPASS.iter().position(|w| *w == v).expect("a pre-pass measure");
                        local[k].as_entire_binding()
                    }
                    other => unreachable!("the pre-pass has no {other:?} binding"),
                })
                .collect(),
        );
        let start = std::time::Instant::now();
        let mut encoder = device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_compute_pass(&Default::default());
            pass.set_pipeline(&kernel.pipeline);
            pass.set_bind_group(0, &bind_group, &[]);
            pass.dispatch_workgroups(width.div_ceil(WORKGROUP[0]), height.div_ceil(WORKGROUP[1]), 1);
        }
        if let Some((keep, spread)) = spread {
            // `keep`: the pre-pass wrote the clamped colour undivided; spread
            // raw − clamped, then (spread + clamped) / modulation is the colour.
            let interface = crate::jit::spread_interface(keep, None);
            let mut buffers = [make("spread"), make("spread")];
            // One texel: the sum of the clamped luminance (`keep=surface`).
            let total = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("spread total"),
                size: 16,
                usage: wgpu::BufferUsages::STORAGE,
                mapped_at_creation: false,
            });
            // Each pixel's direction and clamped luminance (`keep=surface`).
            let surface = (keep == Keep::Surface).then(|| make("spread surface"));
            let normals = normals.map(|n| {
                device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("normals"),
                    contents: bytemuck::cast_slice(n),
                    usage: wgpu::BufferUsages::STORAGE,
                })
            });
            let sequence = SpreadParams::sequence(keep, width, height);
            for (n, dispatch) in sequence.iter().enumerate() {
                let uniform =
                    self.params_buffer(interface.params(), "spread params", bytemuck::bytes_of(&dispatch.params));
                let source = match dispatch.source {
                    SpreadSource::Noisy => color,
                    SpreadSource::Scratch(k) => &buffers[k],
                };
                let target = match dispatch.target {
                    SpreadTarget::Scratch(k) => &buffers[k],
                    SpreadTarget::Total => &total,
                    SpreadTarget::Surface => surface.as_ref().expect("keep=surface has a surface image"),
                };
                // An image not yet written is not read: any other buffer stands in.
                let read = |image, buffer| if written_before(&sequence, n, image) { buffer } else { &modulation };
                let bind_group = self.bind_in_slot_order(
                    spread,
                    interface
                        .bindings
                        .iter()
                        .map(|b| match b.role {
                            Role::Params => uniform.as_entire_binding(),
                            Role::Color => source.as_entire_binding(),
                            Role::Image => prepared.as_entire_binding(),
                            Role::Modulation => modulation.as_entire_binding(),
                            Role::Output => target.as_entire_binding(),
                            Role::Total => read(SpreadTarget::Total, &total).as_entire_binding(),
                            Role::Surface => {
                                read(SpreadTarget::Surface, surface.as_ref().expect("keep=surface has a surface image"))
                                    .as_entire_binding()
                            }
                            Role::Input(_) => {
                                normals.as_ref().expect("keep=surface is given the normals").as_entire_binding()
                            }
                            other => unreachable!("the spread has no {other:?} binding"),
                        })
                        .collect(),
                );
                let mut pass = encoder.begin_compute_pass(&Default::default());
                pass.set_pipeline(&spread.pipeline);
                pass.set_bind_group(0, &bind_group, &[]);
                pass.dispatch_workgroups(width.div_ceil(WORKGROUP[0]), height.div_ceil(WORKGROUP[1]), 1);
            }
            // The finishing dispatch wrote the colour the form filters.
            let SpreadTarget::Scratch(last) = sequence.last().expect("a spread has dispatches").target else {
                unreachable!("a spread ends in a scratch image")
            };
            std::mem::swap(&mut prepared, &mut buffers[last]);
        }
        self.queue().submit([encoder.finish()]);
        self.wait("running the pre-pass")?;
        let dispatch = start.elapsed();
        if let Some(error) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Runtime { during: "running the pre-pass", message: error.to_string() });
        }
        Ok(Prepared { color: prepared, modulation, local, dispatch })
    }
}

/// What the pre-pass leaves on the device.
pub(super) struct Prepared {
    pub color: wgpu::Buffer,
    pub modulation: wgpu::Buffer,
    /// `ScalarVar::FROM_PREPASS`, in that order.
    pub local: [wgpu::Buffer; 3],
    /// Wall time from submission until the pre-pass was done.
    pub dispatch: std::time::Duration,
}
