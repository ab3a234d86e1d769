//! `filterjit evolve`: the GP engine wired to scenes and to the JIT. Each
//! individual is compiled into its own fitness kernel; fitness is reduced on
//! the device; the run checkpoints every generation.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};

use crate::datasets;
use crate::fitness_rule::{FitnessRule, Pool};
use crate::fitness_tiles::{self, TileSampling};
use crate::gp::transport::{InProcess, Transport};
use crate::gp::{self, EvalTime, Evaluator, Fitness, Settings, State};
use crate::gpu::{FitnessScene, Gpu};
use crate::jit::{self, KernelKind};
use crate::lang::{Expr, Feature, ScalarVar};
use crate::pipeline::FilterPipeline;
use crate::render::{self, RenderSettings};
use crate::scene::Scene;
use crate::{metrics, semantics};

/// For each tile, the scene it was cut from and how many pixels it counts.
type Pooling = Vec<(usize, f64)>;

/// Fitness of expressions on a set of scenes, on the GPU.
pub struct GpuEvaluator<'g> {
    gpu: &'g Gpu,
    /// Further devices on the same adapter, opened by the evaluator: software
    /// drivers compile a pipeline at its first dispatch on their queue's
    /// thread, so a queue per core compiles a generation's kernels in parallel.
    more: Vec<Gpu>,
    scenes: Vec<Scene>,
    /// With fitness tiles, what the kernels run on instead of `scenes`.
    tiles: Option<Vec<Scene>>,
    /// With fitness tiles, the scene each tile was cut from and the pixels
    /// it counts: a scene's error pools its tiles'.
    pooling: Option<Pooling>,
    /// What is scored on each device, `gpu` first.
    device_scenes: Vec<Vec<FitnessScene>>,
    /// relMSE of each scene's noisy input (over its tiles' interiors, with
    /// tiles): fitness divides by it (thesis 3.2.3).
    noisy: Vec<f64>,
    /// What each scene's relMSE is divided by before the scenes are pooled:
    /// `noisy`, or a baseline's relMSE on the same pixels ([`FitnessRule`]).
    divisors: Vec<f64>,
    pool: Pool,
    radius: u32,
    /// The pipeline around every kernel; the scenes' buffers are prepared for it.
    pipeline: FilterPipeline,
    threads: usize,
    /// How fitness kernels are lowered: every optimisation, and workgroup
    /// tiles for the run's radius on hardware adapters ([`Tiles::Auto`]).
    options: jit::LowerOptions,
    /// Expressions per fitness kernel ([`Fusion`]).
    fuse: usize,
    /// The weights of the modelled cost (multi-objective searches).
    cost_model: crate::cost::CostModel,
    time: EvalTime,
}

impl<'g> GpuEvaluator<'g> {
    /// An evaluator on `gpu`, plus one device per further core when `gpu` is a software adapter.
    pub fn new(gpu: &'g Gpu, scenes: Vec<Scene>, radius: u32, threads: usize) -> Result<Self> {
        Self::for_pipeline(gpu, scenes, radius, FilterPipeline::WINDOW, threads)
    }

    /// An evaluator that scores every expression through `pipeline` (`radius` is the window form's).
    pub fn for_pipeline(
        gpu: &'g Gpu,
        scenes: Vec<Scene>,
        radius: u32,
        pipeline: FilterPipeline,
        threads: usize,
    ) -> Result<Self> {
        let devices = if gpu.is_software() { threads.max(1) } else { 1 };
        Self::with_devices(gpu, scenes, radius, pipeline, threads, devices)
    }

    /// An evaluator spreading each batch over `devices` devices (at least one, `gpu`).
    pub fn with_devices(
        gpu: &'g Gpu,
        scenes: Vec<Scene>,
        radius: u32,
        pipeline: FilterPipeline,
        threads: usize,
        devices: usize,
    ) -> Result<Self> {
        Self::build(gpu, scenes, None, radius, pipeline, threads, devices)
    }

    /// An evaluator that scores each scene on the tiles `sampling` draws
    /// from `seed` ([`crate::fitness_tiles`]); a scene's error is its tiles'
    /// interiors' together.
    pub fn on_tiles(
        gpu: &'g Gpu,
        scenes: Vec<Scene>,
        sampling: TileSampling,
        seed: u64,
        radius: u32,
        pipeline: FilterPipeline,
        threads: usize,
    ) -> Result<Self> {
        let devices = if gpu.is_software() { threads.max(1) } else { 1 };
        Self::build(gpu, scenes, Some((sampling, seed)), radius, pipeline, threads, devices)
    }

    fn build(
        gpu: &'g Gpu,
        scenes: Vec<Scene>,
        tiles: Option<(TileSampling, u64)>,
        radius: u32,
        pipeline: FilterPipeline,
        threads: usize,
        devices: usize,
    ) -> Result<Self> {
        for s in &scenes {
            s.reference.as_ref().with_context(|| format!("scene `{}` has no reference image", s.name))?;
        }
        let (tiles, counted, pooling): (Option<Vec<Scene>>, Vec<Option<crate::gpu::Region>>, Option<Pooling>) =
            match tiles {
                None => (None, vec![None; scenes.len()], None),
                Some((sampling, seed)) => {
                    let tiles = fitness_tiles::cut(&scenes, sampling, &pipeline, radius, seed);
                    let pooling = tiles.iter().map(|t| (t.scene, t.pixels() as f64)).collect();
                    let counted = tiles.iter().map(|t| t.counted).collect();
                    (Some(tiles.into_iter().map(|t| t.crop).collect()), counted, Some(pooling))
                }
            };
        let scored = tiles.as_deref().unwrap_or(&scenes);
        let mut more = Vec::new();
        for _ in 1..devices.max(1) {
            more.push(Gpu::open_like(gpu)?);
        }
        let mut device_scenes = Vec::new();
        for device in std::iter::once(gpu).chain(more.iter()) {
            let mut on_device = Vec::new();
            for (s, region) in scored.iter().zip(&counted) {
                let fs = FitnessScene::for_pipeline(device, s, &pipeline)?;
                on_device.push(match region {
                    Some(region) => fs.counting(*region),
                    None => fs,
                });
            }
            device_scenes.push(on_device);
        }
        // The noisy input's relMSE over exactly the pixels that count, pooled as errors are (`pooled`).
        let noisy: Vec<f64> = match &pooling {
            None => scored.iter().map(|s| noisy_relmse(s, None)).collect(),
            Some(pooling) => {
                let mut sums = vec![(0.0f64, 0.0f64); scenes.len()];
                for ((s, region), (owner, pixels)) in scored.iter().zip(&counted).zip(pooling) {
                    sums[*owner].0 += noisy_relmse(s, *region) * pixels;
                    sums[*owner].1 += pixels;
                }
                sums.iter().map(|(sum, n)| sum / n).collect()
            }
        };
        let mut evaluator = GpuEvaluator {
            gpu,
            more,
            scenes,
            tiles,
            pooling,
            device_scenes,
            divisors: noisy.clone(),
            noisy,
            pool: Pool::Mean,
            radius,
            pipeline,
            threads,
            options: jit::LowerOptions::ALL,
            fuse: 1,
            cost_model: crate::cost::CostModel::table(),
            time: EvalTime::default(),
        };
        evaluator.set_tiles(Tiles::Auto.enabled(gpu));
        evaluator.set_fusion(Fusion::Auto);
        Ok(evaluator)
    }

