//! A kernel body as data: a flat, hash-consed list of instructions, each on
//! the centre side (computed once per pixel) or the neighbour side (once per
//! neighbour), built from an [`Expr`] by [`Builder`] and printed as WGSL by
//! [`Body::print`].
//!
//! Opcodes are the operator table's (`UnaryOp`, `BinaryOp`, `PairOp`) plus
//! the cheaper forms strength reduction and check skipping lower some of them
//! to. The [`LowerOptions`] switches are rewrites the builder applies as it
//! adds an instruction, each on its own:
//! * constant folding: an operator on literals becomes a literal (unless it
//!   raises a domain flag, which must stay);
//! * common subexpressions: an instruction equal to an earlier one is that one
//!   (hash-consing; operands are already shared, so equal means the same
//!   computation);
//! * hoisting: an instruction that reads nothing of the neighbour goes to the
//!   centre side;
//! * strength reduction: `pow(x, 2)` is a product (`distance2` squared
//!   without its square root), `pow(x, n)` for a whole n up to 128 is
//!   multiplied out by squaring (no `log2` or `exp2`: the same value, and
//!   far cheaper where transcendentals are polynomials, as on a CPU device),
//!   `pow(x, 1)` is x, `x / c` a multiplication by 1/c;
//! * skipping checks: `-x` and `abs(x)` of an in-range value need no saturation,
//!   and where a value's range proves a part of `fin` idle (src/jit/range.rs)
//!   sums, products, quotients, `exp`, `sqrt` and `pow` leave that part out.

use std::collections::{BTreeSet, HashMap};

use super::helpers::Helper;
use super::kernel::LowerOptions;
use super::range::{Guard, Range, INTEGER_POWER_MAX};
use crate::lang::{BinaryOp, Expr, Feature, PairOp, ScalarVar, UnaryOp};
use crate::semantics;

/// What an instruction reads: a literal (the f32 the kernel holds), a
/// variance loaded at the centre, or an earlier instruction's value.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Operand {
    /// The bits of an f32.
    Literal(u32),
    Var(ScalarVar),
    Value(usize),
}

impl Operand {
    fn literal(value: f64) -> Operand {
        Operand::Literal((value as f32).to_bits())
    }

    fn literal_value(self) -> Option<f64> {
        match self {
            Operand::Literal(bits) => Some(f32::from_bits(bits) as f64),
            _ => None,
        }
    }

    /// Whether the value is in range by construction: every helper ends in
    /// `fj_fin` and literals are saturated and flushed; only variances are read raw.
    fn in_range(self) -> bool {
        !matches!(self, Operand::Var(_))
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Op {
    Unary(UnaryOp, Operand),
    Binary(BinaryOp, Operand, Operand),
    Pair(PairOp, Feature, Feature),
    /// `-x` of an in-range x: `0.0 - x` (a zero stays +0, as `fj_fin` leaves it).
    NegInRange(Operand),
    /// `abs(x)` of an in-range x.
    AbsInRange(Operand),
    /// `pow(x, 2)`: `x * x`, with the part of `fin` its range needs.
    Square(Operand, Guard),
    /// `pow(distance2(f_i, f_j), 2)`: the squared distance, no square root.
    Distance2Squared(Feature, Feature),
    /// `x / c` for a literal c: `x * (1/c)` (bits of the f32 1/c), with the
    /// part of `fin` its range needs.
    Scale(Operand, u32, Guard),
    /// `a + b`, `a - b`, `a * b` where the range proves a part of `fin` idle,
    /// or `a / b` where it proves the zero guard idle: the bare operation
    /// with the part of `fin` it needs.
    Arith(BinaryOp, Operand, Operand, Guard),
    /// `exp(x)` of a non-positive x (`fj_exp_nonpos`).
    ExpNonPositive(Operand),
    /// `sqrt(x)` of a non-negative x: no domain flag, no flush.
    SqrtNonNegative(Operand, Guard),
    /// `pow(a, b)` of a non-negative a: no domain flag, no sign (`fj_pow_nonneg`).
    PowNonNegative(Operand, Operand),
    /// `pow(a, n)` for a whole n in 3..=`INTEGER_POWER_MAX`: a held by
    /// its cap so no product passes BIG, then squarings and products, with
    /// the part of `fin` the range needs. A whole exponent never raises the
    /// domain flag, and the sign of an odd power of a negative base comes
    /// out of the products.
    IntegerPower(Operand, u32, PowerCap, Guard),
}

/// What holds the base of a multiplied-out power (the bits of an f32 cap,
/// the largest whose power is at most BIG) where its range needs it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum PowerCap {
    None,
    /// A non-negative base: `min(a, cap)`.
    Ceiling(u32),
    /// `clamp(a, -cap, cap)`.
    Clamp(u32),
}

impl PowerCap {
    fn of(range: Range, n: u32) -> PowerCap {
        match range.power_cap(n) {
            None => PowerCap::None,
            Some(c) if range.non_negative() => PowerCap::Ceiling(c.to_bits()),
            Some(c) => PowerCap::Clamp(c.to_bits()),
        }
    }

