//! A model of what a filter costs to run per pixel, in units of one add: what
//! the multi-objective search (`evolve --objectives error,cost`) trades
//! against error. It counts what the JIT emits: constant subtrees fold away,
//! a subexpression that does not read the neighbour is computed once per
//! pixel (hoisted), one that does is computed at every tap, and equal
//! subexpressions are computed once (common subexpressions). Operators weigh
//! what the operator table says (`UnaryOp::cost` and friends); the form
//! decides the taps. How well it ranks measured times is reported with every
//! front (`pareto.json`, docs/BENCHMARKS.md).

use std::collections::HashSet;

use crate::lang::Expr;
use crate::pipeline::{FilterPipeline, Form, OUTLIER_RADIUS};

/// One tap's fixed work: the loop step, the neighbour's colour load and the two accumulations.
pub const TAP: f64 = 6.0;
/// One pixel's fixed work in a pass: bounds, centre colour, the division, the store.
pub const PIXEL: f64 = 10.0;

/// What an expression costs where it is computed.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ExprCost {
    /// Once per pixel and pass.
    pub per_pixel: f64,
    /// At every tap.
    pub per_tap: f64,
}

impl ExprCost {
    pub fn of(expr: &Expr) -> ExprCost {
        let mut cost = ExprCost::default();
        let mut seen = HashSet::new();
        walk(expr, &mut seen, &mut cost);
        cost
    }
}

fn is_constant(e: &Expr) -> bool {
    let mut constant = true;
    e.visit(&mut |n| constant &= !matches!(n, Expr::Pair(..) | Expr::Var(_)));
    constant
}

fn reads_neighbour(e: &Expr) -> bool {
    let mut found = false;
    e.visit(&mut |n| found |= matches!(n, Expr::Pair(..)));
    found
}

fn walk(e: &Expr, seen: &mut HashSet<String>, cost: &mut ExprCost) {
    if is_constant(e) || !seen.insert(e.to_string()) {
        return;
    }
    let own = match e {
        Expr::Const(_) => 0.0,
        // A centre load.
        Expr::Var(_) => 1.0,
        Expr::Pair(op, ..) => op.cost(),
        Expr::Unary(op, a) => {
            walk(a, seen, cost);
            op.cost()
        }
        Expr::Binary(op, a, b) => {
            walk(a, seen, cost);
            walk(b, seen, cost);
            op.cost()
        }
    };
    if reads_neighbour(e) {
        cost.per_tap += own;
    } else {
        cost.per_pixel += own;
    }
}

/// Taps per pixel of one pass of the form, and the number of passes.
pub fn taps(pipeline: &FilterPipeline, radius: u32) -> (f64, f64) {
    match pipeline.form {
        Form::Window => (((2 * radius + 1) * (2 * radius + 1)) as f64, 1.0),
        Form::Atrous { passes } => {
            let side = (2 * crate::pipeline::ATROUS_HALF_WIDTH + 1) as f64;
            (side * side, passes as f64)
        }
    }
}

/// The whole pipeline's cost per pixel: pre-pass, then every pass of the form.
pub fn model(expr: &Expr, pipeline: &FilterPipeline, radius: u32) -> f64 {
    let e = ExprCost::of(expr);
    let (taps, passes) = taps(pipeline, radius);
    let side = (2 * OUTLIER_RADIUS + 1) as f64;
    let prepass = if pipeline.outliers.is_some() { (side * side - 1.0) * TAP } else { 0.0 }
        + if pipeline.demodulate { PIXEL } else { 0.0 };
    prepass + passes * (PIXEL + e.per_pixel + taps * (TAP + e.per_tap))
}

/// Spearman's rank correlation of two equally long samples (ties get their mean rank).
pub fn rank_correlation(a: &[f64], b: &[f64]) -> f64 {
    fn ranks(v: &[f64]) -> Vec<f64> {
        let mut idx: Vec<usize> = (0..v.len()).collect();
        idx.sort_by(|&x, &y| v[x].total_cmp(&v[y]));
        let mut r = vec![0.0; v.len()];
        let mut k = 0;
        while k < idx.len() {
            let mut end = k;
            while end + 1 < idx.len() && v[idx[end + 1]] == v[idx[k]] {
                end += 1;
            }
            for &i in &idx[k..=end] {
                r[i] = (k + end) as f64 / 2.0;
            }
            k = end + 1;
        }
        r
    }
    let (ra, rb) = (ranks(a), ranks(b));
    let n = a.len() as f64;
    let mean = (n - 1.0) / 2.0;
    let (mut num, mut da, mut db) = (0.0, 0.0, 0.0);
    for (x, y) in ra.iter().zip(&rb) {
        num += (x - mean) * (y - mean);
        da += (x - mean) * (x - mean);
        db += (y - mean) * (y - mean);
    }
    if da == 0.0 || db == 0.0 {
        return 0.0;
    }
    num / (da * db).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lang::parse_expr;

    #[test]
    fn constants_fold_centre_terms_hoist_and_repeats_are_shared() {
        let e = |s: &str| ExprCost::of(&parse_expr(s).unwrap());
        assert_eq!(e("pow(3, 2) / (2 * 4)"), ExprCost::default());
        // distance2 (6) and exp (6) per tap; the variance load (1) once.
        let c = e("exp(distance2(color)) * colorVariance");
        assert_eq!(c.per_tap, 6.0 + 6.0 + 1.0);
        assert_eq!(c.per_pixel, 1.0);
        // The same subexpression twice costs once, plus the add.
        assert_eq!(e("distance2(color) + distance2(color)").per_tap, 6.0 + 1.0);
    }

    #[test]
    fn the_form_decides_the_taps() {
        let bilateral = parse_expr(crate::corpus::lookup("bilateral").unwrap()).unwrap();
        let window = |r| model(&bilateral, &FilterPipeline::WINDOW, r);
        assert!(window(5) > window(3) * 2.0);
        let atrous: FilterPipeline = "atrous=5".parse().unwrap();
        assert!(model(&bilateral, &atrous, 3) < window(10));
        assert!(model(&parse_expr("1").unwrap(), &FilterPipeline::WINDOW, 3) < window(3) / 3.0);
    }

    #[test]
    fn rank_correlation_is_one_for_the_same_order_and_minus_one_reversed() {
        let a = [1.0, 2.0, 3.0, 4.0];
        assert!((rank_correlation(&a, &[10.0, 20.0, 25.0, 100.0]) - 1.0).abs() < 1e-12);
        assert!((rank_correlation(&a, &[4.0, 3.0, 2.0, 1.0]) + 1.0).abs() < 1e-12);
        assert!(rank_correlation(&a, &[1.0, 1.0, 1.0, 1.0]).abs() < 1e-12);
    }
}
