//! The temporal stage's reference (docs/SEMANTICS.md, "The temporal
//! stage"): each frame's colour blended into the history reprojected from
//! the frame before, with the luminance's moments, the history's length
//! and the variance of the blend; `templates/temporal.wgsl.tera` computes
//! the same, formula for formula, in f32. Positions are computed in f32 as
//! on the device, so that both pick the same taps.

use super::Neumaier;
use crate::pipeline::{self, Temporal};
use crate::scene::Motion;

/// What the temporal stage keeps from one frame for the next, stored as
/// f32 as on the device.
#[derive(Clone, Debug, PartialEq)]
pub struct History {
    pub width: usize,
    pub height: usize,
    /// The history's colour: the image `feedback` passes of the form made
    /// of the last frame (demodulated where the pipeline demodulates).
    pub color: Vec<[f32; 3]>,
    /// Per pixel: the luminance's first and second moments, the blend's
    /// variance factor r (Σ of its squared shares) and the history's length.
    pub moments: Vec<[f32; 4]>,
    /// The last frame's surface and albedo ([`Motion::surface`], [`Motion::albedo`]).
    pub surface: Vec<[f32; 4]>,
    pub albedo: Vec<[f32; 4]>,
    /// The modulation blended over frames ([`Accumulated::modulation`]).
    pub modulation: Vec<[f32; 3]>,
}

/// What the stage makes of one frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Accumulated {
    /// The blend, which the form filters.
    pub color: Vec<[f32; 3]>,
    /// The moments the next frame's history keeps ([`History::moments`]).
    pub moments: Vec<[f32; 4]>,
    /// `temporalVariance`: the variance of the blend's luminance.
    pub variance: Vec<f32>,
    /// `historyLength`: the frames in each pixel's blend, this one included.
    pub length: Vec<f32>,
    /// The modulation max(albedo, `pipeline::ALBEDO_FLOOR`) blended as the
    /// colour is: what a demodulating pipeline multiplies its result back by,
    /// the albedo averaged over the pixel's samples of many frames.
    pub modulation: Vec<[f32; 3]>,
}

/// The running sums of a history's colour, moments and modulation over taps.
type Sums = ([Neumaier; 3], [Neumaier; 4], [Neumaier; 3]);

/// A pixel's history as the taps it was read from give it.
struct Taken {
    color: [f64; 3],
    moments: [f64; 4],
    modulation: [f64; 3],
}

