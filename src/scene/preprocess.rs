//! Feature preprocessing (thesis section 3.3.2), made robust to outliers.
//!
//! The thesis divides 1-D features by their maximum and 3-D features by the
//! length of the longest vector. One outlier (Mitsuba's albedo reaches
//! hundreds on metals) would then squash every ordinary value towards zero, so
//! we divide by the 99.9th percentile of the lengths instead and clamp the few
//! longer vectors to unit length, keeping their direction. Without outliers
//! the percentile is close to the maximum and the thesis's rule is recovered.

/// Fraction of values the normalisation scale covers.
pub const NORMALISATION_PERCENTILE: f64 = 0.999;

/// Replace non-finite values by zero and clamp magnitudes to `limit`;
/// returns how many of each there were.
pub fn sanitize(values: &mut [f32], limit: f32) -> Sanitized {
    let mut counts = Sanitized::default();
    for v in values.iter_mut() {
        if !v.is_finite() {
            *v = 0.0;
            counts.non_finite += 1;
        } else if v.abs() > limit {
            *v = v.clamp(-limit, limit);
            counts.limited += 1;
        }
    }
    counts
}

/// What [`sanitize`] changed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Sanitized {
    /// Values that were NaN or infinite, now 0.
    pub non_finite: usize,
    /// Finite values beyond the limit, now at it.
    pub limited: usize,
}

fn length(v: [f32; 3]) -> f32 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

/// The `NORMALISATION_PERCENTILE` quantile of `values` (nearest rank), or 1 when it is 0.
pub fn robust_scale(mut values: Vec<f32>) -> f32 {
    if values.is_empty() {
        return 1.0;
    }
    values.sort_by(f32::total_cmp);
    let rank = ((values.len() as f64 * NORMALISATION_PERCENTILE).ceil() as usize).clamp(1, values.len());
    let scale = values[rank - 1];
    if scale > 0.0 && scale.is_finite() {
        scale
    } else {
        1.0
    }
}

/// Make every normal its direction ([`crate::semantics::unit_direction`]).
/// Returns how many were changed.
pub fn unit_normals(values: &mut [[f32; 3]]) -> usize {
    let mut changed = 0;
    for v in values.iter_mut() {
        let unit = crate::semantics::unit_direction(*v);
        if unit != *v {
            *v = unit;
            changed += 1;
        }
    }
    changed
}

/// Divide vectors by the robust scale of their lengths; clamp longer ones to length 1.
/// Returns the scale used.
pub fn normalise_vectors(values: &mut [[f32; 3]]) -> f32 {
    let scale = robust_scale(values.iter().map(|v| length(*v)).collect());
    for v in values.iter_mut() {
        for c in v.iter_mut() {
            *c /= scale;
        }
        let l = length(*v);
        if l > 1.0 {
            for c in v.iter_mut() {
                *c /= l;
            }
        }
    }
    scale
}

/// Divide scalars by the robust scale of their magnitudes and clamp to [-1, 1].
pub fn normalise_scalars(values: &mut [f32]) -> f32 {
    let scale = robust_scale(values.iter().map(|v| v.abs()).collect());
    for v in values.iter_mut() {
        *v = (*v / scale).clamp(-1.0, 1.0);
    }
    scale
}

/// Per-channel Sobel gradient magnitude, sqrt(gx² + gy²), with clamp-to-edge borders.
pub fn sobel(values: &[[f32; 3]], width: usize, height: usize) -> Vec<[f32; 3]> {
    let at = |x: isize, y: isize| {
        let x = x.clamp(0, width as isize - 1) as usize;
        let y = y.clamp(0, height as isize - 1) as usize;
        values[y * width + x]
    };
    let mut out = vec![[0f32; 3]; values.len()];
    for y in 0..height as isize {
        for x in 0..width as isize {
            let mut g = [0f32; 3];
            for (c, gc) in g.iter_mut().enumerate() {
                let p = |dx: isize, dy: isize| at(x + dx, y + dy)[c];
                let gx = (p(1, -1) + 2.0 * p(1, 0) + p(1, 1)) - (p(-1, -1) + 2.0 * p(-1, 0) + p(-1, 1));
                let gy = (p(-1, 1) + 2.0 * p(0, 1) + p(1, 1)) - (p(-1, -1) + 2.0 * p(0, -1) + p(1, -1));
                *gc = (gx * gx + gy * gy).sqrt();
            }
            out[y as usize * width + x as usize] = g;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_outlier_does_not_squash_ordinary_values() {
        let mut v: Vec<[f32; 3]> = (0..2000).map(|i| [0.5 + (i % 10) as f32 * 0.01, 0.2, 0.1]).collect();
        v[7] = [500.0, 0.0, 0.0];
        normalise_vectors(&mut v);
        assert!(v[0][0] > 0.5, "ordinary albedo keeps its range: {:?}", v[0]);
        assert!((length(v[7]) - 1.0).abs() < 1e-6, "the outlier is clamped to unit length");
    }

    #[test]
    fn sobel_of_a_ramp_is_constant_inside() {
        let (w, h) = (5, 4);
        let v: Vec<[f32; 3]> = (0..w * h).map(|i| [(i % w) as f32, 0.0, 0.0]).collect();
        let g = sobel(&v, w, h);
        assert_eq!(g[w + 2][0], 8.0);
        assert_eq!(g[w + 2][1], 0.0);
    }

    #[test]
    fn sanitize_counts_and_zeroes_non_finite() {
        let mut v = vec![1.0, f32::NAN, f32::INFINITY, -3e9];
        assert_eq!(sanitize(&mut v, 1e7), Sanitized { non_finite: 2, limited: 1 });
        assert_eq!(v, vec![1.0, 0.0, 0.0, -1e7]);
    }
}
