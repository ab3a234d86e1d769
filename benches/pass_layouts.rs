//! What a 3×3 à-trous pass over a 1920×1080 frame costs on the adapter wgpu
//! picks (`WGPU_BACKEND` narrows it), by how its images are laid out and how
//! its result reaches the next pass's texture: the colour, the position, the
//! normal and the albedo in four RGBA32F textures (filterjit's layout), the
//! normal spread over the other three's fourth channels (three textures, the
//! same bits), the normal and albedo as halves in one RGBA32Uint texture, or
//! in two RGBA16Float ones; the result written to a storage buffer and copied
//! into a texture (filterjit's), or stored into the texture by the kernel.
//! Median of five dispatches after the one that compiles, ms.
//! docs/JOURNAL.md, "Guards a value's range proves idle" reads it.
//!
//!     cargo bench --bench pass_layouts

mod common;

use wgpu::util::DeviceExt;

const WIDTH: u32 = 1920;
const HEIGHT: u32 = 1080;

/// How the features sit in textures.
#[derive(Clone, Copy, PartialEq, Debug)]
enum Layout {
    /// colour, position, normal, albedo: four RGBA32F.
    Four,
    /// colour+n.x, position+n.y, albedo+n.z: three RGBA32F.
    ThreeSpread,
    /// colour, position RGBA32F; normal and albedo as six halves in one RGBA32Uint.
    PackedHalves,
    /// colour, position RGBA32F; normal and albedo RGBA16Float.
    Float16,
}

/// How a pass's result reaches the texture the next pass samples.
#[derive(Clone, Copy, PartialEq, Debug)]
enum Output {
    BufferThenCopy,
    Store,
}

fn kernel(layout: Layout, output: Output) -> String {
    let mut s = String::new();
    let texture = |b: u32, name: &str, ty: &str| format!("@group(0) @binding({b}) var {name}: texture_2d<{ty}>;\n");
    s += &texture(1, "t_color", "f32");
    s += &texture(2, "t_position", "f32");
    match layout {
        Layout::Four | Layout::Float16 => {
            s += &texture(3, "t_normal", "f32");
            s += &texture(4, "t_albedo", "f32");
        }
        Layout::ThreeSpread => s += &texture(3, "t_albedo", "f32"),
        Layout::PackedHalves => s += &texture(3, "t_packed", "u32"),
    }
    s += match output {
        Output::BufferThenCopy => "@group(0) @binding(0) var<storage, read_write> out: array<vec4<f32>>;\n",
        Output::Store => "@group(0) @binding(0) var out: texture_storage_2d<rgba32float, write>;\n",
    };
    // The features at (XX, YY) as `let`s with suffix S.
    let load = |x: &str, y: &str, suffix: &str| -> String {
        let at = format!("vec2<i32>({x}, {y})");
        let mut l = format!(
            "let c{suffix} = textureLoad(t_color, {at}, 0);\nlet p{suffix} = textureLoad(t_position, {at}, 0);\n"
        );
        match layout {
            Layout::Four | Layout::Float16 => {
                l += &format!("let n{suffix} = textureLoad(t_normal, {at}, 0).xyz;\nlet a{suffix} = textureLoad(t_albedo, {at}, 0).xyz;\n");
            }
            Layout::ThreeSpread => {
                l += &format!("let aw{suffix} = textureLoad(t_albedo, {at}, 0);\nlet a{suffix} = aw{suffix}.xyz;\nlet n{suffix} = vec3<f32>(c{suffix}.w, p{suffix}.w, aw{suffix}.w);\n");
            }
            Layout::PackedHalves => {
                l += &format!("let q{suffix} = textureLoad(t_packed, {at}, 0);\nlet h0{suffix} = unpack2x16float(q{suffix}.x);\nlet h1{suffix} = unpack2x16float(q{suffix}.y);\nlet h2{suffix} = unpack2x16float(q{suffix}.z);\nlet n{suffix} = vec3<f32>(h0{suffix}, h1{suffix}.x);\nlet a{suffix} = vec3<f32>(h1{suffix}.y, h2{suffix});\n");
            }
        }
        l
    };
    s += "@compute @workgroup_size(8, 8, 1)\nfn main(@builtin(global_invocation_id) gid: vec3<u32>) {\n";
    s += &format!("let x = i32(gid.x);\nlet y = i32(gid.y);\nif (x >= {WIDTH} || y >= {HEIGHT}) {{ return; }}\n");
    s += &load("x", "y", "i");
    s += "var sw = 0.0;\nvar sc = vec3<f32>(0.0);\nfor (var dy = -1; dy <= 1; dy++) {\nfor (var dx = -1; dx <= 1; dx++) {\n";
    s += &format!("let xj = x + dx * 2;\nlet yj = y + dy * 2;\nif (xj < 0 || yj < 0 || xj >= {WIDTH} || yj >= {HEIGHT}) {{ continue; }}\n");
    s += &load("xj", "yj", "j");
    s += "let d = distance(ci.xyz, cj.xyz) * 4.0 + distance(pi.xyz, pj.xyz) * 10.0 + distance(ni, nj) + distance(ai, aj) * 3.0;\n";
    s += "let w = select(0.25, 0.5, dx == 0) * select(0.25, 0.5, dy == 0) * exp(-d);\nsw += w;\nsc += w * cj.xyz;\n}\n}\n";
    s += "let result = vec4<f32>(sc / max(sw, 1e-30), ci.w);\n";
    s += &match output {
        Output::BufferThenCopy => format!("out[u32(y) * {WIDTH}u + u32(x)] = result;\n"),
        Output::Store => "textureStore(out, vec2<i32>(x, y), result);\n".to_string(),
    };
    s += "}\n";
    s
}

