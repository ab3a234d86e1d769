//! `keep`'s spread kernels: what the outlier clamp removed, spread over the
//! neighbourhood and put back before demodulation. One module for every
//! pipeline of each kind: `keep` from `templates/spread.wgsl.tera`,
//! `keep=surface` from `templates/spread_surface.wgsl.tera`, with the stencil
//! and constants `crate::pipeline` owns; `cpu::spread` and
//! `cpu::spread_surface` are their references.

use super::interface::{render_builtin, BindingInterface};
use super::kernel::{wgsl_f32, OutputFormat};
use super::validate::{validate_with_interface, ValidateError, ValidatedModule};
use crate::pipeline::{self, Keep};

/// The pipeline-overridable constant (a `u32`) that holds a dispatch's stage
/// bits in filterjit's own spread kernels, which make a pipeline per stage;
/// exported kernels read `params.stage`.
pub const SPREAD_STAGE: &str = "STAGE";

/// How a spread kernel's text names its stage bits.
fn stage_name(textures: Option<OutputFormat>) -> &'static str {
    if textures.is_some() {
        "params.stage"
    } else {
        SPREAD_STAGE
    }
}

/// What one pass of the spread kernel does: bits of `params.stage`.
pub struct SpreadStage;

impl SpreadStage {
    /// The first pass spreads raw colour − clamped colour; later ones the previous pass's output.
    pub const FIRST: u32 = 1;
    /// The last pass writes (spread + clamped) / modulation, the colour the
    /// form filters, instead of the spread alone: no dispatch of its own.
    pub const FINISH: u32 = 2;
}

/// What one dispatch of the surface spread kernel does: bits of `params.stage`
/// (`templates/spread_surface.wgsl.tera` says each in full).
pub struct SurfaceStage;

impl SurfaceStage {
    /// The first workgroup sums the clamped colour's luminance into `total`.
    pub const TOTAL: u32 = 1;
    /// The value is raw colour − clamped colour.
    pub const FIRST: u32 = 2;
    /// The value is the previous level gathered at step / 2.
    pub const GATHER: u32 = 4;
    /// Writes (value + clamped) / modulation instead of the normalised shares.
    pub const FINISH: u32 = 8;
    /// Writes each pixel's normal direction and clamped luminance into
    /// `surface`, which the taps of every later dispatch read: one load a tap
    /// instead of two, and no normalisation.
    pub const SURFACE: u32 = 16;
}

/// The spread kernel's uniform (`struct Params` of its module; fields in [`BindingInterface::spread`]).
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct SpreadParams {
    pub width: u32,
    pub height: u32,
    /// Pixel step between taps: 2^pass (the surface spread's: the level it normalises).
    pub step: u32,
    /// [`SpreadStage`] bits (`keep`'s), or [`SurfaceStage`] bits (`keep=surface`'s).
    pub stage: u32,
}

/// What a spread dispatch reads as its `Color`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SpreadSource {
    /// The noisy colour (the first dispatch spreads it minus the clamped colour).
    Noisy,
    /// Scratch image k (0 or 1), which the dispatch before wrote.
    Scratch(usize),
}

/// What a spread dispatch writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SpreadTarget {
    /// Scratch image k (0 or 1).
    Scratch(usize),
    /// The surface spread's per-pixel direction and luminance (its first dispatch).
    Surface,
    /// The surface spread's one-texel `total` (its second dispatch).
    Total,
}

/// One dispatch of a spread: its uniform, the image it reads and the
/// image it writes. Two scratch images are ping-ponged; the last
/// dispatch's is the colour the form filters.
#[derive(Clone, Copy, Debug)]
pub struct SpreadDispatch {
    pub params: SpreadParams,
    pub source: SpreadSource,
    pub target: SpreadTarget,
}

