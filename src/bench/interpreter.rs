//! Encoding expressions for the benchmark's stack interpreter
//! (`templates/interpreter.wgsl`). Built for comparison only.

use crate::lang::{BinaryOp, Expr, Feature, PairOp, ScalarVar, UnaryOp};
use crate::semantics;

/// The interpreter's source: the operator helpers, then the interpreter.
pub fn source() -> String {
    format!("{}\n{}", crate::jit::lower::OPS_WGSL, include_str!("../../templates/interpreter.wgsl"))
}

/// Feature slots the interpreter reads the pixel position and colour from.
pub const SLOT_PIXEL: u32 = 254;
pub const SLOT_COLOR: u32 = 255;
/// The interpreter's stack depth.
pub const STACK: usize = 128;

/// A program in postfix order.
pub struct Program {
    pub code: Vec<u32>,
    pub constants: Vec<f32>,
    pub max_depth: usize,
}

fn index<T: PartialEq>(all: &[T], x: &T) -> u32 {
    all.iter().position(|y| y == x).expect("listed in its table") as u32
}

/// Encode `e`; `slot` gives the packed slot of a stored feature, `variance` of a variance.
pub fn encode(e: &Expr, slot: &dyn Fn(Feature) -> u32, variance: &dyn Fn(ScalarVar) -> u32) -> Program {
    let mut p = Program { code: Vec::new(), constants: Vec::new(), max_depth: 0 };
    fn go(e: &Expr, p: &mut Program, depth: usize, slot: &dyn Fn(Feature) -> u32, variance: &dyn Fn(ScalarVar) -> u32) {
        let feature_slot = |f: Feature| match f {
            Feature::Pixel => SLOT_PIXEL,
            Feature::Color => SLOT_COLOR,
            other => slot(other),
        };
        match e {
            Expr::Const(c) => {
                p.code.push((p.constants.len() as u32) << 16);
                p.constants.push(semantics::literal(*c) as f32);
            }
            Expr::Var(v) => p.code.push(1 | (variance(*v) << 8)),
            Expr::Unary(op, a) => {
                go(a, p, depth, slot, variance);
                p.code.push(2 | (index(UnaryOp::ALL, op) << 8));
            }
            Expr::Binary(op, a, b) => {
                go(a, p, depth, slot, variance);
                go(b, p, depth + 1, slot, variance);
                p.code.push(3 | (index(BinaryOp::ALL, op) << 8));
            }
            Expr::Pair(op, i, j) => {
                p.code.push(4 | (index(PairOp::ALL, op) << 8) | (feature_slot(*i) << 16) | (feature_slot(*j) << 24));
            }
        }
        p.max_depth = p.max_depth.max(depth + 1);
    }
    go(e, &mut p, 0, slot, variance);
    p
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::jit::Helper;

    #[test]
    fn the_operator_orders_match_the_interpreter() {
        // templates/interpreter.wgsl switches on these positions.
        let wgsl = include_str!("../../templates/interpreter.wgsl");
        for (k, op) in UnaryOp::ALL.iter().enumerate().take(UnaryOp::ALL.len() - 1) {
            assert!(wgsl.contains(&format!("case {k}u: {{ return {}(a); }}", op.helper())), "{op}");
        }
        for (k, op) in BinaryOp::ALL.iter().enumerate().take(BinaryOp::ALL.len() - 1) {
            assert!(wgsl.contains(&format!("case {k}u: {{ return {}(a, b); }}", op.helper())), "{op}");
        }
        for (k, op) in PairOp::ALL.iter().enumerate().take(PairOp::ALL.len() - 1) {
            assert!(wgsl.contains(&format!("case {k}u: {{ return {}(u, v); }}", op.helper())), "{op}");
        }
    }
}
