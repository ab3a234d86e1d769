//! One GP generation of the thesis's size, per image size: its compile,
//! evaluation and GP time as `evolve` reports them.

use std::time::Instant;

use serde::Serialize;

use super::BenchSettings;
use crate::gp::{self, Evaluator};
use crate::gpu::Gpu;
use crate::lang::{parse_expr, Feature, ScalarVar};
use crate::scene::Scene;

#[derive(Clone, Debug, Serialize)]
pub struct GenerationResult {
    pub size: u32,
    pub radius: u32,
    pub population: usize,
    pub compile_s: f64,
    pub evaluate_s: f64,
    pub gp_s: f64,
    pub total_s: f64,
}

pub(super) fn measure(
    gpu: &Gpu,
    generation_scenes: &mut dyn FnMut(u32) -> anyhow::Result<Scene>,
    settings: &BenchSettings,
    progress: &mut dyn FnMut(&str),
) -> anyhow::Result<Vec<GenerationResult>> {
    let threads = std::thread::available_parallelism().map_or(2, |n| n.get());
    let bilateral = parse_expr(crate::corpus::lookup("bilateral").expect("shipped"))?;
    let mut generations = Vec::new();
    for &size in &settings.generation_sizes {
        progress(&format!("one generation at {size}x{size}"));
        let gscene = generation_scenes(size)?;
        let seed_expr = bilateral.clone();
        let features: Vec<Feature> = gscene.features.keys().copied().chain([Feature::Color, Feature::Pixel]).collect();
        let variances: Vec<ScalarVar> = gscene.variances.keys().copied().collect();
        let scoring = crate::fitness::Settings {
            fusion: settings.fusion,
            ..crate::fitness::Settings::window(settings.generation_radius, threads)
        };
        let mut evaluator = crate::fitness::Scorer::new(gpu, vec![gscene], &scoring)?;
        let gp_settings = gp::Settings {
            islands: 4,
            island_size: settings.population / 4,
            seed: settings.seed,
            ..Default::default()
        };
        let terminals = gp::operators::Terminals {
            features,
            variables: variances,
            constants: crate::lang::ops::THESIS_CONSTANTS.to_vec(),
        };
        let mut engine = gp::Engine::new(gp_settings, terminals, seed_expr, &mut evaluator)?;
        engine.initial()?;
        let t = Instant::now();
        let (_, report) = engine.step()?.expect("one process holds every island");
        let total = t.elapsed().as_secs_f64();
        drop(engine);
        let _ = evaluator.take_time();
        generations.push(GenerationResult {
            size,
            radius: settings.generation_radius,
            population: settings.population,
            compile_s: report.compile_s,
            evaluate_s: report.evaluate_s,
            gp_s: report.gp_s,
            total_s: total,
        });
    }

    Ok(generations)
}
