//! The numeric semantics of every operator, in f64, for the CPU reference.
//!
//! `templates/ops.wgsl` implements the same formulas in f32, line for line;
//! docs/SEMANTICS.md states them once for people. The rules:
//!
//! * Every operator is total on finite inputs and never produces NaN or
//!   infinity: inputs are moved into the domain where the computation is
//!   finite *before* computing (WGSL lets implementations assume there are no
//!   NaN/Inf values, so checking afterwards would not be reliable).
//! * Every result passes through [`fin`]: magnitudes above [`BIG`] saturate,
//!   magnitudes below [`TINY`] flush to zero (GPUs may flush denormals; this
//!   makes the CPU do the same on purpose).
//! * Mathematically undefined operations (sqrt of a negative, asin/acos
//!   outside [-1, 1], a negative base to a non-integer power) still return a
//!   value, and also set a bit in the per-pixel domain-error flags.

/// Saturation bound: every intermediate value lies in [-BIG, BIG].
pub const BIG: f64 = 1e15;
/// Values of smaller magnitude are flushed to zero.
pub const TINY: f64 = 1e-30;
/// Divisors are moved at least this far from zero (= 1/BIG).
pub const DIV_EPS: f64 = 1e-15;
/// exp(x) is 0 below this argument.
pub const EXP_MIN: f64 = -80.0;
/// ln(BIG): exp saturates above this argument.
pub const EXP_MAX: f64 = 34.538_776_394_910_684;
/// Below this magnitude sinc uses its Taylor expansion.
pub const SINC_SMALL: f64 = 1e-4;
/// The sinc kernel's τ (thesis section 3.2.2).
pub const SINC_TAU: f64 = 3.0;

/// How far from 1 a normal's squared length may be and still count as unit
/// length ([`unit_direction`]): far above f32's rounding of a unit vector's.
pub const UNIT_LENGTH2_SLACK: f32 = 1e-5;

/// A normal as the weights read it: its direction. One whose squared length
/// is off 1 by more than [`UNIT_LENGTH2_SLACK`] is divided by its length;
/// zero stays zero. A pixel's normal is the mean of its samples' unit
/// normals, shorter where they differ (a seam, a silhouette, a bump), and
/// a weight that compares normals (SVGF's `pow(dot(normal), 128)`) would
/// collapse to 0 there on its length (docs/JOURNAL.md, "Normals made unit
/// length"). In f32, as the exported shader's `fj_direction` computes it:
/// filterjit applies it when it loads a render.
pub fn unit_direction(v: [f32; 3]) -> [f32; 3] {
    let length2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
    if length2 > 0.0 && (length2 - 1.0).abs() > UNIT_LENGTH2_SLACK {
        let length = length2.sqrt();
        v.map(|c| c / length)
    } else {
        v
    }
}

/// Domain-error flag bits, as counted per pixel.
pub mod flag {
    pub const SQRT: u32 = 1;
    pub const ASIN: u32 = 2;
    pub const ACOS: u32 = 4;
    pub const POW: u32 = 8;

    /// (bit, description) for reports.
    pub const ALL: &[(u32, &str)] = &[
        (SQRT, "sqrt of a negative number"),
        (ASIN, "asin outside [-1, 1]"),
        (ACOS, "acos outside [-1, 1]"),
        (POW, "negative base to a non-integer power"),
    ];

    /// Human-readable list of the bits set in `flags`.
    pub fn describe(flags: u32) -> Vec<&'static str> {
        ALL.iter().filter(|(bit, _)| flags & bit != 0).map(|(_, d)| *d).collect()
    }
}

use std::f64::consts::{PI, TAU};

/// Saturate and flush: the final step of every operator.
pub fn fin(x: f64) -> f64 {
    if x.abs() < TINY {
        0.0
    } else {
        x.clamp(-BIG, BIG)
    }
}

/// A literal's value: rounded to f32, as the GPU holds it, then `fin`.
/// (Without the rounding, tan(pi / 2) would be +1.6e16 on the CPU and
/// −2.3e7 on the GPU: f32's π/2 lies past the pole.)
pub fn literal(c: f64) -> f64 {
    fin(c as f32 as f64)
}

