//! The pipeline's pre-pass on the device (`jit::prepass`, then with `keep`
//! `jit::spread`, with `keep=surface` its surface kernel): one pipeline each
//! per device, run once per scene when its buffers are prepared.

use std::sync::Arc;

use super::{Gpu, GpuError, Pipeline};
use crate::jit::interface::Element;
use crate::jit::{
    written_before, BindingInterface, BuiltIn, Input, PrepassParams, Role, SpreadParams, SpreadSource, SpreadTarget,
    WORKGROUP,
};
use crate::lang::ScalarVar;
use crate::pipeline::{FilterPipeline, Keep};

impl Gpu {
    /// Every pipeline `pipeline`'s pre-pass dispatches on a `width` ×
    /// `height` image, made now: before a GL turn, since creation takes it.
    pub(super) fn prepass_pipelines(
        &self,
        pipeline: &FilterPipeline,
        width: u32,
        height: u32,
    ) -> Result<PrepassPipelines, GpuError> {
        let kernel = self.built_in(BuiltIn::Prepass, 0)?;
        self.blit_pipeline(Element::Vec4F32)?;
        let spread = match pipeline.keep() {
            Some(keep) => {
                let sequence = SpreadParams::sequence(keep, width, height);
                let pipelines = sequence
                    .iter()
                    .map(|d| self.built_in(BuiltIn::Spread(keep), d.params.stage))
                    .collect::<Result<Vec<_>, _>>()?;
                Some((keep, sequence, pipelines))
            }
            None => None,
        };
        Ok(PrepassPipelines { kernel, spread })
    }

