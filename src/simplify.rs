//! Algebraic simplification of weight expressions by equality saturation
//! (the `egg` crate): `Expr` → e-graph → rewrite to saturation → the
//! cheapest equivalent `Expr`.
//!
//! Every rule holds under filterjit's numeric semantics (docs/SEMANTICS.md):
//! results saturate at ±BIG and flush below TINY, division protects its
//! divisor, and undefined maths raises a domain flag. So `x / 1 → x` holds
//! but `x / x → 1` does not (x = 0 gives 0), associativity does not (it moves
//! saturation), and a rule that drops a subterm applies only where that
//! subterm can never raise a flag. Constant subtrees are folded with the CPU
//! semantics, unless folding raises a flag (as the JIT does). Tests check
//! every rule against the CPU evaluator: same weights within
//! [`WEIGHT_TOLERANCE`], same flags.
//!
//! The cost that picks the result is the operator table's kernel cost
//! ([`UnaryOp::cost`] and friends) plus a small charge per node, so among
//! equally fast forms the shorter one wins.

use egg::{Analysis, CostFunction, DidMerge, EGraph, Extractor, Id, Language, RecExpr, Rewrite, Runner};

use crate::lang::{BinaryOp, Expr, Feature, PairOp, ScalarVar, UnaryOp};
use crate::semantics;

/// Largest relative difference (to max(1, |w|)) between an expression's
/// weight and its simplified form's, on the CPU: folded constants are
/// rounded to f32 once, as literals are, where the original rounded each one.
pub const WEIGHT_TOLERANCE: f64 = 1e-6;

/// One e-node: the expression language with children as e-class ids.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Node {
    /// A literal, by the bits of its f64 value (finite, non-negative, ≤ BIG).
    Const(u64),
    Var(ScalarVar),
    Pair(PairOp, Feature, Feature),
    Unary(UnaryOp, [Id; 1]),
    Binary(BinaryOp, [Id; 2]),
}

impl Node {
    fn constant(value: f64) -> Node {
        Node::Const(value.to_bits())
    }
}

impl Language for Node {
    type Discriminant = std::mem::Discriminant<Node>;

    fn discriminant(&self) -> Self::Discriminant {
        std::mem::discriminant(self)
    }

    fn matches(&self, other: &Self) -> bool {
        match (self, other) {
            (Node::Unary(a, _), Node::Unary(b, _)) => a == b,
            (Node::Binary(a, _), Node::Binary(b, _)) => a == b,
            (a, b) => a == b,
        }
    }

    fn children(&self) -> &[Id] {
        match self {
            Node::Unary(_, c) => c,
            Node::Binary(_, c) => c,
            _ => &[],
        }
    }

    fn children_mut(&mut self) -> &mut [Id] {
        match self {
            Node::Unary(_, c) => c,
            Node::Binary(_, c) => c,
            _ => &mut [],
        }
    }
}

impl std::fmt::Display for Node {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Node::Const(bits) => write!(f, "{}", f64::from_bits(*bits)),
            Node::Var(v) => f.write_str(v.name()),
            Node::Pair(op, a, b) => write!(f, "{}:{}:{}", op.name(), a.name(), b.name()),
            Node::Unary(op, _) => f.write_str(op.name()),
            Node::Binary(op, _) => f.write_str(op.name()),
        }
    }
}

/// Patterns spell operators by their names in the operator table (`neg`,
/// `add`, `pow`, …) or by their infix symbols, and literals as numbers.
impl egg::FromOp for Node {
    type Error = String;

    fn from_op(op: &str, children: Vec<Id>) -> Result<Self, Self::Error> {
        let binary = |op| BinaryOp::ALL.iter().copied().find(|b: &BinaryOp| b.name() == op || symbol(*b) == Some(op));
        match children.as_slice() {
            [] => match (op.parse::<f64>(), ScalarVar::from_name(op)) {
                (Ok(value), _) if crate::lang::expr::literal_in_range(value) => Ok(Node::constant(value)),
                (_, Some(v)) => Ok(Node::Var(v)),
                _ => Err(format!("`{op}` is no literal or variable")),
            },
            [a] => UnaryOp::from_name(op).map(|u| Node::Unary(u, [*a])).ok_or_else(|| format!("no unary `{op}`")),
            [a, b] => binary(op).map(|o| Node::Binary(o, [*a, *b])).ok_or_else(|| format!("no binary `{op}`")),
            _ => Err(format!("`{op}` with {} operands", children.len())),
        }
    }
}

