//! The path tracer's data as the GPU reads it (std430 layouts of
//! `templates/pathtrace.wgsl`).

use super::description::{Description, Geometry};

/// f32 sums per pixel a trace dispatch returns: 19 values (colour, albedo,
/// position, normal, secondary albedo, depth, visibility, motion x and y),
/// then their squares.
pub const SUMS_PER_PIXEL: usize = 38;
/// Values per sample, in the order above.
pub const VALUES_PER_SAMPLE: usize = 19;

#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GpuPrim {
    pub info: [u32; 4],
    pub a: [f32; 4],
    pub u: [f32; 4],
    pub v: [f32; 4],
    pub n: [f32; 4],
    pub emission: [f32; 4],
    /// How far the shape moved since the frame before.
    pub step: [f32; 4],
}

#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GpuMaterial {
    pub info: [u32; 4],
    pub albedo: [f32; 4],
    pub albedo2: [f32; 4],
}

#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct TraceParams {
    pub width: u32,
    pub height: u32,
    pub sample_offset: u32,
    pub sample_count: u32,
    pub seed: u32,
    pub with_features: u32,
    pub max_depth: u32,
    pub light_count: u32,
    pub prim_count: u32,
    pub row_offset: u32,
    /// 1: write motion vectors against the frame before's camera.
    pub with_motion: u32,
    pub pad: u32,
    pub environment: [f32; 4],
    pub cam_pos: [f32; 4],
    pub cam_forward: [f32; 4],
    pub cam_right: [f32; 4],
    pub cam_up: [f32; 4],
    pub prev_pos: [f32; 4],
    pub prev_forward: [f32; 4],
    pub prev_right: [f32; 4],
    pub prev_up: [f32; 4],
}

pub struct PackedScene {
    pub prims: Vec<GpuPrim>,
    pub materials: Vec<GpuMaterial>,
    pub lights: Vec<u32>,
}

impl PackedScene {
    /// The tracer's buffers, as bytes.
    pub fn inputs(&self) -> crate::gpu::TraceInputs<'_> {
        crate::gpu::TraceInputs {
            prims: bytemuck::cast_slice(&self.prims),
            materials: bytemuck::cast_slice(&self.materials),
            lights: bytemuck::cast_slice(&self.lights),
        }
    }
}

fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

fn length(a: [f32; 3]) -> f32 {
    (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt()
}

fn scale(a: [f32; 3], s: f32) -> [f32; 3] {
    a.map(|c| c * s)
}

fn four(a: [f32; 3], w: f32) -> [f32; 4] {
    [a[0], a[1], a[2], w]
}

pub fn pack(d: &Description) -> PackedScene {
    let mut prims = Vec::new();
    let mut lights = Vec::new();
    for p in &d.primitives {
        let emission = p.emission.unwrap_or([0.0; 3]);
        let emitter = p.emission.is_some_and(|e| e.iter().any(|c| *c > 0.0));
        let prim = match p.geometry {
            Geometry::Parallelogram { origin, u, v } => {
                let n = cross(u, v);
                let area = length(n);
                GpuPrim {
                    info: [0, p.material as u32, emitter as u32, 0],
                    a: four(origin, area),
                    u: four(u, 0.0),
                    v: four(v, 0.0),
                    n: four(scale(n, 1.0 / area), 1.0 / area),
                    emission: four(emission, 0.0),
                    step: four(p.step, 0.0),
                }
            }
            Geometry::Sphere { center, radius } => {
                let area = 4.0 * std::f32::consts::PI * radius * radius;
                GpuPrim {
                    info: [1, p.material as u32, emitter as u32, 0],
                    a: four(center, radius),
                    u: [0.0; 4],
                    v: [0.0; 4],
                    n: [0.0, 0.0, 0.0, 1.0 / area],
                    emission: four(emission, 0.0),
                    step: four(p.step, 0.0),
                }
            }
        };
        if emitter {
            lights.push(prims.len() as u32);
        }
        prims.push(prim);
    }
    let materials = d
        .materials
        .iter()
        .map(|m| GpuMaterial {
            info: [m.kind as u32, m.texture, 0, 0],
            albedo: four(m.albedo, m.parameter),
            albedo2: four(m.second, m.frequency),
        })
        .collect();
    PackedScene { prims, materials, lights }
}

/// Camera vectors: forward, and right/up scaled by the image plane's half extents.
pub fn camera(d: &Description, width: u32, height: u32) -> ([f32; 4], [f32; 4], [f32; 4], [f32; 4]) {
    let c = &d.camera;
    let f = [c.look_at[0] - c.position[0], c.look_at[1] - c.position[1], c.look_at[2] - c.position[2]];
    let forward = scale(f, 1.0 / length(f));
    let right = cross(forward, c.up);
    let right = scale(right, 1.0 / length(right));
    let up = cross(right, forward);
    let half = (c.fov_degrees.to_radians() / 2.0).tan();
    let (hx, hy) = if width >= height {
        (half * width as f32 / height as f32, half)
    } else {
        (half, half * height as f32 / width as f32)
    };
    (four(c.position, 0.0), four(forward, 0.0), four(scale(right, hx), 0.0), four(scale(up, hy), 0.0))
}
