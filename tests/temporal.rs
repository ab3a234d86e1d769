//! Sequences and the temporal stage: Blender's motion vectors read as
//! Blender writes them (the committed crop of a real Cycles sequence,
//! `tests/data/cycles-seq`), the stage on the device against the f64 CPU
//! reference frame after frame, and `filterjit filter SEQ_DIR -o OUT_DIR` as
//! a user runs it, on good and on damaged sequences.

use std::path::{Path, PathBuf};

use filterjit::cpu;
use filterjit::gpu::{SceneBuffers, TemporalState};
use filterjit::jit::{self, Shape};
use filterjit::lang::parse_expr;
use filterjit::pipeline::FilterPipeline;
use filterjit::scene::{self, exr_io, Request, Sequence};
use filterjit::Scene;

use crate::cli::filterjit;
use crate::common::{agree_fraction, gpu, temp_dir};

/// The committed sequence: `noisy/frame_000{1,2,3}.exr`, `reference/` beside.
pub(crate) fn committed() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/cycles-seq")
}

/// Every frame of the sequence at `dir`, with what a temporal pipeline reads.
pub(crate) fn frames(dir: &Path, request: &Request) -> Vec<Scene> {
    let sequence = Sequence::find(dir).unwrap();
    (0..sequence.frames.len()).map(|k| sequence.load(k, request).unwrap()).collect()
}

/// What a temporal pipeline's filter reads, the reference included.
pub(crate) fn temporal_request() -> Request {
    let mut request = Request { motion: true, albedo: true, reference: true, ..Default::default() };
    request.features.extend([
        filterjit::lang::Feature::Normal,
        filterjit::lang::Feature::Depth,
        filterjit::lang::Feature::WorldPosition,
        filterjit::lang::Feature::Texture,
    ]);
    request
}

/// The mean absolute difference between frame `k`'s reference and frame
/// `k − 1`'s, each pixel compared with the pixel `motion` (scaled per axis by
/// `sign`) points to, where that lies inside the image.
fn warped_difference(before: &Scene, now: &Scene, sign: [f32; 2]) -> f64 {
    let (r0, r1) = (before.reference.as_ref().unwrap(), now.reference.as_ref().unwrap());
    moved_difference((r0, r1), now, sign)
}

/// The mean absolute difference between image `now` of frame `scene` and
/// image `before` of the frame before, each pixel compared with the pixel
/// the frame's motion vectors (scaled per axis by `sign`) point to, where
/// that lies inside the image: how well the vectors line the frames up.
pub(crate) fn moved_difference((r0, r1): (&[[f32; 3]], &[[f32; 3]]), scene: &Scene, sign: [f32; 2]) -> f64 {
    let (w, h) = (scene.width as i64, scene.height as i64);
    let vectors = &scene.motion.as_ref().expect("frames read with their motion").vectors;
    let (mut sum, mut count) = (0.0, 0usize);
    for y in 0..h {
        for x in 0..w {
            let v = vectors[(y * w + x) as usize];
            let (qx, qy) = ((x as f32 + sign[0] * v[0]).round() as i64, (y as f32 + sign[1] * v[1]).round() as i64);
            if qx < 0 || qy < 0 || qx >= w || qy >= h {
                continue;
            }
            let (a, b) = (r0[(qy * w + qx) as usize], r1[(y * w + x) as usize]);
            sum += (0..3).map(|c| (a[c] - b[c]).abs() as f64).sum::<f64>() / 3.0;
            count += 1;
        }
    }
    sum / count.max(1) as f64
}

