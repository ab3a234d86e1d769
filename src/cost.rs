//! A model of what a filter costs to run per pixel, in units of one add: what
//! the multi-objective search (`evolve --objectives error,cost`) trades
//! against error, what `pareto.json` states and what `simplify` keeps a form
//! by. It prices the program that runs: the kernel body the JIT builds
//! (`jit::ir`, with every rewrite the kernels get: constant folding, common
//! subexpressions, hoisting, strength reduction, skipped checks), an
//! instruction on the centre side once per pixel and one on the neighbour
//! side at every tap. Operators weigh what the operator table says
//! (`UnaryOp::cost` and friends), the cheaper forms the lowering gives some of
//! them what they compute ([`CostModel::instruction`]); the form decides the
//! taps. How well it ranks measured times is reported with every front
//! (`pareto.json`, docs/JOURNAL.md).
//!
//! The weights are the operator table's unless a [`CostModel`] measured on a
//! device replaces them: `filterjit bench` measures one (`bench.json`'s
//! `cost_model`), `evolve --cost-model FILE` searches with it and keeps it in
//! the run's checkpoint.

use std::collections::{BTreeMap, HashSet};

use serde::{Deserialize, Serialize};

use crate::jit::ir::{self, Op, Side};
use crate::jit::LowerOptions;
use crate::lang::{BinaryOp, Expr, PairOp, UnaryOp};
use crate::pipeline::{FilterPipeline, Form, OUTLIER_RADIUS};

/// One tap's fixed work: the loop step, the neighbour's colour load and the two accumulations.
pub const TAP: f64 = 6.0;
/// One pixel's fixed work in a pass: bounds, centre colour, the division, the store.
pub const PIXEL: f64 = 10.0;

/// Per-operator costs in units of one add and the fixed work per tap and per
/// pixel, as one device runs them (or as the operator table states them).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CostModel {
    /// What the weights were measured on; `operator table` for the defaults.
    pub device: String,
    pub tap: f64,
    pub pixel: f64,
    /// The cost of each operator, by its name in the language; an operator
    /// that is missing costs what the operator table says.
    pub operators: BTreeMap<String, f64>,
}

impl Default for CostModel {
    fn default() -> Self {
        CostModel::table()
    }
}

impl CostModel {
    /// The operator table's weights (`UnaryOp::cost` and friends), [`TAP`] and [`PIXEL`].
    pub fn table() -> CostModel {
        let mut operators = BTreeMap::new();
        for op in UnaryOp::ALL {
            operators.insert(op.name().to_string(), op.cost());
        }
        for op in BinaryOp::ALL {
            operators.insert(op.name().to_string(), op.cost());
        }
        for op in PairOp::ALL {
            operators.insert(op.name().to_string(), op.cost());
        }
        CostModel { device: "operator table".into(), tap: TAP, pixel: PIXEL, operators }
    }

    fn unary(&self, op: UnaryOp) -> f64 {
        self.operators.get(op.name()).copied().unwrap_or(op.cost())
    }
    fn binary(&self, op: BinaryOp) -> f64 {
        self.operators.get(op.name()).copied().unwrap_or(op.cost())
    }
    fn pair(&self, op: PairOp) -> f64 {
        self.operators.get(op.name()).copied().unwrap_or(op.cost())
    }

    /// The weight of one instruction of a lowered kernel body: an operator
    /// its own, and each cheaper form the lowering gives an operator what it
    /// computes instead.
    pub fn instruction(&self, op: &Op) -> f64 {
        match *op {
            Op::Unary(op, _) => self.unary(op),
            Op::Binary(op, ..) => self.binary(op),
            Op::Pair(op, ..) => self.pair(op),
            // A plain subtraction or absolute value, without saturation.
            Op::NegInRange(_) | Op::AbsInRange(_) => self.binary(BinaryOp::Sub),
            // A product: `x * x`, `x * (1/c)`.
            Op::Square(..) | Op::Scale(..) => self.binary(BinaryOp::Mul),
            // The operator, less the parts of its guard its range proves idle
            // (priced as the operator: the model has no finer weight).
            Op::Arith(op, ..) => self.binary(op),
            Op::ExpNonPositive(_) => self.unary(UnaryOp::Exp),
            Op::SqrtNonNegative(..) => self.unary(UnaryOp::Sqrt),
            Op::PowNonNegative(..) => self.binary(BinaryOp::Pow),
            // Its squarings and the products of the powers n's bits name.
            Op::IntegerPower(_, n, ..) => {
                let products = n.ilog2() + n.count_ones() - 1;
                products as f64 * self.binary(BinaryOp::Mul)
            }
            // The squared distance: `distance2` without its square root (never cheaper than a dot product).
            Op::Distance2Squared(..) => {
                (self.pair(PairOp::Distance2) - self.unary(UnaryOp::Sqrt)).max(self.pair(PairOp::Dot))
            }
        }
    }