/// The temporal stage on one frame: `color` (as the pre-pass left it),
/// `motion` its vectors and surface, `history` what the frame before left
/// (none for a sequence's first frame).
pub fn accumulate(
    temporal: Temporal,
    color: &[[f32; 3]],
    motion: &Motion,
    width: usize,
    height: usize,
    history: Option<&History>,
) -> Accumulated {
    let luminance: Vec<f64> = color.iter().map(|c| pipeline::luminance(c.map(f64::from))).collect();
    let (w, h) = (width as i64, height as i64);
    let mut out = Accumulated {
        color: Vec::with_capacity(color.len()),
        moments: Vec::with_capacity(color.len()),
        variance: Vec::with_capacity(color.len()),
        length: Vec::with_capacity(color.len()),
        modulation: Vec::with_capacity(color.len()),
    };
    // Each pixel's sample variance, stored as f32 as on the device, before its blur.
    let mut samples: Vec<f32> = Vec::with_capacity(color.len());
    for y in 0..h {
        for x in 0..w {
            let i = (y * w + x) as usize;
            let at = surface(motion, i);
            let l = luminance[i];
            let taken = history.and_then(|history| {
                // Tap (xj, yj) of the frame before: whether it sees p's
                // surface, and whether its albedo is alike p's.
                let seen = |xj: i64, yj: i64| {
                    if !inside(xj, yj, w, h) {
                        return None;
                    }
                    let j = (yj * w + xj) as usize;
                    let s = surface_of(history.surface[j], history.albedo[j]);
                    pipeline::same_surface(s, at).then(|| (j, pipeline::alike_albedo(s.albedo, at.albedo)))
                };
                let bilinear = |xj: i64, yj: i64| {
                    seen(xj, yj).is_some_and(|(j, alike)| {
                        alike || {
                            let past = pipeline::luminance(history.color[j].map(f64::from));
                            past <= pipeline::TEMPORAL_UNLIKE_LIGHT * l + pipeline::TEMPORAL_UNLIKE_SLACK
                        }
                    })
                };
                let wider = |xj: i64, yj: i64| seen(xj, yj).is_some_and(|(_, alike)| alike);
                reproject(history, motion.vectors[i], (x, y), bilinear, wider)
            });
            let d = color[i].map(f64::from);
            let mut before = taken.as_ref().map_or(0.0, |t| t.moments[3]);
            // The history's test: where its light is off the frame's, it is cut to one
            // frame; TEMPORAL_ANTILAG_DROP times as far off, dropped.
            if let (Some(kappa), Some(t)) = (temporal.antilag, &taken) {
                // The history's own spread of a sample's luminance: the frame's
                // 3×3 alone is narrowest where its few samples happen to be dark.
                let own = (t.moments[1] - t.moments[0] * t.moments[0]).max(0.0).sqrt();
                let (mean, error) = mean_and_error(&luminance, x, y, w, h, own);
                let past = pipeline::luminance(t.color);
                let allowed = kappa as f64 * error + pipeline::TEMPORAL_ANTILAG_SLACK * mean.max(past);
                if (past - mean).abs() > allowed {
                    before = before.min(1.0);
                }
                if (past - mean).abs() > pipeline::TEMPORAL_ANTILAG_DROP * allowed {
                    before = 0.0;
                }
            }
            let n = (before + 1.0).min(pipeline::TEMPORAL_MAX_HISTORY);
            let a = temporal.share(n);
            let own = motion.albedo[i].map(|c| (c as f64).max(pipeline::ALBEDO_FLOOR));
            let own = [own[0], own[1], own[2]];
            let (blend, m1, m2, r, modulation) = match taken {
                Some(Taken { color: mut past, moments, mut modulation }) => {
                    if let Some(gamma) = temporal.clamp {
                        let (mean, deviation) = neighbourhood(color, x, y, w, h);
                        let (lowest, highest) = modulation_range(motion, x, y, w, h);
                        for k in 0..3 {
                            let g = gamma as f64 * deviation[k];
                            past[k] = past[k].clamp(mean[k] - g, mean[k] + g);
                            modulation[k] = modulation[k].clamp(lowest[k], highest[k]);
                        }
                    }
                    let blend = [0, 1, 2].map(|k| past[k] * (1.0 - a) + d[k] * a);
                    let m1 = moments[0] * (1.0 - a) + l * a;
                    let m2 = moments[1] * (1.0 - a) + l * l * a;
                    let r = moments[2] * (1.0 - a) * (1.0 - a) + a * a;
                    let modulation = [0, 1, 2].map(|k| modulation[k] * (1.0 - a) + own[k] * a);
                    (blend, m1, m2, r, modulation)
                }
                None => (d, l, l * l, 1.0, own),
            };
            let sample_variance = if n >= pipeline::TEMPORAL_SHORT_HISTORY {
                (m2 - m1 * m1).max(0.0)
            } else {
                spatial_variance(&luminance, motion, x, y, w, h)
            };
            out.color.push(blend.map(|c| c as f32));
            out.modulation.push(modulation.map(|c| c as f32));
            out.moments.push([m1 as f32, m2 as f32, r as f32, n as f32]);
            samples.push(sample_variance as f32);
            out.length.push(n as f32);
        }
    }
    out.variance = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .map(|(x, y)| (prefiltered(&samples, x, y, w, h) * out.moments[(y * w + x) as usize][2] as f64) as f32)
        .collect();
    out
}

/// The lowest and highest modulation, max(albedo, `ALBEDO_FLOOR`), channel
/// by channel over the frame's 3×3 around (`x`, `y`) inside the image: the
/// range a history's modulation is clamped to with `clamp` (a texture's
/// edge keeps its mix of both sides; a reflection's history, which the
/// motion of the surface reflecting it does not follow, does not ghost).
fn modulation_range(motion: &Motion, x: i64, y: i64, w: i64, h: i64) -> ([f64; 3], [f64; 3]) {
    let (mut lowest, mut highest) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for (xj, yj) in (-1..=1).flat_map(|dy| (-1..=1).map(move |dx| (x + dx, y + dy))) {
        if inside(xj, yj, w, h) {
            let albedo = motion.albedo[(yj * w + xj) as usize];
            for k in 0..3 {
                let m = (albedo[k] as f64).max(pipeline::ALBEDO_FLOOR);
                lowest[k] = lowest[k].min(m);
                highest[k] = highest[k].max(m);
            }
        }
    }
    (lowest, highest)
}