/// Blender's Vector pass, read as its source says (X, Y: the frame before's
/// position minus this one's, y up): the frame before's reference moved by
/// it lines up with this frame's far better than unmoved, or moved the other
/// way. The crop's motion is mostly sideways (a camera sliding along x):
/// its y sign is told by `tests/blender.rs`, on a render whose camera climbs.
#[test]
fn blenders_vector_pass_points_to_where_each_pixel_was_the_frame_before() {
    let scenes = frames(&committed().join("noisy"), &temporal_request());
    for pair in scenes.windows(2) {
        let (before, now) = (&pair[0], &pair[1]);
        let still = warped_difference(before, now, [0.0, 0.0]);
        let moved = warped_difference(before, now, [1.0, 1.0]);
        let mirrored = warped_difference(before, now, [-1.0, 1.0]);
        eprintln!("{}: still {still:.4}, moved {moved:.4}, moved the other way {mirrored:.4}", now.name);
        assert!(moved < 0.6 * still, "{}: moving by the vectors lines the frames up: {moved} vs {still}", now.name);
        assert!(moved < 0.6 * mirrored, "{}: and the x sign is Blender's: {moved} vs {mirrored}", now.name);
        let rows_down = warped_difference(before, now, [1.0, -1.0]);
        assert!(moved <= rows_down * 1.05, "{}: y up, not down: {moved} vs {rows_down}", now.name);
    }
}

/// The temporal stage on the device, frame after frame with its state
/// carried, against the CPU reference with its history carried: the same
/// images on three frames of a real sequence, then its last frame with its
/// vectors stale, then with the light all but off and on again (the
/// history's test cuts or drops what the frame disagrees with), for pipelines that feed back the blend, a pass
/// or a window's output, clamp or test the history or not, demodulate or
/// not, and weights that read what the stage accumulated.
#[test]
fn the_temporal_stage_on_the_device_matches_the_cpu_reference_frame_after_frame() {
    let gpu = gpu();
    let mut scenes = frames(&committed().join("noisy"), &temporal_request());
    // The last frame again with its own vectors, which now point a frame too far back:
    // most bilinear taps mix histories of three frames at fractional weights, a mean f32
    // rounds off a whole number (docs/JOURNAL.md, "Stale vectors"). Then the camera
    // stopped (no motion), its light all but off, then on again.
    let stale = scenes.last().unwrap().clone();
    let mut last = stale.clone();
    last.motion.as_mut().unwrap().vectors.iter_mut().for_each(|v| *v = [0.0; 2]);
    let mut dark = last.clone();
    dark.color.iter_mut().flatten().for_each(|c| *c *= 0.05);
    scenes.extend([stale, dark, last]);
    let dark_frame = scenes.len() - 2;
    let cases = [
        (
            "demodulate,temporal=0.2,feedback=1,atrous=3",
            "exp(-(distanceMax(color) / (4 * sqrt(temporalVariance) + 0.001) + distance2(normal) / historyLength))",
            0,
        ),
        ("outliers=2,keep,demodulate,temporal=0.1,feedback=0,clamp=2,window", "exp(-distance2(color))", 2),
        ("temporal=0.5,feedback=2,atrous=2,planefit=2", "exp(-(distance2(color) + historyLength))", 0),
        (
            "outliers=2.5,trim,keep,demodulate,temporal=0.2,feedback=0,clamp=2,antilag=3,atrous=3",
            "exp(-(distanceMax(color) / (4 * sqrt(temporalVariance) + 0.001) + distance2(normal)))",
            0,
        ),
    ];
    for (text, weight, radius) in cases {
        let pipeline: FilterPipeline = text.parse().unwrap();
        let expr = parse_expr(weight).unwrap();
        let kernel =
            jit::compile(&expr, jit::KernelSpec { shape: Shape::of(&pipeline), ..jit::KernelSpec::default() }).unwrap();
        let mut state = TemporalState::new();
        let mut history: Option<cpu::temporal::History> = None;
        for (k, scene) in scenes.iter().enumerate() {
            let mut buffers = SceneBuffers::for_frame(&gpu, scene, &pipeline).unwrap();
            let on_gpu = gpu.filter_frame(&kernel, &mut buffers, scene, radius, &mut state).unwrap();
            assert!(buffers.temporal_time().is_some(), "{text}: the stage ran and was timed");
            let (on_cpu, kept) = cpu::filter_frame(&expr, scene, &pipeline, radius, history.as_ref()).unwrap();
            // The light all but off: a history far off the frame is dropped (its length 1 again), not cut to two.
            if pipeline.temporal.unwrap().antilag.is_some() && k == dark_frame {
                let lengths = &kept.as_ref().unwrap().moments;
                let dropped = lengths.iter().filter(|m| m[3] == 1.0).count() as f64 / lengths.len() as f64;
                eprintln!("{text}, frame {}: {dropped:.3} of the histories dropped", k + 1);
                assert!(dropped > 0.2, "{text}: a history far off the dark frame is dropped ({dropped})");
            }
            history = kept;
            let (fraction, worst) = agree_fraction(&on_gpu.rgb(), &on_cpu.color);
            eprintln!("{text}, frame {}: {:.4} within 1e-3, worst {worst:.2e}", k + 1, fraction);
            assert!(fraction > 0.999, "{text}, frame {}: {fraction} within 1e-3, worst {worst:e}", k + 1);
            assert_eq!(state.frames() as usize, k + 1, "{text}: the state counts its frames");
        }
        // The history is what made the last frame: alone, it comes out otherwise.
        let last = scenes.last().unwrap();
        let mut buffers = SceneBuffers::for_frame(&gpu, last, &pipeline).unwrap();
        let alone = gpu.filter_frame(&kernel, &mut buffers, last, radius, &mut TemporalState::new()).unwrap().rgb();
        let mut buffers = SceneBuffers::for_frame(&gpu, last, &pipeline).unwrap();
        let mut carried = state;
        carried.reset();
        let reset = gpu.filter_frame(&kernel, &mut buffers, last, radius, &mut carried).unwrap().rgb();
        assert_eq!(alone, reset, "{text}: a reset state starts the sequence again, bit for bit");
        let (on_cpu, _) = cpu::filter_frame(&expr, last, &pipeline, radius, history.as_ref()).unwrap();
        let (fraction, _) = agree_fraction(&alone, &on_cpu.color);
        assert!(fraction < 0.9, "{text}: the history changes the frame ({fraction} of it unchanged)");
    }
}

