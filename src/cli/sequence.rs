//! `filterjit filter SEQ_DIR -o OUT_DIR`: every frame of a sequence filtered
//! in order, the temporal state carried from frame to frame; each frame's
//! EXR and PNG, an animated preview and `metrics.json` written; per frame
//! and for the sequence, relMSE, light, HDR-FLIP, flicker and temporal
//! relMSE, and the frame's time.

use std::path::Path;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use filterjit::denoise::{Choice, Provided, SequenceFilter};
use filterjit::environment::Environment;
use filterjit::pipeline::FilterPipeline;
use filterjit::report::sequence::{FrameScore, Summary, SETTLED_FROM};
use filterjit::scene::{self, Request, Sequence};
use filterjit::{gpu, metrics, preview};
use serde::Serialize;

use super::args::ReadScene;
use super::ms;

/// A frame's linear RGB pixels.
type Image = Vec<[f32; 3]>;

/// One frame's figures, as `metrics.json` holds them.
#[derive(Serialize)]
struct FrameFigures {
    name: String,
    relmse: Option<f64>,
    noisy_relmse: Option<f64>,
    light: Option<f64>,
    /// The noisy input's light: what the filter is given.
    noisy_light: Option<f64>,
    hdr_flip: Option<f64>,
    /// Against the frame before (none for the first).
    flicker: Option<f64>,
    /// The noisy input's, likewise: what the filter is given.
    noisy_flicker: Option<f64>,
    temporal_relmse: Option<f64>,
    wall_ms: f64,
    device_ms: Option<f64>,
    temporal_ms: Option<f64>,
}

/// The sequence's figures: means over its frames, and over the settled ones.
#[derive(Serialize)]
struct SequenceFigures {
    sequence: String,
    filter: String,
    pipeline: FilterPipeline,
    device: String,
    width: usize,
    height: usize,
    frames: Vec<FrameFigures>,
    /// Its times are the frames' wall times.
    #[serde(flatten)]
    summary: Summary,
}

