//! How every figure is taken: medians over repeats with their spread, and
//! kernels timed in interleaved rounds.

use std::time::Duration;

use serde::Serialize;

use crate::gpu::{Gpu, SceneBuffers};
use crate::jit;
use crate::scene::Scene;

#[derive(Clone, Debug, Serialize)]
pub struct Stat {
    pub median: f64,
    pub min: f64,
    pub max: f64,
}

pub(super) fn stat(mut v: Vec<f64>) -> Stat {
    v.sort_by(f64::total_cmp);
    Stat { median: v[v.len() / 2], min: v[0], max: v[v.len() - 1] }
}

pub(super) fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

/// Warm times of several kernels measured in rounds (one dispatch of each per
/// round), so that a shared machine's drifting load falls on all of them alike.
pub(super) fn interleaved(
    gpu: &Gpu,
    kernels: &[&jit::ValidatedKernel],
    buffers: &mut SceneBuffers,
    scene: &Scene,
    radius: u32,
    repeats: usize,
) -> anyhow::Result<Vec<Stat>> {
    let mut times = vec![Vec::new(); kernels.len()];
    for _ in 0..repeats.max(1) {
        for (k, kernel) in kernels.iter().enumerate() {
            times[k].push(ms(gpu.filter(kernel, buffers, scene, radius)?.kernel_time()));
        }
    }
    Ok(times.into_iter().map(stat).collect())
}
