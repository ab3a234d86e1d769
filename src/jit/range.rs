//! What a kernel value can be, as far as the lowering can tell from its
//! operands, and which parts of `fin` (docs/SEMANTICS.md: flush magnitudes
//! below TINY to 0, clamp to ±BIG) that proves idle.
//!
//! Every operator's result passes through `fin` so that the f64 and the f32
//! twins agree and no value leaves [−BIG, BIG]. On lavapipe that guard is a
//! third of an evolved weight's arithmetic (docs/JOURNAL.md, "Guards a
//! value's range proves idle"). Where an operand's range shows that the
//! clamp or the flush cannot change the value, the kernel leaves that part
//! out and computes the same f32 (a zero's sign aside, which no operator
//! tells apart: docs/SEMANTICS.md).
//!
//! Bounds are widened by a relative margin after every step, so that the
//! rounding of f32 arithmetic (half an ulp, 6e-8) never carries a value
//! past a bound this module proved.

use crate::lang::{BinaryOp, PairOp, UnaryOp};
use crate::semantics;

/// The f32 the kernels clamp to and flush below (`FJ_BIG`, `FJ_TINY`).
const BIG: f64 = semantics::BIG as f32 as f64;
const TINY: f64 = semantics::TINY as f32 as f64;
const DIV_EPS: f64 = semantics::DIV_EPS as f32 as f64;
/// Far more than f32 rounding moves a value, far less than any bound tested.
const MARGIN: f64 = 1e-5;
/// The largest whole exponent `pow` is multiplied out for: a power of two
/// (SVGF's normal weight), and no more products than `fj_pow`'s work.
pub const INTEGER_POWER_MAX: u32 = 128;

/// A value lies in `[lo, hi]` and is either zero or at least `floor` in
/// magnitude (`floor` is infinite for a value that is always zero).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Range {
    pub lo: f64,
    pub hi: f64,
    pub floor: f64,
}

/// The part of `fin` a computed value still needs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Guard {
    /// Neither the clamp nor the flush can change it.
    None,
    /// Non-negative and never tiny: `min(x, BIG)`.
    Ceiling,
    /// Never tiny: the clamp to ±BIG.
    Clamp,
    /// Non-negative and at most BIG: the flush (`fj_flush_pos`).
    FlushNonNegative,
    /// At most BIG in magnitude: the flush (`fj_flush`).
    Flush,
    /// Non-negative: both parts (`fj_fin_pos`).
    FinNonNegative,
    /// Both parts (`fj_fin`).
    Fin,
}

impl Range {
    /// Anything an f32 can hold (a variance read raw).
    pub const ANY: Range = Range { lo: f64::NEG_INFINITY, hi: f64::INFINITY, floor: 0.0 };
    /// Any result of `fin`.
    const FINITE: Range = Range { lo: -BIG, hi: BIG, floor: TINY };

    /// The à-trous pass `level`: a whole number, 0 up to the last pass the
    /// longest pipeline runs (0 in the window form and in fitness kernels).
    pub const LEVEL: Range = Range { lo: 0.0, hi: (crate::pipeline::MAX_ATROUS_PASSES - 1) as f64, floor: 1.0 };

    /// A literal's f32 value.
    pub fn literal(value: f64) -> Range {
        Range { lo: value, hi: value, floor: if value == 0.0 { f64::INFINITY } else { value.abs() } }
    }

    fn new(lo: f64, hi: f64, floor: f64) -> Range {
        if lo.is_nan() || hi.is_nan() {
            return Range::ANY;
        }
        let floor = if floor.is_nan() { 0.0 } else { floor };
        let widen = |x: f64, up: bool| if up { x + x.abs() * MARGIN } else { x - x.abs() * MARGIN };
        Range { lo: widen(lo, false), hi: widen(hi, true), floor }
    }

    pub fn non_negative(self) -> bool {
        self.lo >= 0.0
    }

