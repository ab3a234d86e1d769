//! The cost model's weights measured on this device (probe kernels), and how
//! well the operator table's and the measured weights rank the corpus's
//! warm times.

use std::collections::BTreeMap;

use serde::Serialize;

use super::expressions::{corpus, ExpressionResult};
use super::timing::{interleaved, ms, stat};
use super::BenchSettings;
use crate::gpu::{Gpu, SceneBuffers};
use crate::jit;
use crate::lang::{Expr, Feature};
use crate::scene::Scene;

/// The cost model's weights measured on this device, and how well each
/// model ranks the corpus's measured warm times.
#[derive(Clone, Debug, Serialize)]
pub struct CalibrationResult {
    /// Warm ms of each probe kernel (median), by what it probes.
    pub probe_ms: BTreeMap<String, f64>,
    /// Spearman's rank correlation of the modelled cost with the corpus's
    /// warm dispatch times: the operator table's weights, then these.
    pub table_rank_correlation: f64,
    pub measured_rank_correlation: f64,
}

/// The thesis's Table 4.1 (GTX 980 Ti, population 200), for the side-by-side view.
pub const THESIS_TABLE_4_1: &[(u32, f64, f64)] =
    &[(32, 0.457, 2.667), (128, 6.799, 734.623), (256, 22.038, 3165.72), (512, 183.14, 27501.9)];

/// The report as a text table.
/// Operators chained this deep in each calibration probe, so that each
/// probe's own work stands well above the dispatch's.
const CHAIN: usize = 12;

/// The cost model's weights on this device: the warm time of a chain of
/// [`CHAIN`] of each operator (a vector operator: one on each of three
/// features, summed) minus that of its leaf, per tap, in units chosen so that
/// the operators' weights add up to the operator table's (only their ratios
/// matter to the search); the tap's fixed work from the constant weight at
/// radius 1 and at `radius`. The pixel's fixed work keeps the table's value:
/// a dispatch's own overhead cannot be told apart from it.
pub fn calibrate(
    gpu: &Gpu,
    buffers: &mut SceneBuffers,
    scene: &Scene,
    radius: u32,
    repeats: usize,
) -> anyhow::Result<(crate::cost::CostModel, BTreeMap<String, f64>)> {
    use crate::cost::CostModel;
    use crate::lang::{BinaryOp, PairOp, UnaryOp};
    let leaf = Expr::Pair(PairOp::Distance1, Feature::Color, Feature::Color);
    let chain = |wrap: &dyn Fn(Expr) -> Expr| (0..CHAIN).fold(leaf.clone(), |e, _| wrap(e));
    let mut probes: Vec<(String, Expr)> = vec![("leaf".into(), leaf.clone()), ("constant".into(), Expr::Const(1.0))];
    for &op in UnaryOp::ALL {
        probes.push((op.name().into(), chain(&|e| Expr::unary(op, e))));
    }
    for &op in BinaryOp::ALL {
        probes.push((op.name().into(), chain(&|e| Expr::binary(op, e, leaf.clone()))));
    }
    let features = [Feature::Color, Feature::Normal, Feature::Texture];
    for &op in PairOp::ALL {
        let sum = features
            .iter()
            .map(|&f| Expr::Pair(op, f, f))
            .reduce(|a, b| Expr::binary(BinaryOp::Add, a, b))
            .expect("three features");
        probes.push((op.name().into(), sum));
    }
    let exprs: Vec<Expr> = probes.iter().map(|(_, e)| e.clone()).collect();
    let kernels: Vec<jit::ValidatedKernel> =
        exprs.iter().map(|e| jit::compile(e, jit::KernelSpec::default())).collect::<Result<_, _>>()?;
    let refs: Vec<&jit::ValidatedKernel> = kernels.iter().collect();
    for k in &refs {
        gpu.filter(k, buffers, scene, radius)?;
    }
    let rounds = repeats.max(3) * 2;
    let warm: Vec<f64> =
        interleaved(gpu, &refs, buffers, scene, radius, rounds)?.into_iter().map(|s| s.median).collect();
    let constant_near = stat(
        (0..rounds)
            .map(|_| Ok(ms(gpu.filter(&kernels[1], buffers, scene, 1)?.kernel_time())))
            .collect::<anyhow::Result<Vec<f64>>>()?,
    )
    .median;
    let pixels = scene.pixels() as f64;
    let taps = |r: u32| ((2 * r + 1) * (2 * r + 1)) as f64;
    let per_tap = |ms: f64| ms * 1e6 / (pixels * taps(radius)); // ns per pixel and tap
    let (leaf_ns, constant_ns) = (per_tap(warm[0]), per_tap(warm[1]));
    let table = CostModel::table();
    let mut raw = BTreeMap::new();
    for ((name, _), ms) in probes.iter().zip(&warm).skip(2) {
        let ns = if PairOp::from_name(name).is_some() {
            // Three operators and two adds over the constant weight's loop.
            let add = raw.get(BinaryOp::Add.name()).copied().unwrap_or(0.0);
            (per_tap(*ms) - constant_ns - 2.0 * add) / features.len() as f64
        } else {
            (per_tap(*ms) - leaf_ns) / CHAIN as f64
        };
        raw.insert(name.clone(), ns.max(0.0));
    }
    let table_sum: f64 = raw.keys().map(|k| table.operators[k]).sum();
    let unit = raw.values().sum::<f64>() / table_sum; // ns per unit
    let operators = raw.iter().map(|(k, ns)| (k.clone(), ns / unit.max(1e-12))).collect();
    let tap_ns = (warm[1] - constant_near) * 1e6 / (pixels * (taps(radius) - taps(1)));
    let model =
        CostModel { device: gpu.describe(), tap: (tap_ns / unit.max(1e-12)).max(0.0), pixel: table.pixel, operators };
    let probe_ms = probes.iter().map(|(n, _)| n.clone()).zip(warm).collect();
    Ok((model, probe_ms))
}

pub(super) fn measure(
    gpu: &Gpu,
    scene: &Scene,
    buffers: &mut SceneBuffers,
    settings: &BenchSettings,
    expressions: &[ExpressionResult],
) -> anyhow::Result<(crate::cost::CostModel, CalibrationResult)> {
    let (cost_model, probe_ms) = calibrate(gpu, buffers, scene, settings.radius, settings.repeats)?;
    let ranked = |model: &crate::cost::CostModel| {
        let costs: Vec<f64> = corpus(settings)
            .iter()
            .map(|e| crate::cost::model_with(e, &crate::pipeline::FilterPipeline::WINDOW, settings.radius, model))
            .collect();
        let times: Vec<f64> = expressions.iter().map(|e| e.jit_ms.median).collect();
        crate::cost::rank_correlation(&costs, &times)
    };
    let calibration = CalibrationResult {
        probe_ms,
        table_rank_correlation: ranked(&crate::cost::CostModel::table()),
        measured_rank_correlation: ranked(&cost_model),
    };

    Ok((cost_model, calibration))
}