/// What the dispatch does, in a few words (a profile's name for it).
impl std::fmt::Display for SpreadDispatch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.target {
            SpreadTarget::Surface => write!(f, "surface: directions and luminance"),
            SpreadTarget::Total => write!(f, "surface: total luminance (one workgroup)"),
            SpreadTarget::Scratch(_) => write!(f, "step {}", self.params.step),
        }
    }
}

/// Whether the `n`th dispatch of `sequence` finds `image` written by one
/// before it. Where not (the dispatch that writes it, and the total in the
/// one before that), a host binds a stand-in image there, which it never reads.
pub fn written_before(sequence: &[SpreadDispatch], n: usize, image: SpreadTarget) -> bool {
    sequence[..n].iter().any(|d| d.target == image)
}

impl SpreadParams {
    /// The dispatches of one spread of kind `keep`, in order.
    pub fn sequence(keep: Keep, width: u32, height: u32) -> Vec<SpreadDispatch> {
        let params =
            |level: u32, stage: u32| SpreadParams { width, height, step: pipeline::FilterPipeline::step(level), stage };
        let scratch = |n: usize| SpreadDispatch {
            params: params(0, 0),
            source: if n == 0 { SpreadSource::Noisy } else { SpreadSource::Scratch((n - 1) % 2) },
            target: SpreadTarget::Scratch(n % 2),
        };
        let passes = keep.passes();
        match keep {
            Keep::Even => (0..passes)
                .map(|level| SpreadDispatch {
                    params: params(
                        level,
                        if level == 0 { SpreadStage::FIRST } else { 0 }
                            | if level == passes - 1 { SpreadStage::FINISH } else { 0 },
                    ),
                    ..scratch(level as usize)
                })
                .collect(),
            // Each pixel's direction and luminance, and their total, first;
            // then level k's shares are normalised in the dispatch that
            // gathers level k − 1, and the last one gathers level passes − 1
            // and finishes.
            Keep::Surface => {
                [(SurfaceStage::SURFACE, SpreadTarget::Surface), (SurfaceStage::TOTAL, SpreadTarget::Total)]
                    .map(|(stage, target)| SpreadDispatch {
                        params: params(0, stage),
                        source: SpreadSource::Noisy,
                        target,
                    })
                    .into_iter()
                    .chain((0..=passes).map(|level| SpreadDispatch {
                        params: params(
                            level,
                            if level == 0 { SurfaceStage::FIRST } else { SurfaceStage::GATHER }
                                | if level == passes { SurfaceStage::FINISH } else { 0 },
                        ),
                        ..scratch(level as usize)
                    }))
                    .collect()
            }
        }
    }
}

/// The spread kernel's WGSL: its images sampled, its output a storage buffer (filterjit's, `None`), or
/// exported, on textures (its output `rgba32float` whatever `format` is).
pub fn spread_wgsl(textures: Option<OutputFormat>) -> String {
    let half = pipeline::KEEP_STENCIL.half_width();
    let values = SpreadTemplate {
        passes: pipeline::KEEP_PASSES,
        textures: textures.is_some(),
        stage: stage_name(textures),
        taps: (-half..=half).map(|d| (d, wgsl_f32(pipeline::KEEP_STENCIL.weight(d)))).collect(),
        first: SpreadStage::FIRST,
        finish: SpreadStage::FINISH,
    };
    let template = include_str!("../../templates/spread.wgsl.tera");
    render_builtin("spread", template, &BindingInterface::spread(textures), &values)
}

/// What `templates/spread.wgsl.tera` reads beside the interface.
#[derive(serde::Serialize)]
struct SpreadTemplate {
    passes: u32,
    textures: bool,
    /// How the template names the uniform's stage field.
    stage: &'static str,
    /// Each tap's offset and weight h(offset), across the stencil in order.
    taps: Vec<(i32, String)>,
    first: u32,
    finish: u32,
}

