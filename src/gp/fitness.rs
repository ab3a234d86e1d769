//! What the search asks of its evaluator and gets back: a candidate, its
//! fitness (error, modelled cost, whether it filters at all) and the
//! objectives the search minimises.

use std::time::Duration;

use serde::{Deserialize, Serialize};

use crate::lang::Expr;

/// Fitness of an invalid expression (the thesis used the largest float).
pub const WORST: f64 = 1e30;

/// Mean over training scenes of relMSE(filtered) / relMSE(noisy); lower is better.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Fitness {
    pub value: f64,
    /// Why the expression is invalid, if it is (it then has the worst fitness).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub invalid: Option<String>,
    /// The filter's modelled cost per pixel ([`crate::cost::model`]), where the evaluator gives one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cost: Option<f64>,
    /// Its error against the noisy input's (the thesis's fitness), where
    /// `value` is measured against something else (a baseline filter's
    /// error, the light charged): what says whether it filters at all.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub versus_noisy: Option<f64>,
}

impl Fitness {
    pub fn valid(value: f64) -> Self {
        Fitness { value, invalid: None, cost: None, versus_noisy: None }
    }
    pub fn invalid(reason: impl Into<String>) -> Self {
        Fitness { value: WORST, invalid: Some(reason.into()), cost: None, versus_noisy: None }
    }
    pub fn with_cost(self, cost: f64) -> Self {
        Fitness { cost: Some(cost), ..self }
    }
    pub fn with_versus_noisy(self, versus_noisy: f64) -> Self {
        Fitness { versus_noisy: Some(versus_noisy), ..self }
    }

    /// Whether it filters at all: valid, and its error against the noisy
    /// input's below [`NO_CHOICE`] (a fitness relative to a baseline filter
    /// passes 1 wherever the baseline is better, and such a member is still
    /// a trade-off on a front).
    pub fn is_choice(&self) -> bool {
        self.invalid.is_none() && self.versus_noisy.unwrap_or(self.value) < NO_CHOICE
    }

    /// The point the multi-objective search compares: (error, cost), both
    /// to minimise. An invalid expression, and one that filters nothing
    /// (fitness [`NO_CHOICE`] or worse: say, a weight that is zero
    /// everywhere, the cheapest of all), is worse than every other in both:
    /// it is no trade-off.
    pub fn objectives(&self) -> Vec<f64> {
        match self.is_choice() {
            true => vec![self.value, self.cost.unwrap_or(0.0)],
            false => vec![WORST.max(self.value), WORST],
        }
    }

    /// Its point's exact identity, for keeping one individual per point.
    pub(super) fn point_key(&self) -> Vec<u64> {
        self.objectives().iter().map(|v| v.to_bits()).collect()
    }
}

/// What the search minimises.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum Objectives {
    /// The thesis's single objective: fitness (error) alone.
    #[default]
    #[serde(rename = "error")]
    Error,
    /// Error and modelled cost: NSGA-II's non-dominated sorting and crowding
    /// distance choose parents and survivors; the result is a front.
    #[serde(rename = "error,cost")]
    ErrorCost,
}

impl std::str::FromStr for Objectives {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.replace(' ', "").as_str() {
            "error" => Ok(Objectives::Error),
            "error,cost" | "cost,error" => Ok(Objectives::ErrorCost),
            other => Err(format!("`{other}`: the objectives are `error` or `error,cost`")),
        }
    }
}

impl std::fmt::Display for Objectives {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Objectives::Error => "error",
            Objectives::ErrorCost => "error,cost",
        })
    }
}

/// Time an evaluator spent, split as the progress report shows it.
#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize)]
pub struct EvalTime {
    pub compile: Duration,
    pub evaluate: Duration,
}

/// An individual to score: its weight expression and, where the search
/// evolves it too, its window radius (`None`: the run's radius).
#[derive(Clone, Debug)]
pub struct Candidate {
    pub expr: Expr,
    pub radius: Option<u32>,
}

impl Candidate {
    /// Candidates of `exprs`, each at the run's radius.
    pub fn at_run_radius(exprs: &[Expr]) -> Vec<Candidate> {
        exprs.iter().map(|e| Candidate { expr: e.clone(), radius: None }).collect()
    }
}

/// Computes fitness. Implementations compile and run kernels; the engine only sees numbers.
pub trait Evaluator {
    /// Fitness of each candidate, in order.
    fn evaluate(&mut self, candidates: &[Candidate]) -> anyhow::Result<Vec<Fitness>>;
    /// Time spent since the last call.
    fn take_time(&mut self) -> EvalTime;
}

/// Fitness from which a filter is no choice: within 0.1 % of the noisy
/// input's error (a weight that is zero everywhere scores 1 up to rounding).
pub const NO_CHOICE: f64 = 0.999;
