//! Runs a filter from `filterjit export --target wgsl` with plain wgpu,
//! knowing only the documented interface: the manifest beside the shader.
//! Nothing here uses filterjit; this is what an engine's integration does.
//! (`tests/export.rs` runs this same file against `filterjit filter`.)
//!
//! Per frame it runs the manifest's `frame`, step by step: each dispatch
//! of a shader with the image each binding binds, each copy a sequence keeps
//! for the next frame ([`Sequence`]). Which stage runs when is the
//! manifest's to say, not this host's.

use std::collections::HashMap;

use serde_json::Value;

/// The layout of the manifest this host reads (filterjit's `export::MANIFEST_VERSION`).
const MANIFEST_VERSION: u64 = 8;

/// One frame of an engine's G-buffer, as plain arrays (row-major, top row first).
pub struct Frame {
    pub width: u32,
    pub height: u32,
    /// Noisy linear RGB colour; alpha is passed through.
    pub color: Vec<[f32; 4]>,
    /// The inputs by the manifest's `role` (`normal`, `wpVariance`, …;
    /// `albedo` for a pre-pass that demodulates; `geometry`, `motion` and
    /// `albedo` for the temporal stage), as the engine has them.
    pub inputs: HashMap<String, Vec<[f32; 4]>>,
    /// Normalisation scale per role; 1 when absent (textures already normalised).
    pub scales: HashMap<String, f32>,
}

/// The exported shaders: the form's, and the other stages' by their key in
/// the manifest (`prepass`, `spread`, `temporal`, …) where it has them.
pub struct Shaders {
    pub form: String,
    pub stages: HashMap<String, String>,
}

/// What a sequence keeps on the device from one frame for the next: the
/// images the manifest's `keep` steps copy. A new one (or [`Sequence::reset`])
/// starts a sequence; a frame of another size starts one too.
#[derive(Default)]
pub struct Sequence {
    kept: HashMap<String, wgpu::Texture>,
    size: (u32, u32),
    /// Frames filtered since the sequence started.
    pub frames: u32,
    /// The last frame's GPU work: from its submission to its end, the
    /// uploads done before and the readback's mapping after left out.
    pub gpu_time: Option<std::time::Duration>,
}

impl Sequence {
    pub fn new() -> Self {
        Self::default()
    }

    /// Forget the history: the next frame is a sequence's first (a cut).
    #[allow(dead_code)] // the example filters one sequence; tests/export.rs and engines cut
    pub fn reset(&mut self) {
        *self = Self::default();
    }
}

/// A device on the adapter wgpu prefers (`WGPU_BACKEND` narrows the choice).
pub fn open_device() -> Result<(wgpu::Device, wgpu::Queue), String> {
    let mut descriptor = wgpu::InstanceDescriptor::new_without_display_handle();
    descriptor.backends = wgpu::Backends::from_env().unwrap_or(wgpu::Backends::all());
    let instance = wgpu::Instance::new(descriptor);
    let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions::default()))
        .map_err(|e| format!("no GPU adapter: {e}"))?;
    pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor::default())).map_err(|e| e.to_string())
}

fn field<'a>(v: &'a Value, key: &str) -> Result<&'a Value, String> {
    v.get(key).ok_or_else(|| format!("manifest has no `{key}`"))
}

fn array<'a>(v: &'a Value, key: &str) -> Result<&'a Vec<Value>, String> {
    field(v, key)?.as_array().ok_or_else(|| format!("`{key}` is not an array"))
}

/// The textures of one frame and where each binding role finds its image.
struct Images<'d> {
    device: &'d wgpu::Device,
    queue: &'d wgpu::Queue,
    extent: wgpu::Extent3d,
    /// Images by name: `color`, the inputs, then what the stages write.
    views: HashMap<String, (wgpu::Texture, wgpu::TextureView)>,
}

