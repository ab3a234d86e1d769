//! The path tracer on the device: `templates/pathtrace.wgsl`, validated by
//! naga, one pipeline per device; dispatches return per-pixel sums.

use std::sync::Arc;

use wgpu::util::DeviceExt;

use super::{Gpu, GpuError, Pipeline};
use crate::jit::interface::own_params;
use crate::jit::BuiltIn;

/// A scene's buffers as the tracer reads them, laid out by the renderer
/// (`render::packed`): the device knows their bindings, not their format.
pub struct TraceInputs<'a> {
    pub prims: &'a [u8],
    pub materials: &'a [u8],
    /// May be empty (a scene lit by its environment only).
    pub lights: &'a [u8],
}

/// One band of rows to trace.
#[derive(Clone, Copy, Debug)]
pub struct TraceBand {
    /// The image's size, as the tracer's parameters also say.
    pub width: u32,
    pub height: u32,
    /// The first row, as the tracer's parameters also say.
    pub row_offset: u32,
    pub rows: u32,
    /// The `f32` sums the tracer writes per pixel.
    pub sums_per_pixel: usize,
}

/// A scene uploaded for tracing.
pub struct TraceScene {
    prims: wgpu::Buffer,
    materials: wgpu::Buffer,
    lights: wgpu::Buffer,
}

impl Gpu {
    fn trace_pipeline(&self) -> Result<Arc<Pipeline>, GpuError> {
        self.built_in(BuiltIn::PathTracer, 0)
    }

    /// Upload a scene's tracer buffers.
    pub fn upload_trace_scene(&self, scene: &TraceInputs<'_>) -> TraceScene {
        let storage = |label, bytes: &[u8]| {
            self.device().create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: bytes,
                usage: wgpu::BufferUsages::STORAGE,
            })
        };
        // Empty storage buffers are not allowed: keep at least one element.
        let lights: &[u8] = if scene.lights.is_empty() { &[0; 4] } else { scene.lights };
        TraceScene {
            prims: storage("prims", scene.prims),
            materials: storage("materials", scene.materials),
            lights: storage("lights", lights),
        }
    }

    /// Trace the band's rows with the tracer's parameters `params` (its
    /// uniform's bytes); returns `band.sums_per_pixel` sums per pixel of those rows.
    pub fn trace(&self, scene: &TraceScene, params: &[u8], band: TraceBand) -> Result<Vec<f32>, GpuError> {
        let pipeline = self.trace_pipeline()?;
        let _turn = self.gl_turn();
        let device = self.device();
        let TraceBand { width, height, row_offset, rows, sums_per_pixel } = band;
        debug_assert!(row_offset + rows <= height, "a band inside the image");
        let row_bytes = width as u64 * sums_per_pixel as u64 * 4;
        // The tracer writes the band's rows from the buffer's start.
        let band = rows as u64 * row_bytes;
        let sums = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("sums"),
            size: band,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let staging = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("sums readback"),
            size: band,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let uniform = self.params_buffer(own_params(), "trace params", params);
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        // pathtrace.wgsl declares params, prims, materials, lights, sums in this order.
        let resources = [&uniform, &scene.prims, &scene.materials, &scene.lights, &sums];
        let bind_group = self.bind_in_slot_order(&pipeline, resources.iter().map(|b| b.as_entire_binding()).collect());
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        {
            let mut pass = self.compute_pass(&mut encoder, "trace");
            pass.set_pipeline(&pipeline.pipeline);
            pass.set_bind_group(0, &bind_group, &[]);
            pass.dispatch_workgroups(width.div_ceil(8), rows.div_ceil(8), 1);
        }
        encoder.copy_buffer_to_buffer(&sums, 0, &staging, 0, band);
        let bytes = self.finish_and_read(encoder, scope, "path tracing", &staging)?;
        Ok(bytemuck::pod_collect_to_vec(&bytes))
    }
}
