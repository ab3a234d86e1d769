//! `filterjit report`: error and speed of filters side by side, on scenes
//! with references, written into one folder with an index.
//!
//! For every scene and method: relMSE (both variants), MSE, pixels with
//! domain errors, and the filter's device time per megapixel (median of
//! repeated frames after a warm-up that compiles the pipeline: the pre-pass,
//! if the pipeline has one, and every pass of the form). Then
//! tables (Markdown, CSV, JSON), time-against-error scatter plots with the
//! Pareto front (SVG), tone-mapped crops (PNG), a chart of feature usage, and
//! `index.html` tying them together.

mod pages;
pub mod plot;
pub mod sequence;

use pages::file_name;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use serde::Serialize;

use crate::gpu::{Gpu, SceneBuffers};
use crate::lang::Expr;
use crate::pipeline::FilterPipeline;
use crate::scene::{self, Request, Scene};
use crate::tune::Tuned;
use crate::{io, jit, metrics, oidn, preview};

/// Where a method comes from, for the reader of the report.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Origin {
    /// The unfiltered input.
    Noisy,
    /// The cross-bilateral filter with tuned constant sigmas.
    Baseline,
    /// Published in the thesis.
    Thesis,
    /// Given on the command line or taken from a hall of fame.
    Given,
    /// What a user would pick instead: Intel Open Image Denoise (CPU wall time).
    Peer,
}

/// A filter to compare.
#[derive(Clone, Debug)]
pub struct Method {
    pub name: String,
    pub origin: Origin,
    pub expr: Expr,
    /// The pipeline the expression is filtered through.
    pub pipeline: FilterPipeline,
    /// Its own window radius (a front member's); `None`: the report's.
    pub radius: Option<u32>,
    /// What runs in its place on a scene whose light is sparse, and the
    /// rule that says where, as `filter` runs a role asked for by name
    /// ([`crate::denoise::asked_variant`]).
    pub sparse_light_variant: Option<(Box<Method>, &'static crate::denoise::SparseLightVariant)>,
}

#[derive(Clone, Debug)]
pub struct Settings {
    pub radius: u32,
    /// Timed dispatches per filter and scene (after one warm-up).
    pub repeats: usize,
    /// Side of the square crops, in pixels.
    pub crop: usize,
    /// Times are taken on the scene tiled to at least this many pixels per
    /// side: on a small image a dispatch's fixed cost would hide the filter's.
    pub timing_size: usize,
}

/// One method on one scene.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Cell {
    pub scene: String,
    pub method: String,
    pub relmse: Option<f64>,
    /// relMSE × m/2 (thesis equation 3.5 as printed), where m is known.
    pub relmse_half_spp: Option<f64>,
    pub mse: Option<f64>,
    /// Mean HDR-FLIP against the reference ([`crate::flip`]): what a person sees, in [0, 1].
    pub flip: Option<f64>,
    /// The output's mean luminance over the reference's ([`metrics::light`]):
    /// 1 keeps the image's light; a denoiser must not change it.
    pub light: Option<f64>,
    /// relMSE / the noisy input's relMSE.
    pub normalised: Option<f64>,
    /// relMSE / the peer's (OIDN colour+albedo+normal) on the same scene, where OIDN ran.
    pub vs_peer: Option<f64>,
    /// Median device time per megapixel, milliseconds; none for the noisy input.
    pub ms_per_mpx: Option<f64>,
    /// Fastest and slowest of the timed repeats.
    pub ms_per_mpx_range: Option<(f64, f64)>,
    pub flagged_pixels: usize,
    /// Why the method did not run on this scene (a feature the scene lacks).
    pub unavailable: Option<String>,
    /// The sparse-light variant that ran in the method's place on this scene.
    pub ran_instead: Option<String>,
}