fn main() {
    let (device, queue) = common::device(&format!("pass_layouts, {WIDTH}x{HEIGHT},"));
    let pixels = (WIDTH * HEIGHT) as usize;
    let value = |i: usize, k: usize| ((i * 7 + k * 13) % 101) as f32 / 101.0;
    let rgba: Vec<[f32; 4]> = (0..pixels).map(|i| [value(i, 0), value(i, 1), value(i, 2), value(i, 3)]).collect();
    let extent = wgpu::Extent3d { width: WIDTH, height: HEIGHT, depth_or_array_layers: 1 };
    let texture = |format: wgpu::TextureFormat, bytes: &[u8], texel: u32| {
        let usage =
            wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST | wgpu::TextureUsages::STORAGE_BINDING;
        let t = device.create_texture(&wgpu::TextureDescriptor {
            label: None,
            size: extent,
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage: if format == wgpu::TextureFormat::Rgba16Float {
                usage - wgpu::TextureUsages::STORAGE_BINDING
            } else {
                usage
            },
            view_formats: &[],
        });
        queue.write_texture(
            t.as_image_copy(),
            bytes,
            wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(texel * WIDTH), rows_per_image: Some(HEIGHT) },
            extent,
        );
        t
    };
    let f32x4 = |_k: usize| texture(wgpu::TextureFormat::Rgba32Float, bytemuck::cast_slice(&rgba), 16);
    let halves: Vec<u16> = rgba.iter().flat_map(|p| p.map(half_bits)).collect();
    let f16x4 = || texture(wgpu::TextureFormat::Rgba16Float, bytemuck::cast_slice(&halves), 8);
    let packed: Vec<[u32; 4]> = rgba
        .iter()
        .map(|p| {
            let h = p.map(half_bits).map(u32::from);
            [h[0] | h[1] << 16, h[2] | h[0] << 16, h[1] | h[2] << 16, 0]
        })
        .collect();
    let packed = texture(wgpu::TextureFormat::Rgba32Uint, bytemuck::cast_slice(&packed), 16);
    let color = f32x4(0);
    let position = f32x4(1);
    let normal = f32x4(2);
    let albedo = f32x4(3);
    let (normal16, albedo16) = (f16x4(), f16x4());
    let out_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: None,
        contents: bytemuck::cast_slice(&rgba),
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
    });
    let out_texture = f32x4(4);
    let next_texture = f32x4(5);
    for output in [Output::BufferThenCopy, Output::Store] {
        for layout in [Layout::Four, Layout::ThreeSpread, Layout::PackedHalves, Layout::Float16] {
            let pipeline = common::pipeline(&device, kernel(layout, output));
            let view = |t: &wgpu::Texture| t.create_view(&Default::default());
            let mut views = vec![view(&color), view(&position)];
            match layout {
                Layout::Four => views.extend([view(&normal), view(&albedo)]),
                Layout::Float16 => views.extend([view(&normal16), view(&albedo16)]),
                Layout::ThreeSpread => views.push(view(&albedo)),
                Layout::PackedHalves => views.push(view(&packed)),
            }
            let out_view = view(&out_texture);
            let mut entries = vec![wgpu::BindGroupEntry {
                binding: 0,
                resource: match output {
                    Output::BufferThenCopy => out_buffer.as_entire_binding(),
                    Output::Store => wgpu::BindingResource::TextureView(&out_view),
                },
            }];
            entries.extend(views.iter().enumerate().map(|(i, v)| wgpu::BindGroupEntry {
                binding: i as u32 + 1,
                resource: wgpu::BindingResource::TextureView(v),
            }));
            let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: None,
                layout: &pipeline.get_bind_group_layout(0),
                entries: &entries,
            });
            let median = common::median_ms(&device, &queue, 6, |encoder| {
                common::dispatch(encoder, &pipeline, &group, (WIDTH.div_ceil(8), HEIGHT.div_ceil(8)));
                if output == Output::BufferThenCopy {
                    encoder.copy_buffer_to_texture(
                        wgpu::TexelCopyBufferInfo {
                            buffer: &out_buffer,
                            layout: wgpu::TexelCopyBufferLayout {
                                offset: 0,
                                bytes_per_row: Some(16 * WIDTH),
                                rows_per_image: Some(HEIGHT),
                            },
                        },
                        next_texture.as_image_copy(),
                        extent,
                    );
                }
            });
            println!("{median:8.1} ms  {layout:?}, {output:?}");
        }
    }
}

/// An f32's nearest half, its bits.
fn half_bits(v: f32) -> u16 {
    half::f16::from_f32(v).to_bits()
}