/// `x - floor(x)`, as WGSL's `fract`.
fn fract(x: f64) -> f64 {
    x - x.floor()
}

/// Move a divisor away from zero, keeping its sign (+0 counts as positive).
fn protect(d: f64) -> f64 {
    if d.abs() < DIV_EPS {
        if d < 0.0 {
            -DIV_EPS
        } else {
            DIV_EPS
        }
    } else {
        d
    }
}

/// Reduce an angle to [0, 2π) through a fraction of a turn, as the GPU does.
fn turn(x: f64) -> f64 {
    TAU * fract(x / TAU)
}

pub fn neg(a: f64) -> f64 {
    fin(-a)
}
pub fn abs(a: f64) -> f64 {
    fin(a.abs())
}
pub fn add(a: f64, b: f64) -> f64 {
    fin(a + b)
}
pub fn sub(a: f64, b: f64) -> f64 {
    fin(a - b)
}
pub fn mul(a: f64, b: f64) -> f64 {
    fin(a * b)
}
pub fn div(a: f64, b: f64) -> f64 {
    fin(a / protect(b))
}

pub fn pow(a: f64, b: f64, flags: &mut u32) -> f64 {
    let integral = b == b.round();
    if a < 0.0 && !integral {
        *flags |= flag::POW;
    }
    if a == 0.0 {
        return if b < 0.0 {
            BIG
        } else if b == 0.0 {
            1.0
        } else {
            0.0
        };
    }
    let exponent = (b * a.abs().max(TINY).log2()).clamp(-200.0, EXP_MAX / std::f64::consts::LN_2);
    let magnitude = if exponent < -100.0 { 0.0 } else { exponent.exp2() };
    // An odd integer power of a negative base is negative.
    let odd = integral && (b - 2.0 * (b * 0.5).floor()) == 1.0;
    fin(if a < 0.0 && odd { -magnitude } else { magnitude })
}

pub fn sin(a: f64) -> f64 {
    fin(turn(a).sin())
}
pub fn cos(a: f64) -> f64 {
    fin(turn(a).cos())
}
pub fn tan(a: f64) -> f64 {
    let t = turn(a);
    fin(t.sin() / protect(t.cos()))
}
pub fn exp(a: f64) -> f64 {
    if a < EXP_MIN {
        0.0
    } else if a >= EXP_MAX {
        BIG
    } else {
        fin(a.exp())
    }
}
pub fn asin(a: f64, flags: &mut u32) -> f64 {
    if a.abs() > 1.0 {
        *flags |= flag::ASIN;
    }
    fin(a.clamp(-1.0, 1.0).asin())
}
pub fn acos(a: f64, flags: &mut u32) -> f64 {
    if a.abs() > 1.0 {
        *flags |= flag::ACOS;
    }
    fin(a.clamp(-1.0, 1.0).acos())
}
pub fn atan(a: f64) -> f64 {
    fin(a.atan())
}
pub fn sqrt(a: f64, flags: &mut u32) -> f64 {
    if a < 0.0 {
        *flags |= flag::SQRT;
    }
    fin(a.abs().sqrt())
}

/// Mitchell–Netravali with B = C = 1/3 (thesis equation 3.1).
pub fn mitchell(x: f64) -> f64 {
    let a = x.abs().min(2.0);
    let (b, c) = (1.0 / 3.0, 1.0 / 3.0);
    let inner = (12.0 - 9.0 * b - 6.0 * c) * a * a * a + (-18.0 + 12.0 * b + 6.0 * c) * a * a + (6.0 - 2.0 * b);
    let outer =
        (-b - 6.0 * c) * a * a * a + (6.0 * b + 30.0 * c) * a * a + (-12.0 * b - 48.0 * c) * a + (8.0 * b + 24.0 * c);
    let k = if a < 1.0 {
        inner
    } else if a < 2.0 {
        outer
    } else {
        0.0
    };
    fin(k / 6.0)
}

