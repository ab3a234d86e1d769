//! How a kernel's image loads cost on the adapter wgpu picks (`WGPU_BACKEND`
//! narrows it): one 5×5-tap pass over a 256² frame that reads five RGBA32F
//! images a tap, from storage buffers, from one interleaved storage buffer,
//! and from sampled textures (`textureLoad`), each with the taps outside the
//! image skipped (`continue`) or clamped. Median of seven dispatches, ms.
//! docs/JOURNAL.md, "Textures for the form's taps", reads it.
//!
//!     cargo bench --bench image_loads

mod common;

use wgpu::util::DeviceExt;

const SIDE: u32 = 256;
const IMAGES: usize = 5;

/// The WGSL of one pass; `load` spells image K at (XX, YY).
fn kernel(declarations: &str, load: &str, skip_outside: bool) -> String {
    let at = |k: usize, x: &str, y: &str| load.replace('K', &k.to_string()).replace("XX", x).replace("YY", y);
    let mut s = String::from("@group(0) @binding(0) var<storage, read_write> out: array<vec4<f32>>;\n");
    s += declarations;
    s += "@compute @workgroup_size(8, 8, 1)\nfn main(@builtin(global_invocation_id) gid: vec3<u32>) {\n";
    s += "    let x = i32(gid.x);\n    let y = i32(gid.y);\n    var sw = 0.0;\n    var sc = vec3<f32>(0.0);\n";
    for k in 0..IMAGES {
        s += &format!("    let f{k} = {};\n", at(k, "x", "y"));
    }
    s += "    for (var dy = -2; dy <= 2; dy++) {\n        for (var dx = -2; dx <= 2; dx++) {\n";
    if skip_outside {
        s += "            let xj = x + dx * 2;\n            let yj = y + dy * 2;\n";
        s +=
            "            if (xj < 0 || yj < 0 || xj >= 256 || yj >= 256) {\n                continue;\n            }\n";
        s += "            let inside = 1.0;\n";
    } else {
        s += "            let inside = select(0.0, 1.0, x + dx * 2 >= 0 && y + dy * 2 >= 0 && x + dx * 2 < 256 && y + dy * 2 < 256);\n";
        s += "            let xj = clamp(x + dx * 2, 0, 255);\n            let yj = clamp(y + dy * 2, 0, 255);\n";
    }
    s += &format!("            let cj = {};\n            var d = distance(f0, cj);\n", at(0, "xj", "yj"));
    for k in 1..IMAGES {
        s += &format!("            d += distance(f{k}, {});\n", at(k, "xj", "yj"));
    }
    s += "            let w = inside * exp(-d);\n            sw += w;\n            sc += w * cj;\n        }\n    }\n";
    s += "    out[y * 256 + x] = vec4<f32>(sc / max(sw, 1e-30), 1.0);\n}\n";
    s
}

fn main() {
    let (device, queue) = common::device("image_loads");
    let pixels = (SIDE * SIDE) as usize;
    let images: Vec<Vec<[f32; 4]>> = (0..IMAGES)
        .map(|k| {
            (0..pixels)
                .map(|i| {
                    let v = ((i * 7 + k * 13) % 101) as f32 / 101.0;
                    [v, v * 0.5, 1.0 - v, 1.0]
                })
                .collect()
        })
        .collect();
    let storage = |data: &[[f32; 4]]| {
        device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: None,
            contents: bytemuck::cast_slice(data),
            usage: wgpu::BufferUsages::STORAGE,
        })
    };
    let buffers: Vec<wgpu::Buffer> = images.iter().map(|d| storage(d)).collect();
    let interleaved: Vec<[f32; 4]> = (0..pixels).flat_map(|i| images.iter().map(move |d| d[i])).collect();
    let interleaved = storage(&interleaved);
    let extent = wgpu::Extent3d { width: SIDE, height: SIDE, depth_or_array_layers: 1 };
    let textures: Vec<wgpu::TextureView> = images
        .iter()
        .map(|d| {
            let texture = device.create_texture(&wgpu::TextureDescriptor {
                label: None,
                size: extent,
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: wgpu::TextureFormat::Rgba32Float,
                usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
                view_formats: &[],
            });
            queue.write_texture(
                texture.as_image_copy(),
                bytemuck::cast_slice(d),
                wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(16 * SIDE), rows_per_image: Some(SIDE) },
                extent,
            );
            texture.create_view(&Default::default())
        })
        .collect();
    let out = device.create_buffer(&wgpu::BufferDescriptor {
        label: None,
        size: pixels as u64 * 16,
        usage: wgpu::BufferUsages::STORAGE,
        mapped_at_creation: false,
    });
    let declare = |ty: &str| -> String {
        (0..IMAGES)
            .map(|k| format!("@group(0) @binding({}) var{ty};\n", k + 1).replace("NAME", &k.to_string()))
            .collect()
    };
    let variants: [(&str, String, &str); 3] = [
        ("storage buffers", declare("<storage, read> bNAME: array<vec4<f32>>"), "bK[YY * 256 + XX].xyz"),
        (
            "one interleaved storage buffer",
            "@group(0) @binding(1) var<storage, read> images: array<vec4<f32>>;\n".into(),
            "images[(YY * 256 + XX) * 5 + K].xyz",
        ),
        ("sampled textures", declare(" tNAME: texture_2d<f32>"), "textureLoad(tK, vec2<i32>(XX, YY), 0).xyz"),
    ];
    for (k, (name, declarations, load)) in variants.iter().enumerate() {
        for skip_outside in [true, false] {
            let pipeline = common::pipeline(&device, kernel(declarations, load, skip_outside));
            let mut entries = vec![wgpu::BindGroupEntry { binding: 0, resource: out.as_entire_binding() }];
            let resource = |i: usize| match k {
                0 => buffers[i].as_entire_binding(),
                1 => interleaved.as_entire_binding(),
                _ => wgpu::BindingResource::TextureView(&textures[i]),
            };
            let bound = if k == 1 { 1 } else { IMAGES };
            entries.extend((0..bound).map(|i| wgpu::BindGroupEntry { binding: i as u32 + 1, resource: resource(i) }));
            let layout = pipeline.get_bind_group_layout(0);
            let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: None,
                layout: &layout,
                entries: &entries,
            });
            let median = common::median_ms(&device, &queue, 8, |encoder| {
                common::dispatch(encoder, &pipeline, &group, (SIDE / 8, SIDE / 8))
            });
            let skip = if skip_outside { "taps outside skipped" } else { "taps clamped" };
            println!("{median:8.1} ms  {name}, {skip}");
        }
    }
}
