//! The typed expression tree and its canonical printer.
//!
//! An [`Expr`] is well typed by construction: scalar operators take scalar
//! children and feature-pair operators take two features. Values of this type
//! come from [`crate::lang::check`] (from text) or from code that builds trees
//! directly (tests, the GP engine); [`Expr::validate`] checks the one invariant
//! Rust's types cannot: literals are finite, non-negative and at most
//! [`crate::semantics::BIG`].

use std::collections::BTreeSet;
use std::fmt;

use super::ops::{BinaryOp, Feature, Fixity, PairOp, ScalarVar, UnaryOp, PREFIX_PRECEDENCE};
use crate::semantics;

/// A weight expression `w_ij`.
#[derive(Clone, Debug, PartialEq)]
pub enum Expr {
    /// A literal; finite, non-negative and at most `semantics::BIG`.
    Const(f64),
    /// A per-pixel scalar (a sample variance) of the centre pixel.
    Var(ScalarVar),
    Unary(UnaryOp, Box<Expr>),
    Binary(BinaryOp, Box<Expr>, Box<Expr>),
    /// An operator on feature `.1` of pixel i and feature `.2` of pixel j.
    Pair(PairOp, Feature, Feature),
}

impl Expr {
    pub fn unary(op: UnaryOp, a: Expr) -> Expr {
        Expr::Unary(op, Box::new(a))
    }

    pub fn binary(op: BinaryOp, a: Expr, b: Expr) -> Expr {
        Expr::Binary(op, Box::new(a), Box::new(b))
    }

    /// Number of nodes, counting each feature of a pair operator as a node
    /// (the thesis's expression length).
    pub fn len(&self) -> usize {
        match self {
            Expr::Const(_) | Expr::Var(_) => 1,
            Expr::Unary(_, a) => 1 + a.len(),
            Expr::Binary(_, a, b) => 1 + a.len() + b.len(),
            Expr::Pair(..) => 3,
        }
    }

    pub fn is_empty(&self) -> bool {
        false
    }

    /// How deeply operators nest, as the parser counts it against
    /// [`super::parse::MAX_DEPTH`]: each operator is one level above its operands.
    pub fn depth(&self) -> usize {
        match self {
            Expr::Const(_) | Expr::Var(_) => 0,
            Expr::Pair(..) => 1,
            Expr::Unary(_, a) => 1 + a.depth(),
            Expr::Binary(_, a, b) => 1 + a.depth().max(b.depth()),
        }
    }

    /// Every vector terminal the expression reads.
    pub fn features(&self) -> BTreeSet<Feature> {
        let mut out = BTreeSet::new();
        self.visit(&mut |e| {
            if let Expr::Pair(_, a, b) = e {
                out.insert(*a);
                out.insert(*b);
            }
        });
        out
    }

    /// Every scalar variable the expression reads.
    /// The scalar terminals a scene must store (every one but `level`).
    pub fn stored_variables(&self) -> BTreeSet<ScalarVar> {
        self.variables().into_iter().filter(|v| v.is_stored()).collect()
    }

    /// The scalars a kernel reads from per-pixel buffers: the stored ones
    /// and what the outlier pre-pass measures (everything but `level`).
    pub fn bound_variables(&self) -> BTreeSet<ScalarVar> {
        self.variables().into_iter().filter(|v| v.is_bound()).collect()
    }

    pub fn variables(&self) -> BTreeSet<ScalarVar> {
        let mut out = BTreeSet::new();
        self.visit(&mut |e| {
            if let Expr::Var(v) = e {
                out.insert(*v);
            }
        });
        out
    }

    /// Pre-order walk.
    pub fn visit<'a>(&'a self, f: &mut impl FnMut(&'a Expr)) {
        f(self);
        match self {
            Expr::Unary(_, a) => a.visit(f),
            Expr::Binary(_, a, b) => {
                a.visit(f);
                b.visit(f);
            }
            Expr::Const(_) | Expr::Var(_) | Expr::Pair(..) => {}
        }
    }