    /// Lower fitness kernels with workgroup tiles or without.
    pub fn set_tiles(&mut self, on: bool) {
        self.options.tile_radius = on.then_some(self.radius);
    }

    /// Score candidates by `rule`; a baseline is scored here, once, on the
    /// same pixels and through the same pipeline as every candidate.
    pub fn set_fitness_rule(&mut self, rule: &FitnessRule) -> Result<()> {
        self.pool = rule.pool;
        self.divisors = match &rule.relative_to {
            None => self.noisy.clone(),
            Some(text) => {
                let baseline = crate::lang::parse_expr(text).map_err(|e| anyhow::anyhow!("fitness baseline:\n{e}"))?;
                let scored = self.errors(std::slice::from_ref(&baseline))?.pop().expect("one result");
                let per_scene = scored.map_err(|reason| anyhow::anyhow!("the fitness baseline `{text}` {reason}"))?;
                let flags = domain_flags(&per_scene);
                if flags != 0 {
                    bail!(
                        "the fitness baseline `{text}` raises domain errors: {}",
                        semantics::flag::describe(flags).join("; ")
                    );
                }
                if let Some((scene, _)) =
                    self.scenes.iter().zip(&per_scene).find(|(_, e)| !e.finite || !e.relmse.is_finite())
                {
                    bail!("the fitness baseline `{text}` has no finite error on scene `{}`", scene.name);
                }
                per_scene.iter().map(|e| e.relmse).collect()
            }
        };
        Ok(())
    }

    /// The weights each candidate's modelled cost is computed with.
    pub fn set_cost_model(&mut self, model: crate::cost::CostModel) {
        self.cost_model = model;
    }

    /// How many expressions each fitness kernel scores (results are identical either way).
    pub fn set_fusion(&mut self, fusion: Fusion) {
        self.fuse = fusion.members(self.gpu);
    }

    /// The radius expressions are scored at when they carry none.
    pub fn radius(&self) -> u32 {
        self.radius
    }

    pub fn scenes(&self) -> &[Scene] {
        &self.scenes
    }

    /// relMSE of every expression on every scene (`[expr][scene]`), with
    /// domain-error bits; `Err(reason)` for an expression that does not
    /// compile or that this device cannot run (more inputs than it allows
    /// storage buffers).
    pub fn errors(&mut self, exprs: &[Expr]) -> Result<Vec<ScoredErrors>> {
        self.errors_at(exprs, self.radius)
    }

    /// [`GpuEvaluator::errors`] of each expression at its own radius.
    pub fn errors_each(&mut self, exprs: &[(Expr, u32)]) -> Result<Vec<ScoredErrors>> {
        let radii: BTreeSet<u32> = exprs.iter().map(|(_, r)| *r).collect();
        let mut out: Vec<Option<ScoredErrors>> = vec![None; exprs.len()];
        for radius in radii {
            let (at, group): (Vec<usize>, Vec<Expr>) =
                exprs.iter().enumerate().filter(|(_, (_, r))| *r == radius).map(|(k, (e, _))| (k, e.clone())).unzip();
            for (k, result) in at.into_iter().zip(self.errors_at(&group, radius)?) {
                out[k] = Some(result);
            }
        }
        Ok(out.into_iter().map(|r| r.expect("every expression scored")).collect())
    }

    /// [`GpuEvaluator::errors`] with a `radius` window (tiles, where on, made for it).
    fn errors_at(&mut self, exprs: &[Expr], radius: u32) -> Result<Vec<ScoredErrors>> {
        let mut options = self.options;
        options.tile_radius = options.tile_radius.map(|_| radius);
        let start = Instant::now();
        let threads = self.threads.max(1);
        let shape = jit::Shape::of(&self.pipeline);
        let (kernels, unsupported) = self.fitness_kernels(exprs, options, shape, threads);
        let refs: Vec<&jit::ValidatedKernel> = kernels.iter().collect();
        let devices: Vec<&Gpu> = std::iter::once(self.gpu).chain(self.more.iter()).collect();
        // Contiguous shares, one per device; results come back in order.
        let share = refs.len().div_ceil(devices.len()).max(1);
        let parts: Vec<&[&jit::ValidatedKernel]> = refs.chunks(share).collect();
        for (device, part) in devices.iter().zip(&parts) {
            device.prepare_pipelines(part, threads)?;
        }
        let compiled = start.elapsed();
        let start = Instant::now();
        let data: Vec<&Scene> = self.tiles.as_deref().unwrap_or(&self.scenes).iter().collect();
        type DeviceResult = Result<(Duration, Vec<Vec<crate::gpu::FitnessError>>), crate::gpu::GpuError>;
        let results: Vec<DeviceResult> = std::thread::scope(|s| {
            let handles: Vec<_> = devices
                .iter()
                .zip(self.device_scenes.iter_mut())
                .zip(&parts)
                .map(|((device, scenes), part)| {
                    let data = &data;
                    s.spawn(move || {
                        // The driver's compile first, timed on its own (software drivers compile here).
                        let start = Instant::now();
                        let out = device.prime_fitness(part, scenes, data, radius).and_then(|()| {
                            let primed = start.elapsed();
                            Ok((primed, device.evaluate_fitness(part, scenes, data, radius)?))
                        });
                        // Each generation's kernels are new: the memo keeps their fitness, not
                        // their pipelines. Only this batch's go; what others cached on a shared device stays.
                        let batch: BTreeSet<jit::KernelKey> = part.iter().map(|k| k.key()).collect();
                        device.prune_pipelines(|key| !batch.contains(key));
                        out
                    })
                })
                .collect();
            handles.into_iter().map(|h| h.join().expect("evaluation thread panicked")).collect()
        });
        // Devices work in parallel: the slowest one's compile is the batch's.
        let mut driver_compile = Duration::ZERO;
        let mut evaluated = Vec::with_capacity(refs.len());
        for r in results {
            let (primed, out) = r?;
            driver_compile = driver_compile.max(primed);
            evaluated.extend(out);
        }
        self.time.compile += compiled + driver_compile;
        let mut evaluated = evaluated.into_iter().map(|row| self.pooled(row));
        let out = unsupported
            .into_iter()
            .map(|u| match u {
                Some(reason) => Err(reason),
                None => Ok(evaluated.next().expect("one result per supported kernel")),
            })
            .collect();
        self.time.evaluate += start.elapsed().saturating_sub(driver_compile);
        Ok(out)
    }

