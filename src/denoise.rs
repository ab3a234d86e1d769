//! A render denoised with a filter: the one asked for, or else the best
//! shipped filter whose inputs the render has; the inputs it reads requested
//! from the scene, its pipeline run on the device. The command line's
//! `filter` and the Python module's `denoise` both go through here, so that
//! they choose alike and give the same pixels.

use std::collections::BTreeSet;

use anyhow::{bail, Result};

use crate::corpus;
use crate::gpu::{Filtered, Gpu, SceneBuffers, TemporalState};
use crate::jit;
use crate::lang::{Expr, Feature, ScalarVar};
use crate::pipeline::{FilterPipeline, Form, PixelFilter, Stencil};
use crate::scene::Scene;
use crate::scene::{Holds, Missing, Needs, Request};

/// The shipped filters a render gets when none is asked for, best first, as
/// measured on the seventeen built-in scenes (128x128, 4 spp, 1024-spp
/// references), never on the public renders: the à-trous filters by the
/// geometric mean of their relMSE charged for the light they move
/// ([`crate::fitness::charged`], tolerance 0.05: bias is an error like any
/// other), then the window filters. The first whose inputs a render has is
/// taken; `bilateral` reads colour alone, so there always is one
/// (docs/JOURNAL.md, "Fitness that charges the light").
pub const SHIPPED_BY_QUALITY: &[&str] = &[
    "evolvedAtrous64Plane",
    // The default's weight with the depth for the position, then with
    // neither: every filter after them but `evolvedAtrous64ColorOnly` and
    // `bilateral` reads the position, so where a render lacks it these are
    // what it gets, wherever they stand (docs/JOURNAL.md, "Renders without
    // world positions").
    "evolvedAtrous64PlaneDepth",
    "evolvedAtrous64PlaneNoPosition",
    "evolvedAtrous64Surface",
    "evolvedAtrous64Trim",
    "evolvedAtrous128Trim",
    "evolvedAtrous128Trim3x3",
    "evolvedAtrous128Guide",
    "evolvedAtrous128Guide3x3",
    "evolvedAtrous128Keep",
    "evolvedAtrous3x3Keep",
    "evolvedAtrous128",
    "crossBilateralAtrous",
    "evolvedAtrous3x3",
    "svgfAtrous",
    "crossBilateralTuned",
    "evolvedAtrous64ColorOnly",
    "bilateral",
];

/// The shipped filter meant for real time: chosen on the built-in scenes
/// from a front of error against whole-frame time at 1920x1080
/// (docs/JOURNAL.md, "Choosing the real-time filter").
pub const SHIPPED_REALTIME: &str = "realtime";

/// The shipped filter meant for real-time sequences: `@temporal` with four
/// passes of the 3x3 stencil (docs/SEQUENCES.md, "The real-time sequence filter").
pub const SHIPPED_REALTIME_TEMPORAL: &str = "realtimeTemporal";

/// The shipped temporal filters a sequence gets when none is asked for,
/// best first (docs/SEQUENCES.md, "Measured"); the first whose inputs the
/// frames have is taken.
pub const SHIPPED_TEMPORAL_BY_QUALITY: &[&str] = &["temporal", "temporalDepth", "svgf"];

/// Shipped filters with a variant for renders whose light is sparse, and
/// that variant: the same inputs, the weight's pixel term widened from pass
/// to pass (and for `@evolvedAtrous64Plane` and `@realtime`, one à-trous pass
/// more). A chosen filter, or a role asked for without a pipeline
/// ([`FOLLOWS_THE_LIGHT_WHEN_ASKED`]), gives way
/// to its variant where the noisy input's median pixel is black or nearly
/// ([`SPARSE_MEDIAN_OVER_MEAN`]): at a few samples a pixel most pixels
/// caught no light, and the filter must gather from farther to estimate it
/// (docs/JOURNAL.md, "A wider reach where the light is sparse").
pub const SPARSE_LIGHT_VARIANTS: &[SparseLightVariant] = &[
    SparseLightVariant::below("evolvedAtrous64Plane", "evolvedAtrous64PlaneSparse", SPARSE_MEDIAN_OVER_MEAN),
    SparseLightVariant::below("evolvedAtrous64PlaneDepth", "evolvedAtrous64PlaneDepthSparse", SPARSE_MEDIAN_OVER_MEAN),
    SparseLightVariant::below(
        "evolvedAtrous64PlaneNoPosition",
        "evolvedAtrous64PlaneNoPositionSparse",
        SPARSE_MEDIAN_OVER_MEAN,
    ),
    SparseLightVariant::below("evolvedAtrous64Surface", "evolvedAtrous64SurfaceSparse", SPARSE_MEDIAN_OVER_MEAN),
    SparseLightVariant::below("evolvedAtrous64Trim", "evolvedAtrous64TrimSparse", SPARSE_MEDIAN_OVER_MEAN),
    SparseLightVariant::below("realtime", "realtimeSparse", REALTIME_SPARSE_MEDIAN_OVER_MEAN),
];

/// A shipped filter's variant for sparse light, and where the light counts
/// as sparse for it: the noisy colour's median pixel luminance over its
/// mean ([`crate::metrics::Tails::median_over_mean`]) below `under`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SparseLightVariant {
    pub base: &'static str,
    pub variant: &'static str,
    pub under: f64,
}

impl SparseLightVariant {
    const fn below(base: &'static str, variant: &'static str, under: f64) -> SparseLightVariant {
        SparseLightVariant { base, variant, under }
    }

    /// Where a render whose noisy colour is `color` is sparse for this variant, its median over mean.
    pub fn sparse_for<A: Copy + Into<f64>>(&self, color: &[[A; 3]]) -> Option<f64> {
        crate::metrics::tails(color).map(|t| t.median_over_mean).filter(|m| *m < self.under)
    }
}

