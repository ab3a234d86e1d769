//! The cross-bilateral baseline with its sigmas tuned on training scenes.
//!
//! A filter with hand-set constants is a weak opponent; the report compares
//! evolved filters with the best constant-sigma cross-bilateral filter this
//! search finds on the *training* scenes (never the test scenes): coordinate
//! descent over the five sigmas, each step trying the current value times a
//! few factors, all candidates of a step compiled and evaluated as one batch.

use std::collections::{BTreeMap, BTreeSet};

use anyhow::Result;
use serde::Serialize;

use crate::fitness::Scorer;
use crate::lang::{parse_expr, Expr, Feature};

/// The terms of the cross-bilateral filter, in the order of its formula.
pub const TERMS: [Feature; 5] =
    [Feature::Pixel, Feature::Color, Feature::Normal, Feature::Texture, Feature::WorldPosition];

/// Sigma per term (pixel distance in pixels, the others in normalised units).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Sigmas(pub BTreeMap<String, f64>);

impl Sigmas {
    /// The shipped `@crossBilateral`'s hand-set values, for the terms `features` allows.
    pub fn hand_set(features: &BTreeSet<Feature>) -> Self {
        let value = |f: Feature| match f {
            Feature::Pixel => 3.0,
            Feature::Color => 0.5,
            _ => 0.1,
        };
        Sigmas(TERMS.iter().filter(|f| features.contains(f)).map(|f| (f.name().to_string(), value(*f))).collect())
    }

    /// `exp(-(Σ_f distance2(f)² / (2 σ_f²)))`, in the grammar's syntax.
    pub fn expr(&self) -> Expr {
        let terms: Vec<String> = TERMS
            .iter()
            .filter_map(|f| self.0.get(f.name()).map(|s| (f, s)))
            .map(|(f, s)| format!("pow(distance2({f}), 2) / (2 * pow({}, 2))", short(*s)))
            .collect();
        let text = format!("exp(-({}))", terms.join(" + "));
        parse_expr(&text).expect("the cross-bilateral template parses")
    }
}

/// Three significant digits: readable constants, and a finite search space.
fn short(value: f64) -> String {
    let digits = (2 - value.abs().log10().floor() as i32).max(0) as usize;
    let text = format!("{value:.digits$}");
    if text.contains('.') {
        text.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        text
    }
}

fn round3(value: f64) -> f64 {
    short(value).parse().expect("a number")
}

/// The outcome of a search.
#[derive(Clone, Debug, Serialize)]
pub struct Tuned {
    pub sigmas: Sigmas,
    pub expr: String,
    /// The training fitness by `rule` (the thesis's: mean over the training
    /// scenes of relMSE / noisy relMSE).
    pub fitness: f64,
    /// The fitness rule, in words.
    pub rule: String,
    /// The hand-set sigmas' fitness on the same scenes.
    pub hand_set_fitness: f64,
    pub evaluated: usize,
    pub scenes: Vec<String>,
}

/// Factors each step multiplies a sigma by.
const FACTORS: [f64; 6] = [0.35, 0.5, 0.7, 1.4, 2.0, 2.8];

/// Tune the sigmas of the terms the evaluator's scenes provide, starting from
/// the hand-set values; `sweeps` passes over the five sigmas.
pub fn tune(evaluator: &mut Scorer<'_>, sweeps: usize, on_step: &mut dyn FnMut(&Sigmas, f64)) -> Result<Tuned> {
    let available: Vec<Feature> = TERMS
        .iter()
        .copied()
        .filter(|f| {
            matches!(f, Feature::Pixel | Feature::Color) || evaluator.scenes().iter().all(|s| s.feature(*f).is_some())
        })
        .collect();
    let start = Sigmas::hand_set(&available.iter().copied().collect());
    let names: Vec<String> = available.iter().map(|f| f.name().to_string()).collect();
    let values: Vec<f64> = names.iter().map(|n| start.0[n]).collect();
    let sigmas = |values: &[f64]| Sigmas(names.iter().cloned().zip(values.iter().copied()).collect());
    descend(evaluator, &values, &|v| sigmas(v).expr(), &sigmas, sweeps, on_step)
}

/// Tune every literal of `start` the same way (its structure kept): a
/// hand-set filter of any form, such as the SVGF-style `@svgfAtrous`. The
/// literals are named `c1`, `c2`, … in pre-order.
pub fn tune_literals(
    evaluator: &mut Scorer<'_>,
    start: &Expr,
    sweeps: usize,
    on_step: &mut dyn FnMut(&Sigmas, f64),
) -> Result<Tuned> {
    let values = literals(start);
    let named = |values: &[f64]| Sigmas(values.iter().enumerate().map(|(k, v)| (format!("c{}", k + 1), *v)).collect());
    descend(evaluator, &values, &|v| with_literals(start, &mut v.iter().copied()), &named, sweeps, on_step)
}