/// The sample variance around (`x`, `y`) blurred by the 3×3 Gaussian
/// (1/2, 1/4 each way) over the taps inside the image, as SVGF prefilters
/// it: a pixel whose few samples agreed takes its neighbours' spread.
fn prefiltered(samples: &[f32], x: i64, y: i64, w: i64, h: i64) -> f64 {
    let h_of = |d: i64| if d == 0 { 0.5 } else { 0.25 };
    let (mut sum, mut total) = (0.0, 0.0);
    for dy in -1..=1 {
        for dx in -1..=1 {
            let (xj, yj) = (x + dx, y + dy);
            if inside(xj, yj, w, h) {
                let weight = h_of(dx) * h_of(dy);
                sum += weight * samples[(yj * w + xj) as usize] as f64;
                total += weight;
            }
        }
    }
    sum / total
}

/// What the stage keeps of a frame: `accumulated`'s moments, `feedback` (the
/// image after the pipeline's `feedback` passes) and the frame's surface.
pub fn keep(
    accumulated: &Accumulated,
    feedback: Vec<[f32; 3]>,
    motion: &Motion,
    width: usize,
    height: usize,
) -> History {
    History {
        width,
        height,
        color: feedback,
        moments: accumulated.moments.clone(),
        surface: motion.surface.clone(),
        albedo: motion.albedo.clone(),
        modulation: accumulated.modulation.clone(),
    }
}

/// Pixel `i`'s surface as the history's test compares it.
fn surface(motion: &Motion, i: usize) -> pipeline::Surface {
    surface_of(motion.surface[i], motion.albedo[i])
}

fn surface_of(s: [f32; 4], a: [f32; 4]) -> pipeline::Surface {
    pipeline::Surface {
        normal: [s[0] as f64, s[1] as f64, s[2] as f64],
        depth: s[3] as f64,
        albedo: [a[0] as f64, a[1] as f64, a[2] as f64],
    }
}

fn inside(x: i64, y: i64, w: i64, h: i64) -> bool {
    x >= 0 && y >= 0 && x < w && y < h
}

/// The history at pixel (`x`, `y`) moved by `vector`: the bilinear taps
/// around where the pixel was that qualify (`bilinear`), weighted and
/// renormalised; where they hold less than `TEMPORAL_MIN_FOOTPRINT` of the
/// footprint, the mean of the 3×3 taps around the nearest pixel that
/// qualify for it (`wider`: SVGF's wider search); else none.
fn reproject(
    history: &History,
    vector: [f32; 2],
    (x, y): (i64, i64),
    bilinear: impl Fn(i64, i64) -> bool,
    wider: impl Fn(i64, i64) -> bool,
) -> Option<Taken> {
    let w = history.width as i64;
    // In f32, as on the device: the same floor, the same taps.
    let (qx, qy) = (x as f32 + vector[0], y as f32 + vector[1]);
    let (fx0, fy0) = (qx.floor(), qy.floor());
    let (fx, fy) = ((qx - fx0) as f64, (qy - fy0) as f64);
    let (x0, y0) = (fx0 as i64, fy0 as i64);
    let add = |sums: &mut Sums, weight: f64, j: usize| {
        for (s, c) in sums.0.iter_mut().zip(history.color[j]) {
            s.add(weight * c as f64);
        }
        for (s, m) in sums.1.iter_mut().zip(history.moments[j]) {
            s.add(weight * m as f64);
        }
        for (s, m) in sums.2.iter_mut().zip(history.modulation[j]) {
            s.add(weight * m as f64);
        }
    };
    let taken = |sums: Sums, total: f64| Taken {
        color: sums.0.map(|s| s.total() / total),
        moments: sums.1.map(|s| s.total() / total),
        modulation: sums.2.map(|s| s.total() / total),
    };
    let mut sums: Sums = Default::default();
    let mut total = Neumaier::default();
    let mut qualified = 0;
    for dy in 0..2 {
        for dx in 0..2 {
            let (xj, yj) = (x0 + dx, y0 + dy);
            if bilinear(xj, yj) {
                let weight = if dx == 1 { fx } else { 1.0 - fx } * if dy == 1 { fy } else { 1.0 - fy };
                add(&mut sums, weight, (yj * w + xj) as usize);
                total.add(weight);
                qualified += 1;
            }
        }
    }
    if total.total() > pipeline::TEMPORAL_MIN_FOOTPRINT {
        let mut taken = taken(sums, total.total());
        if qualified == 4 {
            taken.modulation = sharp_modulation(history, (x0, y0), (fx, fy));
        }
        return Some(taken);
    }
    let (cx, cy) = ((qx + 0.5).floor() as i64, (qy + 0.5).floor() as i64);
    let mut sums: Sums = Default::default();
    let mut count = 0.0;
    for dy in -1..=1 {
        for dx in -1..=1 {
            let (xj, yj) = (cx + dx, cy + dy);
            if wider(xj, yj) {
                add(&mut sums, 1.0, (yj * w + xj) as usize);
                count += 1.0;
            }
        }
    }
    (count > 0.0).then(|| taken(sums, count))
}