    fn value(self) -> Option<f32> {
        match self {
            PowerCap::None => None,
            PowerCap::Ceiling(c) | PowerCap::Clamp(c) => Some(f32::from_bits(c)),
        }
    }

    /// `base` held by the cap, in WGSL.
    fn apply(self, base: &str) -> String {
        match self {
            PowerCap::None => base.to_string(),
            PowerCap::Ceiling(c) => format!("min({base}, {:?})", f32::from_bits(c)),
            PowerCap::Clamp(c) => format!("clamp({base}, {:?}, {:?})", -f32::from_bits(c), f32::from_bits(c)),
        }
    }
}

impl Op {
    fn operands(&self) -> impl Iterator<Item = Operand> {
        let (a, b) = match *self {
            Op::Unary(_, a)
            | Op::NegInRange(a)
            | Op::AbsInRange(a)
            | Op::Square(a, _)
            | Op::Scale(a, ..)
            | Op::ExpNonPositive(a)
            | Op::SqrtNonNegative(a, _)
            | Op::IntegerPower(a, ..) => (Some(a), None),
            Op::Binary(_, a, b) | Op::Arith(_, a, b, _) | Op::PowNonNegative(a, b) => (Some(a), Some(b)),
            Op::Pair(..) | Op::Distance2Squared(..) => (None, None),
        };
        a.into_iter().chain(b)
    }

    /// The `templates/ops.wgsl` helper the instruction calls, if any.
    fn helper(&self) -> Option<String> {
        match self {
            Op::Unary(op, _) => Some(op.helper()),
            Op::Binary(op, ..) => Some(op.helper()),
            Op::Pair(op, ..) => Some(op.helper()),
            Op::NegInRange(_) | Op::AbsInRange(_) => None,
            Op::Square(_, Guard::Fin) => Some(BinaryOp::Mul.helper()),
            Op::Distance2Squared(..) => Some("fj_distance2sq".into()),
            Op::Square(_, guard)
            | Op::Scale(_, _, guard)
            | Op::Arith(.., guard)
            | Op::SqrtNonNegative(_, guard)
            | Op::IntegerPower(.., guard) => guard.helper().map(String::from),
            Op::ExpNonPositive(_) => Some("fj_exp_nonpos".into()),
            Op::PowNonNegative(..) => Some("fj_pow_nonneg".into()),
        }
    }
}

/// Where an instruction runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Side {
    /// Once per pixel, before the neighbour loop.
    Centre,
    /// For every neighbour.
    Neighbour,
}

#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Inst {
    pub op: Op,
    pub side: Side,
}

/// One expression's body: its instructions, in order, and its value.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Body {
    pub insts: Vec<Inst>,
    pub result: Operand,
}

impl Body {
    /// Lower `expr` with `options`.
    pub fn of(expr: &Expr, options: LowerOptions) -> Body {
        let mut builder = Builder::new(options);
        let result = builder.build(expr);
        Body { insts: builder.insts, result }
    }

