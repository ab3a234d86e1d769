//! `planefit`'s kernel (docs/SEMANTICS.md, "The pipeline"): after the form,
//! each pixel's demodulated colour moved toward a plane fitted over its
//! neighbourhood. One module for every radius (the uniform says which),
//! rendered from `templates/planefit.wgsl.tera` with the constants
//! `crate::pipeline` owns; `cpu::planefit` is its reference.

use super::interface::{render_builtin, BindingInterface};
use super::kernel::{wgsl_f32, OutputFormat};
use super::validate::{validate_with_interface, ValidateError, ValidatedModule};
use crate::pipeline::{self, FilterPipeline, PlaneFit};

/// The pipeline-overridable constant (a `bool`) of filterjit's own planefit
/// kernels: whether the colour it reads was multiplied by the modulation (a
/// window form's was; filterjit's à-trous form leaves remodulation to the
/// fit, which then reads two images a tap, not three). Exported kernels
/// divide whenever `params.demodulate` says the pipeline demodulates.
pub const PLANEFIT_REMODULATED: &str = "REMODULATED";

/// The kernel's uniform (`struct Params` of its module; fields in
/// [`BindingInterface::planefit`]).
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct PlaneFitParams {
    pub width: u32,
    pub height: u32,
    pub radius: u32,
    /// 1 where the pipeline demodulates: the fit divides by the modulation first.
    pub demodulate: u32,
}

impl PlaneFitParams {
    pub fn of(pipeline: &FilterPipeline, fit: PlaneFit, width: u32, height: u32) -> Self {
        PlaneFitParams { width, height, radius: fit.radius, demodulate: pipeline.demodulate as u32 }
    }
}

/// The kernel's WGSL: its images sampled, its output a storage buffer (filterjit's, `None`), or exported,
/// on textures with its output in `format`.
pub fn planefit_wgsl(textures: Option<OutputFormat>) -> String {
    render(&BindingInterface::planefit(textures), textures, false)
}

/// The kernel, validated by naga; its bindings are checked against its interface.
pub fn planefit_module(textures: Option<OutputFormat>) -> Result<ValidatedModule, ValidateError> {
    validate_with_interface(&planefit_wgsl(textures), "<planefit>", &BindingInterface::planefit(textures))
}

/// The fitness kernel's WGSL: the fit of the form's last image before
/// remodulation, written as relMSE terms and luminance for the reduction.
pub fn planefit_terms_wgsl() -> String {
    render(&BindingInterface::planefit_terms(), None, true)
}

/// The fitness kernel, validated by naga.
pub fn planefit_terms_module() -> Result<ValidatedModule, ValidateError> {
    validate_with_interface(&planefit_terms_wgsl(), "<planefit terms>", &BindingInterface::planefit_terms())
}

fn render(interface: &BindingInterface, textures: Option<OutputFormat>, fitness: bool) -> String {
    let values = PlaneFitTemplate {
        luminance: pipeline::LUMINANCE.map(wgsl_f32),
        normal_sigma: wgsl_f32(pipeline::SURFACE_KEEP_NORMAL_SIGMA),
        luminance_sigma: wgsl_f32(pipeline::PLANEFIT_LUMINANCE_SIGMA),
        luminance_floor: wgsl_f32(pipeline::PLANEFIT_LUMINANCE_FLOOR),
        ridge: wgsl_f32(pipeline::PLANEFIT_RIDGE),
        slope_tau: wgsl_f32(pipeline::PLANEFIT_SLOPE_TAU),
        slope_cap: wgsl_f32(pipeline::PLANEFIT_SLOPE_CAP),
        tiny: wgsl_f32(pipeline::PLANEFIT_TINY),
        relmse_epsilon: wgsl_f32(crate::metrics::RELMSE_EPSILON),
        textures: textures.is_some(),
        fitness,
        sampled: interface.samples_color(),
        remodulated: PLANEFIT_REMODULATED,
    };
    render_builtin("planefit", include_str!("../../templates/planefit.wgsl.tera"), interface, &values)
}

/// What `templates/planefit.wgsl.tera` reads beside the interface: the
/// constants `crate::pipeline` owns, as WGSL literals, and which variant.
#[derive(serde::Serialize)]
struct PlaneFitTemplate {
    luminance: [String; 3],
    normal_sigma: String,
    luminance_sigma: String,
    luminance_floor: String,
    ridge: String,
    slope_tau: String,
    slope_cap: String,
    tiny: String,
    relmse_epsilon: String,
    textures: bool,
    /// The fitness variant: terms against the reference instead of an image.
    fitness: bool,
    sampled: bool,
    remodulated: &'static str,
}
