//! Runs a filter from `filterjit export --target wgsl` with plain wgpu,
//! knowing only the documented interface: the manifest beside the shader.
//! Nothing here uses filterjit; this is what an engine's integration does.
//! (`tests/export.rs` runs this same file against `filterjit filter`.)
//!
//! Per frame, as the manifest's `order` says: the pre-pass shader once (where
//! the pipeline has one), the spread shader's `sequence` (where it keeps what
//! the clamp removed), the temporal stage's two shaders (where the pipeline
//! has `temporal=A`: the blend with the history, then its variance), the
//! guide shader (where the weight reads `guide`), then the form's shader
//! `passes` times (à-trous: pass k with step 2^k, colour and carried
//! variance ping-ponged between textures), then the planefit shader (where
//! the pipeline has `planefit`), then the pixel filter's (where it has
//! `pixelfilter`). A sequence keeps the manifest's `history`
//! from frame to frame ([`Sequence`]).

use std::collections::HashMap;

use serde_json::Value;

/// The layout of the manifest this host reads (filterjit's `export::MANIFEST_VERSION`).
const MANIFEST_VERSION: u64 = 7;

/// The stages besides the form's that run before it, in order.
const BEFORE_THE_FORM: [&str; 4] = ["spread", "temporal", "temporal_variance", "guide"];

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
/// images the manifest's `history` names. A new one (or [`Sequence::reset`])
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
        other => Err(format!("unknown texel format {other:?} of `{}`", binding["role"])),
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