/// The shortest decimal within two f32 ulps of `value`: literals are held
/// as f32, so `2 * pow(0.1, 2)` folds to `0.02`, not `0.020000001`, and
/// `exp(1)` to `2.7182817`. (Two ulps is below [`WEIGHT_TOLERANCE`].)
fn readable(value: f64) -> f64 {
    let target = value as f32;
    let ulp = (f32::from_bits(target.to_bits() + 1) - target).abs() as f64;
    (1..=9)
        .filter_map(|digits| format!("{value:.*e}", digits - 1).parse::<f64>().ok())
        .find(|candidate| (candidate - target as f64).abs() <= 2.0 * ulp)
        .unwrap_or(target as f64)
}

fn symbol(op: BinaryOp) -> Option<&'static str> {
    match op.fixity() {
        crate::lang::ops::Fixity::Infix { symbol, .. } => Some(symbol),
        _ => None,
    }
}

/// An interval that holds every value a class can take, on every input,
/// under the CPU semantics (within [-BIG, BIG] but for raw variances). Bounds come from each
/// operator's monotonicity on the semantics' own functions (`fin` is
/// monotone), so they are sound, not tight; `tests/simplify.rs` checks them
/// against the CPU evaluator on random expressions.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Range {
    pub lo: f64,
    pub hi: f64,
}

impl Range {
    /// What is known of an arbitrary value.
    pub const ANY: Range = Range { lo: -semantics::BIG, hi: semantics::BIG };

    fn point(value: f64) -> Range {
        Range { lo: value, hi: value }
    }

    /// The smallest range holding every value.
    fn hull(values: impl IntoIterator<Item = f64>) -> Range {
        values
            .into_iter()
            .fold(Range { lo: f64::INFINITY, hi: f64::NEG_INFINITY }, |r, v| Range { lo: r.lo.min(v), hi: r.hi.max(v) })
    }

    pub fn nonneg(self) -> bool {
        self.lo >= 0.0
    }

    /// Where both hold (members of a class are equal, so both ranges hold).
    fn intersect(self, other: Range) -> Range {
        let both = Range { lo: self.lo.max(other.lo), hi: self.hi.min(other.hi) };
        // Empty only if a bound were unsound; keep the first rather than invent one.
        if both.lo <= both.hi {
            both
        } else {
            self
        }
    }

    /// The range of |x|.
    fn magnitude(self) -> Range {
        if self.lo >= 0.0 {
            self
        } else if self.hi <= 0.0 {
            Range { lo: -self.hi, hi: -self.lo }
        } else {
            Range { lo: 0.0, hi: self.hi.max(-self.lo) }
        }
    }

    /// Where a non-decreasing `f` takes this range.
    fn increasing(self, f: impl Fn(f64) -> f64) -> Range {
        Range { lo: f(self.lo), hi: f(self.hi) }
    }

    /// The divisor after `protect`: `None` where it may be either sign.
    fn protected(self) -> Option<Range> {
        let eps = semantics::DIV_EPS;
        if self.lo >= 0.0 {
            Some(Range { lo: self.lo.max(eps), hi: self.hi.max(eps) })
        } else if self.hi < 0.0 {
            Some(Range { lo: self.lo.min(-eps), hi: self.hi.min(-eps) })
        } else {
            None
        }
    }

    fn is_integer_point(self) -> bool {
        self.lo == self.hi && self.lo == self.lo.round()
    }
}

/// Where an operator's result lies, given where its operands lie.
fn unary_range(op: UnaryOp, a: Range) -> Range {
    use semantics as s;
    // The window kernels decrease in |x| on [0, 1] and are 0 beyond.
    let kernel = |f: fn(f64) -> f64| {
        let m = a.magnitude();
        Range { lo: f(m.hi), hi: f(m.lo) }
    };
    match op {
        UnaryOp::Neg => Range { lo: s::neg(a.hi), hi: s::neg(a.lo) },
        UnaryOp::Abs => a.magnitude(),
        UnaryOp::Exp => a.increasing(s::exp),
        UnaryOp::Sqrt => a.magnitude().increasing(|x| s::sqrt(x, &mut 0)),
        UnaryOp::Atan => a.increasing(s::atan),
        UnaryOp::Asin => a.increasing(|x| s::asin(x, &mut 0)),
        UnaryOp::Acos => Range { lo: s::acos(a.hi, &mut 0), hi: s::acos(a.lo, &mut 0) },
        UnaryOp::Sin | UnaryOp::Cos => Range { lo: -1.0, hi: 1.0 },
        UnaryOp::Epanechnikov => kernel(s::epanechnikov),
        UnaryOp::Biweight => kernel(s::biweight),
        UnaryOp::Tricube => kernel(s::tricube),
        // Not monotone; both stay within [-1, 1].
        UnaryOp::Mitchell | UnaryOp::Sinc => Range { lo: -1.0, hi: 1.0 },
        UnaryOp::Tan => Range::ANY,
    }
}