/// Shipped names that stand for a role rather than one weight: asked for by
/// name without a pipeline, they still give way to their sparse-light
/// variant ([`SPARSE_LIGHT_VARIANTS`]) as a chosen filter does. `@realtime` is "the real-time filter", which nothing chooses for a
/// render, so it is always asked for; where the light is sparse its three 3x3
/// passes stop short (docs/JOURNAL.md, "The real-time filter where the light
/// is sparse"). A pipeline the caller gives keeps the filter asked for.
pub const FOLLOWS_THE_LIGHT_WHEN_ASKED: &[&str] = &[SHIPPED_REALTIME];

/// The noisy input's median pixel luminance over its mean below which its
/// light counts as sparse for `filter`'s default and its family
/// ([`crate::metrics::Tails::median_over_mean`]). At 4 spp the built-in
/// scenes are either 0.000 (two, lit through an opening or round a corner)
/// or 0.27 and above (docs/SCENES.md). On the scenes made to fill that gap
/// (`scenes/sparse-light/`, medians 0.055–0.55) the default's variant is
/// better below 0.17 and worse at 0.19, but on the one public render in
/// between (0.128) it is worse: a black median is the case it is sure of
/// (docs/JOURNAL.md, "Where the light counts as sparse").
pub const SPARSE_MEDIAN_OVER_MEAN: f64 = 0.05;

/// The same for `@realtime`, whose three 3x3 passes reach seven pixels: its
/// variant is better on every one of those scenes below 0.19 (by 16–19 %
/// from 0.05 to 0.19), so the threshold sits a margin below.
pub const REALTIME_SPARSE_MEDIAN_OVER_MEAN: f64 = 0.15;

/// The sparse-light variant that a filter asked for by `name` with `expr`
/// gives way to where a render's light is sparse: a role's
/// ([`FOLLOWS_THE_LIGHT_WHEN_ASKED`]), unless the caller gave a pipeline.
/// The shipped role, not an entry of a user's file that bears its name: its
/// expression must be the shipped one. What `report` runs in a role's place.
pub fn asked_variant(name: &str, expr: &Expr, pipeline_given: bool) -> Option<&'static SparseLightVariant> {
    if pipeline_given || !FOLLOWS_THE_LIGHT_WHEN_ASKED.contains(&name) {
        return None;
    }
    let shipped = corpus::resolve_with_pipeline(&format!("@{name}")).ok()?;
    (shipped.expr == *expr).then(|| sparse_light_variant(name))?
}

/// The shipped filter `name`'s sparse-light variant ([`SPARSE_LIGHT_VARIANTS`]).
fn sparse_light_variant(name: &str) -> Option<&'static SparseLightVariant> {
    SPARSE_LIGHT_VARIANTS.iter().find(|v| v.base == name)
}

/// Samples per pixel from which `filter`'s choice runs [`FEWER_PASSES`] 5x5
/// à-trous passes where it has three, for a render of
/// [`FEWER_PASSES_MEASURED_AT`] pixels on a side: less noise to spread, and
/// the last pass's reach blurs what the samples already resolve. On the
/// thirteen built-in training scenes (128²) two passes have 0.984× three's
/// relMSE at 8 spp and 0.942× at 16 (geometric means; on the four test
/// scenes 0.884× and 0.828×); the pipeline's three were chosen at 4 spp
/// (docs/JOURNAL.md, "Fewer passes where the render has more samples").
pub const FEWER_PASSES_FROM_SPP: u32 = 8;

/// The passes a render of [`FEWER_PASSES_FROM_SPP`] or more samples gets:
/// two, never one. One pass won on the training scenes (0.866× two's relMSE
/// at 128² and 64 spp, 0.853× at 256² and 128) and lost on the held-out
/// test scenes: better on one of four at 128², on none at 256² (1.24×
/// two's, noise-texture 1.77× and above its noisy input), where two passes
/// beat three on all four (docs/JOURNAL.md, "One pass fails the test scenes").
pub const FEWER_PASSES: u32 = 2;

/// The size [`FEWER_PASSES_FROM_SPP`] was measured at, in pixels on a side.
/// A wider render needs proportionally more samples for the same rule: its
/// surfaces span more pixels, so the passes' reach blurs less of them. At
/// 256² two passes have 1.009× three's relMSE at 8 spp and 0.973× at 16 on
/// the training scenes, as at 128² with 4 spp (1.040×) and 8 (0.974×)
/// (docs/JOURNAL.md, "The pass rule at other sizes"). Smaller renders keep
/// the count measured here.
pub const FEWER_PASSES_MEASURED_AT: u32 = 128;

/// Where a render's sample count took a pass away ([`FEWER_PASSES`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FewerPasses {
    /// The render's samples a pixel.
    pub spp: u32,
    /// Its width and height.
    pub size: (usize, usize),
    /// The count the rule applies from at this size.
    pub from: u32,
    /// The passes it runs.
    pub passes: u32,
}

/// Whether a render of `spp` samples a pixel and `size` pixels gets
/// [`FEWER_PASSES`]: [`FEWER_PASSES_FROM_SPP`] scaled by the render's side
/// (the square root of its pixels) over [`FEWER_PASSES_MEASURED_AT`].
fn fewer_passes(spp: u32, size: (usize, usize)) -> Option<FewerPasses> {
    let side = ((size.0 as f64) * (size.1 as f64)).sqrt();
    let scale = (side / f64::from(FEWER_PASSES_MEASURED_AT)).max(1.0);
    // `as` saturates: a count past u32::MAX is never reached.
    let from = (f64::from(FEWER_PASSES_FROM_SPP) * scale).ceil() as u32;
    (spp >= from).then_some(FewerPasses { spp, size, from, passes: FEWER_PASSES })
}

pub const DEFAULT_RADIUS: u32 = 5;

/// The inputs a render has: stored features (colour and pixel position
/// always) and per-pixel variances.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Provided {
    pub features: BTreeSet<Feature>,
    pub variances: BTreeSet<ScalarVar>,
    /// Motion vectors to the frame before (a sequence's frames), which a temporal stage reprojects by.
    pub motion: bool,
    /// Whether the render is a frame of a sequence (the choice then prefers temporal filters).
    pub sequence: bool,
}

