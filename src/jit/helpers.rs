//! Which helper of `templates/ops.wgsl` implements each operator: the one
//! WGSL fact about operators, kept here so that `lang` knows no WGSL.

use crate::lang::{BinaryOp, PairOp, UnaryOp};

/// An operator implemented by a helper function of `templates/ops.wgsl`.
pub trait Helper {
    /// The helper's name: `fj_` and the operator's name (lower case).
    fn helper(&self) -> String;
}

impl Helper for UnaryOp {
    fn helper(&self) -> String {
        format!("fj_{}", self.name().to_ascii_lowercase())
    }
}

impl Helper for BinaryOp {
    fn helper(&self) -> String {
        format!("fj_{}", self.name())
    }
}

impl Helper for PairOp {
    fn helper(&self) -> String {
        format!("fj_{}", self.name().to_ascii_lowercase())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::jit::lower::OPS_WGSL;

    /// Every operator's helper is defined in `templates/ops.wgsl`, under a valid identifier.
    #[test]
    fn every_operator_has_its_helper() {
        let names: Vec<String> = UnaryOp::ALL
            .iter()
            .map(Helper::helper)
            .chain(BinaryOp::ALL.iter().map(Helper::helper))
            .chain(PairOp::ALL.iter().map(Helper::helper))
            .collect();
        for name in names {
            assert!(name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_'), "{name}");
            assert!(OPS_WGSL.contains(&format!("fn {name}(")), "templates/ops.wgsl defines no {name}");
        }
    }
}
