//! The temporal stage's kernel (docs/SEMANTICS.md, "The temporal stage"):
//! reprojection, the blend, the moments and the variance, one module for
//! every pipeline (the uniform holds α_min and the clamp), rendered from
//! `templates/temporal.wgsl.tera` with the constants `crate::pipeline` owns;
//! `cpu::temporal` is its reference.

use super::interface::{render_builtin, BindingInterface};
use super::kernel::{wgsl_f32, OutputFormat};
use super::validate::{validate_with_interface, ValidateError, ValidatedModule};
use crate::pipeline::{self, Temporal};

/// The kernel's uniform (`struct Params` of its module; fields in [`BindingInterface::temporal`]).
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct TemporalParams {
    pub width: u32,
    pub height: u32,
    /// α_min.
    pub alpha: f32,
    /// γ of the history's clamp; 0 without.
    pub gamma: f32,
    /// 1 where the history holds the frame before's; 0 for a first frame.
    pub history: u32,
    /// κ of the history's test; 0 without.
    pub antilag: f32,
    pub _pad: [u32; 2],
}

impl TemporalParams {
    pub fn of(temporal: Temporal, width: u32, height: u32, history: bool) -> Self {
        TemporalParams {
            width,
            height,
            alpha: temporal.alpha,
            gamma: temporal.clamp.unwrap_or(0.0),
            history: history as u32,
            antilag: temporal.antilag.unwrap_or(0.0),
            _pad: [0; 2],
        }
    }
}

/// The kernel's WGSL: its outputs storage buffers (filterjit's, `None`), or
/// exported, storage textures.
pub fn temporal_wgsl(textures: Option<OutputFormat>) -> String {
    let values = TemporalTemplate {
        luminance: pipeline::LUMINANCE.map(wgsl_f32),
        depth_tolerance: wgsl_f32(pipeline::TEMPORAL_DEPTH_TOLERANCE),
        normal_cosine: wgsl_f32(pipeline::TEMPORAL_NORMAL_COSINE),
        black_albedo: wgsl_f32(pipeline::TEMPORAL_BLACK_ALBEDO),
        alike_albedo: wgsl_f32(pipeline::TEMPORAL_ALIKE_ALBEDO),
        unlike_light: wgsl_f32(pipeline::TEMPORAL_UNLIKE_LIGHT),
        unlike_slack: wgsl_f32(pipeline::TEMPORAL_UNLIKE_SLACK),
        albedo_floor: wgsl_f32(pipeline::ALBEDO_FLOOR),
        antilag_slack: wgsl_f32(pipeline::TEMPORAL_ANTILAG_SLACK),
        antilag_drop: wgsl_f32(pipeline::TEMPORAL_ANTILAG_DROP),
        min_footprint: wgsl_f32(pipeline::TEMPORAL_MIN_FOOTPRINT),
        max_history: wgsl_f32(pipeline::TEMPORAL_MAX_HISTORY),
        short_history: wgsl_f32(pipeline::TEMPORAL_SHORT_HISTORY),
        variance_radius: pipeline::TEMPORAL_VARIANCE_RADIUS,
        window_taps: (2 * pipeline::TEMPORAL_VARIANCE_RADIUS + 1).pow(2),
        textures: textures.is_some(),
    };
    let template = include_str!("../../templates/temporal.wgsl.tera");
    render_builtin("temporal", template, &BindingInterface::temporal(textures), &values)
}

/// What `templates/temporal.wgsl.tera` reads beside the interface: the
/// constants `crate::pipeline` owns, as WGSL literals.
#[derive(serde::Serialize)]
struct TemporalTemplate {
    luminance: [String; 3],
    depth_tolerance: String,
    normal_cosine: String,
    black_albedo: String,
    alike_albedo: String,
    unlike_light: String,
    unlike_slack: String,
    albedo_floor: String,
    antilag_slack: String,
    antilag_drop: String,
    min_footprint: String,
    max_history: String,
    short_history: String,
    variance_radius: i32,
    /// The spatial variance's window, (2 radius + 1)² taps (the template initialises its array).
    window_taps: i32,
    textures: bool,
}

/// What a built-in template reads that only says whether it runs on textures.
#[derive(serde::Serialize)]
struct OnTextures {
    textures: bool,
}

/// The kernel, validated by naga; its bindings are checked against its interface.
pub fn temporal_module(textures: Option<OutputFormat>) -> Result<ValidatedModule, ValidateError> {
    validate_with_interface(&temporal_wgsl(textures), "<temporal>", &BindingInterface::temporal(textures))
}

/// The stage's second kernel: the sample variance blurred by a 3×3
/// Gaussian and multiplied by r, `temporalVariance`
/// (`templates/temporal_variance.wgsl.tera`).
pub fn temporal_variance_wgsl(textures: Option<OutputFormat>) -> String {
    let template = include_str!("../../templates/temporal_variance.wgsl.tera");
    let interface = BindingInterface::temporal_variance(textures);
    render_builtin("temporal variance", template, &interface, &OnTextures { textures: textures.is_some() })
}

/// The variance kernel, validated by naga and checked against its interface.
pub fn temporal_variance_module(textures: Option<OutputFormat>) -> Result<ValidatedModule, ValidateError> {
    let interface = BindingInterface::temporal_variance(textures);
    validate_with_interface(&temporal_variance_wgsl(textures), "<temporal variance>", &interface)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn both_variants_validate() {
        for textures in [None, Some(OutputFormat::Rgba16float)] {
            temporal_module(textures).unwrap_or_else(|e| panic!("{textures:?}: {e}"));
            temporal_variance_module(textures).unwrap_or_else(|e| panic!("{textures:?}: {e}"));
        }
        assert_eq!(std::mem::size_of::<TemporalParams>() as u32, BindingInterface::temporal(None).uniform_bytes);
    }
}