    /// The batch's fitness kernels, in order, and why each expression that
    /// has none could not be scored. Expressions are grouped in order into
    /// kernels of up to `fuse` members within the device's binding limit; a
    /// group whose kernel fails is compiled member by member, so that a
    /// candidate that does not compile, or binds more than this device allows,
    /// is an invalid individual with its reason, never a failed batch.
    fn fitness_kernels(
        &self,
        exprs: &[Expr],
        options: jit::LowerOptions,
        shape: jit::Shape,
        threads: usize,
    ) -> (Vec<jit::ValidatedKernel>, Vec<Option<String>>) {
        let limit = self.gpu.storage_buffer_limit();
        let fuse = if shape.atrous { 1 } else { self.fuse.max(1) };
        let mut groups: Vec<Vec<Expr>> = Vec::new();
        for e in exprs {
            let fits = groups.last().is_some_and(|g: &Vec<Expr>| {
                let mut with = g.clone();
                with.push(e.clone());
                let layout = jit::KernelLayout::of_all(&with);
                g.len() < fuse
                    && jit::BindingInterface::of(KernelKind::Fitness, &layout, shape).storage_buffers() <= limit
            });
            match groups.last_mut() {
                Some(g) if fits => g.push(e.clone()),
                _ => groups.push(vec![e.clone()]),
            }
        }
        let kernel_for = |g: &[Expr]| -> std::result::Result<jit::ValidatedKernel, String> {
            let kernel = jit::compile_fused(g, options, shape).map_err(|e| format!("does not compile: {e}"))?;
            self.gpu.check_bindings(&kernel).map_err(|e| e.to_string())?;
            Ok(kernel)
        };
        let compiled = crate::parallel::map(&groups, threads, |g| match kernel_for(g) {
            Ok(kernel) => vec![Ok(kernel)],
            Err(_) if g.len() > 1 => g.iter().map(|e| kernel_for(std::slice::from_ref(e))).collect(),
            Err(reason) => vec![Err(reason)],
        });
        let mut kernels = Vec::new();
        let mut unsupported = Vec::new();
        for result in compiled.into_iter().flatten() {
            match result {
                Ok(k) => {
                    unsupported.extend(std::iter::repeat_n(None, k.source().exprs.len()));
                    kernels.push(k);
                }
                Err(reason) => unsupported.push(Some(reason)),
            }
        }
        (kernels, unsupported)
    }

    pub fn noisy_relmse(&self) -> &[f64] {
        &self.noisy
    }

    /// The scenes, whole (the evaluator's buffers are freed).
    pub fn into_scenes(self) -> Vec<Scene> {
        self.scenes
    }

    /// Whether fitness is scored on tiles rather than whole scenes.
    pub fn on_tiles_only(&self) -> bool {
        self.pooling.is_some()
    }

    /// One error per scene from one per scored image: with tiles, a scene's
    /// relMSE is over all its tiles' counted pixels, its flags any tile's.
    fn pooled(&self, row: Vec<crate::gpu::FitnessError>) -> Vec<crate::gpu::FitnessError> {
        let Some(pooling) = &self.pooling else { return row };
        let mut out = vec![(0.0, 0.0, 0u32, true); self.scenes.len()];
        for (e, (scene, pixels)) in row.iter().zip(pooling) {
            let pooled = &mut out[*scene];
            pooled.0 += e.relmse * pixels;
            pooled.1 += pixels;
            pooled.2 |= e.flags;
            pooled.3 &= e.finite;
        }
        out.into_iter()
            .map(|(sum, n, flags, finite)| crate::gpu::FitnessError { relmse: sum / n, flags, finite })
            .collect()
    }
}

/// The hall of fame's fitness on `whole`'s scenes, member by member.
fn rescore(whole: &mut GpuEvaluator<'_>, hall: &[(usize, gp::StoredMember)]) -> Result<Vec<Rescored>> {
    let mut unique: Vec<&gp::StoredMember> = Vec::new();
    for (_, m) in hall {
        if m.fitness.invalid.is_none() && !unique.iter().any(|u| u.expr == m.expr) {
            unique.push(m);
        }
    }
    let mut at = Vec::new();
    for m in &unique {
        let expr = crate::lang::parse_expr(&m.expr).map_err(|e| anyhow::anyhow!("hall of fame: {e}"))?;
        at.push((expr, m.radius.unwrap_or(whole.radius())));
    }
    let errors = whole.errors_each(&at)?;
    Ok(unique
        .iter()
        .zip(&errors)
        .map(|(m, result)| {
            let fitness = whole.fitness(result);
            Rescored {
                expr: m.expr.clone(),
                fitness_on_tiles: m.fitness.value,
                fitness: fitness.invalid.is_none().then_some(fitness.value),
                invalid: fitness.invalid.clone(),
            }
        })
        .collect())
}

