//! The textures of the images a kernel samples
//! ([`crate::jit::BindingInterface::samples_images`]: filterjit's à-trous
//! form). [`SceneBuffers`] keeps every image in a storage buffer, which the
//! other kernels read; a kernel that samples gets textures of the same
//! values, blitted on the device (`jit::blit`): the scene's once, the pass
//! images before each pass that reads them.

use std::collections::HashMap;
use std::sync::OnceLock;

use super::filter::SceneBuffers;
use super::{Gpu, GpuError, Pipeline};
use crate::jit::interface::{Element, Resource};
use crate::jit::{BindingInterface, BlitParams, Input, Role, ValidatedKernel, ValidatedModule, WORKGROUP};
use crate::lang::ScalarVar;

/// Textures of a scene's images for the kernels that sample them.
#[derive(Default)]
pub(super) struct Sampled {
    /// The colour the form filters, the modulation and the inputs, blitted once.
    scene: HashMap<Role, wgpu::Texture>,
    /// The à-trous passes' images and carried variances, by scratch index.
    images: [Option<wgpu::Texture>; 2],
    variances: [Option<wgpu::Texture>; 2],
}

impl Gpu {
    /// The blit's pipeline for images of `element`s. Callers make both before
    /// their GL turn, since creating a pipeline takes the turn itself.
    pub(super) fn blit_pipeline(&self, element: Element) -> Result<&Pipeline, GpuError> {
        static VEC4: OnceLock<Result<ValidatedModule, String>> = OnceLock::new();
        static SCALAR: OnceLock<Result<ValidatedModule, String>> = OnceLock::new();
        let (cell, module) = match element {
            Element::F32 => (&self.blit_scalar, &SCALAR),
            _ => (&self.blit_vec4, &VEC4),
        };
        let validate = || crate::jit::blit_module(element).map_err(|e| e.to_string());
        self.built_in(cell, module, "<blit>", validate, || crate::jit::blit_wgsl(element))
    }

    /// Record into `encoder` the blit of `source` (`element`s) into `target`.
    fn record_blit(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        source: &wgpu::Buffer,
        target: &wgpu::Texture,
        element: Element,
        (width, height): (u32, u32),
    ) -> Result<(), GpuError> {
        let pipeline = self.blit_pipeline(element)?;
        let interface = BindingInterface::blit(element);
        let params = BlitParams { width, height, _pad: [0; 2] };
        let uniform = self.params_buffer(interface.params(), "blit params", bytemuck::bytes_of(&params));
        let view = target.create_view(&Default::default());
        let bind_group = self.bind_group(pipeline, &interface, |role| match role {
            Role::Params => uniform.as_entire_binding(),
            Role::Color => source.as_entire_binding(),
            Role::Output => wgpu::BindingResource::TextureView(&view),
            other => unreachable!("the blit has no {other:?} binding"),
        });
        let mut pass = encoder.begin_compute_pass(&Default::default());
        pass.set_pipeline(&pipeline.pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.dispatch_workgroups(width.div_ceil(WORKGROUP[0]), height.div_ceil(WORKGROUP[1]), 1);
        Ok(())
    }

    /// A new texture of `source`'s values (`element`s, a frame of `size`),
    /// its blit recorded into `encoder`.
    pub(super) fn blitted(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        source: &wgpu::Buffer,
        element: Element,
        size: (u32, u32),
    ) -> Result<wgpu::Texture, GpuError> {
        let texture = self.sampled_texture(element, size);
        self.record_blit(encoder, source, &texture, element, size)?;
        Ok(texture)
    }

    /// A texture of the frame's size for an image of `element`s.
    fn sampled_texture(&self, element: Element, (width, height): (u32, u32)) -> wgpu::Texture {
        self.device().create_texture(&wgpu::TextureDescriptor {
            label: Some("sampled image"),
            size: wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: match element {
                Element::F32 => wgpu::TextureFormat::R32Float,
                _ => wgpu::TextureFormat::Rgba32Float,
            },
            usage: wgpu::TextureUsages::STORAGE_BINDING | wgpu::TextureUsages::TEXTURE_BINDING,
            view_formats: &[],
        })
    }
}

/// The roles `kernel` binds as sampled textures.
pub(super) fn sampled_roles(kernel: &ValidatedKernel) -> Vec<Role> {
    let interface = &kernel.source().interface;
    interface.bindings.iter().filter(|b| b.resource == Resource::SampledTexture).map(|b| b.role).collect()
}

/// What an image bound to `role` holds per pixel.
fn element_of(role: Role) -> Element {
    match role {
        Role::Input(input) => Element::of_input(input),
        _ => Element::Vec4F32,
    }
}

impl SceneBuffers {
    /// Views of the textures pass `level` samples for `roles`, blitting into
    /// `encoder` what is not on a texture yet: the scene's images the first
    /// time, the previous pass's image and carried variance every pass.
    pub(super) fn sampled_views(
        &mut self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        roles: &[Role],
        level: u32,
    ) -> Result<HashMap<Role, wgpu::TextureView>, GpuError> {
        let size = (self.width, self.height);
        let read = (level as usize + 1) % 2;
        let mut views = HashMap::new();
        for &role in roles {
            let carried = Role::Input(Input::Variance(ScalarVar::ColorVariance));
            let pass_image = level > 0 && (role == Role::Color || role == carried);
            let texture = if pass_image {
                let scratch = self.scratch.as_ref().expect("an à-trous form has pass images");
                let (source, slot, element) = if role == Role::Color {
                    (&scratch.images[read], &mut self.sampled.images[read], Element::Vec4F32)
                } else {
                    (&scratch.variances[read], &mut self.sampled.variances[read], Element::F32)
                };
                let texture = slot.get_or_insert_with(|| gpu.sampled_texture(element, size)).clone();
                gpu.record_blit(encoder, source, &texture, element, size)?;
                texture
            } else if let Some(texture) = self.sampled.scene.get(&role) {
                texture.clone()
            } else {
                let source = match role {
                    Role::Color => &self.color,
                    Role::Modulation => self.modulation.as_ref().expect("a remodulating form's buffers hold it"),
                    Role::Input(input) => self.inputs.get(&input).expect("inputs are uploaded before binding"),
                    other => unreachable!("a form samples no {other:?}"),
                };
                let texture = gpu.blitted(encoder, source, element_of(role), size)?;
                self.sampled.scene.insert(role, texture.clone());
                texture
            };
            views.insert(role, texture.create_view(&Default::default()));
        }
        Ok(views)
    }
}