impl Images<'_> {
    /// A `format` texture of the frame's size for `usage`.
    fn texture(&self, name: &str, format: wgpu::TextureFormat, usage: wgpu::TextureUsages) -> wgpu::Texture {
        self.device.create_texture(&wgpu::TextureDescriptor {
            label: Some(name),
            size: self.extent,
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage,
            view_formats: &[],
        })
    }

    /// Upload `texels` as an RGBA32F sampled texture called `name` (that a
    /// sequence may copy to keep it).
    fn upload(&mut self, name: &str, texels: &[[f32; 4]]) {
        let usage =
            wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST | wgpu::TextureUsages::COPY_SRC;
        let texture = self.texture(name, wgpu::TextureFormat::Rgba32Float, usage);
        self.queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture: &texture,
                mip_level: 0,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            bytemuck::cast_slice(texels),
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(16 * self.extent.width),
                rows_per_image: Some(self.extent.height),
            },
            self.extent,
        );
        let view = texture.create_view(&Default::default());
        self.views.insert(name.to_string(), (texture, view));
    }

    /// A texture a stage writes and a later one reads, called `name`.
    fn target(&mut self, name: &str, format: wgpu::TextureFormat) {
        let usage =
            wgpu::TextureUsages::STORAGE_BINDING | wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_SRC;
        let texture = self.texture(name, format, usage);
        let view = texture.create_view(&Default::default());
        self.views.insert(name.to_string(), (texture, view));
    }

    /// Bind `texture` as the image `name`.
    fn insert(&mut self, name: &str, texture: wgpu::Texture) {
        let view = texture.create_view(&Default::default());
        self.views.insert(name.to_string(), (texture, view));
    }

    /// Record a copy of the image `from` into a new texture of its format,
    /// which becomes the next frame's `into`.
    fn keep(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        from: &str,
        into: &str,
        kept: &mut HashMap<String, wgpu::Texture>,
    ) -> Result<(), String> {
        let (source, _) = self.views.get(from).ok_or_else(|| format!("no image `{from}` to keep as `{into}`"))?;
        let usage = wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST;
        let texture = self.texture(into, source.format(), usage);
        encoder.copy_texture_to_texture(source.as_image_copy(), texture.as_image_copy(), self.extent);
        kept.insert(into.to_string(), texture);
        Ok(())
    }

    fn view(&self, name: &str) -> Result<&wgpu::TextureView, String> {
        self.views.get(name).map(|(_, v)| v).ok_or_else(|| format!("no image `{name}` (the frame lacks it?)"))
    }
}

/// A storage texture's format, as the manifest gives it.
fn texel_format(binding: &Value) -> Result<wgpu::TextureFormat, String> {
    match binding["format"].as_str() {
        Some("rgba16float") => Ok(wgpu::TextureFormat::Rgba16Float),
        Some("rgba32float") => Ok(wgpu::TextureFormat::Rgba32Float),
        Some("r32float") => Ok(wgpu::TextureFormat::R32Float),
        other => {
            Err(format!("unknown texel format {other:?} of `{}`", binding.get("role").unwrap_or(&binding["name"])))
        }
    }
}

/// One dispatch of a shader: its uniform's values by field name, and the
/// image each role is bound to.
struct Dispatch<'a> {
    values: HashMap<&'a str, f64>,
    images: HashMap<&'a str, String>,
}