#[derive(Clone, Debug, Serialize)]
pub struct MethodInfo {
    pub name: String,
    pub origin: Origin,
    pub expr: Option<String>,
    pub length: Option<usize>,
    pub pipeline: Option<String>,
    /// Means over the scenes it ran on.
    pub mean_relmse: Option<f64>,
    pub mean_flip: Option<f64>,
    pub mean_light: Option<f64>,
    /// The scene whose light this method changes most, and its ratio there.
    pub worst_light: Option<(String, f64)>,
    pub mean_normalised: Option<f64>,
    /// Mean relMSE / the peer's mean relMSE over the same scenes, where OIDN ran on all of them.
    pub mean_vs_peer: Option<f64>,
    pub mean_ms_per_mpx: Option<f64>,
    pub scenes_run: usize,
    /// The sparse-light variant that ran in its place on some scenes.
    pub ran_instead: Option<RanInstead>,
}

/// A role's sparse-light variant, where it ran in the role's place ([`Method::sparse_light_variant`]).
#[derive(Clone, Debug, Serialize)]
pub struct RanInstead {
    pub name: String,
    pub expr: String,
    pub length: usize,
    pub pipeline: String,
    /// The scenes it ran on.
    pub scenes: usize,
}

#[derive(Clone, Debug, Serialize)]
pub struct SceneInfo {
    pub name: String,
    pub path: String,
    pub width: usize,
    pub height: usize,
    pub spp: Option<u32>,
    /// Crop origin and size, pixels.
    pub crop: [usize; 3],
}

/// Everything measured; `results.json`.
#[derive(Clone, Debug, Serialize)]
pub struct Results {
    pub generator: String,
    pub device: String,
    pub radius: u32,
    pub repeats: usize,
    pub scenes: Vec<SceneInfo>,
    pub methods: Vec<MethodInfo>,
    pub cells: Vec<Cell>,
    pub baseline: Option<Tuned>,
    /// Feature counts over the hall of fame's expressions, when one was given.
    pub feature_usage: Option<BTreeMap<String, usize>>,
}

pub const NOISY: &str = "noisy";

/// What a report is made of.
pub struct Inputs<'a> {
    /// Datasets with references.
    pub scenes: &'a [PathBuf],
    pub methods: &'a [Method],
    pub settings: Settings,
    /// How the baseline among `methods` was tuned, when it was.
    pub baseline: Option<Tuned>,
    /// Expressions of a hall of fame, for the feature-usage chart.
    pub hall_of_fame: Option<&'a [Expr]>,
    /// OIDN, when found: two more methods on every scene.
    pub oidn: Option<&'a oidn::Oidn>,
}