pub(crate) fn filter_sequence(
    env: &Environment,
    expr: Option<&str>,
    radius: Option<u32>,
    dir: &Path,
    output: &Path,
    read: ReadScene,
    pipeline: Option<FilterPipeline>,
) -> Result<()> {
    let ReadScene { reference, spp, absent, view_layer } = read;
    if let Some(reference) = reference {
        bail!(
            "--reference {}: a sequence's references are found by frame name (in a `reference/` folder inside or \
             beside {}), not given one by one",
            reference.display(),
            dir.display()
        );
    }
    // Its errors name the folder.
    let sequence = Sequence::find(dir)?;
    let first = &sequence.frames.first().context("the sequence has no frames")?.path;
    let (features, variances) =
        scene::provides(first, view_layer.as_deref()).with_context(|| format!("reading frame {}", first.display()))?;
    let motion = scene::has_motion(first, view_layer.as_deref())?;
    let provided = Provided { motion, sequence: true, ..Provided::new(features, variances) };
    let choice = Choice::asked_or_best(expr, pipeline, radius, &provided)?;
    // A filter asked for in a pipeline that lacks what it reads (`temporalVariance` without
    // `temporal=A`), or a frame that lacks it: said before anything is written.
    let missing: Vec<String> = choice.missing(&provided).iter().map(ToString::to_string).collect();
    if !missing.is_empty() {
        bail!(
            "{} (pipeline {}) reads {}, which neither the pipeline nor the frames of {} give",
            choice.describe(),
            choice.pipeline,
            missing.join(", "),
            dir.display()
        );
    }
    let point_sampled = scene::point_sampled(first, view_layer.as_deref())
        .with_context(|| format!("reading frame {}", first.display()))?;
    let choice = choice.for_point_sampled(point_sampled, pipeline.is_some());
    super::refuse_radius(radius, &choice.pipeline)?;
    if let Some(because) = &choice.chosen_because {
        eprintln!("filter    {} (pipeline {}): {because}", choice.describe(), choice.pipeline);
    }
    let request = Request { spp, absent, view_layer, ..choice.request() };
    // Every frame's header first: a damaged sequence is refused before anything is written.
    let (width, height) = sequence.check(&request).with_context(|| format!("checking sequence {}", dir.display()))?;
    // Frames without a reference among frames with one: filtered alike, scored where they can be.
    let unreferenced: Vec<&str> =
        sequence.frames.iter().filter(|f| f.reference.is_none()).map(|f| f.name.as_str()).collect();
    let any_reference = unreferenced.len() < sequence.frames.len();
    if any_reference && !unreferenced.is_empty() {
        let (has, them) = if unreferenced.len() == 1 { ("has", "it") } else { ("have", "them") };
        eprintln!(
            "note: {} {has} no reference: the figures of {them} and of the change to and from {them} are left out \
             of the sequence's means",
            unreferenced.join(", ")
        );
    }
    std::fs::create_dir_all(output).with_context(|| format!("creating {}", output.display()))?;
    filterjit::io::remove_stale_temporaries(output);

    let gpu = gpu::Gpu::open(&env.adapter)?;
    let pipeline = choice.pipeline;
    let described = choice.describe();
    let mut filter = SequenceFilter::new(&gpu, choice)?;
    println!(
        "sequence  {} ({} frames, {width}x{height}) with {described}, pipeline {pipeline}",
        sequence.name,
        sequence.frames.len()
    );
    println!("device    {}", gpu.describe());
    println!(
        "frame     {:<14} {:>10} {:>10} {:>8} {:>9} {:>9} {:>10} {:>9} {:>9}",
        "", "relMSE", "noisy", "light", "HDR-FLIP", "flicker", "temporal", "wall ms", "device ms"
    );
    let mut figures = Vec::new();
    let mut scores = Vec::new();
    // The frame before's output and reference, for the change between frames, and its noisy input.
    let mut previous: Option<(Image, Option<Image>)> = None;
    let mut previous_noisy: Option<Image> = None;
    // The previews' frames, made small as they come.
    let (side, preview_height) = preview::preview_size(width, height, preview::ANIMATION_SIDE);
    let mut animation: Vec<Vec<[f32; 3]>> = Vec::new();
    let mut comparison: Vec<Vec<[f32; 3]>> = Vec::new();
    // The comparison's reference panel of a frame without one, where others have one.
    let blank: Image = if any_reference { vec![[0.0; 3]; width * height] } else { Vec::new() };
    for k in 0..sequence.frames.len() {
        let frame = &sequence.frames[k];
        let scene = sequence.load(k, &request).with_context(|| format!("loading frame {}", frame.path.display()))?;
        for note in scene.notes.iter().filter(|n| n.warns) {
            eprintln!("note: {}: {note}", frame.name);
        }
        let start = Instant::now();
        let done = filter.frame(&scene).with_context(|| format!("filtering frame {}", frame.path.display()))?;
        let wall = start.elapsed();
        let filtered = done.filtered;
        let rgb = filtered.rgb();
        let exr = output.join(format!("{}.exr", frame.name));
        // Their errors name the file.
        scene::exr_io::write_rgb(&exr, width, height, &rgb)?;
        let png = exr.with_extension("png");
        preview::write_png(&png, width, height, &rgb)?;

        let reference = scene.reference.as_deref();
        let before = previous.as_ref().and_then(|(output, reference)| Some((output.as_slice(), reference.as_deref()?)));
        let score = reference.map(|r| FrameScore::of(&rgb, r, before, scene.spp, (width, height)));
        let noisy = reference.map(|r| metrics::errors(&scene.color, r, scene.spp));
        let noisy_flicker = match (reference, before, &previous_noisy) {
            (Some(r), Some((_, r0)), Some(noisy_before)) => {
                Some(metrics::temporal((noisy_before.as_slice(), scene.color.as_slice()), (r0, r)).flicker)
            }
            _ => None,
        };
        let temporal_ms = done.temporal.map(|span| ms(span.device.unwrap_or(span.wall)));
        let figure = FrameFigures {
            name: frame.name.clone(),
            relmse: score.map(|s| s.relmse),
            noisy_relmse: noisy.map(|e| e.relmse),
            light: score.and_then(|s| s.light),
            noisy_light: noisy.and_then(|e| e.light),
            hdr_flip: score.map(|s| s.hdr_flip),
            flicker: score.and_then(|s| s.flicker),
            noisy_flicker,
            temporal_relmse: score.and_then(|s| s.temporal_relmse),
            wall_ms: ms(wall),
            device_ms: filtered.time.device.map(ms),
            temporal_ms,
        };
        let cell = |v: Option<f64>, width: usize, digits: usize| match v {
            Some(v) => format!("{v:>width$.digits$}"),
            None => format!("{:>width$}", "-"),
        };
        println!(
            "          {:<14} {} {} {} {} {} {} {:>9.1} {}",
            figure.name,
            cell(figure.relmse, 10, 5),
            cell(figure.noisy_relmse, 10, 4),
            cell(figure.light, 8, 4),
            cell(figure.hdr_flip, 9, 4),
            cell(figure.flicker, 9, 5),
            cell(figure.temporal_relmse, 10, 5),
            figure.wall_ms,
            cell(figure.device_ms, 9, 2),
        );
        if let Some(l) = figure.light.filter(|l| (l - 1.0).abs() > metrics::LIGHT_TOLERANCE) {
            // The input's own light beside it: a frame whose samples missed a highlight the reference has is dark
            // before any filter touches it.
            let noisy = figure
                .noisy_light
                .map_or(String::new(), |n| format!("; the noisy input's {:+.1} %", (n - 1.0) * 100.0));
            println!(
                "light     {}: mean luminance {:+.1} % from the reference's (more than {} %{noisy})",
                figure.name,
                (l - 1.0) * 100.0,
                metrics::LIGHT_TOLERANCE * 100.0
            );
        }
        if filtered.flagged_pixels() > 0 {
            println!(
                "domain    {}: {} pixels had domain errors: {}",
                figure.name,
                filtered.flagged_pixels(),
                filterjit::semantics::flag::describe(filtered.all_flags()).join("; ")
            );
        }
        if k < preview::ANIMATION_FRAMES {
            let small = |image: &[[f32; 3]]| preview::shrunk(image, width, height, side, preview_height);
            let reference_panel = reference.or(any_reference.then_some(blank.as_slice()));
            let strip: Vec<Image> = [Some(scene.color.as_slice()), Some(rgb.as_slice()), reference_panel]
                .into_iter()
                .flatten()
                .map(small)
                .collect();
            let strip: Vec<&[[f32; 3]]> = strip.iter().map(Vec::as_slice).collect();
            comparison.push(preview::side_by_side(&strip, side, preview_height));
            animation.push(small(&rgb));
        }
        figures.push(figure);
        scores.push(score);
        previous_noisy = Some(scene.color);
        previous = Some((rgb, scene.reference));
    }

    let walls: Vec<f64> = figures.iter().map(|f| f.wall_ms).collect();
    let summary = SequenceFigures {
        sequence: sequence.name.clone(),
        filter: described,
        pipeline,
        device: gpu.describe(),
        width,
        height,
        summary: Summary::of(&scores, &walls),
        frames: figures,
    };
    print_summary(&summary);
    let animated = output.join("animation.png");
    preview::write_animated_png(&animated, side, preview_height, &animation, 8)?;
    let strips = comparison.first().map_or(1, |f| f.len() / (side * preview_height));
    let compared = output.join("comparison.png");
    preview::write_animated_png(&compared, side * strips, preview_height, &comparison, 8)?;
    let json = output.join("metrics.json");
    filterjit::io::write_bytes_atomically(&json, serde_json::to_string_pretty(&summary)?.as_bytes())?;
    println!(
        "wrote     {} frames (EXR and PNG) in {}; {} (the filtered frames), {} (noisy | filtered{}), {}",
        summary.frames.len(),
        output.display(),
        animated.display(),
        compared.display(),
        if strips > 2 { " | reference" } else { "" },
        json.display()
    );
    Ok(())
}

