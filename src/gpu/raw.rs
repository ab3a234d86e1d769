//! Dispatch of a WGSL module that is not a filterjit kernel (the benchmark's
//! stack interpreter). naga validates it first, like every module.

use std::time::{Duration, Instant};

use wgpu::util::DeviceExt;

use super::{Gpu, GpuError, Pipeline};
use crate::jit::interface::own_params;

/// A validated, compiled WGSL module with entry point `main`.
pub struct RawKernel {
    pipeline: Pipeline,
}

/// One binding of a raw dispatch, in slot order after the uniform (the module's first binding).
pub enum RawBuffer<'a> {
    Read(&'a [u8]),
    /// A zeroed read-write buffer of this many bytes, read back after the dispatch.
    Write(u64),
}

impl Gpu {
    pub fn raw_kernel(&self, wgsl: &str) -> Result<RawKernel, GpuError> {
        let invalid =
            |message: String| GpuError::Pipeline { expression: "<raw kernel>".into(), message, wgsl: wgsl.to_string() };
        let validated = crate::jit::validate_module(wgsl, "<raw kernel>").map_err(|e| invalid(e.to_string()))?;
        let pipeline = self.create_pipeline(&validated, "raw").map_err(invalid)?;
        Ok(RawKernel { pipeline })
    }

    /// One dispatch of `groups` workgroups; returns its time (on the
    /// device's clock where it has one, as [`Filtered::kernel_time`](super::Filtered::kernel_time),
    /// else wall time from submission to completion) and the contents of the
    /// `Write` buffers.
    pub fn run_raw(
        &self,
        kernel: &RawKernel,
        uniform: &[u8],
        buffers: &[RawBuffer<'_>],
        groups: (u32, u32),
    ) -> Result<(Duration, Vec<Vec<u8>>), GpuError> {
        let _turn = self.gl_turn();
        let device = self.device();
        let uniform = self.params_buffer(own_params(), "raw params", uniform);
        let made: Vec<(wgpu::Buffer, Option<u64>)> = buffers
            .iter()
            .map(|b| match b {
                RawBuffer::Read(data) => (
                    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                        label: None,
                        contents: data,
                        usage: wgpu::BufferUsages::STORAGE,
                    }),
                    None,
                ),
                RawBuffer::Write(size) => (
                    device.create_buffer(&wgpu::BufferDescriptor {
                        label: None,
                        size: *size,
                        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                        mapped_at_creation: false,
                    }),
                    Some(*size),
                ),
            })
            .collect();
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let resources = std::iter::once(uniform.as_entire_binding())
            .chain(made.iter().map(|(buffer, _)| buffer.as_entire_binding()))
            .collect();
        let bind_group = self.bind_in_slot_order(&kernel.pipeline, resources);
        let stopwatch = self.stopwatch();
        let mut encoder = device.create_command_encoder(&Default::default());
        stopwatch.start(&mut encoder);
        {
            let mut pass = self.compute_pass(&mut encoder, "raw kernel");
            pass.set_pipeline(&kernel.pipeline.pipeline);
            pass.set_bind_group(0, &bind_group, &[]);
            pass.dispatch_workgroups(groups.0, groups.1, 1);
        }
        stopwatch.stop(&mut encoder);
        let start = Instant::now();
        self.queue().submit([encoder.finish()]);
        self.wait("running a raw kernel")?;
        let wall = start.elapsed();
        let elapsed = stopwatch.read(self)?.unwrap_or(wall);
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Runtime { during: "running a raw kernel", message: e.to_string() });
        }
        let mut outputs = Vec::new();
        for (buffer, size) in &made {
            let Some(size) = size else { continue };
            let staging = device.create_buffer(&wgpu::BufferDescriptor {
                label: None,
                size: *size,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            let mut encoder = device.create_command_encoder(&Default::default());
            encoder.copy_buffer_to_buffer(buffer, 0, &staging, 0, *size);
            self.queue().submit([encoder.finish()]);
            outputs.push(self.read(&staging)?);
        }
        Ok((elapsed, outputs))
    }
}
