//! Every compute pass of a submission on the device's clock, by kernel, where
//! a caller turns profiling on ([`Gpu::set_profiling`]; `filterjit bench
//! --frames … --profile`). A frame's stage times ([`super::Span`]) say which
//! stage costs most; this says which dispatch inside it, so that GPU work is
//! profiled rather than guessed. Each pass writes a timestamp as it begins and
//! one as it ends (wgpu's `TIMESTAMP_QUERY`), and so does each copy of an
//! image into a texture where the device can write timestamps between
//! commands; what a frame's time holds beyond them is the rest of its
//! copies and wgpu's clears of images not yet written.

use std::time::Duration;

use super::{Gpu, GpuError};

/// Passes timed per submission; later ones in the same submission run untimed
/// (and are counted as such).
const CAPACITY: u32 = 1024;

/// The device's clock around each compute pass of the submissions recorded
/// while profiling is on.
pub(crate) struct PassProfile {
    set: wgpu::QuerySet,
    resolved: wgpu::Buffer,
    staging: wgpu::Buffer,
    /// The passes recorded since the last resolve, in the order their timestamps were written.
    pending: Vec<String>,
    /// Passes recorded beyond [`CAPACITY`] since the last resolve.
    untimed: usize,
    /// Whether `staging` holds timestamps of `pending` to read once the submission is done.
    resolved_pending: bool,
    collected: Vec<TimedPass>,
}

/// One compute pass and its time on the device's clock (`None`: recorded
/// past the capacity of its submission, not timed).
#[derive(Clone, Debug, PartialEq)]
pub struct TimedPass {
    pub kernel: String,
    pub device: Option<Duration>,
}

impl PassProfile {
    /// The next pair of timestamps for `kernel`, or none (counted as
    /// untimed) where the submission has used them all.
    fn slot(&mut self, kernel: impl std::fmt::Display) -> Option<u32> {
        let index = self.pending.len() as u32;
        if index >= CAPACITY {
            self.untimed += 1;
            return None;
        }
        self.pending.push(kernel.to_string());
        Some(index)
    }
}