    /// Whether every value is at most BIG in magnitude: the clamp is idle.
    fn within_big(self) -> bool {
        self.lo >= -BIG && self.hi <= BIG
    }

    /// Whether no value is tiny but zero: the flush is idle.
    fn never_tiny(self) -> bool {
        self.floor >= TINY
    }

    /// What `fin` leaves of a value in this range.
    fn finned(self) -> Range {
        let (lo, hi) = (self.lo.clamp(-BIG, BIG), self.hi.clamp(-BIG, BIG));
        Range { lo, hi, floor: self.floor.max(TINY) }
    }

    /// The part of `fin` a value in this range needs, and the range after it.
    pub fn guard(self) -> (Guard, Range) {
        let guard = match (self.within_big(), self.never_tiny(), self.non_negative()) {
            (true, true, _) => Guard::None,
            (false, true, true) => Guard::Ceiling,
            (false, true, false) => Guard::Clamp,
            (true, false, true) => Guard::FlushNonNegative,
            (true, false, false) => Guard::Flush,
            (false, false, true) => Guard::FinNonNegative,
            (false, false, false) => Guard::Fin,
        };
        (guard, self.finned())
    }

    pub fn negated(self) -> Range {
        Range { lo: -self.hi, hi: -self.lo, floor: self.floor }
    }

    pub fn magnitude(self) -> Range {
        let top = self.lo.abs().max(self.hi.abs());
        let bottom = if self.lo > 0.0 || self.hi < 0.0 { self.lo.abs().min(self.hi.abs()) } else { 0.0 };
        Range { lo: bottom, hi: top, floor: self.floor }
    }

    /// `a + b` before `fin`.
    pub fn sum(a: Range, b: Range) -> Range {
        let same_sign = (a.lo >= 0.0 && b.lo >= 0.0) || (a.hi <= 0.0 && b.hi <= 0.0);
        // Operands of one sign: the sum is at least the larger in magnitude,
        // and f32 rounding keeps that (the larger operand is representable).
        let floor = if same_sign {
            let (ma, mb) = (a.magnitude(), b.magnitude());
            a.floor.min(b.floor).max(ma.lo).max(mb.lo)
        } else {
            0.0
        };
        Range::new(a.lo + b.lo, a.hi + b.hi, floor)
    }

    /// `a · b` before `fin`.
    pub fn product(a: Range, b: Range) -> Range {
        let Some((lo, hi)) = span([a.lo * b.lo, a.lo * b.hi, a.hi * b.lo, a.hi * b.hi]) else {
            return Range::ANY;
        };
        // Rounding may take a product half an ulp below the exact one.
        Range::new(lo, hi, a.floor * b.floor * (1.0 - MARGIN))
    }

    /// `a / b` before `fin`, where no divisor is within DIV_EPS of zero (the
    /// zero guard idle); `None` where one may be.
    pub fn quotient(a: Range, b: Range) -> Option<Range> {
        if b.lo < DIV_EPS && b.hi > -DIV_EPS {
            return None;
        }
        let Some((lo, hi)) = span([a.lo / b.lo, a.lo / b.hi, a.hi / b.lo, a.hi / b.hi]) else {
            return Some(Range::ANY);
        };
        Some(Range::new(lo, hi, a.floor / b.magnitude().hi * (1.0 - MARGIN)))
    }

    /// `a op b` as the bare operation computes it, before `fin`: a sum,
    /// difference or product, or a quotient whose zero guard is idle; `None`
    /// for a power and a quotient that needs its guard.
    pub fn arithmetic(op: BinaryOp, a: Range, b: Range) -> Option<Range> {
        match op {
            BinaryOp::Add => Some(Range::sum(a, b)),
            BinaryOp::Sub => Some(Range::sum(a, b.negated())),
            BinaryOp::Mul => Some(Range::product(a, b)),
            BinaryOp::Div => Range::quotient(a, b),
            BinaryOp::Pow => None,
        }
    }