/// relMSE of a scene's noisy input against its reference, over `region` (all of it when `None`).
fn noisy_relmse(scene: &Scene, region: Option<crate::gpu::Region>) -> f64 {
    let reference = scene.reference.as_ref().expect("fitness scenes have references");
    let Some(r) = region else { return metrics::errors(&scene.color, reference, scene.spp).relmse };
    // Only the two images the error reads, not a crop of every feature.
    let inside = |image: &[[f32; 3]]| -> Vec<[f32; 3]> {
        let (x, width) = (r.x as usize, r.width as usize);
        (r.y as usize..(r.y + r.height) as usize)
            .flat_map(|row| image[row * scene.width + x..row * scene.width + x + width].iter().copied())
            .collect()
    };
    metrics::errors(&inside(&scene.color), &inside(reference), scene.spp).relmse
}

/// The thesis's fitness (section 3.2.3): the mean over scenes of relMSE /
/// the noisy input's relMSE. Training fitness and test results both use it.
pub fn normalised_error(per_scene: &[crate::gpu::FitnessError], noisy: &[f64]) -> f64 {
    Pool::Mean.combine(per_scene.iter().map(|e| e.relmse), noisy)
}

/// Every domain-error bit raised on any scene.
pub fn domain_flags(per_scene: &[crate::gpu::FitnessError]) -> u32 {
    per_scene.iter().fold(0, |a, e| a | e.flags)
}

/// One expression's relMSE per scene with its domain flags, or why it could not be scored.
pub type ScoredErrors = std::result::Result<Vec<crate::gpu::FitnessError>, String>;

impl Evaluator for GpuEvaluator<'_> {
    fn evaluate(&mut self, candidates: &[gp::Candidate]) -> Result<Vec<Fitness>> {
        let at: Vec<(Expr, u32)> =
            candidates.iter().map(|c| (c.expr.clone(), c.radius.unwrap_or(self.radius))).collect();
        let errors = self.errors_each(&at)?;
        Ok(errors
            .iter()
            .zip(&at)
            .map(|(result, (expr, radius))| {
                self.fitness(result).with_cost(crate::cost::model_with(expr, &self.pipeline, *radius, &self.cost_model))
            })
            .collect())
    }

    fn take_time(&mut self) -> EvalTime {
        std::mem::take(&mut self.time)
    }
}

impl GpuEvaluator<'_> {
    /// The fitness of one expression's per-scene errors (or of the reason it has none).
    fn fitness(&self, result: &ScoredErrors) -> Fitness {
        let per_scene = match result {
            Ok(per_scene) => per_scene,
            Err(reason) => return Fitness::invalid(reason.clone()),
        };
        let flags = domain_flags(per_scene);
        if flags != 0 {
            return Fitness::invalid(format!("domain error: {}", semantics::flag::describe(flags).join("; ")));
        }
        if per_scene.iter().any(|e| !e.finite || !e.relmse.is_finite()) {
            return Fitness::invalid("non-finite error");
        }
        Fitness::valid(self.pool.combine(per_scene.iter().map(|e| e.relmse), &self.divisors))
    }
}

/// The checkpoint file: the state after a generation, and what produced it.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Checkpoint {
    pub version: u32,
    pub settings: Settings,
    pub run: RunConfig,
    pub state: State,
}

/// The run's inputs besides the GP settings; a resumed run must match them.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunConfig {
    pub training: Vec<String>,
    pub test: Vec<String>,
    pub render: RenderSettings,
    pub radius: u32,
    pub seed_expr: String,
    /// The pipeline every individual is scored through (runs made before pipelines existed: `window`).
    #[serde(default)]
    pub pipeline: FilterPipeline,
    /// The weights of the modelled cost a multi-objective search trades
    /// against error (runs made before it existed: the operator table's).
    #[serde(default)]
    pub cost_model: crate::cost::CostModel,
    /// Fitness on tiles of each training scene instead of whole images
    /// ([`crate::fitness_tiles`]; runs made before tiles existed: whole images).
    #[serde(default)]
    pub fitness_tiles: Option<TileSampling>,
    /// Only these features and variances are terminals (all the training
    /// scenes provide when `None`): a filter meant for renders with fewer
    /// channels than the training scenes must not learn to read the others.
    /// By name, as written in expressions.
    #[serde(default)]
    pub features: Option<BTreeSet<String>>,
    /// How per-scene errors become the training fitness (runs made before
    /// it existed: the thesis's mean of relMSE / noisy relMSE).
    #[serde(default)]
    pub fitness: FitnessRule,
}

impl RunConfig {
    /// What the training fitness in the log and the hall of fame is measured on.
    pub fn scored_on(&self) -> String {
        match self.fitness_tiles {
            None => self.scored_on_whole_images(),
            Some(t) => {
                format!("{} tiles of {}x{} pixels per training scene{}", t.count, t.size, t.size, self.rule_note())
            }
        }
    }

    /// What the hall of fame's rescoring is measured on.
    pub fn scored_on_whole_images(&self) -> String {
        format!("whole training images{}", self.rule_note())
    }

    /// The fitness rule where it is not the thesis's.
    fn rule_note(&self) -> String {
        if self.fitness.is_thesis() {
            String::new()
        } else {
            format!("; {}", self.fitness.describe())
        }
    }
}

pub const CHECKPOINT_FILE: &str = "checkpoint.json";
pub const LOG_FILE: &str = "log.jsonl";
pub const HALL_OF_FAME_FILE: &str = "hall_of_fame.txt";
pub const FEATURES_FILE: &str = "features.json";
pub const SUMMARY_FILE: &str = "summary.json";

pub fn write_checkpoint(dir: &Path, checkpoint: &Checkpoint) -> Result<()> {
    let text = serde_json::to_string(checkpoint)?;
    crate::io::write_bytes_atomically(&dir.join(CHECKPOINT_FILE), text.as_bytes()).map_err(anyhow::Error::from)
}

