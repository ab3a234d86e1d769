//! `filterjit bench`: the JIT measured against the alternatives, in one run
//! on one device. Every figure is a median over repeats, with its spread.
//! One file per measurement; `run` takes them in order.

mod calibration;
mod expressions;
mod frames;
mod generation;
mod handwritten;
pub mod interpreter;
mod population;
mod simplified;
mod table;
mod timing;

use serde::Serialize;

use crate::gpu::{Gpu, SceneBuffers};
use crate::scene::Scene;

pub use calibration::{calibrate, CalibrationResult, THESIS_TABLE_4_1};
pub use expressions::{corpus, CorpusResult, ExpressionResult, VARIANTS};
pub use frames::{FrameMethod, FrameParts, FrameResult, KernelTime, StageResult, FRAME_SIDE, PROFILED_FRAMES};
pub use generation::GenerationResult;
pub use handwritten::{HandWrittenResult, HANDWRITTEN_BILATERAL};
pub use population::PopulationResult;
pub use simplified::{SimplifiedResult, BLOATED};
pub use table::{frames_report, table};
pub use timing::Stat;

#[derive(Clone, Debug, Serialize)]
pub struct BenchSettings {
    pub radius: u32,
    pub repeats: usize,
    /// Individuals compiled together for the amortised compile cost.
    pub population: usize,
    /// Expression lengths of the corpus.
    pub lengths: Vec<usize>,
    /// Image sizes of the one-generation measurement (square).
    pub generation_sizes: Vec<u32>,
    pub generation_radius: u32,
    pub seed: u64,
    /// Individuals per fitness kernel in the population's "as evolve does"
    /// measurement and the generations (`evolve --fuse`).
    pub fusion: crate::fitness::Fusion,
    /// Where OIDN's files go while it runs (the edge's temporary folder).
    #[serde(skip)]
    pub scratch: std::path::PathBuf,
}

#[derive(Clone, Debug, Serialize)]
pub struct Report {
    pub device: String,
    /// What warm kernel times are read from.
    pub clock: Clock,
    pub scene: String,
    pub width: usize,
    pub height: usize,
    pub settings: BenchSettings,
    /// The corpus of expressions measured one by one.
    #[serde(flatten)]
    pub corpus: CorpusResult,
    pub population: PopulationResult,
    /// Per-operator cost weights measured here: `evolve --cost-model bench.json` searches with them.
    pub cost_model: crate::cost::CostModel,
    pub calibration: CalibrationResult,
    pub handwritten: HandWrittenResult,
    pub simplified: Vec<SimplifiedResult>,
    /// The pipeline's stages and forms, side by side (`@crossBilateral` in each form).
    pub stages: Vec<StageResult>,
    /// Whole pipelines (pre-pass and form) of the shipped à-trous filters on
    /// the same frame, and the peer, Intel Open Image Denoise, where found.
    pub frames: Vec<FrameResult>,
    /// The bench scene's noisy input's light, beside the frames' outputs'.
    pub noisy_light: Option<f64>,
    pub generations: Vec<GenerationResult>,
}

/// `bench --frames`: whole frames only, at real sizes.
#[derive(Clone, Debug, Serialize)]
pub struct FramesReport {
    pub device: String,
    pub clock: Clock,
    /// What the frames are: the bench scene's render, tiled to each size.
    pub source: String,
    pub repeats: usize,
    pub frames: Vec<FrameResult>,
}

/// The methods `bench --frames` times: `filter`'s default, the real-time
/// filter, the 3x3 cascade, and the best shipped temporal filter (a still
/// sequence's frames, its history settled); OIDN beside them where found.
pub fn frame_methods() -> anyhow::Result<Vec<FrameMethod>> {
    use crate::denoise::{SHIPPED_BY_QUALITY, SHIPPED_REALTIME, SHIPPED_TEMPORAL_BY_QUALITY};
    let names = [SHIPPED_BY_QUALITY[0], SHIPPED_REALTIME, "evolvedAtrous3x3", SHIPPED_TEMPORAL_BY_QUALITY[0]];
    names.iter().map(|name| FrameMethod::shipped(name)).collect()
}

