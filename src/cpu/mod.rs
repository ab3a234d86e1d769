//! The CPU reference: the same filter as the GPU kernels, evaluated in f64
//! with the semantics of [`crate::semantics`]. Slow and simple on purpose.

mod anchor;
pub mod temporal;

pub use anchor::anchor_light;

use crate::lang::{Expr, Feature, ScalarVar};
use crate::pipeline::{self, FilterPipeline, Form, Keep};
use crate::scene::Scene;
use crate::semantics;

/// Output of a filter run on the CPU.
#[derive(Clone, Debug)]
pub struct CpuFiltered {
    pub color: Vec<[f64; 3]>,
    /// Domain-error bits per pixel (see [`semantics::flag`]).
    pub flags: Vec<u32>,
}

use crate::scene::MissingInput;

/// Values one weight evaluation reads.
struct Pixels<'a> {
    scene: &'a Scene,
    i: usize,
    j: usize,
    width: usize,
    /// The à-trous pass (`level`); 0 in the window form.
    level: u32,
}

impl Pixels<'_> {
    fn feature(&self, f: Feature, index: usize) -> [f64; 3] {
        match f {
            Feature::Pixel => [(index % self.width) as f64, (index / self.width) as f64, 0.0],
            // The first pass's guide, where the pipeline has not stored one (a lone weight's evaluation).
            Feature::Guide if self.scene.feature(f).is_none() => guide_at(self.scene, index).map(f64::from),
            _ => {
                let v = self.scene.feature(f).expect("checked before filtering")[index];
                // 1-D features are (v, 0, 0) whatever the buffer holds beyond v, as on the GPU.
                if f.dimension() == 1 {
                    [v[0] as f64, 0.0, 0.0]
                } else {
                    [v[0] as f64, v[1] as f64, v[2] as f64]
                }
            }
        }
    }

    fn variance(&self, v: ScalarVar) -> f64 {
        if v == ScalarVar::Level {
            return self.level as f64;
        }
        self.scene.variance(v).expect("checked before filtering")[self.i] as f64
    }
}

/// Evaluate `expr` for centre pixel `i` and neighbour `j`.
fn eval(expr: &Expr, px: &Pixels<'_>, flags: &mut u32) -> f64 {
    match expr {
        Expr::Const(c) => semantics::literal(*c),
        Expr::Var(v) => px.variance(*v),
        Expr::Unary(op, a) => op.eval(eval(a, px, flags), flags),
        Expr::Binary(op, a, b) => {
            let a = eval(a, px, flags);
            let b = eval(b, px, flags);
            op.eval(a, b, flags)
        }
        Expr::Pair(op, fi, fj) => op.eval(px.feature(*fi, px.i), px.feature(*fj, px.j)),
    }
}

/// Check that the scene has every input of `expr` (what a pre-pass measured
/// is among its variances once `prepass` has run).
pub fn check_inputs(expr: &Expr, scene: &Scene) -> Result<(), MissingInput> {
    crate::scene::Needs::of(expr, false).check(scene, &FilterPipeline::WINDOW)
}

/// Filter `scene` with weight expression `expr` over a (2r+1)² window.
pub fn filter(expr: &Expr, scene: &Scene, radius: u32) -> Result<CpuFiltered, MissingInput> {
    check_inputs(expr, scene)?;
    let guided;
    let scene = if reads_guide(expr) {
        guided = with_guide(scene);
        &guided
    } else {
        scene
    };
    let r = radius as i64;
    let offsets: Vec<(i64, i64, f64)> = (-r..=r).flat_map(|dy| (-r..=r).map(move |dx| (dx, dy, 1.0))).collect();
    Ok(pass(expr, scene, &offsets, 0, None).0)
}

fn reads_guide(expr: &Expr) -> bool {
    expr.features().contains(&Feature::Guide)
}