    /// How many distinct variances the body loads at the centre.
    pub fn centre_loads(&self) -> usize {
        let mut vars: Vec<ScalarVar> = self
            .insts
            .iter()
            .flat_map(|i| i.op.operands())
            .chain(std::iter::once(self.result))
            .filter_map(|o| match o {
                Operand::Var(v) => Some(v),
                _ => None,
            })
            .collect();
        vars.sort();
        vars.dedup();
        vars.len()
    }

    /// The helpers the instructions call (their dependencies aside).
    pub fn helpers(&self) -> BTreeSet<String> {
        self.insts.iter().filter_map(|i| i.op.helper()).collect()
    }

    /// The body as WGSL: `let` lines for the centre side and the neighbour
    /// side, names `prefix` + instruction index, and the result's spelling.
    pub fn print(&self, prefix: &str) -> (Vec<String>, Vec<String>, String) {
        let operand = |o: Operand| match o {
            Operand::Literal(bits) => format!("{:?}", f32::from_bits(bits)),
            Operand::Var(v) => var_ident(v),
            Operand::Value(k) => format!("{prefix}{k}"),
        };
        let (mut centre, mut neighbour) = (Vec::new(), Vec::new());
        for (k, inst) in self.insts.iter().enumerate() {
            let lines = match inst.side {
                Side::Centre => &mut centre,
                Side::Neighbour => &mut neighbour,
            };
            let value = match inst.op {
                Op::Unary(op, a) => format!("{}({})", op.helper(), operand(a)),
                Op::Binary(op, a, b) => format!("{}({}, {})", op.helper(), operand(a), operand(b)),
                Op::Pair(op, i, j) => format!("{}({}, {})", op.helper(), feature_ident('i', i), feature_ident('j', j)),
                Op::NegInRange(a) => format!("(0.0 - {})", operand(a)),
                Op::AbsInRange(a) => format!("abs({})", operand(a)),
                Op::Square(a, Guard::Fin) => format!("fj_mul({0}, {0})", operand(a)),
                Op::Square(a, guard) => guard.apply(&format!("{0} * {0}", operand(a))),
                Op::Distance2Squared(i, j) => {
                    format!("fj_distance2sq({}, {})", feature_ident('i', i), feature_ident('j', j))
                }
                Op::Scale(a, r, guard) => guard.apply(&format!("{} * {:?}", operand(a), f32::from_bits(r))),
                Op::Arith(op, a, b, guard) => {
                    let symbol = match op {
                        BinaryOp::Add => "+",
                        BinaryOp::Sub => "-",
                        BinaryOp::Mul => "*",
                        BinaryOp::Div => "/",
                        BinaryOp::Pow => unreachable!("a power is never bare"),
                    };
                    guard.apply(&format!("{} {symbol} {}", operand(a), operand(b)))
                }
                Op::ExpNonPositive(a) => format!("fj_exp_nonpos({})", operand(a)),
                Op::SqrtNonNegative(a, guard) => guard.apply(&format!("sqrt({})", operand(a))),
                Op::PowNonNegative(a, b) => format!("fj_pow_nonneg({}, {})", operand(a), operand(b)),
                Op::IntegerPower(a, n, cap, guard) => {
                    let factors = multiply_out(&format!("{prefix}{k}"), &operand(a), n, cap, lines);
                    guard.apply(&factors)
                }
            };
            lines.push(format!("let {prefix}{k} = {value};"));
        }
        (centre, neighbour, operand(self.result))
    }
}

/// `base`^n by squaring: pushes `let` lines for the base held by `cap` and its squares, named `name` + `_p` + the power, and
/// returns the product of the powers whose bits n holds.
fn multiply_out(name: &str, base: &str, n: u32, cap: PowerCap, lines: &mut Vec<String>) -> String {
    lines.push(format!("let {name}_p1 = {};", cap.apply(base)));
    let mut factors = Vec::new();
    let mut power = 1;
    while power <= n {
        if power > 1 {
            let half = power / 2;
            lines.push(format!("let {name}_p{power} = {name}_p{half} * {name}_p{half};"));
        }
        if n & power != 0 {
            factors.push(format!("{name}_p{power}"));
        }
        power *= 2;
    }
    factors.join(" * ")
}