/// Record the dispatches of the manifest's stage `name` (where it has one) as
/// its `sequence` says: each names the image every role binds, and its
/// uniform takes the stage's values, then its own. `filtered` is the image
/// the name `filtered` stands for (the form's last output). Whether it ran.
#[allow(clippy::too_many_arguments)]
fn run_stage(
    images: &mut Images<'_>,
    encoder: &mut wgpu::CommandEncoder,
    manifest: &Value,
    name: &str,
    shader: Option<&str>,
    workgroup: [u32; 2],
    frame: &Frame,
    filtered: Option<&str>,
    first: bool,
) -> Result<bool, String> {
    let Some(stage) = manifest.get(name).filter(|p| !p.is_null()) else { return Ok(false) };
    let wgsl = shader.ok_or(format!("the manifest has a {name} stage, and no {name} shader was given"))?;
    let none = Value::Object(Default::default());
    // A sequence's first frame replaces some of the stage's values (the temporal stage's `history`).
    let first_frame = if first { stage.get("first_frame").unwrap_or(&none) } else { &none };
    for step in array(stage, "sequence")? {
        let mut dispatch = Dispatch { values: HashMap::new(), images: HashMap::new() };
        for values in [field(stage, "uniform_values")?, first_frame, field(step, "uniform_values")?] {
            for (name, value) in values.as_object().ok_or("uniform_values")? {
                dispatch.values.insert(name.as_str(), value.as_f64().ok_or("a uniform value")?);
            }
        }
        for (role, image) in field(step, "images")?.as_object().ok_or("images")? {
            let image = image.as_str().ok_or("an image name")?;
            let image = match (image, filtered) {
                ("filtered", Some(last)) => last,
                _ => image,
            };
            dispatch.images.insert(role.as_str(), image.to_string());
        }
        // What it writes is a fresh texture (`target` replaces by name).
        for b in array(stage, "bindings")?.iter().filter(|b| b["kind"] == "storage_texture") {
            let role = b["role"].as_str().ok_or("binding role")?;
            images.target(dispatch.images.get(role).map(String::as_str).unwrap_or(role), texel_format(b)?);
        }
        record(images, encoder, wgsl, stage, workgroup, frame, &dispatch)?;
    }
    Ok(true)
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
/// with what the frames before left; what the manifest's `history` names is
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
    let first = sequence.frames == 0 || sequence.size != (width, height);
    let history = manifest.get("history").and_then(Value::as_array).cloned().unwrap_or_default();
    for kept in &history {
        let image = field(kept, "image")?.as_str().ok_or("a kept image's name")?;
        match sequence.kept.get(image).filter(|_| !first) {
            Some(texture) => images.insert(image, texture.clone()),
            None => images.upload(image, &vec![[0.0; 4]; (width * height) as usize]),
        }
    }
    let mut kept = HashMap::new();
    let keep_after = |pass: Option<u64>| {
        history.iter().filter(move |k| k.get("after_pass").and_then(Value::as_u64) == pass).map(|k| {
            (k["from"].as_str().unwrap_or_default().to_string(), k["image"].as_str().unwrap_or_default().to_string())
        })
    };
    let stage_shader = |name: &str| shaders.stages.get(name).map(String::as_str);
    let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
    let mut encoder = device.create_command_encoder(&Default::default());

    // The pre-pass, once: it writes the colour the form filters and the modulation.
    if let Some(stage) = manifest.get("prepass").filter(|p| !p.is_null()) {
        let wgsl = stage_shader("prepass").ok_or("the manifest has a pre-pass, and no pre-pass shader was given")?;
        // Everything it writes (`prepared`, `modulation`, what the outlier rule measured) is read later by role.
        for b in array(stage, "bindings")?.iter().filter(|b| b["kind"] == "storage_texture") {
            images.target(b["role"].as_str().ok_or("binding role")?, texel_format(b)?);
        }
        if !images.views.contains_key("albedo") {
            // Not read unless the pipeline demodulates; any texture will do.
            let any = frame.color.clone();
            images.upload("albedo", &any);
        }
        let mut values = HashMap::new();
        for (name, value) in field(stage, "uniform_values")?.as_object().ok_or("uniform_values")? {
            values.insert(name.as_str(), value.as_f64().ok_or("a uniform value")?);
        }
        let dispatch = Dispatch { values, images: HashMap::new() };
        record(&images, &mut encoder, wgsl, stage, workgroup, frame, &dispatch)?;
    }

    // The spread, the temporal stage, then the guide, dispatch by dispatch:
    // each names the image every role binds; its uniform takes the stage's
    // values, then its own.
    for name in BEFORE_THE_FORM {
        run_stage(&mut images, &mut encoder, manifest, name, stage_shader(name), workgroup, frame, None, first)?;
    }
    // The form's first pass filters what the manifest names.
    let mut colour = field(manifest, "filters")?.as_str().ok_or("`filters` is not a name")?.to_string();

    // The form, `passes` times; pass k reads pass k-1's image and variance.
    let passes = field(manifest, "passes")?.as_u64().ok_or("passes")? as u32;
    // The variance the passes carry, where the weight reads one: pass 0 binds the frame's.
    let carried = manifest.get("carries").and_then(Value::as_str);
    let mut variance = carried.unwrap_or("colorVariance").to_string();
    for k in 0..passes {
        let (out, variance_out) = (format!("image{}", k % 2), format!("variance{}", k % 2));
        images.target(&out, output_format);
        if carried.is_some() {
            images.target(&variance_out, wgpu::TextureFormat::R32Float);
        }
        let values: HashMap<&str, f64> = [
            ("radius", radius as f64),
            ("step", (1u64 << k) as f64),
            ("level", k as f64),
            ("last", if k + 1 == passes { 1.0 } else { 0.0 }),
        ]
        .into();
        let mut roles: HashMap<&str, String> = [
            ("color", colour.clone()),
            ("output", out.clone()),
            ("variance_out", variance_out.clone()),
            // The guide stage's in pass 0, the pass's own colour after.
            ("guide", if k == 0 { "guide".to_string() } else { colour.clone() }),
        ]
        .into();
        if let Some(role) = carried {
            roles.insert(role, variance.clone());
        }
        let dispatch = Dispatch { values, images: roles };
        record(&images, &mut encoder, &shaders.form, manifest, workgroup, frame, &dispatch)?;
        // The pass the temporal stage feeds back, kept before a later pass writes its texture again.
        for (from, into) in keep_after(Some(k as u64)) {
            images.keep(&mut encoder, &from, &into, &mut kept)?;
        }
        // Pass k+1 reads what pass k wrote and writes fresh textures (`target` replaces by name).
        colour = out;
        variance = variance_out;
    }
    // `planefit` after the form: its `filtered` is the last pass's output; it writes the frame.
    if run_stage(
        &mut images,
        &mut encoder,
        manifest,
        "planefit",
        stage_shader("planefit"),
        workgroup,
        frame,
        Some(&colour),
        first,
    )? {
        colour = "fitted".to_string();
    }
    // `pixelfilter`, last: it reads the frame so far (`fitted`, or `filtered`: the last pass's output).
    if run_stage(
        &mut images,
        &mut encoder,
        manifest,
        "pixelfilter",
        stage_shader("pixelfilter"),
        workgroup,
        frame,
        Some(&colour),
        first,
    )? {
        colour = "pixelfiltered".to_string();
    }
    // What the next frame reads of this one.
    for (from, into) in keep_after(None) {
        images.keep(&mut encoder, &from, &into, &mut kept)?;
    }

    // Copy the last image out (rows padded to 256 bytes).
    let texel_bytes = if output_format == wgpu::TextureFormat::Rgba16Float { 8 } else { 16 };
    let row_bytes = (width * texel_bytes).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
    let staging = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("read back"),
        size: (row_bytes * height) as u64,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let (last, _) = images.views.get(&colour).ok_or("no filtered image")?;
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
    if !history.is_empty() {
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