/// The `guide` terminal of the first pass (docs/SEMANTICS.md, "The guide"):
/// `scene`'s colour blurred by one pass of the 3×3 linear B-spline, each
/// pixel the mean of its taps inside the image. It is the filter itself with
/// the constant weight 1, so the device runs that kernel for it.
pub fn guide(scene: &Scene) -> Vec<[f32; 3]> {
    (0..scene.pixels()).map(|i| guide_at(scene, i)).collect()
}

/// The guide at pixel `index`, stored as f32 like every image between stages.
fn guide_at(scene: &Scene, index: usize) -> [f32; 3] {
    let stencil = pipeline::GUIDE_STENCIL;
    let half = stencil.half_width() as i64;
    let (w, h) = (scene.width as i64, scene.height as i64);
    let (x, y) = ((index % scene.width) as i64, (index / scene.width) as i64);
    let (mut sum_w, mut sum_c) = (Neumaier::default(), [Neumaier::default(); 3]);
    for dy in -half..=half {
        for dx in -half..=half {
            let (xj, yj) = (x + dx, y + dy);
            if xj < 0 || yj < 0 || xj >= w || yj >= h {
                continue;
            }
            let weight = stencil.weight(dx as i32) * stencil.weight(dy as i32);
            sum_w.add(weight);
            for (sum, c) in sum_c.iter_mut().zip(scene.color[(yj * w + xj) as usize]) {
                sum.add(weight * c as f64);
            }
        }
    }
    sum_c.map(|s| (s.total() / sum_w.total()) as f32)
}

/// `scene` with its first pass's guide among its features.
fn with_guide(scene: &Scene) -> Scene {
    let mut guided = scene.clone();
    guided.features.insert(Feature::Guide, guide(scene));
    guided
}

/// One pass over `offsets` (dx, dy, stencil weight): every pixel's weighted
/// mean of its neighbours inside the image, and with `carry` the variance of
/// that mean, Σ w² v_j / (Σ w)² (SVGF's rule), of the variance it names.
fn pass(
    expr: &Expr,
    scene: &Scene,
    offsets: &[(i64, i64, f64)],
    level: u32,
    carry: Option<ScalarVar>,
) -> (CpuFiltered, Vec<f64>) {
    let (w, h) = (scene.width as i64, scene.height as i64);
    let variance = carry.map(|v| scene.variance(v).expect("checked before filtering"));
    let mut color = Vec::with_capacity(scene.pixels());
    let mut flags = Vec::with_capacity(scene.pixels());
    let mut carried = Vec::with_capacity(if carry.is_some() { scene.pixels() } else { 0 });
    for y in 0..h {
        for x in 0..w {
            let i = (y * w + x) as usize;
            let mut pixel_flags = 0u32;
            let (mut sum_w, mut sum_c, mut sum_wwv) =
                (Neumaier::default(), [Neumaier::default(); 3], Neumaier::default());
            for &(dx, dy, stencil) in offsets {
                let (xj, yj) = (x + dx, y + dy);
                if xj < 0 || yj < 0 || xj >= w || yj >= h {
                    continue;
                }
                let j = (yj * w + xj) as usize;
                let px = Pixels { scene, i, j, width: scene.width, level };
                let weight = stencil * semantics::weight(eval(expr, &px, &mut pixel_flags));
                sum_w.add(weight);
                for (sum, c) in sum_c.iter_mut().zip(scene.color[j]) {
                    sum.add(weight * c as f64);
                }
                if let Some(v) = variance {
                    sum_wwv.add(weight * weight * v[j] as f64);
                }
            }
            let centre = scene.color[i];
            let (sum_w, sum_c) = (sum_w.total(), sum_c.map(|s| s.total()));
            color.push(if sum_w > 0.0 {
                [sum_c[0] / sum_w, sum_c[1] / sum_w, sum_c[2] / sum_w]
            } else {
                [centre[0] as f64, centre[1] as f64, centre[2] as f64]
            });
            if let Some(v) = variance {
                carried.push(if sum_w > 0.0 { sum_wwv.total() / (sum_w * sum_w) } else { v[i] as f64 });
            }
            flags.push(pixel_flags);
        }
    }
    (CpuFiltered { color, flags }, carried)
}

