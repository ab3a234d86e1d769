//! Error metrics (thesis equations 3.4 and 3.5).

use serde::Serialize;

/// ε of equation 3.5.
pub const RELMSE_EPSILON: f64 = 0.01;

/// The least noisy relMSE a normalised error divides by: a scene whose noisy
/// input is already exact (a black render) must not divide by zero.
pub const NOISY_RELMSE_FLOOR: f64 = 1e-12;

/// relMSE relative to the noisy input's (thesis 3.2.3): fitness and the report's "relMSE / noisy".
pub fn normalised(relmse: f64, noisy_relmse: f64) -> f64 {
    relmse / noisy_relmse.max(NOISY_RELMSE_FLOOR)
}

/// Errors of an image against a reference.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Errors {
    /// Equation 3.4: mean over pixels of the squared error summed over RGB.
    pub mse: f64,
    /// Equation 3.5 without the m/2 factor: mean over pixels of
    /// Σ_rgb (c − g)² / (g² + ε).
    pub relmse: f64,
    /// Equation 3.5 as printed, with the m/2 factor (m = samples per pixel);
    /// `None` when m is unknown.
    pub relmse_half_spp: Option<f64>,
    /// The image's mean luminance over the reference's: 1 keeps the light, below
    /// 1 is darker (a denoiser's bias); `None` for a black reference.
    pub light: Option<f64>,
}

/// One pixel's term of equation 3.5: Σ_rgb (c − g)² / (g² + ε).
pub fn pixel_relative_error<A: Copy + Into<f64>, B: Copy + Into<f64>>(c: &[A; 3], g: &[B; 3]) -> f64 {
    (0..3)
        .map(|q| {
            let (c, g): (f64, f64) = (c[q].into(), g[q].into());
            (c - g) * (c - g) / (g * g + RELMSE_EPSILON)
        })
        .sum()
}

/// Compare `image` with `reference`, both linear RGB.
pub fn errors<A: Copy + Into<f64>, B: Copy + Into<f64>>(
    image: &[[A; 3]],
    reference: &[[B; 3]],
    spp: Option<u32>,
) -> Errors {
    assert_eq!(image.len(), reference.len(), "images of equal size");
    let (mut se, mut rel) = (0.0f64, 0.0f64);
    for (c, g) in image.iter().zip(reference) {
        for q in 0..3 {
            let (c, g): (f64, f64) = (c[q].into(), g[q].into());
            se += (c - g) * (c - g);
        }
        rel += pixel_relative_error(c, g);
    }
    let n = image.len().max(1) as f64;
    let relmse = rel / n;
    Errors {
        mse: se / n,
        relmse,
        relmse_half_spp: spp.map(|m| relmse * m as f64 / 2.0),
        light: light(image, reference),
    }
}

/// How an output changes from one frame to the next where its reference
/// does not: a denoiser's flicker. Of two consecutive frames of an output
/// (`previous`, `image`) and of their references.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Temporal {
    /// F: the mean over pixels and channels of |(o_t − o_{t−1}) − (r_t − r_{t−1})|.
    pub flicker: f64,
    /// The mean over pixels of Σ_rgb ((o_t − o_{t−1}) − (r_t − r_{t−1}))² / (r_t² + ε),
    /// relMSE's form (equation 3.5) for the change between frames.
    pub relmse: f64,
}

/// [`Temporal`] of frame t against frame t − 1, all four images of one size.
pub fn temporal<A: Copy + Into<f64>, B: Copy + Into<f64>>(
    (previous, image): (&[[A; 3]], &[[A; 3]]),
    (previous_reference, reference): (&[[B; 3]], &[[B; 3]]),
) -> Temporal {
    assert!(
        [previous.len(), previous_reference.len(), reference.len()].iter().all(|n| *n == image.len()),
        "frames of equal size"
    );
    let (mut absolute, mut relative) = (0.0f64, 0.0f64);
    for p in 0..image.len() {
        for q in 0..3 {
            let change = image[p][q].into() - previous[p][q].into();
            let (r, r0): (f64, f64) = (reference[p][q].into(), previous_reference[p][q].into());
            let e = change - (r - r0);
            absolute += e.abs();
            relative += e * e / (r * r + RELMSE_EPSILON);
        }
    }
    let n = image.len().max(1) as f64;
    Temporal { flicker: absolute / (3.0 * n), relmse: relative / n }
}

/// Mean luminance (`pipeline::luminance`, the outlier rule's) of an image.
pub fn mean_luminance<A: Copy + Into<f64>>(image: &[[A; 3]]) -> f64 {
    let sum: f64 = image.iter().map(|c| crate::pipeline::luminance([c[0].into(), c[1].into(), c[2].into()])).sum();
    sum / image.len().max(1) as f64
}

/// `image`'s mean luminance over `reference`'s; `None` when the reference is black.
pub fn light<A: Copy + Into<f64>, B: Copy + Into<f64>>(image: &[[A; 3]], reference: &[[B; 3]]) -> Option<f64> {
    let reference = mean_luminance(reference);
    (reference > 0.0).then(|| mean_luminance(image) / reference)
}

