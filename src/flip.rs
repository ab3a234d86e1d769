//! HDR-FLIP (Andersson et al., "Visualizing Errors in Rendered High Dynamic
//! Range Images", Eurographics 2021): a perceptual difference between a
//! test image and its reference, as a person at a monitor would see it.
//!
//! A port of the reference implementation (NVlabs/flip, `FLIP.h`, version
//! 1.7) for linear-RGB HDR images, with its defaults: 67.02 pixels per degree
//! (0.7 m from a 0.7 m wide 3840-pixel monitor), the ACES tone mapper, and
//! exposures from the reference's luminance (its maximum and median). Each
//! exposure is tone mapped and scored by LDR-FLIP (colour difference after
//! contrast-sensitivity filtering, in Hunt-adjusted CIELab with HyAB,
//! raised to the power of one minus the edge and point feature difference);
//! a pixel's HDR-FLIP is its largest LDR-FLIP over the exposures. Arithmetic
//! is f32 as in the reference, borders clamp as there, and `tests/flip.rs`
//! compares the result with the `flip-evaluator` package's on small images.
//! Deliberate differences where the reference implementation divides by
//! zero: a median luminance of 0 is replaced by the smallest non-zero one,
//! and a reference with no light at all is scored at exposure 0 alone.

use std::f32::consts::PI;

/// Pixels per degree of visual angle: the reference implementation's default viewing conditions.
pub fn default_ppd() -> f32 {
    0.7 * (3840.0 / 0.7) * (PI / 180.0)
}

const QC: f32 = 0.7;
const PC: f32 = 0.4;
const PT: f32 = 0.95;
const W: f32 = 0.082;
const QF: f32 = 0.5;

/// ACES (Narkowicz's fit, with 0.6 pre-exposure cancellation) as a ratio of quadratics.
const ACES: [f32; 6] = [0.6 * 0.6 * 2.51, 0.6 * 0.03, 0.0, 0.6 * 0.6 * 2.43, 0.6 * 0.59, 0.14];

const ILLUMINANT: [f32; 3] = [0.950_428_5, 1.0, 1.088_900_4];
const INV_ILLUMINANT: [f32; 3] = [1.052_156_9, 1.0, 0.918_357_7];

type Rgb = [f32; 3];

/// A per-pixel HDR-FLIP error map, row-major, values in [0, 1].
#[derive(Clone, Debug)]
pub struct FlipMap {
    pub width: usize,
    pub height: usize,
    pub error: Vec<f32>,
}

impl FlipMap {
    /// The mean error over pixels (the figure a report states).
    pub fn mean(&self) -> f64 {
        // Summed in f32, in order, as the reference does.
        let sum: f32 = self.error.iter().sum();
        (sum / self.error.len().max(1) as f32) as f64
    }
}

/// HDR-FLIP of `test` against `reference` (linear RGB, `width`×`height`, row-major).
pub fn hdr_flip(reference: &[Rgb], test: &[Rgb], width: usize, height: usize) -> FlipMap {
    assert_eq!(reference.len(), width * height, "reference has width*height pixels");
    assert_eq!(test.len(), width * height, "test has width*height pixels");
    let ppd = default_ppd();
    // A reference without light has no exposure range (the reference
    // implementation divides by zero there): score it at exposure 0.
    let (start, stop) = match exposures(reference) {
        (start, stop) if start.is_finite() && stop.is_finite() && start <= stop => (start, stop),
        _ => (0.0, 0.0),
    };
    let count = (stop - start).ceil().max(2.0) as usize;
    let step = (stop - start) / (count - 1) as f32;
    let mut error = vec![0.0f32; width * height];
    for k in 0..count {
        let exposure = start + k as f32 * step;
        let scale = 2.0f32.powf(exposure);
        let map = |image: &[Rgb]| -> Vec<Rgb> {
            image.iter().map(|c| c.map(|v| tone_map(v * scale).clamp(0.0, 1.0))).collect()
        };
        let ldr = ldr_flip(&map(reference), &map(test), width, height, ppd);
        for (e, l) in error.iter_mut().zip(ldr) {
            if l > *e {
                *e = l;
            }
        }
    }
    FlipMap { width, height, error }
}

fn tone_map(x: f32) -> f32 {
    let t = ACES;
    ((x * x) * t[0] + x * t[1] + t[2]) / (x * x * t[3] + x * t[4] + t[5])
}

fn luminance(c: Rgb) -> f32 {
    0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]
}