fn binary_range(op: BinaryOp, a: Range, b: Range) -> Range {
    use semantics as s;
    let corners =
        |f: &dyn Fn(f64, f64) -> f64| Range::hull([f(a.lo, b.lo), f(a.lo, b.hi), f(a.hi, b.lo), f(a.hi, b.hi)]);
    match op {
        BinaryOp::Add => Range { lo: s::add(a.lo, b.lo), hi: s::add(a.hi, b.hi) },
        BinaryOp::Sub => Range { lo: s::sub(a.lo, b.hi), hi: s::sub(a.hi, b.lo) },
        BinaryOp::Mul => corners(&s::mul),
        // a / d is monotone in each operand while d keeps its sign.
        BinaryOp::Div => match b.protected() {
            Some(d) => Range::hull(
                [(a.lo, d.lo), (a.lo, d.hi), (a.hi, d.lo), (a.hi, d.hi)].map(|(x, y)| semantics::fin(x / y)),
            ),
            None => Range::ANY,
        },
        BinaryOp::Pow => {
            if a == Range::point(1.0) {
                // The exponent multiplies log2(1) = 0.
                Range::point(1.0)
            } else if a.lo >= 0.0 && a.hi <= 1.0 && b.lo >= 0.0 {
                Range { lo: 0.0, hi: 1.0 }
            } else if a.lo >= 1.0 && b.lo >= 0.0 {
                Range { lo: 1.0, hi: s::BIG }
            } else if a.lo >= 0.0 || (b.is_integer_point() && b.lo % 2.0 == 0.0) {
                Range { lo: 0.0, hi: s::BIG }
            } else {
                Range::ANY
            }
        }
    }
}

/// Whether an operator can raise a flag itself, given where its operands lie.
fn unary_flags(op: UnaryOp, a: Range) -> bool {
    match op {
        UnaryOp::Sqrt => a.lo < 0.0,
        UnaryOp::Asin | UnaryOp::Acos => a.lo < -1.0 || a.hi > 1.0,
        _ => {
            debug_assert!(!op.can_flag(), "{op:?} flags: say when");
            false
        }
    }
}

fn binary_flags(op: BinaryOp, a: Range, b: Range) -> bool {
    match op {
        BinaryOp::Pow => a.lo < 0.0 && !b.is_integer_point(),
        _ => {
            debug_assert!(!op.can_flag(), "{op:?} flags: say when");
            false
        }
    }
}

/// What the e-graph knows of a class.
#[derive(Clone, Debug, PartialEq)]
pub struct Facts {
    /// The class's value when it is constant (evaluated with the CPU
    /// semantics, no flag raised), or when its range is one point and it
    /// never flags (`pow(1, x)` is 1 wherever `x` never flags).
    pub constant: Option<f64>,
    /// Whether some input can make the class raise a domain flag. Members of
    /// a class agree on flags (every rule keeps them), so one member that
    /// provably never flags clears it for the class.
    pub may_flag: bool,
    /// Where the class's values lie (members are equal, so each member's
    /// range holds for the class).
    pub range: Range,
    /// How often merges have narrowed `range` (at most [`NARROWINGS`]).
    narrowed: u8,
}

/// How often a class's range may be narrowed by merging. Literals are equal
/// within two f32 ulps (`readable`), so `x * c` and `x` can share a class for
/// a `c` a hair below 1; each narrowing of the class's range then narrows
/// `x * c`'s by the factor c again, forever. A range left wider is still
/// sound, so after this many narrowings a class keeps the one it has.
const NARROWINGS: u8 = 16;

impl Facts {
    fn of(range: Range, may_flag: bool) -> Facts {
        let constant = (range.lo == range.hi && !may_flag).then_some(range.lo);
        Facts { constant, may_flag, range, narrowed: 0 }
    }
}