/// How heavy-tailed an image's light is: the two statistics that tell a room
/// lit through a small opening (most pixels near black, a few carrying most
/// of the light) from a tamely lit one (docs/SCENES.md).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tails {
    /// The median pixel's luminance over the mean luminance (near 0: the median pixel is black).
    pub median_over_mean: f64,
    /// The share of the total luminance that the brightest 1 % of pixels hold.
    pub top_percent_share: f64,
}

/// [`Tails`] of an image; `None` when it is black (luminance clamped at 0 per pixel).
pub fn tails<A: Copy + Into<f64>>(image: &[[A; 3]]) -> Option<Tails> {
    let mut lum: Vec<f64> =
        image.iter().map(|c| crate::pipeline::luminance([c[0].into(), c[1].into(), c[2].into()]).max(0.0)).collect();
    let total: f64 = lum.iter().sum();
    if lum.is_empty() || total <= 0.0 {
        return None;
    }
    // Selections, not a sort: `filter` and `denoise` ask this of every frame they choose for.
    let brightest_first = |a: &f64, b: &f64| b.total_cmp(a);
    let (n, mean) = (lum.len(), total / lum.len() as f64);
    let median = *lum.select_nth_unstable_by(n / 2, brightest_first).1;
    let top = n.div_ceil(100);
    let _ = lum.select_nth_unstable_by(top - 1, brightest_first);
    Some(Tails { median_over_mean: median / mean, top_percent_share: lum[..top].iter().sum::<f64>() / total })
}

/// How far a mean-luminance ratio may stray from 1 before a method is said
/// to change the image's light (`filter` and `report` flag it).
pub const LIGHT_TOLERANCE: f64 = 0.03;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tails_tell_a_few_bright_pixels_from_an_even_light() {
        // 200 pixels: 198 black, 2 carrying everything.
        let mut image = vec![[0.0f32; 3]; 200];
        image[7] = [5.0; 3];
        image[90] = [3.0; 3];
        let t = tails(&image).unwrap();
        assert_eq!(t.median_over_mean, 0.0);
        assert!((t.top_percent_share - 1.0).abs() < 1e-12, "the top 2 pixels hold it all: {t:?}");
        // Even light: the median is the mean, the top 1 % holds 1 %.
        let t = tails(&vec![[0.5f32; 3]; 300]).unwrap();
        assert!((t.median_over_mean - 1.0).abs() < 1e-12 && (t.top_percent_share - 0.01).abs() < 1e-12, "{t:?}");
        assert_eq!(tails(&[[0.0f32; 3]; 10]), None);
    }

    #[test]
    fn relmse_follows_equation_3_5() {
        let image = [[1.0f32, 0.0, 0.0], [0.0, 0.0, 0.0]];
        let reference = [[0.0f32, 0.0, 0.0], [0.0, 0.0, 0.0]];
        let e = errors(&image, &reference, Some(4));
        assert!((e.relmse - 50.0).abs() < 1e-9, "(1/2) * 1/(0 + 0.01)");
        assert_eq!(e.relmse_half_spp, Some(100.0));
        assert_eq!(e.mse, 0.5);
        assert_eq!(e.light, None, "a black reference has no light to keep");
    }

    #[test]
    fn flicker_counts_change_the_reference_does_not_have() {
        let (r0, r1) = ([[0.0f32; 3], [1.0; 3]], [[0.0f32; 3], [2.0; 3]]);
        // Following the reference's change exactly is no flicker, whatever the offset.
        let follows = ([[0.5f32; 3], [1.5; 3]], [[0.5f32; 3], [2.5; 3]]);
        let t = temporal((&follows.0, &follows.1), (&r0, &r1));
        assert_eq!((t.flicker, t.relmse), (0.0, 0.0));
        // A still output where the reference brightens by 1 in one of two pixels: F is 1 in half the channels.
        let still = ([[0.0f32; 3], [1.0; 3]], [[0.0f32; 3], [1.0; 3]]);
        let t = temporal((&still.0, &still.1), (&r0, &r1));
        assert!((t.flicker - 0.5).abs() < 1e-12, "{t:?}");
        assert!((t.relmse - 3.0 / (4.0 + RELMSE_EPSILON) / 2.0).abs() < 1e-12, "{t:?}");
    }

    #[test]
    fn light_is_the_ratio_of_mean_luminances() {
        let reference = [[1.0f32, 1.0, 1.0], [0.0, 0.0, 0.0]];
        let darker = [[0.5f32, 0.5, 0.5], [0.0, 0.0, 0.0]];
        // The same mean moved between pixels keeps the light; halving it does not.
        let moved = [[0.0f32, 0.0, 0.0], [1.0, 1.0, 1.0]];
        assert!((errors(&darker, &reference, None).light.unwrap() - 0.5).abs() < 1e-12);
        assert!((errors(&moved, &reference, None).light.unwrap() - 1.0).abs() < 1e-12);
        // Only green: its luminance weight.
        let green = [[0.0f32, 1.0, 0.0], [0.0, 0.0, 0.0]];
        assert!((light(&green, &reference).unwrap() - crate::pipeline::LUMINANCE[1]).abs() < 1e-12);
    }
}
