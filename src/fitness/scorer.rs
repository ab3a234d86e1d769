//! The device scorer: relMSE of many expressions on many scenes (or their
//! fitness tiles) in few submissions, spread over one device per core on
//! software adapters, and the fitness the search sees.

use std::collections::BTreeSet;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};

use crate::gp::{self, EvalTime, Evaluator, Fitness};
use crate::gpu::{FitnessScene, Gpu, GpuError, SceneScore};
use crate::jit;
use crate::lang::Expr;
use crate::scene::Scene;

use super::invalid::Invalid;
use super::pool::{self, Counted, Pooling};
use super::rule::Pool;
use super::settings::Settings;
use super::tiles;

/// One expression's relMSE per scene with its domain flags, or why it could not be scored.
pub type ScoredErrors = std::result::Result<Vec<SceneScore>, Invalid>;

/// Fitness of expressions on a set of scenes, on the GPU.
pub struct Scorer<'g> {
    gpu: &'g Gpu,
    /// Further devices on the same adapter, opened by the scorer: software
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
    /// Each scene's noisy input's mean luminance over the same pixels: the
    /// light a candidate's is measured against where the rule charges it.
    noisy_luminance: Vec<f64>,
    /// What each scene's relMSE is divided by before the scenes are pooled:
    /// `noisy`, or a baseline's relMSE on the same pixels (`settings.rule`).
    divisors: Vec<f64>,
    settings: Settings,
    /// How fitness kernels are lowered: every optimisation, and workgroup
    /// tiles for the run's radius where `settings.workgroup_tiles` says.
    options: jit::LowerOptions,
    /// Expressions per fitness kernel on this device.
    fuse: usize,
    time: EvalTime,
}

impl<'g> Scorer<'g> {
    /// A scorer of `scenes` (each with a reference) on `gpu` as `settings`
    /// say; a fitness baseline is scored here, once, on the same pixels and
    /// through the same pipeline as every candidate will be.
    pub fn new(gpu: &'g Gpu, scenes: Vec<Scene>, settings: &Settings) -> Result<Self> {
        for s in &scenes {
            s.reference.as_ref().with_context(|| format!("scene `{}` has no reference image", s.name))?;
        }
        let (radius, pipeline) = (settings.radius, &settings.pipeline);
        let (tiles, counted, pooling): (Option<Vec<Scene>>, Vec<Counted>, Option<Pooling>) = match settings.tiles {
            None => (None, vec![None; scenes.len()], None),
            Some(draw) => {
                let tiles = tiles::cut(&scenes, draw.sampling, pipeline, radius, draw.seed);
                let pooling = tiles.iter().map(|t| (t.scene, t.pixels() as f64)).collect();
                let (crops, counted) = tiles.into_iter().map(|t| (t.crop, t.counted)).unzip();
                (Some(crops), counted, Some(pooling))
            }
        };
        let scored = tiles.as_deref().unwrap_or(&scenes);
        let mut more = Vec::new();
        for _ in 1..settings.devices_on(gpu) {
            more.push(Gpu::open_like(gpu)?);
        }
        let mut device_scenes = Vec::new();
        for device in std::iter::once(gpu).chain(more.iter()) {
            let mut on_device = Vec::new();
            for (s, region) in scored.iter().zip(&counted) {
                let fs = FitnessScene::for_pipeline(device, s, pipeline)?;
                on_device.push(match region {
                    Some(regions) => fs.counting(regions.clone()),
                    None => fs,
                });
            }
            device_scenes.push(on_device);
        }
        let noisy_errors = pool::noisy_per_scene(scored, &counted, pooling.as_ref(), scenes.len());
        let noisy: Vec<f64> = noisy_errors.iter().map(|e| e.relmse).collect();
        let options = jit::LowerOptions {
            tile_radius: settings.workgroup_tiles.enabled(gpu).then_some(radius),
            ..jit::LowerOptions::ALL
        };
        let mut scorer = Scorer {
            gpu,
            more,
            scenes,
            tiles,
            pooling,
            device_scenes,
            divisors: noisy.clone(),
            noisy,
            noisy_luminance: noisy_errors.iter().map(|e| e.luminance).collect(),
            settings: settings.clone(),
            options,
            fuse: settings.fusion.members(gpu),
            time: EvalTime::default(),
        };
        if let Some(text) = &settings.rule.relative_to {
            scorer.divisors = scorer.baseline_errors(text)?;
        }
        Ok(scorer)
    }

