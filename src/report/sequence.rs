//! `filterjit report --sequence SEQ_DIR`: filters side by side on one
//! sequence. Each filter runs over the frames in order with its temporal
//! state carried (`denoise::SequenceFilter`), beside the noisy input and
//! Intel Open Image Denoise on each frame alone (it has no temporal mode).
//! Per frame: relMSE, light, HDR-FLIP, flicker and the temporal relMSE; for
//! the sequence, their means over every frame and over the settled ones;
//! plots of relMSE and flicker over the frames, an animated comparison, all
//! in one folder with `index.html` and `sequence.json`.

use std::path::Path;

use anyhow::{bail, Context, Result};
use serde::Serialize;

use super::plot;
use crate::denoise::{Choice, SequenceFilter};
use crate::gpu::Gpu;
use crate::lang::Feature;
use crate::scene::{self, Request, Sequence};
use crate::{flip, io, metrics, oidn, preview};

/// Frames before this one still build their history: a sequence's
/// "settled" figures start here (the sequences issue's frames 5–12 of twelve).
pub const SETTLED_FROM: usize = 4;

/// A frame's linear RGB pixels.
pub type Image = Vec<[f32; 3]>;

/// The frame before's output and reference.
pub type Before<'a> = (&'a [[f32; 3]], &'a [[f32; 3]]);

/// One frame of a method against the frame's reference.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct FrameScore {
    pub relmse: f64,
    /// Mean luminance over the reference's.
    pub light: Option<f64>,
    pub hdr_flip: f64,
    /// Against the frame before: mean |(o_t − o_t−1) − (r_t − r_t−1)| (none for the first).
    pub flicker: Option<f64>,
    pub temporal_relmse: Option<f64>,
}

impl FrameScore {
    /// `output` (`size`) against `reference`; `before` is the frame before's
    /// output and reference, where there is one.
    pub fn of(
        output: &[[f32; 3]],
        reference: &[[f32; 3]],
        before: Option<Before<'_>>,
        spp: Option<u32>,
        (width, height): (usize, usize),
    ) -> FrameScore {
        let errors = metrics::errors(output, reference, spp);
        let change = before.map(|(output_before, reference_before)| {
            metrics::temporal((output_before, output), (reference_before, reference))
        });
        FrameScore {
            relmse: errors.relmse,
            light: errors.light,
            hdr_flip: flip::hdr_flip(reference, output, width, height).mean(),
            flicker: change.map(|c| c.flicker),
            temporal_relmse: change.map(|c| c.relmse),
        }
    }
}

/// What a method is, for the reader.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Kind {
    Noisy,
    Filter,
    /// OIDN on each frame alone.
    Peer,
}

/// A sequence's figures: means over every frame, and over the settled ones
/// (from [`SETTLED_FROM`]); `filter SEQ_DIR`'s `metrics.json` and each
/// method of a sequence report hold them.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Summary {
    pub relmse: Option<f64>,
    pub relmse_settled: Option<f64>,
    pub flicker: Option<f64>,
    pub flicker_settled: Option<f64>,
    pub temporal_relmse: Option<f64>,
    pub hdr_flip: Option<f64>,
    pub light_min: Option<f64>,
    pub light_max: Option<f64>,
    /// The median time a frame after the first (which compiles).
    pub frame_ms: Option<f64>,
}

impl Summary {
    /// Of `frames` in order (none where a frame has no reference), each taking `ms[k]`.
    pub fn of(frames: &[Option<FrameScore>], ms: &[f64]) -> Summary {
        let mean = |values: Vec<f64>| (!values.is_empty()).then(|| values.iter().sum::<f64>() / values.len() as f64);
        let of = |from: usize, pick: &dyn Fn(&FrameScore) -> Option<f64>| {
            mean(frames.iter().skip(from).flatten().filter_map(pick).collect())
        };
        let lights: Vec<f64> = frames.iter().flatten().filter_map(|f| f.light).collect();
        let mut later: Vec<f64> = ms.iter().skip(1).copied().collect();
        if later.is_empty() {
            later = ms.to_vec();
        }
        later.sort_by(f64::total_cmp);
        Summary {
            relmse: of(0, &|f| Some(f.relmse)),
            relmse_settled: of(SETTLED_FROM, &|f| Some(f.relmse)),
            flicker: of(0, &|f| f.flicker),
            flicker_settled: of(SETTLED_FROM, &|f| f.flicker),
            temporal_relmse: of(0, &|f| f.temporal_relmse),
            hdr_flip: of(0, &|f| Some(f.hdr_flip)),
            light_min: lights.iter().copied().reduce(f64::min),
            light_max: lights.iter().copied().reduce(f64::max),
            frame_ms: later.get(later.len() / 2).copied(),
        }
    }
}

