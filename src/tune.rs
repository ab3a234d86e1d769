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

use crate::evolve::GpuEvaluator;
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
    /// Mean over the training scenes of relMSE / noisy relMSE.
    pub fitness: f64,
    /// The hand-set sigmas' fitness on the same scenes.
    pub hand_set_fitness: f64,
    pub evaluated: usize,
    pub scenes: Vec<String>,
}

/// Factors each step multiplies a sigma by.
const FACTORS: [f64; 6] = [0.35, 0.5, 0.7, 1.4, 2.0, 2.8];

/// Tune the sigmas of the terms the evaluator's scenes provide, starting from
/// the hand-set values; `sweeps` passes over the five sigmas.
pub fn tune(evaluator: &mut GpuEvaluator<'_>, sweeps: usize, on_step: &mut dyn FnMut(&Sigmas, f64)) -> Result<Tuned> {
    let available: BTreeSet<Feature> = TERMS
        .iter()
        .copied()
        .filter(|f| {
            matches!(f, Feature::Pixel | Feature::Color) || evaluator.scenes().iter().all(|s| s.feature(*f).is_some())
        })
        .collect();
    let mut memo: BTreeMap<String, f64> = BTreeMap::new();
    let mut score = |evaluator: &mut GpuEvaluator<'_>, candidates: &[Sigmas]| -> Result<Vec<f64>> {
        let exprs: Vec<Expr> = candidates.iter().map(Sigmas::expr).collect();
        let texts: Vec<String> = exprs.iter().map(Expr::to_string).collect();
        let fresh: BTreeMap<&String, &Expr> =
            texts.iter().zip(&exprs).filter(|(t, _)| !memo.contains_key(*t)).collect();
        if !fresh.is_empty() {
            let noisy = evaluator.noisy_relmse().to_vec();
            let batch: Vec<Expr> = fresh.values().map(|e| (*e).clone()).collect();
            for (text, result) in fresh.keys().zip(evaluator.errors(&batch)?) {
                let fitness = match result {
                    Ok(per_scene) if per_scene.iter().all(|s| s.flags == 0 && s.relmse.is_finite()) => {
                        crate::evolve::normalised_error(&per_scene, &noisy)
                    }
                    _ => f64::INFINITY,
                };
                memo.insert((*text).clone(), fitness);
            }
        }
        Ok(texts.iter().map(|t| memo[t]).collect())
    };
    let start = Sigmas::hand_set(&available);
    let hand_set_fitness = score(evaluator, std::slice::from_ref(&start))?[0];
    let (mut best, mut best_fitness) = (start, hand_set_fitness);
    on_step(&best, best_fitness);
    for _ in 0..sweeps {
        let before = best_fitness;
        for term in TERMS.iter().filter(|f| available.contains(f)) {
            let name = term.name().to_string();
            let candidates: Vec<Sigmas> = FACTORS
                .iter()
                .map(|factor| {
                    let mut s = best.clone();
                    s.0.insert(name.clone(), round3(best.0[&name] * factor));
                    s
                })
                .collect();
            for (candidate, fitness) in candidates.iter().zip(score(evaluator, &candidates)?) {
                if fitness < best_fitness {
                    (best, best_fitness) = (candidate.clone(), fitness);
                }
            }
            on_step(&best, best_fitness);
        }
        if best_fitness >= before {
            break;
        }
    }
    Ok(Tuned {
        expr: best.expr().to_string(),
        sigmas: best,
        fitness: best_fitness,
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
    fn constants_keep_three_significant_digits() {
        assert_eq!(short(3.0), "3");
        assert_eq!(short(0.123456), "0.123");
        assert_eq!(short(12.345), "12.3");
        assert_eq!(short(0.05), "0.05");
        assert_eq!(round3(0.35 * 0.1), 0.035);
    }
}
