//! `filterjit bench`: the JIT measured against the alternatives, in one run
//! on one device. Every figure is a median over repeats, with its spread.

pub mod interpreter;

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use serde::Serialize;

use crate::gp::{self, Evaluator};
use crate::gpu::{Gpu, RawBuffer, SceneBuffers};
use crate::jit::{self, KernelKind, KernelLayout, KernelSource, LowerOptions};
use crate::lang::random::Alphabet;
use crate::lang::{parse_expr, Expr, Feature, FeatureSource, ScalarVar};
use crate::rng::Rng;
use crate::scene::Scene;

/// Bench settings.
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
    pub fusion: crate::evolve::Fusion,
}

#[derive(Clone, Debug, Serialize)]
pub struct Stat {
    pub median: f64,
    pub min: f64,
    pub max: f64,
}

fn stat(mut v: Vec<f64>) -> Stat {
    v.sort_by(f64::total_cmp);
    Stat { median: v[v.len() / 2], min: v[0], max: v[v.len() - 1] }
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

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

#[derive(Clone, Debug, Serialize)]
pub struct HandWrittenResult {
    pub handwritten_ms: Stat,
    pub generated_ms: Stat,
    pub generated_plain_ms: Stat,
    /// The generated kernel with workgroup tiles.
    pub generated_tiled_ms: Stat,
    pub tiled_ratio: f64,
    /// generated / hand-written.
    pub ratio: f64,
    pub plain_ratio: f64,
}

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

/// One stage or form of the filter pipeline on a frame of [`FRAME_SIDE`]².
#[derive(Clone, Debug, Serialize)]
pub struct StageResult {
    pub stage: String,
    /// Lower and validate of its kernel (none for the pre-pass: one module for every pipeline).
    pub lower_validate_ms: Option<f64>,
    /// Pipeline creation plus the first dispatch, where software drivers compile.
    pub compile_ms: f64,
    pub warm_ms: Stat,
    pub ms_per_mpx: f64,
}

/// One way to denoise a whole frame of [`FRAME_SIDE`]²: a shipped filter in
/// the pipeline it is stored with (device time of the pre-pass and every pass
/// of the form), or OIDN (CPU wall time of each execution, as `oidnDenoise`
/// reports it).
#[derive(Clone, Debug, Serialize)]
pub struct FrameResult {
    pub method: String,
    pub pipeline: String,
    /// Pipeline creation plus the first frame (none for OIDN: its program creates its filter each run).
    pub compile_ms: Option<f64>,
    pub warm_ms: Stat,
    pub ms_per_mpx: f64,
    /// This method's warm median over OIDN's (none without OIDN).
    pub over_oidn: Option<f64>,
}

/// Side of the frame the pipeline's stages are timed on (the size OIDN is compared at).
pub const FRAME_SIDE: usize = 256;

#[derive(Clone, Debug, Serialize)]
pub struct Report {
    pub device: String,
    pub scene: String,
    pub width: usize,
    pub height: usize,
    pub settings: BenchSettings,
    pub expressions: Vec<ExpressionResult>,
    pub interpreter_ratio_median: f64,
    pub optimisation_ratio_median: f64,
    /// Per variant of [`VARIANTS`]: median over the corpus of its time / the default kernel's time.
    pub variant_ratio_median: Vec<(String, f64)>,
    pub weights_per_second_median: f64,
    pub gp_ops_per_second_median: f64,
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
    pub generations: Vec<GenerationResult>,
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

/// The hand-written cross-bilateral kernel a person would write for `@bilateral`.
pub const HANDWRITTEN_BILATERAL: &str = include_str!("../../templates/handwritten_bilateral.wgsl");

/// Neighbour evaluations of one filter pass (windows clipped to the image).
fn weights(width: usize, height: usize, radius: u32) -> f64 {
    let r = radius as i64;
    let span = |n: usize, p: i64| ((p + r).min(n as i64 - 1) - (p - r).max(0) + 1) as f64;
    let xs: f64 = (0..width as i64).map(|x| span(width, x)).sum();
    let ys: f64 = (0..height as i64).map(|y| span(height, y)).sum();
    xs * ys
}

/// Warm times of several kernels measured in rounds (one dispatch of each per
/// round), so that a shared machine's drifting load falls on all of them alike.
fn interleaved(
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
            times[k].push(ms(gpu.filter(kernel, buffers, scene, radius)?.dispatch));
        }
    }
    Ok(times.into_iter().map(stat).collect())
}