    /// The range of an operator's helper result (which ends in `fin`).
    pub fn binary(op: BinaryOp, a: Range, b: Range) -> Range {
        match op {
            BinaryOp::Pow if a.non_negative() => Range { lo: 0.0, ..Range::FINITE },
            _ => Range::arithmetic(op, a, b).unwrap_or(Range::FINITE).finned(),
        }
    }

    /// The range of a unary operator's helper result (which ends in `fin`).
    pub fn unary(op: UnaryOp, a: Range) -> Range {
        let unit = Range { lo: 0.0, hi: 1.0, floor: TINY };
        match op {
            UnaryOp::Neg => a.negated().finned(),
            UnaryOp::Abs => a.magnitude().finned(),
            UnaryOp::Exp => Range { lo: 0.0, hi: a.hi.min(semantics::EXP_MAX).exp(), floor: TINY }.finned(),
            UnaryOp::Sqrt => Range { lo: 0.0, hi: a.magnitude().hi.sqrt(), floor: TINY }.finned(),
            UnaryOp::Sin | UnaryOp::Cos => Range { lo: -1.0, hi: 1.0, floor: TINY },
            UnaryOp::Epanechnikov | UnaryOp::Biweight | UnaryOp::Tricube => unit,
            _ => Range::FINITE,
        }
    }

    /// The range of a pair operator's helper result.
    pub fn pair(op: PairOp) -> Range {
        match op {
            PairOp::Dot => Range::FINITE,
            _ => Range { lo: 0.0, ..Range::FINITE },
        }
    }

    /// This range without its negative part (for a value known never to be negative).
    pub fn at_least_zero(self) -> Range {
        Range { lo: self.lo.max(0.0), hi: self.hi.max(0.0), floor: self.floor }
    }

    /// The magnitude a base of `pow(a, n)` is clamped to before the `n`th
    /// power is multiplied out, where this range needs it: the largest f32
    /// whose `n`th power is at most BIG, so no product overflows (`None`
    /// where every base's power is at most BIG already).
    pub fn power_cap(self, n: u32) -> Option<f32> {
        if self.magnitude().hi.powi(n as i32) * (1.0 + MARGIN) <= BIG {
            return None;
        }
        let mut cap = BIG.powf(1.0 / n as f64) as f32;
        while (cap as f64).powi(n as i32) > BIG {
            cap = f32::from_bits(cap.to_bits() - 1);
        }
        Some(cap)
    }

    /// `a^n` multiplied out for a whole `n` in `2..=INTEGER_POWER_MAX`, the
    /// base clamped to ±`cap` first, before `fin`. The rounding of the
    /// squarings and products grows to about (n − 1) half-ulps (7.6e-6 at
    /// n = 128; 8.4e-6 measured on lavapipe): the bounds are widened by n
    /// whole ulps first, then by the margin every bound is.
    pub fn integer_power(self, n: u32, cap: Option<f32>) -> Range {
        debug_assert!((2..=INTEGER_POWER_MAX).contains(&n));
        // The base as the kernel holds it: every bound, the floor included, at most the cap.
        let capped = match cap.map(f64::from) {
            Some(c) => Range { lo: self.lo.clamp(-c, c), hi: self.hi.clamp(-c, c), floor: self.floor.min(c) },
            None => self,
        };
        let m = capped.magnitude();
        let rounding = n as f64 * f32::EPSILON as f64;
        let (small, large) = (m.lo.powi(n as i32) * (1.0 - rounding), m.hi.powi(n as i32) * (1.0 + rounding));
        let (lo, hi) = if n.is_multiple_of(2) || capped.lo >= 0.0 {
            (small, large)
        } else if capped.hi <= 0.0 {
            (-large, -small)
        } else {
            (-large, large)
        };
        Range::new(lo, hi, m.floor.powi(n as i32) * (1.0 - rounding) * (1.0 - MARGIN))
    }

    /// `exp(a)` of a non-positive `a` can use `fj_exp_nonpos`.
    pub fn non_positive(self) -> bool {
        self.hi <= 0.0
    }