impl Provided {
    /// From the stored features a render has (colour, pixel and gradients are derived).
    pub fn new(stored: BTreeSet<Feature>, variances: BTreeSet<ScalarVar>) -> Self {
        Provided { features: crate::scene::with_derived(stored), variances, motion: false, sequence: false }
    }
}

/// A filter ready to run: its expression, pipeline and radius, and how it was chosen.
#[derive(Clone, Debug)]
pub struct Choice {
    /// The shipped or stored name, when it has one.
    pub name: Option<String>,
    pub expr: Expr,
    pub pipeline: FilterPipeline,
    pub radius: u32,
    /// Why this filter (and pipeline), where filterjit chose either.
    pub chosen_because: Option<Because>,
}

/// A shipped filter passed over, with the inputs it reads that the render lacks.
pub type PassedOver = (String, Vec<Missing>);

/// Why a filter was chosen, as data: the command line renders it with
/// filterjit's names for the inputs (`Display`), the Python module with its
/// arguments' ([`Because::render`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Because {
    /// Whether the filter was chosen (else it was asked for, and only its pipeline's end was).
    pub chosen: bool,
    /// The better shipped filters passed over, best first.
    pub passed_over: Vec<PassedOver>,
    /// For a sequence's frames, the temporal filters passed over where none
    /// fits: the filter then runs frame by frame.
    pub no_temporal: Vec<PassedOver>,
    /// Where the sparse-light variant was taken: the render's median pixel
    /// over its mean luminance, and the variant's threshold.
    pub sparse_light: Option<(f64, f64)>,
    /// Whether the pixel filter was added for a render sampled at one point a pixel.
    pub point_sampled: bool,
    /// Where a pass was left out for a render of many samples
    /// ([`FEWER_PASSES`]).
    pub fewer_passes: Option<FewerPasses>,
}

/// How a caller names the inputs a filter reads, for [`Because::render`].
pub trait InputNames {
    /// An input, with why a render may lack it where that is not plain.
    fn full(&self, missing: Missing) -> String;
    /// An input, in a list of several.
    fn short(&self, missing: Missing) -> String;
    /// Where each shipped filter's inputs are listed.
    fn listing(&self) -> &str;
}

/// filterjit's own names (`worldPosition`, `texture (the albedo …)`).
struct FilterjitNames;

impl InputNames for FilterjitNames {
    fn full(&self, missing: Missing) -> String {
        missing.to_string()
    }

    fn short(&self, missing: Missing) -> String {
        missing.name().to_string()
    }

    fn listing(&self) -> &str {
        "`filterjit list`"
    }
}

impl Because {
    /// In words, the inputs named by `names`.
    pub fn render(&self, names: &dyn InputNames) -> String {
        let full = |lacks: &[Missing]| lacks.iter().map(|m| names.full(*m)).collect::<Vec<_>>().join(", ");
        let mut parts = Vec::new();
        if self.chosen {
            let mut chosen = match self.passed_over.as_slice() {
                [] => "the best shipped filter, and the render has every input it reads".to_string(),
                [(best, lacks)] => {
                    format!(
                        "the best shipped filter whose inputs the render has (@{best}, the best, needs {})",
                        full(lacks)
                    )
                }
                // One line, not one clause a filter passed over: what the better ones lack, together.
                [(best, lacks), ..] => {
                    let mut all: Vec<String> = Vec::new();
                    for input in self.passed_over.iter().flat_map(|(_, lacks)| lacks) {
                        let name = names.short(*input);
                        if !all.contains(&name) {
                            all.push(name);
                        }
                    }
                    format!(
                        "the best shipped filter whose inputs the render has: the {} better ones read what it lacks \
                         ({}; @{best}, the best, needs {}); {} gives each one's inputs",
                        self.passed_over.len(),
                        all.join(", "),
                        full(lacks),
                        names.listing()
                    )
                }
            };
            if !self.no_temporal.is_empty() {
                // Filters that lack the same inputs in one clause: the reason is said once.
                let mut groups: Vec<(Vec<&str>, &[Missing])> = Vec::new();
                for (name, lacks) in &self.no_temporal {
                    match groups.iter_mut().find(|(_, same)| *same == lacks.as_slice()) {
                        Some((names, _)) => names.push(name),
                        None => groups.push((vec![name], lacks)),
                    }
                }
                let each: Vec<String> = groups
                    .iter()
                    .map(|(names, lacks)| {
                        let names: Vec<String> = names.iter().map(|name| format!("@{name}")).collect();
                        let need = if names.len() == 1 { "needs" } else { "need" };
                        format!("{} {need} {}", names.join(", "), full(lacks))
                    })
                    .collect();
                chosen = format!("{chosen}, frame by frame (no shipped temporal filter fits: {})", each.join("; "));
            }
            parts.push(chosen);
        }
        if let Some((median_over_mean, under)) = self.sparse_light {
            // Asked for by name, the filter changed: say how to keep it.
            let keep = if self.chosen { "" } else { "; a pipeline given keeps the filter asked for" };
            parts.push(format!(
                "its variant for sparse light, as the render's median pixel is {median_over_mean:.3} of its mean \
                 luminance (under {under}){keep}"
            ));
        }
        if let Some(FewerPasses { spp, size: (width, height), from, passes }) = self.fewer_passes {
            let passes = match passes {
                2 => "two à-trous passes".to_string(),
                n => format!("{n} à-trous passes"),
            };
            parts.push(format!(
                "{passes}, not three, as the render has {spp} samples a pixel (from {from} on at its \
                 {width}x{height} pixels: less noise to spread)"
            ));
        }
        if self.point_sampled {
            parts.push(
                "then the pixel filter, as the render samples each pixel at one point (Cycles at 1 sample)".to_string(),
            );
        }
        parts.join("; ")
    }
}

impl std::fmt::Display for Because {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.render(&FilterjitNames))
    }
}