/// Windowed sinc: sinc(x)·sinc(τx) on [-1, 1], 1 at 0 (docs/SEMANTICS.md
/// explains this reading of the thesis's formula).
pub fn sinc(x: f64) -> f64 {
    let a = x.abs().min(1.0);
    let s = a.max(SINC_SMALL);
    let exact = (PI * s).sin() * (SINC_TAU * PI * s).sin() / (SINC_TAU * PI * PI * s * s);
    let series = 1.0 - (1.0 + SINC_TAU * SINC_TAU) * PI * PI * a * a / 6.0;
    let k = if x.abs() > 1.0 {
        0.0
    } else if a < SINC_SMALL {
        series
    } else {
        exact
    };
    fin(k)
}

pub fn epanechnikov(x: f64) -> f64 {
    let a = x.abs().min(1.0);
    fin(if x.abs() < 1.0 { 2.0 / PI * (1.0 - a * a) } else { 0.0 })
}

pub fn biweight(x: f64) -> f64 {
    let a = x.abs().min(1.0);
    let t = 1.0 - a * a;
    fin(15.0 / 16.0 * t * t)
}

pub fn tricube(x: f64) -> f64 {
    let a = x.abs().min(1.0);
    let t = 1.0 - a * a * a;
    fin(t * t * t)
}

pub fn dot(u: [f64; 3], v: [f64; 3]) -> f64 {
    fin(u[0] * v[0] + u[1] * v[1] + u[2] * v[2])
}
pub fn distance2(u: [f64; 3], v: [f64; 3]) -> f64 {
    let d = [u[0] - v[0], u[1] - v[1], u[2] - v[2]];
    fin((d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt())
}
pub fn distance1(u: [f64; 3], v: [f64; 3]) -> f64 {
    fin((u[0] - v[0]).abs() + (u[1] - v[1]).abs() + (u[2] - v[2]).abs())
}
pub fn distance_max(u: [f64; 3], v: [f64; 3]) -> f64 {
    fin((u[0] - v[0]).abs().max((u[1] - v[1]).abs()).max((u[2] - v[2]).abs()))
}

/// A weight as the filter uses it: negative weights count as zero.
pub fn weight(w: f64) -> f64 {
    fin(w).max(0.0)
}

/// Bound on input colour magnitudes after sanitising (keeps every product finite).
pub const COLOR_LIMIT: f32 = 1e7;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kernels_are_continuous_at_their_breakpoints() {
        let eps = 1e-9;
        for (name, k, at) in [
            ("mitchell", mitchell as fn(f64) -> f64, 1.0),
            ("mitchell", mitchell, 2.0),
            ("sinc", sinc, SINC_SMALL),
            ("sinc", sinc, 1.0),
            ("epanechnikov", epanechnikov, 1.0),
            ("biweight", biweight, 1.0),
            ("tricube", tricube, 1.0),
        ] {
            let (l, r) = (k(at - eps), k(at + eps));
            assert!((l - r).abs() < 1e-6, "{name} jumps at {at}: {l} vs {r}");
        }
        assert_eq!(sinc(0.0), 1.0);
        assert!((mitchell(0.0) - 8.0 / 9.0).abs() < 1e-12);
    }

    #[test]
    fn domain_errors_set_flags_and_stay_finite() {
        let mut f = 0;
        assert_eq!(sqrt(-4.0, &mut f), 2.0);
        assert_eq!(f, flag::SQRT);
        let mut f = 0;
        assert!(asin(2.0, &mut f).is_finite() && f == flag::ASIN);
        let mut f = 0;
        assert!(pow(-2.0, 0.5, &mut f).is_finite() && f == flag::POW);
        let mut f = 0;
        assert_eq!(pow(-2.0, 3.0, &mut f), -8.0);
        assert_eq!(f, 0);
        assert_eq!(pow(0.0, -1.0, &mut f), BIG);
        assert!((div(1.0, 0.0) - BIG).abs() < 1.0);
        assert!((div(-1.0, -0.0) + BIG).abs() < 1.0, "-0 counts as positive: -1 / +eps");
        assert_eq!(exp(100.0), BIG);
        assert_eq!(exp(-100.0), 0.0);
        assert_eq!(f, 0, "division by zero and pow(0, -1) saturate without a flag");
    }
}
