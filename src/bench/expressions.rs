//! Each corpus expression: lowering, validation, pipeline creation and the
//! first dispatch; then warm times of the default kernel, the unoptimised
//! one, each optimisation switched off (and tiles on), and the stack
//! interpreter, in interleaved rounds.

use std::time::Instant;

use serde::Serialize;

use super::timing::{interleaved, ms, stat, Stat};
use super::{interpreter, BenchSettings};
use crate::gpu::{Gpu, SceneBuffers};
use crate::jit::{self, LowerOptions};
use crate::lang::random::Alphabet;
use crate::lang::{Expr, Feature, ScalarVar};
use crate::rng::Rng;
use crate::scene::Scene;

#[derive(Clone, Debug, Serialize)]
pub struct ExpressionResult {
    pub expr: String,
    pub length: usize,
    pub lower_ms: f64,
    pub validate_ms: f64,
    pub pipeline_ms: f64,
    /// The first dispatch, where software drivers compile the pipeline.
    pub first_dispatch_ms: f64,
    /// Warm dispatches, generated kernel (all optimisations).
    pub jit_ms: Stat,
    /// Warm dispatches, generated kernel without optimisations.
    pub jit_plain_ms: Stat,
    /// Median warm time of each variant of [`VARIANTS`] (none where tiles do not fit).
    pub variant_ms: Vec<Option<f64>>,
    pub interpreter_ms: Option<Stat>,
    /// interpreter / JIT, median times.
    pub interpreter_ratio: Option<f64>,
    pub weights_per_second: f64,
    pub gp_ops_per_second: f64,
}

/// What each optimisation is worth: the default kernel with one switch
/// turned off, and with workgroup tiles turned on (for the bench radius).
pub const VARIANTS: [&str; 6] = ["-fold", "-cse", "-hoist", "-strength", "-skip-checks", "+tiles"];

fn variant(name: &str, radius: u32) -> LowerOptions {
    let all = LowerOptions::ALL;
    match name {
        "-fold" => LowerOptions { fold_constants: false, ..all },
        "-cse" => LowerOptions { common_subexpressions: false, ..all },
        "-hoist" => LowerOptions { hoist_centre_terms: false, ..all },
        "-strength" => LowerOptions { strength_reduction: false, ..all },
        "-skip-checks" => LowerOptions { skip_redundant_checks: false, ..all },
        "+tiles" => all.with_tiles(radius),
        other => unreachable!("unknown variant {other}"),
    }
}

/// Neighbour evaluations of one filter pass (windows clipped to the image).
fn weights(width: usize, height: usize, radius: u32) -> f64 {
    let r = radius as i64;
    let span = |n: usize, p: i64| ((p + r).min(n as i64 - 1) - (p - r).max(0) + 1) as f64;
    let xs: f64 = (0..width as i64).map(|x| span(width, x)).sum();
    let ys: f64 = (0..height as i64).map(|y| span(height, y)).sum();
    xs * ys
}

/// The benchmark corpus: random expressions of each length over the scene's features.
pub fn corpus(settings: &BenchSettings) -> Vec<Expr> {
    let alphabet = Alphabet::with(
        &[
            Feature::Normal,
            Feature::Texture,
            Feature::WorldPosition,
            Feature::Depth,
            Feature::Color,
            Feature::Pixel,
            Feature::NGradient,
        ],
        &[ScalarVar::ColorVariance, ScalarVar::NVariance],
    );
    let mut rng = Rng::seeded(settings.seed);
    let mut out = Vec::new();
    for &length in &settings.lengths {
        for _ in 0..2 {
            out.push(alphabet.of_length(&mut rng, length));
        }
    }
    out
}

/// The corpus measured, and medians over it (flattened into `bench.json`).
#[derive(Clone, Debug, Serialize)]
pub struct CorpusResult {
    pub expressions: Vec<ExpressionResult>,
    pub interpreter_ratio_median: f64,
    pub optimisation_ratio_median: f64,
    /// Per variant of [`VARIANTS`]: median over the corpus of its time / the default kernel's time.
    pub variant_ratio_median: Vec<(String, f64)>,
    pub weights_per_second_median: f64,
    pub gp_ops_per_second_median: f64,
}