pub fn read_checkpoint(dir: &Path) -> Result<Checkpoint> {
    let path = dir.join(CHECKPOINT_FILE);
    let text = std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    let checkpoint: Checkpoint =
        serde_json::from_str(&text).with_context(|| format!("{} is not a filterjit checkpoint", path.display()))?;
    if checkpoint.version != 1 {
        bail!("{}: checkpoint version {} is not supported", path.display(), checkpoint.version);
    }
    Ok(checkpoint)
}

/// The log keeps one JSON line per generation; rewrite it to end at `generation`
/// (a resumed run may have logged generations after its last checkpoint).
pub fn log_upto(dir: &Path, generation: u32) -> Result<()> {
    let path = dir.join(LOG_FILE);
    let Ok(text) = std::fs::read_to_string(&path) else { return Ok(()) };
    let kept: String = text
        .lines()
        .filter(|l| {
            serde_json::from_str::<serde_json::Value>(l)
                .ok()
                .and_then(|v| v["generation"].as_u64())
                .is_some_and(|g| g <= generation as u64)
        })
        .map(|l| format!("{l}\n"))
        .collect();
    crate::io::write_bytes_atomically(&path, kept.as_bytes()).map_err(anyhow::Error::from)
}

/// One generation's line: the report, and what its fitness was measured on.
pub fn append_log(dir: &Path, report: &gp::Report, scored_on: &str) -> Result<()> {
    let mut line = serde_json::to_value(report)?;
    line["scored_on"] = scored_on.into();
    append_log_line(dir, &line)
}

fn append_log_line(dir: &Path, line: &serde_json::Value) -> Result<()> {
    use std::io::Write;
    let mut file = std::fs::OpenOptions::new().create(true).append(true).open(dir.join(LOG_FILE))?;
    writeln!(file, "{}", serde_json::to_string(line)?)?;
    Ok(())
}

/// A hall-of-fame member scored again on whole training images, after a run on tiles.
#[derive(Clone, Debug, Serialize)]
pub struct Rescored {
    pub expr: String,
    /// Its fitness on the run's tiles.
    pub fitness_on_tiles: f64,
    /// Its fitness on the whole training images (`None`: invalid there, with the reason in `invalid`).
    pub fitness: Option<f64>,
    pub invalid: Option<String>,
}

/// The hall of fame in the named-expression format `filter --expr @FILE` reads;
/// a multi-objective run's front follows as `front1` (cheapest) … `frontN`.
/// `rescored`, after a run on tiles: each member's fitness on whole training
/// images, which then orders the entries (the first is the one to use).
pub fn hall_of_fame_text(
    state: &State,
    k: usize,
    pipeline: &FilterPipeline,
    rule: &FitnessRule,
    front: &[gp::StoredMember],
    rescored: &[Rescored],
) -> String {
    let mut text = String::from("# filterjit hall of fame: the best expressions of every island, best first.\n# Use one with `filterjit filter --expr @hall_of_fame.txt:NAME` (the first without :NAME);\n# it is filtered through the pipeline it was scored with:\n");
    text.push_str(&format!("{} {pipeline}\n", crate::corpus::PIPELINE_PREFIX));
    text.push_str(&format!("# fitness: {}\n", rule.describe()));
    if !rescored.is_empty() {
        text.push_str("# The search scored fitness on tiles; `fitness` below is on the whole training images.\n");
    }
    let whole = |expr: &str| rescored.iter().find(|r| r.expr == expr).map(|r| r.fitness.unwrap_or(f64::INFINITY));
    let mut entries = gp::hall_of_fame(state, k);
    entries.sort_by(|a, b| {
        let key = |m: &gp::StoredMember| whole(&m.expr).unwrap_or(m.fitness.value);
        key(&a.1).total_cmp(&key(&b.1))
    });
    let mut rank_in_island = vec![0usize; state.islands.len()];
    for (island, m) in entries {
        rank_in_island[island] += 1;
        let parsed = crate::lang::parse_expr(&m.expr).ok();
        let len = parsed.as_ref().map_or(0, |e| e.len());
        let fitness = match (&m.fitness.invalid, rescored.iter().find(|r| r.expr == m.expr)) {
            (Some(reason), _) => format!("invalid ({reason})"),
            (None, Some(r)) => match (r.fitness, &r.invalid) {
                (Some(f), _) => format!("{f:.6} (on tiles {:.6})", r.fitness_on_tiles),
                (None, reason) => format!("invalid on whole images ({})", reason.as_deref().unwrap_or("?")),
            },
            (None, None) => format!("{:.6}", m.fitness.value),
        };
        text.push_str(&format!("# fitness {fitness}, length {len}\n"));
        if let Some(simplified) = parsed.map(|e| crate::simplify::simplify(&e)) {
            // Beside the raw form that was scored: the same weights, for people.
            text.push_str(&format!("# simplified (length {}): {simplified}\n", simplified.len()));
        }
        if let Some(r) = m.radius {
            text.push_str(&format!("{} {r}\n", crate::corpus::RADIUS_PREFIX));
        }
        text.push_str(&format!("island{island}_rank{} = {}\n", rank_in_island[island], m.expr));
    }
    if !front.is_empty() {
        text.push_str("#\n# The front of (error, modelled cost per pixel), cheapest first: no member is both\n# more accurate and cheaper than another (pareto.json has their measured times).\n");
        for (n, m) in front.iter().enumerate() {
            let cost = m.fitness.cost.unwrap_or(0.0);
            text.push_str(&format!("# fitness {:.6}, cost {cost:.0}\n", m.fitness.value));
            if let Some(r) = m.radius {
                text.push_str(&format!("{} {r}\n", crate::corpus::RADIUS_PREFIX));
            }
            text.push_str(&format!("front{} = {}\n", n + 1, m.expr));
        }
    }
    text
}

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

/// Time each filter through `pipeline` on `scene`: one warm-up, then the median of `repeats`, in ms per megapixel.
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
            let kernel = jit::compile_shaped(e, KernelKind::Filter, jit::LowerOptions::ALL, shape)?;
            gpu.filter(&kernel, &mut buffers, scene, radius)?;
            let mut times: Vec<f64> = (0..repeats.max(1))
                .map(|_| Ok(gpu.filter(&kernel, &mut buffers, scene, radius)?.dispatch.as_secs_f64()))
                .collect::<Result<_>>()?;
            times.sort_by(f64::total_cmp);
            Ok(times[times.len() / 2] * 1e3 / mpx)
        })
        .collect()
}

