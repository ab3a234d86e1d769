// filterjit operator helpers: the f32 twin of src/semantics.rs, formula for
// formula. Every helper moves its inputs into the domain where the f32
// computation is finite before computing (WGSL implementations may assume
// there is no NaN or infinity, so nothing here tests for them afterwards).
// Undefined operations set a bit in fj_domain and still return a value.

const FJ_BIG: f32 = 1e15;
const FJ_TINY: f32 = 1e-30;
const FJ_DIV_EPS: f32 = 1e-15;
const FJ_EXP_MIN: f32 = -80.0;
const FJ_EXP_MAX: f32 = 34.538776;
const FJ_LOG2_BIG: f32 = 49.828922;
const FJ_SINC_SMALL: f32 = 1e-4;
const FJ_SINC_TAU: f32 = 3.0;
const FJ_PI: f32 = 3.14159265358979;
const FJ_TAU: f32 = 6.28318530717959;

const FJ_FLAG_SQRT: u32 = 1u;
const FJ_FLAG_ASIN: u32 = 2u;
const FJ_FLAG_ACOS: u32 = 4u;
const FJ_FLAG_POW: u32 = 8u;

var<private> fj_domain: u32 = 0u;

fn fj_fin(x: f32) -> f32 {
    return select(clamp(x, -FJ_BIG, FJ_BIG), 0.0, abs(x) < FJ_TINY);
}

// The parts of fj_fin, for values whose range proves the other part idle
// (src/jit/range.rs): the same f32 wherever the lowering uses them.
fn fj_flush(x: f32) -> f32 {
    return select(x, 0.0, abs(x) < FJ_TINY);
}
fn fj_flush_pos(x: f32) -> f32 {
    return select(x, 0.0, x < FJ_TINY);
}
fn fj_fin_pos(x: f32) -> f32 {
    return select(min(x, FJ_BIG), 0.0, x < FJ_TINY);
}

fn fj_protect(d: f32) -> f32 {
    return select(d, select(FJ_DIV_EPS, -FJ_DIV_EPS, d < 0.0), abs(d) < FJ_DIV_EPS);
}

fn fj_turn(x: f32) -> f32 {
    return FJ_TAU * fract(x / FJ_TAU);
}

fn fj_neg(a: f32) -> f32 { return fj_fin(-a); }
fn fj_abs(a: f32) -> f32 { return fj_fin(abs(a)); }
fn fj_add(a: f32, b: f32) -> f32 { return fj_fin(a + b); }
fn fj_sub(a: f32, b: f32) -> f32 { return fj_fin(a - b); }
fn fj_mul(a: f32, b: f32) -> f32 { return fj_fin(a * b); }
fn fj_div(a: f32, b: f32) -> f32 { return fj_fin(a / fj_protect(b)); }

// fj_pow of a non-negative base (src/jit/range.rs): no domain flag, no sign.
fn fj_pow_nonneg(a: f32, b: f32) -> f32 {
    if (a == 0.0) {
        return select(select(0.0, 1.0, b == 0.0), FJ_BIG, b < 0.0);
    }
    let e = clamp(b * log2(max(a, FJ_TINY)), -200.0, FJ_LOG2_BIG);
    return fj_fin_pos(select(exp2(e), 0.0, e < -100.0));
}
// The magnitude is the power of |a| (a zero base included); the sign is a's
// for an odd integral power (`fin` is symmetric, and `0.0 - m` keeps a zero +0).
fn fj_pow(a: f32, b: f32) -> f32 {
    let integral = b == round(b);
    if (a < 0.0 && !integral) {
        fj_domain |= FJ_FLAG_POW;
    }
    let magnitude = fj_pow_nonneg(abs(a), b);
    let odd = integral && (b - 2.0 * floor(b * 0.5)) == 1.0;
    return select(magnitude, 0.0 - magnitude, a < 0.0 && odd);
}
fn fj_sin(a: f32) -> f32 { return fj_fin(sin(fj_turn(a))); }
fn fj_cos(a: f32) -> f32 { return fj_fin(cos(fj_turn(a))); }
fn fj_tan(a: f32) -> f32 {
    let t = fj_turn(a);
    return fj_fin(sin(t) / fj_protect(cos(t)));
}
fn fj_exp(a: f32) -> f32 {
    let e = fj_fin(exp(clamp(a, FJ_EXP_MIN, FJ_EXP_MAX)));
    return select(select(e, FJ_BIG, a >= FJ_EXP_MAX), 0.0, a < FJ_EXP_MIN);
}
// fj_exp of a non-positive argument (src/jit/range.rs): exp(EXP_MIN) is
// below TINY, so the lower cut-off is the flush's.
fn fj_exp_nonpos(a: f32) -> f32 {
    let e = exp(max(a, FJ_EXP_MIN));
    return select(e, 0.0, e < FJ_TINY);
}
fn fj_asin(a: f32) -> f32 {
    if (abs(a) > 1.0) {
        fj_domain |= FJ_FLAG_ASIN;
    }
    return fj_fin(asin(clamp(a, -1.0, 1.0)));
}
fn fj_acos(a: f32) -> f32 {
    if (abs(a) > 1.0) {
        fj_domain |= FJ_FLAG_ACOS;
    }
    return fj_fin(acos(clamp(a, -1.0, 1.0)));
}
fn fj_atan(a: f32) -> f32 { return fj_fin(atan(a)); }
fn fj_sqrt(a: f32) -> f32 {
    if (a < 0.0) {
        fj_domain |= FJ_FLAG_SQRT;
    }
    return fj_fin(sqrt(abs(a)));
}