    /// `sqrt(a)` of a non-negative `a` needs no domain check nor flush
    /// (the root of any positive f32 is above TINY): `sqrt(a)` or
    /// `min(sqrt(a), BIG)`, and the range after it.
    pub fn sqrt_non_negative(self) -> (Guard, Range) {
        debug_assert!(self.non_negative());
        Range { lo: self.lo.sqrt(), hi: self.hi.sqrt(), floor: TINY }.guard()
    }
}

/// The least and the greatest of the four products or quotients of two
/// ranges' bounds; `None` where one is undefined (0 · ∞, ∞ / ∞).
fn span(values: [f64; 4]) -> Option<(f64, f64)> {
    if values.iter().any(|v| v.is_nan()) {
        return None;
    }
    let lo = values.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    Some((lo, hi))
}

impl Guard {
    /// `value` (WGSL) with this guard applied.
    pub fn apply(self, value: &str) -> String {
        match self {
            Guard::None => format!("({value})"),
            Guard::Ceiling => format!("min({value}, FJ_BIG)"),
            Guard::Clamp => format!("clamp({value}, -FJ_BIG, FJ_BIG)"),
            Guard::FlushNonNegative => format!("fj_flush_pos({value})"),
            Guard::Flush => format!("fj_flush({value})"),
            Guard::FinNonNegative => format!("fj_fin_pos({value})"),
            Guard::Fin => format!("fj_fin({value})"),
        }
    }

