//! The device's own clock: timestamps the GPU writes at the start and at the
//! end of a command buffer, where the adapter offers them (wgpu's
//! `TIMESTAMP_QUERY` with `TIMESTAMP_QUERY_INSIDE_ENCODERS`). On a hardware
//! GPU a small dispatch's wall time is mostly the submit–wait round trip
//! (about 0.2 ms on an NVIDIA H200 whatever the kernel, docs/JOURNAL.md,
//! "On a GPU"); the device's clock measures the work itself, so kernels
//! compare by what they cost rather than by that floor.

use std::time::Duration;

use super::{Gpu, GpuError};

/// How long a stage of a frame took: by wall time, from recording its
/// commands until the device was done, and on the device's own clock where it
/// has one (the GPU's work without the submit–wait round trip).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Span {
    pub wall: Duration,
    pub device: Option<Duration>,
}

/// What the device must offer for a [`Stopwatch`] to time anything.
pub(super) const CLOCK_FEATURES: wgpu::Features =
    wgpu::Features::TIMESTAMP_QUERY.union(wgpu::Features::TIMESTAMP_QUERY_INSIDE_ENCODERS);

/// The device's clock around the commands recorded between
/// [`Stopwatch::start`] and [`Stopwatch::stop`] in one encoder; on a device
/// without one it records nothing and reads `None`.
pub(crate) struct Stopwatch(Option<Timestamps>);

/// Two timestamps and what reads them back.
pub(crate) struct Timestamps {
    set: wgpu::QuerySet,
    resolved: wgpu::Buffer,
    staging: wgpu::Buffer,
}

impl Gpu {
    /// Whether this device has its own clock ([`Filtered::time`](super::Filtered::time)).
    pub fn has_device_clock(&self) -> bool {
        self.device.features().contains(CLOCK_FEATURES)
    }

    /// A stopwatch on the device's clock: used timestamps where some are free
    /// ([`Stopwatch::read`] hands them back), so that timing a frame
    /// allocates nothing on the device.
    pub(super) fn stopwatch(&self) -> Stopwatch {
        if !self.has_device_clock() {
            return Stopwatch(None);
        }
        if let Some(free) = self.stopwatches.lock().unwrap_or_else(|poisoned| poisoned.into_inner()).pop() {
            return Stopwatch(Some(free));
        }
        let buffer = |label, usage| {
            self.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: 16,
                usage,
                mapped_at_creation: false,
            })
        };
        Stopwatch(Some(Timestamps {
            set: self.device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("stopwatch"),
                ty: wgpu::QueryType::Timestamp,
                count: 2,
            }),
            resolved: buffer("stopwatch resolved", wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC),
            staging: buffer("stopwatch readback", wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST),
        }))
    }
}

impl Gpu {
    /// Record commands with `record` into an encoder of their own, submit them
    /// and wait: what `record` returned, and the time from recording until the
    /// device was done, by wall and on the device's clock. A validation error
    /// in them, or a failed wait, is an error `during` that work. Callers hold the GL turn.
    pub(super) fn timed_submission<T>(
        &self,
        during: &'static str,
        record: impl FnOnce(&mut wgpu::CommandEncoder) -> Result<T, GpuError>,
    ) -> Result<(T, Span), GpuError> {
        let scope = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let stopwatch = self.stopwatch();
        let start = std::time::Instant::now();
        let mut encoder = self.device.create_command_encoder(&Default::default());
        stopwatch.start(&mut encoder);
        let recorded = record(&mut encoder)?;
        stopwatch.stop(&mut encoder);
        self.resolve_profile(&mut encoder);
        self.queue().submit([encoder.finish()]);
        self.wait(during)?;
        self.collect_profile()?;
        let wall = start.elapsed();
        if let Some(error) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Runtime { during, message: error.to_string() });
        }
        Ok((recorded, Span { wall, device: stopwatch.read(self)? }))
    }
}

impl Stopwatch {
    /// Record the first timestamp: before every later command of `encoder`.
    pub fn start(&self, encoder: &mut wgpu::CommandEncoder) {
        if let Some(t) = &self.0 {
            encoder.write_timestamp(&t.set, 0);
        }
    }

    /// Record the second timestamp and what makes both readable.
    pub fn stop(&self, encoder: &mut wgpu::CommandEncoder) {
        if let Some(t) = &self.0 {
            encoder.write_timestamp(&t.set, 1);
            encoder.resolve_query_set(&t.set, 0..2, &t.resolved, 0);
            encoder.copy_buffer_to_buffer(&t.resolved, 0, &t.staging, 0, 16);
        }
    }

    /// The time between the two once the encoder's submission is done
    /// (`None` without a clock); the timestamps go back to `gpu`'s free ones.
    pub fn read(self, gpu: &Gpu) -> Result<Option<Duration>, GpuError> {
        let Some(t) = self.0 else { return Ok(None) };
        let bytes = gpu.read(&t.staging)?;
        let ticks: [u64; 2] = bytemuck::pod_read_unaligned(&bytes[..16]);
        let nanoseconds = ticks[1].saturating_sub(ticks[0]) as f64 * f64::from(gpu.queue().get_timestamp_period());
        gpu.stopwatches.lock().unwrap_or_else(|poisoned| poisoned.into_inner()).push(t);
        Ok(Some(Duration::from_secs_f64(nanoseconds * 1e-9)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::SceneBuffers;
    use crate::scene::Scene;

    /// Where the device has a clock, a frame's time on it is positive and
    /// lies inside the frame's wall time; elsewhere there is none.
    #[test]
    fn the_device_clock_times_the_work_inside_its_wall_time() {
        // On the adapter the tests run on, read at the edge as `tests/common` reads it.
        let environment = crate::environment::Environment::read().expect("FILTERJIT_BACKEND names a backend");
        let gpu = Gpu::open(&environment.adapter).expect("an adapter");
        let (width, height) = (48, 40);
        let color = (0..width * height).map(|i| [(i as f32 * 0.1).sin().abs(), 0.5, (i % 7) as f32 * 0.1]).collect();
        let scene = Scene::from_color("clock", width, height, color);
        let expr = crate::lang::parse_expr("exp(-distance2(color) / (1 + sqrt(distance2(pixel))))").unwrap();
        let kernel = crate::jit::compile(&expr, crate::jit::KernelSpec::default()).unwrap();
        let mut buffers = SceneBuffers::new(&gpu, &scene);
        let within = |span: Span| {
            assert_eq!(span.device.is_some(), gpu.has_device_clock());
            if let Some(device) = span.device {
                assert!(device > Duration::ZERO, "the device's clock did not move");
                assert!(device <= span.wall, "device {device:?} longer than the wall time {:?}", span.wall);
            }
        };
        for _ in 0..3 {
            let frame = gpu.filter(&kernel, &mut buffers, &scene, 4).unwrap();
            eprintln!("on {}: wall {:?}, device {:?}", gpu.describe(), frame.time.wall, frame.time.device);
            within(frame.time);
            assert_eq!(frame.kernel_time(), frame.time.device.unwrap_or(frame.time.wall));
        }
        // The pre-pass (with `keep`'s spread) is timed on both clocks too.
        let pipeline: crate::pipeline::FilterPipeline = "outliers=2,keep,atrous=2".parse().unwrap();
        let prepared = SceneBuffers::for_pipeline(&gpu, &scene, &pipeline).unwrap();
        within(prepared.prepass_time().expect("a pipeline with a pre-pass times it"));
    }
}