/// The Catmull-Rom spline's weights for the four texels around a fraction `t`.
fn catmull_rom(t: f64) -> [f64; 4] {
    [
        0.5 * (((2.0 - t) * t - 1.0) * t),
        0.5 * ((3.0 * t - 5.0) * t * t + 2.0),
        0.5 * (((4.0 - 3.0 * t) * t + 1.0) * t),
        0.5 * ((t - 1.0) * t * t),
    ]
}

/// The history's modulation at (`x0` + `fx`, `y0` + `fy`), where all four
/// bilinear taps qualify: the Catmull-Rom spline over the 4×4 texels around
/// it (their positions held to the image), each channel held to the range
/// of the four bilinear taps it replaces. Resampled bilinearly every frame,
/// a texture's edge would blur a little more each time, and the modulation
/// is what the form's result is multiplied back by (docs/JOURNAL.md, "A
/// sharp history for the modulation").
fn sharp_modulation(history: &History, (x0, y0): (i64, i64), (fx, fy): (f64, f64)) -> [f64; 3] {
    let (w, h) = (history.width as i64, history.height as i64);
    let at = |xj: i64, yj: i64| history.modulation[(yj.clamp(0, h - 1) * w + xj.clamp(0, w - 1)) as usize];
    let (wx, wy) = (catmull_rom(fx), catmull_rom(fy));
    let mut sums: [Neumaier; 3] = Default::default();
    for (j, weight_y) in wy.iter().enumerate() {
        for (i, weight_x) in wx.iter().enumerate() {
            let m = at(x0 + i as i64 - 1, y0 + j as i64 - 1);
            for (s, c) in sums.iter_mut().zip(m) {
                s.add(weight_x * weight_y * c as f64);
            }
        }
    }
    let inner = [(0, 0), (1, 0), (0, 1), (1, 1)].map(|(dx, dy)| at(x0 + dx, y0 + dy));
    [0, 1, 2].map(|k| {
        let lowest = inner.iter().map(|m| m[k] as f64).fold(f64::INFINITY, f64::min);
        let highest = inner.iter().map(|m| m[k] as f64).fold(f64::NEG_INFINITY, f64::max);
        sums[k].total().clamp(lowest, highest)
    })
}

/// The mean of the luminance over the 3×3 pixels around (`x`, `y`) inside
/// the image, and its standard error: the larger of the taps' population
/// standard deviation and `least_deviation`, over √N. What the history's
/// test (`antilag=K`) holds the history to.
fn mean_and_error(luminance: &[f64], x: i64, y: i64, w: i64, h: i64, least_deviation: f64) -> (f64, f64) {
    let taps: Vec<f64> = (-1..=1)
        .flat_map(|dy| (-1..=1).map(move |dx| (x + dx, y + dy)))
        .filter(|&(xj, yj)| inside(xj, yj, w, h))
        .map(|(xj, yj)| luminance[(yj * w + xj) as usize])
        .collect();
    let n = taps.len() as f64;
    let mean = taps.iter().sum::<f64>() / n;
    let deviation = (taps.iter().map(|l| (l - mean).powi(2)).sum::<f64>() / n).sqrt();
    (mean, deviation.max(least_deviation) / n.sqrt())
}

/// Each channel's mean and standard deviation over the 3×3 pixels around
/// (`x`, `y`) inside the image: what `clamp=G` holds the history to.
fn neighbourhood(color: &[[f32; 3]], x: i64, y: i64, w: i64, h: i64) -> ([f64; 3], [f64; 3]) {
    let taps: Vec<[f64; 3]> = (-1..=1)
        .flat_map(|dy| (-1..=1).map(move |dx| (x + dx, y + dy)))
        .filter(|&(xj, yj)| inside(xj, yj, w, h))
        .map(|(xj, yj)| color[(yj * w + xj) as usize].map(f64::from))
        .collect();
    let n = taps.len() as f64;
    let mean = [0, 1, 2].map(|k| taps.iter().map(|t| t[k]).sum::<f64>() / n);
    let deviation = [0, 1, 2].map(|k| (taps.iter().map(|t| (t[k] - mean[k]).powi(2)).sum::<f64>() / n).sqrt());
    (mean, deviation)
}