/// The first and last exposure: where the brightest and the median pixel tone map to 0.85.
fn exposures(reference: &[Rgb]) -> (f32, f32) {
    let t = 0.85f32;
    let (a, b, c) = (ACES[0] - t * ACES[3], ACES[1] - t * ACES[4], ACES[2] - t * ACES[5]);
    // The larger root of a x² + b x + c = 0.
    let x_max = if a == 0.0 {
        -c / b
    } else {
        let d1 = -0.5 * (b / a);
        d1 + ((d1 * d1) - (c / a)).sqrt()
    };
    let mut luminances: Vec<f32> = reference.iter().map(|&c| luminance(c)).collect();
    let y_max = luminances.iter().copied().fold(-1e30f32, f32::max);
    let y_min = luminances.iter().copied().filter(|&y| y != 0.0).fold(1e30f32, f32::min);
    let middle = luminances.len() / 2;
    luminances.select_nth_unstable_by(middle, f32::total_cmp);
    let median = match luminances[middle] {
        m if m > 0.0 => m,
        _ => y_min,
    };
    ((x_max / y_max).log2(), (x_max / median).log2())
}

fn linear_rgb_to_xyz(c: Rgb) -> Rgb {
    let m = [
        [10135552.0 / 24577794.0, 8788810.0 / 24577794.0, 4435075.0 / 24577794.0],
        [2613072.0 / 12288897.0, 8788810.0 / 12288897.0, 887015.0 / 12288897.0],
        [1425312.0 / 73733382.0, 8788810.0 / 73733382.0, 70074185.0 / 73733382.0],
    ];
    m.map(|row: [f32; 3]| row[0] * c[0] + row[1] * c[1] + row[2] * c[2])
}

fn xyz_to_linear_rgb(c: Rgb) -> Rgb {
    let m = [
        [3.241_003_3, -1.537_398_9, -0.498_615_87],
        [-0.969_224_33, 1.875_930_1, 0.041_554_224],
        [0.055_639_423, -0.204_011_2, 1.057_148_9],
    ];
    m.map(|row: [f32; 3]| row[0] * c[0] + row[1] * c[1] + row[2] * c[2])
}

fn xyz_to_ycxcz(c: Rgb) -> Rgb {
    let c = [c[0] * INV_ILLUMINANT[0], c[1] * INV_ILLUMINANT[1], c[2] * INV_ILLUMINANT[2]];
    [116.0 * c[1] - 16.0, 500.0 * (c[0] - c[1]), 200.0 * (c[1] - c[2])]
}

fn ycxcz_to_xyz(c: Rgb) -> Rgb {
    let y = (c[0] + 16.0) / 116.0;
    let (cx, cz) = (c[1] / 500.0, c[2] / 200.0);
    [(y + cx) * ILLUMINANT[0], y * ILLUMINANT[1], (y - cz) * ILLUMINANT[2]]
}

fn xyz_to_lab(c: Rgb) -> Rgb {
    let delta = 6.0f32 / 29.0;
    let delta_cube = delta * delta * delta;
    let factor = 1.0 / (3.0 * delta * delta);
    let term = 4.0f32 / 29.0;
    let f = |v: f32| if v > delta_cube { v.powf(1.0 / 3.0) } else { factor * v + term };
    let c = [f(c[0] * INV_ILLUMINANT[0]), f(c[1] * INV_ILLUMINANT[1]), f(c[2] * INV_ILLUMINANT[2])];
    [116.0 * c[1] - 16.0, 500.0 * (c[0] - c[1]), 200.0 * (c[1] - c[2])]
}

fn hunt(luminance: f32, chrominance: f32) -> f32 {
    0.01 * luminance * chrominance
}

fn hyab(a: Rgb, b: Rgb) -> f32 {
    (a[0] - b[0]).abs() + ((a[1] - b[1]) * (a[1] - b[1]) + (a[2] - b[2]) * (a[2] - b[2])).sqrt()
}

fn hunt_lab(linear: Rgb) -> Rgb {
    let lab = xyz_to_lab(linear_rgb_to_xyz(linear));
    [lab[0], hunt(lab[0], lab[1]), hunt(lab[0], lab[2])]
}

/// The largest colour difference: green against blue, Hunt-adjusted.
fn max_distance() -> f32 {
    hyab(hunt_lab([0.0, 1.0, 0.0]), hunt_lab([0.0, 0.0, 1.0])).powf(QC)
}

/// The reference's unnormalised Gaussian `a √(π/b) exp(−π² x² / b)`.
fn gaussian_ab(x2: f32, a: f32, b: f32) -> f32 {
    a * (PI / b).sqrt() * (-(PI * PI) * x2 / b).exp()
}

/// Its square root's use in a separated sum of two Gaussians.
fn gaussian_ab_sqrt(x2: f32, a: f32, b: f32) -> f32 {
    (a * (PI / b).sqrt()).sqrt() * (-(PI * PI) * x2 / b).exp()
}

