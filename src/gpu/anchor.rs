//! `anchor` on the device (`jit::anchor`): one pipeline per device; after
//! the form and `planefit`, the sums averaged into a half-resolution grid,
//! blurred there level by level, and the image scaled; `cpu::anchor_light` is its reference.

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
    /// `encoder`, returning the buffer it writes. The image, and the sums
    /// after each dispatch on the grid, are copied into textures for the
    /// next dispatch to sample. Callers hold the GL turn and ran [`Gpu::prepare_anchor`].
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
        let buffer = |label, (width, height): (u32, u32)| {
            self.device().create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: (width * height) as u64 * 16,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            })
        };
        let image = self.blitted(encoder, image, Element::Vec4F32, (width, height))?.create_view(&Default::default());
        let frame = frame.create_view(&Default::default());
        // The sums so far; the first dispatch reads none, and binds the image in their place.
        let mut sums: Option<wgpu::TextureView> = None;
        let grid = Anchor::grid(width, height);
        let (summed, anchored) = (buffer("anchor sums", grid), buffer("anchored", (width, height)));
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
            let (columns, rows) = params.writes();
            pass.dispatch_workgroups(columns.div_ceil(WORKGROUP[0]), rows.div_ceil(WORKGROUP[1]), 1);
            drop(pass);
            if !params.scales() {
                let texture = self.blitted(encoder, &summed, Element::Vec4F32, grid)?;
                sums = Some(texture.create_view(&Default::default()));
            }
        }
        Ok(anchored)
    }
}