impl Choice {
    /// A filter asked for: an expression's text, `@name` of a shipped one or
    /// `@FILE[:NAME]`; `pipeline` and `radius` override what it was stored with.
    pub fn asked(filter: &str, pipeline: Option<FilterPipeline>, radius: Option<u32>) -> Result<Choice> {
        let resolved = corpus::resolve_with_pipeline(filter)?;
        Ok(Choice {
            name: resolved.name,
            expr: resolved.expr,
            pipeline: pipeline.or(resolved.pipeline).unwrap_or_default(),
            radius: radius.or(resolved.radius).unwrap_or(DEFAULT_RADIUS),
            chosen_because: None,
        })
    }

    /// The best shipped filter (`SHIPPED_BY_QUALITY`) whose inputs `provided` has.
    pub fn best_for(provided: &Provided) -> Result<Choice> {
        Self::best_single(provided, None)
    }

    /// [`Choice::best_for`] in `pipeline` where one is given: the best
    /// shipped weight whose inputs the render has in that pipeline.
    fn best_single(provided: &Provided, pipeline: Option<FilterPipeline>) -> Result<Choice> {
        match Self::best_of(SHIPPED_BY_QUALITY, provided, pipeline)? {
            Ok(choice) => Ok(choice),
            Err(passed_over) => {
                let each: Vec<String> = passed_over
                    .iter()
                    .map(|(name, lacks)| {
                        let lacks: Vec<String> = lacks.iter().map(Missing::to_string).collect();
                        format!("@{name} needs {}", lacks.join(", "))
                    })
                    .collect();
                bail!("no shipped filter fits this render: {}", each.join("; "))
            }
        }
    }

    /// The best shipped temporal filter (`SHIPPED_TEMPORAL_BY_QUALITY`) whose
    /// inputs a sequence's frames (`provided`) have; without motion vectors,
    /// the best filter of single renders, frame by frame.
    pub fn best_temporal_for(provided: &Provided) -> Result<Choice> {
        Self::best_sequence(provided, None)
    }

    /// [`Choice::best_temporal_for`] in `pipeline` where one is given (a
    /// pipeline without the temporal stage fits no temporal filter).
    fn best_sequence(provided: &Provided, pipeline: Option<FilterPipeline>) -> Result<Choice> {
        match Self::best_of(SHIPPED_TEMPORAL_BY_QUALITY, provided, pipeline)? {
            Ok(choice) => Ok(choice),
            Err(no_temporal) => {
                let choice = Self::best_single(provided, pipeline)?;
                let because = Because { no_temporal, ..choice.chosen_because.clone().unwrap_or_default() };
                Ok(Choice { chosen_because: Some(because), ..choice })
            }
        }
    }

    /// The first of `names` (shipped filters, best first) whose inputs
    /// `provided` has, each in its own pipeline or in `pipeline` where one
    /// is given, or else each one with what it lacks.
    fn best_of(
        names: &[&str],
        provided: &Provided,
        pipeline: Option<FilterPipeline>,
    ) -> Result<Result<Choice, Vec<PassedOver>>> {
        let mut passed_over = Vec::new();
        for name in names {
            let choice = Choice::asked(&format!("@{name}"), pipeline, None)?;
            let missing = choice.missing(provided);
            if missing.is_empty() {
                let because = Because { chosen: true, passed_over, ..Because::default() };
                return Ok(Ok(Choice { chosen_because: Some(because), ..choice }));
            }
            passed_over.push((name.to_string(), missing));
        }
        Ok(Err(passed_over))
    }

    /// This choice for a render whose noisy colour is `color`: a chosen
    /// filter with a sparse-light variant ([`SPARSE_LIGHT_VARIANTS`]) gives
    /// way to it where the render's light is sparse, in the variant's own
    /// pipeline unless the caller gave one (`pipeline_given`); so does a role
    /// asked for by name without a pipeline ([`FOLLOWS_THE_LIGHT_WHEN_ASKED`]);
    /// anything else, and any other filter asked for, stays. The variant
    /// reads what its filter reads, so the render loaded for the first serves
    /// the second.
    pub fn for_light<A: Copy + Into<f64>>(self, color: &[[A; 3]], pipeline_given: bool) -> Result<Choice> {
        let Some(name) = &self.name else { return Ok(self) };
        let chosen = self.chosen_because.as_ref().is_some_and(|b| b.chosen);
        let variant = match chosen {
            true => sparse_light_variant(name),
            false => asked_variant(name, &self.expr, pipeline_given),
        };
        let Some(variant) = variant else { return Ok(self) };
        let Some(median_over_mean) = variant.sparse_for(color) else { return Ok(self) };
        let because = self.chosen_because.clone().unwrap_or_default();
        let asked = Choice::asked(&format!("@{}", variant.variant), None, None)?;
        Ok(Choice {
            name: asked.name,
            expr: asked.expr,
            pipeline: if pipeline_given { self.pipeline } else { asked.pipeline },
            chosen_because: Some(Because { sparse_light: Some((median_over_mean, variant.under)), ..because }),
            ..self
        })
    }

    /// This choice for a render of `spp` samples a pixel and `size` pixels:
    /// `filter`'s choice of a still's filter runs two 5x5 à-trous passes
    /// where it has three from [`FEWER_PASSES_FROM_SPP`] on at 128² and
    /// proportionally more on wider renders (`fewer_passes`); a
    /// filter asked for, a pipeline given, a sparse-light variant (whose
    /// light needs the reach) and a sequence's filter stay as they are.
    /// Where the count is unknown (arrays, renders without a header or
    /// `meta.json`) nothing changes.
    pub fn for_samples(self, spp: Option<u32>, size: (usize, usize), pipeline_given: bool) -> Choice {
        let Some(rule) = spp.and_then(|spp| fewer_passes(spp, size)) else { return self };
        let because = self.chosen_because.clone().unwrap_or_default();
        let three = Form::Atrous { passes: 3, stencil: Stencil::Cubic5 };
        let still = self.pipeline.temporal.is_none() && self.pipeline.form == three;
        if pipeline_given || !because.chosen || because.sparse_light.is_some() || !still {
            return self;
        }
        let form = Form::Atrous { passes: rule.passes, stencil: Stencil::Cubic5 };
        Choice {
            pipeline: FilterPipeline { form, ..self.pipeline },
            chosen_because: Some(Because { fewer_passes: Some(rule), ..because }),
            ..self
        }
    }