    /// The helper the guard calls, if any.
    pub fn helper(self) -> Option<&'static str> {
        match self {
            Guard::None | Guard::Ceiling | Guard::Clamp => None,
            Guard::FlushNonNegative => Some("fj_flush_pos"),
            Guard::Flush => Some("fj_flush"),
            Guard::FinNonNegative => Some("fj_fin_pos"),
            Guard::Fin => Some("fj_fin"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `fin` as the kernels compute it, in f32.
    fn fin32(x: f32) -> f32 {
        if x.abs() < TINY as f32 {
            0.0
        } else {
            x.clamp(-BIG as f32, BIG as f32)
        }
    }

    /// Values an operand in `range` can take, the bounds and the floor included.
    fn samples(range: Range) -> Vec<f32> {
        let mut v = if range.lo <= 0.0 && range.hi >= 0.0 { vec![0.0f32] } else { Vec::new() };
        for x in [range.lo, range.hi, range.floor, -range.floor, range.floor * 1.5, (range.lo + range.hi) / 2.0] {
            let x = x as f32;
            if x.is_finite()
                && (x == 0.0 || (x as f64 >= range.lo && x as f64 <= range.hi && x.abs() as f64 >= range.floor))
            {
                v.push(x);
            }
        }
        v
    }

    /// Where the analysis proves a guard part idle, leaving it out gives
    /// `fin`'s value: sums, products and quotients of operands at the edges
    /// of their ranges.
    #[test]
    fn an_idle_guard_changes_no_value() {
        let ranges = [
            Range::literal(6.377551),
            Range::literal(-2.0),
            Range::literal(1e-20),
            Range::literal(1.0),
            Range { lo: 0.0, ..Range::FINITE },
            Range::FINITE,
            Range { lo: 0.0, hi: 1.0, floor: TINY },
            Range { lo: 1.0, hi: 1e8, floor: 1.0 },
        ];
        let guarded = |g: Guard, x: f32| match g {
            Guard::None => x,
            Guard::Ceiling => x.min(BIG as f32),
            Guard::Clamp => x.clamp(-BIG as f32, BIG as f32),
            Guard::FlushNonNegative | Guard::Flush => {
                if x.abs() < TINY as f32 {
                    0.0
                } else {
                    x
                }
            }
            Guard::FinNonNegative | Guard::Fin => fin32(x),
        };
        for &a in &ranges {
            for &b in &ranges {
                type Case = (Option<Range>, fn(f32, f32) -> f32);
                let cases: [Case; 3] = [
                    (Some(Range::sum(a, b)), |x, y| x + y),
                    (Some(Range::product(a, b)), |x, y| x * y),
                    (Range::quotient(a, b), |x, y| x / y),
                ];
                for (range, op) in cases {
                    let Some(range) = range else { continue };
                    let (guard, after) = range.guard();
                    for x in samples(a) {
                        for y in samples(b) {
                            let exact = op(x, y);
                            if !exact.is_finite() {
                                continue;
                            }
                            assert_eq!(guarded(guard, exact), fin32(exact), "{a:?} {b:?}: {x} {y} under {guard:?}");
                            let value = fin32(exact) as f64;
                            assert!(value >= after.lo && value <= after.hi, "{value} outside {after:?}");
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn sums_of_non_negative_terms_need_only_the_ceiling() {
        let term = Range { lo: 0.0, ..Range::FINITE };
        assert_eq!(Range::sum(term, term).guard().0, Guard::Ceiling);
        // A difference can cancel to a tiny value: the flush stays.
        assert_eq!(Range::sum(term, term.negated()).guard().0, Guard::Fin);
        // A scaled unit value stays in range and above TINY.
        let unit = Range { lo: 0.0, hi: 1.0, floor: TINY };
        assert_eq!(Range::product(unit, Range::literal(1e7)).guard().0, Guard::None);
        assert_eq!(Range::product(term, Range::literal(0.05)).guard().0, Guard::FlushNonNegative);
        assert_eq!(Range::product(term, term).guard().0, Guard::FinNonNegative);
        // A raw variance proves nothing.
        assert_eq!(Range::sum(Range::ANY, term).guard().0, Guard::Fin);
        assert_eq!(Range::quotient(term, Range::literal(0.0)), None);
    }

    /// A whole power multiplied out in f32 (the base held by its cap) stays
    /// inside the range `integer_power` gives, and its guard's value is
    /// `fin` of it; the cap keeps every product at most BIG.
    #[test]
    fn whole_powers_multiplied_out_stay_in_their_range() {
        let ranges = [
            Range::FINITE,
            Range { lo: 0.0, ..Range::FINITE },
            Range { lo: 0.0, hi: 1.0, floor: TINY },
            Range { lo: -3.0, hi: -0.5, floor: 0.5 },
            Range { lo: 1.0, hi: 1e8, floor: 1.0 },
            // Every base above the cap: the kernel's power is the cap's, and so is the floor.
            Range { lo: 3.0, hi: 1e8, floor: 3.0 },
            Range { lo: -1e8, hi: -3.0, floor: 3.0 },
        ];
        for range in ranges {
            for n in [3u32, 4, 7, 64, 127, INTEGER_POWER_MAX] {
                let cap = range.power_cap(n);
                if let Some(c) = cap {
                    assert!((c as f64).powi(n as i32) <= BIG, "{c}^{n}");
                }
                let bound = range.integer_power(n, cap);
                for x in samples(range) {
                    let base = cap.map_or(x, |c| x.clamp(-c, c));
                    let (mut power, mut square, mut bits) = (1.0f32, base, n);
                    while bits > 0 {
                        if bits & 1 == 1 {
                            power *= square;
                        }
                        square *= square;
                        bits >>= 1;
                    }
                    let v = power as f64;
                    assert!(v.is_finite() && v >= bound.lo && v <= bound.hi, "{x}^{n} = {v} outside {bound:?}");
                    assert!(v == 0.0 || v.abs() >= bound.floor, "{x}^{n} = {v} below the floor of {bound:?}");
                }
            }
        }
        // A base never above 1 needs no cap; any base that can pass BIG^(1/n) does.
        assert_eq!(Range { lo: 0.0, hi: 1.0, floor: TINY }.power_cap(128), None);
        assert!(Range::FINITE.power_cap(3).is_some());
    }
}
