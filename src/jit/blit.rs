//! The blit kernel: an image from a storage buffer into a texture of the same
//! values, for the kernels that sample their images
//! ([`BindingInterface::samples_images`]). One module per element type,
//! rendered from `templates/blit.wgsl.tera`.

use super::interface::{render_builtin, BindingInterface, Element};
use super::validate::{validate_with_interface, ValidateError, ValidatedModule};

/// The blit's uniform (`struct Params` of its module; fields in [`BindingInterface::blit`]).
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct BlitParams {
    pub width: u32,
    pub height: u32,
    pub _pad: [u32; 2],
}

/// The blit's WGSL for images of `element`s: `Vec4F32` into `rgba32float`, `F32` into `r32float`.
pub fn blit_wgsl(element: Element) -> String {
    let scalar = element == Element::F32;
    let values = BlitTemplate { scalar, format: if scalar { "r32float" } else { "rgba32float" } };
    render_builtin("blit", include_str!("../../templates/blit.wgsl.tera"), &BindingInterface::blit(element), &values)
}

/// What `templates/blit.wgsl.tera` reads beside the interface.
#[derive(serde::Serialize)]
struct BlitTemplate {
    scalar: bool,
    /// The texture's format.
    format: &'static str,
}

/// The blit, validated by naga; its bindings are checked against its interface.
pub fn blit_module(element: Element) -> Result<ValidatedModule, ValidateError> {
    validate_with_interface(&blit_wgsl(element), "<blit>", &BindingInterface::blit(element))
}