    /// A model read from `path`: a bare model, or `bench.json` (its `cost_model`).
    pub fn read(path: &std::path::Path) -> Result<CostModel, String> {
        let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
        Self::parse(&text).map_err(|e| format!("{}: {e}", path.display()))
    }

    /// The model `filterjit bench` measured on lavapipe on a 2-core CPU
    /// (`data/cost-model-lavapipe.json`), which `evolve --preset realtime`
    /// searches with; other devices measure their own (`--cost-model`).
    pub fn lavapipe() -> CostModel {
        Self::parse(include_str!("../data/cost-model-lavapipe.json")).expect("the shipped cost model parses")
    }

    /// A model from JSON text: a bare model, or a bench report with one.
    fn parse(text: &str) -> Result<CostModel, String> {
        let value: serde_json::Value = serde_json::from_str(text).map_err(|e| format!("not JSON: {e}"))?;
        let model = value.get("cost_model").cloned().unwrap_or(value);
        let model: CostModel =
            serde_json::from_value(model).map_err(|e| format!("not a cost model or a bench report with one: {e}"))?;
        let known: HashSet<&str> = UnaryOp::ALL
            .iter()
            .map(|o| o.name())
            .chain(BinaryOp::ALL.iter().map(|o| o.name()))
            .chain(PairOp::ALL.iter().map(|o| o.name()))
            .collect();
        for (name, cost) in &model.operators {
            if !known.contains(name.as_str()) {
                return Err(format!("`{name}` is not an operator"));
            }
            if !(cost.is_finite() && *cost >= 0.0) {
                return Err(format!("the cost of `{name}` must be a finite number ≥ 0, not {cost}"));
            }
        }
        if !(model.tap.is_finite() && model.tap >= 0.0 && model.pixel.is_finite() && model.pixel >= 0.0) {
            return Err("`tap` and `pixel` must be finite numbers ≥ 0".to_string());
        }
        Ok(model)
    }
}

/// What an expression costs where it is computed.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ExprCost {
    /// Once per pixel and pass.
    pub per_pixel: f64,
    /// At every tap.
    pub per_tap: f64,
}

impl ExprCost {
    /// With the operator table's weights.
    pub fn of(expr: &Expr) -> ExprCost {
        Self::with(expr, &CostModel::table())
    }

    /// What the kernel body the JIT builds for `expr` costs: each
    /// instruction where it runs, and a load per centre variance it reads.
    pub fn with(expr: &Expr, model: &CostModel) -> ExprCost {
        let body = ir::Body::of(expr, LowerOptions::ALL);
        let mut cost = ExprCost { per_pixel: body.centre_loads() as f64, per_tap: 0.0 };
        for inst in &body.insts {
            let own = model.instruction(&inst.op);
            match inst.side {
                Side::Centre => cost.per_pixel += own,
                Side::Neighbour => cost.per_tap += own,
            }
        }
        cost
    }
}

/// Taps per pixel of one pass of the form, and the number of passes.
pub fn taps(pipeline: &FilterPipeline, radius: u32) -> (f64, f64) {
    match pipeline.form {
        Form::Window => (((2 * radius + 1) * (2 * radius + 1)) as f64, 1.0),
        Form::Atrous { passes, stencil } => {
            let side = (2 * stencil.half_width() + 1) as f64;
            (side * side, passes as f64)
        }
    }
}