/// The WGSL name of feature `f` loaded at the centre (`side` = 'i') or the neighbour ('j').
pub fn feature_ident(side: char, f: Feature) -> String {
    format!("feat_{side}_{}", f.name().to_ascii_lowercase())
}

/// The WGSL name of variance `v` loaded at the centre.
pub fn var_ident(v: ScalarVar) -> String {
    format!("var_{}", v.name().to_ascii_lowercase())
}

/// `b` as an exponent `pow` multiplies out: a whole number from 3 to `INTEGER_POWER_MAX`.
fn whole_exponent(b: f64) -> Option<u32> {
    (b == b.round() && (3.0..=INTEGER_POWER_MAX as f64).contains(&b)).then_some(b as u32)
}

/// The f32 value of a literal or of the negation of one, as the kernel holds it.
fn literal_syntax(e: &Expr) -> Option<f64> {
    match e {
        Expr::Const(c) => Some(semantics::literal(*c) as f32 as f64),
        Expr::Unary(UnaryOp::Neg, a) => match **a {
            Expr::Const(c) => Some(-(semantics::literal(c) as f32 as f64)),
            _ => None,
        },
        _ => None,
    }
}

/// Adds instructions, applying the rewrites `options` switch on.
struct Builder {
    options: LowerOptions,
    insts: Vec<Inst>,
    /// What each instruction's value can be.
    ranges: Vec<Range>,
    /// Each instruction's index, for hash-consing.
    known: HashMap<Op, usize>,
}

impl Builder {
    fn new(options: LowerOptions) -> Builder {
        Builder { options, insts: Vec::new(), ranges: Vec::new(), known: HashMap::new() }
    }

    fn build(&mut self, e: &Expr) -> Operand {
        match e {
            Expr::Const(c) => Operand::literal(semantics::literal(*c)),
            Expr::Var(v) => Operand::Var(*v),
            Expr::Pair(op, i, j) => self.add(Op::Pair(*op, *i, *j)),
            Expr::Unary(op, a) => {
                let a = self.build(a);
                if let Some(value) = self.fold(|flags| Some(op.eval(a.literal_value()?, flags))) {
                    return value;
                }
                let ranged = self.options.skip_redundant_checks;
                let skip = ranged && a.in_range();
                let range = self.range(a);
                self.add(match op {
                    UnaryOp::Neg if skip => Op::NegInRange(a),
                    UnaryOp::Abs if skip => Op::AbsInRange(a),
                    UnaryOp::Exp if ranged && range.non_positive() => Op::ExpNonPositive(a),
                    UnaryOp::Sqrt if ranged && range.non_negative() && a.literal_value().is_none() => {
                        Op::SqrtNonNegative(a, range.sqrt_non_negative().0)
                    }
                    _ => Op::Unary(*op, a),
                })
            }
            Expr::Binary(op, a_expr, b_expr) => {
                let strength = self.options.strength_reduction;
                // `pow(distance2(f), 2)` needs no square root, nor the distance itself.
                if let (true, BinaryOp::Pow, Expr::Pair(PairOp::Distance2, i, j)) = (strength, op, &**a_expr) {
                    if self.literal_of(b_expr) == Some(2.0) {
                        return self.add(Op::Distance2Squared(*i, *j));
                    }
                }
                let a = self.build(a_expr);
                // Without folding, `-c` would become an instruction: a divisor is read off the syntax.
                let (b, syntactic) = match (self.options.fold_constants, literal_syntax(b_expr)) {
                    (false, Some(c)) if strength && *op == BinaryOp::Div => (None, Some(c)),
                    _ => (Some(self.build(b_expr)), None),
                };
                let divisor = syntactic.or_else(|| b.and_then(Operand::literal_value)).filter(|_| *op == BinaryOp::Div);
                if let Some(d) = divisor.filter(|d| strength && d.abs() >= semantics::DIV_EPS) {
                    if let Some(value) = self.fold(|flags| Some(op.eval(a.literal_value()?, d, flags))) {
                        return value;
                    }
                    // The zero guard only changes divisors below FJ_DIV_EPS.
                    let reciprocal = (1.0 / d) as f32;
                    let guard = self.guard(a, Range::product(self.range(a), Range::literal(reciprocal as f64)));
                    return self.add(Op::Scale(a, reciprocal.to_bits(), guard));
                }
                let b = match b {
                    Some(b) => b,
                    None => self.build(b_expr),
                };
                if let Some(value) = self.fold(|flags| Some(op.eval(a.literal_value()?, b.literal_value()?, flags))) {
                    return value;
                }
                if strength && *op == BinaryOp::Pow && b.literal_value() == Some(2.0) {
                    let magnitude = self.range(a).magnitude();
                    return self.add(Op::Square(a, self.guard(a, Range::product(magnitude, magnitude))));
                }
                // Every operand is already saturated (0 or at least FJ_TINY in
                // size, at most FJ_BIG), and there `pow(x, 1)` is x up to the
                // rounding of exp2(log2 x); an integral power never flags.
                if strength && *op == BinaryOp::Pow && b.literal_value() == Some(1.0) {
                    return a;
                }
                let whole = b.literal_value().and_then(whole_exponent);
                if let (true, BinaryOp::Pow, Some(n)) = (strength, op, whole) {
                    let cap = PowerCap::of(self.range(a), n);
                    let guard = self.guard(a, self.range(a).integer_power(n, cap.value()));
                    return self.add(Op::IntegerPower(a, n, cap, guard));
                }
                if self.options.skip_redundant_checks {
                    if let Some(op) = self.bare(*op, a, b) {
                        return self.add(op);
                    }
                }
                self.add(Op::Binary(*op, a, b))
            }
        }
    }