/// The e-graph analysis: constant values, ranges and whether a class may flag.
#[derive(Default)]
pub struct Semantics;

impl Analysis<Node> for Semantics {
    type Data = Facts;

    fn make(egraph: &mut EGraph<Node, Self>, node: &Node, _: Id) -> Facts {
        let facts = |id: &Id| &egraph[*id].data;
        let constant =
            |value: f64| Facts { constant: Some(value), may_flag: false, range: Range::point(value), narrowed: 0 };
        match node {
            Node::Const(bits) => constant(semantics::literal(f64::from_bits(*bits))),
            Node::Var(ScalarVar::Level) => Facts::of(Range { lo: 0.0, hi: semantics::BIG }, false),
            // Variances are read as the scene holds them, unsaturated: any finite f32.
            Node::Var(_) => Facts::of(Range { lo: f32::MIN as f64, hi: f32::MAX as f64 }, false),
            Node::Pair(PairOp::Dot, ..) => Facts::of(Range::ANY, false),
            Node::Pair(..) => Facts::of(Range { lo: 0.0, hi: semantics::BIG }, false),
            Node::Unary(op, [a]) => {
                let a = facts(a);
                let mut flags = 0;
                match a.constant.map(|x| op.eval(x, &mut flags)) {
                    Some(value) if flags == 0 => constant(value),
                    _ => Facts::of(unary_range(*op, a.range), a.may_flag || unary_flags(*op, a.range)),
                }
            }
            Node::Binary(op, [a, b]) => {
                let (a, b) = (facts(a), facts(b));
                let mut flags = 0;
                match a.constant.zip(b.constant).map(|(x, y)| op.eval(x, y, &mut flags)) {
                    Some(value) if flags == 0 => constant(value),
                    _ => Facts::of(
                        binary_range(*op, a.range, b.range),
                        a.may_flag || b.may_flag || binary_flags(*op, a.range, b.range),
                    ),
                }
            }
        }
    }

    fn merge(&mut self, a: &mut Facts, b: Facts) -> DidMerge {
        let narrowed = a.narrowed.max(b.narrowed);
        let (range, narrowed) = match a.range.intersect(b.range) {
            same if same == a.range => (same, narrowed),
            narrower if narrowed < NARROWINGS => (narrower, narrowed + 1),
            _ => (a.range, narrowed),
        };
        let merged = Facts { constant: a.constant.or(b.constant), may_flag: a.may_flag && b.may_flag, range, narrowed };
        let merged =
            Facts { constant: merged.constant.or(Facts::of(merged.range, merged.may_flag).constant), ..merged };
        let changed_a = merged != *a;
        let changed_b = merged != b;
        *a = merged;
        DidMerge(changed_a, changed_b)
    }

    fn modify(egraph: &mut EGraph<Node, Self>, id: Id) {
        let Some(value) = egraph[id].data.constant else { return };
        // Once per class: a class that holds a literal (or the negation of
        // one) has its folded form already.
        let folded = |node: &Node| match node {
            Node::Const(_) => true,
            Node::Unary(UnaryOp::Neg, [a]) => egraph[*a].nodes.iter().any(|n| matches!(n, Node::Const(_))),
            _ => false,
        };
        if egraph[id].nodes.iter().any(folded) {
            return;
        }
        let magnitude = readable(value.abs());
        let literal = egraph.add(Node::constant(magnitude));
        let folded = if value < 0.0 { egraph.add(Node::Unary(UnaryOp::Neg, [literal])) } else { literal };
        egraph.union(id, folded);
    }
}

/// When a rule may fire.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Condition {
    Always,
    /// Only where `?x` can never raise a domain flag (the rule drops it).
    XNeverFlags,
    /// Only where `?x` is never negative.
    XNonNegative,
    /// `pow(pow(?x, ?p), ?q)` with `?x` never negative, `?p` a constant > 0
    /// and `?q` a constant ≥ 1: then saturation and flushing of the inner
    /// power carry through the outer one, and one power of `?x` gives the same.
    NestedPower,
    /// `?x` scaled by two constants `?p` and `?q` that are powers of two (in
    /// [2^-20, 2^20]), the first step (`?x` times the given factor) never
    /// saturating: scaling by a power of two is exact, so the two scales are
    /// one (up to flushing below TINY, which moves a value by less than 1e-29).
    PowersOfTwo(FirstScale),
}