/// The variance of the luminance over the (2R+1)² pixels around (`x`, `y`)
/// that see its surface with an albedo alike its own (R =
/// `TEMPORAL_VARIANCE_RADIUS`): a history too short for its moments (SVGF's
/// spatial estimate).
fn spatial_variance(luminance: &[f64], motion: &Motion, x: i64, y: i64, w: i64, h: i64) -> f64 {
    let at = surface(motion, (y * w + x) as usize);
    let r = pipeline::TEMPORAL_VARIANCE_RADIUS as i64;
    let taps: Vec<f64> = (-r..=r)
        .flat_map(|dy| (-r..=r).map(move |dx| (x + dx, y + dy)))
        .filter(|&(xj, yj)| {
            inside(xj, yj, w, h) && {
                let s = surface(motion, (yj * w + xj) as usize);
                pipeline::same_surface(s, at) && pipeline::alike_albedo(s.albedo, at.albedo)
            }
        })
        .map(|(xj, yj)| luminance[(yj * w + xj) as usize])
        .collect();
    let n = taps.len() as f64;
    let mean = taps.iter().sum::<f64>() / n;
    taps.iter().map(|l| (l - mean).powi(2)).sum::<f64>() / n
}

#[cfg(test)]
mod tests {
    use super::*;

    const UP: [f32; 4] = [0.0, 0.0, 1.0, 1.0];

    const GREY: [f32; 4] = [0.5, 0.5, 0.5, 0.0];

    /// A `w`×`h` frame of one colour, facing the camera at depth 1, still.
    fn still(w: usize, h: usize, value: f32) -> (Vec<[f32; 3]>, Motion) {
        let motion = Motion { vectors: vec![[0.0; 2]; w * h], surface: vec![UP; w * h], albedo: vec![GREY; w * h] };
        (vec![[value; 3]; w * h], motion)
    }

    fn stage(alpha: f32) -> Temporal {
        Temporal { alpha, feedback: 0, clamp: None, antilag: None }
    }

    #[test]
    fn a_still_history_averages_its_frames_evenly_then_forgets_at_alpha() {
        let (w, h) = (6, 5);
        let mut history: Option<History> = None;
        // Frames of 0, 3, 6, 9, …: while 1/n > α every frame counts alike.
        for k in 0..6 {
            let (color, motion) = still(w, h, 3.0 * k as f32);
            let out = accumulate(stage(0.2), &color, &motion, w, h, history.as_ref());
            let n = (k + 1) as f32;
            assert_eq!(out.length[7], n, "frame {k}");
            let even = 3.0 * k as f32 / 2.0;
            if n <= 5.0 {
                assert!(
                    (out.color[7][0] - even).abs() < 1e-5,
                    "frame {k}: {} against the mean {even}",
                    out.color[7][0]
                );
                // r: the blend's squared shares sum to 1/n.
                assert!((out.moments[7][2] - 1.0 / n).abs() < 1e-6, "frame {k}: r {}", out.moments[7][2]);
            } else {
                // From n > 1/α on, the newest frame gets α.
                let before = history.as_ref().unwrap().color[7][0];
                assert!((out.color[7][0] - (0.8 * before + 0.2 * 3.0 * k as f32)).abs() < 1e-4, "frame {k}");
            }
            history = Some(keep(&out, out.color.clone(), &motion, w, h));
        }
    }

    #[test]
    fn a_surface_the_frame_before_did_not_see_starts_a_new_history() {
        let (w, h) = (8, 4);
        let (color, motion) = still(w, h, 1.0);
        let first = accumulate(stage(0.2), &color, &motion, w, h, None);
        let history = keep(&first, first.color.clone(), &motion, w, h);
        // The right half now sees a surface twice as far (an object moved away), the
        // bottom-left row a surface turned sideways, its top-left pixel a black
        // emitter lying flat where the wall was: all disoccluded, the rest not.
        let mut moved = motion.clone();
        for y in 0..h {
            for x in 0..w {
                if x >= w / 2 {
                    moved.surface[y * w + x] = [0.0, 0.0, 1.0, 2.0];
                } else if y == h - 1 {
                    moved.surface[y * w + x] = [1.0, 0.0, 0.0, 1.0];
                }
            }
        }
        moved.albedo[0] = [0.0; 4];
        let second = accumulate(stage(0.2), &color, &moved, w, h, Some(&history));
        for y in 0..h {
            for x in 0..w {
                let fresh = x >= w / 2 || y == h - 1 || (x, y) == (0, 0);
                assert_eq!(second.length[y * w + x], if fresh { 1.0 } else { 2.0 }, "({x}, {y})");
            }
        }
    }