    /// What `operand` can be.
    fn range(&self, operand: Operand) -> Range {
        match operand {
            Operand::Literal(bits) => Range::literal(f32::from_bits(bits) as f64),
            Operand::Var(ScalarVar::Level) => Range::LEVEL,
            Operand::Var(_) => Range::ANY,
            Operand::Value(k) => self.ranges[k],
        }
    }

    /// The part of `fin` a value in `range` computed from `operand` needs
    /// (all of it with checks not skipped, or for a literal operand, which
    /// WGSL would multiply as an abstract float: `bare`).
    fn guard(&self, operand: Operand, range: Range) -> Guard {
        if self.options.skip_redundant_checks && operand.literal_value().is_none() {
            range.guard().0
        } else {
            Guard::Fin
        }
    }

    /// `a op b` as a bare operation where the operands' ranges prove part of
    /// its guards idle: a part of `fin`, or (for a quotient) the zero guard.
    fn bare(&self, op: BinaryOp, a: Operand, b: Operand) -> Option<Op> {
        // WGSL evaluates an operation on two literals as abstract floats, not
        // in f32: such an operation (unfolded) keeps its helper, whose
        // arguments are f32.
        if a.literal_value().is_some() && b.literal_value().is_some() {
            return None;
        }
        let ra = self.range(a);
        if op == BinaryOp::Pow {
            return ra.non_negative().then_some(Op::PowNonNegative(a, b));
        }
        let guard = self.arithmetic(op, a, b)?.guard().0;
        // A bare quotient drops its zero guard, worth it even with all of `fin`.
        (guard != Guard::Fin || op == BinaryOp::Div).then_some(Op::Arith(op, a, b, guard))
    }