/// What the first of two scalings multiplies `?x` by.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FirstScale {
    TimesP,
    OverP,
    TimesQ,
    OverQ,
}

/// Commutativity is left out on purpose: it would let extraction reorder
/// operands for nothing; each identity is listed for both operand orders.
///
/// A rewrite rule as data: name, left side, right side (egg's s-expression
/// patterns, operators spelled as in the operator table or by their infix
/// symbols), and when it applies. Each is exact under the semantics up to
/// [`WEIGHT_TOLERANCE`] (pow by exp2/log2 rounds) and keeps the domain flags;
/// `tests/simplify.rs` checks every one against the CPU evaluator.
pub const RULES: &[(&str, &str, &str, Condition)] = &[
    ("div-one", "(/ ?x 1)", "?x", Condition::Always),
    ("mul-one", "(* ?x 1)", "?x", Condition::Always),
    ("add-zero", "(+ ?x 0)", "?x", Condition::Always),
    ("sub-zero", "(- ?x 0)", "?x", Condition::Always),
    ("zero-sub", "(- 0 ?x)", "(neg ?x)", Condition::Always),
    ("pow-one", "(pow ?x 1)", "?x", Condition::Always),
    ("pow-neg-square", "(pow (neg ?x) 2)", "(pow ?x 2)", Condition::Always),
    ("one-mul", "(* 1 ?x)", "?x", Condition::Always),
    ("zero-add", "(+ 0 ?x)", "?x", Condition::Always),
    ("neg-neg", "(neg (neg ?x))", "?x", Condition::Always),
    ("abs-neg", "(abs (neg ?x))", "(abs ?x)", Condition::Always),
    ("abs-abs", "(abs (abs ?x))", "(abs ?x)", Condition::Always),
    ("sub-neg", "(- ?x (neg ?y))", "(+ ?x ?y)", Condition::Always),
    ("add-neg", "(+ ?x (neg ?y))", "(- ?x ?y)", Condition::Always),
    ("neg-add", "(+ (neg ?y) ?x)", "(- ?x ?y)", Condition::Always),
    ("mul-neg", "(* ?x (neg ?y))", "(neg (* ?x ?y))", Condition::Always),
    ("neg-mul", "(* (neg ?x) ?y)", "(neg (* ?x ?y))", Condition::Always),
    ("add-self", "(+ ?x ?x)", "(* 2 ?x)", Condition::Always),
    ("mul-zero", "(* ?x 0)", "0", Condition::XNeverFlags),
    ("zero-mul", "(* 0 ?x)", "0", Condition::XNeverFlags),
    ("zero-div", "(/ 0 ?x)", "0", Condition::XNeverFlags),
    ("pow-zero", "(pow ?x 0)", "1", Condition::XNeverFlags),
    ("sub-self", "(- ?x ?x)", "0", Condition::XNeverFlags),
    ("one-pow", "(pow 1 ?x)", "1", Condition::XNeverFlags),
    ("abs-nonneg", "(abs ?x)", "?x", Condition::XNonNegative),
    ("pow-half", "(pow ?x 0.5)", "(sqrt ?x)", Condition::XNonNegative),
    ("sqrt-half", "(sqrt ?x)", "(pow ?x 0.5)", Condition::XNonNegative),
    ("pow-pow", "(pow (pow ?x ?p) ?q)", "(pow ?x (* ?p ?q))", Condition::NestedPower),
    ("div-div-pow2", "(/ (/ ?x ?p) ?q)", "(/ ?x (* ?p ?q))", Condition::PowersOfTwo(FirstScale::OverP)),
    ("mul-mul-pow2", "(* ?p (* ?q ?x))", "(* (* ?p ?q) ?x)", Condition::PowersOfTwo(FirstScale::TimesQ)),
    ("mul-mul-pow2-right", "(* (* ?x ?p) ?q)", "(* ?x (* ?p ?q))", Condition::PowersOfTwo(FirstScale::TimesP)),
    ("div-mul-pow2", "(/ (* ?p ?x) ?q)", "(* (/ ?p ?q) ?x)", Condition::PowersOfTwo(FirstScale::TimesP)),
    ("div-mul-pow2-right", "(/ (* ?x ?p) ?q)", "(* ?x (/ ?p ?q))", Condition::PowersOfTwo(FirstScale::TimesP)),
    ("mul-div-pow2", "(* ?p (/ ?x ?q))", "(* (/ ?p ?q) ?x)", Condition::PowersOfTwo(FirstScale::OverQ)),
];