/// Measure the methods on the scenes and write the report into `output`.
pub fn run(gpu: &Gpu, inputs: Inputs<'_>, output: &Path, progress: &mut dyn FnMut(&str)) -> Result<Results> {
    let Inputs { scenes, methods, settings, baseline, hall_of_fame, oidn } = inputs;
    let settings = &settings;
    std::fs::create_dir_all(output).with_context(|| format!("creating {}", output.display()))?;
    io::remove_stale_temporaries(output);
    let mut results = Results {
        generator: format!("filterjit {}", env!("CARGO_PKG_VERSION")),
        device: gpu.describe(),
        radius: settings.radius,
        repeats: settings.repeats,
        scenes: Vec::new(),
        methods: Vec::new(),
        cells: Vec::new(),
        baseline,
        feature_usage: hall_of_fame.map(feature_usage),
    };
    let compile = |m: &Method| {
        let shape = jit::Shape::of(&m.pipeline);
        jit::compile(&m.expr, jit::KernelSpec { shape, ..jit::KernelSpec::default() }).with_context(|| m.name.clone())
    };
    // Each method's kernel, and its sparse-light variant's where it has one.
    let kernels: Vec<(jit::ValidatedKernel, Option<jit::ValidatedKernel>)> = methods
        .iter()
        .map(|m| Ok((compile(m)?, m.sparse_light_variant.as_ref().map(|(v, _)| compile(v)).transpose()?)))
        .collect::<Result<_>>()?;
    for path in scenes {
        let (provided, provided_variances) =
            scene::provides(path, None).with_context(|| format!("reading {}", path.display()))?;
        let runnable = |e: &Expr| {
            let missing: Vec<String> = e
                .features()
                .into_iter()
                .filter(|f| !provided.contains(f))
                .map(|f| f.to_string())
                .chain(
                    e.stored_variables().into_iter().filter(|v| !provided_variances.contains(v)).map(|v| v.to_string()),
                )
                .collect();
            if missing.is_empty() {
                None
            } else {
                Some(format!("the scene has no {}", missing.join(", ")))
            }
        };
        let mut request = Request { reference: true, ..Default::default() };
        let variants = methods.iter().filter_map(|m| m.sparse_light_variant.as_ref().map(|(v, _)| &**v));
        for m in methods.iter().chain(variants).filter(|m| runnable(&m.expr).is_none()) {
            request.features.extend(m.expr.features());
            request.features.extend(m.pipeline.features());
            request.variances.extend(m.expr.stored_variables());
            request.albedo |= m.pipeline.demodulate;
        }
        if oidn.is_some() && provided.contains(&crate::lang::Feature::Texture) {
            request.albedo = true;
            request.features.insert(crate::lang::Feature::Normal);
        }
        let scene = scene::load(path, &request).with_context(|| format!("loading {}", path.display()))?;
        let reference = scene
            .reference
            .clone()
            .with_context(|| format!("{} has no reference image to compare with", path.display()))?;
        progress(&format!("scene {} ({}x{})", scene.name, scene.width, scene.height));
        let crop = crop_window(&scene.color, &reference, scene.width, scene.height, settings.crop);
        let views = Views::new(output, &scene, crop)?;
        let mut strip = vec![views.write("noisy", &scene.color)?];

        let noisy = metrics::errors(&scene.color, &reference, scene.spp);
        let flip = |image: &[[f32; 3]]| crate::flip::hdr_flip(&reference, image, scene.width, scene.height).mean();
        results.cells.push(Cell {
            scene: scene.name.clone(),
            method: NOISY.into(),
            relmse: Some(noisy.relmse),
            relmse_half_spp: noisy.relmse_half_spp,
            mse: Some(noisy.mse),
            flip: Some(flip(&scene.color)),
            light: noisy.light,
            normalised: Some(1.0),
            ..Cell::default()
        });
        let timing_scene = scene.tiled(settings.timing_size);
        // Buffers per pipeline: each pipeline's pre-pass runs once per scene.
        let mut prepared: BTreeMap<String, (SceneBuffers, SceneBuffers, f64)> = BTreeMap::new();
        for (asked, (kernel, variant_kernel)) in methods.iter().zip(&kernels) {
            // A role's variant runs in its place where the light is sparse, under its name.
            let (method, kernel, ran_instead) = match (&asked.sparse_light_variant, variant_kernel) {
                (Some((variant, rule)), Some(k)) if rule.sparse_for(&scene.color).is_some() => {
                    (&**variant, k, Some(variant.name.clone()))
                }
                _ => (asked, kernel, None),
            };
            if let Some(reason) = runnable(&method.expr) {
                results.cells.push(Cell {
                    scene: scene.name.clone(),
                    method: asked.name.clone(),
                    unavailable: Some(reason),
                    ran_instead,
                    ..Cell::default()
                });
                continue;
            }
            match &ran_instead {
                Some(variant) => progress(&format!(
                    "scene {}: {} (as {variant}: its variant for sparse light, as `filter` runs it)",
                    scene.name, asked.name
                )),
                None => progress(&format!("scene {}: {}", scene.name, method.name)),
            }
            let key = method.pipeline.to_string();
            if !prepared.contains_key(&key) {
                let buffers = SceneBuffers::for_pipeline(gpu, &scene, &method.pipeline)?;
                // The pre-pass runs once a frame, whatever the form: its dispatch
                // time, median over as many preparations, joins every filter's.
                let mut preparations = (0..settings.repeats.max(1))
                    .map(|_| SceneBuffers::for_pipeline(gpu, &timing_scene, &method.pipeline))
                    .collect::<Result<Vec<_>, _>>()?;
                let mut prepass_ms: Vec<f64> =
                    preparations.iter().map(|b| b.prepass_time().map_or(0.0, |t| t.wall.as_secs_f64() * 1e3)).collect();
                prepass_ms.sort_by(f64::total_cmp);
                let timing_buffers = preparations.pop().expect("at least one preparation");
                prepared.insert(key.clone(), (buffers, timing_buffers, prepass_ms[prepass_ms.len() / 2]));
            }
            let (buffers, timing_buffers, prepass_ms) = prepared.get_mut(&key).expect("prepared above");
            let buffers = &mut *buffers;
            let mut timing = Timing { scene: &timing_scene, buffers: timing_buffers, prepass_ms: *prepass_ms };
            let (cell, filtered) =
                measure(gpu, kernel, buffers, &scene, &mut timing, &reference, settings, method.radius, noisy.relmse)
                    .with_context(|| format!("filtering {} with {}", scene.name, method.name))?;
            strip.push(views.write(&asked.name, &filtered)?);
            results.cells.push(Cell { method: asked.name.clone(), ran_instead, ..cell });
        }
        if let Some(oidn) = oidn {
            for aux in [oidn::Auxiliary::ColorOnly, oidn::Auxiliary::AlbedoNormal] {
                let name = aux.method_name().to_string();
                if aux == oidn::Auxiliary::AlbedoNormal
                    && (scene.albedo.is_none() || !provided.contains(&crate::lang::Feature::Normal))
                {
                    let unavailable = Some("the scene has no albedo and normal".to_string());
                    results.cells.push(Cell {
                        scene: scene.name.clone(),
                        method: name,
                        unavailable,
                        ..Cell::default()
                    });
                    continue;
                }
                progress(&format!("scene {}: {name}", scene.name));
                let work = output.join("oidn").join(file_name(&scene.name));
                // Timed on the same tiled scene as filterjit's filters; one run when that is the scene itself.
                let timed = oidn.denoise(&timing_scene, aux, settings.repeats.max(1), &work)?;
                let denoised = if timing_scene.pixels() == scene.pixels() {
                    timed.clone()
                } else {
                    oidn.denoise(&scene, aux, 1, &work)?
                };
                let _ = std::fs::remove_dir_all(&work);
                let mut times = timed.warm_ms;
                times.sort_by(f64::total_cmp);
                let mpx = timing_scene.pixels() as f64 / 1e6;
                let e = metrics::errors(&denoised.color, &reference, scene.spp);
                strip.push(views.write(&name, &denoised.color)?);
                results.cells.push(Cell {
                    scene: scene.name.clone(),
                    method: name,
                    relmse: Some(e.relmse),
                    relmse_half_spp: e.relmse_half_spp,
                    mse: Some(e.mse),
                    flip: Some(flip(&denoised.color)),
                    light: e.light,
                    normalised: Some(metrics::normalised(e.relmse, noisy.relmse)),
                    ms_per_mpx: Some(times[times.len() / 2] / mpx),
                    ms_per_mpx_range: Some((times[0] / mpx, times[times.len() - 1] / mpx)),
                    ..Cell::default()
                });
            }
        }
        strip.push(views.write("reference", &reference)?);
        write_strip(&output.join("crops").join(format!("{}.png", file_name(&scene.name))), &strip)?;
        results.scenes.push(SceneInfo {
            name: scene.name.clone(),
            path: path.display().to_string(),
            width: scene.width,
            height: scene.height,
            spp: scene.spp,
            crop: [crop.0, crop.1, crop.2],
        });
    }
    // OIDN's working files went scene by scene; their folder goes too (only if empty).
    let _ = std::fs::remove_dir(output.join("oidn"));
    let peers = oidn.map_or(&[][..], |_| &[oidn::Auxiliary::ColorOnly, oidn::Auxiliary::AlbedoNormal][..]);
    // Every error against the peer a user would pick instead, scene by scene.
    let peer = oidn::Auxiliary::AlbedoNormal.method_name();
    let peer_relmse: BTreeMap<String, f64> =
        results.cells.iter().filter(|c| c.method == peer).filter_map(|c| Some((c.scene.clone(), c.relmse?))).collect();
    for c in &mut results.cells {
        c.vs_peer = c.relmse.zip(peer_relmse.get(&c.scene)).map(|(e, p)| e / p.max(metrics::NOISY_RELMSE_FLOOR));
    }
    results.methods = std::iter::once((NOISY.to_string(), Origin::Noisy, None))
        .chain(methods.iter().map(|m| (m.name.clone(), m.origin, Some(m))))
        .chain(peers.iter().map(|aux| (aux.method_name().to_string(), Origin::Peer, None)))
        .map(|(name, origin, method)| summarise(&results.cells, name, origin, method, &peer_relmse))
        .collect();
    pages::write(&results, output)?;
    Ok(results)
}