/// Build `stage`'s pipeline (its bindings from the manifest) and record one
/// dispatch of it into `encoder`.
#[allow(clippy::too_many_arguments)]
fn record(
    images: &Images<'_>,
    encoder: &mut wgpu::CommandEncoder,
    wgsl: &str,
    stage: &Value,
    workgroup: [u32; 2],
    frame: &Frame,
    dispatch: &Dispatch<'_>,
) -> Result<(), String> {
    let device = images.device;
    let bindings = array(stage, "bindings")?;
    // The uniform, field by field: width and height, the dispatch's values,
    // and the normalisation scales of the inputs (`scale[k]`, k a binding's `scale_index`).
    let uniform_info = field(stage, "uniform")?;
    let size = field(uniform_info, "size_bytes")?.as_u64().ok_or("uniform size")? as usize;
    let mut uniform = vec![0u8; size];
    for f in array(uniform_info, "fields")? {
        let name = f["name"].as_str().ok_or("field name")?;
        let offset = f["offset"].as_u64().ok_or("field offset")? as usize;
        let value = match name {
            "width" => Some(frame.width as f64),
            "height" => Some(frame.height as f64),
            _ if name.starts_with("scale[") => {
                let k: u64 = name[6..name.len() - 1].parse().map_err(|_| format!("bad field {name}"))?;
                let role = bindings
                    .iter()
                    .find(|b| b.get("scale_index").and_then(Value::as_u64) == Some(k))
                    .and_then(|b| b["role"].as_str())
                    .ok_or_else(|| format!("no binding has scale index {k}"))?;
                Some(frame.scales.get(role).copied().unwrap_or(1.0) as f64)
            }
            _ => dispatch.values.get(name).copied(),
        };
        let bytes = match (f["type"].as_str(), value) {
            (_, None) => [0; 4],
            (Some("u32"), Some(v)) => (v as u32).to_le_bytes(),
            (Some("f32" | "vec4<f32>"), Some(v)) => (v as f32).to_le_bytes(),
            (other, _) => return Err(format!("field {name} has type {other:?}")),
        };
        uniform[offset..offset + 4].copy_from_slice(&bytes);
    }
    let params = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("params"),
        size: size as u64,
        usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    images.queue.write_buffer(&params, 0, &uniform);

    // Layout and resources, binding by binding, from the manifest.
    let mut layout_entries = Vec::new();
    let mut resources = Vec::new();
    for b in bindings {
        let binding = b["binding"].as_u64().ok_or("binding number")? as u32;
        let role = b["role"].as_str().ok_or("binding role")?;
        // The image a binding reads or writes: the dispatch's choice, else the manifest's `image`, else its role.
        let image = || -> Result<&wgpu::TextureView, String> {
            images.view(dispatch.images.get(role).map(String::as_str).or(b["image"].as_str()).unwrap_or(role))
        };
        let (ty, resource) = match b["kind"].as_str() {
            Some("uniform") => (
                wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                params.as_entire_binding(),
            ),
            Some("storage_texture") => (
                wgpu::BindingType::StorageTexture {
                    access: wgpu::StorageTextureAccess::WriteOnly,
                    format: texel_format(b)?,
                    view_dimension: wgpu::TextureViewDimension::D2,
                },
                wgpu::BindingResource::TextureView(image()?),
            ),
            // Read with textureLoad only: 32-bit float textures need no filtering.
            Some("sampled_texture") => (
                wgpu::BindingType::Texture {
                    sample_type: wgpu::TextureSampleType::Float { filterable: false },
                    view_dimension: wgpu::TextureViewDimension::D2,
                    multisampled: false,
                },
                wgpu::BindingResource::TextureView(image()?),
            ),
            other => return Err(format!("unknown binding kind {other:?}")),
        };
        layout_entries.push(wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty,
            count: None,
        });
        resources.push(wgpu::BindGroupEntry { binding, resource });
    }
    let layout =
        device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: None, entries: &layout_entries });
    let bind_group =
        device.create_bind_group(&wgpu::BindGroupDescriptor { label: None, layout: &layout, entries: &resources });
    let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: None,
        bind_group_layouts: &[Some(&layout)],
        immediate_size: 0,
    });
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("exported filter"),
        source: wgpu::ShaderSource::Wgsl(wgsl.into()),
    });
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some("exported filter"),
        layout: Some(&pipeline_layout),
        module: &module,
        entry_point: Some(field(stage, "entry_point")?.as_str().ok_or("entry point")?),
        compilation_options: Default::default(),
        cache: None,
    });
    let mut pass = encoder.begin_compute_pass(&Default::default());
    pass.set_pipeline(&pipeline);
    pass.set_bind_group(0, &bind_group, &[]);
    pass.dispatch_workgroups(frame.width.div_ceil(workgroup[0]), frame.height.div_ceil(workgroup[1]), 1);
    Ok(())
}

/// Filter `frame` with the exported `shaders` described by `manifest`, as
/// a frame of its own; returns the filtered frame's texels as f32 RGBA.
pub fn filter(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    shaders: &Shaders,
    manifest: &Value,
    frame: &Frame,
    radius: u32,
) -> Result<Vec<[f32; 4]>, String> {
    filter_frame(device, queue, shaders, manifest, frame, radius, &mut Sequence::new())
}