pub(super) fn measure(
    gpu: &Gpu,
    scene: &Scene,
    buffers: &mut SceneBuffers,
    settings: &BenchSettings,
    progress: &mut dyn FnMut(&str),
) -> anyhow::Result<CorpusResult> {
    let interpreter_kernel = gpu.raw_kernel(&interpreter::source())?;
    let packed = interpreter::pack(scene);
    let per_pass = weights(scene.width, scene.height, settings.radius);
    let mut expressions = Vec::new();
    for (k, expr) in corpus(settings).iter().enumerate() {
        progress(&format!("expression {}/{} (length {})", k + 1, settings.lengths.len() * 2, expr.len()));
        let t = Instant::now();
        let source = jit::lower(expr, jit::KernelSpec::default())?;
        let lower = t.elapsed();
        let t = Instant::now();
        let kernel = jit::validate(source)?;
        let validate = t.elapsed();
        let first = gpu.filter(&kernel, buffers, scene, settings.radius)?;
        // The default kernel, the unoptimised one and each variant, timed in rounds.
        let plain = jit::validate(jit::lower(
            expr,
            jit::KernelSpec { options: LowerOptions::NONE, ..jit::KernelSpec::default() },
        )?)?;
        let mut variants = Vec::new();
        for name in VARIANTS {
            let source = jit::lower(
                expr,
                jit::KernelSpec { options: variant(name, settings.radius), ..jit::KernelSpec::default() },
            )?;
            // Tiles that do not fit leave the default kernel: nothing to time.
            let fits = name != "+tiles" || source.tile_radius.is_some();
            variants.push(if fits { Some(jit::validate(source)?) } else { None });
        }
        let all: Vec<&jit::ValidatedKernel> = [&kernel, &plain].into_iter().chain(variants.iter().flatten()).collect();
        for k in &all[1..] {
            gpu.filter(k, buffers, scene, settings.radius)?;
        }
        let mut stats = interleaved(gpu, &all, buffers, scene, settings.radius, settings.repeats)?.into_iter();
        let jit_ms = stats.next().expect("default kernel");
        let jit_plain_ms = stats.next().expect("plain kernel");
        let variant_ms: Vec<Option<f64>> =
            variants.iter().map(|v| v.as_ref().and_then(|_| stats.next().map(|s| s.median))).collect();
        let interpreter_ms =
            interpreter::interpret(gpu, &interpreter_kernel, &packed, expr, scene, settings.radius, settings.repeats)?;
        let seconds = jit_ms.median / 1e3;
        expressions.push(ExpressionResult {
            expr: expr.to_string(),
            length: expr.len(),
            lower_ms: ms(lower),
            validate_ms: ms(validate),
            pipeline_ms: ms(first.pipeline.create),
            first_dispatch_ms: ms(first.time.wall),
            interpreter_ratio: interpreter_ms.as_ref().map(|i| i.median / jit_ms.median),
            jit_plain_ms,
            variant_ms,
            interpreter_ms,
            weights_per_second: per_pass / seconds,
            gp_ops_per_second: per_pass * expr.len() as f64 / seconds,
            jit_ms,
        });
        gpu.prune_pipelines(|_| false);
    }
    let median = |v: Vec<f64>| stat(v).median;
    let interpreter_ratio_median = median(expressions.iter().filter_map(|e| e.interpreter_ratio).collect());
    let optimisation_ratio_median =
        median(expressions.iter().map(|e| e.jit_plain_ms.median / e.jit_ms.median).collect());
    let variant_ratio_median = VARIANTS
        .iter()
        .enumerate()
        .map(|(k, name)| {
            let ratios = expressions.iter().filter_map(|e| e.variant_ms[k].map(|v| v / e.jit_ms.median)).collect();
            (name.to_string(), median(ratios))
        })
        .collect();
    let weights_per_second_median = median(expressions.iter().map(|e| e.weights_per_second).collect());
    let gp_ops_per_second_median = median(expressions.iter().map(|e| e.gp_ops_per_second).collect());

    Ok(CorpusResult {
        expressions,
        interpreter_ratio_median,
        optimisation_ratio_median,
        variant_ratio_median,
        weights_per_second_median,
        gp_ops_per_second_median,
    })
}
