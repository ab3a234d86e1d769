//! Random well-typed expressions, for property tests, fuzzing and the GP engine.

use super::expr::Expr;
use super::ops::{BinaryOp, Feature, PairOp, ScalarVar, UnaryOp, THESIS_CONSTANTS};
use crate::rng::Rng;

/// What random expressions may contain.
#[derive(Clone, Debug)]
pub struct Alphabet {
    pub features: Vec<Feature>,
    pub variables: Vec<ScalarVar>,
    pub constants: Vec<f64>,
    /// Also draw arbitrary literals (any magnitude up to 1e6) besides `constants`.
    pub arbitrary_literals: bool,
}

impl Alphabet {
    /// Every terminal of the language.
    pub fn full() -> Self {
        Alphabet {
            features: Feature::ALL.to_vec(),
            variables: ScalarVar::ALL.to_vec(),
            constants: THESIS_CONSTANTS.to_vec(),
            arbitrary_literals: true,
        }
    }

    /// Restricted to the given features and variables, with the thesis's constants.
    pub fn with(features: &[Feature], variables: &[ScalarVar]) -> Self {
        Alphabet {
            features: features.to_vec(),
            variables: variables.to_vec(),
            constants: THESIS_CONSTANTS.to_vec(),
            arbitrary_literals: false,
        }
    }

    fn terminal(&self, rng: &mut Rng) -> Expr {
        let choices = 1 + usize::from(!self.variables.is_empty()) + usize::from(!self.features.is_empty());
        match rng.below(choices) {
            0 => {
                if self.arbitrary_literals && rng.chance(0.3) {
                    // Log-uniform magnitudes from 1e-6 to 1e6, and exact zero now and then.
                    if rng.chance(0.1) {
                        Expr::Const(0.0)
                    } else {
                        Expr::Const(10f64.powf(rng.unit() * 12.0 - 6.0))
                    }
                } else {
                    Expr::Const(*rng.pick(&self.constants))
                }
            }
            1 if !self.features.is_empty() => self.pair(rng),
            _ if !self.variables.is_empty() => Expr::Var(*rng.pick(&self.variables)),
            _ => self.pair(rng),
        }
    }

    fn pair(&self, rng: &mut Rng) -> Expr {
        let op = *rng.pick(PairOp::ALL);
        let i = *rng.pick(&self.features);
        let j = if rng.chance(0.8) { i } else { *rng.pick(&self.features) };
        Expr::Pair(op, i, j)
    }

    /// A random expression of depth at most `depth` ("grow" method).
    pub fn grow(&self, rng: &mut Rng, depth: usize) -> Expr {
        if depth <= 1 || rng.chance(0.25) {
            return self.terminal(rng);
        }
        if rng.chance(0.5) {
            Expr::unary(*rng.pick(UnaryOp::ALL), self.grow(rng, depth - 1))
        } else {
            Expr::binary(*rng.pick(BinaryOp::ALL), self.grow(rng, depth - 1), self.grow(rng, depth - 1))
        }
    }

    /// A random expression of close to `length` nodes (at least `length`).
    pub fn of_length(&self, rng: &mut Rng, length: usize) -> Expr {
        let mut e = self.terminal(rng);
        while e.len() < length {
            e = if rng.chance(0.4) {
                Expr::unary(*rng.pick(UnaryOp::ALL), e)
            } else {
                let other = self.grow(rng, 3);
                if rng.chance(0.5) {
                    Expr::binary(*rng.pick(BinaryOp::ALL), e, other)
                } else {
                    Expr::binary(*rng.pick(BinaryOp::ALL), other, e)
                }
            };
        }
        e
    }
}