/// What the pre-pass hands the form: the colour it filters, and the factor
/// remodulation multiplies the result by (with demodulation).
#[derive(Clone, Debug)]
pub struct Prepared {
    /// Stored as f32, as on the device.
    pub color: Vec<[f32; 3]>,
    pub modulation: Option<Vec<[f32; 3]>>,
    /// With outliers: what the rule measured (`ScalarVar::FROM_PREPASS`, in that order), as f32.
    pub local: Option<[Vec<f32>; 3]>,
}

/// The pre-pass of `pipeline` (outliers, what they removed put back spread
/// with `keep`, then demodulation) on `scene`'s colour.
pub fn prepass(scene: &Scene, pipeline: &FilterPipeline) -> Result<Prepared, MissingInput> {
    let (w, h) = (scene.width as i64, scene.height as i64);
    let f64s = |c: [f32; 3]| c.map(|v| v as f64);
    let modulation = match (pipeline.demodulate, &scene.albedo) {
        (false, _) => None,
        (true, Some(albedo)) => Some(albedo.iter().map(|a| pipeline::modulation(f64s(*a))).collect::<Vec<_>>()),
        (true, None) => return Err(MissingInput { scene: scene.name.clone(), missing: crate::scene::Missing::Albedo }),
    };
    let mut clamped: Vec<[f64; 3]> = Vec::with_capacity(scene.pixels());
    let mut local: [Vec<f32>; 3] = Default::default();
    for y in 0..h {
        for x in 0..w {
            let i = (y * w + x) as usize;
            let mut c = f64s(scene.color[i]);
            let mut measured = [0.0f64; 3];
            if let Some(pipeline::Outliers { k, trim, .. }) = pipeline.outliers {
                let mut neighbours: Vec<f64> = pipeline::outlier_neighbours()
                    .map(|[dx, dy]| (x + dx as i64, y + dy as i64))
                    .filter(|&(xj, yj)| xj >= 0 && yj >= 0 && xj < w && yj < h)
                    .map(|(xj, yj)| pipeline::luminance(f64s(scene.color[(yj * w + xj) as usize])))
                    .collect();
                if trim && !neighbours.is_empty() {
                    // The first of the brightest, in the neighbourhood's order, is left out.
                    let mut brightest = 0;
                    for (j, &l) in neighbours.iter().enumerate() {
                        if l > neighbours[brightest] {
                            brightest = j;
                        }
                    }
                    neighbours.remove(brightest);
                }
                if !neighbours.is_empty() {
                    let n = neighbours.len() as f64;
                    let mean = neighbours.iter().sum::<f64>() / n;
                    let std = (neighbours.iter().map(|l| (l - mean) * (l - mean)).sum::<f64>() / n).sqrt();
                    let limit = mean + k as f64 * std;
                    let l = pipeline::luminance(c);
                    measured = [mean, std, 0.0];
                    if l > limit {
                        c = c.map(|v| v * (limit / l));
                        measured[2] = (l - limit) / l;
                    }
                }
            }
            for (out, value) in local.iter_mut().zip(measured) {
                out.push(value as f32);
            }
            clamped.push(c);
        }
    }
    if let Some(keep) = pipeline.keep() {
        // Stored as f32 between stages, as on the device.
        let clamped32: Vec<[f32; 3]> = clamped.iter().map(|c| c.map(|v| v as f32)).collect();
        let removed: Vec<[f32; 3]> = scene
            .color
            .iter()
            .zip(&clamped32)
            .map(|(raw, c)| [0, 1, 2].map(|q| (raw[q] as f64 - c[q] as f64) as f32))
            .collect();
        let spread = match keep {
            Keep::Even => spread(&removed, scene.width, scene.height),
            Keep::Surface => {
                let normals = scene.required_feature(Feature::Normal)?;
                spread_surface(&removed, &clamped32, normals, scene.width, scene.height)
            }
        };
        for ((c, kept), s) in clamped.iter_mut().zip(&clamped32).zip(&spread) {
            *c = [0, 1, 2].map(|q| kept[q] as f64 + s[q] as f64);
        }
    }
    let color = clamped
        .iter()
        .enumerate()
        .map(|(i, c)| match &modulation {
            Some(m) => [c[0] / m[i][0], c[1] / m[i][1], c[2] / m[i][2]].map(|v| v as f32),
            None => c.map(|v| v as f32),
        })
        .collect();
    let modulation = modulation.map(|m| m.into_iter().map(|v| v.map(|x| x as f32)).collect());
    Ok(Prepared { color, modulation, local: pipeline.outliers.map(|_| local) })
}