/// A temporal filter's frames are better with their history than without
/// it (the same frame as the first of a sequence), keep the light of what
/// they are given, and are finite everywhere.
#[test]
fn the_history_lowers_the_error_and_keeps_the_light() {
    let gpu = gpu();
    let scenes = frames(&committed().join("noisy"), &temporal_request());
    let svgf = filterjit::corpus::resolve_with_pipeline("@svgf").unwrap();
    let pipeline = svgf.pipeline.unwrap();
    let kernel =
        jit::compile(&svgf.expr, jit::KernelSpec { shape: Shape::of(&pipeline), ..jit::KernelSpec::default() })
            .unwrap();
    let mut state = TemporalState::new();
    for (k, scene) in scenes.iter().enumerate() {
        let mut buffers = SceneBuffers::for_frame(&gpu, scene, &pipeline).unwrap();
        let out = gpu.filter_frame(&kernel, &mut buffers, scene, 0, &mut state).unwrap().rgb();
        assert!(out.iter().flatten().all(|v| v.is_finite()), "{}: every pixel finite", scene.name);
        let errors = |image: &[[f32; 3]]| filterjit::metrics::errors(image, scene.reference.as_ref().unwrap(), None);
        let (filtered, noisy) = (errors(&out), errors(&scene.color));
        // A crop's few bright pixels move its noisy light off the reference's: the filter keeps the noisy light.
        let light = filtered.light.unwrap() / noisy.light.unwrap();
        eprintln!(
            "{}: relMSE {:.4} (noisy {:.4}), light {light:.4} of the noisy input's",
            scene.name, filtered.relmse, noisy.relmse
        );
        assert!(filtered.relmse < 0.2 * noisy.relmse, "{}", scene.name);
        assert!((light - 1.0).abs() < 0.05, "{}: the light is kept: {light}", scene.name);
        if k > 0 {
            let mut buffers = SceneBuffers::for_frame(&gpu, scene, &pipeline).unwrap();
            let alone = gpu.filter_frame(&kernel, &mut buffers, scene, 0, &mut TemporalState::new()).unwrap().rgb();
            let alone = errors(&alone).relmse;
            assert!(filtered.relmse < alone, "{}: with history {} against {alone} alone", scene.name, filtered.relmse);
        }
    }
}

