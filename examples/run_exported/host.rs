//! Runs a shader from `filterjit export --target wgsl` with plain wgpu,
//! knowing only the documented interface: the manifest beside the shader.
//! Nothing here uses filterjit; this is what an engine's integration does.
//! (`tests/export.rs` runs this same file against `filterjit filter`.)

use std::collections::HashMap;

use serde_json::Value;

/// One frame of an engine's G-buffer, as plain arrays (row-major, top row first).
pub struct Frame {
    pub width: u32,
    pub height: u32,
    /// Noisy linear RGB colour; alpha is passed through.
    pub color: Vec<[f32; 4]>,
    /// The inputs by the manifest's `role` (`normal`, `wpVariance`, …), as the engine has them.
    pub inputs: HashMap<String, Vec<[f32; 4]>>,
    /// Normalisation scale per role; 1 when absent (textures already normalised).
    pub scales: HashMap<String, f32>,
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

/// Filter `frame` with the exported shader `wgsl` described by `manifest`;
/// returns the output texture's texels as f32 RGBA.
pub fn filter(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    wgsl: &str,
    manifest: &Value,
    frame: &Frame,
    radius: u32,
) -> Result<Vec<[f32; 4]>, String> {
    let (width, height) = (frame.width, frame.height);
    let extent = wgpu::Extent3d { width, height, depth_or_array_layers: 1 };
    let output_format = match field(manifest, "output_format")?.as_str() {
        Some("rgba16float") => wgpu::TextureFormat::Rgba16Float,
        Some("rgba32float") => wgpu::TextureFormat::Rgba32Float,
        other => return Err(format!("unknown output format {other:?}")),
    };
    let workgroup: Vec<u32> = field(manifest, "workgroup_size")?
        .as_array()
        .ok_or("workgroup_size is not an array")?
        .iter()
        .map(|v| v.as_u64().unwrap_or(1) as u32)
        .collect();

    // The uniform: width, height, radius, pad, then one vec4 per scale_index.
    let bindings = field(manifest, "bindings")?.as_array().ok_or("bindings is not an array")?;
    let size = field(field(manifest, "uniform")?, "size_bytes")?.as_u64().ok_or("uniform size")? as usize;
    let mut uniform = vec![0u8; size];
    for (k, value) in [width, height, radius, 0].into_iter().enumerate() {
        uniform[4 * k..4 * k + 4].copy_from_slice(&value.to_le_bytes());
    }
    for b in bindings {
        if let (Some(k), Some(role)) = (b.get("scale_index").and_then(Value::as_u64), b["role"].as_str()) {
            let scale = frame.scales.get(role).copied().unwrap_or(1.0);
            let offset = 16 + 16 * k as usize;
            uniform[offset..offset + 4].copy_from_slice(&scale.to_le_bytes());
        }
    }
    let params = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("params"),
        size: size as u64,
        usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    queue.write_buffer(&params, 0, &uniform);

    let sampled = |label: &str, texels: &[[f32; 4]]| -> wgpu::TextureView {
        let texture = device.create_texture(&wgpu::TextureDescriptor {
            label: Some(label),
            size: extent,
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::Rgba32Float,
            usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            view_formats: &[],
        });
        queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture: &texture,
                mip_level: 0,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            bytemuck::cast_slice(texels),
            wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(16 * width), rows_per_image: Some(height) },
            extent,
        );
        texture.create_view(&Default::default())
    };
    let output = device.create_texture(&wgpu::TextureDescriptor {
        label: Some("filtered"),
        size: extent,
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: output_format,
        usage: wgpu::TextureUsages::STORAGE_BINDING | wgpu::TextureUsages::COPY_SRC,
        view_formats: &[],
    });
    let output_view = output.create_view(&Default::default());

    // Layout and resources, binding by binding, from the manifest.
    let mut layout_entries = Vec::new();
    let mut views = Vec::new();
    for b in bindings {
        let binding = b["binding"].as_u64().ok_or("binding number")? as u32;
        let role = b["role"].as_str().ok_or("binding role")?;
        let ty = match b["kind"].as_str() {
            Some("uniform") => wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Uniform,
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            Some("storage_texture") => wgpu::BindingType::StorageTexture {
                access: wgpu::StorageTextureAccess::WriteOnly,
                format: output_format,
                view_dimension: wgpu::TextureViewDimension::D2,
            },
            Some("sampled_texture") => {
                let texels = if role == "color" {
                    &frame.color
                } else {
                    frame.inputs.get(role).ok_or_else(|| format!("the frame has no `{role}`"))?
                };
                views.push((binding, sampled(role, texels)));
                // Read with textureLoad only: 32-bit float textures need no filtering.
                wgpu::BindingType::Texture {
                    sample_type: wgpu::TextureSampleType::Float { filterable: false },
                    view_dimension: wgpu::TextureViewDimension::D2,
                    multisampled: false,
                }
            }
            other => return Err(format!("unknown binding kind {other:?}")),
        };
        layout_entries.push(wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty,
            count: None,
        });
    }
    let bind_group_layout =
        device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: None, entries: &layout_entries });
    let mut entries = vec![
        wgpu::BindGroupEntry { binding: 0, resource: params.as_entire_binding() },
        wgpu::BindGroupEntry { binding: 2, resource: wgpu::BindingResource::TextureView(&output_view) },
    ];
    for (binding, view) in &views {
        entries.push(wgpu::BindGroupEntry { binding: *binding, resource: wgpu::BindingResource::TextureView(view) });
    }
    let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: None,
        layout: &bind_group_layout,
        entries: &entries,
    });
    let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: None,
        bind_group_layouts: &[Some(&bind_group_layout)],
        immediate_size: 0,
    });
    let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("exported filter"),
        source: wgpu::ShaderSource::Wgsl(wgsl.into()),
    });
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some("exported filter"),
        layout: Some(&pipeline_layout),
        module: &module,
        entry_point: Some(field(manifest, "entry_point")?.as_str().ok_or("entry point")?),
        compilation_options: Default::default(),
        cache: None,
    });

    // Dispatch, then copy the output texture out (rows padded to 256 bytes).
    let texel_bytes = if output_format == wgpu::TextureFormat::Rgba16Float { 8 } else { 16 };
    let row_bytes = (width * texel_bytes).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
    let staging = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("read back"),
        size: (row_bytes * height) as u64,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut encoder = device.create_command_encoder(&Default::default());
    {
        let mut pass = encoder.begin_compute_pass(&Default::default());
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.dispatch_workgroups(width.div_ceil(workgroup[0]), height.div_ceil(workgroup[1]), 1);
    }
    encoder.copy_texture_to_buffer(
        wgpu::TexelCopyTextureInfo {
            texture: &output,
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
    queue.submit([encoder.finish()]);
    if let Some(error) = pollster::block_on(scope.pop()) {
        return Err(error.to_string());
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