/// The front scored on the test scenes and timed on the first of them, tiled.
fn measure_front(
    gpu: &Gpu,
    tester: &mut GpuEvaluator<'_>,
    front: &[gp::StoredMember],
    config: &RunConfig,
) -> Result<Front> {
    let exprs: Vec<(Expr, u32)> = front
        .iter()
        .map(|m| {
            let e = crate::lang::parse_expr(&m.expr).map_err(|e| anyhow::anyhow!("{e}"))?;
            Ok((e, m.radius.unwrap_or(config.radius)))
        })
        .collect::<Result<_>>()?;
    let tested = test_each(tester, &exprs)?;
    let timing_scene = crate::report::tile(&tester.scenes()[0], FRONT_TIMING_SIDE);
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

/// Test-set results of one expression.
#[derive(Clone, Debug, Serialize)]
pub struct TestResult {
    pub expr: String,
    /// relMSE per test scene (equation 3.5 without m/2).
    pub relmse: Vec<f64>,
    /// Mean over test scenes of relMSE / noisy relMSE.
    pub normalised: f64,
    pub invalid: Option<String>,
}

/// What a finished run reports.
#[derive(Clone, Debug, Serialize)]
pub struct Summary {
    pub generations: u32,
    /// What `best.fitness` (the search's training fitness) was measured on.
    pub training_scored_on: String,
    /// After a run on tiles: the hall of fame on whole training images
    /// (`best` is the best of it there); empty otherwise.
    pub rescored_hall_of_fame: Vec<Rescored>,
    pub best: gp::StoredMember,
    /// The best expression simplified (the same weights; what `export` and `report` use).
    pub best_simplified: String,
    pub test_scenes: Vec<String>,
    pub test_noisy_relmse: Vec<f64>,
    pub test_best: TestResult,
    pub test_seed: TestResult,
    /// Other filters on the same test scenes, for comparison (those whose features the scenes have).
    pub test_baselines: Vec<TestResult>,
    pub feature_frequencies: std::collections::BTreeMap<String, usize>,
    pub seconds: f64,
}

/// Evaluate expressions on test scenes.
pub fn test(evaluator: &mut GpuEvaluator<'_>, exprs: &[Expr]) -> Result<Vec<TestResult>> {
    let radius = evaluator.radius();
    test_each(evaluator, &exprs.iter().map(|e| (e.clone(), radius)).collect::<Vec<_>>())
}

/// Evaluate expressions on test scenes, each at its own radius.
pub fn test_each(evaluator: &mut GpuEvaluator<'_>, exprs: &[(Expr, u32)]) -> Result<Vec<TestResult>> {
    let errors = evaluator.errors_each(exprs)?;
    let noisy = evaluator.noisy_relmse().to_vec();
    Ok(exprs
        .iter()
        .map(|(e, _)| e)
        .zip(errors)
        .map(|(e, result)| {
            let per_scene = match result {
                Ok(per_scene) => per_scene,
                Err(reason) => {
                    return TestResult {
                        expr: e.to_string(),
                        relmse: vec![f64::NAN; noisy.len()],
                        normalised: f64::NAN,
                        invalid: Some(reason),
                    }
                }
            };
            let flags = domain_flags(&per_scene);
            TestResult {
                expr: e.to_string(),
                relmse: per_scene.iter().map(|s| s.relmse).collect(),
                normalised: normalised_error(&per_scene, &noisy),
                invalid: (flags != 0).then(|| semantics::flag::describe(flags).join("; ")),
            }
        })
        .collect())
}

/// Everything `run` needs.
pub struct RunOptions<'a> {
    pub settings: Settings,
    pub config: RunConfig,
    pub output: PathBuf,
    pub resume: bool,
    pub threads: usize,
    /// Stop after this many generations in this process (for tests of resuming); `None` runs to the end.
    pub stop_after: Option<u32>,
    pub on_report: &'a mut dyn FnMut(&gp::Report),
    pub on_render: render::Progress<'a>,
    /// Expressions to compare with on the test scenes (they do not affect the search).
    pub baselines: Vec<Expr>,
    /// Whether fitness kernels stage their windows in workgroup memory
    /// (results are identical either way; only the time differs).
    pub tiles: Tiles,
    /// How many individuals each fitness kernel scores (identical results).
    pub fusion: Fusion,
    /// Where built-in and .toml scenes are rendered to and found again.
    pub cache: PathBuf,
}

/// When fitness kernels get workgroup tiles.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum Tiles {
    /// On hardware adapters; off on software ones, whose compilers make
    /// barriers expensive (`filterjit bench` shows it: docs/BENCHMARKS.md).
    #[default]
    Auto,
    On,
    Off,
}

impl Tiles {
    pub fn enabled(self, gpu: &Gpu) -> bool {
        match self {
            Tiles::Auto => !gpu.is_software(),
            Tiles::On => true,
            Tiles::Off => false,
        }
    }
}

/// How many individuals one fitness kernel scores. Fitness is the same
/// either way (tests/evolve.rs); only the driver's compile time differs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Fusion {
    /// [`FUSED_ON_SOFTWARE`] on software adapters, whose compile cost is per
    /// module and grows with its size more slowly than linearly; one per
    /// kernel on hardware, which compiles fast and runs each kernel apart.
    #[default]
    Auto,
    /// This many per kernel (1: a kernel per individual, the thesis's design).
    Members(usize),
}

/// Individuals per fitness kernel on software adapters, by measurement
/// (docs/BENCHMARKS.md, "Fused fitness kernels").
pub const FUSED_ON_SOFTWARE: usize = 12;

impl Fusion {
    pub fn members(self, gpu: &Gpu) -> usize {
        match self {
            Fusion::Auto if gpu.is_software() => FUSED_ON_SOFTWARE,
            Fusion::Auto => 1,
            Fusion::Members(n) => n.max(1),
        }
    }
}

impl std::str::FromStr for Fusion {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "auto" => Ok(Fusion::Auto),
            n => match n.parse::<usize>() {
                Ok(n) if n >= 1 => Ok(Fusion::Members(n)),
                _ => Err(format!("`{s}` is not `auto` or a number of individuals per kernel (1 or more)")),
            },
        }
    }
}