/// [`RULES`] as egg rewrites.
pub fn rules() -> Vec<Rewrite<Node, Semantics>> {
    let x: egg::Var = "?x".parse().expect("a pattern variable");
    RULES
        .iter()
        .map(|(name, lhs, rhs, condition)| {
            let lhs: egg::Pattern<Node> = lhs.parse().expect("a valid pattern");
            let rhs: egg::Pattern<Node> = rhs.parse().expect("a valid pattern");
            if *condition == Condition::Always {
                return Rewrite::new(*name, lhs, rhs).expect("a well-formed rule");
            }
            let condition = *condition;
            Rewrite::new(
                *name,
                lhs,
                egg::ConditionalApplier {
                    condition: move |egraph: &mut EGraph<Node, Semantics>, _: Id, subst: &egg::Subst| {
                        let facts = |var: egg::Var| egraph[subst[var]].data.clone();
                        let (p, q) = ("?p".parse().expect("a variable"), "?q".parse().expect("a variable"));
                        holds(condition, &facts(x), || (facts(p).constant, facts(q).constant))
                    },
                    applier: rhs,
                },
            )
            .expect("a well-formed rule")
        })
        .collect()
}

/// Whether a conditional rule may fire, from the facts of `?x` and the
/// constants of `?p` and `?q` (asked for only by the rule that needs them).
fn holds(condition: Condition, x: &Facts, exponents: impl FnOnce() -> (Option<f64>, Option<f64>)) -> bool {
    match condition {
        Condition::Always => true,
        Condition::XNeverFlags => !x.may_flag,
        Condition::XNonNegative => x.range.nonneg(),
        // Constant bases are folded already; merging their powers would only
        // make new constants without end.
        Condition::NestedPower => {
            x.range.nonneg() && x.constant.is_none() && matches!(exponents(), (Some(p), Some(q)) if p > 0.0 && q >= 1.0)
        }
        Condition::PowersOfTwo(first) => {
            let (Some(p), Some(q)) = exponents() else { return false };
            let power_of_two = |c: f64| c > 0.0 && c.log2().fract() == 0.0 && (-20.0..=20.0).contains(&c.log2());
            let factor = match first {
                FirstScale::TimesP => p,
                FirstScale::OverP => 1.0 / p,
                FirstScale::TimesQ => q,
                FirstScale::OverQ => 1.0 / q,
            };
            let largest = x.range.lo.abs().max(x.range.hi.abs());
            x.constant.is_none() && power_of_two(p) && power_of_two(q) && largest * factor <= semantics::BIG
        }
    }
}

/// One side of a rule with its pattern variables replaced (`?x` by `x`, `?y` by `y`).
pub fn instantiate(pattern: &str, x: &Expr, y: &Expr) -> Expr {
    instantiate_with(pattern, &[("?x", x), ("?y", y)])
}

/// One side of a rule with each named pattern variable replaced.
pub fn instantiate_with(pattern: &str, values: &[(&str, &Expr)]) -> Expr {
    let pattern: egg::Pattern<Node> = pattern.parse().expect("a valid pattern");
    let ast = &pattern.ast;
    fn build(ast: &RecExpr<egg::ENodeOrVar<Node>>, id: Id, values: &[(&str, &Expr)]) -> Expr {
        match &ast[id] {
            egg::ENodeOrVar::Var(v) => {
                let name = v.to_string();
                let (_, value) = values.iter().find(|(n, _)| *n == name).expect("every pattern variable has a value");
                (*value).clone()
            }
            egg::ENodeOrVar::ENode(node) => match node {
                Node::Const(bits) => Expr::Const(f64::from_bits(*bits)),
                Node::Var(v) => Expr::Var(*v),
                Node::Pair(op, a, b) => Expr::Pair(*op, *a, *b),
                Node::Unary(op, [a]) => Expr::unary(*op, build(ast, *a, values)),
                Node::Binary(op, [a, b]) => Expr::binary(*op, build(ast, *a, values), build(ast, *b, values)),
            },
        }
    }
    build(ast, Id::from(ast.as_ref().len() - 1), values)
}