    /// A wall an emitter slid off: in the frame before, pixel `edge` was the
    /// emitter's edge (its albedo a quarter of the wall's, its demodulated
    /// light the emitter's over that albedo) and pixel `texture` a texture's
    /// darker side (a fifth of the wall's albedo, the wall's light). Now both see
    /// the plain wall: the texture's edge keeps its history; the emitter's
    /// edge lends none, and the wider search takes the wall's around it.
    #[test]
    fn an_emitters_edge_lends_no_history_where_a_textures_edge_does() {
        let (w, h) = (6, 3);
        let (mut before, mut motion) = still(w, h, 0.3);
        let wall = [0.75, 0.75, 0.75, 0.0];
        motion.albedo = vec![wall; w * h];
        let edge = w + 1;
        let texture = w + 4;
        motion.albedo[edge] = [0.19, 0.19, 0.19, 0.0];
        before[edge] = [40.0; 3];
        motion.albedo[texture] = [0.15, 0.15, 0.15, 0.0];
        let first = accumulate(stage(0.2), &before, &motion, w, h, None);
        let history = keep(&first, first.color.clone(), &motion, w, h);
        let now = Motion { albedo: vec![wall; w * h], ..motion.clone() };
        let (wall_light, _) = still(w, h, 0.3);
        let second = accumulate(stage(0.2), &wall_light, &now, w, h, Some(&history));
        assert_eq!(second.length[texture], 2.0, "a texture's edge keeps its history");
        assert_eq!(second.length[edge], 2.0, "the wall around the emitter's edge lends it its history");
        for (i, c) in second.color.iter().enumerate() {
            assert!((c[0] - 0.3).abs() < 1e-6, "pixel {i}: {c:?}: the emitter's light leaked");
        }
        // Without the tests of the albedo, the emitter's light is the edge's history.
        let mut unlike = motion.clone();
        unlike.albedo[edge] = [0.7, 0.7, 0.7, 0.0];
        let first = accumulate(stage(0.2), &before, &unlike, w, h, None);
        let history = keep(&first, first.color.clone(), &unlike, w, h);
        let leaked = accumulate(stage(0.2), &wall_light, &now, w, h, Some(&history));
        assert!(leaked.color[edge][0] > 10.0, "{:?}", leaked.color[edge]);
    }

    /// A texture's edge moved a quarter pixel: the history's modulation is
    /// the Catmull-Rom spline's, sharper than the bilinear taps' mean, and
    /// held to their range where the spline would ring.
    #[test]
    fn the_modulation_is_resampled_sharply_and_held_to_its_taps_range() {
        let (w, h) = (8, 3);
        let (color, mut motion) = still(w, h, 1.0);
        // Albedo 0.2 left of x = 4, 0.8 from x = 4 on.
        for (i, a) in motion.albedo.iter_mut().enumerate() {
            let v = if i % w < 4 { 0.2 } else { 0.8 };
            *a = [v, v, v, 0.0];
        }
        let first = accumulate(stage(0.2), &color, &motion, w, h, None);
        let history = keep(&first, first.color.clone(), &motion, w, h);
        // Pixel (4, 1) was at x = 3.25: taps x = 3 (0.2) and 4 (0.8).
        let moved = Motion { vectors: vec![[-0.75, 0.0]; w * h], ..motion.clone() };
        let second = accumulate(stage(0.2), &color, &moved, w, h, Some(&history));
        let bilinear = 0.75 * 0.2 + 0.25 * 0.8;
        let [w0, w1, w2, w3] = catmull_rom(0.25);
        let spline = (w0 + w1) * 0.2 + (w2 + w3) * 0.8;
        // The second frame of a history blends half and half.
        let past = (second.modulation[w + 4][0] as f64 - 0.5 * 0.8) / 0.5;
        assert!((past - spline).abs() < 1e-6, "{past} against the spline's {spline} (bilinear {bilinear})");
        assert!(spline < bilinear - 0.02);
        // Beside the edge (x = 2 was at 1.25, between 0.2 and 0.2) the spline would
        // reach below 0.2 (its lobe over x = 3.. holds 0.8 above): held to 0.2.
        let beside = (second.modulation[w + 2][0] as f64 - 0.5 * 0.2) / 0.5;
        assert!((beside - 0.2).abs() < 1e-6, "{beside}");
    }