    /// Check the literal invariant; returns the offending literal.
    pub fn validate(&self) -> Result<(), f64> {
        let mut bad = None;
        self.visit(&mut |e| {
            if let Expr::Const(c) = e {
                if !literal_in_range(*c) && bad.is_none() {
                    bad = Some(*c);
                }
            }
        });
        bad.map_or(Ok(()), Err)
    }

    /// The canonical text; `parse(e.to_string()) == e`.
    pub fn canonical(&self) -> String {
        self.to_string()
    }

    fn precedence(&self) -> u8 {
        match self {
            Expr::Unary(op, _) if matches!(op.fixity(), Fixity::Prefix { .. }) => PREFIX_PRECEDENCE,
            Expr::Binary(op, ..) => match op.fixity() {
                Fixity::Infix { precedence, .. } => precedence,
                _ => u8::MAX,
            },
            _ => u8::MAX,
        }
    }

    fn write(&self, f: &mut fmt::Formatter<'_>, min_precedence: u8) -> fmt::Result {
        let parens = self.precedence() < min_precedence;
        if parens {
            f.write_str("(")?;
        }
        match self {
            Expr::Const(c) => write_literal(f, *c)?,
            Expr::Var(v) => f.write_str(v.name())?,
            Expr::Unary(op, a) => match op.fixity() {
                Fixity::Prefix { symbol } => {
                    f.write_str(symbol)?;
                    a.write(f, PREFIX_PRECEDENCE)?;
                }
                _ => {
                    write!(f, "{}(", op.name())?;
                    a.write(f, 0)?;
                    f.write_str(")")?;
                }
            },
            Expr::Binary(op, a, b) => match op.fixity() {
                Fixity::Infix { symbol, precedence } => {
                    a.write(f, precedence)?;
                    write!(f, " {symbol} ")?;
                    // Left associative: an equal-precedence right operand needs parentheses.
                    b.write(f, precedence + 1)?;
                }
                _ => {
                    write!(f, "{}(", op.name())?;
                    a.write(f, 0)?;
                    f.write_str(", ")?;
                    b.write(f, 0)?;
                    f.write_str(")")?;
                }
            },
            Expr::Pair(op, a, b) if a == b => write!(f, "{}({})", op.name(), a.name())?,
            Expr::Pair(op, a, b) => write!(f, "{}({}, {})", op.name(), a.name(), b.name())?,
        }
        if parens {
            f.write_str(")")?;
        }
        Ok(())
    }
}

impl fmt::Display for Expr {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.write(f, 0)
    }
}

/// How many of `exprs`' operators read each terminal: a feature once per
/// pair operator that compares it (`distance2(normal)` counts `normal` once,
/// `dot(normal, texture)` each once), a variance once per occurrence. The one
/// definition of "feature usage" (evolve's `features.json`, `report`).
pub fn terminal_usage<'a>(exprs: impl IntoIterator<Item = &'a Expr>) -> std::collections::BTreeMap<String, usize> {
    let mut counts = std::collections::BTreeMap::new();
    for e in exprs {
        e.visit(&mut |node| match node {
            Expr::Pair(_, i, j) => {
                *counts.entry(i.name().to_string()).or_default() += 1;
                if i != j {
                    *counts.entry(j.name().to_string()).or_default() += 1;
                }
            }
            Expr::Var(v) => *counts.entry(v.name().to_string()).or_default() += 1,
            _ => {}
        });
    }
    counts
}

/// Whether a literal satisfies the language's invariant.
pub fn literal_in_range(c: f64) -> bool {
    c.is_finite() && (0.0..=semantics::BIG).contains(&c)
}

/// Shortest text that parses back to exactly `c`.
fn write_literal(f: &mut fmt::Formatter<'_>, c: f64) -> fmt::Result {
    if c == std::f64::consts::PI {
        f.write_str(super::ops::PI_NAMES[0])
    } else if c.fract() == 0.0 && c.abs() < 1e15 {
        write!(f, "{}", c as i64)
    } else {
        // Debug prints the shortest representation that round-trips, with an
        // exponent for very large or small values.
        write!(f, "{c:?}")
    }
}