// Mitchell-Netravali, B = C = 1/3.
fn fj_mitchell(x: f32) -> f32 {
    let a = min(abs(x), 2.0);
    let b = 1.0 / 3.0;
    let c = 1.0 / 3.0;
    let inner = (12.0 - 9.0 * b - 6.0 * c) * a * a * a + (-18.0 + 12.0 * b + 6.0 * c) * a * a + (6.0 - 2.0 * b);
    let outer = (-b - 6.0 * c) * a * a * a + (6.0 * b + 30.0 * c) * a * a + (-12.0 * b - 48.0 * c) * a + (8.0 * b + 24.0 * c);
    let k = select(select(0.0, outer, a < 2.0), inner, a < 1.0);
    return fj_fin(k / 6.0);
}

// sinc(x) * sinc(tau x) on [-1, 1], 1 at 0.
fn fj_sinc(x: f32) -> f32 {
    let a = min(abs(x), 1.0);
    let s = max(a, FJ_SINC_SMALL);
    let exact = sin(FJ_PI * s) * sin(FJ_SINC_TAU * FJ_PI * s) / (FJ_SINC_TAU * FJ_PI * FJ_PI * s * s);
    let series = 1.0 - (1.0 + FJ_SINC_TAU * FJ_SINC_TAU) * FJ_PI * FJ_PI * a * a / 6.0;
    let k = select(select(exact, series, a < FJ_SINC_SMALL), 0.0, abs(x) > 1.0);
    return fj_fin(k);
}

fn fj_epanechnikov(x: f32) -> f32 {
    let a = min(abs(x), 1.0);
    return fj_fin(select(0.0, 2.0 / FJ_PI * (1.0 - a * a), abs(x) < 1.0));
}

fn fj_biweight(x: f32) -> f32 {
    let a = min(abs(x), 1.0);
    let t = 1.0 - a * a;
    return fj_fin(15.0 / 16.0 * t * t);
}

fn fj_tricube(x: f32) -> f32 {
    let a = min(abs(x), 1.0);
    let t = 1.0 - a * a * a;
    return fj_fin(t * t * t);
}

fn fj_dot(u: vec3<f32>, v: vec3<f32>) -> f32 { return fj_fin(u.x * v.x + u.y * v.y + u.z * v.z); }
fn fj_distance2(u: vec3<f32>, v: vec3<f32>) -> f32 {
    let d = u - v;
    return fj_fin(sqrt(d.x * d.x + d.y * d.y + d.z * d.z));
}
// pow(distance2(u, v), 2) without the square root (strength reduction).
fn fj_distance2sq(u: vec3<f32>, v: vec3<f32>) -> f32 {
    let d = u - v;
    return fj_fin(d.x * d.x + d.y * d.y + d.z * d.z);
}
fn fj_distance1(u: vec3<f32>, v: vec3<f32>) -> f32 {
    let d = abs(u - v);
    return fj_fin(d.x + d.y + d.z);
}
fn fj_distancemax(u: vec3<f32>, v: vec3<f32>) -> f32 {
    let d = abs(u - v);
    return fj_fin(max(max(d.x, d.y), d.z));
}

fn fj_weight(w: f32) -> f32 { return max(fj_fin(w), 0.0); }