/// The whole pipeline's cost per pixel (operator table weights): pre-pass, then every pass of the form.
pub fn model(expr: &Expr, pipeline: &FilterPipeline, radius: u32) -> f64 {
    model_with(expr, pipeline, radius, &CostModel::table())
}

/// [`model`] with a device's weights.
pub fn model_with(expr: &Expr, pipeline: &FilterPipeline, radius: u32, weights: &CostModel) -> f64 {
    let e = ExprCost::with(expr, weights);
    let (taps, passes) = taps(pipeline, radius);
    let side = (2 * OUTLIER_RADIUS + 1) as f64;
    let prepass = if pipeline.outliers.is_some() { (side * side - 1.0) * weights.tap } else { 0.0 }
        + if pipeline.demodulate { weights.pixel } else { 0.0 };
    prepass + passes * (weights.pixel + e.per_pixel + taps * (weights.tap + e.per_tap))
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

    /// The model prices what the lowering emits, not the tree as written.
    #[test]
    fn strength_reduced_forms_cost_what_the_kernel_runs() {
        let e = |s: &str| ExprCost::of(&parse_expr(s).unwrap());
        let table = CostModel::table();
        // One squared-distance instruction: no square root, no `pow`.
        let squared = e("pow(distance2(normal), 2)");
        let no_root = (PairOp::Distance2.cost() - UnaryOp::Sqrt.cost()).max(PairOp::Dot.cost());
        assert_eq!(squared.per_tap, no_root);
        assert!(squared.per_tap < PairOp::Distance2.cost() + BinaryOp::Pow.cost());
        // `x / 4` is a product by 0.25; `pow(x, 2)` of anything a product.
        assert_eq!(e("distance1(color) / 4").per_tap, PairOp::Distance1.cost() + BinaryOp::Mul.cost());
        assert_eq!(e("pow(distance1(color), 2)").per_tap, PairOp::Distance1.cost() + BinaryOp::Mul.cost());
        // Each instruction of the lowered body is charged once, where it runs.
        let expr = parse_expr("exp(-(distance2(color) / (0.5 + colorVariance)))").unwrap();
        let body = crate::jit::ir::Body::of(&expr, LowerOptions::ALL);
        let charged: f64 = body.insts.iter().map(|i| table.instruction(&i.op)).sum::<f64>() + 1.0;
        let c = ExprCost::of(&expr);
        assert_eq!(c.per_pixel + c.per_tap, charged);
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
    fn a_measured_model_replaces_the_table_where_it_names_an_operator() {
        let mut measured = CostModel::table();
        assert_eq!(
            model_with(&parse_expr("exp(distance2(color))").unwrap(), &FilterPipeline::WINDOW, 2, &measured),
            model(&parse_expr("exp(distance2(color))").unwrap(), &FilterPipeline::WINDOW, 2)
        );
        measured.operators.insert("exp".into(), 60.0);
        measured.operators.remove("distance2");
        let c = ExprCost::with(&parse_expr("exp(distance2(color))").unwrap(), &measured);
        assert_eq!(c.per_tap, 60.0 + PairOp::Distance2.cost());
        let dir = std::env::temp_dir().join(format!("filterjit-cost-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("bench.json");
        std::fs::write(&file, serde_json::json!({ "cost_model": measured }).to_string()).unwrap();
        assert_eq!(CostModel::read(&file).unwrap(), measured);
        measured.operators.insert("cosh".into(), 1.0);
        std::fs::write(&file, serde_json::to_string(&measured).unwrap()).unwrap();
        let err = CostModel::read(&file).unwrap_err();
        assert!(err.contains("`cosh` is not an operator") && err.contains("bench.json"), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn rank_correlation_is_one_for_the_same_order_and_minus_one_reversed() {
        let a = [1.0, 2.0, 3.0, 4.0];
        assert!((rank_correlation(&a, &[10.0, 20.0, 25.0, 100.0]) - 1.0).abs() < 1e-12);
        assert!((rank_correlation(&a, &[4.0, 3.0, 2.0, 1.0]) + 1.0).abs() < 1e-12);
        assert!(rank_correlation(&a, &[1.0, 1.0, 1.0, 1.0]).abs() < 1e-12);
    }
}