/// Filter `frame`, the next of `sequence`: the temporal stage blends it
/// with what the frames before left; what the manifest's `keep` steps copy is
/// kept for the next.
pub fn filter_frame(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    shaders: &Shaders,
    manifest: &Value,
    frame: &Frame,
    radius: u32,
    sequence: &mut Sequence,
) -> Result<Vec<[f32; 4]>, String> {
    if manifest.get("version").and_then(Value::as_u64) != Some(MANIFEST_VERSION) {
        return Err(format!(
            "manifest version {:?}: this host reads version {MANIFEST_VERSION}",
            manifest.get("version")
        ));
    }
    let (width, height) = (frame.width, frame.height);
    let extent = wgpu::Extent3d { width, height, depth_or_array_layers: 1 };
    let output_format = match field(manifest, "output_format")?.as_str() {
        Some("rgba16float") => wgpu::TextureFormat::Rgba16Float,
        Some("rgba32float") => wgpu::TextureFormat::Rgba32Float,
        other => return Err(format!("unknown output format {other:?}")),
    };
    let size: Vec<u32> = array(manifest, "workgroup_size")?.iter().map(|v| v.as_u64().unwrap_or(1) as u32).collect();
    let workgroup = [size[0], size[1]];
    let mut images = Images { device, queue, extent, views: HashMap::new() };
    images.upload("color", &frame.color);
    for (role, texels) in &frame.inputs {
        images.upload(role, texels);
    }
    // What the frame before kept; on a sequence's first frame, textures the blend does not read.
    // Every other image the pipeline makes is a texture of its format.
    let first = sequence.frames == 0 || sequence.size != (width, height);
    for image in array(manifest, "images")? {
        let name = field(image, "name")?.as_str().ok_or("an image's name")?;
        if image.get("kept_from").is_some() {
            match sequence.kept.get(name).filter(|_| !first) {
                Some(texture) => images.insert(name, texture.clone()),
                None => images.upload(name, &vec![[0.0; 4]; (width * height) as usize]),
            }
        } else {
            images.target(name, texel_format(image)?);
        }
    }
    let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
    let mut encoder = device.create_command_encoder(&Default::default());
    // The frame, step by step, as the manifest's `frame` says.
    let mut kept = HashMap::new();
    let none = Value::Object(Default::default());
    for step in array(manifest, "frame")? {
        if let Some(keep) = step.get("keep") {
            let name = |key| field(keep, key).and_then(|v| v.as_str().ok_or(format!("a keep step's `{key}`")));
            images.keep(&mut encoder, name("from")?, name("into")?, &mut kept)?;
            continue;
        }
        let step = field(step, "dispatch")?;
        let shader = field(step, "shader")?.as_str().ok_or("a dispatch's shader")?;
        let (stage, wgsl) = match shader {
            "form" => (manifest, shaders.form.as_str()),
            _ => (
                field(manifest, shader)?,
                shaders
                    .stages
                    .get(shader)
                    .ok_or(format!("the frame dispatches {shader}, and no {shader} shader was given"))?
                    .as_str(),
            ),
        };
        let mut dispatch = Dispatch { values: HashMap::new(), images: HashMap::new() };
        // A sequence's first frame replaces some values (the temporal stage's `history`).
        let first_frame = if first { step.get("first_frame").unwrap_or(&none) } else { &none };
        for values in [field(step, "values")?, first_frame] {
            for (name, value) in values.as_object().ok_or("values")? {
                dispatch.values.insert(name.as_str(), value.as_f64().ok_or("a uniform value")?);
            }
        }
        // A window form's radius may be the caller's.
        if shader == "form" && dispatch.values.contains_key("radius") {
            dispatch.values.insert("radius", radius as f64);
        }
        for (role, image) in field(step, "images")?.as_object().ok_or("images")? {
            dispatch.images.insert(role.as_str(), image.as_str().ok_or("an image name")?.to_string());
        }
        record(&images, &mut encoder, wgsl, stage, workgroup, frame, &dispatch)?;
    }
    let output = field(manifest, "output")?.as_str().ok_or("`output` is not a name")?;

    // Copy the last image out (rows padded to 256 bytes).
    let texel_bytes = if output_format == wgpu::TextureFormat::Rgba16Float { 8 } else { 16 };
    let row_bytes = (width * texel_bytes).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
    let staging = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("read back"),
        size: (row_bytes * height) as u64,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let (last, _) = images.views.get(output).ok_or("no filtered image")?;
    encoder.copy_texture_to_buffer(
        wgpu::TexelCopyTextureInfo {
            texture: last,
            mip_level: 0,
            origin: wgpu::Origin3d::ZERO,
            aspect: wgpu::TextureAspect::All,
        },
        wgpu::TexelCopyBufferInfo {
            buffer: &staging,
            layout: wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(row_bytes), rows_per_image: None },
        },
        extent,
    );
    // The uploads first, so that the frame's time is its GPU work alone (an
    // engine's inputs are on the GPU already; it would not wait here).
    queue.submit([]);
    device.poll(wgpu::PollType::wait_indefinitely()).map_err(|e| e.to_string())?;
    let submitted = std::time::Instant::now();
    queue.submit([encoder.finish()]);
    if let Some(error) = pollster::block_on(scope.pop()) {
        return Err(error.to_string());
    }
    device.poll(wgpu::PollType::wait_indefinitely()).map_err(|e| e.to_string())?;
    let gpu_time = Some(submitted.elapsed());
    if !kept.is_empty() {
        let frames = if first { 1 } else { sequence.frames + 1 };
        *sequence = Sequence { kept, size: (width, height), frames, gpu_time };
    } else {
        sequence.gpu_time = gpu_time;
    }
    let slice = staging.slice(..);
    slice.map_async(wgpu::MapMode::Read, |_| {});
    device.poll(wgpu::PollType::wait_indefinitely()).map_err(|e| e.to_string())?;
    let bytes = slice.get_mapped_range().map_err(|e| e.to_string())?;
    let mut texels = Vec::with_capacity((width * height) as usize);
    for row in bytes.chunks(row_bytes as usize) {
        for texel in row[..(width * texel_bytes) as usize].chunks(texel_bytes as usize) {
            let mut rgba = [0f32; 4];
            for (c, value) in rgba.iter_mut().enumerate() {
                *value = if texel_bytes == 8 {
                    half::f16::from_le_bytes([texel[2 * c], texel[2 * c + 1]]).to_f32()
                } else {
                    f32::from_le_bytes(texel[4 * c..4 * c + 4].try_into().expect("4 bytes"))
                };
            }
            texels.push(rgba);
        }
    }
    Ok(texels)
}
