//! `pixelfilter`'s kernel (docs/SEMANTICS.md, "The pipeline"): the filtered
//! image convolved with a separable 3×3 kernel whose two 1-D weights the
//! uniform holds (`pipeline::PixelFilter::weights`), rendered from
//! `templates/pixelfilter.wgsl.tera`; `cpu::pixel_filter` is its reference.

use super::interface::{render_builtin, BindingInterface};
use super::kernel::OutputFormat;
use super::validate::{validate_with_interface, ValidateError, ValidatedModule};
use crate::pipeline::PixelFilter;

/// The kernel's uniform (`struct Params` of its module; fields in [`BindingInterface::pixel_filter`]).
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct PixelFilterParams {
    pub width: u32,
    pub height: u32,
    pub centre: f32,
    pub side: f32,
}

impl PixelFilterParams {
    pub fn of(filter: PixelFilter, width: u32, height: u32) -> Self {
        let [centre, side] = filter.weights();
        PixelFilterParams { width, height, centre, side }
    }
}

/// The kernel's WGSL: its image sampled, its output a storage buffer
/// (filterjit's, `None`) or, exported, a storage texture in `format`.
pub fn pixel_filter_wgsl(textures: Option<OutputFormat>) -> String {
    let template = include_str!("../../templates/pixelfilter.wgsl.tera");
    let values = PixelFilterTemplate { textures: textures.is_some() };
    render_builtin("pixelfilter", template, &BindingInterface::pixel_filter(textures), &values)
}

/// What `templates/pixelfilter.wgsl.tera` reads beside the interface: whether it is exported.
#[derive(serde::Serialize)]
struct PixelFilterTemplate {
    textures: bool,
}

/// The kernel, validated by naga; its bindings are checked against its interface.
pub fn pixel_filter_module(textures: Option<OutputFormat>) -> Result<ValidatedModule, ValidateError> {
    validate_with_interface(&pixel_filter_wgsl(textures), "<pixelfilter>", &BindingInterface::pixel_filter(textures))
}