/// The contrast-sensitivity filters: (Y, Cx) one Gaussian each, Cz a sum of
/// two separated into two passes; each tap as (first, second) weight.
fn spatial_filters(ppd: f32) -> (Vec<[f32; 2]>, Vec<[f32; 2]>) {
    let (a1, b1, a2, b2) =
        ([1.0f32, 1.0, 34.1], [0.0047f32, 0.0053, 0.04], [0.0f32, 0.0, 13.5], [1.0e-5f32, 1.0e-5, 0.025]);
    let largest = b1.iter().chain(&b2).copied().fold(f32::MIN, f32::max);
    let radius = (3.0 * (largest / (2.0 * PI * PI)).sqrt() * ppd).ceil() as i32;
    let dx = 1.0 / ppd;
    let mut ycx = Vec::new();
    let mut cz = Vec::new();
    let (mut sum_ycx, mut sum_cz) = ([0.0f32; 2], [0.0f32; 2]);
    for x in -radius..=radius {
        let ix = x as f32 * dx;
        let ix2 = ix * ix;
        let v_ycx = [gaussian_ab(ix2, a1[0], b1[0]), gaussian_ab(ix2, a1[1], b1[1])];
        let v_cz = [gaussian_ab_sqrt(ix2, a1[2], b1[2]), gaussian_ab_sqrt(ix2, a2[2], b2[2])];
        sum_ycx = [sum_ycx[0] + v_ycx[0], sum_ycx[1] + v_ycx[1]];
        sum_cz = [sum_cz[0] + v_cz[0], sum_cz[1] + v_cz[1]];
        ycx.push(v_ycx);
        cz.push(v_cz);
    }
    let norm_ycx = [1.0 / sum_ycx[0], 1.0 / sum_ycx[1]];
    let norm_cz = 1.0 / (sum_cz[0] * sum_cz[0] + sum_cz[1] * sum_cz[1]).sqrt();
    for w in &mut ycx {
        *w = [w[0] * norm_ycx[0], w[1] * norm_ycx[1]];
    }
    for w in &mut cz {
        *w = [w[0] * norm_cz, w[1] * norm_cz];
    }
    (ycx, cz)
}

/// The feature filter: a Gaussian and its first and second derivatives,
/// each derivative's positive and negative weights summing to ±1.
fn feature_filter(ppd: f32) -> Vec<[f32; 3]> {
    let sd = 0.5 * W * ppd;
    let radius = (3.0 * sd).ceil() as i32;
    let gaussian = |x: f32| (-(x * x) / (2.0 * sd * sd)).exp();
    let mut taps = Vec::new();
    let (mut g_sum, mut dg_neg, mut dg_pos, mut ddg_neg, mut ddg_pos) = (0.0f32, 0.0f32, 0.0f32, 0.0f32, 0.0f32);
    for x in -radius..=radius {
        let xf = x as f32;
        let g = gaussian(xf);
        g_sum += g;
        let dg = -xf * g;
        if dg > 0.0 {
            dg_pos += dg;
        } else {
            dg_neg -= dg;
        }
        let ddg = (xf * xf / (sd * sd) - 1.0) * g;
        if ddg > 0.0 {
            ddg_pos += ddg;
        } else {
            ddg_neg -= ddg;
        }
        taps.push([g, dg, ddg]);
    }
    taps.into_iter()
        .map(|[g, dg, ddg]| {
            [g / g_sum, dg / if dg > 0.0 { dg_pos } else { dg_neg }, ddg / if ddg > 0.0 { ddg_pos } else { ddg_neg }]
        })
        .collect()
}

/// LDR-FLIP of two linear-RGB images in [0, 1].
fn ldr_flip(reference: &[Rgb], test: &[Rgb], width: usize, height: usize, ppd: f32) -> Vec<f32> {
    let to_ycxcz = |image: &[Rgb]| -> Vec<Rgb> { image.iter().map(|&c| xyz_to_ycxcz(linear_rgb_to_xyz(c))).collect() };
    let (reference, test) = (to_ycxcz(reference), to_ycxcz(test));
    let color = color_difference(&reference, &test, width, height, ppd);
    feature_difference_and_error(&reference, &test, color, width, height, ppd)
}

fn clamp_index(i: i32, n: usize) -> usize {
    i.clamp(0, n as i32 - 1) as usize
}