impl Gpu {
    /// Time every compute pass from now on (`true`), or stop and drop what was
    /// collected (`false`). Without a device clock nothing is timed.
    pub fn set_profiling(&self, on: bool) {
        let mut profile = self.profile.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        if !on || !self.device.features().contains(wgpu::Features::TIMESTAMP_QUERY) {
            *profile = None;
            return;
        }
        if profile.is_some() {
            return;
        }
        let bytes = u64::from(CAPACITY) * 2 * 8;
        let buffer = |label, usage| {
            self.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: bytes,
                usage,
                mapped_at_creation: false,
            })
        };
        *profile = Some(PassProfile {
            set: self.device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("pass profile"),
                ty: wgpu::QueryType::Timestamp,
                count: CAPACITY * 2,
            }),
            resolved: buffer("pass profile resolved", wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC),
            staging: buffer("pass profile readback", wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST),
            pending: Vec::new(),
            untimed: 0,
            resolved_pending: false,
            collected: Vec::new(),
        });
    }

    /// The passes timed since profiling was turned on or last taken, in the
    /// order they ran.
    pub fn take_profile(&self) -> Vec<TimedPass> {
        let mut profile = self.profile.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        profile.as_mut().map(|p| std::mem::take(&mut p.collected)).unwrap_or_default()
    }

    /// Begin a compute pass of `kernel` in `encoder`: every pass of a
    /// frame starts here, timed where profiling is on. `kernel` is written
    /// out only then: a frame's passes allocate nothing for it.
    pub(super) fn compute_pass<'e>(
        &self,
        encoder: &'e mut wgpu::CommandEncoder,
        kernel: impl std::fmt::Display,
    ) -> wgpu::ComputePass<'e> {
        let mut profile = self.profile.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        let timed = profile.as_mut().and_then(|p| Some((p.slot(kernel)?, &p.set)));
        encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: None,
            timestamp_writes: timed.map(|(index, set)| wgpu::ComputePassTimestampWrites {
                query_set: set,
                beginning_of_pass_write_index: Some(2 * index),
                end_of_pass_write_index: Some(2 * index + 1),
            }),
        })
    }

    /// Record commands other than a compute pass (a copy) with `record`,
    /// timed as `kernel` where profiling is on and the device can write
    /// timestamps between commands.
    pub(super) fn profiled<T>(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        kernel: &str,
        record: impl FnOnce(&mut wgpu::CommandEncoder) -> T,
    ) -> T {
        let slot = {
            let mut profile = self.profile.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
            match profile.as_mut() {
                Some(p) if self.device.features().contains(super::clock::CLOCK_FEATURES) => {
                    p.slot(kernel).map(|index| (p.set.clone(), index))
                }
                _ => None,
            }
        };
        if let Some((set, index)) = &slot {
            encoder.write_timestamp(set, 2 * index);
        }
        let recorded = record(encoder);
        if let Some((set, index)) = &slot {
            encoder.write_timestamp(set, 2 * index + 1);
        }
        recorded
    }

    /// Before `encoder` is finished: resolve its passes' timestamps into a
    /// buffer [`Gpu::collect_profile`] reads once the submission is done.
    pub(super) fn resolve_profile(&self, encoder: &mut wgpu::CommandEncoder) {
        let mut profile = self.profile.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        let Some(profile) = profile.as_mut() else { return };
        let count = profile.pending.len() as u32 * 2;
        if count == 0 {
            return;
        }
        encoder.resolve_query_set(&profile.set, 0..count, &profile.resolved, 0);
        encoder.copy_buffer_to_buffer(&profile.resolved, 0, &profile.staging, 0, u64::from(count) * 8);
        profile.resolved_pending = true;
    }

    /// After the submission [`Gpu::resolve_profile`] was recorded in is done:
    /// its passes' times join the collected ones.
    pub(super) fn collect_profile(&self) -> Result<(), GpuError> {
        let mut guard = self.profile.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        let Some(profile) = guard.as_mut() else { return Ok(()) };
        if !profile.resolved_pending {
            return Ok(());
        }
        profile.resolved_pending = false;
        let bytes = self.read(&profile.staging)?;
        let period = f64::from(self.queue().get_timestamp_period());
        let ticks: Vec<u64> = bytemuck::pod_collect_to_vec(&bytes[..profile.pending.len() * 16]);
        for (kernel, pair) in profile.pending.drain(..).zip(ticks.chunks_exact(2)) {
            let nanoseconds = pair[1].saturating_sub(pair[0]) as f64 * period;
            profile.collected.push(TimedPass { kernel, device: Some(Duration::from_secs_f64(nanoseconds * 1e-9)) });
        }
        for _ in 0..std::mem::take(&mut profile.untimed) {
            profile.collected.push(TimedPass { kernel: "(untimed: past the profile's capacity)".into(), device: None });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::SceneBuffers;
    use crate::scene::Scene;

    /// A profiled frame names each of its passes in the order they ran, and
    /// where the device has a clock their times are positive and add up to
    /// no more than the frame's; unprofiled frames record nothing.
    #[test]
    fn a_profiled_frame_times_each_pass_inside_the_frame() {
        let environment = crate::environment::Environment::read().expect("FILTERJIT_BACKEND names a backend");
        let gpu = Gpu::open(&environment.adapter).expect("an adapter");
        let (width, height) = (40, 32);
        let color = (0..width * height).map(|i| [(i as f32 * 0.3).sin().abs(), 0.5, (i % 5) as f32 * 0.2]).collect();
        let scene = Scene::from_color("profile", width, height, color);
        let pipeline: crate::pipeline::FilterPipeline = "outliers=2,keep,atrous=2".parse().unwrap();
        let expr = crate::lang::parse_expr("exp(-distance2(color))").unwrap();
        let spec = crate::jit::KernelSpec { shape: crate::jit::Shape::of(&pipeline), ..Default::default() };
        let kernel = crate::jit::compile(&expr, spec).unwrap();
        let frame = |gpu: &Gpu| {
            let mut buffers = SceneBuffers::for_frame(gpu, &scene, &pipeline).unwrap();
            gpu.filter(&kernel, &mut buffers, &scene, 2).unwrap()
        };
        frame(&gpu);
        assert!(gpu.take_profile().is_empty(), "profiling is off until asked for");

        gpu.set_profiling(true);
        let filtered = frame(&gpu);
        let passes = gpu.take_profile();
        gpu.set_profiling(false);
        if !gpu.device.features().contains(wgpu::Features::TIMESTAMP_QUERY) {
            assert!(passes.is_empty(), "a device without a clock times nothing");
            return;
        }
        // A row of 40 texels is not the 256-byte multiple a copy into a
        // texture needs: those images are blitted, each pass of it timed too.
        let (blits, kernels): (Vec<&str>, Vec<&str>) =
            passes.iter().map(|p| p.kernel.as_str()).partition(|k| *k == "blit to a texture");
        assert!(!blits.is_empty(), "{passes:?}");
        let spread: Vec<String> =
            (0..crate::pipeline::KEEP_PASSES).map(|k| format!("pre-pass: keep spread, step {}", 1 << k)).collect();
        let expected: Vec<&str> = std::iter::once("pre-pass")
            .chain(spread.iter().map(String::as_str))
            .chain(["form: à-trous pass 0", "form: à-trous pass 1"])
            .collect();
        assert_eq!(kernels, expected);
        let sum: Duration = passes.iter().map(|p| p.device.expect("timed")).sum();
        assert!(passes.iter().all(|p| p.device.unwrap() > Duration::ZERO), "{passes:?}");
        if let Some(whole) = filtered.time.device {
            assert!(sum <= whole, "the passes' {sum:?} exceed the frame's {whole:?}");
        }
        frame(&gpu);
        assert!(gpu.take_profile().is_empty(), "profiling was turned off");
    }
}
