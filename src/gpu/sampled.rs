//! The textures of the images a kernel samples
//! ([`crate::jit::BindingInterface::samples_images`]: filterjit's à-trous
//! form). [`super::buffers::SceneBuffers`] keeps every image in a storage buffer, which the
//! other kernels read; a kernel that samples gets textures of the same
//! values, copied or blitted on the device (`jit::blit`): the scene's once,
//! the pass images before each pass that reads them.

use std::collections::HashMap;
use std::sync::Arc;

use super::{Gpu, GpuError, Pipeline};
use crate::jit::interface::{Element, Resource};
use crate::jit::{BindingInterface, BlitParams, BuiltIn, Input, Role, ValidatedKernel, WORKGROUP};
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

impl Sampled {
    /// Drop the texture of the scene's image bound to `role` (replaced on the device).
    pub(super) fn forget(&mut self, role: Role) {
        self.scene.remove(&role);
    }

    /// Take `texture`, which holds the values of the scene's image bound to
    /// `role`, as that image's texture (a stage that made one already).
    pub(super) fn provide(&mut self, role: Role, texture: wgpu::Texture) {
        self.scene.insert(role, texture);
    }
}

impl Gpu {
    /// The blit's pipeline for images of `element`s. Callers make both before
    /// their GL turn, since creating a pipeline takes the turn itself.
    pub(super) fn blit_pipeline(&self, element: Element) -> Result<Arc<Pipeline>, GpuError> {
        let element = if element == Element::F32 { Element::F32 } else { Element::Vec4F32 };
        self.built_in(BuiltIn::Blit(element), 0)
    }

    /// Record into `encoder` the blit of `source` (`element`s) into `target`:
    /// a buffer-to-texture copy where the rows' bytes meet the copy's
    /// alignment (and `source` may be copied from), else the blit kernel. The
    /// texel values are the same either way; the copy skips a dispatch and
    /// the clear wgpu gives a texture a kernel writes first (about 0.8 ms a
    /// 256² image on lavapipe; docs/JOURNAL.md, "Where the default's frame goes").
    fn record_blit(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        source: &wgpu::Buffer,
        target: &wgpu::Texture,
        element: Element,
        (width, height): (u32, u32),
    ) -> Result<(), GpuError> {
        // The texture's texel is the element's bytes for these two (the formats of `sampled_texture`).
        let same_layout = matches!(element, Element::F32 | Element::Vec4F32);
        let row_bytes = width * element.bytes();
        if same_layout
            && source.usage().contains(wgpu::BufferUsages::COPY_SRC)
            && row_bytes.is_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT)
        {
            self.profiled(encoder, "copy into a texture", |encoder| {
                encoder.copy_buffer_to_texture(
                    wgpu::TexelCopyBufferInfo {
                        buffer: source,
                        layout: wgpu::TexelCopyBufferLayout {
                            offset: 0,
                            bytes_per_row: Some(row_bytes),
                            rows_per_image: Some(height),
                        },
                    },
                    target.as_image_copy(),
                    wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
                )
            });
            return Ok(());
        }
        let pipeline = self.blit_pipeline(element)?;
        let interface = BindingInterface::blit(element);
        let params = BlitParams { width, height, _pad: [0; 2] };
        let uniform = self.params_buffer(interface.params(), "blit params", bytemuck::bytes_of(&params));
        let view = target.create_view(&Default::default());
        let bind_group = self.bind_group(&pipeline, &interface, |role| match role {
            Role::Params => uniform.as_entire_binding(),
            Role::Color => source.as_entire_binding(),
            Role::Output => wgpu::BindingResource::TextureView(&view),
            other => unreachable!("the blit has no {other:?} binding"),
        });
        let mut pass = self.compute_pass(encoder, "blit to a texture");
        pass.set_pipeline(&pipeline.pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.dispatch_workgroups(width.div_ceil(WORKGROUP[0]), height.div_ceil(WORKGROUP[1]), 1);
        Ok(())
    }

    /// A new texture of `source`'s values (`element`s, a frame of `size`),
    /// its copy or blit recorded into `encoder` (`record_blit`).
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

    /// A texture of `texels` (a frame of `size`), written from the host: an
    /// image only the kernels that sample read is uploaded as one, not as a
    /// buffer copied into one on the device.
    pub(super) fn uploaded_texture(&self, texels: &[[f32; 4]], (width, height): (u32, u32)) -> wgpu::Texture {
        let texture = self.sampled_texture(Element::Vec4F32, (width, height));
        self.queue().write_texture(
            texture.as_image_copy(),
            bytemuck::cast_slice(texels),
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(width * Element::Vec4F32.bytes()),
                rows_per_image: Some(height),
            },
            wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
        );
        texture
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
            // Written by the blit (storage) or a copy (COPY_DST), sampled by
            // the kernels, read back by the tests (COPY_SRC).
            usage: wgpu::TextureUsages::STORAGE_BINDING
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_DST
                | wgpu::TextureUsages::COPY_SRC,
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

/// The storage buffers a kernel's sampled images are made from: a scene's
/// ([`super::buffers::SceneBuffers`] lends its own).
pub(super) struct Sources<'a> {
    pub(super) size: (u32, u32),
    pub(super) color: &'a wgpu::Buffer,
    pub(super) modulation: Option<&'a wgpu::Buffer>,
    pub(super) inputs: &'a HashMap<Input, wgpu::Buffer>,
    /// The à-trous passes' images and carried variances (ping-ponged), where the form has passes.
    pub(super) passes: Option<(&'a [wgpu::Buffer; 2], &'a [wgpu::Buffer; 2])>,
}