    #[test]
    fn motion_vectors_bring_the_history_from_where_the_surface_was() {
        let (w, h) = (9, 3);
        // The frame before: a ramp in x.
        let ramp: Vec<[f32; 3]> = (0..w * h).map(|p| [(p % w) as f32; 3]).collect();
        let (_, motion) = still(w, h, 0.0);
        let first = accumulate(stage(0.5), &ramp, &motion, w, h, None);
        let history = keep(&first, ramp.clone(), &motion, w, h);
        // Everything moved 2.5 pixels right: each pixel was 2.5 pixels left of here.
        let moved = Motion { vectors: vec![[-2.5, 0.0]; w * h], ..motion.clone() };
        let (zeros, _) = still(w, h, 0.0);
        let second = accumulate(stage(0.5), &zeros, &moved, w, h, Some(&history));
        for x in 3..w {
            // History (x − 2.5), bilinear; then blended half and half with 0.
            let expected = (x as f32 - 2.5) * 0.5;
            assert!((second.color[w + x][0] - expected).abs() < 1e-5, "x {x}: {}", second.color[w + x][0]);
            assert_eq!(second.length[w + x], 2.0);
        }
        // Pixels whose surface was outside the frame before start afresh (x − 2.5 < −0.5 … the wider search aside).
        assert_eq!(second.length[w], 1.0, "x 0 was at −2.5: outside");
        // A vector far outside any image (a non-finite one, sanitised) is no history.
        let away = Motion { vectors: vec![[1e7, 1e7]; w * h], ..motion.clone() };
        let third = accumulate(stage(0.5), &zeros, &away, w, h, Some(&history));
        assert!(third.length.iter().all(|n| *n == 1.0));
    }

    #[test]
    fn the_clamp_holds_a_disagreeing_history_to_the_frame() {
        let (w, h) = (5, 5);
        let (bright, motion) = still(w, h, 10.0);
        let first = accumulate(stage(0.1), &bright, &motion, w, h, None);
        let history = keep(&first, first.color.clone(), &motion, w, h);
        let (dark, _) = still(w, h, 1.0);
        let clamped = Temporal { clamp: Some(2.0), ..stage(0.1) };
        // A flat frame has no spread: the history is clamped to it, no ghost of the light before.
        let out = accumulate(clamped, &dark, &motion, w, h, Some(&history));
        assert!((out.color[12][0] - 1.0).abs() < 1e-6, "{}", out.color[12][0]);
        let ghost = accumulate(stage(0.1), &dark, &motion, w, h, Some(&history));
        assert!((ghost.color[12][0] - 5.5).abs() < 1e-5, "without the clamp, half of each: {}", ghost.color[12][0]);
    }

    #[test]
    fn the_history_test_cuts_a_history_whose_light_changed() {
        let (w, h) = (5, 5);
        let (bright, motion) = still(w, h, 4.0);
        let mut history: Option<History> = None;
        for _ in 0..6 {
            let out = accumulate(stage(0.1), &bright, &motion, w, h, history.as_ref());
            history = Some(keep(&out, out.color.clone(), &motion, w, h));
        }
        let testing = Temporal { antilag: Some(3.0), ..stage(0.1) };
        // The same light again: the history stays.
        let same = accumulate(testing, &bright, &motion, w, h, history.as_ref());
        assert_eq!(same.length[12], 7.0);
        // The light dimmed past what the test allows (noise-free: 2 % of it), within three
        // times that: the history is cut to one frame, the blend half the new light.
        let (dimmed, _) = still(w, h, 3.8);
        let cut = accumulate(testing, &dimmed, &motion, w, h, history.as_ref());
        assert_eq!(cut.length[12], 2.0);
        assert!((cut.color[12][0] - 3.9).abs() < 1e-5, "{}", cut.color[12][0]);
        // A shadow swept in, far beyond it: the history is dropped, the blend the new light.
        let (dark, _) = still(w, h, 1.0);
        let dropped = accumulate(testing, &dark, &motion, w, h, history.as_ref());
        assert_eq!(dropped.length[12], 1.0);
        assert!((dropped.color[12][0] - 1.0).abs() < 1e-5, "{}", dropped.color[12][0]);
        // Without the test it lags: a seventh of the new light.
        let lagging = accumulate(stage(0.1), &dark, &motion, w, h, history.as_ref());
        assert!((lagging.color[12][0] - (4.0 - 3.0 / 7.0)).abs() < 1e-5, "{}", lagging.color[12][0]);
    }

    /// One sample a pixel of a still surface whose light is rare and bright
    /// (10 with probability 0.1, else 0: mean 1): the history's test must not
    /// cut where the frame's few samples happen to be dark, which would keep
    /// the dark ones and darken the image.
    #[test]
    fn the_history_test_keeps_the_light_of_skewed_samples() {
        let (w, h) = (24, 24);
        let (_, motion) = still(w, h, 0.0);
        let testing = Temporal { antilag: Some(3.0), ..stage(0.2) };
        let mut state = 12345u32;
        let mut history: Option<History> = None;
        let (mut sum, mut count) = (0.0f64, 0usize);
        for frame in 0..60 {
            let color: Vec<[f32; 3]> = (0..w * h)
                .map(|_| {
                    state = state.wrapping_mul(1664525).wrapping_add(1013904223);
                    [if (state >> 8).is_multiple_of(10) { 10.0 } else { 0.0 }; 3]
                })
                .collect();
            let out = accumulate(testing, &color, &motion, w, h, history.as_ref());
            if frame >= 20 {
                sum += out.color.iter().map(|c| c[0] as f64).sum::<f64>();
                count += out.color.len();
            }
            history = Some(keep(&out, out.color.clone(), &motion, w, h));
        }
        let light = sum / count as f64;
        assert!((light - 1.0).abs() < 0.03, "the blend's mean {light} against the samples' 1");
    }