/// `filterjit filter SEQ -o OUT`: the sequence's frames in order, with
/// the best shipped temporal filter chosen and said; each frame's EXR and
/// PNG, the animated previews and `metrics.json`; per frame and for the
/// sequence, relMSE, light, HDR-FLIP, flicker and the frame's time.
#[test]
fn a_sequence_filters_end_to_end_with_no_flag() {
    let out = temp_dir("temporal", "cli").join("out");
    let noisy = committed().join("noisy");
    let o = filterjit(&["filter", noisy.to_str().unwrap(), "-o", out.to_str().unwrap()]);
    let (stdout, stderr) = (String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    assert!(o.status.success(), "{stderr}");
    let temporal = filterjit::denoise::SHIPPED_TEMPORAL_BY_QUALITY[0];
    assert!(stderr.contains(&format!("filter    @{temporal} (")), "says which filter and why: {stderr}");
    // The committed frames are Cycles' at one sample, as their headers say: the pixel filter ends the pipeline.
    assert!(stderr.contains(",pixelfilter=0.4): ") && stderr.contains("at one point"), "{stderr}");
    assert!(stdout.contains("sequence  noisy (3 frames, 64x64)"), "{stdout}");
    for k in 1..=3 {
        for ext in ["exr", "png"] {
            let file = out.join(format!("frame_{k:04}.{ext}"));
            assert!(file.is_file(), "{} written", file.display());
        }
    }
    for file in ["animation.png", "comparison.png", "metrics.json"] {
        assert!(out.join(file).is_file(), "{file} written");
    }
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("metrics.json")).unwrap()).unwrap();
    let frames = metrics["frames"].as_array().unwrap();
    assert_eq!(frames.len(), 3);
    for frame in frames {
        let (relmse, noisy) = (frame["relmse"].as_f64().unwrap(), frame["noisy_relmse"].as_f64().unwrap());
        assert!(relmse < 0.2 * noisy, "{frame}");
        let light = frame["light"].as_f64().unwrap() / frame["noisy_light"].as_f64().unwrap();
        assert!((light - 1.0).abs() < 0.05, "{frame}");
        assert!(frame["hdr_flip"].as_f64().is_some() && frame["wall_ms"].as_f64().unwrap() > 0.0, "{frame}");
    }
    assert!(frames[0]["flicker"].is_null() && frames[1]["flicker"].as_f64().unwrap() > 0.0, "flicker from frame 2 on");
    // The noisy input's flicker beside it: what the filter took out.
    for frame in &frames[1..] {
        assert!(frame["noisy_flicker"].as_f64().unwrap() > 2.0 * frame["flicker"].as_f64().unwrap(), "{frame}");
    }
    assert!(metrics["flicker"].as_f64().is_some() && metrics["temporal_relmse"].as_f64().is_some());
    // The sequence's line states what the issue asks of it.
    let line = stdout.lines().find(|l| l.starts_with("sequence  relMSE")).unwrap_or_else(|| panic!("{stdout}"));
    assert!(line.contains("flicker") && line.contains("light") && line.contains("ms a frame"), "{line}");
    assert!(line.contains("(the noisy input's "), "{line}");

    // One frame of it filtered alone is scored against its reference of the
    // same name in `reference/` beside `noisy/`, as the sequence's frames are.
    let single = out.with_file_name("frame_0002.exr");
    let o = filterjit(&["filter", noisy.join("frame_0002.exr").to_str().unwrap(), "-o", single.to_str().unwrap()]);
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(stdout.lines().any(|l| l.trim_start().starts_with("filtered ")), "scored: {stdout}");
}

