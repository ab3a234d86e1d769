//! A whole population compiled at once, as `evolve` does: lowering and
//! validation, pipelines, the first evaluation; with wgpu's run-time checks
//! kept; and scored as the search scores a batch, a kernel per individual
//! and fused.

use std::time::Instant;

use serde::Serialize;

use super::timing::ms;
use super::BenchSettings;
use crate::gpu::Gpu;
use crate::jit::{self, KernelKind};
use crate::lang::random::Alphabet;
use crate::lang::{Expr, Feature};
use crate::rng::Rng;
use crate::scene::Scene;

#[derive(Clone, Debug, Serialize)]
pub struct PopulationResult {
    pub individuals: usize,
    pub distinct: usize,
    pub lower_validate_ms: f64,
    pub pipelines_ms: f64,
    /// The first evaluation of all of them: software drivers compile here.
    pub first_evaluation_ms: f64,
    pub per_individual_ms: f64,
    /// The same with wgpu's run-time bounds checks and loop bounding kept in the kernels.
    pub checked_per_individual_ms: f64,
    /// As `evolve` scores a batch (every queue of its evaluator, lowering to
    /// fitness): a kernel per individual, then `fused_members` per kernel.
    pub evolve_single_per_individual_ms: f64,
    pub evolve_fused_per_individual_ms: f64,
    pub fused_members: usize,
    /// Whether both gave every individual the same errors and flags, bit for bit.
    pub fused_identical: bool,
}

pub(super) fn measure(gpu: &Gpu, scene: &Scene, settings: &BenchSettings) -> anyhow::Result<PopulationResult> {
    let alphabet = Alphabet::with(&[Feature::Normal, Feature::Texture, Feature::Color, Feature::Pixel], &[]);
    let mut rng = Rng::seeded(settings.seed ^ 1);
    let population: Vec<Expr> = (0..settings.population)
        .map(|_| {
            let length = 10 + rng.below(40);
            alphabet.of_length(&mut rng, length)
        })
        .collect();
    let mut distinct: Vec<Expr> = Vec::new();
    let mut seen = std::collections::HashSet::new();
    for e in &population {
        if seen.insert(e.to_string()) {
            distinct.push(e.clone());
        }
    }
    let threads = std::thread::available_parallelism().map_or(2, |n| n.get());
    let t = Instant::now();
    let kernels = jit::compile_each(&distinct, jit::KernelSpec::of(KernelKind::Fitness), threads)
        .into_iter()
        .collect::<Result<Vec<_>, _>>()?;
    let lower_validate = t.elapsed();
    let refs: Vec<&jit::ValidatedKernel> = kernels.iter().collect();
    let t = Instant::now();
    gpu.prepare_pipelines(&refs, threads)?;
    let pipelines = t.elapsed();
    let mut fitness_scene = [crate::gpu::FitnessScene::new(gpu, scene)?];
    let t = Instant::now();
    gpu.evaluate_fitness(&refs, &mut fitness_scene, &[scene], settings.radius)?;
    let first_evaluation = t.elapsed();
    gpu.prune_pipelines(|_| false);
    // The same kernels again with wgpu's run-time checks kept (what `create_shader_module` adds).
    gpu.set_kernel_runtime_checks(true);
    let t = Instant::now();
    gpu.prepare_pipelines(&refs, threads)?;
    gpu.evaluate_fitness(&refs, &mut fitness_scene, &[scene], settings.radius)?;
    let checked = t.elapsed();
    gpu.set_kernel_runtime_checks(false);
    // As evolve scores a generation: one kernel per individual, then fused kernels.
    let per_individual = |fusion| -> anyhow::Result<(f64, Vec<crate::fitness::ScoredErrors>)> {
        let scoring = crate::fitness::Settings { fusion, ..crate::fitness::Settings::window(settings.radius, threads) };
        let mut evaluator = crate::fitness::Scorer::new(gpu, vec![scene.clone()], &scoring)?;
        let t = Instant::now();
        let scored = evaluator.errors(&distinct)?;
        Ok((ms(t.elapsed()) / distinct.len() as f64, scored))
    };
    let (evolve_single_per_individual_ms, single) = per_individual(crate::fitness::Fusion::Members(1))?;
    let (evolve_fused_per_individual_ms, fused) = per_individual(settings.fusion)?;
    Ok(PopulationResult {
        evolve_single_per_individual_ms,
        evolve_fused_per_individual_ms,
        fused_members: settings.fusion.members(gpu),
        fused_identical: bit_identical(&single, &fused),
        checked_per_individual_ms: ms(lower_validate + checked) / population.len() as f64,
        individuals: population.len(),
        distinct: distinct.len(),
        lower_validate_ms: ms(lower_validate),
        pipelines_ms: ms(pipelines),
        first_evaluation_ms: ms(first_evaluation),
        per_individual_ms: ms(lower_validate + pipelines + first_evaluation) / population.len() as f64,
    })
}

/// Whether two scorings agree bit for bit (NaN included).
fn bit_identical(a: &[crate::fitness::ScoredErrors], b: &[crate::fitness::ScoredErrors]) -> bool {
    let key = |s: &crate::fitness::ScoredErrors| match s {
        Ok(errors) => Ok(errors.iter().map(|e| (e.relmse.to_bits(), e.flags, e.finite)).collect::<Vec<_>>()),
        Err(reason) => Err(reason.clone()),
    };
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| key(x) == key(y))
}