    #[test]
    fn the_clamp_holds_a_historys_modulation_to_the_frames_neighbourhood() {
        let (w, h) = (6, 5);
        let with_albedo = |albedo: &dyn Fn(usize) -> f32| {
            let (color, mut motion) = still(w, h, 1.0);
            motion.albedo = (0..w * h).map(|p| [albedo(p % w), albedo(p % w), albedo(p % w), 0.0]).collect();
            (color, motion)
        };
        let clamped = Temporal { clamp: Some(2.0), ..stage(0.2) };
        let second_frame = |temporal: Temporal, before: &dyn Fn(usize) -> f32, now: &dyn Fn(usize) -> f32| {
            let (color, motion) = with_albedo(before);
            let first = accumulate(temporal, &color, &motion, w, h, None);
            let history = keep(&first, first.color.clone(), &motion, w, h);
            let (color, motion) = with_albedo(now);
            accumulate(temporal, &color, &motion, w, h, Some(&history))
        };
        // A reflection: the same surface, another texture on it. The clamp
        // takes the frame's; without it the two are blended evenly.
        let centre = 2 * w + 2;
        let out = second_frame(clamped, &|_| 0.9, &|_| 0.3);
        assert!((out.modulation[centre][0] - 0.3).abs() < 1e-6, "{}", out.modulation[centre][0]);
        let out = second_frame(stage(0.2), &|_| 0.9, &|_| 0.3);
        assert!((out.modulation[centre][0] - 0.6).abs() < 1e-6, "{}", out.modulation[centre][0]);
        // A texture's edge whose pixel saw the dark side, then the bright one:
        // its 3x3 holds both, so the clamp keeps the mix.
        let out = second_frame(clamped, &|x| if x < 3 { 0.2 } else { 0.8 }, &|x| if x < 2 { 0.2 } else { 0.8 });
        assert!((out.modulation[centre][0] - 0.5).abs() < 1e-6, "{}", out.modulation[centre][0]);
    }

    #[test]
    fn a_short_history_takes_its_variance_from_the_neighbourhood() {
        let (w, h) = (15, 15);
        // Alternating 0 and 2: a sample variance of about 1 around every pixel of the frame.
        let checker: Vec<[f32; 3]> = (0..w * h).map(|p| [2.0 * ((p % w + p / w) % 2) as f32; 3]).collect();
        let (_, motion) = still(w, h, 0.0);
        let out = accumulate(stage(0.2), &checker, &motion, w, h, None);
        // Around the centre every pixel's window holds one more of its own value than of the other.
        let taps = (2 * pipeline::TEMPORAL_VARIANCE_RADIUS + 1).pow(2);
        let p = f64::from(taps + 1) / 2.0 / f64::from(taps);
        let expected = 4.0 * p * (1.0 - p);
        let centre = 7 * w + 7;
        assert!((out.variance[centre] as f64 - expected).abs() < 1e-5, "{} against {expected}", out.variance[centre]);
    }

    #[test]
    fn a_pixel_whose_samples_agreed_takes_its_neighbours_spread() {
        let (w, h) = (5, 5);
        let (_, motion) = still(w, h, 0.0);
        let mut history: Option<History> = None;
        // Four frames: every pixel alternates 0 and 2 but the centre, always 0 (a dim
        // pixel whose few samples all missed the light).
        for k in 0..4 {
            let frame: Vec<[f32; 3]> =
                (0..w * h).map(|p| if p == 12 { [0.0; 3] } else { [2.0 * ((p + k) % 2) as f32; 3] }).collect();
            let out = accumulate(stage(0.2), &frame, &motion, w, h, history.as_ref());
            history = Some(keep(&out, out.color.clone(), &motion, w, h));
            if k == 3 {
                assert_eq!(out.length[12], 4.0);
                // Its own moments say 0; its neighbours' say 1 a sample, a quarter for a blend of four.
                assert!((out.variance[12] - 0.75 * 0.25).abs() < 1e-6, "{}", out.variance[12]);
            }
        }
    }
}
