//! The fitness reduction kernel: one module for every fitness kernel, which
//! writes per-pixel terms (`templates/fitness.wgsl.tera`); this kernel sums
//! them per workgroup (`templates/reduce.wgsl.tera`). Keeping the barriers
//! out of the generated kernels is what makes them cheap to compile on
//! software drivers, and the tree is the same for every member, fused or not.

use super::interface::{render_builtin, BindingInterface, NoValues};
use super::validate::{validate_with_interface, ValidateError, ValidatedModule};

/// The reduction's uniform (`struct Params` of its module; fields in [`BindingInterface::reduce`]).
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct ReduceParams {
    pub width: u32,
    pub height: u32,
    /// Which member's terms: they start at `member * width * height`.
    pub member: u32,
    pub _pad: u32,
}

/// The reduction's WGSL.
pub fn reduce_wgsl() -> String {
    let template = include_str!("../../templates/reduce.wgsl.tera");
    render_builtin("reduction", template, &BindingInterface::reduce(), &NoValues {})
}

/// The reduction, validated by naga; its bindings are checked against its interface.
pub fn reduce_module() -> Result<ValidatedModule, ValidateError> {
    validate_with_interface(&reduce_wgsl(), "<fitness reduction>", &BindingInterface::reduce())
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_reduction_validates_with_its_interface() {
        super::reduce_module().expect("the reduction validates with the slots its interface gives");
    }
}