/// `keep`'s spread (docs/SEMANTICS.md, "The pipeline"): `pipeline::KEEP_PASSES`
/// passes in which every pixel hands its value to the stencil's taps inside
/// the image, in proportion to their weights (`pipeline::spread_share`), so
/// the image's total is kept exactly. Stored as f32 between passes.
pub fn spread(image: &[[f32; 3]], width: usize, height: usize) -> Vec<[f32; 3]> {
    let (w, h) = (width as i64, height as i64);
    let half = pipeline::KEEP_STENCIL.half_width() as i64;
    let mut current = image.to_vec();
    for level in 0..pipeline::KEEP_PASSES {
        let step = FilterPipeline::step(level) as i64;
        let mut next = Vec::with_capacity(current.len());
        for y in 0..h {
            for x in 0..w {
                let mut sum = [Neumaier::default(); 3];
                for dy in -half..=half {
                    for dx in -half..=half {
                        // The source j = i - d·step hands i its share for offset d.
                        let (xj, yj) = (x - dx * step, y - dy * step);
                        if xj < 0 || yj < 0 || xj >= w || yj >= h {
                            continue;
                        }
                        let share = pipeline::spread_share(xj, dx, step, w) * pipeline::spread_share(yj, dy, step, h);
                        for (s, v) in sum.iter_mut().zip(current[(yj * w + xj) as usize]) {
                            s.add(share * v as f64);
                        }
                    }
                }
                next.push(sum.map(|s| s.total() as f32));
            }
        }
        current = next;
    }
    current
}