fn summarise(
    cells: &[Cell],
    name: String,
    origin: Origin,
    method: Option<&Method>,
    peer_relmse: &BTreeMap<String, f64>,
) -> MethodInfo {
    let expr = method.map(|m| &m.expr);
    let ran: Vec<&Cell> = cells.iter().filter(|c| c.method == name && c.relmse.is_some()).collect();
    let mean = |f: &dyn Fn(&Cell) -> Option<f64>| -> Option<f64> {
        let values: Vec<f64> = ran.iter().filter_map(|c| f(c)).collect();
        (!values.is_empty()).then(|| values.iter().sum::<f64>() / values.len() as f64)
    };
    // The peer's mean over exactly the scenes this method ran on.
    let peer_mean = ran.iter().map(|c| peer_relmse.get(&c.scene).copied()).collect::<Option<Vec<f64>>>();
    let mean_vs_peer = match (mean(&|c| c.relmse), peer_mean) {
        (Some(m), Some(p)) if !p.is_empty() => {
            Some(m / (p.iter().sum::<f64>() / p.len() as f64).max(metrics::NOISY_RELMSE_FLOOR))
        }
        _ => None,
    };
    let ran_instead = method.and_then(|m| m.sparse_light_variant.as_ref()).and_then(|(v, _)| {
        let scenes = ran.iter().filter(|c| c.ran_instead.as_deref() == Some(v.name.as_str())).count();
        (scenes > 0).then(|| RanInstead {
            name: v.name.clone(),
            expr: v.expr.to_string(),
            length: v.expr.len(),
            pipeline: v.pipeline.to_string(),
            scenes,
        })
    });
    MethodInfo {
        ran_instead,
        mean_vs_peer,
        mean_relmse: mean(&|c| c.relmse),
        mean_flip: mean(&|c| c.flip),
        mean_light: mean(&|c| c.light),
        worst_light: ran
            .iter()
            .filter_map(|c| Some((c.scene.clone(), c.light?)))
            .max_by(|a, b| (a.1 - 1.0).abs().total_cmp(&(b.1 - 1.0).abs())),
        mean_normalised: mean(&|c| c.normalised),
        mean_ms_per_mpx: mean(&|c| c.ms_per_mpx),
        scenes_run: ran.len(),
        name,
        origin,
        expr: expr.map(|e| e.to_string()),
        length: expr.map(Expr::len),
        pipeline: method.map(|m| m.pipeline.to_string()),
    }
}