/// A copy of the committed frame `k` (from 1) at `file`, its channels as
/// `change` leaves them (name and values; none: dropped), `size` pixels a side.
fn altered_frame(k: usize, file: &Path, change: impl Fn(&str, Vec<f32>) -> Option<Vec<f32>>, size: Option<usize>) {
    let source = committed().join(format!("noisy/frame_{k:04}.exr"));
    let (names, width, height) = exr_io::channel_names(&source).unwrap();
    let refs: Vec<&str> = names.iter().map(String::as_str).collect();
    let data = exr_io::read_channels(&source, &refs).unwrap().data;
    let side = size.unwrap_or(width);
    let channels: Vec<(&str, Vec<f32>)> = names
        .iter()
        .zip(data)
        .filter_map(|(n, values)| {
            let values: Vec<f32> =
                (0..side * side.min(height)).map(|p| values[(p / side) * width + p % side]).collect();
            change(n, values).map(|v| (n.as_str(), v))
        })
        .collect();
    exr_io::write_channels(file, side, side.min(height), &channels).unwrap();
}

/// A sequence built from the committed frames (`frames`: which, from 1),
/// with frame `altered` changed by `change`, and their references beside.
fn sequence_with(
    name: &str,
    frames: &[usize],
    altered: usize,
    change: impl Fn(&str, Vec<f32>) -> Option<Vec<f32>>,
    size: Option<usize>,
) -> PathBuf {
    let dir = temp_dir("temporal", name);
    let (noisy, reference) = (dir.join("noisy"), dir.join("reference"));
    std::fs::create_dir_all(&noisy).unwrap();
    std::fs::create_dir_all(&reference).unwrap();
    for &k in frames {
        let file = noisy.join(format!("frame_{k:04}.exr"));
        if k == altered {
            altered_frame(k, &file, &change, size);
        } else {
            std::fs::copy(committed().join(format!("noisy/frame_{k:04}.exr")), &file).unwrap();
        }
        let name = format!("frame_{k:04}.exr");
        std::fs::copy(committed().join("reference").join(&name), reference.join(&name)).unwrap();
    }
    dir
}

