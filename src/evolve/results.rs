//! What a finished run reports: each compared filter on the test scenes,
//! and the summary.

use anyhow::Result;
use serde::Serialize;

use super::hall::Rescored;
use crate::fitness::{domain_flags, normalised_error, Scorer};
use crate::gp;
use crate::lang::Expr;
use crate::semantics;

/// Test-set results of one expression.
#[derive(Clone, Debug, Serialize)]
pub struct TestResult {
    pub expr: String,
    /// relMSE per test scene (equation 3.5 without m/2).
    pub relmse: Vec<f64>,
    /// Mean over test scenes of relMSE / noisy relMSE.
    pub normalised: f64,
    /// The output's mean luminance over the reference's, per test scene
    /// (1 keeps the light; `None` where the reference is black or the filter invalid).
    pub light: Vec<Option<f64>>,
    pub invalid: Option<String>,
}

/// A baseline's test result, by the name it was asked for.
#[derive(Clone, Debug, Serialize)]
pub struct BaselineResult {
    pub name: String,
    #[serde(flatten)]
    pub result: TestResult,
}

/// What a finished run reports.
#[derive(Clone, Debug, Serialize)]
pub struct Summary {
    pub generations: u32,
    /// What `best.fitness` (the search's training fitness) was measured on.
    pub training_scored_on: String,
    /// After a run on tiles: the hall of fame on whole training images
    /// (`best` is the best of it there); empty otherwise.
    pub rescored_hall_of_fame: Vec<Rescored>,
    pub best: gp::StoredMember,
    /// The best expression simplified (the same weights; what `export` and `report` use).
    pub best_simplified: String,
    pub test_scenes: Vec<String>,
    pub test_noisy_relmse: Vec<f64>,
    /// The noisy inputs' light per test scene.
    pub test_noisy_light: Vec<Option<f64>>,
    pub test_best: TestResult,
    pub test_seed: TestResult,
    /// Other filters on the same test scenes, for comparison (those whose features the scenes have).
    pub test_baselines: Vec<BaselineResult>,
    pub feature_frequencies: std::collections::BTreeMap<String, usize>,
    pub seconds: f64,
}

/// Evaluate expressions on test scenes.
pub fn test(evaluator: &mut Scorer<'_>, exprs: &[Expr]) -> Result<Vec<TestResult>> {
    let radius = evaluator.radius();
    test_each(evaluator, &exprs.iter().map(|e| (e.clone(), radius)).collect::<Vec<_>>())
}

/// Evaluate expressions on test scenes, each at its own radius.
pub fn test_each(evaluator: &mut Scorer<'_>, exprs: &[(Expr, u32)]) -> Result<Vec<TestResult>> {
    let errors = evaluator.errors_each(exprs)?;
    let noisy = evaluator.noisy_relmse().to_vec();
    exprs
        .iter()
        .zip(errors)
        .map(|((e, radius), result)| {
            let per_scene = match result {
                Ok(per_scene) => per_scene,
                Err(reason) => {
                    return Ok(TestResult {
                        expr: e.to_string(),
                        relmse: vec![f64::NAN; noisy.len()],
                        normalised: f64::NAN,
                        light: vec![None; noisy.len()],
                        invalid: Some(reason.to_string()),
                    })
                }
            };
            let flags = domain_flags(&per_scene);
            Ok(TestResult {
                expr: e.to_string(),
                relmse: per_scene.iter().map(|s| s.relmse).collect(),
                normalised: normalised_error(&per_scene, &noisy),
                light: evaluator.light(e, *radius)?,
                invalid: (flags != 0).then(|| semantics::flag::describe(flags).join("; ")),
            })
        })
        .collect()
}

/// The mean of the light ratios that exist.
pub fn mean_light(light: &[Option<f64>]) -> Option<f64> {
    let known: Vec<f64> = light.iter().flatten().copied().collect();
    (!known.is_empty()).then(|| known.iter().sum::<f64>() / known.len() as f64)
}