/// One method over the sequence.
#[derive(Clone, Debug, Serialize)]
pub struct Entrant {
    pub name: String,
    pub kind: Kind,
    /// A filter's pipeline as it reads.
    pub pipeline: Option<String>,
    pub frames: Vec<FrameScore>,
    /// Its times: a filter's on the device's clock where it has one, OIDN's its program's own.
    #[serde(flatten)]
    pub summary: Summary,
}

/// The report on one sequence, as `sequence.json` holds it.
#[derive(Clone, Debug, Serialize)]
pub struct SequenceReport {
    pub sequence: String,
    pub width: usize,
    pub height: usize,
    pub frames: Vec<String>,
    /// The first settled frame, counted from 1.
    pub settled_from: usize,
    pub device: String,
    pub entrants: Vec<Entrant>,
}

/// What to report on.
pub struct SequenceInputs<'a> {
    pub sequence: &'a Sequence,
    /// The filters, each with its name.
    pub filters: Vec<(String, Choice)>,
    pub oidn: Option<&'a oidn::Oidn>,
    /// How to read the frames (samples per pixel, absent channels, view layer);
    /// what each method reads is added.
    pub read: Request,
}

/// One method's state while the frames go by.
struct Running {
    frames: Vec<FrameScore>,
    ms: Vec<f64>,
    previous: Option<Image>,
}

/// Filter the sequence with every method, frame by frame, and write the
/// report into `output`.
pub fn run(
    gpu: &Gpu,
    inputs: SequenceInputs<'_>,
    output: &Path,
    progress: &mut dyn FnMut(&str),
) -> Result<SequenceReport> {
    let SequenceInputs { sequence, filters, oidn, read } = inputs;
    let first = &sequence.frames.first().context("the sequence has no frames")?.path;
    // OIDN is given the albedo and normals where the frames hold them.
    let (features, _) = scene::provides(first, read.view_layer.as_deref())
        .with_context(|| format!("reading frame {}", first.display()))?;
    let aux = match features.contains(&Feature::Texture) && features.contains(&Feature::Normal) {
        true => oidn::Auxiliary::AlbedoNormal,
        false => oidn::Auxiliary::ColorOnly,
    };
    // One request for every method: what each filter reads, OIDN's inputs, the references.
    let mut request = Request { reference: true, ..read };
    for (_, choice) in &filters {
        let wanted = choice.request();
        request.features.extend(wanted.features);
        request.variances.extend(wanted.variances);
        request.albedo |= wanted.albedo;
        request.motion |= wanted.motion;
    }
    if oidn.is_some() && aux == oidn::Auxiliary::AlbedoNormal {
        request.albedo = true;
        request.features.insert(Feature::Normal);
    }
    // Every frame scored against its own reference: one without is refused before anything is measured.
    if let Some(frame) = sequence.frames.iter().find(|f| f.reference.is_none()) {
        bail!("{}: no reference; a sequence report scores every frame against its own", frame.path.display());
    }
    let (width, height) = sequence.check(&request).with_context(|| format!("checking sequence {}", sequence.name))?;
    std::fs::create_dir_all(output).with_context(|| format!("creating {}", output.display()))?;
    io::remove_stale_temporaries(output);

    let mut names: Vec<(String, Kind, Option<String>)> = vec![("noisy".into(), Kind::Noisy, None)];
    let mut runners = Vec::new();
    for (name, choice) in filters {
        names.push((name, Kind::Filter, Some(choice.pipeline.to_string())));
        runners.push(SequenceFilter::new(gpu, choice)?);
    }
    if oidn.is_some() {
        names.push((aux.method_name().to_string(), Kind::Peer, None));
    }
    let mut running: Vec<Running> =
        names.iter().map(|_| Running { frames: Vec::new(), ms: Vec::new(), previous: None }).collect();
    let work = output.join("oidn-work");
    let (side, preview_height) = preview::preview_size(width, height, preview::ANIMATION_SIDE);
    let mut animation = Vec::new();
    let mut previous_reference: Option<Image> = None;
    for k in 0..sequence.frames.len() {
        let frame = &sequence.frames[k];
        progress(&format!("frame {} of {}: {}", k + 1, sequence.frames.len(), frame.name));
        let mut scene =
            sequence.load(k, &request).with_context(|| format!("loading frame {}", frame.path.display()))?;
        let Some(reference) = scene.reference.take() else {
            bail!("{}: no reference; a sequence report scores every frame against its own", frame.path.display());
        };
        let mut outputs: Vec<Image> = vec![scene.color.clone()];
        for runner in &mut runners {
            let done = runner.frame(&scene).with_context(|| format!("filtering frame {}", frame.path.display()))?;
            let span = done.filtered.time;
            running[outputs.len()].ms.push(span.device.unwrap_or(span.wall).as_secs_f64() * 1e3);
            outputs.push(done.filtered.rgb());
        }
        if let Some(oidn) = oidn {
            let denoised = oidn.denoise(&scene, aux, 1, &work)?;
            let mut warm = denoised.warm_ms.clone();
            warm.sort_by(f64::total_cmp);
            running[outputs.len()].ms.push(warm.get(warm.len() / 2).copied().unwrap_or(0.0));
            outputs.push(denoised.color);
        }
        for (method, image) in running.iter_mut().zip(&outputs) {
            let before = method.previous.as_deref().zip(previous_reference.as_deref());
            method.frames.push(FrameScore::of(image, &reference, before, scene.spp, (width, height)));
        }
        if k < preview::ANIMATION_FRAMES {
            let small: Vec<Image> = outputs
                .iter()
                .chain([&reference])
                .map(|image| preview::shrunk(image, width, height, side, preview_height))
                .collect();
            // The viewer's pictures: each method's frame (and the reference's) on its own.
            for (view, image) in small.iter().enumerate() {
                let png = output.join(view_file(view, k));
                std::fs::create_dir_all(png.parent().expect("in a folder"))?;
                preview::write_png(&png, side, preview_height, image)?;
            }
            let strip: Vec<&[[f32; 3]]> = small.iter().map(Vec::as_slice).collect();
            animation.push(preview::side_by_side(&strip, side, preview_height));
        }
        for (method, image) in running.iter_mut().zip(outputs) {
            method.previous = Some(image);
        }
        previous_reference = Some(reference);
    }
    let _ = std::fs::remove_dir_all(&work);

    let entrants: Vec<Entrant> = names
        .into_iter()
        .zip(running)
        .map(|((name, kind, pipeline), run)| {
            let scored: Vec<Option<FrameScore>> = run.frames.iter().copied().map(Some).collect();
            Entrant { name, kind, pipeline, summary: Summary::of(&scored, &run.ms), frames: run.frames }
        })
        .collect();
    let report = SequenceReport {
        sequence: sequence.name.clone(),
        width,
        height,
        frames: sequence.frames.iter().map(|f| f.name.clone()).collect(),
        settled_from: SETTLED_FROM + 1,
        device: gpu.describe(),
        entrants,
    };
    let strips = report.entrants.len() + 1;
    preview::write_animated_png(&output.join("comparison.png"), side * strips, preview_height, &animation, 8)?;
    write_pages(&report, output)?;
    Ok(report)
}