/// Where `filterjit evolve` writes when no run directory is named.
pub const DEFAULT_RUN_DIR: &str = "runs/evolve";

/// The run directory used when none is named: `base` itself, or, once it holds
/// a run, the first of `base-2`, `base-3`, … that does not, so that running
/// the same command twice starts a second run instead of stopping at an error.
/// With `resume`, the newest of them that holds a run (or `base`).
pub fn default_run_dir(base: &Path, resume: bool) -> PathBuf {
    let numbered = |n: u32| match n {
        1 => base.to_path_buf(),
        n => {
            let mut name = base.file_name().unwrap_or_default().to_os_string();
            name.push(format!("-{n}"));
            base.with_file_name(name)
        }
    };
    let holds_run = |dir: &Path| dir.join(CHECKPOINT_FILE).is_file();
    let first_free = (1..).find(|&n| !holds_run(&numbered(n))).expect("some number is free");
    if resume && first_free > 1 {
        numbered(first_free - 1)
    } else {
        numbered(first_free)
    }
}

/// Run (or resume) a search in this process; returns the summary when the last generation is done.
pub fn run(gpu: &Gpu, options: RunOptions<'_>) -> Result<Option<Summary>> {
    run_with(gpu, options, &mut InProcess)
}

/// The state to resume from, if any, after checking the run directory: the root's job.
fn prepare_run_dir(output: &Path, resume: bool, settings: &Settings, config: &RunConfig) -> Result<Option<State>> {
    std::fs::create_dir_all(output).with_context(|| format!("creating {}", output.display()))?;
    crate::io::remove_stale_temporaries(output);
    let existing = output.join(CHECKPOINT_FILE).is_file();
    match (existing, resume) {
        (true, true) => {
            let checkpoint = read_checkpoint(output)?;
            if checkpoint.settings != *settings || checkpoint.run != *config {
                bail!(
                    "{} was made with other settings or scenes; resume with the same flags, or choose another --output",
                    output.join(CHECKPOINT_FILE).display()
                );
            }
            log_upto(output, checkpoint.state.generation)?;
            Ok(Some(checkpoint.state))
        }
        (true, false) => {
            bail!("{} holds a run already; pass --resume to continue it, or choose another --output", output.display())
        }
        (false, true) => bail!("nothing to resume: {} has no {CHECKPOINT_FILE}", output.display()),
        (false, false) => {
            let _ = std::fs::remove_file(output.join(LOG_FILE));
            Ok(None)
        }
    }
}

