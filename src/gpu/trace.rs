//! The path tracer on the device: `templates/pathtrace.wgsl`, validated by
//! naga, one pipeline per device; dispatches return per-pixel sums.

use std::sync::OnceLock;

use wgpu::util::DeviceExt;

use super::{Gpu, GpuError, Pipeline};
use crate::jit::interface::own_params;
use crate::jit::ValidatedModule;
use crate::render::packed::{PackedScene, TraceParams, SUMS_PER_PIXEL};

/// The path tracer's source.
pub const PATHTRACE_WGSL: &str = include_str!("../../templates/pathtrace.wgsl");

/// The tracer's WGSL, parsed and validated once.
fn module() -> Result<&'static ValidatedModule, GpuError> {
    static MODULE: OnceLock<Result<ValidatedModule, String>> = OnceLock::new();
    MODULE
        .get_or_init(|| crate::jit::validate_module(PATHTRACE_WGSL, "<path tracer>").map_err(|e| e.to_string()))
        .as_ref()
        .map_err(|message| GpuError::Pipeline {
            expression: "<path tracer>".into(),
            message: message.clone(),
            wgsl: String::new(),
        })
}

/// A scene uploaded for tracing.
pub struct TraceScene {
    prims: wgpu::Buffer,
    materials: wgpu::Buffer,
    lights: wgpu::Buffer,
}

impl Gpu {
    fn trace_pipeline(&self) -> Result<&Pipeline, GpuError> {
        if let Some(p) = self.tracer.get() {
            return Ok(p);
        }
        let pipeline = self.create_pipeline(module()?, "filterjit path tracer").map_err(|message| {
            GpuError::Pipeline { expression: "<path tracer>".into(), message, wgsl: String::new() }
        })?;
        Ok(self.tracer.get_or_init(|| pipeline))
    }

    /// Upload a packed scene.
    pub fn upload_trace_scene(&self, scene: &PackedScene) -> TraceScene {
        let storage = |label, bytes: &[u8]| {
            self.device().create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: bytes,
                usage: wgpu::BufferUsages::STORAGE,
            })
        };
        // Empty storage buffers are not allowed: keep at least one element.
        let lights: Vec<u32> = if scene.lights.is_empty() { vec![0] } else { scene.lights.clone() };
        TraceScene {
            prims: storage("prims", bytemuck::cast_slice(&scene.prims)),
            materials: storage("materials", bytemuck::cast_slice(&scene.materials)),
            lights: storage("lights", bytemuck::cast_slice(&lights)),
        }
    }

    /// Trace `params.sample_count` samples for rows `params.row_offset ..
    /// + rows`; returns `SUMS_PER_PIXEL` sums per pixel of those rows.
    pub fn trace(&self, scene: &TraceScene, params: &TraceParams, rows: u32) -> Result<Vec<f32>, GpuError> {
        let pipeline = self.trace_pipeline()?;
        let _turn = self.gl_turn();
        let device = self.device();
        let pixels = (params.width * params.height) as u64;
        let size = pixels * SUMS_PER_PIXEL as u64 * 4;
        let sums = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("sums"),
            size,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let first = params.row_offset as u64 * params.width as u64 * SUMS_PER_PIXEL as u64 * 4;
        let band = rows as u64 * params.width as u64 * SUMS_PER_PIXEL as u64 * 4;
        let staging = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("sums readback"),
            size: band,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let uniform = self.params_buffer(own_params(), "trace params", bytemuck::bytes_of(params));
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        // pathtrace.wgsl declares params, prims, materials, lights, sums in this order.
        let resources = [&uniform, &scene.prims, &scene.materials, &scene.lights, &sums];
        let bind_group = self.bind_in_slot_order(pipeline, resources.iter().map(|b| b.as_entire_binding()).collect());
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        {
            let mut pass =
                encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: None, timestamp_writes: None });
            pass.set_pipeline(&pipeline.pipeline);
            pass.set_bind_group(0, &bind_group, &[]);
            pass.dispatch_workgroups(params.width.div_ceil(8), rows.div_ceil(8), 1);
        }
        encoder.copy_buffer_to_buffer(&sums, first, &staging, 0, band);
        let bytes = self.finish_and_read(encoder, scope, "path tracing", &staging)?;
        Ok(bytemuck::pod_collect_to_vec(&bytes))
    }
}
