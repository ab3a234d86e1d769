//! Why a candidate has no fitness, as data: the search counts reasons by
//! kind; `gp` receives the text only at its boundary ([`Invalid`]'s
//! `Display`), so checkpoints keep the words they always had.

use crate::semantics;

#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum Invalid {
    /// Lowering or naga's validation refused the kernel.
    #[error("does not compile: {0}")]
    DoesNotCompile(String),
    /// The kernel binds more storage buffers than the device allows.
    #[error(
        "the kernel for `{expression}` needs {needed} storage buffers, but {adapter} allows {limit} per shader stage"
    )]
    TooManyBindings { expression: String, needed: u32, limit: u32, adapter: String },
    /// Some pixel of some scene raised these domain-error bits (`semantics::flag`).
    #[error("domain error: {}", semantics::flag::describe(*.0).join("; "))]
    DomainError(u32),
    /// The error came out infinite or NaN on some scene.
    #[error("non-finite error")]
    NonFinite,
}

impl Invalid {
    /// A short name of the kind, for counts.
    pub fn kind(&self) -> &'static str {
        match self {
            Invalid::DoesNotCompile(_) => "does not compile",
            Invalid::TooManyBindings { .. } => "too many bindings",
            Invalid::DomainError(_) => "domain error",
            Invalid::NonFinite => "non-finite error",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_text_gp_stores_is_the_one_checkpoints_always_held() {
        // Checkpoints written before reasons were data hold these exact words.
        assert_eq!(Invalid::NonFinite.to_string(), "non-finite error");
        let flags = semantics::flag::SQRT;
        assert_eq!(
            Invalid::DomainError(flags).to_string(),
            format!("domain error: {}", semantics::flag::describe(flags)[0])
        );
        assert!(Invalid::DoesNotCompile("x".into()).to_string().starts_with("does not compile: "));
        assert_eq!(Invalid::DomainError(flags).kind(), "domain error");
    }
}