/// Run (or resume) a search whose islands are shared among the processes
/// `transport` reaches (docs/DISTRIBUTED.md). Every process calls this with
/// the same options. Only the root (rank 0) touches the run directory:
/// it checkpoints the whole population each generation, writes the log, the
/// hall of fame and the summary, and scores the test scenes; it returns the
/// summary, the others `None`.
pub fn run_with(gpu: &Gpu, options: RunOptions<'_>, transport: &mut dyn Transport) -> Result<Option<Summary>> {
    let start = Instant::now();
    let RunOptions {
        settings,
        config,
        output,
        resume,
        threads,
        stop_after,
        on_report,
        on_render,
        baselines,
        tiles,
        fusion,
        cache,
    } = options;
    settings.check().map_err(anyhow::Error::msg)?;
    let root = transport.is_root();
    let resumed = if root { prepare_run_dir(&output, resume, &settings, &config)? } else { None };
    let resumed: Option<State> = serde_json::from_slice(&transport.broadcast(serde_json::to_vec(&resumed)?)?)?;

    // The root renders missing scenes into the cache first; the others then
    // find them there (or, on a node that does not share it, render their own).
    let mut training = Vec::new();
    if root {
        training = datasets::resolve(gpu, &config.training, &config.render, &cache, &mut *on_render)?;
    }
    transport.barrier();
    if !root {
        training = datasets::resolve(gpu, &config.training, &config.render, &cache, &mut *on_render)?;
    }
    let (mut features, mut variances) = datasets::common_terminals(&training)?;
    if let Some(names) = &config.features {
        let (mut allowed, mut allowed_variances) = (BTreeSet::new(), BTreeSet::new());
        for name in names {
            let provided = match (Feature::from_name(name), ScalarVar::from_name(name)) {
                // What the outlier rule measured comes with the pipeline, not the scenes.
                (None, Some(v)) if v.from_prepass() => {
                    if config.pipeline.outliers.is_none() {
                        bail!("--features names `{name}`, which the outlier pre-pass measures: add `outliers=K` to --pipeline");
                    }
                    true
                }
                (Some(f), _) => features.contains(&f) && allowed.insert(f),
                (None, Some(v)) => variances.contains(&v) && allowed_variances.insert(v),
                (None, None) => bail!("--features names `{name}`, which is no feature or variance"),
            };
            if !provided {
                bail!("--features names `{name}`, which the training scenes do not all provide");
            }
        }
        features.retain(|f| allowed.contains(f));
        variances.retain(|v| allowed_variances.contains(v));
    }
    let seed_expr = crate::lang::parse_expr(&config.seed_expr).map_err(|e| anyhow::anyhow!("seed expression:\n{e}"))?;
    for f in seed_expr.features() {
        if !features.contains(&f) {
            bail!("the seed expression reads `{f}`, which the training scenes do not all provide");
        }
    }
    let scenes = datasets::load_all(&training, &features, &variances, &config.pipeline)?;
    let mut evaluator = match config.fitness_tiles {
        None => GpuEvaluator::for_pipeline(gpu, scenes, config.radius, config.pipeline, threads)?,
        Some(sampling) => {
            GpuEvaluator::on_tiles(gpu, scenes, sampling, settings.seed, config.radius, config.pipeline, threads)?
        }
    };
    evaluator.set_cost_model(config.cost_model.clone());
    evaluator.set_tiles(tiles.enabled(gpu));
    evaluator.set_fusion(fusion);
    evaluator.set_fitness_rule(&config.fitness)?;
    // `level` (the à-trous pass) is a terminal where there are passes: a filter may change with scale.
    let level = config.pipeline.is_atrous().then_some(ScalarVar::Level);
    // What the outlier rule measured, where the pipeline has it: a weight may adapt to fireflies.
    let measures = config.pipeline.outliers.map(|_| ScalarVar::FROM_PREPASS).into_iter().flatten();
    let terminals = gp::operators::Terminals {
        features: features.iter().copied().collect(),
        variables: variances.iter().copied().chain(level).chain(measures).collect(),
        constants: crate::lang::ops::THESIS_CONSTANTS.to_vec(),
    };
    let mut engine = gp::Engine::with_transport(
        settings.clone(),
        terminals,
        seed_expr.clone(),
        &mut evaluator,
        Box::new(transport),
    )?;
    // Trading error for cost, a window's radius is the largest lever: it evolves too (up to the run's).
    if settings.objectives == gp::Objectives::ErrorCost && config.pipeline.form == crate::pipeline::Form::Window {
        engine.set_radii(1..=config.radius);
    }

    // A generation is done once it is logged and checkpointed, in that order: a
    // resumed run drops log lines past its checkpoint.
    let mut record = |state: &State, report: &gp::Report| -> Result<()> {
        append_log(&output, report, &config.scored_on())?;
        write_checkpoint(
            &output,
            &Checkpoint { version: 1, settings: settings.clone(), run: config.clone(), state: state.clone() },
        )?;
        on_report(report);
        Ok(())
    };
    // Only the root holds the whole population.
    let mut state = match resumed {
        Some(state) => {
            engine.resume(&state)?;
            Some(state)
        }
        None => engine.initial()?.map(|(state, report)| record(&state, &report).map(|()| state)).transpose()?,
    };
    let mut done_here = 0;
    while engine.generation().expect("a generation is done") < settings.generations {
        if stop_after.is_some_and(|n| done_here >= n) {
            return Ok(None);
        }
        if let Some((next, report)) = engine.step()? {
            record(&next, &report)?;
            state = Some(next);
        }
        done_here += 1;
    }
    drop(engine);
    // The others end here: the run directory, the hall of fame and the test scenes are the root's.
    let Some(state) = state.filter(|_| root) else { return Ok(None) };

    // Fitness on tiles picked the hall of fame; whole images say which of it is best.
    let rescored = if evaluator.on_tiles_only() {
        let mut whole =
            GpuEvaluator::for_pipeline(gpu, evaluator.into_scenes(), config.radius, config.pipeline, threads)?;
        whole.set_cost_model(config.cost_model.clone());
        whole.set_tiles(tiles.enabled(gpu));
        whole.set_fusion(fusion);
        whole.set_fitness_rule(&config.fitness)?;
        let rescored = rescore(&mut whole, &gp::hall_of_fame(&state, settings.hall_of_fame))?;
        append_log_line(
            &output,
            &serde_json::json!({
                "generation": state.generation,
                "scored_on": config.scored_on_whole_images(),
                "rescored_hall_of_fame": rescored,
            }),
        )?;
        rescored
    } else {
        drop(evaluator);
        Vec::new()
    };
    let front = match settings.objectives {
        gp::Objectives::Error => Vec::new(),
        gp::Objectives::ErrorCost => gp::pareto_front(&state),
    };
    let hall = hall_of_fame_text(&state, settings.hall_of_fame, &config.pipeline, &config.fitness, &front, &rescored);
    crate::io::write_bytes_atomically(&output.join(HALL_OF_FAME_FILE), hall.as_bytes())?;
    let frequencies = gp::feature_frequencies(&state);
    crate::io::write_bytes_atomically(
        &output.join(FEATURES_FILE),
        serde_json::to_string_pretty(&frequencies)?.as_bytes(),
    )?;
    let best_whole = rescored.iter().filter_map(|r| r.fitness.map(|f| (f, r))).min_by(|a, b| a.0.total_cmp(&b.0));
    let best = match best_whole.map(|(_, r)| r) {
        Some(r) => gp::hall_of_fame(&state, settings.hall_of_fame)
            .into_iter()
            .map(|(_, m)| m)
            .find(|m| m.expr == r.expr)
            .expect("rescored members are the hall of fame's"),
        None => gp::hall_of_fame(&state, 1)
            .into_iter()
            .map(|(_, m)| m)
            .min_by(|a, b| a.fitness.value.total_cmp(&b.fitness.value))
            .expect("a non-empty population"),
    };

    let test_sets = datasets::resolve(gpu, &config.test, &config.render, &cache, &mut *on_render)?;
    let test_scenes = datasets::load_all(&test_sets, &features, &variances, &config.pipeline)?;
    let names = test_scenes.iter().map(|s| s.name.clone()).collect();
    let mut tester = GpuEvaluator::for_pipeline(gpu, test_scenes, config.radius, config.pipeline, threads)?;
    let best_expr = crate::lang::parse_expr(&best.expr).map_err(|e| anyhow::anyhow!("{e}"))?;
    let mut compared = vec![best_expr, seed_expr];
    compared.extend(
        baselines
            .into_iter()
            .filter(|b| b.features().is_subset(&features) && b.stored_variables().is_subset(&variances)),
    );
    let mut results = test(&mut tester, &compared)?.into_iter();
    let test_best = results.next().expect("best");
    let test_seed = results.next().expect("seed");
    let test_baselines = results.collect();
    if !front.is_empty() {
        let front = measure_front(gpu, &mut tester, &front, &config)?;
        crate::io::write_bytes_atomically(&output.join(FRONT_FILE), serde_json::to_string_pretty(&front)?.as_bytes())?;
    }
    let summary = Summary {
        generations: state.generation,
        training_scored_on: config.scored_on(),
        rescored_hall_of_fame: rescored,
        best_simplified: crate::simplify::simplify(&compared[0]).to_string(),
        best,
        test_scenes: names,
        test_noisy_relmse: tester.noisy_relmse().to_vec(),
        test_best,
        test_seed,
        test_baselines,
        feature_frequencies: frequencies,
        seconds: start.elapsed().as_secs_f64(),
    };
    crate::io::write_bytes_atomically(&output.join(SUMMARY_FILE), serde_json::to_string_pretty(&summary)?.as_bytes())?;
    Ok(Some(summary))
}