/// The interpreter's inputs for a scene: features and variances packed by slot.
struct Packed {
    features: Vec<Feature>,
    variances: Vec<ScalarVar>,
    feature_data: Vec<u8>,
    variance_data: Vec<u8>,
}

fn pack(scene: &Scene) -> Packed {
    let features: Vec<Feature> = scene
        .features
        .keys()
        .copied()
        .filter(|f| matches!(f.source(), FeatureSource::Stored(_) | FeatureSource::Gradient(_)))
        .collect();
    let variances: Vec<ScalarVar> = scene.variances.keys().copied().collect();
    let mut fdata: Vec<[f32; 4]> = Vec::new();
    for f in &features {
        fdata.extend(scene.features[f].iter().map(|v| {
            if f.dimension() == 1 {
                [v[0], 0.0, 0.0, 0.0]
            } else {
                [v[0], v[1], v[2], 0.0]
            }
        }));
    }
    if fdata.is_empty() {
        fdata.push([0.0; 4]);
    }
    let mut vdata: Vec<f32> = variances.iter().flat_map(|v| scene.variances[v].iter().copied()).collect();
    if vdata.is_empty() {
        vdata.push(0.0);
    }
    Packed {
        features,
        variances,
        feature_data: bytemuck::cast_slice(&fdata).to_vec(),
        variance_data: bytemuck::cast_slice(&vdata).to_vec(),
    }
}