/// The spread kernel, validated by naga; its bindings are checked against its interface.
pub fn spread_module(textures: Option<OutputFormat>) -> Result<ValidatedModule, ValidateError> {
    validate_with_interface(&spread_wgsl(textures), "<spread>", &BindingInterface::spread(textures))
}

/// The lanes of the surface spread's total: one workgroup's invocations.
const TOTAL_LANES: u32 = super::WORKGROUP[0] * super::WORKGROUP[1];
// The template adds the lanes' sums pairwise, halving: a power of two.
const _: () = assert!(TOTAL_LANES.is_power_of_two());

/// The surface spread kernel's WGSL (`keep=surface`), on storage buffers or
/// exported on textures, as [`spread_wgsl`].
pub fn spread_surface_wgsl(textures: Option<OutputFormat>) -> String {
    let half = pipeline::KEEP_STENCIL.half_width();
    let values = SurfaceSpreadTemplate {
        dispatches: SpreadParams::sequence(Keep::Surface, 0, 0).len(),
        textures: textures.is_some(),
        stage: stage_name(textures),
        taps: (-half..=half)
            .flat_map(|dy| (-half..=half).map(move |dx| (dx, dy)))
            .map(|(dx, dy)| (dx, dy, wgsl_f32(pipeline::KEEP_STENCIL.weight(dx) * pipeline::KEEP_STENCIL.weight(dy))))
            .collect(),
        luminance: pipeline::LUMINANCE.map(wgsl_f32),
        sigma: wgsl_f32(pipeline::SURFACE_KEEP_NORMAL_SIGMA),
        floor_factor: wgsl_f32(pipeline::SURFACE_KEEP_LIGHT_FLOOR),
        lanes: TOTAL_LANES,
        surface: SurfaceStage::SURFACE,
        total: SurfaceStage::TOTAL,
        first: SurfaceStage::FIRST,
        gather: SurfaceStage::GATHER,
        finish: SurfaceStage::FINISH,
    };
    let template = include_str!("../../templates/spread_surface.wgsl.tera");
    render_builtin("spread_surface", template, &BindingInterface::spread_surface(textures), &values)
}

/// What `templates/spread_surface.wgsl.tera` reads beside the interface:
/// the stages' bits ([`SurfaceStage`]) and the constants `crate::pipeline` owns.
#[derive(serde::Serialize)]
struct SurfaceSpreadTemplate {
    dispatches: usize,
    textures: bool,
    stage: &'static str,
    /// Each tap's offsets (dx, dy) and weight h(dx)·h(dy), row by row.
    taps: Vec<(i32, i32, String)>,
    luminance: [String; 3],
    sigma: String,
    floor_factor: String,
    lanes: u32,
    surface: u32,
    total: u32,
    first: u32,
    gather: u32,
    finish: u32,
}

/// The surface spread kernel, validated by naga; its bindings are checked against its interface.
pub fn spread_surface_module(textures: Option<OutputFormat>) -> Result<ValidatedModule, ValidateError> {
    validate_with_interface(
        &spread_surface_wgsl(textures),
        "<surface spread>",
        &BindingInterface::spread_surface(textures),
    )
}

/// The binding interface of the kernel `keep` spreads with.
pub fn spread_interface(keep: Keep, textures: Option<OutputFormat>) -> BindingInterface {
    match keep {
        Keep::Even => BindingInterface::spread(textures),
        Keep::Surface => BindingInterface::spread_surface(textures),
    }
}

/// The kernel `keep` spreads with: its interface, WGSL and validated module.
pub fn spread_kernel(
    keep: Keep,
    textures: Option<OutputFormat>,
) -> (BindingInterface, String, Result<ValidatedModule, ValidateError>) {
    let (wgsl, module) = match keep {
        Keep::Even => (spread_wgsl(textures), spread_module(textures)),
        Keep::Surface => (spread_surface_wgsl(textures), spread_surface_module(textures)),
    };
    (spread_interface(keep, textures), wgsl, module)
}
