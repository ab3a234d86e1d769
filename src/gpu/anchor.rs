//! `anchor` on the device (`jit::anchor`): one pipeline per device, a
//! dispatch per blur level and one that scales the image, after the form
//! and `planefit`; `cpu::anchor_light` is its reference.

use super::{Gpu, GpuError};
use crate::jit::interface::Element;
use crate::jit::{AnchorParams, BindingInterface, BuiltIn, Role, WORKGROUP};
use crate::pipeline::Anchor;

impl Gpu {
    /// Make the kernel's pipeline and the blit it needs; callers do it
    /// before their GL turn, since creating a pipeline takes the turn itself.
    pub(super) fn prepare_anchor(&self) -> Result<(), GpuError> {
        self.built_in(BuiltIn::Anchor, 0)?;
        self.blit_pipeline(Element::Vec4F32)?;
        Ok(())
    }

    /// Record `anchor` of `image` (`size`) against the noisy `frame` into
    /// `encoder`, returning the buffer it writes. The image, and each blur
    /// level's sums, are copied into textures for the next dispatch to
    /// sample. Callers hold the GL turn and ran [`Gpu::prepare_anchor`].
    pub(super) fn anchor(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        anchor: Anchor,
        frame: &wgpu::Texture,
        image: &wgpu::Buffer,
        (width, height): (u32, u32),
    ) -> Result<wgpu::Buffer, GpuError> {
        let kernel = self.built_in(BuiltIn::Anchor, 0)?;
        let interface = BindingInterface::anchor(None);
        let buffer = |label| {
            self.device().create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: (width * height) as u64 * 16,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            })
        };
        let image = self.blitted(encoder, image, Element::Vec4F32, (width, height))?.create_view(&Default::default());
        let frame = frame.create_view(&Default::default());
        // The level before's sums; level 0 reads none, and binds the image in their place.
        let mut sums: Option<wgpu::TextureView> = None;
        let (summed, anchored) = (buffer("anchor sums"), buffer("anchored"));
        for params in AnchorParams::sequence(anchor, width, height) {
            let out = if params.scales() { &anchored } else { &summed };
            let uniform = self.params_buffer(interface.params(), "anchor params", bytemuck::bytes_of(&params));
            let bind_group = self.bind_group(&kernel, &interface, |role| match role {
                Role::Params => uniform.as_entire_binding(),
                Role::Color => wgpu::BindingResource::TextureView(&frame),
                Role::Image => wgpu::BindingResource::TextureView(&image),
                Role::Sums => wgpu::BindingResource::TextureView(sums.as_ref().unwrap_or(&image)),
                Role::Output => out.as_entire_binding(),
                other => unreachable!("anchor has no {other:?} binding"),
            });
            let mut pass = self.compute_pass(encoder, format_args!("anchor: level {}", params.level));
            pass.set_pipeline(&kernel.pipeline);
            pass.set_bind_group(0, &bind_group, &[]);
            pass.dispatch_workgroups(width.div_ceil(WORKGROUP[0]), height.div_ceil(WORKGROUP[1]), 1);
            drop(pass);
            if !params.scales() {
                let texture = self.blitted(encoder, &summed, Element::Vec4F32, (width, height))?;
                sums = Some(texture.create_view(&Default::default()));
            }
        }
        Ok(anchored)
    }
}
