//! Expansion operators (thesis 3.2.4) and the codebook (3.2.2), strongly
//! typed: subtrees are only exchanged between slots of the same type.

use std::collections::BTreeSet;

use super::tree::{self, Node, Slot};
use crate::lang::{BinaryOp, Expr, Feature, PairOp, ScalarVar, UnaryOp};
use crate::rng::Rng;

/// What a run may use: the terminal set the training scenes provide.
#[derive(Clone, Debug)]
pub struct Terminals {
    pub features: Vec<Feature>,
    pub variables: Vec<ScalarVar>,
    pub constants: Vec<f64>,
}

/// The four mutations.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mutation {
    Insert,
    Replace,
    Swap,
    Delete,
}

/// Sub-expressions of the analytic filters, grouped by slot type.
#[derive(Clone, Debug)]
pub struct Codebook {
    pub scalars: Vec<Expr>,
    pub features: Vec<Feature>,
}

impl Codebook {
    /// All sub-expressions of k(‖f_i − f_j‖₂) for the kernels mitchell, sinc,
    /// epanechnikov, biweight and tricube, and of the Gaussian
    /// exp(−‖f_i − f_j‖²/(2·0.1²)), for every available feature f.
    pub fn new(terminals: &Terminals) -> Self {
        let mut seen = BTreeSet::new();
        let mut scalars = Vec::new();
        let mut add = |e: Expr| {
            let mut subs = Vec::new();
            e.visit(&mut |s| subs.push(s.clone()));
            for s in subs {
                if seen.insert(s.to_string()) {
                    scalars.push(s);
                }
            }
        };
        for &f in &terminals.features {
            let d = Expr::Pair(PairOp::Distance2, f, f);
            for k in [UnaryOp::Mitchell, UnaryOp::Sinc, UnaryOp::Epanechnikov, UnaryOp::Biweight, UnaryOp::Tricube] {
                add(Expr::unary(k, d.clone()));
            }
            let sigma2 = Expr::binary(BinaryOp::Pow, Expr::Const(0.1), Expr::Const(2.0));
            let gaussian = Expr::unary(
                UnaryOp::Exp,
                Expr::unary(
                    UnaryOp::Neg,
                    Expr::binary(
                        BinaryOp::Div,
                        Expr::binary(BinaryOp::Pow, d.clone(), Expr::Const(2.0)),
                        Expr::binary(BinaryOp::Mul, Expr::Const(2.0), sigma2),
                    ),
                ),
            );
            add(gaussian);
        }
        Codebook { scalars, features: terminals.features.clone() }
    }
}

fn pick_other<T: Copy + PartialEq>(rng: &mut Rng, all: &[T], current: T) -> T {
    let others: Vec<T> = all.iter().copied().filter(|x| *x != current).collect();
    if others.is_empty() {
        current
    } else {
        *rng.pick(&others)
    }
}

/// Replace a node by another of the same kind: an operator by one of the same
/// arity, a terminal by a terminal (variables and constants uniformly), a feature by a feature.
fn point(e: &Expr, index: usize, terminals: &Terminals, rng: &mut Rng) -> Option<Expr> {
    let replacement = match tree::get(e, index) {
        Node::Feature(f) => Node::Feature(pick_other(rng, &terminals.features, f)),
        Node::Scalar(s) => Node::Scalar(match s {
            Expr::Const(_) | Expr::Var(_) => {
                let total = terminals.variables.len() + terminals.constants.len();
                let k = rng.below(total);
                if k < terminals.variables.len() {
                    Expr::Var(terminals.variables[k])
                } else {
                    Expr::Const(terminals.constants[k - terminals.variables.len()])
                }
            }
            Expr::Unary(op, a) => Expr::Unary(pick_other(rng, UnaryOp::ALL, op), a),
            Expr::Binary(op, a, b) => Expr::Binary(pick_other(rng, BinaryOp::ALL, op), a, b),
            Expr::Pair(op, i, j) => Expr::Pair(pick_other(rng, PairOp::ALL, op), i, j),
        }),
    };
    Some(tree::replace(e, index, &replacement))
}

