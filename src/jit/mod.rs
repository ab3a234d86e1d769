//! The JIT: typed expression → WGSL (lower) → naga-validated kernel (validate).
//! Nothing here talks to wgpu; [`crate::gpu`] turns a [`ValidatedKernel`] into a pipeline.

pub mod lower;
pub mod validate;

pub use lower::{
    lower, lower_kind, lower_with, Input, KernelKind, KernelLayout, KernelSource, LowerError, LowerOptions,
    FIRST_INPUT_BINDING, TEMPLATE_VERSION, WORKGROUP,
};
pub use validate::{validate, KernelKey, ValidateError, ValidatedKernel};

/// Lower and validate in one step.
pub fn compile(expr: &crate::lang::Expr) -> Result<ValidatedKernel, CompileError> {
    Ok(validate(lower(expr)?)?)
}

/// Lower and validate a kernel of the given kind.
pub fn compile_kind(expr: &crate::lang::Expr, kind: KernelKind) -> Result<ValidatedKernel, CompileError> {
    Ok(validate(lower_kind(expr, kind)?)?)
}

#[derive(Debug, thiserror::Error)]
pub enum CompileError {
    #[error(transparent)]
    Lower(#[from] LowerError),
    #[error(transparent)]
    Validate(#[from] ValidateError),
}