    /// `a op b` as the bare operation computes it, before `fin`
    /// (`Range::arithmetic`), knowing that `x + abs(x)` is never negative:
    /// it is 2x or exactly 0 (the `max(0, x)` twice a weight spells so).
    fn arithmetic(&self, op: BinaryOp, a: Operand, b: Operand) -> Option<Range> {
        let range = Range::arithmetic(op, self.range(a), self.range(b))?;
        // Only for an in-range x, whose `abs` is exact: a raw variance's saturates at BIG.
        let abs_of = |v: Operand, x: Operand| match v {
            Operand::Value(k) => {
                x.in_range() && matches!(self.insts[k].op, Op::AbsInRange(y) | Op::Unary(UnaryOp::Abs, y) if y == x)
            }
            _ => false,
        };
        let one_sided = op == BinaryOp::Add && (abs_of(b, a) || abs_of(a, b));
        Some(if one_sided { range.at_least_zero() } else { range })
    }

    /// What the value of `op` (with its operands' ranges known) can be.
    fn range_of(&self, op: &Op) -> Range {
        let after = |range: Range| range.guard().1;
        match *op {
            Op::Unary(op, a) => Range::unary(op, self.range(a)),
            Op::Binary(op, a, b) => match self.arithmetic(op, a, b) {
                Some(range) => range.guard().1,
                None => Range::binary(op, self.range(a), self.range(b)),
            },
            Op::Pair(op, ..) => Range::pair(op),
            Op::NegInRange(a) => self.range(a).negated(),
            Op::AbsInRange(a) => self.range(a).magnitude(),
            Op::Square(a, _) => {
                let magnitude = self.range(a).magnitude();
                after(Range::product(magnitude, magnitude))
            }
            Op::Distance2Squared(..) => Range::pair(PairOp::Distance2),
            Op::Scale(a, r, _) => after(Range::product(self.range(a), Range::literal(f32::from_bits(r) as f64))),
            Op::Arith(op, a, b, _) => after(self.arithmetic(op, a, b).expect("a bare operation's range is known")),
            Op::ExpNonPositive(a) => Range::unary(UnaryOp::Exp, self.range(a)),
            Op::SqrtNonNegative(a, _) => self.range(a).sqrt_non_negative().1,
            Op::PowNonNegative(a, b) => Range::binary(BinaryOp::Pow, self.range(a), self.range(b)),
            Op::IntegerPower(a, n, cap, _) => after(self.range(a).integer_power(n, cap.value())),
        }
    }

    /// The literal `compute` gives when folding is on, the operands are
    /// literals and no domain flag is raised (a flag must stay in the kernel).
    fn fold(&self, compute: impl FnOnce(&mut u32) -> Option<f64>) -> Option<Operand> {
        if !self.options.fold_constants {
            return None;
        }
        let mut flags = 0;
        let value = compute(&mut flags)?;
        (flags == 0).then(|| Operand::literal(semantics::fin(value)))
    }

    /// The f32 value of `e` if it is a literal or the negation of one, or
    /// (folding on) folds to a literal; no instruction is added. Only
    /// `pow(distance2(f), 2)` needs to know before its operands are built.
    fn literal_of(&self, e: &Expr) -> Option<f64> {
        if let Some(c) = literal_syntax(e) {
            return Some(c);
        }
        if !self.options.fold_constants {
            return None;
        }
        let mut probe = Builder::new(self.options);
        match probe.build(e) {
            Operand::Literal(bits) if probe.insts.is_empty() => Some(f32::from_bits(bits) as f64),
            _ => None,
        }
    }