    /// This choice for a render (or a sequence's frames) whose renderer
    /// sampled every pixel at one point (`point_sampled`: Cycles at one
    /// sample, `scene::point_sampled`; the same point in every frame), while
    /// a reference integrates its pixel filter: the pipeline ends with that filter
    /// ([`PixelFilter::POINT_SAMPLED`]), unless the caller gave the pipeline
    /// (`pipeline_given`) or it has one already. Why goes into
    /// `chosen_because`, which then says so for a filter asked for too.
    pub fn for_point_sampled(self, point_sampled: bool, pipeline_given: bool) -> Choice {
        if !point_sampled || pipeline_given || self.pipeline.pixel_filter.is_some() {
            return self;
        }
        Choice {
            pipeline: FilterPipeline { pixel_filter: Some(PixelFilter::POINT_SAMPLED), ..self.pipeline },
            chosen_because: Some(Because { point_sampled: true, ..self.chosen_because.unwrap_or_default() }),
            ..self
        }
    }

    /// The filter asked for, or else the best shipped one for what the
    /// render provides (for a sequence's frames, the best temporal one).
    pub fn asked_or_best(
        filter: Option<&str>,
        pipeline: Option<FilterPipeline>,
        radius: Option<u32>,
        provided: &Provided,
    ) -> Result<Choice> {
        match filter {
            Some(filter) => Choice::asked(filter, pipeline, radius),
            None => {
                // The best whose inputs the render has in the pipeline given, where one is.
                let best = match provided.sequence {
                    true => Choice::best_sequence(provided, pipeline)?,
                    false => Choice::best_single(provided, pipeline)?,
                };
                Ok(Choice { radius: radius.unwrap_or(best.radius), ..best })
            }
        }
    }

    /// The inputs this filter reads that `provided` lacks (the albedo, which
    /// demodulation divides by, among them): `scene::Needs`'s rule.
    pub fn missing(&self, provided: &Provided) -> Vec<Missing> {
        let holds = Holds {
            features: &provided.features,
            variances: &provided.variances,
            measured: self.pipeline.outliers.is_some(),
            accumulated: self.pipeline.is_temporal(),
            albedo: provided.features.contains(&Feature::Texture),
            motion: provided.motion,
        };
        Needs::of_filter(&self.expr, &self.pipeline).missing(holds)
    }

    /// What a scene must hold for this filter (its reference too, for errors).
    pub fn request(&self) -> Request {
        let mut request = Request {
            albedo: self.pipeline.demodulate,
            motion: self.pipeline.is_temporal(),
            ..Request::for_expr(&self.expr)
        };
        request.features.extend(self.pipeline.features());
        request
    }

    /// How the filter is called in messages: `@name` or the expression.
    pub fn describe(&self) -> String {
        match &self.name {
            Some(name) => format!("@{name}"),
            None => self.expr.to_string(),
        }
    }

    /// The filter's kernel for its pipeline, lowered and validated.
    pub fn compile(&self) -> Result<jit::ValidatedKernel> {
        let shape = jit::Shape::of(&self.pipeline);
        Ok(jit::compile(&self.expr, jit::KernelSpec { shape, ..jit::KernelSpec::default() })?)
    }
}

/// A shipped filter as `filterjit list` shows it.
pub struct Shipped {
    pub name: &'static str,
    pub pipeline: FilterPipeline,
    /// What a render must hold for it: `color`, the stored features, the
    /// per-pixel variances, and `albedo` where it demodulates.
    pub reads: Vec<&'static str>,
    /// Its place in the order `filter` tries shipped filters in when none is
    /// asked for (`SHIPPED_BY_QUALITY`), from 1.
    pub rank: Option<usize>,
    /// What it was measured to do on the public renders (its `# measured:` line).
    pub measured: Option<&'static str>,
    /// The entry whose weight it shares, where the file writes it as `@other`.
    pub weight_of: Option<&'static str>,
    /// The filter it stands in for where a render's light is sparse ([`SPARSE_LIGHT_VARIANTS`]).
    pub sparse_light_variant_of: Option<&'static SparseLightVariant>,
    pub text: &'static str,
}

/// Every shipped filter, in file order.
pub fn shipped() -> Result<Vec<Shipped>> {
    corpus::named()
        .into_iter()
        .map(|(name, text)| {
            let choice = Choice::asked(&format!("@{name}"), None, None)?;
            let needs = Needs::of_filter(&choice.expr, &choice.pipeline);
            let mut reads = vec!["color"];
            let bases: BTreeSet<&'static str> =
                needs.features.iter().filter(|f| **f != Feature::Color).map(|f| f.base().name()).collect();
            reads.extend(bases);
            reads.extend(needs.variances.iter().map(|v| v.name()));
            if needs.albedo {
                reads.push("albedo");
            }
            Ok(Shipped {
                name,
                pipeline: choice.pipeline,
                reads,
                rank: SHIPPED_BY_QUALITY.iter().position(|n| *n == name).map(|k| k + 1),
                measured: corpus::shipped().get(name).and_then(|e| e.measured()),
                weight_of: corpus::shipped().get(name).and_then(|e| e.alias_of()),
                sparse_light_variant_of: SPARSE_LIGHT_VARIANTS.iter().find(|v| v.variant == name),
                text,
            })
        })
        .collect()
}

/// `scene` filtered on `gpu` with `kernel` (the choice's, [`Choice::compile`]):
/// the pre-pass, then the form, in one submission, read back. A temporal
/// filter's single frame is the first of its sequence.
pub fn filter(gpu: &Gpu, choice: &Choice, kernel: &jit::ValidatedKernel, scene: &Scene) -> Result<Filtered> {
    let mut buffers = SceneBuffers::for_frame(gpu, scene, &choice.pipeline)?;
    Ok(gpu.filter(kernel, &mut buffers, scene, choice.radius)?)
}

