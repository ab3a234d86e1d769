//! Fitness on tiles: each training scene contributes a few S×S tiles
//! instead of all its pixels, so that a generation on full-size renders
//! costs what one on small scenes does.
//!
//! A tile is cut from the scene with a halo as wide as everything the
//! pipeline reads around a pixel (the pre-pass's neighbourhood, the window
//! or the whole à-trous cascade), rounded up to whole workgroups; only its
//! interior counts (`gpu::Region`). So an interior pixel is filtered from the
//! same data as in the whole image: its error is the one the whole image
//! would give it, bit for bit (tested), but for expressions that read
//! absolute pixel positions (`dot(pixel)`, `distance2(normal, pixel)`),
//! which see the tile's own coordinates. The run scores its hall of fame on
//! whole images at the end.
//!
//! Tiles are fixed for a run: drawn once from the run's seed, from a grid of
//! S×S cells (without repeats), so fitness values stay comparable across
//! generations, the hall of fame stays meaningful, and a resumed run cuts the
//! same tiles.

use serde::{Deserialize, Serialize};

use crate::gpu::Region;
use crate::jit::WORKGROUP;
use crate::pipeline::{FilterPipeline, Form, OUTLIER_RADIUS};
use crate::rng::Rng;
use crate::scene::Scene;

/// How many tiles of what size each training scene contributes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct TileSampling {
    /// Tiles per scene (a scene with fewer cells gives all of them).
    pub count: u32,
    /// Side of a tile's counted interior, in pixels (a multiple of the workgroup's 8).
    pub size: u32,
}

impl std::fmt::Display for TileSampling {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}x{}", self.count, self.size)
    }
}

impl std::str::FromStr for TileSampling {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, String> {
        let bad = |why: &str| {
            format!("fitness tiles `{text}`: {why} (write COUNTxSIZE, e.g. `8x32`: 8 tiles of 32x32 pixels per scene)")
        };
        let (count, size) = text.split_once('x').ok_or_else(|| bad("no `x`"))?;
        let count: u32 = count.trim().parse().map_err(|_| bad("the count is not a whole number"))?;
        let size: u32 = size.trim().parse().map_err(|_| bad("the size is not a whole number"))?;
        if count == 0 {
            return Err(bad("at least one tile per scene"));
        }
        if size == 0 || !size.is_multiple_of(WORKGROUP[0]) || !size.is_multiple_of(WORKGROUP[1]) {
            return Err(bad(&format!("the size must be a positive multiple of {}", WORKGROUP[0])));
        }
        Ok(TileSampling { count, size })
    }
}

/// How far from a pixel the whole pipeline reads, in pixels: the outlier
/// pre-pass's neighbourhood (and `keep`'s spread of what it clamps; with
/// `keep=surface` also its light floor, a mean over the whole image, which a
/// tile takes over its crop: the one thing a tile only approximates), the
/// first pass's `guide` (blurred once more; counted whether or not the weight
/// reads it), then the window's radius or the sum of the à-trous passes'
/// reaches (each pass filters the previous one's output), then `planefit`'s
/// radius and `pixelfilter`'s one pixel.
pub fn reach(pipeline: &FilterPipeline, radius: u32) -> u32 {
    let prepass = match pipeline.outliers {
        Some(outliers) => OUTLIER_RADIUS + outliers.keep.map_or(0, |keep| keep.reach()),
        None => 0,
    };
    let form = match pipeline.form {
        Form::Window => radius,
        Form::Atrous { passes, .. } => {
            (0..passes).map(|level| pipeline.pass_radius(radius) * FilterPipeline::step(level)).sum()
        }
    };
    let fit = pipeline.planefit.map_or(0, |fit| fit.radius);
    let pixel_filter = u32::from(pipeline.pixel_filter.is_some());
    prepass + crate::pipeline::GUIDE_STENCIL.half_width() as u32 + form + fit + pixel_filter
}