impl Sampled {
    /// Views of the textures pass `level` samples for `roles`, blitting into
    /// `encoder` what is not on a texture yet: the scene's images the first
    /// time, the previous pass's image and carried variance every pass.
    pub(super) fn views(
        &mut self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        sources: Sources<'_>,
        roles: &[Role],
        level: u32,
        carried: Option<ScalarVar>,
    ) -> Result<HashMap<Role, wgpu::TextureView>, GpuError> {
        let size = sources.size;
        let read = (level as usize + 1) % 2;
        let mut views = HashMap::new();
        for &role in roles {
            let carried = carried.map(|v| Role::Input(Input::Variance(v)));
            let pass_image = level > 0 && (role == Role::Color || Some(role) == carried);
            let texture = if pass_image {
                let (images, variances) = sources.passes.expect("an à-trous form has pass images");
                let (source, slot, element) = if role == Role::Color {
                    (&images[read], &mut self.images[read], Element::Vec4F32)
                } else {
                    (&variances[read], &mut self.variances[read], Element::F32)
                };
                let texture = slot.get_or_insert_with(|| gpu.sampled_texture(element, size)).clone();
                gpu.record_blit(encoder, source, &texture, element, size)?;
                texture
            } else if let Some(texture) = self.scene.get(&role) {
                texture.clone()
            } else {
                let source = match role {
                    Role::Color => sources.color,
                    Role::Modulation => sources.modulation.expect("a remodulating form's buffers hold it"),
                    Role::Input(input) => sources.inputs.get(&input).expect("inputs are uploaded before binding"),
                    other => unreachable!("a form samples no {other:?}"),
                };
                let texture = gpu.blitted(encoder, source, element_of(role), size)?;
                self.scene.insert(role, texture.clone());
                texture
            };
            views.insert(role, texture.create_view(&Default::default()));
        }
        Ok(views)
    }
}

#[cfg(test)]
mod tests {
    use wgpu::util::DeviceExt;

    use super::*;

    /// The texture `blitted` makes of `values` (`element`s, `width` wide),
    /// read back; `copyable`: whether the buffer allows the copy path.
    fn texels(gpu: &Gpu, values: &[f32], element: Element, width: u32, copyable: bool) -> Vec<f32> {
        let floats = element.bytes() / 4;
        let height = values.len() as u32 / floats / width;
        let extra = if copyable { wgpu::BufferUsages::COPY_SRC } else { wgpu::BufferUsages::empty() };
        let source = gpu.device().create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: None,
            contents: bytemuck::cast_slice(values),
            usage: wgpu::BufferUsages::STORAGE | extra,
        });
        let row = (width * element.bytes()).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        let staging = gpu.device().create_buffer(&wgpu::BufferDescriptor {
            label: None,
            size: (row * height) as u64,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let scope = gpu.device().push_error_scope(wgpu::ErrorFilter::Validation);
        let mut encoder = gpu.device().create_command_encoder(&Default::default());
        let texture = gpu.blitted(&mut encoder, &source, element, (width, height)).unwrap();
        encoder.copy_texture_to_buffer(
            texture.as_image_copy(),
            wgpu::TexelCopyBufferInfo {
                buffer: &staging,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(row),
                    rows_per_image: Some(height),
                },
            },
            wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
        );
        let bytes = gpu.finish_and_read(encoder, scope, "reading a texture back", &staging).unwrap();
        let read: Vec<f32> = bytemuck::pod_collect_to_vec(&bytes);
        let (row, line) = ((row / 4) as usize, (width * floats) as usize);
        (0..height as usize).flat_map(|y| read[y * row..][..line].to_vec()).collect()
    }

    /// A buffer reaches its texture by a copy where its rows allow one and
    /// by the blit kernel elsewhere, with the same texel values either way.
    #[test]
    fn copied_and_blitted_textures_hold_the_buffers_values() {
        // On the adapter the tests run on, read at the edge as `tests/common` reads it.
        let environment = crate::environment::Environment::read().expect("FILTERJIT_BACKEND names a backend");
        let gpu = Gpu::open(&environment.adapter).expect("an adapter");
        eprintln!("on {}", gpu.describe());
        // 16 RGBA texels and 64 scalars a row meet the copy's 256-byte alignment; 17 and 65 do not.
        for (element, widths) in [(Element::Vec4F32, [16, 17]), (Element::F32, [64, 65])] {
            for width in widths {
                let count = (width * 3 * element.bytes() / 4) as usize;
                let values: Vec<f32> = (0..count).map(|i| (i as f32 * 0.37).sin() * 1e3 + i as f32).collect();
                for copyable in [true, false] {
                    let got = texels(&gpu, &values, element, width, copyable);
                    assert_eq!(got, values, "{element:?}, {width} wide, copyable {copyable}");
                }
            }
        }
    }
}