/// Apply one mutation at a uniformly chosen node; `None` when it cannot apply.
pub fn mutate(e: &Expr, kind: Mutation, terminals: &Terminals, codebook: &Codebook, rng: &mut Rng) -> Option<Expr> {
    let nodes = tree::nodes(e);
    let index = rng.below(nodes.len());
    match kind {
        Mutation::Replace => point(e, index, terminals, rng),
        Mutation::Insert => {
            let node = match nodes[index].slot {
                Slot::Scalar => Node::Scalar(rng.pick(&codebook.scalars).clone()),
                Slot::Feature => Node::Feature(*rng.pick(&codebook.features)),
            };
            Some(tree::replace(e, index, &node))
        }
        Mutation::Delete => {
            // A feature slot takes its feature-pair operator with it.
            let target = match nodes[index].slot {
                Slot::Scalar => index,
                Slot::Feature => nodes[index].parent.expect("a feature slot has a parent"),
            };
            Some(tree::replace(e, target, &Node::Scalar(Expr::Const(1.0))))
        }
        Mutation::Swap => {
            // A second point of the same type, outside the first's subtree and the first outside its.
            let a = index;
            let candidates: Vec<usize> = (0..nodes.len())
                .filter(|&b| {
                    nodes[b].slot == nodes[a].slot
                        && b != a
                        && !(a <= b && b < a + nodes[a].size)
                        && !(b <= a && a < b + nodes[b].size)
                })
                .collect();
            if candidates.is_empty() {
                return None;
            }
            let b = *rng.pick(&candidates);
            let (first, second) = (a.min(b), a.max(b));
            let (node_first, node_second) = (tree::get(e, first), tree::get(e, second));
            // Replace the later one first so the earlier index stays valid.
            let e = tree::replace(e, second, &node_first);
            Some(tree::replace(&e, first, &node_second))
        }
    }
}

/// Strongly typed subtree crossover: a uniformly chosen node of `a` and a
/// uniformly chosen node of the same type in `b` exchange their subtrees.
pub fn crossover(a: &Expr, b: &Expr, rng: &mut Rng) -> Option<(Expr, Expr)> {
    let na = tree::nodes(a);
    let nb = tree::nodes(b);
    let i = rng.below(na.len());
    let compatible: Vec<usize> = (0..nb.len()).filter(|&j| nb[j].slot == na[i].slot).collect();
    if compatible.is_empty() {
        return None;
    }
    let j = *rng.pick(&compatible);
    let (sa, sb) = (tree::get(a, i), tree::get(b, j));
    Some((tree::replace(a, i, &sb), tree::replace(b, j, &sa)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lang::parse_expr;

    fn terminals() -> Terminals {
        Terminals {
            features: vec![Feature::Normal, Feature::Color, Feature::Pixel],
            variables: vec![ScalarVar::ColorVariance],
            constants: crate::lang::ops::THESIS_CONSTANTS.to_vec(),
        }
    }

    #[test]
    fn operators_keep_expressions_well_typed_and_within_the_terminal_set() {
        let t = terminals();
        let codebook = Codebook::new(&t);
        assert!(codebook
            .scalars
            .iter()
            .any(|e| e.to_string() == "exp(-(pow(distance2(normal), 2) / (2 * pow(0.1, 2))))"));
        assert!(codebook.scalars.iter().any(|e| e.to_string() == "0.1"));
        let mut rng = Rng::seeded(5);
        let mut e = parse_expr("exp(-(pow(distance2(pixel), 2) / 18 + pow(distance2(color), 2) / 0.5))").unwrap();
        for step in 0..2000 {
            let kind = [Mutation::Insert, Mutation::Replace, Mutation::Swap, Mutation::Delete][step % 4];
            if let Some(m) = mutate(&e, kind, &t, &codebook, &mut rng) {
                // Printing and parsing back checks well-typedness.
                assert_eq!(parse_expr(&m.to_string()).unwrap(), m);
                for f in m.features() {
                    assert!(t.features.contains(&f), "{f} is outside the terminal set");
                }
                if m.len() < 60 {
                    e = m;
                }
            }
            let other = parse_expr("biweight(distance1(normal)) * colorVariance").unwrap();
            if let Some((x, y)) = crossover(&e, &other, &mut rng) {
                assert_eq!(x.len() + y.len(), e.len() + other.len());
            }
        }
    }

    #[test]
    fn delete_of_a_feature_removes_its_pair_operator() {
        let t = terminals();
        let codebook = Codebook::new(&t);
        let e = parse_expr("distance2(normal)").unwrap();
        // Indices 1 and 2 are feature slots; any deletion yields the constant 1.
        for seed in 0..10 {
            let m = mutate(&e, Mutation::Delete, &t, &codebook, &mut Rng::seeded(seed)).unwrap();
            assert_eq!(m, Expr::Const(1.0));
        }
    }
}
