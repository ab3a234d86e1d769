//! Bloated expressions, as GP leaves them, against their simplified forms.

use serde::Serialize;

use super::timing::{interleaved, Stat};
use super::BenchSettings;
use crate::gpu::{Gpu, SceneBuffers};
use crate::jit;
use crate::lang::parse_expr;
use crate::scene::Scene;

/// A bloated expression against its simplified form.
#[derive(Clone, Debug, Serialize)]
pub struct SimplifiedResult {
    pub raw: String,
    pub simplified: String,
    pub raw_length: usize,
    pub simplified_length: usize,
    pub raw_ms: Stat,
    pub simplified_ms: Stat,
    /// simplified / raw, median warm times.
    pub ratio: f64,
}

/// Expressions as GP leaves them (the first is the default run's best of an
/// earlier version, from the simplification issue).
pub const BLOATED: &[&str] = &[
    "exp(-(pow(distance1(pixel), 2) / (exp(-(pow(distance2(texture), 2) + pow(distance1(normal, color), distance2(dovGradient, color)) / 1)) * pow(3, 2)) + pow(3, 2) / 1))",
    "exp(-(distance2(normal) / 1 + pow(pow(3, 2), 1) * distance2(color) / (2 + 2))) * (1 + 0 * dot(texture))",
    "exp(-(pow(distance2(pixel), 2) / (2 * pow(3, 2)) + pow(distance2(color), 2) / (2 * pow(0.5, 2)))) / 1",
];

pub(super) fn measure(
    gpu: &Gpu,
    scene: &Scene,
    buffers: &mut SceneBuffers,
    settings: &BenchSettings,
) -> anyhow::Result<Vec<SimplifiedResult>> {
    let mut simplified = Vec::new();
    for text in BLOATED {
        let raw = parse_expr(text)?;
        let simple = crate::simplify::simplify(&raw);
        let kernels =
            [jit::compile(&raw, jit::KernelSpec::default())?, jit::compile(&simple, jit::KernelSpec::default())?];
        let refs: Vec<&jit::ValidatedKernel> = kernels.iter().collect();
        for k in &refs {
            gpu.filter(k, buffers, scene, settings.radius)?;
        }
        let [raw_ms, simplified_ms]: [Stat; 2] =
            interleaved(gpu, &refs, buffers, scene, settings.radius, settings.repeats * 2)?
                .try_into()
                .expect("two kernels");
        simplified.push(SimplifiedResult {
            raw: raw.to_string(),
            simplified: simple.to_string(),
            raw_length: raw.len(),
            simplified_length: simple.len(),
            ratio: simplified_ms.median / raw_ms.median,
            raw_ms,
            simplified_ms,
        });
    }

    Ok(simplified)
}
