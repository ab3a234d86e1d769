//! The first pass's `guide` on the device (docs/SEMANTICS.md, "The guide"):
//! the colour the form filters, blurred by one pass of
//! `pipeline::GUIDE_STENCIL`. It is the form's own kernel with the constant
//! weight 1, compiled like any candidate and cached with them; `cpu::guide`
//! is its reference.

use std::sync::OnceLock;

use super::buffers::SceneBuffers;
use super::filter::{rows_per_dispatch, uniform_bytes};
use super::{Gpu, GpuError};
use crate::jit::interface::Element;
use crate::jit::{self, Input, KernelKind, Params, Role, ValidatedKernel, WORKGROUP};
use crate::lang::Feature;
use crate::pipeline::GUIDE_STENCIL;

/// The guide's kernel: one à-trous pass of the constant weight, nothing multiplied back.
fn guide_kernel() -> Result<&'static ValidatedKernel, GpuError> {
    static KERNEL: OnceLock<Result<ValidatedKernel, String>> = OnceLock::new();
    KERNEL.get_or_init(|| jit::compile_guide(KernelKind::Filter).map_err(|e| e.to_string())).as_ref().map_err(
        |message| GpuError::Pipeline { expression: "<guide>".into(), message: message.clone(), wgsl: String::new() },
    )
}

impl Gpu {
    /// Make the guide's pipeline now if `kernel` reads the guide: callers
    /// do this before their GL turn, since creating a pipeline takes the
    /// turn itself and turns never nest (the guide is dispatched inside one).
    pub(super) fn prepare_guide_for(&self, kernel: &ValidatedKernel) -> Result<(), GpuError> {
        if kernel.source().layout.reads_guide() {
            self.pipeline(guide_kernel()?)?;
            self.blit_pipeline(Element::Vec4F32)?;
        }
        Ok(())
    }

    /// Record the guide of `color` into `encoder`; callers hold the GL turn
    /// and made its pipeline ([`Gpu::prepare_guide_for`]).
    pub(super) fn record_guide(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        color: &wgpu::TextureView,
        width: u32,
        height: u32,
    ) -> Result<wgpu::Buffer, GpuError> {
        let kernel = guide_kernel()?;
        // A cache hit: `prepare_guide_for` made it before the caller's GL turn.
        let (pipeline, _) = self.pipeline(kernel)?;
        let device = self.device();
        let make = |label, bytes: u64| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: (width * height) as u64 * bytes,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            })
        };
        let (guide, flags) = (make("guide", 16), make("guide flags", 4));
        let interface = &kernel.source().interface;
        // In bands of rows, as the form's passes are dispatched.
        let band = rows_per_dispatch(width, GUIDE_STENCIL.half_width() as u32);
        for row in (0..height).step_by(band as usize) {
            let params = uniform_bytes(true, Params { width, height, radius: 0, row_offset: row }, 0, 1, true);
            let params = self.params_buffer(interface.params(), "guide params", &params);
            let bind_group = self.bind_group(&pipeline, interface, |role| match role {
                Role::Params => params.as_entire_binding(),
                Role::Color => wgpu::BindingResource::TextureView(color),
                Role::Output => guide.as_entire_binding(),
                Role::Flags => flags.as_entire_binding(),
                other => unreachable!("the guide's kernel binds no {other:?}"),
            });
            let mut pass = self.compute_pass(encoder, "guide");
            pass.set_pipeline(&pipeline.pipeline);
            pass.set_bind_group(0, &bind_group, &[]);
            pass.dispatch_workgroups(width.div_ceil(WORKGROUP[0]), band.min(height - row).div_ceil(WORKGROUP[1]), 1);
        }
        Ok(guide)
    }
}

impl SceneBuffers {
    /// Record the guide of these buffers' colour into `encoder` and keep it
    /// as their `guide` input: its kernel samples the colour, as the form's
    /// first pass does, so both read one texture. Callers hold the GL turn.
    pub(super) fn record_guide(&mut self, gpu: &Gpu, encoder: &mut wgpu::CommandEncoder) -> Result<(), GpuError> {
        let views = self.sampled_views(gpu, encoder, &[Role::Color], 0, None)?;
        let guide = gpu.record_guide(encoder, &views[&Role::Color], self.width, self.height)?;
        self.inputs.insert(Input::Feature(Feature::Guide), guide);
        Ok(())
    }
}