/// The next frame of a sequence filtered on `gpu` with `kernel` (the
/// choice's), in one submission: a temporal pipeline blends it into
/// `state`'s history and leaves its own there for the frame after; any other
/// filters the frame alone. [`SequenceFilter`] and Python's `Denoiser` share it.
pub fn filter_frame(
    gpu: &Gpu,
    choice: &Choice,
    kernel: &jit::ValidatedKernel,
    scene: &Scene,
    state: &mut TemporalState,
) -> Result<FilteredFrame> {
    let mut buffers = SceneBuffers::for_frame(gpu, scene, &choice.pipeline)?;
    let filtered = gpu.filter_frame(kernel, &mut buffers, scene, choice.radius, state)?;
    Ok(FilteredFrame { filtered, temporal: buffers.temporal_time() })
}

/// A frame of a sequence, filtered.
pub struct FilteredFrame {
    pub filtered: Filtered,
    /// The temporal stage's part of the frame's time, where its pipeline has one.
    pub temporal: Option<crate::gpu::Span>,
}

/// A sequence filtered frame by frame on one device: the filter's kernel,
/// and the temporal state its pipeline carries from each frame to the next
/// (none for a filter without a temporal stage, which filters each frame alone).
pub struct SequenceFilter<'g> {
    gpu: &'g Gpu,
    choice: Choice,
    kernel: jit::ValidatedKernel,
    state: TemporalState,
}

impl<'g> SequenceFilter<'g> {
    /// Compile `choice`'s kernel; the first frame starts the sequence.
    pub fn new(gpu: &'g Gpu, choice: Choice) -> Result<Self> {
        let kernel = choice.compile()?;
        Ok(SequenceFilter { gpu, choice, kernel, state: TemporalState::new() })
    }

    /// The next frame, filtered, in one submission; its history is kept for the frame after.
    pub fn frame(&mut self, scene: &Scene) -> Result<FilteredFrame> {
        filter_frame(self.gpu, &self.choice, &self.kernel, scene, &mut self.state)
    }

    /// Forget the history: the next frame starts a sequence (a cut).
    pub fn reset(&mut self) {
        self.state.reset();
    }

    /// Frames blended since the sequence started (or was reset).
    pub fn frames(&self) -> u32 {
        self.state.frames()
    }

    pub fn choice(&self) -> &Choice {
        &self.choice
    }

