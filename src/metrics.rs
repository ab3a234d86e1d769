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
    Errors { mse: se / n, relmse, relmse_half_spp: spp.map(|m| relmse * m as f64 / 2.0) }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn relmse_follows_equation_3_5() {
        let image = [[1.0f32, 0.0, 0.0], [0.0, 0.0, 0.0]];
        let reference = [[0.0f32, 0.0, 0.0], [0.0, 0.0, 0.0]];
        let e = errors(&image, &reference, Some(4));
        assert!((e.relmse - 50.0).abs() < 1e-9, "(1/2) * 1/(0 + 0.01)");
        assert_eq!(e.relmse_half_spp, Some(100.0));
        assert_eq!(e.mse, 0.5);
    }
}