/// The scene a filter is timed on, and its buffers.
struct Timing<'a> {
    scene: &'a Scene,
    buffers: &'a mut SceneBuffers,
    /// The pipeline's pre-pass on this scene (0 without one), added to every dispatch's time.
    prepass_ms: f64,
}

/// Filter the scene for the errors; time the filter on the timing scene: one
/// warm-up dispatch (it compiles the pipeline), then `repeats` timed ones,
/// each with the pipeline's pre-pass: a frame's device time.
#[allow(clippy::too_many_arguments)]
fn measure(
    gpu: &Gpu,
    kernel: &jit::ValidatedKernel,
    buffers: &mut SceneBuffers,
    scene: &Scene,
    timing: &mut Timing<'_>,
    reference: &[[f32; 3]],
    settings: &Settings,
    radius: Option<u32>,
    noisy_relmse: f64,
) -> Result<(Cell, Vec<[f32; 3]>)> {
    let radius = radius.unwrap_or(settings.radius);
    let first = gpu.filter(kernel, buffers, scene, radius)?;
    gpu.filter(kernel, timing.buffers, timing.scene, radius)?;
    // The guide runs once a frame too, where the weight reads it (the warm-up made it).
    let guide = match kernel.source().layout.reads_guide() {
        true => timing.buffers.guide_time().map_or(0.0, |t| t.wall.as_secs_f64()),
        false => 0.0,
    };
    let mut times = Vec::new();
    for _ in 0..settings.repeats.max(1) {
        let form = gpu.filter(kernel, timing.buffers, timing.scene, radius)?.time.wall.as_secs_f64();
        times.push(form + guide + timing.prepass_ms / 1e3);
    }
    times.sort_by(f64::total_cmp);
    let mpx = timing.scene.pixels() as f64 / 1e6;
    let per_mpx = |t: f64| t * 1e3 / mpx;
    let rgb = first.rgb();
    let e = metrics::errors(&rgb, reference, scene.spp);
    let cell = Cell {
        scene: scene.name.clone(),
        relmse: Some(e.relmse),
        relmse_half_spp: e.relmse_half_spp,
        mse: Some(e.mse),
        flip: Some(crate::flip::hdr_flip(reference, &rgb, scene.width, scene.height).mean()),
        light: e.light,
        normalised: Some(metrics::normalised(e.relmse, noisy_relmse)),
        ms_per_mpx: Some(per_mpx(times[times.len() / 2])),
        ms_per_mpx_range: Some((per_mpx(times[0]), per_mpx(times[times.len() - 1]))),
        flagged_pixels: first.flagged_pixels(),
        ..Cell::default()
    };
    Ok((cell, rgb))
}

