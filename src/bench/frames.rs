//! The filter pipeline's stages and forms, and whole frames of the shipped
//! à-trous filters against the peer, on a frame of [`FRAME_SIDE`]².

use std::time::{Duration, Instant};

use serde::Serialize;

use super::timing::{ms, stat, Stat};
use crate::gpu::{Gpu, SceneBuffers, Span};
use crate::jit::{self};
use crate::lang::{parse_expr, Expr};
use crate::metrics;
use crate::scene::Scene;

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
/// the pipeline it is stored with (wall time from recording its pre-pass,
/// guide and passes, in one submission, to completion; uploads excluded), or
/// OIDN (wall time of each execution, as `oidnDenoise` reports it, on the
/// device it chose).
#[derive(Clone, Debug, Serialize)]
pub struct FrameResult {
    pub method: String,
    pub pipeline: String,
    /// The frame's size.
    pub width: usize,
    pub height: usize,
    /// Pipeline creation plus the first frame (none for OIDN: its program creates its filter each run).
    pub compile_ms: Option<f64>,
    pub warm_ms: Stat,
    pub ms_per_mpx: f64,
    /// This method's warm median over OIDN's (none without OIDN).
    pub over_oidn: Option<f64>,
    /// The output's mean luminance over the reference's, on the bench scene
    /// itself (the frame is that scene tiled, without a reference).
    pub light: Option<f64>,
    /// Where a shipped filter's frame goes: the medians of its pre-pass
    /// (outliers, `keep`'s spread, demodulation), its temporal stage, its
    /// guide and its passes, in ms, on the device's clock where it has one
    /// (none for OIDN). They need not add up to `warm_ms`'s median.
    pub parts_ms: Option<FrameParts>,
    /// The same frame on the device's own clock, the sum of its parts' (none
    /// where the device has no clock, and for OIDN): the GPU's work, without
    /// the submit–wait round trips.
    pub device: Option<Stat>,
    /// `warm_ms`'s median: the frame's wall time.
    pub wall_ms: f64,
    /// `device`'s median, where measured.
    pub device_ms: Option<f64>,
    /// Where `bench --frames --profile` asked: each kernel's share of the
    /// frame on the device's clock, in the order they first ran (none for
    /// OIDN, and where the device has no clock).
    pub profile: Option<Vec<KernelTime>>,
}

/// One kernel's compute passes in a profiled frame ([`crate::gpu::Gpu::set_profiling`]).
#[derive(Clone, Debug, Serialize)]
pub struct KernelTime {
    pub kernel: String,
    /// Its passes a frame.
    pub dispatches: usize,
    /// Their time a frame on the device's clock, the median over [`PROFILED_FRAMES`].
    pub device_ms: f64,
}

/// Frames each method is profiled over, after its timed rounds.
pub const PROFILED_FRAMES: usize = 3;

/// `passes` of [`PROFILED_FRAMES`] frames in the order they ran, gathered by
/// kernel: its passes a frame and the median of its time a frame.
fn by_kernel(frames: &[Vec<crate::gpu::TimedPass>]) -> Vec<KernelTime> {
    let mut kernels: Vec<String> = Vec::new();
    for pass in frames.iter().flatten() {
        if !kernels.contains(&pass.kernel) {
            kernels.push(pass.kernel.clone());
        }
    }
    kernels
        .into_iter()
        .map(|kernel| {
            let mine = |frame: &Vec<crate::gpu::TimedPass>| -> Vec<Option<Duration>> {
                frame.iter().filter(|p| p.kernel == kernel).map(|p| p.device).collect()
            };
            let dispatches = frames.first().map_or(0, |f| mine(f).len());
            let sums = frames.iter().map(|f| ms(mine(f).into_iter().flatten().sum())).collect();
            KernelTime { kernel, dispatches, device_ms: stat(sums).median }
        })
        .collect()
}

/// The medians of a frame's parts, in ms.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct FrameParts {
    pub prepass: f64,
    /// The temporal stage (0 without one).
    pub temporal: f64,
    pub guide: f64,
    pub passes: f64,
}

