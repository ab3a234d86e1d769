//! `anchor=K`'s kernel (docs/SEMANTICS.md, "The pipeline"; the formula at
//! `pipeline::Anchor`): one module for the whole stage, a dispatch that
//! averages the frame's 2×2 blocks, one per blur level on that grid and one
//! that scales the image, told apart by the uniform's `level`; rendered from `templates/anchor.wgsl.tera` with the constants
//! `crate::pipeline` owns. `cpu::anchor_light` is its reference.

use super::interface::{render_builtin, BindingInterface};
use super::kernel::{wgsl_f32, OutputFormat};
use super::validate::{validate_with_interface, ValidateError, ValidatedModule};
use crate::pipeline::{self, Anchor, ANCHOR_LEVELS};

/// The kernel's uniform (`struct Params` of its module; fields in [`BindingInterface::anchor`]).
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct AnchorParams {
    pub width: u32,
    pub height: u32,
    /// 0: average the frame's 2×2 blocks into the half-resolution grid;
    /// 1 ..= [`ANCHOR_LEVELS`]: blur level `level - 1` on the grid;
    /// [`ANCHOR_LEVELS`] + 1: scale the image.
    pub level: u32,
    pub gate: f32,
}

impl AnchorParams {
    /// The stage's dispatches in order: the blocks averaged, every blur level, then the scaling.
    pub fn sequence(anchor: Anchor, width: u32, height: u32) -> Vec<AnchorParams> {
        (0..ANCHOR_DISPATCHES as u32).map(|level| AnchorParams { width, height, level, gate: anchor.gate }).collect()
    }

    /// Whether this dispatch scales the image (the last), not a step of the sums.
    pub fn scales(&self) -> bool {
        self.level == ANCHOR_LEVELS + 1
    }

    /// The pixels this dispatch writes: the half-resolution grid's
    /// (`Anchor::grid`), or the frame's for the scaling.
    pub fn writes(&self) -> (u32, u32) {
        if self.scales() {
            (self.width, self.height)
        } else {
            Anchor::grid(self.width, self.height)
        }
    }
}

/// How many dispatches the stage takes: the blocks averaged, [`ANCHOR_LEVELS`] blurs, the scaling.
pub const ANCHOR_DISPATCHES: usize = ANCHOR_LEVELS as usize + 2;

/// The kernel's WGSL: its images sampled, its output a storage buffer
/// (filterjit's, `None`: the grid's texels densely, or the frame's pixels)
/// or, exported, a storage texture of the frame's size (`rgba32float`
/// whatever the output format: the sums are squared luminances; the grid in
/// its top-left corner).
pub fn anchor_wgsl(textures: Option<OutputFormat>) -> String {
    let template = include_str!("../../templates/anchor.wgsl.tera");
    let values = AnchorTemplate {
        textures: textures.is_some(),
        luminance: pipeline::LUMINANCE.map(wgsl_f32),
        stencil: Anchor::STENCIL.weights().iter().map(|&w| wgsl_f32(w)).collect(),
        levels: ANCHOR_LEVELS,
        samples: wgsl_f32(Anchor::samples() as f64),
        error_floor: wgsl_f32(pipeline::ANCHOR_ERROR_FLOOR),
        light_floor: wgsl_f32(pipeline::ANCHOR_LIGHT_FLOOR),
    };
    render_builtin("anchor", template, &BindingInterface::anchor(textures), &values)
}

/// What `templates/anchor.wgsl.tera` reads beside the interface.
#[derive(serde::Serialize)]
struct AnchorTemplate {
    textures: bool,
    luminance: [String; 3],
    /// h(0), h(1), h(2) of the cubic B-spline.
    stencil: Vec<String>,
    levels: u32,
    samples: String,
    error_floor: String,
    light_floor: String,
}

/// The kernel, validated by naga; its bindings are checked against its interface.
pub fn anchor_module(textures: Option<OutputFormat>) -> Result<ValidatedModule, ValidateError> {
    validate_with_interface(&anchor_wgsl(textures), "<anchor>", &BindingInterface::anchor(textures))
}