/// What extraction minimises, node by node (egg's extractor sees one node
/// and its children's costs): the operator table's weights plus a tenth per
/// node (literals cost only that: they are folded into the code), counted in
/// tenths so that sums are exact and ties stay ties. A guide to the
/// cheapest form; whether the form found is kept is decided by
/// [`kernel_cost`], which prices the lowered kernel.
struct KernelCost<'a> {
    /// For the classes' facts: a literal exponent or divisor is what
    /// strength reduction turns into a product.
    egraph: &'a EGraph<Node, Semantics>,
}

impl CostFunction<Node> for KernelCost<'_> {
    type Cost = u64;

    fn cost<C: FnMut(Id) -> u64>(&mut self, node: &Node, mut costs: C) -> u64 {
        let constant = |id: &Id| self.egraph[*id].data.constant;
        let own = match node {
            Node::Const(_) => 0.0,
            Node::Var(_) => 1.0,
            Node::Pair(op, ..) => op.cost(),
            Node::Unary(op, _) => op.cost(),
            // As the lowering emits them (`jit::ir`): `pow(x, 2)` a product, `x / c` a product by 1/c.
            Node::Binary(BinaryOp::Pow, [_, e]) if constant(e) == Some(2.0) => BinaryOp::Mul.cost(),
            Node::Binary(BinaryOp::Div, [_, d]) if constant(d).is_some_and(|c| c != 0.0) => BinaryOp::Mul.cost(),
            Node::Binary(op, _) => op.cost(),
        };
        node.fold((own * 10.0).round() as u64 + 1, |sum, id| sum + costs(id))
    }
}

/// `expr` as an e-graph term.
fn to_rec(expr: &Expr, rec: &mut RecExpr<Node>) -> Id {
    let node = match expr {
        Expr::Const(c) => Node::constant(*c),
        Expr::Var(v) => Node::Var(*v),
        Expr::Pair(op, a, b) => Node::Pair(*op, *a, *b),
        Expr::Unary(op, a) => Node::Unary(*op, [to_rec(a, rec)]),
        Expr::Binary(op, a, b) => Node::Binary(*op, [to_rec(a, rec), to_rec(b, rec)]),
    };
    rec.add(node)
}

fn from_rec(rec: &RecExpr<Node>, id: Id) -> Expr {
    match &rec[id] {
        Node::Const(bits) => Expr::Const(f64::from_bits(*bits)),
        Node::Var(v) => Expr::Var(*v),
        Node::Pair(op, a, b) => Expr::Pair(*op, *a, *b),
        Node::Unary(op, [a]) => Expr::unary(*op, from_rec(rec, *a)),
        Node::Binary(op, [a, b]) => Expr::binary(*op, from_rec(rec, *a), from_rec(rec, *b)),
    }
}

/// Limits of one saturation run: node and iteration counts only, never
/// time, so that the result does not depend on how busy the machine is.
const NODE_LIMIT: usize = 20_000;
const ITERATION_LIMIT: usize = 30;

/// The cheapest expression equal to `expr` under the rules (never costlier than `expr`).
pub fn simplify(expr: &Expr) -> Expr {
    let mut rec = RecExpr::default();
    to_rec(expr, &mut rec);
    let runner = Runner::<Node, Semantics, ()>::default()
        .with_node_limit(NODE_LIMIT)
        .with_iter_limit(ITERATION_LIMIT)
        .with_time_limit(std::time::Duration::from_secs(3600))
        .with_expr(&rec)
        .run(&rules());
    let root = runner.roots[0];
    let (_, best) = Extractor::new(&runner.egraph, KernelCost { egraph: &runner.egraph }).find_best(root);
    let last = Id::from(best.as_ref().len() - 1);
    let simplified = from_rec(&best, last);
    // The lowered kernel's cost decides; where it ties (literal subtrees fold
    // away in both), the shorter form, for people; full ties keep the original,
    // so an already simple expression prints as written.
    let key = |e: &Expr| (kernel_cost(e), e.len());
    if key(&simplified) < key(expr) {
        simplified
    } else {
        expr.clone()
    }
}

/// Whether `condition` holds for `expr` as `?x` as the e-graph's analysis
/// sees it (the same test a conditional rule makes; exponents of
/// [`Condition::NestedPower`] are the caller's to choose).
pub fn condition_holds(condition: Condition, expr: &Expr) -> bool {
    holds(condition, &facts(expr), || (None, None))
}