/// `keep=surface`'s spread (docs/SEMANTICS.md, "The pipeline") of `removed`
/// over an image whose clamped colour is `clamped` and whose normals are
/// `normals`: `pipeline::SURFACE_KEEP_PASSES` levels in which every pixel j
/// hands each tap t = j + d·step of the 3×3 B-spline inside the image the share
/// h(d) · normal term(j, t) · light(t), normalised over j's taps, so the image's
/// total is kept exactly. Stored as f32 between levels, as on the device.
pub fn spread_surface(
    removed: &[[f32; 3]],
    clamped: &[[f32; 3]],
    normals: &[[f32; 3]],
    width: usize,
    height: usize,
) -> Vec<[f32; 3]> {
    let (w, h) = (width as i64, height as i64);
    let half = pipeline::KEEP_STENCIL.half_width() as i64;
    let f64s = |c: [f32; 3]| c.map(|v| v as f64);
    let mut total = Neumaier::default();
    for c in clamped {
        total.add(pipeline::luminance(f64s(*c)));
    }
    let floor = pipeline::SURFACE_KEEP_LIGHT_FLOOR * total.total() / (width * height).max(1) as f64;
    let light: Vec<f64> =
        clamped.iter().map(|c| pipeline::surface_light_term(pipeline::luminance(f64s(*c)), floor)).collect();
    let normal = |x: i64, y: i64| f64s(normals[(y * w + x) as usize]);
    let taps = || (-half..=half).flat_map(move |dy| (-half..=half).map(move |dx| (dx, dy)));
    let stencil =
        |dx: i64, dy: i64| pipeline::KEEP_STENCIL.weight(dx as i32) * pipeline::KEEP_STENCIL.weight(dy as i32);
    let mut current = removed.to_vec();
    for level in 0..pipeline::SURFACE_KEEP_PASSES {
        let step = FilterPipeline::step(level) as i64;
        // Each source's share of its value per unit of weight: value / Z_j.
        let shares: Vec<[f64; 3]> = (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .map(|(x, y)| {
                let mut z = Neumaier::default();
                for (dx, dy) in taps() {
                    let (xt, yt) = (x + dx * step, y + dy * step);
                    if xt >= 0 && yt >= 0 && xt < w && yt < h {
                        let n = pipeline::surface_normal_term(normal(x, y), normal(xt, yt));
                        z.add(stencil(dx, dy) * n * light[(yt * w + xt) as usize]);
                    }
                }
                f64s(current[(y * w + x) as usize]).map(|v| v / z.total())
            })
            .collect();
        current = (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .map(|(x, y)| {
                let mut sum = [Neumaier::default(); 3];
                for (dx, dy) in taps() {
                    // The source j = i - d·step hands i its share for offset d.
                    let (xj, yj) = (x - dx * step, y - dy * step);
                    if xj >= 0 && yj >= 0 && xj < w && yj < h {
                        let n = pipeline::surface_normal_term(normal(x, y), normal(xj, yj));
                        for (s, v) in sum.iter_mut().zip(shares[(yj * w + xj) as usize]) {
                            s.add(stencil(dx, dy) * n * v);
                        }
                    }
                }
                let l = light[(y * w + x) as usize];
                sum.map(|s| (l * s.total()) as f32)
            })
            .collect();
    }
    current
}

/// Filter `scene` with `expr` through the whole `pipeline` (docs/SEMANTICS.md,
/// "The pipeline"); `radius` is the window form's. Images between stages and
/// passes are stored as f32, as on the device; each stage computes in f64.
pub fn filter_pipeline(
    expr: &Expr,
    scene: &Scene,
    pipeline: &FilterPipeline,
    radius: u32,
) -> Result<CpuFiltered, MissingInput> {
    Ok(filter_frame(expr, scene, pipeline, radius, None)?.0)
}

/// [`filter_pipeline`] on a frame of a sequence: a temporal stage blends
/// the frame into `history` (what the frame before kept; none for the
/// first) and the frame's own history for the next comes back beside the
/// result (`None` without a temporal stage).
pub fn filter_frame(
    expr: &Expr,
    scene: &Scene,
    pipeline: &FilterPipeline,
    radius: u32,
    history: Option<&temporal::History>,
) -> Result<(CpuFiltered, Option<temporal::History>), MissingInput> {
    let mut prepared = prepass(scene, pipeline)?;
    let mut working = scene.clone();
    working.color = prepared.color.clone();
    // What the outlier rule measured is read like a variance, at the centre.
    if let Some(local) = prepared.local {
        for (v, values) in ScalarVar::FROM_PREPASS.into_iter().zip(local) {
            working.variances.insert(v, values);
        }
    }
    // The temporal stage: the form filters the blend, and may read what it accumulated.
    let accumulated = match pipeline.temporal {
        Some(stage) => {
            let motion = scene
                .motion
                .as_ref()
                .ok_or_else(|| MissingInput { scene: scene.name.clone(), missing: crate::scene::Missing::Motion })?;
            let accumulated = temporal::accumulate(stage, &working.color, motion, scene.width, scene.height, history);
            working.color = accumulated.color.clone();
            // The result is multiplied back by the albedo blended over frames.
            if prepared.modulation.is_some() {
                prepared.modulation = Some(accumulated.modulation.clone());
            }
            working.variances.insert(ScalarVar::HistoryLength, accumulated.length.clone());
            working.variances.insert(ScalarVar::TemporalVariance, accumulated.variance.clone());
            Some((stage, motion, accumulated))
        }
        None => None,
    };
    // The image the next frame's history starts from: the blend, or a pass's output.
    let feedback_after = accumulated.as_ref().map(|(stage, ..)| stage.feedback);
    let mut feedback = match &accumulated {
        Some((_, _, accumulated)) if feedback_after == Some(0) => Some(accumulated.color.clone()),
        _ => None,
    };
    check_inputs(expr, &working)?;
    let mut out = match pipeline.form {
        Form::Window => {
            let out = filter(expr, &working, radius)?;
            if feedback_after == Some(1) {
                feedback = Some(out.color.iter().map(|c| c.map(|v| v as f32)).collect());
            }
            out
        }
        Form::Atrous { passes, stencil } => {
            if reads_guide(expr) {
                working = with_guide(&working);
            }
            let carried = FilterPipeline::carried_variance(&expr.variables());
            let mut flags = vec![0u32; scene.pixels()];
            let mut last = None;
            for level in 0..passes {
                let step = FilterPipeline::step(level) as i64;
                let half = stencil.half_width() as i64;
                let offsets: Vec<(i64, i64, f64)> = (-half..=half)
                    .flat_map(|dy| {
                        (-half..=half).map(move |dx| {
                            (dx * step, dy * step, stencil.weight(dx as i32) * stencil.weight(dy as i32))
                        })
                    })
                    .collect();
                let (filtered, variance) = pass(expr, &working, &offsets, level, carried);
                for (a, b) in flags.iter_mut().zip(&filtered.flags) {
                    *a |= b;
                }
                working.color = filtered.color.iter().map(|c| c.map(|v| v as f32)).collect();
                if feedback_after == Some(level + 1) {
                    feedback = Some(working.color.clone());
                }
                if reads_guide(expr) {
                    // From the second pass on the guide is the pass's input, already filtered.
                    working.features.insert(Feature::Guide, working.color.clone());
                }
                if let Some(v) = carried {
                    working.variances.insert(v, variance.iter().map(|v| *v as f32).collect());
                }
                last = Some(filtered.color);
            }
            CpuFiltered { color: last.expect("at least one pass"), flags }
        }
    };
    if let Some(m) = &prepared.modulation {
        for (c, m) in out.color.iter_mut().zip(m) {
            *c = [c[0] * m[0] as f64, c[1] * m[1] as f64, c[2] * m[2] as f64];
        }
    }
    if let Some(fit) = pipeline.planefit {
        // The form's output is stored as f32 before the fit reads it, as on the device.
        let image: Vec<[f32; 3]> = out.color.iter().map(|c| c.map(|v| v as f32)).collect();
        let normals = scene.required_feature(Feature::Normal)?;
        out.color = planefit(&image, normals, prepared.modulation.as_deref(), scene.width, scene.height, fit);
    }
    if let Some(anchor) = pipeline.anchor {
        // Stored as f32 before the stage reads it, as on the device.
        let image: Vec<[f32; 3]> = out.color.iter().map(|c| c.map(|v| v as f32)).collect();
        out.color = anchor_light(&scene.color, &image, scene.width, scene.height, anchor);
    }
    if let Some(pixel) = pipeline.pixel_filter {
        // Stored as f32 before the stage reads it, as on the device.
        let image: Vec<[f32; 3]> = out.color.iter().map(|c| c.map(|v| v as f32)).collect();
        out.color = pixel_filter(&image, scene.width, scene.height, pixel);
    }
    let kept = accumulated.map(|(_, motion, accumulated)| {
        let feedback = feedback.expect("the feedback pass is among the form's passes (`most_feedback`)");
        temporal::keep(&accumulated, feedback, motion, scene.width, scene.height)
    });
    Ok((out, kept))
}

/// `pixelfilter=S` on the filtered `image` (docs/SEMANTICS.md, "The
/// pipeline"): each pixel the sum over its 3×3 of w(dx)·w(dy) times the tap,
/// with `pipeline::PixelFilter::weights` and taps outside the image clamped
/// to its edge. The reference of `templates/pixelfilter.wgsl.tera`.
pub fn pixel_filter(image: &[[f32; 3]], width: usize, height: usize, filter: pipeline::PixelFilter) -> Vec<[f64; 3]> {
    let [centre, side] = filter.weights().map(f64::from);
    let tap = |x: i64, y: i64| {
        let (x, y) = (x.clamp(0, width as i64 - 1) as usize, y.clamp(0, height as i64 - 1) as usize);
        image[y * width + x].map(f64::from)
    };
    // As the kernel sums: each row weighed by w(dx), then the rows by w(dy).
    let row = |x: i64, y: i64| {
        let (left, middle, right) = (tap(x - 1, y), tap(x, y), tap(x + 1, y));
        std::array::from_fn::<f64, 3, _>(|k| side * (left[k] + right[k]) + centre * middle[k])
    };
    let mut out = Vec::with_capacity(image.len());
    for y in 0..height as i64 {
        for x in 0..width as i64 {
            let (above, middle, below) = (row(x, y - 1), row(x, y), row(x, y + 1));
            out.push(std::array::from_fn(|k| side * (above[k] + below[k]) + centre * middle[k]));
        }
    }
    out
}

/// `planefit=R` on the form's output `image` (docs/SEMANTICS.md, "The
/// pipeline"): each pixel's demodulated colour (divided by `modulation`
/// where the pipeline demodulates) moved toward the value at the pixel of a
/// plane fitted by weighted least squares over its (2R+1)² neighbourhood
/// (`pipeline::PlaneFit::weight`), as far as the plane's slope lets it
/// (`pipeline::PLANEFIT_SLOPE_TAU`), then multiplied back. The reference of
/// `templates/planefit.wgsl.tera`, formula for formula.
pub fn planefit(
    image: &[[f32; 3]],
    normals: &[[f32; 3]],
    modulation: Option<&[[f32; 3]]>,
    width: usize,
    height: usize,
    fit: pipeline::PlaneFit,
) -> Vec<[f64; 3]> {
    use pipeline::{LUMINANCE, PLANEFIT_RIDGE, PLANEFIT_SLOPE_CAP, PLANEFIT_SLOPE_TAU, PLANEFIT_TINY};
    let (w, h, r) = (width as i64, height as i64, fit.radius as i64);
    let f64s = |c: [f32; 3]| c.map(|v| v as f64);
    let modulation_at = |i: usize| modulation.map_or([1.0; 3], |m| f64s(m[i]));
    let demodulated: Vec<[f64; 3]> = (0..image.len())
        .map(|i| {
            let (c, m) = (f64s(image[i]), modulation_at(i));
            [c[0] / m[0], c[1] / m[1], c[2] / m[2]]
        })
        .collect();
    let luminance: Vec<f64> = demodulated.iter().map(|&c| pipeline::luminance(c)).collect();
    let signed = |c: [f64; 3]| LUMINANCE[0] * c[0] + LUMINANCE[1] * c[1] + LUMINANCE[2] * c[2];
    (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .map(|(x, y)| {
            let i = (y * w + x) as usize;
            let mut moments = [Neumaier::default(); 6]; // s, su, sv, suu, svv, suv
            let mut sums = [[Neumaier::default(); 3]; 3]; // b0, bu, bv per channel
            for dy in -r..=r {
                for dx in -r..=r {
                    let (xj, yj) = (x + dx, y + dy);
                    if xj < 0 || yj < 0 || xj >= w || yj >= h {
                        continue;
                    }
                    let j = (yj * w + xj) as usize;
                    let normal_pair = (f64s(normals[i]), f64s(normals[j]));
                    let weight = fit.weight(dx as i32, dy as i32, normal_pair, (luminance[i], luminance[j]));
                    let (u, v) = (dx as f64 / r as f64, dy as f64 / r as f64);
                    for (m, term) in moments.iter_mut().zip([1.0, u, v, u * u, v * v, u * v]) {
                        m.add(weight * term);
                    }
                    for (sum, factor) in sums.iter_mut().zip([1.0, u, v]) {
                        for (s, l) in sum.iter_mut().zip(demodulated[j]) {
                            s.add(weight * factor * l);
                        }
                    }
                }
            }
            let [s, su, sv, suu, svv, suv] = moments.map(|m| m.total());
            let [b0, bu, bv] = sums.map(|sum| sum.map(|t| t.total()));
            let (mu, mv) = (su / s, sv / s);
            let mean = b0.map(|b| b / s);
            let cuu = suu / s - mu * mu + PLANEFIT_RIDGE / s;
            let cvv = svv / s - mv * mv + PLANEFIT_RIDGE / s;
            let cuv = suv / s - mu * mv;
            // Each slope moment holds at least λ / s, so the determinant is at least its square.
            let det = (cuu * cvv - cuv * cuv).max(PLANEFIT_RIDGE * PLANEFIT_RIDGE / (s * s));
            let mut slope_u = [0.0; 3];
            let mut slope_v = [0.0; 3];
            let mut a = [0.0; 3];
            for k in 0..3 {
                let cul = bu[k] / s - mu * mean[k];
                let cvl = bv[k] / s - mv * mean[k];
                slope_u[k] = (cvv * cul - cuv * cvl) / det;
                slope_v[k] = (cuu * cvl - cuv * cul) / det;
                a[k] = mean[k] - slope_u[k] * mu - slope_v[k] * mv;
            }
            let slope = signed(slope_u).hypot(signed(slope_v));
            let steep = (slope / signed(a).abs().max(PLANEFIT_TINY)).min(PLANEFIT_SLOPE_CAP) / PLANEFIT_SLOPE_TAU;
            let trust = 1.0 / (1.0 + steep * steep);
            let (l, m) = (demodulated[i], modulation_at(i));
            [0, 1, 2].map(|k| (l[k] + trust * (a[k] - l[k])) * m[k])
        })
        .collect()
}

/// Neumaier's compensated sum: the reference keeps its sums exact to about
/// one rounding, however large the window.
#[derive(Clone, Copy, Debug, Default)]
pub struct Neumaier {
    sum: f64,
    compensation: f64,
}

impl Neumaier {
    pub fn add(&mut self, x: f64) {
        let t = self.sum + x;
        if self.sum.abs() >= x.abs() {
            self.compensation += (self.sum - t) + x;
        } else {
            self.compensation += (x - t) + self.sum;
        }
        self.sum = t;
    }

    pub fn total(&self) -> f64 {
        self.sum + self.compensation
    }
}

/// Evaluate the weight expression once, for tests of single operators.
pub fn weight_at(expr: &Expr, scene: &Scene, i: usize, j: usize) -> (f64, u32) {
    let mut flags = 0;
    let w = eval(expr, &Pixels { scene, i, j, width: scene.width, level: 0 }, &mut flags);
    (w, flags)
}

#[cfg(test)]
mod pixel_filter_tests {
    use super::pixel_filter;
    use crate::pipeline::PixelFilter;

    #[test]
    fn an_impulse_spreads_into_the_separable_weights_and_keeps_its_light() {
        let (width, height) = (5, 4);
        let mut image = vec![[0.0f32; 3]; width * height];
        image[2 * width + 2] = [1.0, 2.0, 0.0];
        let filter = PixelFilter { sigma: 0.5 };
        let [centre, side] = filter.weights().map(f64::from);
        let out = pixel_filter(&image, width, height, filter);
        let w = |d: i64| if d == 0 { centre } else { side };
        for y in 0..height as i64 {
            for x in 0..width as i64 {
                let (dx, dy) = (x - 2, y - 2);
                let expected = if dx.abs() <= 1 && dy.abs() <= 1 { w(dx) * w(dy) } else { 0.0 };
                let got = out[y as usize * width + x as usize];
                assert!((got[0] - expected).abs() < 1e-12 && (got[1] - 2.0 * expected).abs() < 1e-12, "({x}, {y})");
            }
        }
        let total: f64 = out.iter().map(|c| c[0]).sum();
        assert!((total - 1.0).abs() < 1e-6, "the light is kept: {total}");
    }

    #[test]
    fn an_even_image_stays_even_to_its_edges() {
        let (width, height) = (3, 2);
        let image = vec![[0.25f32, 4.0, 1.0]; width * height];
        for c in pixel_filter(&image, width, height, PixelFilter { sigma: 1.0 }) {
            assert!((c[0] - 0.25).abs() < 1e-6 && (c[1] - 4.0).abs() < 1e-6, "{c:?}");
        }
    }
}