fn interpret(
    gpu: &Gpu,
    kernel: &crate::gpu::RawKernel,
    packed: &Packed,
    expr: &Expr,
    scene: &Scene,
    radius: u32,
    repeats: usize,
) -> anyhow::Result<Option<Stat>> {
    let slot = |f: Feature| packed.features.iter().position(|g| *g == f).expect("the scene has it") as u32;
    let variance = |v: ScalarVar| packed.variances.iter().position(|w| *w == v).expect("the scene has it") as u32;
    let program = interpreter::encode(expr, &slot, &variance);
    if program.max_depth > interpreter::STACK {
        return Ok(None);
    }
    let (w, h) = (scene.width as u32, scene.height as u32);
    let params: [u32; 8] = [w, h, radius, 0, program.code.len() as u32, w * h, 0, 0];
    let color: Vec<[f32; 4]> = scene.color.iter().map(|c| [c[0], c[1], c[2], 1.0]).collect();
    let constants = if program.constants.is_empty() { vec![0.0] } else { program.constants.clone() };
    let pixels = (w * h) as u64;
    let mut times = Vec::new();
    for _ in 0..repeats + 1 {
        let buffers = [
            RawBuffer::Read(bytemuck::cast_slice(&color)),
            RawBuffer::Write(pixels * 16),
            RawBuffer::Write(pixels * 4),
            RawBuffer::Read(bytemuck::cast_slice(&program.code)),
            RawBuffer::Read(bytemuck::cast_slice(&constants)),
            RawBuffer::Read(&packed.feature_data),
            RawBuffer::Read(&packed.variance_data),
        ];
        let (t, _) = gpu.run_raw(kernel, bytemuck::cast_slice(&params), &buffers, (w.div_ceil(8), h.div_ceil(8)))?;
        times.push(ms(t));
    }
    times.remove(0); // the first dispatch compiles
    Ok(Some(stat(times)))
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

/// Run everything on `scene` (which must carry the corpus's features and a reference).
pub fn run(
    gpu: &Gpu,
    scene: &Scene,
    generation_scenes: &mut dyn FnMut(u32) -> anyhow::Result<Scene>,
    settings: &BenchSettings,
    peer: Option<&crate::report::oidn::Oidn>,
    progress: &mut dyn FnMut(&str),
) -> anyhow::Result<Report> {
    let mut buffers = SceneBuffers::new(gpu, scene);
    let interpreter_kernel = gpu.raw_kernel(&interpreter::source())?;
    let packed = pack(scene);
    let per_pass = weights(scene.width, scene.height, settings.radius);

    let mut expressions = Vec::new();
    for (k, expr) in corpus(settings).iter().enumerate() {
        progress(&format!("expression {}/{} (length {})", k + 1, settings.lengths.len() * 2, expr.len()));
        let t = Instant::now();
        let source = jit::lower_with(expr, KernelKind::Filter, LowerOptions::ALL)?;
        let lower = t.elapsed();
        let t = Instant::now();
        let kernel = jit::validate(source)?;
        let validate = t.elapsed();
        let first = gpu.filter(&kernel, &mut buffers, scene, settings.radius)?;
        // The default kernel, the unoptimised one and each variant, timed in rounds.
        let plain = jit::validate(jit::lower_with(expr, KernelKind::Filter, LowerOptions::NONE)?)?;
        let mut variants = Vec::new();
        for name in VARIANTS {
            let source = jit::lower_with(expr, KernelKind::Filter, variant(name, settings.radius))?;
            // Tiles that do not fit leave the default kernel: nothing to time.
            let fits = name != "+tiles" || source.tile_radius.is_some();
            variants.push(if fits { Some(jit::validate(source)?) } else { None });
        }
        let all: Vec<&jit::ValidatedKernel> = [&kernel, &plain].into_iter().chain(variants.iter().flatten()).collect();
        for k in &all[1..] {
            gpu.filter(k, &mut buffers, scene, settings.radius)?;
        }
        let mut stats = interleaved(gpu, &all, &mut buffers, scene, settings.radius, settings.repeats)?.into_iter();
        let jit_ms = stats.next().expect("default kernel");
        let jit_plain_ms = stats.next().expect("plain kernel");
        let variant_ms: Vec<Option<f64>> =
            variants.iter().map(|v| v.as_ref().and_then(|_| stats.next().map(|s| s.median))).collect();
        let interpreter_ms =
            interpret(gpu, &interpreter_kernel, &packed, expr, scene, settings.radius, settings.repeats)?;
        let seconds = jit_ms.median / 1e3;
        expressions.push(ExpressionResult {
            expr: expr.to_string(),
            length: expr.len(),
            lower_ms: ms(lower),
            validate_ms: ms(validate),
            pipeline_ms: ms(first.pipeline.create),
            first_dispatch_ms: ms(first.dispatch),
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

    // A whole population compiled at once, as evolve does.
    progress(&format!("population of {}", settings.population));
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
    let kernels = jit::compile_all(&distinct, KernelKind::Fitness, threads)?;
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
    let mut evaluator = crate::evolve::GpuEvaluator::new(gpu, vec![scene.clone()], settings.radius, threads)?;
    let mut per_individual = |fusion| -> anyhow::Result<(f64, Vec<crate::evolve::ScoredErrors>)> {
        evaluator.set_fusion(fusion);
        let t = Instant::now();
        let scored = evaluator.errors(&distinct)?;
        Ok((ms(t.elapsed()) / distinct.len() as f64, scored))
    };
    let (evolve_single_per_individual_ms, single) = per_individual(crate::evolve::Fusion::Members(1))?;
    let (evolve_fused_per_individual_ms, fused) = per_individual(settings.fusion)?;
    let population_result = PopulationResult {
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
    };

    progress("cost model calibration");
    let (cost_model, probe_ms) = calibrate(gpu, &mut buffers, scene, settings.radius, settings.repeats)?;
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

    // Generated against hand-written, for the bilateral seed's formula.
    progress("hand-written bilateral");
    let bilateral = parse_expr(crate::corpus::lookup("bilateral").expect("shipped"))?;
    let layout = KernelLayout::of(&bilateral);
    let handwritten = jit::validate(KernelSource {
        kind: KernelKind::Filter,
        options: LowerOptions::NONE,
        shape: jit::Shape::WINDOW,
        canonical: "<hand-written bilateral>".into(),
        interface: jit::BindingInterface::of(KernelKind::Filter, &layout, jit::Shape::WINDOW),
        layout,
        tile_radius: None,
        exprs: vec![bilateral.clone()],
        wgsl: HANDWRITTEN_BILATERAL.to_string(),
    })?;
    let generated = jit::compile(&bilateral)?;
    let generated_plain = jit::validate(jit::lower_with(&bilateral, KernelKind::Filter, LowerOptions::NONE)?)?;
    let generated_tiled =
        jit::validate(jit::lower_with(&bilateral, KernelKind::Filter, LowerOptions::ALL.with_tiles(settings.radius))?)?;
    let kernels = [&handwritten, &generated, &generated_plain, &generated_tiled];
    for k in kernels {
        gpu.filter(k, &mut buffers, scene, settings.radius)?;
    }
    let [handwritten_ms, generated_ms, generated_plain_ms, generated_tiled_ms]: [Stat; 4] =
        interleaved(gpu, &kernels, &mut buffers, scene, settings.radius, settings.repeats * 4)?
            .try_into()
            .expect("four kernels");
    let handwritten_result = HandWrittenResult {
        tiled_ratio: generated_tiled_ms.median / handwritten_ms.median,
        generated_tiled_ms,
        ratio: generated_ms.median / handwritten_ms.median,
        plain_ratio: generated_plain_ms.median / handwritten_ms.median,
        handwritten_ms,
        generated_ms,
        generated_plain_ms,
    };

    // Bloated expressions against their simplified forms.
    progress("simplified expressions");
    let mut simplified = Vec::new();
    for text in BLOATED {
        let raw = parse_expr(text)?;
        let simple = crate::simplify::simplify(&raw);
        let kernels = [jit::compile(&raw)?, jit::compile(&simple)?];
        let refs: Vec<&jit::ValidatedKernel> = kernels.iter().collect();
        for k in &refs {
            gpu.filter(k, &mut buffers, scene, settings.radius)?;
        }
        let [raw_ms, simplified_ms]: [Stat; 2] =
            interleaved(gpu, &refs, &mut buffers, scene, settings.radius, settings.repeats * 2)?
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

    progress(&format!("pipeline stages and forms on {FRAME_SIDE}x{FRAME_SIDE}"));
    let stages = pipeline_stages(gpu, scene, settings.repeats)?;
    progress(&format!(
        "whole frames on {FRAME_SIDE}x{FRAME_SIDE}{}",
        if peer.is_some() { ", and OIDN" } else { " (OIDN not found)" }
    ));
    let frames = whole_frames(gpu, scene, settings.repeats, peer)?;

    // One GP generation of the thesis's size.
    let mut generations = Vec::new();
    for &size in &settings.generation_sizes {
        progress(&format!("one generation at {size}x{size}"));
        let gscene = generation_scenes(size)?;
        let seed_expr = bilateral.clone();
        let features: Vec<Feature> = gscene.features.keys().copied().chain([Feature::Color, Feature::Pixel]).collect();
        let variances: Vec<ScalarVar> = gscene.variances.keys().copied().collect();
        let mut evaluator = crate::evolve::GpuEvaluator::new(gpu, vec![gscene], settings.generation_radius, threads)?;
        evaluator.set_fusion(settings.fusion);
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
        let mut engine = gp::Engine::new(gp_settings, terminals, seed_expr, &mut evaluator);
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

    Ok(Report {
        device: gpu.describe(),
        scene: scene.name.clone(),
        width: scene.width,
        height: scene.height,
        settings: settings.clone(),
        expressions,
        interpreter_ratio_median,
        optimisation_ratio_median,
        variant_ratio_median,
        weights_per_second_median,
        gp_ops_per_second_median,
        population: population_result,
        cost_model,
        calibration,
        handwritten: handwritten_result,
        simplified,
        stages,
        frames,
        generations,
    })
}

/// Each stage's and each form's time on a frame of [`FRAME_SIDE`]² (the bench
/// scene tiled), measured in interleaved rounds: the pre-pass (outliers and
/// demodulation; the difference between preparing the frame's buffers with it
/// and without, so uploads cancel), and `@crossBilateral` as a window of
/// radius 3 and 10 and as 5 à-trous passes.
fn pipeline_stages(gpu: &Gpu, scene: &Scene, repeats: usize) -> anyhow::Result<Vec<StageResult>> {
    use crate::pipeline::FilterPipeline;
    let frame = crate::report::tile(scene, FRAME_SIDE);
    let mpx = frame.pixels() as f64 / 1e6;
    let expr = parse_expr(crate::corpus::lookup("crossBilateral").expect("shipped"))?;
    let with_prepass: FilterPipeline = "outliers=2,demodulate,window".parse().expect("valid");
    let mut results = Vec::new();

    let t = Instant::now();
    SceneBuffers::for_pipeline(gpu, &frame, &with_prepass)?;
    let compile_ms = ms(t.elapsed());
    let (mut plain, mut prepared) = (Vec::new(), Vec::new());
    for _ in 0..repeats.max(1) * 2 {
        let t = Instant::now();
        SceneBuffers::for_pipeline(gpu, &frame, &FilterPipeline::WINDOW)?;
        plain.push(ms(t.elapsed()));
        let t = Instant::now();
        SceneBuffers::for_pipeline(gpu, &frame, &with_prepass)?;
        prepared.push(ms(t.elapsed()));
    }
    let difference: Vec<f64> = prepared.iter().zip(&plain).map(|(p, u)| (p - u).max(0.0)).collect();
    let warm_ms = stat(difference);
    results.push(StageResult {
        stage: "pre-pass outliers=2,demodulate".into(),
        lower_validate_ms: None,
        compile_ms,
        ms_per_mpx: warm_ms.median / mpx,
        warm_ms,
    });

    let forms: [(&str, FilterPipeline, u32); 3] = [
        ("window r=3", FilterPipeline::WINDOW, 3),
        ("window r=10", FilterPipeline::WINDOW, 10),
        ("atrous=5", "atrous=5".parse().expect("valid"), 2),
    ];
    let mut prepared = Vec::new();
    for (name, pipeline, radius) in forms {
        let t = Instant::now();
        let kernel = jit::compile_shaped(&expr, KernelKind::Filter, LowerOptions::ALL, jit::Shape::of(&pipeline))?;
        let lower_validate = ms(t.elapsed());
        let mut buffers = SceneBuffers::for_pipeline(gpu, &frame, &pipeline)?;
        let t = Instant::now();
        gpu.filter(&kernel, &mut buffers, &frame, radius)?;
        prepared.push((name, kernel, buffers, radius, lower_validate, ms(t.elapsed())));
    }
    let mut times = vec![Vec::new(); prepared.len()];
    for _ in 0..repeats.max(1) * 2 {
        for (k, (_, kernel, buffers, radius, _, _)) in prepared.iter_mut().enumerate() {
            times[k].push(ms(gpu.filter(kernel, buffers, &frame, *radius)?.dispatch));
        }
    }
    for ((name, _, _, _, lower_validate, compile_ms), times) in prepared.into_iter().zip(times) {
        let warm_ms = stat(times);
        results.push(StageResult {
            stage: name.into(),
            lower_validate_ms: Some(lower_validate),
            compile_ms,
            ms_per_mpx: warm_ms.median / mpx,
            warm_ms,
        });
    }
    Ok(results)
}

/// Every shipped filter stored with an à-trous pipeline, as a whole frame
/// of [`FRAME_SIDE`]² (the bench scene tiled): the pre-pass's dispatch (the
/// frame's buffers prepared afresh each round, uploads not counted) plus
/// every pass of the form, in interleaved rounds; then OIDN colour + albedo
/// + normal on the same frame, where its program is found.
fn whole_frames(
    gpu: &Gpu,
    scene: &Scene,
    repeats: usize,
    peer: Option<&crate::report::oidn::Oidn>,
) -> anyhow::Result<Vec<FrameResult>> {
    let frame = crate::report::tile(scene, FRAME_SIDE);
    let mpx = frame.pixels() as f64 / 1e6;
    let shipped: Vec<(String, Expr, crate::pipeline::FilterPipeline)> = crate::corpus::named()
        .into_iter()
        .filter_map(|(name, text)| {
            let pipeline = crate::corpus::pipeline_of(crate::corpus::EXPRESSIONS, name)?.ok()?;
            pipeline.is_atrous().then(|| Ok((name.to_string(), parse_expr(text)?, pipeline)))
        })
        .collect::<anyhow::Result<_>>()?;
    let radius = 2;
    let mut prepared = Vec::new();
    for (name, expr, pipeline) in &shipped {
        let t = Instant::now();
        let kernel = jit::compile_shaped(expr, KernelKind::Filter, LowerOptions::ALL, jit::Shape::of(pipeline))?;
        let mut buffers = SceneBuffers::for_pipeline(gpu, &frame, pipeline)?;
        gpu.filter(&kernel, &mut buffers, &frame, radius)?;
        prepared.push((name, pipeline, kernel, ms(t.elapsed())));
    }
    let mut times = vec![Vec::new(); prepared.len()];
    for _ in 0..repeats.max(1) * 2 {
        for (k, (_, pipeline, kernel, _)) in prepared.iter().enumerate() {
            let mut buffers = SceneBuffers::for_pipeline(gpu, &frame, pipeline)?;
            let prepass = buffers.prepass_time().unwrap_or_default();
            times[k].push(ms(prepass + gpu.filter(kernel, &mut buffers, &frame, radius)?.dispatch));
        }
    }
    let oidn = match peer {
        Some(oidn) => {
            let dir = std::env::temp_dir().join(format!("filterjit-bench-oidn-{}", std::process::id()));
            let denoised = oidn.denoise(&frame, crate::report::oidn::Auxiliary::AlbedoNormal, repeats.max(1) * 2, &dir);
            let _ = std::fs::remove_dir_all(&dir);
            Some(stat(denoised?.warm_ms))
        }
        None => None,
    };
    let over = |median: f64| oidn.as_ref().map(|o| median / o.median);
    let mut results: Vec<FrameResult> = prepared
        .into_iter()
        .zip(times)
        .map(|((name, pipeline, _, compile_ms), times)| {
            let warm_ms = stat(times);
            FrameResult {
                method: format!("@{name}"),
                pipeline: pipeline.to_string(),
                compile_ms: Some(compile_ms),
                ms_per_mpx: warm_ms.median / mpx,
                over_oidn: over(warm_ms.median),
                warm_ms,
            }
        })
        .collect();
    if let Some(warm_ms) = oidn {
        results.push(FrameResult {
            method: "OIDN colour+albedo+normal (CPU)".into(),
            pipeline: "-".into(),
            compile_ms: None,
            ms_per_mpx: warm_ms.median / mpx,
            over_oidn: Some(1.0),
            warm_ms,
        });
    }
    Ok(results)
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
    let kernels: Vec<jit::ValidatedKernel> = exprs.iter().map(jit::compile).collect::<Result<_, _>>()?;
    let refs: Vec<&jit::ValidatedKernel> = kernels.iter().collect();
    for k in &refs {
        gpu.filter(k, buffers, scene, radius)?;
    }
    let rounds = repeats.max(3) * 2;
    let warm: Vec<f64> =
        interleaved(gpu, &refs, buffers, scene, radius, rounds)?.into_iter().map(|s| s.median).collect();
    let constant_near = stat(
        (0..rounds)
            .map(|_| Ok(ms(gpu.filter(&kernels[1], buffers, scene, 1)?.dispatch)))
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

/// Whether two scorings agree bit for bit (NaN included).
fn bit_identical(a: &[crate::evolve::ScoredErrors], b: &[crate::evolve::ScoredErrors]) -> bool {
    let key = |s: &crate::evolve::ScoredErrors| match s {
        Ok(errors) => Ok(errors.iter().map(|e| (e.relmse.to_bits(), e.flags, e.finite)).collect::<Vec<_>>()),
        Err(reason) => Err(reason.clone()),
    };
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| key(x) == key(y))
}

pub fn table(r: &Report) -> String {
    let mut t = String::new();
    t += &format!(
        "device  {}\nscene   {} ({}x{}), radius {}, {} repeats per figure (median [min, max])\n\n",
        r.device, r.scene, r.width, r.height, r.settings.radius, r.settings.repeats
    );
    t += "compile latency and throughput per expression (ms)\n";
    t += &format!(
        "{:>4} {:>7} {:>8} {:>9} {:>9} {:>10} {:>10} {:>11} {:>9} {:>10}\n",
        "len", "lower", "validate", "pipeline", "1st disp", "jit", "jit plain", "interpreter", "interp/jit", "Gops/s"
    );
    for e in &r.expressions {
        t += &format!(
            "{:>4} {:>7.2} {:>8.2} {:>9.2} {:>9.1} {:>10.2} {:>10.2} {:>11} {:>9} {:>10.2}\n",
            e.length,
            e.lower_ms,
            e.validate_ms,
            e.pipeline_ms,
            e.first_dispatch_ms,
            e.jit_ms.median,
            e.jit_plain_ms.median,
            e.interpreter_ms.as_ref().map_or("-".into(), |s| format!("{:.2}", s.median)),
            e.interpreter_ratio.map_or("-".into(), |x| format!("{x:.1}x")),
            e.gp_ops_per_second / 1e9
        );
    }
    t += &format!(
        "\nmedian: interpreter / JIT {:.1}x; unoptimised / optimised {:.2}x; {:.3} G weights/s; {:.2} G GP ops/s\n",
        r.interpreter_ratio_median,
        r.optimisation_ratio_median,
        r.weights_per_second_median / 1e9,
        r.gp_ops_per_second_median / 1e9
    );
    t += "what each optimisation is worth (median over the corpus of the variant's time / the default kernel's):\n";
    for (name, ratio) in &r.variant_ratio_median {
        let meaning = if name.starts_with('-') { "without" } else { "with" };
        t += &format!("  {name:<13} {ratio:.3}x  ({meaning} {})\n", name.trim_start_matches(['-', '+']));
    }
    let p = &r.population;
    t += &format!(
        "\npopulation of {} ({} distinct) compiled together: lower+validate {:.0} ms, pipelines {:.0} ms, first evaluation {:.0} ms => {:.2} ms per individual\n",
        p.individuals, p.distinct, p.lower_validate_ms, p.pipelines_ms, p.first_evaluation_ms, p.per_individual_ms
    );
    t += &format!(
        "  trusted modules (no run-time checks, the default) {:.2} ms per individual; with wgpu's checks {:.2} ms ({:.2}x)\n",
        p.per_individual_ms,
        p.checked_per_individual_ms,
        p.checked_per_individual_ms / p.per_individual_ms
    );
    t += &format!(
        "  as evolve scores them (every queue): a kernel per individual {:.2} ms per individual; {} per kernel {:.2} ms ({:.2}x faster; results {})\n",
        p.evolve_single_per_individual_ms,
        p.fused_members,
        p.evolve_fused_per_individual_ms,
        p.evolve_single_per_individual_ms / p.evolve_fused_per_individual_ms,
        if p.fused_identical { "identical" } else { "DIFFER" }
    );
    let c = &r.calibration;
    t += "\ncost model measured here (units: the operators' weights add up to the operator table's; `evolve --cost-model bench.json`):\n ";
    for (name, w) in &r.cost_model.operators {
        t += &format!(" {name} {w:.1}");
    }
    t += &format!(
        "; tap {:.1}\n  rank correlation with the corpus's warm times: operator table {:.3}, measured {:.3}\n",
        r.cost_model.tap, c.table_rank_correlation, c.measured_rank_correlation
    );
    let h = &r.handwritten;
    t += &format!(
        "\nbilateral: hand-written {:.3} ms, generated {:.3} ms ({:.2}x), generated with tiles {:.3} ms ({:.2}x), generated unoptimised {:.3} ms ({:.2}x)\n",
        h.handwritten_ms.median,
        h.generated_ms.median,
        h.ratio,
        h.generated_tiled_ms.median,
        h.tiled_ratio,
        h.generated_plain_ms.median,
        h.plain_ratio
    );
    if !r.simplified.is_empty() {
        t += "\nsimplified against raw (warm dispatch, ms):\n";
        for s in &r.simplified {
            t += &format!(
                "  length {:>3} -> {:>3}: {:.3} -> {:.3} ({:.2}x)\n",
                s.raw_length, s.simplified_length, s.raw_ms.median, s.simplified_ms.median, s.ratio
            );
        }
    }
    if !r.stages.is_empty() {
        t += &format!(
            "\npipeline stages and forms, one {FRAME_SIDE}x{FRAME_SIDE} frame (@crossBilateral; warm median, ms):\n"
        );
        t += &format!(
            "  {:<32} {:>12} {:>12} {:>10} {:>10}\n",
            "stage", "lower+val ms", "compile ms", "warm ms", "ms/Mpx"
        );
        for s in &r.stages {
            t += &format!(
                "  {:<32} {:>12} {:>12.1} {:>10.2} {:>10.1}\n",
                s.stage,
                s.lower_validate_ms.map_or("-".into(), |v| format!("{v:.2}")),
                s.compile_ms,
                s.warm_ms.median,
                s.ms_per_mpx
            );
        }
    }
    if !r.frames.is_empty() {
        t += &format!(
            "\nwhole frames, {FRAME_SIDE}x{FRAME_SIDE} (shipped a-trous filters: device time of pre-pass + passes; OIDN: CPU wall time; warm median [min, max], ms):\n"
        );
        t += &format!(
            "  {:<34} {:<32} {:>10} {:>22} {:>10} {:>8}\n",
            "method", "pipeline", "compile ms", "warm ms", "ms/Mpx", "/ OIDN"
        );
        for f in &r.frames {
            t += &format!(
                "  {:<34} {:<32} {:>10} {:>22} {:>10.1} {:>8}\n",
                f.method,
                f.pipeline,
                f.compile_ms.map_or("-".into(), |v| format!("{v:.1}")),
                format!("{:.2} [{:.2}, {:.2}]", f.warm_ms.median, f.warm_ms.min, f.warm_ms.max),
                f.ms_per_mpx,
                f.over_oidn.map_or("-".into(), |v| format!("{v:.2}x")),
            );
        }
        if !r.frames.iter().any(|f| f.compile_ms.is_none()) {
            t += "  (OIDN's oidnDenoise not found: FILTERJIT_OIDN, PATH or `pip install pyoidn`)\n";
        }
    }
    if !r.generations.is_empty() {
        t += "\none GP generation (this device) next to the thesis's Table 4.1 (GTX 980 Ti, population 200: another machine)\n";
        t += &format!(
            "{:>8} {:>6} {:>10} {:>10} {:>8} {:>9}   {:>12} {:>12}\n",
            "size", "pop", "compile s", "evaluate s", "gp s", "total s", "thesis GPU s", "thesis CPU s"
        );
        for g in &r.generations {
            let thesis = THESIS_TABLE_4_1.iter().find(|(s, ..)| *s == g.size);
            t += &format!(
                "{:>8} {:>6} {:>10.2} {:>10.2} {:>8.3} {:>9.2}   {:>12} {:>12}\n",
                format!("{0}x{0}", g.size),
                g.population,
                g.compile_s,
                g.evaluate_s,
                g.gp_s,
                g.total_s,
                thesis.map_or("-".into(), |t| format!("{:.3}", t.1)),
                thesis.map_or("-".into(), |t| format!("{:.1}", t.2))
            );
        }
    }
    t
}
