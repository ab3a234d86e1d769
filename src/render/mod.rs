//! The built-in path tracer's host side: scene descriptions, render passes,
//! datasets on disk, and the dataset cache.
//!
//! A dataset is a directory in the layout `scene::load` reads (pbrt-v4 names
//! plus filterjit's): `noisy.exr` (colour, features and per-pixel sample
//! variances), `reference.exr`, and `meta.json` (written last; its presence
//! marks a complete dataset).

pub mod description;
pub mod packed;

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::Serialize;
use sha2::{Digest, Sha256};

use crate::gpu::{Gpu, GpuError, TraceBand};
use crate::metrics::RELMSE_EPSILON;
pub use description::{Description, DescriptionError, Split};
use packed::{TraceParams, SUMS_PER_PIXEL, VALUES_PER_SAMPLE};

/// Bumped whenever the renderer's output for the same inputs changes; part of the cache key.
pub const RENDERER_VERSION: u32 = 1;

/// Upper bound on paths in one dispatch, so that no dispatch runs long enough
/// to trip a GPU watchdog.
pub const MAX_PATHS_PER_DISPATCH: u64 = 1 << 17;

/// The scenes shipped inside the binary (`scenes/*.toml`).
pub const BUILTIN: &[(&str, &str)] = &[
    ("cornell", include_str!("../../scenes/cornell.toml")),
    ("glossy-floor", include_str!("../../scenes/glossy-floor.toml")),
    ("indirect-room", include_str!("../../scenes/indirect-room.toml")),
    ("firefly", include_str!("../../scenes/firefly.toml")),
    ("mirror-glass", include_str!("../../scenes/mirror-glass.toml")),
    ("fine-texture", include_str!("../../scenes/fine-texture.toml")),
    ("soft-shadows", include_str!("../../scenes/soft-shadows.toml")),
    ("misleading", include_str!("../../scenes/misleading.toml")),
    ("glossy-cornell", include_str!("../../scenes/glossy-cornell.toml")),
    ("noise-texture", include_str!("../../scenes/noise-texture.toml")),
    ("emitter-view", include_str!("../../scenes/emitter-view.toml")),
    ("rough-metal", include_str!("../../scenes/rough-metal.toml")),
    ("glass-caustic", include_str!("../../scenes/glass-caustic.toml")),
    ("sub-pixel-texture", include_str!("../../scenes/sub-pixel-texture.toml")),
    ("dark-corridor", include_str!("../../scenes/dark-corridor.toml")),
    ("sky-window", include_str!("../../scenes/sky-window.toml")),
    ("skylight-slot", include_str!("../../scenes/skylight-slot.toml")),
];

/// The sequences shipped inside the binary (`scenes/seq-*.toml`): scenes
/// with a `[sequence]`, rendered frame by frame with motion vectors
/// (docs/SCENES.md, "Sequences"); the temporal stage trains and is scored on them.
pub const BUILTIN_SEQUENCES: &[(&str, &str)] = &[
    ("seq-pan-pillars", include_str!("../../scenes/seq-pan-pillars.toml")),
    ("seq-dolly-room", include_str!("../../scenes/seq-dolly-room.toml")),
    ("seq-moving-ball", include_str!("../../scenes/seq-moving-ball.toml")),
    ("seq-moving-light", include_str!("../../scenes/seq-moving-light.toml")),
    ("seq-orbit-desk", include_str!("../../scenes/seq-orbit-desk.toml")),
];

/// A built-in scene (a still or a sequence) by name.
pub fn builtin(name: &str) -> Option<Result<Description, DescriptionError>> {
    BUILTIN
        .iter()
        .chain(BUILTIN_SEQUENCES)
        .find(|(n, _)| *n == name)
        .map(|(n, text)| Description::parse(n, text, Path::new(&format!("scenes/{n}.toml"))))
}

/// Every built-in sequence of a split.
pub fn builtin_sequences(split: Split) -> Vec<Description> {
    BUILTIN_SEQUENCES
        .iter()
        .map(|(n, _)| builtin(n).expect("listed").expect("built-in sequences parse"))
        .filter(|d| d.split == split)
        .collect()
}