/// Whether a rule under `condition` may fire with `x`, `p` and `q` as `?x`, `?p` and `?q`.
pub fn condition_holds_for(condition: Condition, x: &Expr, p: &Expr, q: &Expr) -> bool {
    let (p, q) = (facts(p).constant, facts(q).constant);
    holds(condition, &facts(x), || (p, q))
}

/// What the e-graph's analysis knows of `expr` alone, before any rewrite.
pub fn facts(expr: &Expr) -> Facts {
    let mut rec = RecExpr::default();
    to_rec(expr, &mut rec);
    let mut egraph = EGraph::<Node, Semantics>::default();
    let root = egraph.add_expr(&rec);
    egraph.rebuild();
    egraph[root].data.clone()
}

/// What the kernel for `expr` costs per pixel in a 3×3 window, in units of
/// one add, priced on the program that runs (`cost::ExprCost`, from the
/// lowered body): `simplify` keeps a form only where this is lower.
pub fn kernel_cost(expr: &Expr) -> f64 {
    crate::cost::model(expr, &crate::pipeline::FilterPipeline::WINDOW, 1)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lang::parse_expr;

    fn simplified(text: &str) -> String {
        simplify(&parse_expr(text).unwrap()).to_string()
    }

    #[test]
    fn literal_subtrees_fold_and_identities_vanish() {
        assert_eq!(simplified("pow(pow(3, 2), 1)"), "9");
        assert_eq!(simplified("distance2(normal) / 1 + (2 + 2) * 0"), "distance2(normal)");
        assert_eq!(simplified("exp(-distance2(normal) / (2 * pow(0.5, 2)))"), "exp(-distance2(normal) / 0.5)");
        assert_eq!(simplified("0 - exp(1)"), "-2.718282");
        assert_eq!(simplified("--distance1(color)"), "distance1(color)");
    }

    #[test]
    fn ranges_prove_what_no_flag_and_no_sign_can_hide() {
        // pow of a non-negative base never flags, so pow(1, ·) of it is 1.
        assert_eq!(simplified("pow(1, pow(distance2(color), 0.1))"), "1");
        assert_eq!(simplified("pow(2 * pow(1, distance2(normal) / 0), distance2(pixel))"), "pow(2, distance2(pixel))");
        // sqrt of a magnitude never flags either; exp is never negative.
        assert_eq!(simplified("sqrt(abs(dot(normal))) * 0 + distance1(color)"), "distance1(color)");
        assert_eq!(simplified("abs(exp(dot(normal)))"), "exp(dot(normal))");
        // A kernel past its support is 0.
        assert_eq!(simplified("epanechnikov(distance2(normal) + 1) * dot(color)"), "0");
    }

    #[test]
    fn scalings_by_powers_of_two_merge_where_the_first_cannot_saturate() {
        assert_eq!(simplified("distance2(color) / 2 / 0.5"), "distance2(color)");
        assert_eq!(simplified("0.5 * (0.5 * distance2(normal))"), "0.25 * distance2(normal)");
        assert_eq!(simplified("2 * (2 * exp(-distance2(normal)))"), "4 * exp(-distance2(normal))");
        assert_eq!(simplified("exp(-distance1(color)) * 4 / 8"), "exp(-distance1(color)) * 0.5");
        // Doubling first may saturate a distance; 3 is no power of two.
        assert_eq!(simplified("distance2(color) * 2 / 2"), "distance2(color) * 2 / 2");
        assert_eq!(simplified("2 * (2 * distance2(normal))"), "2 * (2 * distance2(normal))");
        assert_eq!(simplified("distance2(color) / 3 / 2"), "distance2(color) / 3 / 2");
    }

    #[test]
    fn what_the_semantics_forbid_is_left_alone() {
        // x / x is 0 at x = 0; sqrt of a negative flags, so its product with 0 stays.
        assert_eq!(simplified("distance2(normal) / distance2(normal)"), "distance2(normal) / distance2(normal)");
        assert_eq!(simplified("sqrt(dot(normal)) * 0"), "sqrt(dot(normal)) * 0");
        // Folding that would raise a flag is not done.
        assert_eq!(simplified("sqrt(0 - 1)"), "sqrt(-1)");
        // sqrt of a dot product may flag, so pow(1, ·) of it keeps it.
        assert_eq!(simplified("pow(1, sqrt(dot(normal)))"), "pow(1, sqrt(dot(normal)))");
    }
}