/// The pixel filter follows what the first frame's header says: Cycles'
/// `cycles.ViewLayer.samples` of 1 in the committed frames, none in a copy
/// written without it (as filterjit's own renders and other renderers' are);
/// and a single render's header likewise.
#[test]
fn the_pixel_filter_follows_the_sample_count_in_the_header() {
    let noisy = committed().join("noisy");
    assert_eq!(scene::samples_per_pixel(&noisy.join("frame_0001.exr"), None).unwrap(), Some(1));
    assert_eq!(scene::samples_per_pixel(&noisy.join("frame_0001.exr"), Some("Other")).unwrap(), None);
    let dir = sequence_with("headerless", &[1, 2], 1, |_, values| Some(values), None);
    assert_eq!(scene::samples_per_pixel(&dir.join("noisy/frame_0001.exr"), None).unwrap(), None);
    let out = dir.join("out");
    let o = filterjit(&["filter", dir.join("noisy").to_str().unwrap(), "-o", out.to_str().unwrap()]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    assert!(stderr.contains("filter    @") && !stderr.contains("pixelfilter"), "no header, no pixel filter: {stderr}");
    // One frame alone, filtered as a render of its own: the same rule.
    let (frame, out) = (noisy.join("frame_0002.exr"), dir.join("one.exr"));
    let o = filterjit(&["filter", frame.to_str().unwrap(), "-o", out.to_str().unwrap()]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success() && stderr.contains(",pixelfilter=0.4): "), "{stderr}");
}

/// A damaged sequence is refused with the file and what is wrong named,
/// before anything is written; a NaN in the vectors is a documented
/// recovery (those pixels start a new history), never a non-finite pixel.
#[test]
fn a_damaged_sequence_is_refused_before_anything_is_written() {
    let run = |dir: &Path| {
        let out = dir.join("out");
        let o = filterjit(&["filter", dir.join("noisy").to_str().unwrap(), "-o", out.to_str().unwrap()]);
        (o, out)
    };
    let keep = |_: &str, values: Vec<f32>| Some(values);
    let refused = |dir: &Path, needles: &[&str]| {
        let (o, out) = run(dir);
        let stderr = String::from_utf8_lossy(&o.stderr).into_owned();
        assert!(!o.status.success(), "refused: {stderr}");
        for needle in needles {
            assert!(stderr.contains(needle), "names `{needle}`: {stderr}");
        }
        assert!(!out.exists(), "nothing written for {}", dir.display());
    };
    // A frame missing from the numbering.
    refused(&sequence_with("gap", &[1, 3], 0, keep, None), &["frame 2 is missing", "frame_0001.exr", "frame_0003.exr"]);
    // A frame of another size.
    refused(&sequence_with("size", &[1, 2, 3], 2, keep, Some(32)), &["frame_0002.exr", "32x32", "64x64"]);
    // A frame without motion vectors, where the temporal filter needs them.
    let no_vectors = |n: &str, v: Vec<f32>| (!n.contains(".Vector.")).then_some(v);
    refused(&sequence_with("vectors", &[1, 2, 3], 3, no_vectors, None), &["frame_0003", "motion vectors", "Vector"]);

    // NaN in a frame's vectors: filtered, said, every pixel finite.
    let nan_vectors = |n: &str, mut v: Vec<f32>| {
        if n.ends_with(".Vector.X") {
            v.iter_mut().step_by(7).for_each(|x| *x = f32::NAN);
        }
        Some(v)
    };
    let dir = sequence_with("nan", &[1, 2, 3], 2, nan_vectors, None);
    let (o, out) = run(&dir);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    assert!(stderr.contains("non-finite vectors; those pixels start a new history"), "{stderr}");
    let image = exr_io::read_channels(&out.join("frame_0002.exr"), &["R", "G", "B"]).unwrap();
    assert!(image.data.iter().flatten().all(|v| v.is_finite()), "every pixel finite");
}

/// What a user's folders get wrong, each refused before anything is
/// written or, where the frames can still be filtered, said: a frame twice
/// (a dataset folder beside an EXR of its name), an output into the frames'
/// own folder (either layout), a filter whose pipeline lacks what it reads,
/// a report on frames one of which lacks its reference or written into the
/// frames' folder; a frame without a reference among frames with one is
/// filtered, scored where it can be, and every file written.
#[test]
fn a_sequence_folder_used_wrongly_is_refused_or_said_before_anything_is_written() {
    let keep = |_: &str, values: Vec<f32>| Some(values);
    let run = |args: &[&str]| {
        let o = filterjit(args);
        (o.status.success(), String::from_utf8_lossy(&o.stderr).into_owned())
    };
    let text = |p: &Path| p.to_str().unwrap().to_string();

    // Frame 2 twice: as an EXR file and as a dataset folder of the same name.
    let dir = sequence_with("twice", &[1, 2, 3], 0, keep, None);
    let noisy = dir.join("noisy");
    std::fs::create_dir_all(noisy.join("frame_0002")).unwrap();
    std::fs::copy(noisy.join("frame_0002.exr"), noisy.join("frame_0002/noisy.exr")).unwrap();
    let out = dir.join("out");
    let (ok, stderr) = run(&["filter", &text(&noisy), "-o", &text(&out)]);
    assert!(!ok && stderr.contains("frame 2 is there twice") && stderr.contains("frame_0002.exr"), "{stderr}");
    assert!(!out.exists(), "nothing written");
    std::fs::remove_dir_all(noisy.join("frame_0002")).unwrap();

    // Into the frames' own folder, named with or without a trailing slash, or inside it as datasets.
    for output in [text(&noisy), format!("{}/", text(&noisy))] {
        let (ok, stderr) = run(&["filter", &text(&noisy), "-o", &output]);
        assert!(!ok && stderr.contains("the renders are read from this folder"), "{output}: {stderr}");
    }
    let datasets = dir.join("datasets");
    for k in 1..=3 {
        let frame = datasets.join(format!("frame_{k:04}"));
        std::fs::create_dir_all(&frame).unwrap();
        std::fs::copy(noisy.join(format!("frame_{k:04}.exr")), frame.join("noisy.exr")).unwrap();
    }
    let (ok, stderr) = run(&["filter", &text(&datasets), "-o", &text(&datasets)]);
    assert!(!ok && stderr.contains("the renders are read from this folder"), "{stderr}");
    assert!(!datasets.join("frame_0001.exr").exists(), "nothing written beside the frames' folders");

    // A filter whose pipeline lacks what its weight reads.
    let (ok, stderr) = run(&["filter", &text(&noisy), "--expr", "@svgf", "--pipeline", "atrous=5", "-o", &text(&out)]);
    assert!(!ok && stderr.contains("reads temporalVariance") && stderr.contains("temporal=A"), "{stderr}");
    assert!(!out.exists(), "nothing written");
    // No filter asked for, a pipeline without the temporal stage: the best filter that fits it.
    let (ok, stderr) = run(&["filter", &text(&noisy), "--pipeline", "window", "-o", &text(&out)]);
    assert!(ok && stderr.contains("(pipeline window)") && stderr.contains("frame by frame"), "{stderr}");
    std::fs::remove_dir_all(&out).unwrap();

    // One reference missing: filtered, said, every file written, that frame unscored.
    std::fs::remove_file(dir.join("reference/frame_0002.exr")).unwrap();
    let o = filterjit(&["filter", &text(&noisy), "-o", &text(&out)]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    assert!(stderr.contains("frame_0002 has no reference"), "{stderr}");
    for file in ["frame_0002.exr", "animation.png", "comparison.png", "metrics.json"] {
        assert!(out.join(file).is_file(), "{file} written");
    }
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("metrics.json")).unwrap()).unwrap();
    let frames = metrics["frames"].as_array().unwrap();
    assert!(frames[0]["relmse"].is_f64() && frames[1]["relmse"].is_null() && frames[2]["relmse"].is_f64());
    assert!(frames[2]["flicker"].is_null(), "no change scored against a frame without a reference");
    // A report needs every frame's reference, and is not written among the frames.
    let report = dir.join("report");
    let (ok, stderr) = run(&["report", "--sequence", &text(&dir), "--no-oidn", "-o", &text(&report)]);
    assert!(!ok && stderr.contains("frame_0002.exr: no reference"), "{stderr}");
    assert!(!report.exists(), "refused before anything is measured");
    std::fs::copy(committed().join("reference/frame_0002.exr"), dir.join("reference/frame_0002.exr")).unwrap();
    let (ok, stderr) = run(&["report", "--sequence", &text(&dir), "--no-oidn", "-o", &text(&dir)]);
    assert!(!ok && stderr.contains("the report's files would mix with them"), "{stderr}");
    assert!(!dir.join("sequence.json").exists());
}