    /// Add `op` (or find it, with common subexpressions on), on the centre
    /// side when hoisting is on and it reads nothing of the neighbour.
    fn add(&mut self, op: Op) -> Operand {
        if self.options.common_subexpressions {
            if let Some(&k) = self.known.get(&op) {
                return Operand::Value(k);
            }
        }
        let reads_neighbour = matches!(op, Op::Pair(..) | Op::Distance2Squared(..))
            || op.operands().any(|o| matches!(o, Operand::Value(k) if self.insts[k].side == Side::Neighbour));
        let side = if self.options.hoist_centre_terms && !reads_neighbour { Side::Centre } else { Side::Neighbour };
        self.ranges.push(self.range_of(&op));
        self.insts.push(Inst { op, side });
        let k = self.insts.len() - 1;
        if self.options.common_subexpressions {
            self.known.insert(op, k);
        }
        Operand::Value(k)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lang::parse_expr;

    fn body(text: &str, options: LowerOptions) -> Body {
        Body::of(&parse_expr(text).unwrap(), options)
    }

    #[test]
    fn equal_subexpressions_are_one_instruction_and_centre_terms_are_hoisted() {
        let b = body("exp(-distance2(normal)) * exp(-distance2(normal)) + sqrt(colorVariance)", LowerOptions::ALL);
        let pairs = b.insts.iter().filter(|i| matches!(i.op, Op::Pair(..))).count();
        assert_eq!(pairs, 1, "{b:?}");
        let sqrt = b.insts.iter().find(|i| matches!(i.op, Op::Unary(UnaryOp::Sqrt, _))).unwrap();
        assert_eq!(sqrt.side, Side::Centre, "sqrt(colorVariance) reads nothing of the neighbour");
        let plain = LowerOptions { common_subexpressions: false, hoist_centre_terms: false, ..LowerOptions::ALL };
        let b = body("exp(-distance2(normal)) * exp(-distance2(normal)) + sqrt(colorVariance)", plain);
        assert_eq!(b.insts.iter().filter(|i| matches!(i.op, Op::Pair(..))).count(), 2);
        assert!(b.insts.iter().all(|i| i.side == Side::Neighbour));
    }

    #[test]
    fn constants_fold_unless_they_raise_a_flag_and_strength_is_reduced() {
        let b = body("distance2(color) * (2 + 3)", LowerOptions::ALL);
        // A distance times 5 is never tiny but may pass BIG: only the ceiling is left.
        assert_eq!(
            b.insts.last().unwrap().op,
            Op::Arith(BinaryOp::Mul, Operand::Value(0), Operand::literal(5.0), Guard::Ceiling)
        );
        // sqrt of a negative value raises a domain flag at run time: it stays an instruction.
        let b = body("sqrt(0 - 1)", LowerOptions::ALL);
        assert!(matches!(b.insts[0].op, Op::Unary(UnaryOp::Sqrt, Operand::Literal(_))), "{b:?}");
        let b = body("pow(distance2(normal), 2) + distance1(color) / 4", LowerOptions::ALL);
        assert_eq!(b.insts[0].op, Op::Distance2Squared(Feature::Normal, Feature::Normal));
        assert!(
            b.insts.iter().any(|i| i.op == Op::Scale(Operand::Value(1), 0.25f32.to_bits(), Guard::FlushNonNegative)),
            "{b:?}"
        );
        let (_, neighbour, result) = b.print("_e");
        assert_eq!(neighbour[0], "let _e0 = fj_distance2sq(feat_i_normal, feat_j_normal);");
        assert_eq!(result, "_e3");
        // The sum of two non-negative terms never tiny needs only `min`: no `fj_add`.
        assert_eq!(b.helpers(), ["fj_distance1", "fj_distance2sq", "fj_flush_pos"].map(String::from).into());
    }

    #[test]
    fn the_pass_level_is_a_small_whole_number() {
        // A first pass picked out by `exp(-20 * level)` keeps the weight's colour scale positive,
        // so the weight's exponent is provably non-positive and takes the guard-free exp.
        let b = body(
            "exp(-(distance1(color) / ((4 - exp(-20 * level)) * sqrt(colorVariance) + 0.001)))",
            LowerOptions::ALL,
        );
        assert!(b.insts.iter().any(|i| matches!(i.op, Op::ExpNonPositive(..))), "{b:?}");
        let b = body(
            "exp(-(distance1(color) / ((4 - exp(-20 * texVariance)) * sqrt(colorVariance) + 0.001)))",
            LowerOptions::ALL,
        );
        assert!(
            b.insts.iter().all(|i| !matches!(i.op, Op::ExpNonPositive(..))),
            "a raw variance can be anything: {b:?}"
        );
    }

    #[test]
    fn a_first_power_is_its_base() {
        let b = body("pow(distance2(normal), 1) * distance1(color)", LowerOptions::ALL);
        assert!(b.insts.iter().all(|i| !matches!(i.op, Op::Binary(BinaryOp::Pow, ..))), "{b:?}");
        assert_eq!(b.insts.len(), 3, "{b:?}");
        let plain = LowerOptions { strength_reduction: false, ..LowerOptions::ALL };
        let b = body("pow(distance2(normal), 1) * distance1(color)", plain);
        // Without strength reduction the power stays (of a distance: the sign-free helper).
        assert!(b.insts.iter().any(|i| matches!(i.op, Op::PowNonNegative(..))), "{b:?}");
    }

    #[test]
    fn whole_powers_are_multiplied_out_and_their_bases_held_only_where_a_product_could_pass_big() {
        // A distance may exceed BIG^(1/128) = 1.31: its base is held by `min`;
        // the seven squarings follow and the result keeps both parts of `fin`.
        let b = body("pow(distance2(color), 128)", LowerOptions::ALL);
        let cap = 1.3097472f32.to_bits();
        assert_eq!(
            b.insts[1].op,
            Op::IntegerPower(Operand::Value(0), 128, PowerCap::Ceiling(cap), Guard::FinNonNegative)
        );
        let (_, neighbour, result) = b.print("_e");
        assert_eq!(neighbour[1], "let _e1_p1 = min(_e0, 1.3097472);");
        assert_eq!(neighbour[8], "let _e1_p128 = _e1_p64 * _e1_p64;");
        assert_eq!(neighbour[9], "let _e1 = fj_fin_pos(_e1_p128);");
        assert_eq!(result, "_e1");
        assert!(!b.helpers().iter().any(|h| h.starts_with("fj_pow")), "{:?}", b.helpers());
        // An odd power of a signed value: clamped both ways, the powers of n's bits multiplied.
        let b = body("pow(dot(normal), 5)", LowerOptions::ALL);
        let (_, neighbour, _) = b.print("_e");
        assert_eq!(neighbour[1], "let _e1_p1 = clamp(_e0, -999.99994, 999.99994);");
        assert_eq!(neighbour.last().unwrap(), "let _e1 = fj_fin(_e1_p1 * _e1_p4);");
        // A base in [0, 1] needs no hold, and its power only the flush.
        let b = body("pow(exp(-distance2(color)), 64)", LowerOptions::ALL);
        assert!(matches!(b.insts.last().unwrap().op, Op::IntegerPower(_, 64, PowerCap::None, Guard::FlushNonNegative)));
        // Exponents outside 3..=128 or not whole keep the helper.
        for text in ["pow(dot(normal), 129)", "pow(dot(normal), 2.5)", "pow(dot(normal), -3)"] {
            let b = body(text, LowerOptions::ALL);
            assert!(matches!(b.insts.last().unwrap().op, Op::Binary(BinaryOp::Pow, ..)), "{text}: {b:?}");
        }
        let plain = LowerOptions { strength_reduction: false, ..LowerOptions::ALL };
        assert!(!body("pow(dot(normal), 5)", plain).insts.iter().any(|i| matches!(i.op, Op::IntegerPower(..))));
    }

    #[test]
    fn a_value_plus_its_magnitude_is_known_never_negative() {
        // SVGF's max(0, n_i · n_j), spelled with what the grammar has.
        let b = body("(dot(normal) + abs(dot(normal))) / 2", LowerOptions::ALL);
        let (_, neighbour, _) = b.print("_e");
        assert_eq!(neighbour[2], "let _e2 = fj_fin_pos(_e0 + _e1);");
        assert_eq!(neighbour[3], "let _e3 = fj_flush_pos(_e2 * 0.5);");
        // Not for a raw variance (its `abs` saturates), a difference, nor another value's magnitude.
        let b = body("colorVariance + abs(colorVariance)", LowerOptions::ALL);
        assert!(b.helpers().contains("fj_add"), "{:?}", b.helpers());
        let b = body("dot(normal) - abs(dot(normal)) + (dot(color) + abs(dot(normal)))", LowerOptions::ALL);
        assert!(b.helpers().contains("fj_add") && b.helpers().contains("fj_sub"), "{:?}", b.helpers());
    }
}