    /// Record `pipeline`'s pre-pass on `inputs` into `encoder`: the colour the
    /// form filters, the modulation (1 without demodulation), and what the
    /// outlier rule measured (`ScalarVar::FROM_PREPASS`, in that order; 0
    /// without it). All stay on the device. `pipelines`: this pipeline's,
    /// from [`Gpu::prepass_pipelines`]; callers hold the GL turn.
    pub(super) fn record_prepass(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        pipelines: PrepassPipelines,
        pipeline: &FilterPipeline,
        inputs: &PrepassInputs,
    ) -> Result<Prepared, GpuError> {
        let PrepassPipelines { kernel, spread } = pipelines;
        let PrepassInputs { color, albedo, normals, width, height } = inputs;
        let (width, height) = (*width, *height);
        let device = self.device();
        let params = PrepassParams::of(pipeline, width, height);
        let uniform = self.params_buffer(
            BindingInterface::prepass(None).params(),
            "pre-pass params",
            bytemuck::bytes_of(&params),
        );
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
        // The kernel samples the colour and the albedo.
        let size = (width, height);
        let sampled = |encoder: &mut wgpu::CommandEncoder, buffer: &wgpu::Buffer| {
            Ok::<_, GpuError>(self.blitted(encoder, buffer, Element::Vec4F32, size)?.create_view(&Default::default()))
        };
        let noisy = sampled(encoder, color)?;
        // Without demodulation the albedo is never read: the colour stands in for it.
        let albedo = match albedo {
            Some(albedo) => sampled(encoder, albedo)?,
            None => noisy.clone(),
        };
        let interface = BindingInterface::prepass(None);
        let bind_group = self.bind_in_slot_order(
            &kernel,
            interface
                .bindings
                .iter()
                .map(|b| match b.role {
                    Role::Params => uniform.as_entire_binding(),
                    Role::Color => wgpu::BindingResource::TextureView(&noisy),
                    Role::Albedo => wgpu::BindingResource::TextureView(&albedo),
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
        {
            let mut pass = self.compute_pass(encoder, "pre-pass");
            pass.set_pipeline(&kernel.pipeline);
            pass.set_bind_group(0, &bind_group, &[]);
            pass.dispatch_workgroups(width.div_ceil(WORKGROUP[0]), height.div_ceil(WORKGROUP[1]), 1);
        }
        if let Some((keep, sequence, pipelines)) = spread {
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
            // The kernel samples its images: each is copied (or blitted) into a texture
            // once it is written (the scratch images after every dispatch
            // that writes them), and read from there.
            let image = sampled(encoder, &prepared)?;
            let modulation_view = sampled(encoder, &modulation)?;
            let normal_view = match &normals {
                Some(normals) => Some(sampled(encoder, normals)?),
                None => None,
            };
            let mut scratch_views: [Option<wgpu::TextureView>; 2] = [None, None];
            let mut surface_view = None;
            for (n, (dispatch, spread)) in sequence.iter().zip(&pipelines).enumerate() {
                let uniform =
                    self.params_buffer(interface.params(), "spread params", bytemuck::bytes_of(&dispatch.params));
                // An image not yet written is not read: any other texture stands in.
                let source = match dispatch.source {
                    SpreadSource::Noisy => &noisy,
                    SpreadSource::Scratch(k) => scratch_views[k].as_ref().unwrap_or(&modulation_view),
                };
                let target = match dispatch.target {
                    SpreadTarget::Scratch(k) => &buffers[k],
                    SpreadTarget::Total => &total,
                    SpreadTarget::Surface => surface.as_ref().expect("keep=surface has a surface image"),
                };
                let bind_group = self.bind_in_slot_order(
                    spread,
                    interface
                        .bindings
                        .iter()
                        .map(|b| match b.role {
                            Role::Params => uniform.as_entire_binding(),
                            Role::Color => wgpu::BindingResource::TextureView(source),
                            Role::Image => wgpu::BindingResource::TextureView(&image),
                            Role::Modulation => wgpu::BindingResource::TextureView(&modulation_view),
                            Role::Output => target.as_entire_binding(),
                            Role::Total => {
                                if written_before(&sequence, n, SpreadTarget::Total) { &total } else { &modulation }
                                    .as_entire_binding()
                            }
                            Role::Surface => {
                                wgpu::BindingResource::TextureView(surface_view.as_ref().unwrap_or(&modulation_view))
                            }
                            Role::Input(_) => wgpu::BindingResource::TextureView(
                                normal_view.as_ref().expect("keep=surface is given the normals"),
                            ),
                            other => unreachable!("the spread has no {other:?} binding"),
                        })
                        .collect(),
                );
                {
                    let mut pass =
                        self.compute_pass(encoder, format_args!("pre-pass: {} spread, {dispatch}", keep.text()));
                    pass.set_pipeline(&spread.pipeline);
                    pass.set_bind_group(0, &bind_group, &[]);
                    // The total is one workgroup's work: the others would do nothing.
                    if dispatch.target == SpreadTarget::Total {
                        pass.dispatch_workgroups(1, 1, 1);
                    } else {
                        pass.dispatch_workgroups(width.div_ceil(WORKGROUP[0]), height.div_ceil(WORKGROUP[1]), 1);
                    }
                }
                // What a later dispatch reads, onto its texture.
                if n + 1 < sequence.len() {
                    match dispatch.target {
                        SpreadTarget::Scratch(k) => scratch_views[k] = Some(sampled(encoder, &buffers[k])?),
                        SpreadTarget::Surface => surface_view = Some(sampled(encoder, target)?),
                        SpreadTarget::Total => {}
                    }
                }
            }
            // The finishing dispatch wrote the colour the form filters.
            let SpreadTarget::Scratch(last) = sequence.last().expect("a spread has dispatches").target else {
                unreachable!("a spread ends in a scratch image")
            };
            std::mem::swap(&mut prepared, &mut buffers[last]);
        }
        Ok(Prepared { color: prepared, modulation, local })
    }
}

/// What the pre-pass leaves on the device.
pub(super) struct Prepared {
    pub color: wgpu::Buffer,
    pub modulation: wgpu::Buffer,
    /// `ScalarVar::FROM_PREPASS`, in that order.
    pub local: [wgpu::Buffer; 3],
}

/// The pipelines a pre-pass dispatches ([`Gpu::prepass_pipelines`]).
pub(super) struct PrepassPipelines {
    kernel: Arc<Pipeline>,
    /// `keep`'s spread: its dispatches and a pipeline for each.
    spread: Option<(Keep, Vec<crate::jit::SpreadDispatch>, Vec<Arc<Pipeline>>)>,
}

/// What a pre-pass reads, uploaded: the noisy colour, the raw albedo where
/// the pipeline demodulates, the normals where `keep=surface` spreads.
pub(super) struct PrepassInputs {
    pub color: wgpu::Buffer,
    pub albedo: Option<wgpu::Buffer>,
    pub normals: Option<wgpu::Buffer>,
    pub width: u32,
    pub height: u32,
}
