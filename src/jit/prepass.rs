//! The pipeline's pre-pass kernel (outliers, then demodulation): one module
//! for every pipeline, its stages chosen by the uniform, rendered from
//! `templates/prepass.wgsl.tera` with the constants `crate::pipeline` owns.

use super::interface::{render_builtin, BindingInterface};
use super::kernel::{wgsl_f32, OutputFormat};
use super::validate::{validate_with_interface, ValidateError, ValidatedModule};
use crate::pipeline::{self, FilterPipeline};

/// The pre-pass's uniform (`struct Params` of its module; fields in
/// [`BindingInterface::prepass`]).
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct PrepassParams {
    pub width: u32,
    pub height: u32,
    /// The outlier rule's k.
    pub k: f32,
    /// Bit 0: outliers; bit 1: demodulation; bit 2: `keep`, under which the
    /// colour is written clamped but undivided (the spread kernel divides it);
    /// bit 3: `trim`, the rule leaves out the brightest neighbour.
    pub stages: u32,
}

impl PrepassParams {
    pub fn of(pipeline: &FilterPipeline, width: u32, height: u32) -> Self {
        let outliers = pipeline.outliers.map_or(0, |_| 1);
        let demodulate = if pipeline.demodulate { 2 } else { 0 };
        let keep = if pipeline.outliers.is_some_and(|o| o.keep.is_some()) { 4 } else { 0 };
        let trim = if pipeline.outliers.is_some_and(|o| o.trim) { 8 } else { 0 };
        let stages = outliers | demodulate | keep | trim;
        PrepassParams { width, height, k: pipeline.outliers.map_or(0.0, |o| o.k), stages }
    }
}

/// The pre-pass's WGSL: on storage buffers (filterjit's, `None`), or
/// exported, on textures with outputs in `format`.
pub fn prepass_wgsl(textures: Option<OutputFormat>) -> String {
    let values = PrepassTemplate {
        luminance: pipeline::LUMINANCE.map(wgsl_f32),
        outlier_radius: pipeline::OUTLIER_RADIUS,
        neighbours: pipeline::outlier_neighbours().collect(),
        albedo_floor: wgsl_f32(pipeline::ALBEDO_FLOOR),
        textures: textures.is_some(),
    };
    let template = include_str!("../../templates/prepass.wgsl.tera");
    render_builtin("pre-pass", template, &BindingInterface::prepass(textures), &values)
}

/// What `templates/prepass.wgsl.tera` reads beside the interface: the
/// constants `crate::pipeline` owns, as WGSL literals.
#[derive(serde::Serialize)]
struct PrepassTemplate {
    luminance: [String; 3],
    outlier_radius: u32,
    /// The outlier rule's neighbourhood, in its order: the template unrolls it.
    neighbours: Vec<[i32; 2]>,
    albedo_floor: String,
    /// Exported, on textures (else on filterjit's storage buffers).
    textures: bool,
}

/// The pre-pass, validated by naga; its bindings are checked against its interface.
pub fn prepass_module(textures: Option<OutputFormat>) -> Result<ValidatedModule, ValidateError> {
    validate_with_interface(&prepass_wgsl(textures), "<pre-pass>", &BindingInterface::prepass(textures))
}
