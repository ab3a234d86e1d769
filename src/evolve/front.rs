//! A multi-objective run's front, scored on the test scenes and timed:
//! `pareto.json`.

use std::path::Path;

use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};

use super::results::test_each;
use super::RunConfig;
use crate::fitness::Scorer;
use crate::gp;
use crate::gpu::Gpu;
use crate::jit::{self};
use crate::lang::Expr;
use crate::pipeline::FilterPipeline;
use crate::scene::Scene;

/// One member of a run's front, as `pareto.json` lists it.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct FrontMember {
    pub name: String,
    pub expr: String,
    pub simplified: String,
    /// The window radius it was scored and timed with.
    pub radius: u32,
    /// Training fitness (mean relMSE / noisy relMSE).
    pub fitness: f64,
    /// The modelled cost per pixel ([`crate::cost::model_with`], the run's weights).
    pub cost: f64,
    /// Mean over the test scenes of relMSE / noisy relMSE.
    pub test_normalised: f64,
    /// Median time of the whole pipeline per megapixel on the timing scene, in ms.
    pub ms_per_mpx: f64,
}

/// `pareto.json`: a multi-objective run's front, measured.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Front {
    pub pipeline: FilterPipeline,
    pub radius: u32,
    pub device: String,
    /// The scene timed (the first test scene, tiled to the timing side), and its size.
    pub timing_scene: String,
    pub timing_pixels: usize,
    /// What the modelled costs' weights were measured on (`operator table` for the defaults).
    #[serde(default)]
    pub cost_model: String,
    /// Spearman's rank correlation of the modelled cost and the measured time over the members.
    pub rank_correlation: f64,
    /// Cheapest first.
    pub members: Vec<FrontMember>,
}

pub const FRONT_FILE: &str = "pareto.json";

impl Front {
    pub fn read(path: &Path) -> Result<Front> {
        let path = if path.is_dir() { path.join(FRONT_FILE) } else { path.to_path_buf() };
        let text = std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
        serde_json::from_str(&text)
            .with_context(|| format!("{} is not a filterjit front (pareto.json)", path.display()))
    }

    /// The most accurate member whose measured time for `pixels` pixels fits
    /// `budget_ms` (times scale with the pixel count: one dispatch over the image).
    pub fn within_budget(&self, budget_ms: f64, pixels: f64) -> Result<&FrontMember> {
        let time = |m: &FrontMember| m.ms_per_mpx * pixels / 1e6;
        self.members
            .iter()
            .filter(|m| time(m) <= budget_ms)
            .min_by(|a, b| a.fitness.total_cmp(&b.fitness))
            .ok_or_else(|| {
                let fastest = self.members.iter().map(time).fold(f64::INFINITY, f64::min);
                anyhow::anyhow!(
                    "no member of the front fits {budget_ms} ms at {:.2} megapixels: the fastest takes {fastest:.2} ms on {}",
                    pixels / 1e6,
                    self.device
                )
            })
    }
}

/// Side of the scene the front is timed on: large enough for stable times.
pub const FRONT_TIMING_SIDE: usize = 256;

/// Time each filter through `pipeline` on `scene`: one warm-up, then the median of `repeats`, in ms per megapixel,
/// on the device's clock where it has one (`Filtered::kernel_time`).
pub fn time_filters(
    gpu: &Gpu,
    exprs: &[(Expr, u32)],
    scene: &Scene,
    pipeline: &FilterPipeline,
    repeats: usize,
) -> Result<Vec<f64>> {
    let mut buffers = crate::gpu::SceneBuffers::for_pipeline(gpu, scene, pipeline)?;
    let shape = jit::Shape::of(pipeline);
    let mpx = scene.pixels() as f64 / 1e6;
    exprs
        .iter()
        .map(|(e, radius)| {
            let radius = *radius;
            let kernel = jit::compile(e, jit::KernelSpec { shape, ..jit::KernelSpec::default() })?;
            gpu.filter(&kernel, &mut buffers, scene, radius)?;
            let mut times: Vec<f64> = (0..repeats.max(1))
                .map(|_| Ok(gpu.filter(&kernel, &mut buffers, scene, radius)?.kernel_time().as_secs_f64()))
                .collect::<Result<_>>()?;
            times.sort_by(f64::total_cmp);
            Ok(times[times.len() / 2] * 1e3 / mpx)
        })
        .collect()
}

/// The front scored on the test scenes and timed on the first of them, tiled.
pub(super) fn measure_front(
    gpu: &Gpu,
    tester: &mut Scorer<'_>,
    front: &[gp::StoredMember],
    config: &RunConfig,
) -> Result<Front> {
    let exprs: Vec<(Expr, u32)> = front
        .iter()
        .map(|m| {
            let e = crate::lang::parse_expr(&m.expr)?;
            Ok((e, m.radius.unwrap_or(config.radius)))
        })
        .collect::<Result<_>>()?;
    let tested = test_each(tester, &exprs)?;
    let timing_scene = tester.scenes()[0].tiled(FRONT_TIMING_SIDE);
    let ms = time_filters(gpu, &exprs, &timing_scene, &config.pipeline, 5)?;
    let costs: Vec<f64> = front.iter().map(|m| m.fitness.cost.unwrap_or(0.0)).collect();
    let members = front
        .iter()
        .zip(&exprs)
        .zip(tested)
        .zip(&ms)
        .enumerate()
        .map(|(k, (((m, (e, radius)), t), ms))| FrontMember {
            name: format!("front{}", k + 1),
            expr: m.expr.clone(),
            simplified: crate::simplify::simplify(e).to_string(),
            radius: *radius,
            fitness: m.fitness.value,
            cost: m.fitness.cost.unwrap_or(0.0),
            test_normalised: t.normalised,
            ms_per_mpx: *ms,
        })
        .collect();
    Ok(Front {
        pipeline: config.pipeline,
        radius: config.radius,
        device: gpu.describe(),
        timing_scene: timing_scene.name.clone(),
        timing_pixels: timing_scene.pixels(),
        cost_model: config.cost_model.device.clone(),
        rank_correlation: crate::cost::rank_correlation(&costs, &ms),
        members,
    })
}