/// A filter whose whole frames are timed: a shipped one in its own pipeline.
pub struct FrameMethod {
    pub name: String,
    pub expr: Expr,
    pub pipeline: crate::pipeline::FilterPipeline,
}

impl FrameMethod {
    /// A shipped filter, `@name`, in the pipeline it is stored with.
    pub fn shipped(name: &str) -> anyhow::Result<FrameMethod> {
        FrameMethod::resolve(&format!("@{name}"), name)
    }

    /// An expression argument (`@name`, `@FILE[:NAME]` or text) in the
    /// pipeline stored with it, else `filter`'s default one; called `@NAME`,
    /// or `unnamed` where the argument has no name.
    pub fn resolve(arg: &str, unnamed: &str) -> anyhow::Result<FrameMethod> {
        let resolved = crate::corpus::resolve_with_pipeline(arg)?;
        let name = resolved.name.map_or_else(|| unnamed.to_string(), |n| format!("@{n}"));
        Ok(FrameMethod { name, expr: resolved.expr, pipeline: resolved.pipeline.unwrap_or_default() })
    }
}

/// Side of the frame the pipeline's stages are timed on (the size OIDN is compared at).
pub const FRAME_SIDE: usize = 256;

/// Each stage's and each form's time on a frame of [`FRAME_SIDE`]² (the bench
/// scene tiled), measured in interleaved rounds: the pre-pass (outliers and
/// demodulation; the difference between preparing the frame's buffers with it
/// and without, so uploads cancel), and `@crossBilateral` as a window of
/// radius 3 and 10 and as 5 à-trous passes.
pub(super) fn pipeline_stages(gpu: &Gpu, scene: &Scene, repeats: usize) -> anyhow::Result<Vec<StageResult>> {
    use crate::pipeline::FilterPipeline;
    let frame = scene.tiled(FRAME_SIDE);
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
        let kernel =
            jit::compile(&expr, jit::KernelSpec { shape: jit::Shape::of(&pipeline), ..jit::KernelSpec::default() })?;
        let lower_validate = ms(t.elapsed());
        let mut buffers = SceneBuffers::for_pipeline(gpu, &frame, &pipeline)?;
        let t = Instant::now();
        gpu.filter(&kernel, &mut buffers, &frame, radius)?;
        prepared.push((name, kernel, buffers, radius, lower_validate, ms(t.elapsed())));
    }
    let mut times = vec![Vec::new(); prepared.len()];
    for _ in 0..repeats.max(1) * 2 {
        for (k, (_, kernel, buffers, radius, _, _)) in prepared.iter_mut().enumerate() {
            times[k].push(ms(gpu.filter(kernel, buffers, &frame, *radius)?.time.wall));
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
/// of [`FRAME_SIDE`]² (the bench scene tiled), and OIDN on the same frame
/// ([`frames`]).
pub(super) fn whole_frames(
    gpu: &Gpu,
    renders: &[Scene],
    repeats: usize,
    peer: Option<&crate::oidn::Oidn>,
    scratch: &std::path::Path,
) -> anyhow::Result<Vec<FrameResult>> {
    let methods: Vec<FrameMethod> = crate::corpus::named()
        .into_iter()
        .filter_map(|(name, text)| {
            let pipeline = crate::corpus::shipped().get(name)?.pipeline?;
            pipeline
                .is_atrous()
                .then(|| Ok(FrameMethod { name: format!("@{name}"), expr: parse_expr(text)?, pipeline }))
        })
        .collect::<anyhow::Result<_>>()?;
    frames(gpu, renders, (FRAME_SIDE, FRAME_SIDE), &methods, &Rounds { repeats, profile: false, scratch }, peer)
}

/// How each method's frames are measured: `repeats` (twice that many timed
/// rounds), whether its kernels are profiled after them, and where OIDN's files go.
#[derive(Clone, Copy)]
pub struct Rounds<'a> {
    pub repeats: usize,
    pub profile: bool,
    pub scratch: &'a std::path::Path,
}

/// `methods` and OIDN colour + albedo + normal (where its program is
/// found) on whole frames of `size`, the bench scene tiled, in interleaved
/// rounds: a filter's frame is its pre-pass, temporal stage, guide and passes
/// in one submission (the frame's buffers made afresh each round, uploads
/// not counted), as a renderer runs it; OIDN's is its program's own time for
/// each execution on the device it chose. With `profile`, each method's
/// kernels are then timed pass by pass over [`PROFILED_FRAMES`] more frames.
///
/// `renders` are the bench scene rendered with different seeds, the first
/// the one every single-image filter and OIDN take. A temporal filter's
/// frames are a still camera's sequence as a renderer makes it, each frame
/// its own noise: its k-th frame is render k mod n's, and its history is
/// carried from round to round after a few frames to settle. (One render
/// fed again and again is no renderer's sequence: its history converges on
/// that render's own samples, and the history test then cuts every pixel
/// whose sample stands out from its neighbours, each frame.)
pub fn frames(
    gpu: &Gpu,
    renders: &[Scene],
    (width, height): (usize, usize),
    methods: &[FrameMethod],
    rounds: &Rounds,
    peer: Option<&crate::oidn::Oidn>,
) -> anyhow::Result<Vec<FrameResult>> {
    let Rounds { repeats, profile, scratch } = *rounds;
    let scene = renders.first().expect("the bench scene has a render");
    // Only a temporal filter reads the renders after the first.
    let used = if methods.iter().any(|m| m.pipeline.is_temporal()) { renders.len() } else { 1 };
    let sequence: Vec<Scene> = renders[..used].iter().map(|render| render.tiled_to(width, height).still()).collect();
    let frame = &sequence[0];
    // A temporal filter's n-th frame (0: the one its kernels compile on).
    let nth_frame = |n: usize| &sequence[n % sequence.len()];
    // What a method filters in timed round `round` (the profiled frames continue the count).
    let frame_of = |method: &FrameMethod, round: usize| {
        if method.pipeline.is_temporal() {
            nth_frame(SETTLING_FRAMES + 1 + round)
        } else {
            frame
        }
    };
    let mpx = frame.pixels() as f64 / 1e6;
    let radius = 2;
    let reference = scene.reference.as_ref().expect("the bench scene has a reference");
    let still = scene.still();
    let mut prepared = Vec::new();
    for method in methods {
        let FrameMethod { expr, pipeline, .. } = method;
        let t = Instant::now();
        let kernel =
            jit::compile(expr, jit::KernelSpec { shape: jit::Shape::of(pipeline), ..jit::KernelSpec::default() })?;
        let mut state = crate::gpu::TemporalState::new();
        let mut buffers = SceneBuffers::for_frame(gpu, frame, pipeline)?;
        gpu.filter_frame(&kernel, &mut buffers, frame, radius, &mut state)?;
        let compile = ms(t.elapsed());
        // A temporal stage settles over its first frames: time it once it has.
        let settling = if pipeline.is_temporal() { SETTLING_FRAMES } else { 0 };
        for n in 1..=settling {
            let frame = nth_frame(n);
            let mut buffers = SceneBuffers::for_frame(gpu, frame, pipeline)?;
            gpu.filter_frame(&kernel, &mut buffers, frame, radius, &mut state)?;
        }
        let mut on_scene = SceneBuffers::for_frame(gpu, &still, pipeline)?;
        let light = metrics::light(&gpu.filter(&kernel, &mut on_scene, &still, radius)?.rgb(), reference);
        prepared.push((method, kernel, state, compile, light));
    }
    let mut times = vec![Vec::new(); prepared.len()];
    let mut parts = vec![[Vec::new(), Vec::new(), Vec::new(), Vec::new()]; prepared.len()];
    let mut on_device = vec![Vec::new(); prepared.len()];
    for round in 0..repeats.max(1) * 2 {
        for (k, (method, kernel, state, _, _)) in prepared.iter_mut().enumerate() {
            // A frame as a renderer runs it: the pre-pass, the temporal stage, the
            // guide (where the weight reads it) and the passes in one submission, uploads excluded.
            let frame = frame_of(method, round);
            let mut buffers = SceneBuffers::for_frame(gpu, frame, &method.pipeline)?;
            let whole = gpu.filter_frame(kernel, &mut buffers, frame, radius, state)?.time;
            times[k].push(ms(whole.wall));
            // Its parts on the device's clock where it has one, else the
            // recording's wall time (the passes' then hold the waiting).
            let part = |span: Option<Span>| span.map_or(Duration::ZERO, |s| s.device.unwrap_or(s.wall));
            let (prepass, temporal, guide) =
                (part(buffers.prepass_time()), part(buffers.temporal_time()), part(buffers.guide_time()));
            let passes = whole.device.unwrap_or(whole.wall).saturating_sub(prepass + temporal + guide);
            for (part, t) in parts[k].iter_mut().zip([prepass, temporal, guide, passes]) {
                part.push(ms(t));
            }
            if let Some(device) = whole.device {
                on_device[k].push(ms(device));
            }
        }
    }
    let mut profiles = vec![None; prepared.len()];
    if profile && gpu.has_device_clock() {
        for (k, (method, kernel, state, _, _)) in prepared.iter_mut().enumerate() {
            let mut passes = Vec::new();
            for n in 0..PROFILED_FRAMES {
                let frame = frame_of(method, repeats.max(1) * 2 + n);
                let mut buffers = SceneBuffers::for_frame(gpu, frame, &method.pipeline)?;
                // Only the frame's own submission is profiled, not the uploads'.
                gpu.set_profiling(true);
                let filtered = gpu.filter_frame(kernel, &mut buffers, frame, radius, state);
                passes.push(gpu.take_profile());
                gpu.set_profiling(false);
                filtered?;
            }
            profiles[k] = Some(by_kernel(&passes));
        }
    }
    let oidn = match peer {
        Some(oidn) => {
            let dir = scratch.join(format!("filterjit-bench-oidn-{}", std::process::id()));
            let denoised = oidn.denoise(frame, crate::oidn::Auxiliary::AlbedoNormal, repeats.max(1) * 2, &dir);
            let on_scene = oidn.denoise(scene, crate::oidn::Auxiliary::AlbedoNormal, 1, &dir);
            let _ = std::fs::remove_dir_all(&dir);
            let denoised = denoised?;
            Some((stat(denoised.warm_ms), metrics::light(&on_scene?.color, reference), denoised.device))
        }
        None => None,
    };
    let over = |median: f64| oidn.as_ref().map(|(o, _, _)| median / o.median);
    let mut results: Vec<FrameResult> = prepared
        .into_iter()
        .zip(times)
        .zip(parts)
        .zip(on_device)
        .zip(profiles)
        .map(
            |(
                ((((method, _, _, compile_ms, light), times), [prepass, temporal, guide, passes]), on_device),
                profile,
            )| {
                let warm_ms = stat(times);
                let parts_ms = FrameParts {
                    prepass: stat(prepass).median,
                    temporal: stat(temporal).median,
                    guide: stat(guide).median,
                    passes: stat(passes).median,
                };
                FrameResult {
                    method: method.name.clone(),
                    pipeline: method.pipeline.to_string(),
                    width,
                    height,
                    compile_ms: Some(compile_ms),
                    ms_per_mpx: warm_ms.median / mpx,
                    over_oidn: over(warm_ms.median),
                    wall_ms: warm_ms.median,
                    warm_ms,
                    light,
                    parts_ms: Some(parts_ms),
                    device_ms: (!on_device.is_empty()).then(|| stat(on_device.clone()).median),
                    device: (!on_device.is_empty()).then(|| stat(on_device)),
                    profile,
                }
            },
        )
        .collect();
    if let Some((warm_ms, light, device)) = oidn {
        results.push(FrameResult {
            method: format!("OIDN colour+albedo+normal ({device})"),
            pipeline: "-".into(),
            width,
            height,
            compile_ms: None,
            ms_per_mpx: warm_ms.median / mpx,
            over_oidn: Some(1.0),
            wall_ms: warm_ms.median,
            warm_ms,
            light,
            parts_ms: None,
            device: None,
            device_ms: None,
            profile: None,
        });
    }
    Ok(results)
}

/// Frames a temporal stage runs before its frames are timed: its history is
/// then as long as a sequence's settles to (1/α frames at α = 0.2).
const SETTLING_FRAMES: usize = 5;