    pub fn kernel(&self) -> &jit::ValidatedKernel {
        &self.kernel
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn provided(features: &[Feature], variances: &[ScalarVar]) -> Provided {
        Provided::new(features.iter().copied().collect(), variances.iter().copied().collect())
    }

    #[test]
    fn every_listed_filter_is_shipped_and_the_last_reads_colour_alone() {
        for name in SHIPPED_BY_QUALITY {
            assert!(corpus::lookup(name).is_some(), "@{name} is shipped");
        }
        // Any render has what the last reads; one of colour alone gets the better of the two that read no more.
        let last = Choice::asked(&format!("@{}", SHIPPED_BY_QUALITY.last().unwrap()), None, None).unwrap();
        assert!(last.missing(&provided(&[], &[])).is_empty());
        let colour = Choice::best_for(&provided(&[], &[])).unwrap();
        assert_eq!(colour.name.as_deref(), Some("evolvedAtrous64ColorOnly"));
        assert!(!colour.pipeline.demodulate, "no albedo to divide by: {}", colour.pipeline);
    }

    #[test]
    fn the_best_filter_is_taken_when_the_render_has_its_inputs() {
        use Feature::*;
        let all = provided(&[Texture, Normal, WorldPosition, Depth], &[ScalarVar::ColorVariance]);
        let best = Choice::best_for(&all).unwrap();
        assert_eq!(best.name.as_deref(), Some(SHIPPED_BY_QUALITY[0]));
        assert!(best.missing(&all).is_empty());
        assert_eq!(best.pipeline.to_string(), "outliers=2.5,trim,keep=surface,demodulate,atrous=3,planefit=3");

        // It reads no variance: a render without one (Cycles, Mitsuba's plain `aov`) gets it too.
        let no_variance = provided(&[Texture, Normal, WorldPosition, Depth], &[]);
        let chosen = Choice::best_for(&no_variance).unwrap();
        assert!(!chosen.expr.stored_variables().contains(&ScalarVar::ColorVariance));
        assert_eq!(chosen.name.as_deref(), Some("evolvedAtrous64Plane"));
        assert!(chosen.pipeline.outliers.is_some_and(|o| o.keep.is_some()), "keeps the light: {}", chosen.pipeline);

        // Without depth the default still applies: it reads none.
        let no_depth = provided(&[Texture, Normal, WorldPosition], &[ScalarVar::ColorVariance]);
        assert_eq!(Choice::best_for(&no_depth).unwrap().name.as_deref(), Some("evolvedAtrous64Plane"));

        // Without a position, the default's weight with the depth in its place; the message says what was passed over.
        let no_position = provided(&[Texture, Normal, Depth], &[ScalarVar::ColorVariance]);
        let chosen = Choice::best_for(&no_position).unwrap();
        assert_eq!(chosen.name.as_deref(), Some("evolvedAtrous64PlaneDepth"));
        assert!(!chosen.expr.features().contains(&WorldPosition), "{:?}", chosen.name);
        let because = chosen.chosen_because.unwrap();
        assert_eq!(because.passed_over, [("evolvedAtrous64Plane".to_string(), vec![Missing::Feature(WorldPosition)])]);
        assert!(because.to_string().contains("@evolvedAtrous64Plane, the best, needs worldPosition"), "{because}");
        // Without the depth too (OIDN's inputs), the one with neither; the filters passed over
        // are summed up in one clause, each input named once.
        let oidn_inputs = provided(&[Texture, Normal], &[]);
        let chosen = Choice::best_for(&oidn_inputs).unwrap();
        assert_eq!(chosen.name.as_deref(), Some("evolvedAtrous64PlaneNoPosition"));
        assert_eq!(chosen.pipeline.to_string(), "outliers=2.5,trim,keep=surface,demodulate,atrous=3,planefit=3");
        let because = chosen.chosen_because.unwrap().to_string();
        assert!(because.contains("the 2 better ones read what it lacks (worldPosition, depth;"), "{because}");

        // A sequence's frames with motion but no position (a real-time G-buffer): @temporal with the depth.
        let frames = |features: &[Feature]| Provided { motion: true, sequence: true, ..provided(features, &[]) };
        let g_buffer = Choice::best_temporal_for(&frames(&[Texture, Normal, Depth])).unwrap();
        assert_eq!(g_buffer.name.as_deref(), Some("temporalDepth"));
        assert!(g_buffer.pipeline.is_temporal() && g_buffer.missing(&frames(&[Texture, Normal, Depth])).is_empty());
        let full = Choice::best_temporal_for(&frames(&[Texture, Normal, Depth, WorldPosition])).unwrap();
        assert_eq!(full.name.as_deref(), Some(SHIPPED_TEMPORAL_BY_QUALITY[0]));
        // Without motion vectors, the best filter of single renders, frame by frame, and why.
        let still = Provided { motion: false, ..frames(&[Texture, Normal, Depth, WorldPosition]) };
        let frame_by_frame = Choice::best_temporal_for(&still).unwrap();
        assert_eq!(frame_by_frame.name.as_deref(), Some(SHIPPED_BY_QUALITY[0]));
        let because = frame_by_frame.chosen_because.unwrap();
        assert_eq!(because.no_temporal.len(), SHIPPED_TEMPORAL_BY_QUALITY.len());
        assert!(because.no_temporal.iter().all(|(_, lacks)| lacks.contains(&Missing::Motion)), "{because:?}");
        let said = because.to_string();
        assert!(
            said.contains(
                "frame by frame (no shipped temporal filter fits: @temporal, @temporalDepth, @svgf need motion vectors"
            ),
            "{said}"
        );

        // `keep=surface` reads the normal even where the weight does not:
        // its needs say so, and so does what it asks a render for.
        let weight = crate::lang::parse_expr("exp(-distance2(color))").unwrap();
        let surface = Choice { expr: weight.clone(), ..Choice::asked("@evolvedAtrous64Surface", None, None).unwrap() };
        let even = Choice { expr: weight, ..Choice::asked("@evolvedAtrous64Trim", None, None).unwrap() };
        assert!(surface.request().features.contains(&Normal) && !even.request().features.contains(&Normal));
        let no_normal = provided(&[Texture, WorldPosition, Depth], &[]);
        assert_eq!(surface.missing(&no_normal), [Missing::Feature(Normal)]);
        assert!(even.missing(&no_normal).is_empty());

        // Demodulation needs the albedo even where the weight does not read it.
        let no_albedo = provided(&[Normal, WorldPosition, Depth], &[ScalarVar::ColorVariance]);
        let chosen = Choice::best_for(&no_albedo).unwrap();
        assert!(!chosen.pipeline.demodulate, "{}", chosen.pipeline);
    }

    #[test]
    fn a_filter_asked_for_overrides_the_choice_and_keeps_its_pipeline() {
        let choice = Choice::asked_or_best(Some("@svgfAtrous"), None, None, &Provided::default()).unwrap();
        assert_eq!(choice.name.as_deref(), Some("svgfAtrous"));
        assert_eq!(choice.pipeline.to_string(), "outliers=2,demodulate,atrous=5");
        assert!(choice.chosen_because.is_none());
        let err = Choice::asked("@noSuchFilter", None, None).unwrap_err().to_string();
        assert!(err.contains("no shipped expression `@noSuchFilter`"), "{err}");
    }

    #[test]
    fn where_the_median_pixel_is_black_the_chosen_filter_gives_way_to_its_sparse_light_variant() {
        use Feature::*;
        let all = provided(&[Texture, Normal, WorldPosition, Depth], &[]);
        // 100 pixels, 90 black: the median is black.
        let mut sparse = vec![[0.0f32; 3]; 100];
        for (k, pixel) in sparse.iter_mut().enumerate().take(10) {
            *pixel = [k as f32 + 1.0; 3];
        }
        let even = vec![[0.5f32; 3]; 100];
        let chosen = Choice::best_for(&all).unwrap();
        let SparseLightVariant { base, variant, .. } = SPARSE_LIGHT_VARIANTS[0];
        assert_eq!(chosen.name.as_deref(), Some(base));

        let swapped = chosen.clone().for_light(&sparse, false).unwrap();
        assert_eq!(swapped.name.as_deref(), Some(variant));
        assert_eq!(swapped.pipeline, Choice::asked(&format!("@{variant}"), None, None).unwrap().pipeline);
        assert_ne!(swapped.pipeline, chosen.pipeline, "the sparse variant reaches one pass farther");
        let because = swapped.chosen_because.as_ref().unwrap().to_string();
        assert!(because.contains("sparse light") && because.contains("0.000 of its mean"), "{because}");
        let kept = chosen.clone().for_light(&even, false).unwrap();
        assert_eq!(kept.name.as_deref(), Some(base), "an even light keeps the filter");

        // One asked for by name stays, sparse or not.
        let asked = Choice::asked(&format!("@{base}"), None, None).unwrap();
        assert_eq!(asked.for_light(&sparse, false).unwrap().name.as_deref(), Some(base));
        // A role asked for by name follows the light, unless given a pipeline.
        let role = FOLLOWS_THE_LIGHT_WHEN_ASKED[0];
        let sparse_role = sparse_light_variant(role).unwrap().variant;
        let asked = Choice::asked(&format!("@{role}"), None, None).unwrap();
        let swapped = asked.clone().for_light(&sparse, false).unwrap();
        assert_eq!(swapped.name.as_deref(), Some(sparse_role));
        assert_eq!(swapped.pipeline, Choice::asked(&format!("@{sparse_role}"), None, None).unwrap().pipeline);
        let because = swapped.chosen_because.as_ref().unwrap().to_string();
        assert!(because.contains("sparse light") && because.contains("a pipeline given keeps"), "{because}");
        assert_eq!(asked.clone().for_light(&even, false).unwrap().name.as_deref(), Some(role));
        let pinned = Choice::asked(&format!("@{role}"), Some(asked.pipeline), None).unwrap();
        assert_eq!(pinned.for_light(&sparse, true).unwrap().name.as_deref(), Some(role), "{}", asked.pipeline);
        // Where the median pixel is a tenth of the mean, the role's light is
        // sparse and the default's is not: each variant has its own threshold.
        let mut dim = vec![[0.1f32; 3]; 60];
        dim.extend([[2.35f32; 3]; 40]);
        assert_eq!(chosen.clone().for_light(&dim, false).unwrap().name.as_deref(), Some(base));
        assert_eq!(asked.clone().for_light(&dim, false).unwrap().name.as_deref(), Some(sparse_role));
        // A user's own expression under the role's name is not the role.
        let own = Choice { expr: crate::lang::parse_expr("exp(-distance2(color))").unwrap(), ..asked.clone() };
        assert_eq!(own.for_light(&sparse, false).unwrap().name.as_deref(), Some(role));
        // A pipeline the user gave stays with the variant.
        let given: FilterPipeline = "outliers=2,keep,demodulate,atrous=5".parse().unwrap();
        let chosen = Choice::asked_or_best(None, Some(given), None, &all).unwrap();
        assert_eq!(chosen.for_light(&sparse, true).unwrap().pipeline, given);
    }

    #[test]
    fn a_render_of_many_samples_gets_two_passes_from_the_chosen_filter_never_one() {
        use Feature::*;
        let all = provided(&[Texture, Normal, WorldPosition, Depth], &[]);
        let chosen = Choice::best_for(&all).unwrap();
        let three = Form::Atrous { passes: 3, stencil: Stencil::Cubic5 };
        assert_eq!(chosen.pipeline.form, three, "the default runs three 5x5 passes");
        let measured = FEWER_PASSES_MEASURED_AT as usize;
        let size = (measured, measured);
        let many = chosen.clone().for_samples(Some(FEWER_PASSES_FROM_SPP), size, false);
        assert_eq!(many.pipeline.form, Form::Atrous { passes: 2, stencil: Stencil::Cubic5 });
        assert_eq!(FilterPipeline { form: three, ..many.pipeline }, chosen.pipeline, "only the count changes");
        let because = many.chosen_because.as_ref().unwrap().to_string();
        let samples = format!("{FEWER_PASSES_FROM_SPP} samples");
        assert!(because.contains("two à-trous passes, not three") && because.contains(&samples), "{because}");
        // Never one pass, however many samples (the test scenes lost by it).
        let most = chosen.clone().for_samples(Some(u32::MAX), size, false);
        assert_eq!(most.pipeline.form, Form::Atrous { passes: FEWER_PASSES, stencil: Stencil::Cubic5 });
        assert_eq!(FEWER_PASSES, 2);
        for (spp, pipeline_given) in [(Some(FEWER_PASSES_FROM_SPP - 1), false), (None, false), (Some(64), true)] {
            assert_eq!(chosen.clone().for_samples(spp, size, pipeline_given).pipeline, chosen.pipeline, "{spp:?}");
        }
        // A render twice as wide needs twice the samples; a smaller one keeps the counts measured.
        let wide = (2 * measured, 2 * measured);
        let twice = chosen.clone().for_samples(Some(2 * FEWER_PASSES_FROM_SPP - 1), wide, false);
        assert_eq!(twice.pipeline, chosen.pipeline, "too few samples at twice the width");
        let twice = chosen.clone().for_samples(Some(2 * FEWER_PASSES_FROM_SPP), wide, false);
        assert_eq!(twice.pipeline.form, Form::Atrous { passes: 2, stencil: Stencil::Cubic5 });
        let because = twice.chosen_because.as_ref().unwrap().to_string();
        assert!(because.contains(&format!("from {} on at its", 2 * FEWER_PASSES_FROM_SPP)), "{because}");
        let small = chosen.clone().for_samples(Some(FEWER_PASSES_FROM_SPP), (measured / 4, measured / 2), false);
        assert_eq!(small.pipeline.form, Form::Atrous { passes: 2, stencil: Stencil::Cubic5 });
        let tall = fewer_passes(FEWER_PASSES_FROM_SPP * 3, (measured, 4 * measured)).unwrap();
        assert_eq!((tall.from, tall.passes), (2 * FEWER_PASSES_FROM_SPP, 2), "the side is the root of the pixels");
        // A filter asked for stays as asked.
        let asked = Choice::asked(&format!("@{}", SHIPPED_BY_QUALITY[0]), None, None).unwrap();
        assert_eq!(asked.clone().for_samples(Some(64), size, false).pipeline, asked.pipeline);
        // A sparse-light variant keeps its reach.
        let mut sparse = vec![[0.0f32; 3]; 100];
        sparse[0] = [100.0; 3];
        let variant = chosen.for_light(&sparse, false).unwrap();
        assert_eq!(variant.clone().for_samples(Some(64), size, false).pipeline, variant.pipeline);
    }

    #[test]
    fn a_sparse_light_variant_reads_what_its_filter_reads() {
        for SparseLightVariant { base, variant, .. } in SPARSE_LIGHT_VARIANTS {
            let (a, b) = (
                Choice::asked(&format!("@{base}"), None, None).unwrap(),
                Choice::asked(&format!("@{variant}"), None, None).unwrap(),
            );
            let inputs = |c: &Choice| {
                let r = c.request();
                (r.features, r.variances, r.albedo)
            };
            assert_eq!(inputs(&a), inputs(&b), "@{variant}: the render loaded for @{base} must serve it");
            // Only a filter something chooses, or a role asked for, ever gives way to it.
            assert!(SHIPPED_BY_QUALITY.contains(base) || FOLLOWS_THE_LIGHT_WHEN_ASKED.contains(base), "@{base}");
        }
    }
}
