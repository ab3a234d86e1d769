//! Errors of tiles pooled into errors of scenes, and the noisy input's error
//! over exactly the pixels that count: pure functions of numbers and images.

use crate::gpu::{FitnessError, Region};
use crate::metrics;
use crate::scene::Scene;

/// For each scored image (a tile), the scene it was cut from and how many pixels it counts.
pub(super) type Pooling = Vec<(usize, f64)>;

/// One error per scene from one per tile: a scene's relMSE is the
/// pixel-weighted mean over its tiles' counted pixels, its flags any tile's.
pub(super) fn pool_errors(row: &[FitnessError], pooling: &Pooling, scenes: usize) -> Vec<FitnessError> {
    let mut out = vec![(0.0, 0.0, 0u32, true); scenes];
    for (e, (scene, pixels)) in row.iter().zip(pooling) {
        let pooled = &mut out[*scene];
        pooled.0 += e.relmse * pixels;
        pooled.1 += pixels;
        pooled.2 |= e.flags;
        pooled.3 &= e.finite;
    }
    out.into_iter().map(|(sum, n, flags, finite)| FitnessError { relmse: sum / n, flags, finite }).collect()
}

/// relMSE of a scene's noisy input against its reference, over `region` (all of it when `None`).
pub(super) fn noisy_relmse(scene: &Scene, region: Option<Region>) -> f64 {
    let reference = scene.reference.as_ref().expect("fitness scenes have references");
    let Some(r) = region else { return metrics::errors(&scene.color, reference, scene.spp).relmse };
    // Only the two images the error reads, not a crop of every feature.
    let inside = |image: &[[f32; 3]]| -> Vec<[f32; 3]> {
        let (x, width) = (r.x as usize, r.width as usize);
        (r.y as usize..(r.y + r.height) as usize)
            .flat_map(|row| image[row * scene.width + x..row * scene.width + x + width].iter().copied())
            .collect()
    };
    metrics::errors(&inside(&scene.color), &inside(reference), scene.spp).relmse
}

/// The noisy input's relMSE per scene, pooled as [`pool_errors`] pools a candidate's.
pub(super) fn noisy_per_scene(
    scored: &[Scene],
    counted: &[Option<Region>],
    pooling: Option<&Pooling>,
    scenes: usize,
) -> Vec<f64> {
    match pooling {
        None => scored.iter().map(|s| noisy_relmse(s, None)).collect(),
        Some(pooling) => {
            let mut sums = vec![(0.0f64, 0.0f64); scenes];
            for ((s, region), (owner, pixels)) in scored.iter().zip(counted).zip(pooling) {
                sums[*owner].0 += noisy_relmse(s, *region) * pixels;
                sums[*owner].1 += pixels;
            }
            sums.iter().map(|(sum, n)| sum / n).collect()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_scenes_error_is_its_tiles_pixel_weighted_mean_and_any_flag() {
        let e = |relmse, flags, finite| FitnessError { relmse, flags, finite };
        let row = [e(1.0, 0, true), e(4.0, 2, true), e(10.0, 0, false)];
        // Tiles 0 and 1 are scene 0's (100 and 300 pixels), tile 2 scene 1's.
        let pooled = pool_errors(&row, &vec![(0, 100.0), (0, 300.0), (1, 50.0)], 2);
        assert_eq!(pooled[0].relmse, (1.0 * 100.0 + 4.0 * 300.0) / 400.0);
        assert_eq!((pooled[0].flags, pooled[0].finite), (2, true));
        assert_eq!((pooled[1].relmse, pooled[1].flags, pooled[1].finite), (10.0, 0, false));
    }

    #[test]
    fn the_noisy_error_over_a_region_reads_only_that_region() {
        let mut scene = Scene::from_color("s", 4, 4, vec![[1.0; 3]; 16]);
        let mut reference = vec![[1.0f32; 3]; 16];
        reference[0] = [2.0; 3]; // outside the region below
        scene.reference = Some(reference);
        scene.spp = Some(4);
        let region = Region { x: 2, y: 2, width: 2, height: 2 };
        assert_eq!(noisy_relmse(&scene, Some(region)), 0.0);
        assert!(noisy_relmse(&scene, None) > 0.0);
    }
}