/// What `bench --frames` measures: the sizes, each frame's repeats, and
/// where OIDN's files go.
pub struct FramesSettings<'a> {
    pub sizes: &'a [(usize, usize)],
    pub repeats: usize,
    /// Each method's kernels timed pass by pass after its timed frames ([`FrameResult::profile`]).
    pub profile: bool,
    pub scratch: &'a std::path::Path,
}

/// Whole frames of `methods` and OIDN at every size of `settings`, from
/// `renders` (the bench scene with different seeds) tiled to each
/// ([`frames::frames`]).
pub fn frames_at(
    gpu: &Gpu,
    renders: &[Scene],
    methods: &[FrameMethod],
    settings: &FramesSettings,
    peer: Option<&crate::oidn::Oidn>,
    progress: &mut dyn FnMut(&str),
) -> anyhow::Result<FramesReport> {
    let FramesSettings { sizes, repeats, profile, scratch } = *settings;
    let rounds = frames::Rounds { repeats, profile, scratch };
    let scene = renders.first().expect("the bench scene has a render");
    let mut all = Vec::new();
    for &size in sizes {
        progress(&format!("whole frames {}x{}", size.0, size.1));
        all.extend(frames::frames(gpu, renders, size, methods, &rounds, peer)?);
    }
    Ok(FramesReport {
        device: gpu.describe(),
        clock: if gpu.has_device_clock() { Clock::Device } else { Clock::Wall },
        source: format!(
            "{} ({}x{}), tiled to each size{}",
            scene.name,
            scene.width,
            scene.height,
            match renders.len() {
                1 => String::new(),
                n => format!("; a temporal filter's frames cycle through {n} renders of it with their own seeds"),
            }
        ),
        repeats,
        frames: all,
    })
}

/// The clock warm kernels are timed by ([`crate::gpu::Filtered::kernel_time`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Clock {
    /// The device's timestamps around the commands.
    Device,
    /// Wall time from submission to completion: the device has no timestamps.
    Wall,
}

/// Run everything on `renders[0]` (which must carry the corpus's features
/// and a reference); the other renders are the same scene with other seeds,
/// a temporal filter's later frames ([`frames::frames`]).
pub fn run(
    gpu: &Gpu,
    renders: &[Scene],
    generation_scenes: &mut dyn FnMut(u32) -> anyhow::Result<Scene>,
    settings: &BenchSettings,
    peer: Option<&crate::oidn::Oidn>,
    progress: &mut dyn FnMut(&str),
) -> anyhow::Result<Report> {
    let scene = renders.first().expect("the bench scene has a render");
    let mut buffers = SceneBuffers::new(gpu, scene);
    let measured = expressions::measure(gpu, scene, &mut buffers, settings, progress)?;
    progress(&format!("population of {}", settings.population));
    let population = population::measure(gpu, scene, settings)?;
    progress("cost model calibration");
    let (cost_model, calibration) = calibration::measure(gpu, scene, &mut buffers, settings, &measured.expressions)?;
    progress("hand-written bilateral");
    let handwritten = handwritten::measure(gpu, scene, &mut buffers, settings)?;
    progress("simplified expressions");
    let simplified = simplified::measure(gpu, scene, &mut buffers, settings)?;
    progress(&format!("pipeline stages and forms on {FRAME_SIDE}x{FRAME_SIDE}"));
    let stages = frames::pipeline_stages(gpu, scene, settings.repeats)?;
    progress(&format!(
        "whole frames on {FRAME_SIDE}x{FRAME_SIDE}{}",
        if peer.is_some() { ", and OIDN" } else { " (OIDN not found)" }
    ));
    let frames = frames::whole_frames(gpu, renders, settings.repeats, peer, &settings.scratch)?;
    let generations = generation::measure(gpu, generation_scenes, settings, progress)?;
    Ok(Report {
        device: gpu.describe(),
        clock: if gpu.has_device_clock() { Clock::Device } else { Clock::Wall },
        scene: scene.name.clone(),
        width: scene.width,
        height: scene.height,
        settings: settings.clone(),
        corpus: measured,
        population,
        cost_model,
        calibration,
        handwritten,
        simplified,
        stages,
        frames,
        noisy_light: crate::metrics::light(
            &scene.color,
            scene.reference.as_ref().expect("the bench scene has a reference"),
        ),
        generations,
    })
}
