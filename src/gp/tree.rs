//! Addressing and editing expression nodes by pre-order index.
//!
//! Every node has a slot type (strongly typed GP, thesis 3.2.4): scalar
//! expression nodes, and the feature slots of feature-pair operators.

use crate::lang::{Expr, Feature};

/// A node's type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Slot {
    Scalar,
    Feature,
}

/// A subtree cut out of an expression, or to be put in.
#[derive(Clone, Debug, PartialEq)]
pub enum Node {
    Scalar(Expr),
    Feature(Feature),
}

impl Node {
    pub fn slot(&self) -> Slot {
        match self {
            Node::Scalar(_) => Slot::Scalar,
            Node::Feature(_) => Slot::Feature,
        }
    }
}

/// One node of the pre-order listing.
#[derive(Clone, Copy, Debug)]
pub struct NodeInfo {
    pub slot: Slot,
    pub parent: Option<usize>,
    /// Nodes in the subtree, this one included.
    pub size: usize,
}

/// All nodes in pre-order (the expression's length is the listing's length).
pub fn nodes(e: &Expr) -> Vec<NodeInfo> {
    fn walk(e: &Expr, parent: Option<usize>, out: &mut Vec<NodeInfo>) {
        let me = out.len();
        out.push(NodeInfo { slot: Slot::Scalar, parent, size: 1 });
        match e {
            Expr::Const(_) | Expr::Var(_) => {}
            Expr::Unary(_, a) => walk(a, Some(me), out),
            Expr::Binary(_, a, b) => {
                walk(a, Some(me), out);
                walk(b, Some(me), out);
            }
            Expr::Pair(..) => {
                out.push(NodeInfo { slot: Slot::Feature, parent: Some(me), size: 1 });
                out.push(NodeInfo { slot: Slot::Feature, parent: Some(me), size: 1 });
            }
        }
        out[me].size = out.len() - me;
    }
    let mut out = Vec::with_capacity(e.len());
    walk(e, None, &mut out);
    out
}

/// The subtree at pre-order index `index`.
pub fn get(e: &Expr, index: usize) -> Node {
    fn find(e: &Expr, index: usize, next: &mut usize) -> Option<Node> {
        if *next == index {
            return Some(Node::Scalar(e.clone()));
        }
        *next += 1;
        match e {
            Expr::Const(_) | Expr::Var(_) => None,
            Expr::Unary(_, a) => find(a, index, next),
            Expr::Binary(_, a, b) => find(a, index, next).or_else(|| find(b, index, next)),
            Expr::Pair(_, i, j) => {
                for f in [i, j] {
                    if *next == index {
                        return Some(Node::Feature(*f));
                    }
                    *next += 1;
                }
                None
            }
        }
    }
    find(e, index, &mut 0).expect("index within the expression")
}

/// A copy of `e` with the subtree at `index` replaced by `with` (of the same slot type).
pub fn replace(e: &Expr, index: usize, with: &Node) -> Expr {
    fn go(e: &Expr, index: usize, with: &Node, next: &mut usize) -> Expr {
        if *next == index {
            *next += e.len();
            return match with {
                Node::Scalar(s) => s.clone(),
                Node::Feature(_) => panic!("a feature cannot replace a scalar node"),
            };
        }
        *next += 1;
        match e {
            Expr::Const(_) | Expr::Var(_) => e.clone(),
            Expr::Unary(op, a) => Expr::unary(*op, go(a, index, with, next)),
            Expr::Binary(op, a, b) => {
                let a = go(a, index, with, next);
                let b = go(b, index, with, next);
                Expr::binary(*op, a, b)
            }
            Expr::Pair(op, i, j) => {
                let mut pick = |f: Feature| {
                    let here = *next == index;
                    *next += 1;
                    match (here, with) {
                        (true, Node::Feature(g)) => *g,
                        (true, Node::Scalar(_)) => panic!("a scalar cannot replace a feature slot"),
                        (false, _) => f,
                    }
                };
                let i = pick(*i);
                let j = pick(*j);
                Expr::Pair(*op, i, j)
            }
        }
    }
    go(e, index, with, &mut 0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lang::parse_expr;

    #[test]
    fn listing_get_and_replace_agree() {
        let e = parse_expr("exp(-distance2(normal, texture)) + 2").unwrap();
        let n = nodes(&e);
        assert_eq!(n.len(), e.len());
        assert_eq!(n[0].size, e.len());
        let slots: Vec<Slot> = n.iter().map(|i| i.slot).collect();
        let (s, f) = (Slot::Scalar, Slot::Feature);
        assert_eq!(slots, vec![s, s, s, s, f, f, s]);
        assert_eq!(get(&e, 5), Node::Feature(Feature::Texture));
        assert_eq!(n[5].parent, Some(3));
        let e2 = replace(&e, 5, &Node::Feature(Feature::Depth));
        assert_eq!(e2.to_string(), "exp(-distance2(normal, depth)) + 2");
        let e3 = replace(&e, 3, &Node::Scalar(Expr::Const(1.0)));
        assert_eq!(e3.to_string(), "exp(-1) + 2");
        let e4 = replace(&e, 6, &get(&e, 1));
        assert_eq!(e4.to_string(), "exp(-distance2(normal, texture)) + exp(-distance2(normal, texture))");
    }
}