/// The viewer's picture of view `view` (a method, in the report's order, or
/// the reference after them) at frame `k` (from 0).
fn view_file(view: usize, k: usize) -> String {
    format!("frames/{view}/{:04}.png", k + 1)
}

/// What the page's viewer shows: a picture of each view at each frame.
#[derive(Serialize)]
struct Viewer<'a> {
    /// The methods' names, then "reference"; their pictures are `frames/INDEX/NNNN.png`.
    views: Vec<&'a str>,
    /// Frames with pictures.
    frames: usize,
    width: usize,
    height: usize,
}

/// `sequence.json`, the two plots and `index.html`.
fn write_pages(report: &SequenceReport, output: &Path) -> Result<()> {
    let labels: Vec<String> = (1..=report.frames.len()).map(|k| k.to_string()).collect();
    let series = |pick: &dyn Fn(&FrameScore) -> Option<f64>| -> Vec<(String, Vec<Option<f64>>)> {
        report.entrants.iter().map(|e| (e.name.clone(), e.frames.iter().map(pick).collect())).collect()
    };
    let plots = [
        ("relmse.svg", plot::lines("relMSE a frame", "relMSE", &labels, &series(&|f| Some(f.relmse)))),
        ("flicker.svg", plot::lines("flicker against the frame before", "flicker F", &labels, &series(&|f| f.flicker))),
    ];
    for (file, svg) in &plots {
        io::write_bytes_atomically(&output.join(file), svg.as_bytes())?;
    }
    io::write_bytes_atomically(&output.join("sequence.json"), serde_json::to_string_pretty(report)?.as_bytes())?;
    let mut context = tera::Context::from_serialize(report)?;
    let (width, height) = preview::preview_size(report.width, report.height, preview::ANIMATION_SIDE);
    let views = report.entrants.iter().map(|e| e.name.as_str()).chain(["reference"]).collect();
    let frames = report.frames.len().min(preview::ANIMATION_FRAMES);
    context.insert("viewer", &Viewer { views, frames, width, height });
    let html = tera::Tera::one_off(include_str!("../../templates/report_sequence.html.tera"), &context, true)
        .context("rendering report_sequence.html")?;
    io::write_bytes_atomically(&output.join("index.html"), html.as_bytes())?;
    Ok(())
}