/// The literals of `e`, in pre-order.
pub fn literals(e: &Expr) -> Vec<f64> {
    fn walk(e: &Expr, out: &mut Vec<f64>) {
        match e {
            Expr::Const(c) => out.push(*c),
            Expr::Unary(_, a) => walk(a, out),
            Expr::Binary(_, a, b) => {
                walk(a, out);
                walk(b, out);
            }
            Expr::Var(_) | Expr::Pair(..) => {}
        }
    }
    let mut out = Vec::new();
    walk(e, &mut out);
    out
}

/// `e` with its literals, in pre-order, replaced by `values`.
pub fn with_literals(e: &Expr, values: &mut impl Iterator<Item = f64>) -> Expr {
    match e {
        Expr::Const(c) => Expr::Const(values.next().unwrap_or(*c)),
        Expr::Unary(op, a) => Expr::unary(*op, with_literals(a, values)),
        Expr::Binary(op, a, b) => {
            let a = with_literals(a, values);
            Expr::binary(*op, a, with_literals(b, values))
        }
        other => other.clone(),
    }
}

/// Coordinate descent from `start`: each step tries one value times each of
/// [`FACTORS`] (three significant digits), all of a step's candidates
/// compiled and scored as one batch; `sweeps` passes, or until one gains nothing.
fn descend(
    evaluator: &mut Scorer<'_>,
    start: &[f64],
    build: &dyn Fn(&[f64]) -> Expr,
    named: &dyn Fn(&[f64]) -> Sigmas,
    sweeps: usize,
    on_step: &mut dyn FnMut(&Sigmas, f64),
) -> Result<Tuned> {
    let mut memo: BTreeMap<String, f64> = BTreeMap::new();
    let mut score = |evaluator: &mut Scorer<'_>, candidates: &[Vec<f64>]| -> Result<Vec<f64>> {
        let exprs: Vec<Expr> = candidates.iter().map(|c| build(c)).collect();
        let texts: Vec<String> = exprs.iter().map(Expr::to_string).collect();
        let fresh: BTreeMap<&String, &Expr> =
            texts.iter().zip(&exprs).filter(|(t, _)| !memo.contains_key(*t)).collect();
        if !fresh.is_empty() {
            let noisy = evaluator.noisy_relmse().to_vec();
            let batch: Vec<Expr> = fresh.values().map(|e| (*e).clone()).collect();
            for (text, result) in fresh.keys().zip(evaluator.errors(&batch)?) {
                let fitness = match result {
                    Ok(per_scene) if per_scene.iter().all(|s| s.flags == 0 && s.relmse.is_finite()) => {
                        crate::fitness::normalised_error(&per_scene, &noisy)
                    }
                    _ => f64::INFINITY,
                };
                memo.insert((*text).clone(), fitness);
            }
        }
        Ok(texts.iter().map(|t| memo[t]).collect())
    };
    let hand_set_fitness = score(evaluator, &[start.to_vec()])?[0];
    let (mut best, mut best_fitness) = (start.to_vec(), hand_set_fitness);
    on_step(&named(&best), best_fitness);
    for _ in 0..sweeps {
        let before = best_fitness;
        for k in 0..best.len() {
            let candidates: Vec<Vec<f64>> = FACTORS
                .iter()
                .map(|factor| {
                    let mut c = best.clone();
                    c[k] = round3(best[k] * factor);
                    c
                })
                .collect();
            for (candidate, fitness) in candidates.iter().zip(score(evaluator, &candidates)?) {
                if fitness < best_fitness {
                    (best, best_fitness) = (candidate.clone(), fitness);
                }
            }
            on_step(&named(&best), best_fitness);
        }
        if best_fitness >= before {
            break;
        }
    }
    Ok(Tuned {
        expr: build(&best).to_string(),
        sigmas: named(&best),
        fitness: best_fitness,
        rule: evaluator.settings().rule.describe(),
        hand_set_fitness,
        evaluated: memo.len(),
        scenes: evaluator.scenes().iter().map(|s| s.name.clone()).collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hand_set_sigmas_give_the_shipped_cross_bilateral() {
        let all: BTreeSet<Feature> = TERMS.into_iter().collect();
        let shipped = parse_expr(crate::corpus::lookup("crossBilateral").unwrap()).unwrap();
        assert_eq!(Sigmas::hand_set(&all).expr(), shipped);
    }

    #[test]
    fn literals_are_read_and_replaced_in_pre_order() {
        let e = parse_expr("exp(-(distance2(normal) / 0.1 + distance1(depth) / (2 * 0.5)))").unwrap();
        assert_eq!(literals(&e), [0.1, 2.0, 0.5]);
        let changed = with_literals(&e, &mut [0.2, 3.0, 0.25].into_iter());
        assert_eq!(changed.to_string(), "exp(-(distance2(normal) / 0.2 + distance1(depth) / (3 * 0.25)))");
        assert_eq!(with_literals(&e, &mut literals(&e).into_iter()), e);
    }

    #[test]
    fn constants_keep_three_significant_digits() {
        assert_eq!(short(3.0), "3");
        assert_eq!(short(0.123456), "0.123");
        assert_eq!(short(12.345), "12.3");
        assert_eq!(short(0.05), "0.05");
        assert_eq!(round3(0.35 * 0.1), 0.035);
    }
}