    /// The fitness baseline's error per scene (charged as the rule says), which candidates' are divided by.
    fn baseline_errors(&mut self, text: &str) -> Result<Vec<f64>> {
        let baseline = crate::lang::parse_expr(text).map_err(|e| anyhow::anyhow!("fitness baseline:\n{e}"))?;
        let scored = self.errors(std::slice::from_ref(&baseline))?.pop().expect("one result");
        let per_scene = scored.map_err(|reason| anyhow::anyhow!("the fitness baseline `{text}` {reason}"))?;
        let flags = domain_flags(&per_scene);
        if flags != 0 {
            bail!(
                "the fitness baseline `{text}` raises domain errors: {}",
                crate::semantics::flag::describe(flags).join("; ")
            );
        }
        if let Some((scene, _)) = self.scenes.iter().zip(&per_scene).find(|(_, e)| !e.finite || !e.relmse.is_finite()) {
            bail!("the fitness baseline `{text}` has no finite error on scene `{}`", scene.name);
        }
        Ok(self.charged(&per_scene))
    }

    /// Each scene's error as the rule counts it: relMSE, charged for the
    /// light moved where the rule says so.
    fn charged(&self, per_scene: &[SceneScore]) -> Vec<f64> {
        let tolerance = self.settings.rule.light_tolerance;
        per_scene
            .iter()
            .zip(&self.noisy_luminance)
            .map(|(e, noisy)| super::rule::charged(e.relmse, e.luminance, *noisy, tolerance))
            .collect()
    }

    /// Each scene's light moved by a candidate: its mean luminance over the
    /// noisy input's on the scored pixels (`None` where the input is black).
    pub fn light_moved(&self, per_scene: &[SceneScore]) -> Vec<Option<f64>> {
        per_scene.iter().zip(&self.noisy_luminance).map(|(e, n)| super::rule::light_moved(e.luminance, *n)).collect()
    }

    /// The settings the scorer was made with.
    pub fn settings(&self) -> &Settings {
        &self.settings
    }

    /// The radius expressions are scored at when they carry none.
    pub fn radius(&self) -> u32 {
        self.settings.radius
    }

    pub fn scenes(&self) -> &[Scene] {
        &self.scenes
    }

    /// relMSE of every expression on every scene (`[expr][scene]`), with
    /// domain-error bits; `Err(reason)` for an expression that does not
    /// compile or that this device cannot run (more inputs than it allows
    /// storage buffers).
    pub fn errors(&mut self, exprs: &[Expr]) -> Result<Vec<ScoredErrors>> {
        self.errors_at(exprs, self.settings.radius)
    }

    /// [`Scorer::errors`] of each expression at its own radius.
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

