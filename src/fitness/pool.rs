//! Errors of tiles pooled into errors of scenes, and the noisy input's error
//! over exactly the pixels that count: pure functions of numbers and images.

use crate::gpu::{Region, SceneScore};
use crate::metrics;
use crate::scene::Scene;

/// For each scored image (a tile), the scene it was cut from and how many pixels it counts.
pub(super) type Pooling = Vec<(usize, f64)>;

/// The pixels of a scored image whose errors count: all when `None`, else
/// these disjoint rectangles (tiles' interiors).
pub(super) type Counted = Option<Vec<Region>>;

/// One error per scene from one per tile: a scene's relMSE and luminance
/// are the pixel-weighted means over its tiles' counted pixels, its flags
/// any tile's.
pub(super) fn pool_errors(row: &[SceneScore], pooling: &Pooling, scenes: usize) -> Vec<SceneScore> {
    let mut out = vec![(0.0, 0.0, 0.0, 0u32, true); scenes];
    for (e, (scene, pixels)) in row.iter().zip(pooling) {
        let pooled = &mut out[*scene];
        pooled.0 += e.relmse * pixels;
        pooled.1 += e.luminance * pixels;
        pooled.2 += pixels;
        pooled.3 |= e.flags;
        pooled.4 &= e.finite;
    }
    out.into_iter()
        .map(|(sum, luminance, n, flags, finite)| SceneScore {
            relmse: sum / n,
            luminance: luminance / n,
            flags,
            finite,
        })
        .collect()
}

/// The noisy input's error against its reference, and its mean luminance,
/// over `regions` (all of it when `None`): what a candidate's are measured against.
pub(super) fn noisy_error(scene: &Scene, regions: Option<&[Region]>) -> SceneScore {
    let reference = scene.reference.as_ref().expect("fitness scenes have references");
    let measure = |color: &[[f32; 3]], reference: &[[f32; 3]]| SceneScore {
        relmse: metrics::errors(color, reference, scene.spp).relmse,
        luminance: metrics::mean_luminance(color),
        flags: 0,
        finite: true,
    };
    let Some(regions) = regions else { return measure(&scene.color, reference) };
    // Only the two images the error reads, not a crop of every feature.
    let inside = |image: &[[f32; 3]]| -> Vec<[f32; 3]> {
        let rows = |r: &Region| {
            let (x, width) = (r.x as usize, r.width as usize);
            (r.y as usize..(r.y + r.height) as usize).map(move |row| (row * scene.width + x, width))
        };
        regions.iter().flat_map(rows).flat_map(|(start, width)| image[start..start + width].iter().copied()).collect()
    };
    measure(&inside(&scene.color), &inside(reference))
}

/// The noisy input's error per scene, pooled as [`pool_errors`] pools a candidate's.
pub(super) fn noisy_per_scene(
    scored: &[Scene],
    counted: &[Counted],
    pooling: Option<&Pooling>,
    scenes: usize,
) -> Vec<SceneScore> {
    let row: Vec<SceneScore> = scored.iter().zip(counted).map(|(s, r)| noisy_error(s, r.as_deref())).collect();
    match pooling {
        None => row,
        Some(pooling) => pool_errors(&row, pooling, scenes),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_scenes_error_is_its_tiles_pixel_weighted_mean_and_any_flag() {
        let e = |relmse, flags, finite| SceneScore { relmse, luminance: relmse * 2.0, flags, finite };
        let row = [e(1.0, 0, true), e(4.0, 2, true), e(10.0, 0, false)];
        // Tiles 0 and 1 are scene 0's (100 and 300 pixels), tile 2 scene 1's.
        let pooled = pool_errors(&row, &vec![(0, 100.0), (0, 300.0), (1, 50.0)], 2);
        assert_eq!(pooled[0].relmse, (1.0 * 100.0 + 4.0 * 300.0) / 400.0);
        assert_eq!(pooled[0].luminance, (2.0 * 100.0 + 8.0 * 300.0) / 400.0);
        assert_eq!((pooled[0].flags, pooled[0].finite), (2, true));
        assert_eq!((pooled[1].relmse, pooled[1].flags, pooled[1].finite), (10.0, 0, false));
    }

    #[test]
    fn the_noisy_error_and_light_over_a_region_read_only_that_region() {
        let mut scene = Scene::from_color("s", 4, 4, vec![[1.0; 3]; 16]);
        let mut reference = vec![[1.0f32; 3]; 16];
        reference[0] = [2.0; 3]; // outside the region below
        scene.reference = Some(reference);
        scene.spp = Some(4);
        let region = [Region { x: 2, y: 2, width: 2, height: 2 }];
        assert_eq!(noisy_error(&scene, Some(&region)).relmse, 0.0);
        assert!(noisy_error(&scene, None).relmse > 0.0);
        scene.color[0] = [0.0; 3];
        assert_eq!(noisy_error(&scene, Some(&region)).luminance, 1.0);
        assert_eq!(noisy_error(&scene, None).luminance, 15.0 / 16.0);
        // Two regions count as their pixels together: here 4 of 1 and 2 of 0.
        let two = [region[0], Region { x: 0, y: 0, width: 2, height: 1 }];
        assert_eq!(noisy_error(&scene, Some(&two)).luminance, 5.0 / 6.0);
    }
}