/// How often each feature occurs in a set of expressions (feature pairs count once per occurrence).
pub fn feature_usage(exprs: &[Expr]) -> BTreeMap<String, usize> {
    crate::lang::terminal_usage(exprs)
}

/// The `side`² window where the noisy input is furthest from the reference
/// (summed relative squared error): where filtering has most to do.
fn crop_window(
    noisy: &[[f32; 3]],
    reference: &[[f32; 3]],
    width: usize,
    height: usize,
    side: usize,
) -> (usize, usize, usize) {
    let side = side.min(width).min(height).max(1);
    let error: Vec<f64> =
        noisy.iter().zip(reference).map(|(c, g)| crate::metrics::pixel_relative_error(c, g)).collect();
    // Summed-area table for O(1) window sums.
    let mut table = vec![0.0; (width + 1) * (height + 1)];
    for y in 0..height {
        for x in 0..width {
            table[(y + 1) * (width + 1) + x + 1] =
                error[y * width + x] + table[y * (width + 1) + x + 1] + table[(y + 1) * (width + 1) + x]
                    - table[y * (width + 1) + x];
        }
    }
    let sum = |x: usize, y: usize| {
        table[(y + side) * (width + 1) + x + side]
            - table[y * (width + 1) + x + side]
            - table[(y + side) * (width + 1) + x]
            + table[y * (width + 1) + x]
    };
    let mut best = (0, 0, f64::NEG_INFINITY);
    for y in 0..=height - side {
        for x in 0..=width - side {
            let s = sum(x, y);
            if s > best.2 {
                best = (x, y, s);
            }
        }
    }
    (best.0, best.1, side)
}