fn color_difference(reference: &[Rgb], test: &[Rgb], width: usize, height: usize, ppd: f32) -> Vec<f32> {
    let cmax = max_distance();
    let pccmax = PC * cmax;
    let (f_ycx, f_cz) = spatial_filters(ppd);
    let half = (f_ycx.len() / 2) as i32;
    // Per image: (Y, Cx) filtered once, Cz through both Gaussians, first across the rows.
    let across = |image: &[Rgb]| -> Vec<[f32; 4]> {
        let mut out = vec![[0.0f32; 4]; width * height];
        for y in 0..height {
            for x in 0..width {
                let mut acc = [0.0f32; 4];
                for ix in -half..=half {
                    let c = image[y * width + clamp_index(x as i32 + ix, width)];
                    let (wy, wz) = (f_ycx[(ix + half) as usize], f_cz[(ix + half) as usize]);
                    acc = [acc[0] + wy[0] * c[0], acc[1] + wy[1] * c[1], acc[2] + wz[0] * c[2], acc[3] + wz[1] * c[2]];
                }
                out[y * width + x] = acc;
            }
        }
        out
    };
    let (r, t) = (across(reference), across(test));
    let mut out = vec![0.0f32; width * height];
    for y in 0..height {
        for x in 0..width {
            let mut sum = [[0.0f32; 4]; 2];
            for iy in -half..=half {
                let k = clamp_index(y as i32 + iy, height) * width + x;
                let (wy, wz) = (f_ycx[(iy + half) as usize], f_cz[(iy + half) as usize]);
                for (s, image) in sum.iter_mut().zip([&r, &t]) {
                    let c = image[k];
                    *s = [s[0] + wy[0] * c[0], s[1] + wy[1] * c[1], s[2] + wz[0] * c[2], s[3] + wz[1] * c[3]];
                }
            }
            let lab = sum.map(|s| {
                let linear = xyz_to_linear_rgb(ycxcz_to_xyz([s[0], s[1], s[2] + s[3]])).map(|v| v.clamp(0.0, 1.0));
                hunt_lab(linear)
            });
            let difference = hyab(lab[0], lab[1]).powf(QC);
            out[y * width + x] = if difference < pccmax {
                difference * (PT / pccmax)
            } else {
                PT + ((difference - pccmax) / (cmax - pccmax)) * (1.0 - PT)
            };
        }
    }
    out
}

fn feature_difference_and_error(
    reference: &[Rgb],
    test: &[Rgb],
    color: Vec<f32>,
    width: usize,
    height: usize,
    ppd: f32,
) -> Vec<f32> {
    let filter = feature_filter(ppd);
    let half = (filter.len() / 2) as i32;
    let norm = 1.0 / 2.0f32.sqrt();
    // Across the rows: (first derivative, second derivative, Gaussian) of the normalised luminance.
    let across = |image: &[Rgb]| -> Vec<[f32; 3]> {
        let mut out = vec![[0.0f32; 3]; width * height];
        for y in 0..height {
            for x in 0..width {
                let mut acc = [0.0f32; 3];
                for ix in -half..=half {
                    let w = filter[(ix + half) as usize];
                    let v = image[y * width + clamp_index(x as i32 + ix, width)][0] * (1.0 / 116.0) + 16.0 / 116.0;
                    acc = [acc[0] + w[1] * v, acc[1] + w[2] * v, acc[2] + w[0] * v];
                }
                out[y * width + x] = acc;
            }
        }
        out
    };
    let (r, t) = (across(reference), across(test));
    let mut out = color;
    for y in 0..height {
        for x in 0..width {
            // Per image: dx, ddx (Gaussian down the columns), dy, ddy (derivatives down the columns).
            let mut d = [[0.0f32; 4]; 2];
            for iy in -half..=half {
                let w = filter[(iy + half) as usize];
                let k = clamp_index(y as i32 + iy, height) * width + x;
                for (s, image) in d.iter_mut().zip([&r, &t]) {
                    let c = image[k];
                    *s = [s[0] + w[0] * c[0], s[1] + w[0] * c[1], s[2] + w[1] * c[2], s[3] + w[2] * c[2]];
                }
            }
            let edge = d.map(|s| (s[0] * s[0] + s[2] * s[2]).sqrt());
            let point = d.map(|s| (s[1] * s[1] + s[3] * s[3]).sqrt());
            let feature = (norm * (edge[0] - edge[1]).abs().max((point[0] - point[1]).abs())).powf(QF);
            let k = y * width + x;
            out[k] = out[k].powf(1.0 - feature);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_black_reference_gives_finite_errors_in_range() {
        let black = vec![[0.0f32; 3]; 12 * 10];
        let grey: Vec<Rgb> = (0..120).map(|i| [0.01 * (i % 7) as f32; 3]).collect();
        for (reference, test) in [(&black, &grey), (&black, &black)] {
            let map = hdr_flip(reference, test, 12, 10);
            assert!(map.error.iter().all(|e| e.is_finite() && (0.0..=1.0).contains(e)), "{:?}", map.error);
        }
        assert!(hdr_flip(&black, &grey, 12, 10).mean() > 0.0);
    }
}