/// A regression: filterjit's own frames name one normal for the feature and
/// for the temporal stage's surface test, and loading both decoded the
/// channels into one of the two only (the feature read as zero, so every
/// weight that compared normals was 0). Each image is loaded whole, whoever asks.
#[test]
fn a_channel_both_a_feature_and_the_temporal_stage_read_is_loaded_for_both() {
    let (w, h) = (4usize, 3usize);
    let n = w * h;
    let ramp = |k: usize| (0..n).map(|p| (p + k) as f32 * 0.1).collect::<Vec<f32>>();
    let channels = [
        ("R", ramp(0)),
        ("G", ramp(1)),
        ("B", ramp(2)),
        ("Ns.X", vec![0.0; n]),
        ("Ns.Y", vec![0.6; n]),
        ("Ns.Z", vec![0.8; n]),
        ("Z", vec![2.0; n]),
        ("Vector.X", vec![0.5; n]),
        ("Vector.Y", vec![0.25; n]),
    ];
    let file = temp_dir("temporal", "shared-channels").join("noisy.exr");
    exr_io::write_channels(&file, w, h, &channels).unwrap();
    let features = [filterjit::lang::Feature::Normal, filterjit::lang::Feature::Depth].into();
    let alone = filterjit::scene::load(&file, &Request { features, ..Default::default() }).unwrap();
    let features = [filterjit::lang::Feature::Normal, filterjit::lang::Feature::Depth].into();
    let both = filterjit::scene::load(&file, &Request { features, motion: true, ..Default::default() }).unwrap();
    for f in [filterjit::lang::Feature::Normal, filterjit::lang::Feature::Depth] {
        assert_eq!(both.feature(f), alone.feature(f), "{f} as a feature");
        assert!(both.feature(f).unwrap().iter().all(|v| v.iter().any(|c| *c != 0.0)), "{f} is not zero");
    }
    let motion = both.motion.unwrap();
    assert!(motion.surface.iter().all(|s| (s[1] - 0.6).abs() < 1e-6 && (s[2] - 0.8).abs() < 1e-6 && s[3] == 2.0));
    // Blender's y up, read as image rows down.
    assert!(motion.vectors.iter().all(|v| *v == [0.5, -0.25]));
}