/// Every built-in scene of a split.
pub fn builtin_split(split: Split) -> Vec<Description> {
    BUILTIN
        .iter()
        .map(|(n, _)| builtin(n).expect("listed").expect("built-in scenes parse"))
        .filter(|d| d.split == split)
        .collect()
}

/// A scene file path, or the name of a built-in scene.
pub fn describe(arg: &str) -> Result<Description, DescriptionError> {
    let path = Path::new(arg);
    if path.is_file() {
        return Description::load(path);
    }
    let name = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    match builtin(arg).or_else(|| builtin(&name)) {
        Some(d) => d,
        None => Err(DescriptionError::Io {
            file: path.into(),
            cause: std::io::Error::new(
                std::io::ErrorKind::NotFound,
                format!(
                    "no such scene file, and no built-in scene of that name (built-in: {})",
                    BUILTIN.iter().chain(BUILTIN_SEQUENCES).map(|(n, _)| *n).collect::<Vec<_>>().join(", ")
                ),
            ),
        }),
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, serde::Deserialize)]
pub struct RenderSettings {
    pub width: u32,
    pub height: u32,
    /// Samples per pixel of the noisy image.
    pub spp: u32,
    /// Samples per pixel of the reference (split in two halves to estimate its own error).
    pub reference_spp: u32,
    pub seed: u32,
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings { width: 128, height: 128, spp: 4, reference_spp: 1024, seed: 0 }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    #[error(transparent)]
    Gpu(#[from] GpuError),
    #[error(transparent)]
    Description(#[from] DescriptionError),
    #[error("{}: {message}", path.display())]
    Write { path: PathBuf, message: String },
    #[error(transparent)]
    Output(#[from] crate::io::WriteError),
    #[error("bad render settings: {0}")]
    Settings(String),
}

/// What a render pass accumulated, in f64.
struct Pass {
    sums: Vec<f64>,
    samples: u32,
}

/// A rendered dataset in memory.
pub struct Rendered {
    pub width: u32,
    pub height: u32,
    noisy: Pass,
    reference_halves: [Pass; 2],
    pub seconds: f64,
    /// Paths traced per second, both passes together.
    pub samples_per_second: f64,
}

/// Progress: (samples done, samples in all), counted in pixel samples.
pub type Progress<'a> = &'a mut dyn FnMut(u64, u64);

fn check(settings: &RenderSettings) -> Result<(), RenderError> {
    if settings.width == 0 || settings.height == 0 {
        return Err(RenderError::Settings("the image size must be at least 1x1".into()));
    }
    if settings.spp == 0 || settings.reference_spp < 2 {
        return Err(RenderError::Settings("--spp must be at least 1 and --reference-spp at least 2".into()));
    }
    Ok(())
}

/// Render a scene's noisy image with features, and its reference.
pub fn render(
    gpu: &Gpu,
    d: &Description,
    settings: &RenderSettings,
    progress: Progress<'_>,
) -> Result<Rendered, RenderError> {
    check(settings)?;
    let start = Instant::now();
    let packed = packed::pack(d);
    let scene = gpu.upload_trace_scene(&packed.inputs());
    let (pos, forward, right, up) = packed::camera(d, settings.width, settings.height);
    // A sequence's frame: motion vectors against the frame before's camera.
    let (prev_pos, prev_forward, prev_right, prev_up) = match d.animation {
        Some(_) => packed::camera(&d.at_frame_before(), settings.width, settings.height),
        None => (pos, forward, right, up),
    };
    let base = TraceParams {
        width: settings.width,
        height: settings.height,
        sample_offset: 0,
        sample_count: 0,
        seed: 0,
        with_features: 0,
        max_depth: d.max_depth,
        light_count: packed.lights.len() as u32,
        prim_count: packed.prims.len() as u32,
        row_offset: 0,
        with_motion: d.animation.is_some() as u32,
        pad: 0,
        environment: [d.environment[0], d.environment[1], d.environment[2], 0.0],
        cam_pos: pos,
        cam_forward: forward,
        cam_right: right,
        cam_up: up,
        prev_pos,
        prev_forward,
        prev_right,
        prev_up,
    };
    let pixels = settings.width as u64 * settings.height as u64;
    let total = pixels * (settings.spp as u64 + settings.reference_spp as u64);
    let mut done = 0u64;
    let mut run = |seed: u32, features: bool, first: u32, count: u32, done: &mut u64| -> Result<Pass, RenderError> {
        let mut sums = vec![0f64; pixels as usize * SUMS_PER_PIXEL];
        // Rows per dispatch (a multiple of the workgroup height) and samples per dispatch.
        let rows = ((MAX_PATHS_PER_DISPATCH / settings.width as u64).max(8) / 8 * 8).min(settings.height as u64) as u32;
        let rows = rows.max(1);
        let per_dispatch =
            (MAX_PATHS_PER_DISPATCH / (rows as u64 * settings.width as u64)).clamp(1, count as u64) as u32;
        let mut offset = 0;
        while offset < count {
            let n = per_dispatch.min(count - offset);
            let mut row = 0;
            while row < settings.height {
                let band = rows.min(settings.height - row);
                let params = TraceParams {
                    sample_offset: first + offset,
                    sample_count: n,
                    seed,
                    with_features: features as u32,
                    row_offset: row,
                    ..base
                };
                let rows = TraceBand {
                    width: settings.width,
                    height: settings.height,
                    row_offset: row,
                    rows: band,
                    sums_per_pixel: SUMS_PER_PIXEL,
                };
                let out = gpu.trace(&scene, bytemuck::bytes_of(&params), rows)?;
                let start = row as usize * settings.width as usize * SUMS_PER_PIXEL;
                for (acc, v) in sums[start..start + out.len()].iter_mut().zip(&out) {
                    *acc += *v as f64;
                }
                *done += band as u64 * settings.width as u64 * n as u64;
                progress(*done, total);
                row += band;
            }
            offset += n;
        }
        Ok(Pass { sums, samples: count })
    };
    let noisy = run(settings.seed, true, 0, settings.spp, &mut done)?;
    // The reference uses its own random streams, so it is independent of the noisy image.
    let reference_seed = settings.seed ^ 0x9e37_79b9;
    let half = settings.reference_spp / 2;
    let a = run(reference_seed, false, 0, half, &mut done)?;
    let b = run(reference_seed, false, half, settings.reference_spp - half, &mut done)?;
    let seconds = start.elapsed().as_secs_f64();
    Ok(Rendered {
        width: settings.width,
        height: settings.height,
        noisy,
        reference_halves: [a, b],
        seconds,
        samples_per_second: total as f64 / seconds.max(1e-9),
    })
}

impl Pass {
    fn mean(&self, pixel: usize, value: usize) -> f64 {
        self.sums[pixel * SUMS_PER_PIXEL + value] / self.samples as f64
    }

    /// Unbiased per-sample variance (ddof = 1) of one value.
    fn variance(&self, pixel: usize, value: usize) -> f64 {
        let n = self.samples as f64;
        if self.samples < 2 {
            return 0.0;
        }
        let sum = self.sums[pixel * SUMS_PER_PIXEL + value];
        let squares = self.sums[pixel * SUMS_PER_PIXEL + VALUES_PER_SAMPLE + value];
        ((squares - sum * sum / n) / (n - 1.0)).max(0.0)
    }
}

impl Rendered {
    fn pixels(&self) -> usize {
        (self.width * self.height) as usize
    }

    /// The reference colour: both halves together.
    pub fn reference(&self) -> Vec<[f32; 3]> {
        let [a, b] = &self.reference_halves;
        let n = (a.samples + b.samples) as f64;
        (0..self.pixels())
            .map(|p| {
                std::array::from_fn(|q| ((a.sums[p * SUMS_PER_PIXEL + q] + b.sums[p * SUMS_PER_PIXEL + q]) / n) as f32)
            })
            .collect()
    }

    /// The noisy colour.
    pub fn noisy(&self) -> Vec<[f32; 3]> {
        (0..self.pixels()).map(|p| std::array::from_fn(|q| self.noisy.mean(p, q) as f32)).collect()
    }

    /// Estimated relMSE of the reference against the converged image, from its
    /// two independent halves A and B: Var(reference) ≈ (A − B)² / 4.
    pub fn reference_residual_relmse(&self) -> f64 {
        let [a, b] = &self.reference_halves;
        let reference = self.reference();
        let mut total = 0.0;
        for (p, g) in reference.iter().enumerate() {
            for (q, g) in g.iter().enumerate() {
                let d = a.mean(p, q) - b.mean(p, q);
                total += d * d / 4.0 / (*g as f64 * *g as f64 + RELMSE_EPSILON);
            }
        }
        total / self.pixels() as f64
    }

    /// Write the dataset into `dir` (created if needed); `meta.json` last.
    pub fn write(&self, dir: &Path, d: &Description, settings: &RenderSettings) -> Result<(), RenderError> {
        let werr = |path: &Path, message: String| RenderError::Write { path: path.into(), message };
        std::fs::create_dir_all(dir).map_err(|e| werr(dir, e.to_string()))?;
        let n = self.pixels();
        let mut channels: Vec<(&str, Vec<f32>)> = Vec::new();
        let mean = |value: usize| (0..n).map(|p| self.noisy.mean(p, value) as f32).collect::<Vec<f32>>();
        let variance = |value: usize| (0..n).map(|p| self.noisy.variance(p, value) as f32).collect::<Vec<f32>>();
        let mean_variance = |first: usize| {
            (0..n)
                .map(|p| ((0..3).map(|c| self.noisy.variance(p, first + c)).sum::<f64>() / 3.0) as f32)
                .collect::<Vec<f32>>()
        };
        // Values per sample: 0 colour, 3 albedo, 6 position, 9 normal, 12 secondary albedo, 15 depth, 16 visibility.
        for (k, name) in ["R", "G", "B"].iter().enumerate() {
            channels.push((name, mean(k)));
        }
        for (first, names) in [
            (3, ["Albedo.R", "Albedo.G", "Albedo.B"]),
            (6, ["P.X", "P.Y", "P.Z"]),
            (9, ["Ns.X", "Ns.Y", "Ns.Z"]),
            (12, ["SecondaryAlbedo.R", "SecondaryAlbedo.G", "SecondaryAlbedo.B"]),
        ] {
            for (c, name) in names.iter().enumerate() {
                channels.push((name, mean(first + c)));
            }
        }
        channels.push(("Z", mean(15)));
        channels.push(("DirectVisibility", mean(16)));
        if d.animation.is_some() {
            // Blender's Vector pass: where each pixel's surface was in the frame before minus where it is, y up.
            channels.push(("Vector.X", mean(17)));
            channels.push(("Vector.Y", mean(18)));
        }
        for (k, name) in ["Variance.R", "Variance.G", "Variance.B"].iter().enumerate() {
            channels.push((name, variance(k)));
        }
        channels.push(("AlbedoVariance", mean_variance(3)));
        channels.push(("PVariance", mean_variance(6)));
        channels.push(("NVariance", mean_variance(9)));
        channels.push(("SecondaryAlbedoVariance", mean_variance(12)));
        channels.push(("ZVariance", variance(15)));
        channels.push(("DirectVisibilityVariance", variance(16)));
        let noisy_path = dir.join(crate::scene::NOISY_FILE);
        crate::scene::exr_io::write_channels(&noisy_path, self.width as usize, self.height as usize, &channels)
            .map_err(|e| werr(&noisy_path, e.to_string()))?;
        let reference_path = dir.join(crate::scene::REFERENCE_FILE);
        crate::scene::exr_io::write_rgb(&reference_path, self.width as usize, self.height as usize, &self.reference())
            .map_err(|e| werr(&reference_path, e.to_string()))?;
        let meta = serde_json::json!({
            "scene": d.name,
            "frame": d.animation.map(|_| d.frame + 1),
            "split": d.split,
            "description": d.summary,
            "spp": settings.spp,
            "reference_spp": settings.reference_spp,
            "width": settings.width,
            "height": settings.height,
            "seed": settings.seed,
            "renderer_version": RENDERER_VERSION,
            "reference_residual_relmse": self.reference_residual_relmse(),
            "render_seconds": self.seconds,
            "samples_per_second": self.samples_per_second,
        });
        let meta_path = dir.join(crate::scene::META_FILE);
        crate::io::write_bytes_atomically(&meta_path, serde_json::to_string_pretty(&meta).expect("json").as_bytes())?;
        Ok(())
    }
}

/// The name of frame `k` (from 0) of a sequence, as Blender numbers its frames: `frame_0001`.
pub fn frame_name(k: u32) -> String {
    format!("frame_{:04}", k + 1)
}

/// Render every frame of a sequence (`d` with an animation) into `dir`:
/// `frame_0001/`, … each a dataset with its reference, each frame with its
/// own noise; `sequence.json` last (its presence marks a complete sequence).
pub fn render_sequence(
    gpu: &Gpu,
    d: &Description,
    settings: &RenderSettings,
    dir: &Path,
    progress: Progress<'_>,
) -> Result<(), RenderError> {
    let animation = d
        .animation
        .ok_or_else(|| RenderError::Settings(format!("scene `{}` has no [sequence]: it is a still", d.name)))?;
    let frames = animation.frames;
    for k in 0..frames {
        let frame = d.at_frame(k);
        // Each frame its own noise, as Cycles' animated seed gives.
        let frame_settings = RenderSettings { seed: settings.seed.wrapping_add(k.wrapping_mul(7919)), ..*settings };
        let mut frame_progress = |done: u64, total: u64| progress(k as u64 * total + done, frames as u64 * total);
        let rendered = render(gpu, &frame, &frame_settings, &mut frame_progress)?;
        rendered.write(&dir.join(frame_name(k)), &frame, &frame_settings)?;
    }
    let meta = serde_json::json!({
        "scene": d.name,
        "frames": frames,
        "spp": settings.spp,
        "reference_spp": settings.reference_spp,
        "width": settings.width,
        "height": settings.height,
        "seed": settings.seed,
        "renderer_version": RENDERER_VERSION,
    });
    let path = dir.join(SEQUENCE_META);
    crate::io::write_bytes_atomically(&path, serde_json::to_string_pretty(&meta).expect("json").as_bytes())?;
    Ok(())
}

/// The file whose presence marks a rendered sequence complete.
pub const SEQUENCE_META: &str = "sequence.json";

/// The cache directory of a scene rendered with some settings: keyed by the
/// description's text, the settings and the renderer version.
pub fn cache_dir(root: &Path, d: &Description, settings: &RenderSettings) -> PathBuf {
    let mut hasher = Sha256::new();
    hasher.update(RENDERER_VERSION.to_le_bytes());
    hasher.update(d.source.as_bytes());
    hasher.update(serde_json::to_string(settings).expect("json").as_bytes());
    let key: [u8; 32] = hasher.finalize().into();
    let hex: String = key[..8].iter().map(|b| format!("{b:02x}")).collect();
    root.join("datasets").join(format!("{}-{}x{}-{}spp-{hex}", d.name, settings.width, settings.height, settings.spp))
}

/// The dataset of a scene, rendered now unless the cache under `root`
/// ([`crate::environment::Environment::cache`] for the user's cache) has it.
pub fn cached(
    gpu: &Gpu,
    root: &Path,
    d: &Description,
    settings: &RenderSettings,
    progress: Progress<'_>,
) -> Result<PathBuf, RenderError> {
    let dir = cache_dir(root, d, settings);
    // A sequence is complete once its `sequence.json` is there, a still once its `meta.json` is.
    let marker = if d.animation.is_some() { SEQUENCE_META } else { crate::scene::META_FILE };
    if dir.join(marker).is_file() {
        return Ok(dir);
    }
    // Render into a private directory, then move it into place in one step.
    let tmp = dir.with_extension(format!("tmp-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&tmp);
    if let Some(parent) = dir.parent() {
        std::fs::create_dir_all(parent)
            .map_err(|e| RenderError::Write { path: parent.into(), message: e.to_string() })?;
    }
    match d.animation {
        Some(_) => render_sequence(gpu, d, settings, &tmp, progress)?,
        None => render(gpu, d, settings, progress)?.write(&tmp, d, settings)?,
    }
    if let Err(e) = std::fs::rename(&tmp, &dir) {
        let _ = std::fs::remove_dir_all(&tmp);
        if !dir.join(marker).is_file() {
            return Err(RenderError::Write { path: dir, message: e.to_string() });
        }
    }
    Ok(dir)
}
