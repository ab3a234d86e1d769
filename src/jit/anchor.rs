//! `anchor=K`'s kernel (docs/SEMANTICS.md, "The pipeline"; the formula at
//! `pipeline::Anchor`): one module for the whole stage, a dispatch per blur
//! level and one that scales the image, told apart by the uniform's
//! `level`; rendered from `templates/anchor.wgsl.tera` with the constants
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
    /// The blur level this dispatch sums (0 reads the frame and the image,
    /// later ones the sums), or [`ANCHOR_LEVELS`]: scale the image.
    pub level: u32,
    pub gate: f32,
}

impl AnchorParams {
    /// The stage's dispatches in order: every blur level, then the scaling.
    pub fn sequence(anchor: Anchor, width: u32, height: u32) -> Vec<AnchorParams> {
        (0..=ANCHOR_LEVELS).map(|level| AnchorParams { width, height, level, gate: anchor.gate }).collect()
    }

    /// Whether this dispatch scales the image (the last), not a blur level.
    pub fn scales(&self) -> bool {
        self.level == ANCHOR_LEVELS
    }
}

/// The kernel's WGSL: its images sampled, its output a storage buffer
/// (filterjit's, `None`) or, exported, a storage texture (`rgba32float`
/// whatever the output format: the sums are squared luminances).
pub fn anchor_wgsl(textures: Option<OutputFormat>) -> String {
    let template = include_str!("../../templates/anchor.wgsl.tera");
    let values = AnchorTemplate {
        textures: textures.is_some(),
        luminance: pipeline::LUMINANCE.map(wgsl_f32),
        stencil: pipeline::Stencil::Cubic5.weights().iter().map(|&w| wgsl_f32(w)).collect(),
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