fn print_summary(figures: &SequenceFigures) {
    let s = &figures.summary;
    let f = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.5}"));
    // The settled frames' figures, where the sequence reaches them.
    let settled = |v: Option<f64>| match figures.frames.len() > SETTLED_FROM {
        true => format!(" (frames {}–{}: {})", SETTLED_FROM + 1, figures.frames.len(), f(v)),
        false => String::new(),
    };
    // The noisy input's flicker beside the output's, over the same frames: what the filter took out.
    let from = if figures.frames.len() > SETTLED_FROM { SETTLED_FROM } else { 0 };
    let noisy: Vec<f64> = figures.frames.iter().skip(from).filter_map(|f| f.noisy_flicker).collect();
    let noisy =
        (!noisy.is_empty()).then(|| format!("the noisy input's {:.5}", noisy.iter().sum::<f64>() / noisy.len() as f64));
    let flicker = match (from, noisy) {
        (0, None) => f(s.flicker),
        (0, Some(noisy)) => format!("{} ({noisy})", f(s.flicker)),
        (_, None) => format!("{}{}", f(s.flicker), settled(s.flicker_settled)),
        (_, Some(noisy)) => format!(
            "{} (frames {}–{}: {}; {noisy})",
            f(s.flicker),
            SETTLED_FROM + 1,
            figures.frames.len(),
            f(s.flicker_settled)
        ),
    };
    println!(
        "sequence  relMSE {}{} | flicker {flicker} | temporal relMSE {} | HDR-FLIP {} | light {} | {:.1} ms a frame",
        f(s.relmse),
        settled(s.relmse_settled),
        f(s.temporal_relmse),
        f(s.hdr_flip),
        match (s.light_min, s.light_max) {
            (Some(min), Some(max)) => format!("{min:.3}–{max:.3}"),
            _ => "-".to_string(),
        },
        s.frame_ms.unwrap_or(0.0)
    );
    println!(
        "          (relMSE: Σ_rgb (o − r)² / (r² + 0.01); flicker F: mean |(o_t − o_t−1) − (r_t − r_t−1)| over pixels and \
         channels; temporal relMSE: the mean of ((o_t − o_t−1) − (r_t − r_t−1))² / (r_t² + 0.01); light: the mean \
         luminance over the reference's)"
    );
}