/// `report --sequence`: the shipped temporal filters beside the noisy input
/// over every frame, their figures per frame and for the sequence, the plots
/// and the animated comparison; flags about scenes to render are refused.
#[test]
fn a_sequence_report_compares_the_temporal_filters_frame_by_frame() {
    let out = temp_dir("temporal", "report").join("out");
    let dir = committed();
    let o = filterjit(&["report", "--sequence", dir.to_str().unwrap(), "--no-oidn", "-o", out.to_str().unwrap()]);
    let (stdout, stderr) = (String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    assert!(o.status.success(), "{stderr}");
    for file in ["index.html", "sequence.json", "relmse.svg", "flicker.svg", "comparison.png"] {
        assert!(out.join(file).is_file(), "{file} written");
    }
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("sequence.json")).unwrap()).unwrap();
    let entrants = report["entrants"].as_array().unwrap();
    let names: Vec<&str> = entrants.iter().map(|e| e["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["noisy", "@temporal", "@realtimeTemporal", "@svgf"], "{stdout}");
    let noisy = &entrants[0];
    for entrant in entrants {
        let frames = entrant["frames"].as_array().unwrap();
        assert_eq!(frames.len(), 3, "{entrant}");
        assert!(frames[0]["flicker"].is_null() && frames[2]["flicker"].as_f64().unwrap() > 0.0, "{entrant}");
        assert!(frames.iter().all(|f| f["hdr_flip"].as_f64().unwrap() > 0.0), "{entrant}");
    }
    for filter in &entrants[1..] {
        assert!(filter["pipeline"].as_str().unwrap().contains("temporal="), "{filter}");
        assert!(filter["relmse"].as_f64().unwrap() < 0.2 * noisy["relmse"].as_f64().unwrap(), "{filter}");
        assert!(filter["flicker"].as_f64().unwrap() < 0.5 * noisy["flicker"].as_f64().unwrap(), "{filter}");
        assert!(filter["frame_ms"].as_f64().unwrap() > 0.0, "{filter}");
    }
    // Each method's line in each plot, and the page names them all.
    let html = std::fs::read_to_string(out.join("index.html")).unwrap();
    for file in ["relmse.svg", "flicker.svg"] {
        let svg = std::fs::read_to_string(out.join(file)).unwrap();
        assert_eq!(svg.matches("<path").count(), 4, "{file}");
    }
    assert!(names.iter().all(|n| html.contains(n)), "the page names every method");
    // The viewer's pictures: every method's and the reference's, every frame.
    for view in 0..=names.len() {
        for k in 1..=3 {
            let png = out.join(format!("frames/{view}/{k:04}.png"));
            assert!(png.is_file(), "{} written", png.display());
        }
    }

    let o = filterjit(&["report", "--sequence", dir.to_str().unwrap(), "--scenes", "cornell"]);
    assert!(!o.status.success(), "--scenes with --sequence is refused");
    assert!(String::from_utf8_lossy(&o.stderr).contains("--scenes"), "{}", String::from_utf8_lossy(&o.stderr));
}