    /// [`Scorer::errors`] with a `radius` window (tiles, where on, made for it).
    fn errors_at(&mut self, exprs: &[Expr], radius: u32) -> Result<Vec<ScoredErrors>> {
        let mut options = self.options;
        options.tile_radius = options.tile_radius.map(|_| radius);
        let start = Instant::now();
        let threads = self.settings.threads.max(1);
        let shape = jit::Shape::of(&self.settings.pipeline);
        let (kernels, unsupported) = super::batch::kernels(self.gpu, exprs, self.fuse, options, shape, threads);
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
        type DeviceResult = Result<(Duration, Vec<Vec<SceneScore>>), GpuError>;
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
        let mut evaluated = evaluated.into_iter().map(|row| match &self.pooling {
            None => row,
            Some(pooling) => pool::pool_errors(&row, pooling, self.scenes.len()),
        });
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

    pub fn noisy_relmse(&self) -> &[f64] {
        &self.noisy
    }

    /// Each whole scene's filtered output's light, `expr` at `radius`
    /// through the scorer's pipeline on its first device: the mean luminance
    /// over the reference's ([`crate::metrics::light`]; `None` for a black reference).
    pub fn light(&self, expr: &Expr, radius: u32) -> Result<Vec<Option<f64>>> {
        let pipeline = &self.settings.pipeline;
        let shape = jit::Shape::of(pipeline);
        let kernel = jit::compile(expr, jit::KernelSpec { shape, ..jit::KernelSpec::default() })?;
        self.scenes
            .iter()
            .map(|scene| {
                let mut buffers = crate::gpu::SceneBuffers::for_pipeline(self.gpu, scene, pipeline)?;
                let filtered = self.gpu.filter(&kernel, &mut buffers, scene, radius)?;
                let reference = scene.reference.as_ref().expect("scored scenes have references");
                Ok(crate::metrics::light(&filtered.rgb(), reference))
            })
            .collect()
    }

    /// Each scene's noisy input's light.
    pub fn noisy_light(&self) -> Vec<Option<f64>> {
        self.scenes
            .iter()
            .map(|s| crate::metrics::light(&s.color, s.reference.as_ref().expect("scored scenes have references")))
            .collect()
    }

    /// The scenes, whole (the scorer's buffers are freed).
    pub fn into_scenes(self) -> Vec<Scene> {
        self.scenes
    }

    /// Whether fitness is scored on tiles rather than whole scenes.
    pub fn on_tiles_only(&self) -> bool {
        self.pooling.is_some()
    }

    /// The fitness of one expression's per-scene errors (or of the reason it has none).
    pub fn fitness(&self, result: &ScoredErrors) -> Result<f64, Invalid> {
        let per_scene = result.as_ref().map_err(Clone::clone)?;
        let flags = domain_flags(per_scene);
        if flags != 0 {
            return Err(Invalid::DomainError(flags));
        }
        if per_scene.iter().any(|e| !e.finite || !e.relmse.is_finite()) {
            return Err(Invalid::NonFinite);
        }
        Ok(self.settings.rule.pool.combine(self.charged(per_scene), &self.divisors))
    }
}

/// The thesis's fitness (section 3.2.3): the mean over scenes of relMSE /
/// the noisy input's relMSE. Training fitness and test results both use it.
pub fn normalised_error(per_scene: &[SceneScore], noisy: &[f64]) -> f64 {
    Pool::Mean.combine(per_scene.iter().map(|e| e.relmse), noisy)
}

/// Every domain-error bit raised on any scene.
pub fn domain_flags(per_scene: &[SceneScore]) -> u32 {
    per_scene.iter().fold(0, |a, e| a | e.flags)
}

/// The search's view: a candidate's fitness, its reason as text where it has
/// none (the boundary where [`Invalid`] becomes words), and its modelled cost.
impl Evaluator for Scorer<'_> {
    fn evaluate(&mut self, candidates: &[gp::Candidate]) -> Result<Vec<Fitness>> {
        let radius = self.settings.radius;
        let at: Vec<(Expr, u32)> = candidates.iter().map(|c| (c.expr.clone(), c.radius.unwrap_or(radius))).collect();
        let errors = self.errors_each(&at)?;
        Ok(errors
            .iter()
            .zip(&at)
            .map(|(result, (expr, radius))| {
                // Beside the rule's value, the error against the noisy input's: whether it filters at all.
                let fitness = match (self.fitness(result), result) {
                    (Ok(value), Ok(per_scene)) => {
                        Fitness::valid(value).with_versus_noisy(normalised_error(per_scene, &self.noisy))
                    }
                    (Err(reason), _) => Fitness::invalid(reason.to_string()),
                    (Ok(_), Err(_)) => unreachable!("a fitness is made of a candidate's errors"),
                };
                let settings = &self.settings;
                fitness.with_cost(crate::cost::model_with(expr, &settings.pipeline, *radius, &settings.cost_model))
            })
            .collect())
    }

    fn take_time(&mut self) -> EvalTime {
        std::mem::take(&mut self.time)
    }
}
