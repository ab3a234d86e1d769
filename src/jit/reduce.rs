//! The fitness reduction kernel: one module for every fitness kernel, which
//! writes per-pixel terms (`templates/fitness.wgsl.tera`); this kernel sums
//! them per workgroup (`templates/reduce.wgsl.tera`). Keeping the barriers
//! out of the generated kernels is what makes them cheap to compile on
//! software drivers, and the tree is the same for every member, fused or not.

use super::interface::BindingInterface;
use super::kernel::{TEMPLATE_VERSION, WORKGROUP};
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
    let mut tera = tera::Tera::default();
    tera.add_raw_template("reduce", include_str!("../../templates/reduce.wgsl.tera"))
        .expect("built-in reduction template parses");
    let mut context = tera::Context::new();
    context.insert("crate_version", env!("CARGO_PKG_VERSION"));
    context.insert("template_version", &TEMPLATE_VERSION);
    context.insert("workgroup_x", &WORKGROUP[0]);
    context.insert("workgroup_y", &WORKGROUP[1]);
    let interface = BindingInterface::reduce();
    context.insert("params_struct", &interface.params_struct());
    context.insert("declarations", &interface.declarations());
    tera.render("reduce", &context).expect("built-in reduction template renders")
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