/// The halo cut around a tile: the pipeline's reach, rounded up to whole
/// workgroups so that the interior is a set of whole reduction partials.
pub fn halo(pipeline: &FilterPipeline, radius: u32) -> u32 {
    reach(pipeline, radius).div_ceil(WORKGROUP[0].max(WORKGROUP[1])) * WORKGROUP[0].max(WORKGROUP[1])
}

/// One tile: the crop (interior and halo) and where its interior lies in it.
pub struct Tile {
    /// Index of the training scene it was cut from.
    pub scene: usize,
    pub crop: Scene,
    /// The pixels that count, disjoint interiors of the cells drawn (one, or
    /// several sharing a crop); `None`: all of them (a scene too small to tile).
    pub counted: Option<Vec<Region>>,
}

impl Tile {
    /// How many pixels count.
    pub fn pixels(&self) -> usize {
        self.counted.as_ref().map_or(self.crop.pixels(), |r| r.iter().map(|r| r.pixels() as usize).sum())
    }
}

/// The tiles of every scene, drawn from `seed`. A scene without two whole
/// cells is one tile: the whole scene, every pixel counted. Where a scene's
/// tiles' crops, halos included, would hold as many pixels as one crop
/// around them all, they are that one crop with every interior counted.
pub fn cut(scenes: &[Scene], sampling: TileSampling, pipeline: &FilterPipeline, radius: u32, seed: u64) -> Vec<Tile> {
    let halo = halo(pipeline, radius) as usize;
    let size = sampling.size as usize;
    let mut tiles = Vec::new();
    for (index, scene) in scenes.iter().enumerate() {
        let (across, down) = (scene.width / size, scene.height / size);
        if across * down <= 1 {
            tiles.push(Tile { scene: index, crop: scene.crop(0, 0, scene.width, scene.height), counted: None });
            continue;
        }
        // A stream per scene, so that adding a scene does not move another's tiles.
        let mut rng = Rng::seeded(seed ^ 0x7469_6c65_7300_0000 ^ (index as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15));
        let mut cells: Vec<(usize, usize)> = (0..down).flat_map(|r| (0..across).map(move |c| (c, r))).collect();
        let wanted = (sampling.count as usize).min(cells.len());
        // A partial Fisher–Yates shuffle: the first `wanted` cells, without repeats.
        for k in 0..wanted {
            let j = k + rng.below(cells.len() - k);
            cells.swap(k, j);
        }
        let mut chosen = cells[..wanted].to_vec();
        chosen.sort_unstable_by_key(|&(c, r)| (r, c));
        let cells: Vec<(usize, usize)> = chosen.into_iter().map(|(c, r)| (c * size, r * size)).collect();
        let crop_of = |&(x, y): &(usize, usize)| {
            let (x0, y0) = (x.saturating_sub(halo), y.saturating_sub(halo));
            (x0, y0, (x + size + halo).min(scene.width), (y + size + halo).min(scene.height))
        };
        let crops: Vec<(usize, usize, usize, usize)> = cells.iter().map(crop_of).collect();
        let interior = |&(x, y): &(usize, usize), (x0, y0): (usize, usize)| Region {
            x: (x - x0) as u32,
            y: (y - y0) as u32,
            width: size as u32,
            height: size as u32,
        };
        // A wide reach (`keep=surface`'s spread) makes the crops overlap
        // most of the scene: then one crop around them all, counting each
        // interior, filters fewer pixels for the same errors.
        let area = |&(x0, y0, x1, y1): &(usize, usize, usize, usize)| (x1 - x0) * (y1 - y0);
        let around = crops
            .iter()
            .fold((scene.width, scene.height, 0, 0), |a, c| (a.0.min(c.0), a.1.min(c.1), a.2.max(c.2), a.3.max(c.3)));
        if crops.iter().map(area).sum::<usize>() >= area(&around) {
            let (x0, y0, x1, y1) = around;
            let counted = cells.iter().map(|cell| interior(cell, (x0, y0))).collect();
            tiles.push(Tile { scene: index, crop: scene.crop(x0, y0, x1 - x0, y1 - y0), counted: Some(counted) });
            continue;
        }
        for (cell, &(x0, y0, x1, y1)) in cells.iter().zip(&crops) {
            let counted = vec![interior(cell, (x0, y0))];
            tiles.push(Tile { scene: index, crop: scene.crop(x0, y0, x1 - x0, y1 - y0), counted: Some(counted) });
        }
    }
    tiles
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::{Keep, Outliers};

    #[test]
    fn sampling_parses_and_says_what_is_wrong() {
        assert_eq!("8x32".parse::<TileSampling>(), Ok(TileSampling { count: 8, size: 32 }));
        assert_eq!(TileSampling { count: 8, size: 32 }.to_string(), "8x32");
        for bad in ["8", "0x32", "8x30", "ax32", "8x0"] {
            let error = bad.parse::<TileSampling>().unwrap_err();
            assert!(error.contains(bad) && error.contains("COUNTxSIZE"), "{error}");
        }
    }

    #[test]
    fn the_halo_covers_what_the_pipeline_reads() {
        // The window's radius and the guide's one pixel.
        assert_eq!(reach(&FilterPipeline::WINDOW, 3), 4);
        assert_eq!(halo(&FilterPipeline::WINDOW, 3), 8);
        assert_eq!(halo(&FilterPipeline::WINDOW, 10), 16);
        let atrous = FilterPipeline {
            outliers: Some(Outliers { k: 2.0, trim: false, keep: None }),
            demodulate: true,
            temporal: None,
            form: Form::Atrous { passes: 5, stencil: Default::default() },
            planefit: None,
            anchor: None,
            pixel_filter: None,
        };
        // 2 (pre-pass) + 1 (guide) + 2 · (1 + 2 + 4 + 8 + 16).
        assert_eq!(reach(&atrous, 3), 65);
        assert_eq!(halo(&atrous, 3), 72);
        let keep =
            FilterPipeline { outliers: Some(Outliers { k: 2.0, trim: false, keep: Some(Keep::Even) }), ..atrous };
        // The spread of what the clamp removed reaches 31 more, 127 along the surface.
        assert_eq!(reach(&keep, 3), 96);
        let surface =
            FilterPipeline { outliers: Some(Outliers { k: 2.0, trim: false, keep: Some(Keep::Surface) }), ..atrous };
        assert_eq!(reach(&surface, 3), 192);
        let fitted = FilterPipeline { planefit: Some(crate::pipeline::PlaneFit { radius: 3 }), ..surface };
        assert_eq!(reach(&fitted, 3), 195);
    }

    #[test]
    fn tiles_are_distinct_cells_with_their_halo_and_the_same_for_the_same_seed() {
        let scene = numbered_scene();
        let sampling = TileSampling { count: 4, size: 16 };
        let tiles = cut(std::slice::from_ref(&scene), sampling, &FilterPipeline::WINDOW, 3, 5);
        assert_eq!(tiles.len(), 4);
        let mut origins = Vec::new();
        for t in &tiles {
            let [counted] = t.counted.as_deref().expect("a tiled scene's tiles count their interiors") else {
                panic!("a small halo keeps one cell to a crop");
            };
            let (x0, y0) = origin(t);
            let (x0, y0) = (x0 as usize, y0 as usize);
            let (x, y) = (x0 + counted.x as usize, y0 + counted.y as usize);
            assert!(x % 16 == 0 && y % 16 == 0 && counted.width == 16, "{counted:?}");
            // The crop holds the scene's own pixels, and a halo of 8 wherever the scene has them.
            assert_eq!(t.crop.color[counted.y as usize * t.crop.width + counted.x as usize][0], (y * 96 + x) as f32);
            assert_eq!(counted.x, x.min(8) as u32);
            assert!(x0 + t.crop.width == (x + 16 + 8).min(96));
            origins.push((x, y));
        }
        origins.sort();
        origins.dedup();
        assert_eq!(origins.len(), 4, "distinct cells");
        let again = cut(std::slice::from_ref(&scene), sampling, &FilterPipeline::WINDOW, 3, 5);
        assert!(tiles.iter().zip(&again).all(|(a, b)| a.crop.name == b.crop.name));
        let other = cut(std::slice::from_ref(&scene), sampling, &FilterPipeline::WINDOW, 3, 6);
        assert!(tiles.iter().zip(&other).any(|(a, b)| a.crop.name != b.crop.name), "another seed, other tiles");
    }

    /// A 96x80 scene whose pixel i has red i: a crop's pixels say where they came from.
    fn numbered_scene() -> Scene {
        let color: Vec<[f32; 3]> = (0..96 * 80).map(|i| [i as f32, 0.0, 0.0]).collect();
        Scene::from_color("s", 96, 80, color)
    }

    /// Where a tile's crop lies in its scene, from the crop's name (`NAME@X,Y`).
    fn origin(t: &Tile) -> (u32, u32) {
        let (x0, y0) = t.crop.name.rsplit_once('@').unwrap().1.split_once(',').unwrap();
        (x0.parse().unwrap(), y0.parse().unwrap())
    }

    /// The cells' top-left corners in the scene, whichever crops count them.
    fn cells(tiles: &[Tile]) -> Vec<(u32, u32)> {
        let mut cells: Vec<(u32, u32)> = tiles
            .iter()
            .flat_map(|t| {
                let (x0, y0) = origin(t);
                t.counted.as_ref().unwrap().iter().map(move |r| (x0 + r.x, y0 + r.y))
            })
            .collect();
        cells.sort_unstable();
        cells
    }

    #[test]
    fn tiles_whose_crops_would_cover_one_crop_around_them_all_share_it() {
        let scene = numbered_scene();
        let sampling = TileSampling { count: 4, size: 16 };
        let window = cut(std::slice::from_ref(&scene), sampling, &FilterPipeline::WINDOW, 3, 5);
        // `keep=surface` reaches 192 pixels: every crop would be most of the scene.
        let surface = FilterPipeline {
            outliers: Some(Outliers { k: 2.0, trim: false, keep: Some(Keep::Surface) }),
            demodulate: true,
            temporal: None,
            form: Form::Atrous { passes: 4, stencil: Default::default() },
            planefit: None,
            anchor: None,
            pixel_filter: None,
        };
        let shared = cut(std::slice::from_ref(&scene), sampling, &surface, 3, 5);
        assert_eq!(shared.len(), 1);
        assert_eq!((shared[0].crop.width, shared[0].crop.height), (96, 80));
        assert_eq!(shared[0].pixels(), 4 * 16 * 16);
        // The same cells are drawn and counted, whatever the halo.
        assert_eq!(cells(&shared).len(), 4);
        assert_eq!(cells(&shared), cells(&window));
        for (x, y) in cells(&shared) {
            let r = shared[0].counted.as_ref().unwrap().iter().find(|r| (r.x, r.y) == (x, y)).unwrap();
            assert_eq!(shared[0].crop.color[(r.y * 96 + r.x) as usize][0], (y * 96 + x) as f32);
        }
        // Two far-apart cells with a small halo keep crops of their own.
        let wide = Scene::from_color("w", 256, 16, vec![[1.0; 3]; 256 * 16]);
        let two = cut(std::slice::from_ref(&wide), TileSampling { count: 2, size: 16 }, &FilterPipeline::WINDOW, 1, 3);
        let apart = cells(&two);
        assert!(two.len() == 2 || apart[1].0 - apart[0].0 <= 2 * 16, "{apart:?}");
    }

    #[test]
    fn a_scene_without_two_cells_is_scored_whole() {
        let scene = Scene::from_color("small", 20, 12, vec![[1.0; 3]; 240]);
        let tiles =
            cut(std::slice::from_ref(&scene), TileSampling { count: 4, size: 16 }, &FilterPipeline::WINDOW, 3, 1);
        assert_eq!(tiles.len(), 1);
        assert!(tiles[0].counted.is_none() && tiles[0].pixels() == 240);
    }
}
