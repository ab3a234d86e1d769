//! `pixelfilter` on the device (`jit::pixel_filter`): one pipeline per
//! device, one dispatch after the form (and `planefit`); `cpu::pixel_filter`
//! is its reference.

use super::{Gpu, GpuError};
use crate::jit::interface::Element;
use crate::jit::{BindingInterface, BuiltIn, PixelFilterParams, Role, WORKGROUP};
use crate::pipeline::PixelFilter;

impl Gpu {
    /// Make the kernel's pipeline and the blit it needs; callers do it
    /// before their GL turn, since creating a pipeline takes the turn itself.
    pub(super) fn prepare_pixel_filter(&self) -> Result<(), GpuError> {
        self.built_in(BuiltIn::PixelFilter, 0)?;
        self.blit_pipeline(Element::Vec4F32)?;
        Ok(())
    }

    /// Record `filter` of `image` (`size`) into `encoder`, returning the
    /// buffer it writes; the image is blitted into a texture first. Callers
    /// hold the GL turn and ran [`Gpu::prepare_pixel_filter`] before it.
    pub(super) fn pixel_filter(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        filter: PixelFilter,
        image: &wgpu::Buffer,
        (width, height): (u32, u32),
    ) -> Result<wgpu::Buffer, GpuError> {
        let kernel = self.built_in(BuiltIn::PixelFilter, 0)?;
        let interface = BindingInterface::pixel_filter(None);
        let filtered = self.device().create_buffer(&wgpu::BufferDescriptor {
            label: Some("pixelfilter"),
            size: (width * height) as u64 * 16,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let colour = self.blitted(encoder, image, Element::Vec4F32, (width, height))?.create_view(&Default::default());
        let params = PixelFilterParams::of(filter, width, height);
        let uniform = self.params_buffer(interface.params(), "pixelfilter params", bytemuck::bytes_of(&params));
        let bind_group = self.bind_group(&kernel, &interface, |role| match role {
            Role::Params => uniform.as_entire_binding(),
            Role::Color => wgpu::BindingResource::TextureView(&colour),
            Role::Output => filtered.as_entire_binding(),
            other => unreachable!("pixelfilter has no {other:?} binding"),
        });
        let mut pass = self.compute_pass(encoder, "pixelfilter");
        pass.set_pipeline(&kernel.pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.dispatch_workgroups(width.div_ceil(WORKGROUP[0]), height.div_ceil(WORKGROUP[1]), 1);
        drop(pass);
        Ok(filtered)
    }
}
