//! Expressions as LaTeX formulas, for people (`filterjit check E --latex`).
//!
//! Division becomes a fraction, `pow` a superscript, the feature-pair
//! operators norms and dot products of the centre pixel's feature (subscript
//! i) and the neighbour's (subscript j); variances are read at i.

use super::expr::Expr;
use super::ops::{BinaryOp, Feature, PairOp, UnaryOp};

/// Binding strength of the formula's outermost operator: a child of an
/// operator that binds tighter is wrapped in parentheses.
const SUM: u8 = 1;
const PRODUCT: u8 = 2;
const PREFIX: u8 = 3;
const ATOM: u8 = 4;

/// `expr` as a LaTeX math-mode formula (without the surrounding `$`).
pub fn latex(expr: &Expr) -> String {
    write(expr).0
}

fn wrapped(expr: &Expr, min: u8) -> String {
    let (text, precedence) = write(expr);
    if precedence < min {
        format!("\\left({text}\\right)")
    } else {
        text
    }
}

fn feature(f: Feature, pixel: char) -> String {
    format!("\\mathrm{{{}}}_{pixel}", f.name())
}

fn write(expr: &Expr) -> (String, u8) {
    match expr {
        Expr::Const(c) if *c == std::f64::consts::PI => ("\\pi".into(), ATOM),
        Expr::Const(_) => (expr.to_string(), ATOM),
        Expr::Var(v) => (format!("\\mathrm{{{}}}_i", v.name()), ATOM),
        Expr::Pair(op, a, b) => {
            let (fi, fj) = (feature(*a, 'i'), feature(*b, 'j'));
            let text = match op {
                PairOp::Dot => return (format!("{fi} \\cdot {fj}"), PRODUCT),
                PairOp::Distance2 => format!("\\left\\lVert {fi} - {fj} \\right\\rVert_2"),
                PairOp::Distance1 => format!("\\left\\lVert {fi} - {fj} \\right\\rVert_1"),
                PairOp::DistanceMax => format!("\\left\\lVert {fi} - {fj} \\right\\rVert_\\infty"),
            };
            (text, ATOM)
        }
        Expr::Unary(op, a) => {
            let call = |name: &str| format!("{name}\\left({}\\right)", write(a).0);
            let text = match op {
                UnaryOp::Neg => return (format!("-{}", wrapped(a, PREFIX)), PREFIX),
                UnaryOp::Sqrt => format!("\\sqrt{{{}}}", write(a).0),
                UnaryOp::Abs => format!("\\left|{}\\right|", write(a).0),
                UnaryOp::Exp => call("\\exp"),
                UnaryOp::Sin => call("\\sin"),
                UnaryOp::Cos => call("\\cos"),
                UnaryOp::Tan => call("\\tan"),
                UnaryOp::Asin => call("\\arcsin"),
                UnaryOp::Acos => call("\\arccos"),
                UnaryOp::Atan => call("\\arctan"),
                kernel => call(&format!("\\operatorname{{{}}}", kernel.name())),
            };
            (text, ATOM)
        }
        Expr::Binary(op, a, b) => match op {
            BinaryOp::Add => (format!("{} + {}", wrapped(a, SUM), wrapped(b, SUM)), SUM),
            // Left associative: an equal-precedence right operand needs parentheses.
            BinaryOp::Sub => (format!("{} - {}", wrapped(a, SUM), wrapped(b, PRODUCT)), SUM),
            BinaryOp::Mul => (format!("{} \\cdot {}", wrapped(a, PRODUCT), wrapped(b, PREFIX)), PRODUCT),
            BinaryOp::Div => (format!("\\frac{{{}}}{{{}}}", write(a).0, write(b).0), ATOM),
            BinaryOp::Pow => (format!("{{{}}}^{{{}}}", wrapped(a, ATOM), write(b).0), ATOM),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lang::parse_expr;

    #[test]
    fn formulas_read_as_in_a_paper() {
        let e = parse_expr("exp(-(pow(distance2(pixel), 2) / (2 * pow(3, 2)) + distance2(color) / 0.5))").unwrap();
        assert_eq!(
            latex(&e),
            "\\exp\\left(-\\left(\\frac{{\\left\\lVert \\mathrm{pixel}_i - \\mathrm{pixel}_j \\right\\rVert_2}^{2}}\
             {2 \\cdot {3}^{2}} + \\frac{\\left\\lVert \\mathrm{color}_i - \\mathrm{color}_j \\right\\rVert_2}{0.5}\\right)\\right)"
        );
        assert_eq!(
            latex(&parse_expr("1 - (2 - dot(normal, texture)) * colorVariance").unwrap()),
            "1 - \\left(2 - \\mathrm{normal}_i \\cdot \\mathrm{texture}_j\\right) \\cdot \\mathrm{colorVariance}_i"
        );
    }
}