/// One enlarged crop: its side and linear pixels.
type Crop = (usize, Vec<[f32; 3]>);

/// The crops side by side, 4 white pixels apart, in one PNG.
fn write_strip(path: &Path, crops: &[Crop]) -> Result<()> {
    let gap = 4;
    let side = crops.iter().map(|c| c.0).max().unwrap_or(1);
    let width = crops.len() * (side + gap) - gap;
    let mut pixels = vec![[1.0f32; 3]; width * side];
    for (k, (s, crop)) in crops.iter().enumerate() {
        for y in 0..*s {
            for x in 0..*s {
                pixels[y * width + k * (side + gap) + x] = crop[y * s + x];
            }
        }
    }
    preview::write_png(path, width, side, &pixels).map_err(anyhow::Error::from)
}

/// Where a scene's pictures go: each method's crop (`crops/SCENE/METHOD.png`)
/// and its whole frame (`full/SCENE/METHOD.png`, which the page's viewer
/// flips between), tone-mapped alike.
struct Views<'a> {
    crops: PathBuf,
    full: PathBuf,
    scene: &'a Scene,
    crop: (usize, usize, usize),
}

impl<'a> Views<'a> {
    fn new(output: &Path, scene: &'a Scene, crop: (usize, usize, usize)) -> Result<Views<'a>> {
        let (crops, full) =
            (output.join("crops").join(file_name(&scene.name)), output.join("full").join(file_name(&scene.name)));
        std::fs::create_dir_all(&crops)?;
        std::fs::create_dir_all(&full)?;
        Ok(Views { crops, full, scene, crop })
    }

    /// Write `method`'s crop and whole frame; the crop, for the strip.
    fn write(&self, method: &str, image: &[[f32; 3]]) -> Result<Crop> {
        let file = format!("{}.png", file_name(method));
        preview::write_png(&self.full.join(&file), self.scene.width, self.scene.height, image)?;
        write_crop(&self.crops.join(&file), image, self.scene, self.crop)
    }
}

/// The crop, tone-mapped like every preview and enlarged to about 192 pixels (nearest neighbour).
fn write_crop(path: &Path, image: &[[f32; 3]], scene: &Scene, (x0, y0, side): (usize, usize, usize)) -> Result<Crop> {
    let zoom = (192 / side).max(1);
    let out_side = side * zoom;
    let mut pixels = Vec::with_capacity(out_side * out_side);
    for y in 0..out_side {
        for x in 0..out_side {
            pixels.push(image[(y0 + y / zoom) * scene.width + x0 + x / zoom]);
        }
    }
    preview::write_png(path, out_side, out_side, &pixels)?;
    Ok((out_side, pixels))
}

/// A name safe as a file name.
#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_crop_finds_the_noisiest_window() {
        let (w, h) = (20, 10);
        let reference = vec![[0.5f32; 3]; w * h];
        let mut noisy = reference.clone();
        noisy[7 * w + 15] = [9.0, 9.0, 9.0];
        let (x, y, side) = crop_window(&noisy, &reference, w, h, 4);
        assert_eq!(side, 4);
        assert!((x..x + 4).contains(&15) && (y..y + 4).contains(&7), "({x}, {y})");
        assert_eq!(crop_window(&noisy, &reference, w, h, 64).2, 10, "a crop never exceeds the image");
    }

    #[test]
    fn feature_usage_counts_each_occurrence() {
        let e = crate::lang::parse_expr("distance2(normal) + dot(normal, texture) + wpVariance").unwrap();
        let usage = feature_usage(&[e]);
        assert_eq!(usage["normal"], 2);
        assert_eq!(usage["texture"], 1);
        assert_eq!(usage["wpVariance"], 1);
    }
}
