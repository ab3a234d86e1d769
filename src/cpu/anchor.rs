//! `anchor=K`'s reference (docs/SEMANTICS.md, "The pipeline"): the
//! filtered image's light pulled to the noisy frame's at a coarse scale,
//! formula for formula as `templates/anchor.wgsl.tera`.

use crate::pipeline;

/// `anchor=K` on the filtered `image` of the noisy `frame` (docs/SEMANTICS.md,
/// "The pipeline"; the formula at [`pipeline::Anchor`]): the sums (l, l², o)
/// averaged over 2×2 blocks into the half-resolution grid, blurred there
/// level by level with the cubic B-spline at steps 1, 2, taps outside the
/// frame or the grid clamped to its edge and each step's sums stored as f32,
/// then interpolated bilinearly to each pixel, which is scaled. The reference of `templates/anchor.wgsl.tera`.
pub fn anchor_light(
    frame: &[[f32; 3]],
    image: &[[f32; 3]],
    width: usize,
    height: usize,
    anchor: pipeline::Anchor,
) -> Vec<[f64; 3]> {
    use pipeline::{luminance, Anchor, ANCHOR_ERROR_FLOOR, ANCHOR_LEVELS, ANCHOR_LIGHT_FLOOR};
    let f64s = |c: [f32; 3]| c.map(f64::from);
    let (w, h) = (width as i64, height as i64);
    let (gw, gh) = Anchor::grid(width as u32, height as u32);
    let (gw, gh) = (gw as i64, gh as i64);
    // The frame's pixel (x, y)'s sums (l, l², o), clamped to the frame.
    let pixel_sums = |x: i64, y: i64| {
        let i = (y.clamp(0, h - 1) * w + x.clamp(0, w - 1)) as usize;
        let l = luminance(f64s(frame[i])) as f32;
        [l, l * l, luminance(f64s(image[i])) as f32].map(f64::from)
    };
    // The 2×2 blocks averaged into the grid, stored as f32 as on the device.
    let mut sums: Vec<[f32; 3]> = Vec::with_capacity((gw * gh) as usize);
    for y in 0..gh {
        for x in 0..gw {
            let mut sum = [0.0f64; 3];
            for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                let v = pixel_sums(2 * x + dx, 2 * y + dy);
                for k in 0..3 {
                    sum[k] += 0.25 * v[k];
                }
            }
            sums.push(sum.map(|v| v as f32));
        }
    }
    // The grid's texel (x, y), clamped to the grid.
    let texel = |sums: &[[f32; 3]], x: i64, y: i64| {
        sums[(y.clamp(0, gh - 1) * gw + x.clamp(0, gw - 1)) as usize].map(f64::from)
    };
    let stencil = Anchor::STENCIL;
    let half = stencil.half_width() as i64;
    for level in 0..ANCHOR_LEVELS {
        let step = Anchor::step(level) as i64;
        let mut next = Vec::with_capacity(sums.len());
        for y in 0..gh {
            for x in 0..gw {
                let mut sum = [0.0f64; 3];
                for dy in -half..=half {
                    for dx in -half..=half {
                        let weight = stencil.weight(dx as i32) * stencil.weight(dy as i32);
                        let v = texel(&sums, x + dx * step, y + dy * step);
                        for k in 0..3 {
                            sum[k] += weight * v[k];
                        }
                    }
                }
                next.push(sum.map(|v| v as f32));
            }
        }
        sums = next;
    }
    // Along one axis, the lower of the two texels around pixel x (centres at
    // 2k + 0.5) and its weight: 0.25 below an even pixel, 0.75 below an odd one.
    let lower = |x: i64| if x % 2 == 0 { (x / 2 - 1, 0.25) } else { (x / 2, 0.75) };
    let samples = f64::from(Anchor::samples());
    let gate = f64::from(anchor.gate);
    let mut out = Vec::with_capacity(image.len());
    for y in 0..h {
        for x in 0..w {
            let ((x0, wx), (y0, wy)) = (lower(x), lower(y));
            let row = |y: i64| {
                let (a, b) = (texel(&sums, x0, y), texel(&sums, x0 + 1, y));
                std::array::from_fn::<f64, 3, _>(|k| wx * a[k] + (1.0 - wx) * b[k])
            };
            let (above, below) = (row(y0), row(y0 + 1));
            let [frame_light, frame_square, out_light]: [f64; 3] =
                std::array::from_fn(|k| wy * above[k] + (1.0 - wy) * below[k]);
            let error = ((frame_square - frame_light * frame_light).max(0.0) / samples).sqrt() + ANCHOR_ERROR_FLOOR;
            let pull = (((frame_light - out_light).abs() / error - gate) / gate).clamp(0.0, 1.0);
            let scale = 1.0 + pull * (frame_light / out_light.max(ANCHOR_LIGHT_FLOOR) - 1.0);
            out.push(f64s(image[(y * w + x) as usize]).map(|v| v * scale));
        }
    }
    out
}

#[cfg(test)]
mod anchor_tests {
    use super::anchor_light;
    use crate::pipeline::{luminance, Anchor};
    use crate::rng::Rng;

    fn mean_light(image: &[[f64; 3]]) -> f64 {
        image.iter().map(|&c| luminance(c)).sum::<f64>() / image.len() as f64
    }

    #[test]
    fn the_anchor_restores_lost_light_and_leaves_light_within_the_noise() {
        let (width, height) = (64, 64);
        let mut rng = Rng::seeded(7);
        // A noisy frame of mean light 1 (one sample a pixel, exponential-ish noise).
        let frame: Vec<[f32; 3]> = (0..width * height)
            .map(|_| {
                let v = -(1.0 - rng.unit()).ln() as f32;
                [v, v, v]
            })
            .collect();
        // A filter that lost 40 % of the light is pulled back to the frame's...
        let dark: Vec<[f32; 3]> = vec![[0.6; 3]; width * height];
        let anchored = anchor_light(&frame, &dark, width, height, Anchor::SHIPPED);
        let light = mean_light(&anchored);
        assert!((light - 1.0).abs() < 0.05, "pulled to the frame's light: {light}");
        // ...one within the frame's noise of it is mostly left alone: not
        // where the frame's local mean strays past the gate by chance, nor
        // always near the edges, where clamped taps repeat pixels and the
        // blur averages fewer samples than `Anchor::samples` says.
        let close: Vec<[f32; 3]> = vec![[0.995; 3]; width * height];
        let kept = anchor_light(&frame, &close, width, height, Anchor::SHIPPED);
        let still = kept.iter().zip(&close).filter(|(a, b)| a[0] == b[0] as f64).count();
        assert!(still as f64 >= 0.75 * close.len() as f64, "{still} of {} pixels kept", close.len());
        // Every output is finite on a black frame, where the blurred lights are 0.
        let black = vec![[0.0f32; 3]; width * height];
        assert!(anchor_light(&black, &dark, width, height, Anchor::SHIPPED).iter().flatten().all(|v| v.is_finite()));
    }
}
