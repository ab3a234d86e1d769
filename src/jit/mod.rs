//! The JIT: typed expression → WGSL (lower) → naga-validated kernel (validate).
//! Nothing here talks to wgpu; [`crate::gpu`] turns a [`ValidatedKernel`] into a pipeline.

pub mod anchor;
pub mod blit;
pub mod builtin;
mod builtin_interface;
mod context;
pub mod helpers;
pub mod interface;
pub mod ir;
pub mod kernel;
pub mod lower;
pub mod pixel_filter;
pub mod planefit;
pub mod prepass;
pub mod range;
pub mod reduce;
pub mod spread;
pub mod temporal;
pub mod validate;

pub use anchor::{anchor_module, anchor_wgsl, AnchorParams, ANCHOR_DISPATCHES};
pub use blit::{blit_module, blit_wgsl, BlitParams};
pub use builtin::BuiltIn;
pub use helpers::Helper;
pub use interface::{Access, AtrousParams, BindingInterface, Params, Role, Slot, TEXTURE_IN_FOURTH_CHANNELS};
pub use kernel::{
    wgsl_f32, Input, KernelKind, KernelLayout, KernelSpec, LowerOptions, OutputFormat, PassRole, Shape, FIRST_PASS,
    TEMPLATE_VERSION, WORKGROUP, WORKGROUP_STORAGE_BUDGET,
};
pub use lower::{lower, lower_fused, KernelSource, LowerError};
pub use pixel_filter::{pixel_filter_module, pixel_filter_wgsl, PixelFilterParams};
pub use planefit::{
    planefit_module, planefit_terms_module, planefit_terms_wgsl, planefit_wgsl, PlaneFitParams, PLANEFIT_REMODULATED,
};
pub use prepass::{prepass_module, prepass_wgsl, PrepassParams};
pub use reduce::{reduce_module, reduce_wgsl, ReduceParams};
pub use spread::{
    spread_interface, spread_kernel, spread_module, spread_surface_module, spread_surface_wgsl, spread_wgsl,
    written_before, SpreadDispatch, SpreadParams, SpreadSource, SpreadStage, SpreadTarget, SurfaceStage, SPREAD_STAGE,
};
pub use temporal::{temporal_module, temporal_variance_module, temporal_variance_wgsl, temporal_wgsl, TemporalParams};
pub use validate::{validate, validate_module, KernelKey, ValidateError, ValidatedKernel, ValidatedModule};

/// Lower and validate: the kernel `spec` describes for `expr`.
pub fn compile(expr: &crate::lang::Expr, spec: KernelSpec) -> Result<ValidatedKernel, CompileError> {
    Ok(validate(lower(expr, spec)?)?)
}

/// [`compile`] for many expressions on up to `threads` threads, each on its
/// own: one that fails does not stop the others. Results in order.
pub fn compile_each(
    exprs: &[crate::lang::Expr],
    spec: KernelSpec,
    threads: usize,
) -> Vec<Result<ValidatedKernel, CompileError>> {
    crate::parallel::map(exprs, threads, |e| compile(e, spec))
}

/// One fitness kernel scoring every expression of `exprs` ([`lower_fused`]).
pub fn compile_fused(exprs: &[crate::lang::Expr], spec: KernelSpec) -> Result<ValidatedKernel, CompileError> {
    Ok(validate(lower_fused(exprs, spec)?)?)
}

/// The kernel that makes the first pass's `guide` (docs/SEMANTICS.md, "The
/// guide"): the form's own kernel of `kind` (the filter's, or an export's)
/// with the constant weight 1, one pass of `pipeline::GUIDE_STENCIL`,
/// nothing multiplied back.
pub fn compile_guide(kind: KernelKind) -> Result<ValidatedKernel, CompileError> {
    let shape = Shape { atrous: true, remodulate: false, stencil: crate::pipeline::GUIDE_STENCIL };
    compile(&crate::lang::Expr::Const(1.0), KernelSpec { kind, shape, ..KernelSpec::default() })
}

#[derive(Debug, thiserror::Error)]
pub enum CompileError {
    #[error(transparent)]
    Lower(#[from] LowerError),
    #[error(transparent)]
    Validate(#[from] ValidateError),
}
