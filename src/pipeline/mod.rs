//! The filter pipeline around an evolved weight:
//! `outliers → demodulate → temporal → form → remodulate` (docs/SEMANTICS.md, "The pipeline").
//!
//! The thesis filters once over a (2r+1)² window. On real renders three
//! things around the weight matter as much as the weight: fireflies are
//! smeared into blotches unless they are tamed first, texture blurs unless the
//! albedo is divided out before filtering and multiplied back after, and a
//! small window leaves low-frequency noise that an à-trous cascade (Dammertz
//! et al. 2010; SVGF 2017) removes cheaply. [`FilterPipeline`] says which of
//! these a filter uses; it is written as text (`outliers=2,demodulate,atrous=5`)
//! in run settings and halls of fame, so that a stored filter is reproduced
//! exactly as it was scored. This module owns the stages' constants; the CPU
//! reference (`cpu::filter_pipeline`) and the kernels (`jit`) read them here.

mod text;

pub use text::PipelineError;

/// Luminance weights (Rec. 709) of the outlier rule.
pub const LUMINANCE: [f64; 3] = [0.2126, 0.7152, 0.0722];

/// The outlier rule compares a pixel with its (2R+1)² neighbourhood, itself excluded.
pub const OUTLIER_RADIUS: u32 = 2;

/// The outlier rule's neighbourhood: the offsets (dx, dy) of the (2R+1)²
/// square without its centre, row by row, the order both the CPU reference
/// and the pre-pass kernel sum in.
pub fn outlier_neighbours() -> impl Iterator<Item = [i32; 2]> {
    let r = OUTLIER_RADIUS as i32;
    (-r..=r).flat_map(move |dy| (-r..=r).map(move |dx| [dx, dy])).filter(|&d| d != [0, 0])
}

/// Demodulation divides by the albedo clipped to [0, 1] and raised to at
/// least this, per channel: continuous, so that emitters and escaped rays
/// (albedo 0) neither blow up nor lose their colour, and albedo above 1
/// (Mitsuba's rough metals reach hundreds) does not darken.
pub const ALBEDO_FLOOR: f64 = 0.1;

/// The taps of one à-trous pass: h(dx)·h(dy) for dx, dy in -half..=half
/// steps multiplies the evolved weight.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub enum Stencil {
    /// 5×5 taps, the cubic B-spline h = (3/8, 1/4, 1/16) of Dammertz et al.
    /// and SVGF (`atrous=K`).
    #[default]
    Cubic5,
    /// 3×3 taps, the linear B-spline h = (1/2, 1/4) (`atrous3x3=K`): 9 taps
    /// a pass instead of 25, for a cascade that must cost less than one
    /// pass of a learned denoiser on a CPU; K+1 passes reach as far as K of
    /// the 5×5 stencil, less one step.
    Linear3,
}

impl Stencil {
    /// h(0), h(±1)[, h(±2)]: the 1-D weights, which sum to 1 over -half..=half.
    pub fn weights(self) -> &'static [f64] {
        match self {
            Stencil::Cubic5 => &[3.0 / 8.0, 1.0 / 4.0, 1.0 / 16.0],
            Stencil::Linear3 => &[1.0 / 2.0, 1.0 / 4.0],
        }
    }

    /// Half-width in steps: taps from -half to half each way.
    pub fn half_width(self) -> i32 {
        self.weights().len() as i32 - 1
    }

    /// The weight h(|d|) of offset d in -half..=half.
    pub fn weight(self, d: i32) -> f64 {
        self.weights()[d.unsigned_abs() as usize]
    }

    /// The form's name in a pipeline's text (`atrous=K`, `atrous3x3=K`).
    fn stage_name(self) -> &'static str {
        match self {
            Stencil::Cubic5 => "atrous",
            Stencil::Linear3 => "atrous3x3",
        }
    }
}

/// The stencil the first pass's `guide` is blurred with (docs/SEMANTICS.md,
/// "The guide"): one pass of the 3×3 linear B-spline, so that a rare bright
/// sample counts for a quarter of itself where the weight compares colours,
/// while an edge moves by at most one pixel.
pub const GUIDE_STENCIL: Stencil = Stencil::Linear3;

/// The largest number of à-trous passes (step 2^(passes-1) ≤ 2^15 pixels).
pub const MAX_ATROUS_PASSES: u32 = 16;

/// How the evolved weight is applied.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Form {
    /// One pass over the (2r+1)² window (the thesis's filter); r is the run's radius.
    Window,
    /// `passes` passes of a `stencil` (5×5 or 3×3 taps) with step 2^k in pass
    /// k, each filtering the previous pass's output with the same kernel.
    Atrous { passes: u32, stencil: Stencil },
}

/// What the outlier pre-pass does to each pixel (before demodulation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Outliers {
    /// A pixel whose luminance exceeds its neighbours' mean + k·std is scaled down to it.
    pub k: f32,
    /// Whether the rule's mean and deviation leave out the brightest neighbour
    /// (`trim`): two bright samples side by side otherwise raise each other's
    /// limit and both pass (docs/JOURNAL.md, "A trimmed outlier rule").
    pub trim: bool,
    /// Whether and how what the clamp removed is put back, spread over the
    /// neighbourhood (`keep`, `keep=surface`): a clamp alone darkens renders
    /// whose light arrives in rare bright samples (docs/JOURNAL.md, "Where
    /// the light goes").
    pub keep: Option<Keep>,
}

/// How `keep` hands back what the outlier clamp removed. Both keep the
/// image's total exactly: every source hands out all it has.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Keep {
    /// `keep`: evenly, by [`KEEP_PASSES`] passes of the 3×3 B-spline (±31 pixels).
    Even,
    /// `keep=surface`: by [`SURFACE_KEEP_PASSES`] passes (±127 pixels) in
    /// which each source's shares also follow the surface (the normals'
    /// agreement, [`SURFACE_KEEP_NORMAL_SIGMA`]) and the light already there
    /// (the clamped luminance plus [`SURFACE_KEEP_LIGHT_FLOOR`] times the
    /// image's mean): a rare bright sample's light goes back where light of
    /// its kind lands, not as a blotch on whatever is beside it
    /// (docs/JOURNAL.md, "Handing the light back along the surface").
    Surface,
}

impl Keep {
    /// The stage as a pipeline's text spells it.
    pub fn text(self) -> &'static str {
        match self {
            Keep::Even => "keep",
            Keep::Surface => "keep=surface",
        }
    }

    /// The passes of its spread; pass k has step 2^k.
    pub fn passes(self) -> u32 {
        match self {
            Keep::Even => KEEP_PASSES,
            Keep::Surface => SURFACE_KEEP_PASSES,
        }
    }

    /// How far its spread reaches, in pixels.
    pub fn reach(self) -> u32 {
        (0..self.passes()).map(|level| FilterPipeline::step(level) * KEEP_STENCIL.half_width() as u32).sum()
    }
}

/// `keep=surface`'s passes: out to ±127 pixels. Chosen with the next two
/// constants on the seventeen built-in scenes only (docs/JOURNAL.md,
/// "Handing the light back along the surface"): 6 passes gained less, 8 no more.
pub const SURFACE_KEEP_PASSES: u32 = 7;

/// σ of `keep=surface`'s normal term exp(−max(0, 1 − n_i·n_j) / σ).
pub const SURFACE_KEEP_NORMAL_SIGMA: f64 = 0.2;

/// F of `keep=surface`'s light term: a target's share is in proportion to
/// its clamped luminance plus F times the clamped image's mean luminance, so
/// that dark surfaces still take their part (F → ∞ ignores the light).
pub const SURFACE_KEEP_LIGHT_FLOOR: f64 = 3.0;

/// `keep=surface`'s normal term between two pixels' normals: of their
/// directions, so that a normal stored at any length (a renderer's unit
/// normals, filterjit's normalised feature, an engine's scaled texture) gives
/// the same shares; a zero normal has no direction and agrees with none.
pub fn surface_normal_term(a: [f64; 3], b: [f64; 3]) -> f64 {
    let (a, b) = (direction(a), direction(b));
    let dot = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    (-(1.0 - dot).max(0.0) / SURFACE_KEEP_NORMAL_SIGMA).exp()
}

/// `keep=surface`'s light term of a target whose clamped luminance is `l`,
/// where `floor` is [`SURFACE_KEEP_LIGHT_FLOOR`] times the clamped image's
/// mean luminance: l + floor, or 1 everywhere when nothing survived the clamp
/// (floor 0), so that the shares are still defined and even.
pub fn surface_light_term(l: f64, floor: f64) -> f64 {
    if floor > 0.0 {
        l + floor
    } else {
        1.0
    }
}

/// `keep` spreads what the clamp removed by this many passes of the 3×3
/// linear B-spline with steps 1, 2, 4, …: out to ±(2^passes − 1) pixels,
/// wide enough that a rare bright sample's light lands on the surface around it
/// rather than in a blotch (measured: 2 passes leave blotches, 4–6 agree).
pub const KEEP_PASSES: u32 = 5;

/// The stencil both `keep`s spread with.
pub const KEEP_STENCIL: Stencil = Stencil::Linear3;

/// The share of a source pixel's value that its tap at offset `d` (steps)
/// receives in one spread pass along one axis, for a source at `x` of `n`
/// pixels: h(d) over the sum of h over the taps that land inside the image, so
/// that every source hands out all it has (the spread keeps the total exactly).
pub fn spread_share(x: i64, d: i64, step: i64, n: i64) -> f64 {
    let half = KEEP_STENCIL.half_width() as i64;
    let inside: f64 =
        (-half..=half).filter(|e| (0..n).contains(&(x + e * step))).map(|e| KEEP_STENCIL.weight(e as i32)).sum();
    KEEP_STENCIL.weight(d as i32) / inside
}

/// The temporal stage (`temporal=A`, docs/SEMANTICS.md, "The temporal
/// stage"): ahead of the form, each frame's colour (as the pre-pass left it)
/// is blended into a history reprojected from the frame before by the motion
/// vectors, where the surface is the same one (depth and normal agree), with
/// the luminance's first two moments beside it (SVGF, Schied et al. 2017).
/// The form filters the blend and may read the history's length and the
/// variance of its luminance (`historyLength`, `temporalVariance`); the
/// image after `feedback` passes of the form is the next frame's history.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Temporal {
    /// α_min: a frame's share of the blend is max(α_min, 1/n) after n frames
    /// of history, so that the first frames are averaged evenly and later
    /// ones forget at rate α_min.
    pub alpha: f32,
    /// The passes of the form whose output becomes the history (0: the blend
    /// itself; SVGF feeds back its first pass's).
    pub feedback: u32,
    /// γ of the history's clamp, if any: each channel of the reprojected
    /// history is clamped to the current frame's 3×3 mean ± γ standard
    /// deviations, and its modulation to the range of the frame's 3×3
    /// modulations, so that a history the frame disagrees with (a moving
    /// shadow, a reflection) fades instead of ghosting.
    pub clamp: Option<f32>,
    /// κ of the history's test, if any (`antilag=K`): where the history's
    /// luminance lies more than κ standard errors from the mean of the
    /// frame's 3×3 (plus [`TEMPORAL_ANTILAG_SLACK`] of it), the light there
    /// changed (a light moved, a shadow swept in) and the history is cut to
    /// one frame, so that the blend follows within a few frames; beyond
    /// [`TEMPORAL_ANTILAG_DROP`] times that bound it is dropped.
    pub antilag: Option<f32>,
}

impl Temporal {
    /// A frame's share of the blend after `n` frames of history (n ≥ 1; 1: no history).
    pub fn share(self, n: f64) -> f64 {
        (self.alpha as f64).max(1.0 / n)
    }
}

/// The relative change of luminance the history's test (`antilag=K`) always
/// allows, beside κ standard errors: where the frame's neighbourhood is
/// flat, noise-free light that changed by less is no change.
pub const TEMPORAL_ANTILAG_SLACK: f64 = 0.02;

/// How many times farther than the history's test allows the history must
/// lie from the frame's 3×3 to be dropped, not cut to one frame: a light
/// switched on or moved, a cut that kept the surfaces. Cut to one frame, the
/// old light took ½, ⅓, ¼ of the next frames (docs/JOURNAL.md, "A history
/// far off the frame is dropped").
pub const TEMPORAL_ANTILAG_DROP: f64 = 3.0;

/// The largest relative depth difference |z' − z| / z at which a history
/// sample is taken to see the same surface as the pixel.
pub const TEMPORAL_DEPTH_TOLERANCE: f64 = 0.1;

/// The smallest cosine between the normals' directions at which a history
/// sample is taken to see the same surface (about 26°).
pub const TEMPORAL_NORMAL_COSINE: f64 = 0.9;

/// A bilinear footprint whose consistent taps hold less than this share of
/// its weight is not taken: the wider search looks instead.
pub const TEMPORAL_MIN_FOOTPRINT: f64 = 1e-3;

/// The history's length is counted up to this many frames.
pub const TEMPORAL_MAX_HISTORY: f64 = 255.0;

/// Below this history length the variance comes from the frame's own
/// neighbourhood (SVGF's spatial estimate) instead of the moments: from
/// four frames on. A pixel's length is the mean of its bilinear taps' whole
/// lengths, which f32 rounds to either side of a whole number (taps of 3
/// frames mix to 2.9999998 on the device, 3 in f64), so the threshold is a
/// 64th below 4, which no such rounding reaches: the device and the CPU
/// take the same branch (docs/JOURNAL.md, "Stale vectors").
pub const TEMPORAL_SHORT_HISTORY: f64 = 3.984375;

/// The spatial variance estimate's neighbourhood: (2R+1)² pixels. SVGF's
/// 7×7 (R = 3) and a 5×5 gave the same errors on the two Cycles and five
/// built-in sequences as this 3×3, at a third and a sixth more of the
/// stage's time: a history test cuts a few per cent of the pixels every
/// frame, and a SIMD group with one of them pays for the window on every
/// lane (docs/JOURNAL.md, "A 5×5 window for a short history", "A 3×3 window
/// for a short history").
pub const TEMPORAL_VARIANCE_RADIUS: i32 = 1;

/// The largest α_min: a history that forgets faster than this is no history.
pub const TEMPORAL_MAX_ALPHA: f32 = 1.0;

/// Below this albedo in every channel a surface counts as black: an
/// emitter's (or a void's). A history sample and a pixel see the same
/// surface only where both are black or neither is: an emitter sliding over
/// a wall it lies flat on leaves light whose demodulated value is ten times
/// its own behind, though depth and normal agree. Other albedos mix, so
/// that a texture's edges are averaged over the pixel's samples of many
/// frames, as the reference averages them, except where an emitter's edge
/// gives itself away ([`TEMPORAL_ALIKE_ALBEDO`]).
pub const TEMPORAL_BLACK_ALBEDO: f64 = 0.05;

/// Two albedos are alike when the smaller of their luminances is at least
/// this share of the larger ([`alike_albedo`]). A pixel partly covered by an
/// emitter has a darker albedo than the surface around it (the emitter's
/// samples are black) and, demodulated, the emitter's light divided by the
/// surface's albedo: tens of times the surface's own. Only neighbours of
/// alike albedo lend a pixel their history (the wider search) or count in
/// its spatial variance; on the built-in moving light their light leaked
/// into the ceiling the emitter had left (docs/JOURNAL.md, "Emitters' edges
/// in the history").
pub const TEMPORAL_ALIKE_ALBEDO: f64 = 0.8;

/// A bilinear history tap whose albedo is not alike the pixel's is still
/// taken where the history's luminance there is at most this many times the
/// pixel's own, plus [`TEMPORAL_UNLIKE_SLACK`]: a texture's edge (whose
/// demodulated light is the surface's on both sides) keeps its history, an
/// emitter's edge (whose demodulated light is the emitter's) does not.
pub const TEMPORAL_UNLIKE_LIGHT: f64 = 8.0;

/// See [`TEMPORAL_UNLIKE_LIGHT`]: what a dark pixel's bound starts from.
pub const TEMPORAL_UNLIKE_SLACK: f64 = 0.01;

/// Whether albedos `a` and `b` are alike: the smaller luminance at least
/// [`TEMPORAL_ALIKE_ALBEDO`] of the larger (two black ones are alike).
pub fn alike_albedo(a: [f64; 3], b: [f64; 3]) -> bool {
    let (la, lb) = (luminance(a), luminance(b));
    la.min(lb) >= TEMPORAL_ALIKE_ALBEDO * la.max(lb)
}

/// A pixel's surface as the history's test compares it: the normal's
/// direction (unit, or zero: no surface, the sky), the depth and the albedo
/// clipped to [0, 1].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Surface {
    pub normal: [f64; 3],
    pub depth: f64,
    pub albedo: [f64; 3],
}

/// Whether a history sample on surface `s` sees the surface `at` of a
/// pixel: depths within [`TEMPORAL_DEPTH_TOLERANCE`] of the pixel's,
/// normals' directions within [`TEMPORAL_NORMAL_COSINE`] (a zero normal
/// only matches another), and both black or neither ([`TEMPORAL_BLACK_ALBEDO`]).
pub fn same_surface(s: Surface, at: Surface) -> bool {
    let has = |v: [f64; 3]| v.iter().any(|c| *c != 0.0);
    let (n, at_n) = (s.normal, at.normal);
    let normals = match (has(n), has(at_n)) {
        (true, true) => n[0] * at_n[0] + n[1] * at_n[1] + n[2] * at_n[2] >= TEMPORAL_NORMAL_COSINE,
        (false, false) => true,
        _ => false,
    };
    let black = |a: [f64; 3]| a.iter().all(|c| *c < TEMPORAL_BLACK_ALBEDO);
    let albedo = black(s.albedo) == black(at.albedo);
    normals && albedo && (s.depth - at.depth).abs() <= TEMPORAL_DEPTH_TOLERANCE * at.depth
}

/// A normal's direction: the unit vector, or zero for a zero normal. In f64,
/// for the stages that compare surfaces (the temporal stage's test, the
/// spread along the surface, planefit), each of which normalises in its own
/// kernel; a weight's `normal` feature is made unit on loading instead, in
/// f32 with a slack ([`crate::semantics::unit_direction`]), so that the
/// exported shaders can apply the same rule to what an engine binds and
/// leave a loaded normal's bits as they are.
pub fn direction(v: [f64; 3]) -> [f64; 3] {
    let length2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
    if length2 > 0.0 {
        v.map(|c| c / length2.sqrt())
    } else {
        [0.0; 3]
    }
}

/// `planefit=R`'s largest radius.
pub const MAX_PLANEFIT_RADIUS: u32 = 8;

/// σ of `planefit`'s luminance term exp(−ln²((Y_j + F) / (Y_i + F)) / 2σ²):
/// a neighbour twice as bright counts 0.38, ten times 0.
pub const PLANEFIT_LUMINANCE_SIGMA: f64 = 0.5;

/// F of `planefit`'s luminance term, in the demodulated colour's units: it
/// keeps the ratio finite where a pixel is black.
pub const PLANEFIT_LUMINANCE_FLOOR: f64 = 1e-3;

/// λ added to the fit's slope moments (ridge): where the taps that count sit
/// on one line, the slopes stay finite and the fit tends to the weighted mean.
pub const PLANEFIT_RIDGE: f64 = 1e-3;

/// τ of `planefit`'s trust in the plane, 1 / (1 + (s / τ)²), where s is the
/// fitted luminance's change over the radius relative to its value: a
/// steep plane is more often a curve (a contact shadow, a corner's falloff)
/// that a plane would flatten, and there the pixel keeps the form's value.
pub const PLANEFIT_SLOPE_TAU: f64 = 0.2;

/// The largest relative slope s counted (the trust is then about 4·10⁻¹⁴):
/// keeps s² finite in f32.
pub const PLANEFIT_SLOPE_CAP: f64 = 1e6;

/// Below this a length or level counts as zero.
pub const PLANEFIT_TINY: f64 = 1e-30;

/// `planefit=R`: after the form, each pixel's demodulated colour is replaced
/// by the value at the pixel of a plane a + b·u + c·v (u, v: screen offsets
/// over R) fitted by weighted least squares over its (2R+1)² neighbourhood
/// (docs/SEMANTICS.md, "The pipeline"). An average over a surface leaves
/// blotches where the form's last pass left them, and flattens gradients where
/// it reaches farther; a plane removes the blotches and keeps the gradient
/// (docs/JOURNAL.md, "A plane fitted after the form").
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct PlaneFit {
    pub radius: u32,
}

impl PlaneFit {
    /// The weight of neighbour j of pixel i, offset (dx, dy): a Gaussian of σ
    /// R over the offset, the normals' agreement (`keep=surface`'s term) and
    /// the luminances' ratio.
    pub fn weight(self, dx: i32, dy: i32, normals: ([f64; 3], [f64; 3]), luminances: (f64, f64)) -> f64 {
        let r = self.radius as f64;
        let spatial = (-((dx * dx + dy * dy) as f64) / (2.0 * r * r)).exp();
        let (yi, yj) = luminances;
        let ratio = ((yj.max(0.0) + PLANEFIT_LUMINANCE_FLOOR) / (yi.max(0.0) + PLANEFIT_LUMINANCE_FLOOR)).ln();
        let light = (-ratio * ratio / (2.0 * PLANEFIT_LUMINANCE_SIGMA * PLANEFIT_LUMINANCE_SIGMA)).exp();
        spatial * surface_normal_term(normals.0, normals.1) * light
    }
}

/// `anchor=K`'s blur: the frame's 2×2 blocks averaged into a grid of half
/// the resolution each way (all of the anchor's sums are low-frequency:
/// a quarter of the pixels to blur), then the cubic B-spline stencil
/// ([`Stencil::Cubic5`]) on that grid at steps 1 and 2, one level each, and
/// the result interpolated bilinearly back to every pixel: a kernel about
/// as wide as a Gaussian of σ 4.5 pixels, the scale at which one sample a
/// pixel still tells a change of light from noise (docs/JOURNAL.md, "The
/// moving light's error is lag at low frequency").
pub const ANCHOR_LEVELS: u32 = 2;

/// Added to the anchor's standard error, so that a flat black region has one.
pub const ANCHOR_ERROR_FLOOR: f64 = 1e-4;

/// The least blurred output luminance the anchor divides by.
pub const ANCHOR_LIGHT_FLOOR: f64 = 1e-6;

/// `anchor=K`'s largest gate, in standard errors.
pub const MAX_ANCHOR_GATE: f32 = 100.0;

/// `anchor=K`, after the form and `planefit`: the filtered image's light
/// pulled toward the frame's own at a coarse scale, where the two differ by
/// more than the frame's noise explains. With G the blur of
/// [`ANCHOR_LEVELS`] levels, l the luminance of the noisy frame and o of the
/// filtered image (each clamped at 0 per channel):
///
///   e = sqrt(max(G l² − (G l)², 0) / N) + floor   (the standard error of G l; N = [`Anchor::samples`])
///   t = clamp((|G l − G o| / e − K) / K, 0, 1)
///   out = P · (1 + t · (G l / max(G o, floor) − 1))
///
/// A history that lags a moving light, or passes that lose light where it
/// is sparse, are pulled back; where the difference is within K standard
/// errors, nothing changes (docs/SEMANTICS.md, "The pipeline").
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Anchor {
    /// K: how many standard errors the blurred lights must differ by before the pull starts.
    pub gate: f32,
}

impl Anchor {
    /// The gate shipped pipelines use.
    pub const SHIPPED: Anchor = Anchor { gate: 2.0 };

    /// The stencil of every blur level (the kernel's loop is written for its 5×5 taps).
    pub const STENCIL: Stencil = Stencil::Cubic5;

    /// The half-resolution grid of a frame of `width` × `height`: each texel
    /// averages a 2×2 block (the last row or column of an odd size repeats
    /// the frame's edge).
    pub fn grid(width: u32, height: u32) -> (u32, u32) {
        (width.div_ceil(2), height.div_ceil(2))
    }

    /// The step, in texels of the half-resolution grid, of blur level
    /// `level` (0 .. [`ANCHOR_LEVELS`]).
    pub fn step(level: u32) -> u32 {
        1 << level
    }

    /// The 1-D weights, over the half-resolution grid, of the whole blur
    /// (every level's stencil convolved), from offset −half to +half.
    pub fn blur_weights() -> Vec<f64> {
        let stencil = Self::STENCIL;
        let half = stencil.half_width();
        let mut weights = vec![1.0];
        for level in 0..ANCHOR_LEVELS {
            let step = Self::step(level) as usize;
            let reach = (weights.len() - 1) / 2;
            let next_reach = reach + half as usize * step;
            let mut next = vec![0.0; 2 * next_reach + 1];
            for (i, w) in weights.iter().enumerate() {
                for d in -half..=half {
                    let at = i as i64 - reach as i64 + d as i64 * step as i64 + next_reach as i64;
                    next[at as usize] += w * stencil.weight(d);
                }
            }
            weights = next;
        }
        weights
    }

    /// N, the number of pixels the blur averages as far as its noise goes:
    /// four a texel of the grid over Σ W² of the 2-D weights W on the grid
    /// (away from the edges; the interpolation's own averaging left out,
    /// which makes the standard error a little larger, the gate a little
    /// stricter), rounded to f32 once: the device and the CPU reference
    /// divide by this same number.
    pub fn samples() -> f32 {
        let squares: f64 = Self::blur_weights().iter().map(|w| w * w).sum();
        (4.0 / (squares * squares)) as f32
    }
}

/// `pixelfilter=S`'s largest σ, in pixels: a 3×3 kernel holds no wider one.
pub const MAX_PIXEL_FILTER_SIGMA: f32 = 1.0;

/// `pixelfilter=S`, the last stage: the filtered image convolved with a 3×3
/// Gaussian of σ = S pixels (taps outside the image clamped to its edge).
/// For frames whose renderer sampled every pixel at one point (Cycles at one
/// sample: the same point every frame) while their references integrate the
/// renderer's pixel filter: the filtered frame estimates the point-sampled
/// image, and this stage applies the filter the frames left out
/// (docs/JOURNAL.md, "The 1-spp frames are not what their references average").
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PixelFilter {
    pub sigma: f32,
}

impl PixelFilter {
    /// The σ `filter` applies to point-sampled frames: smaller than Cycles'
    /// own filter (1.5-pixel Blackman-Harris, about σ 0.7 on the 3×3) since
    /// the filtered frame is a little blurred already; the narrower side of
    /// the best σ measured, as a wider one costs more than a narrower
    /// (docs/JOURNAL.md, "A pixel filter for point-sampled frames").
    pub const POINT_SAMPLED: PixelFilter = PixelFilter { sigma: 0.4 };

    /// The 1-D weights (centre, each side), normalised to sum to 1 and
    /// rounded to f32 once: the device and the CPU reference use these same
    /// two numbers; tap (dx, dy) weighs w(dx)·w(dy).
    pub fn weights(self) -> [f32; 2] {
        let side = (-1.0 / (2.0 * (self.sigma as f64).powi(2))).exp();
        let total = 1.0 + 2.0 * side;
        [(1.0 / total) as f32, (side / total) as f32]
    }
}

/// The whole pipeline of a filter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FilterPipeline {
    pub outliers: Option<Outliers>,
    pub demodulate: bool,
    /// The temporal stage, for sequences: `temporal=A` after the pre-pass.
    pub temporal: Option<Temporal>,
    pub form: Form,
    /// `planefit=R` after the form, if any.
    pub planefit: Option<PlaneFit>,
    /// `anchor=K` after the form and `planefit`, if any.
    pub anchor: Option<Anchor>,
    /// `pixelfilter=S`, last, if any.
    pub pixel_filter: Option<PixelFilter>,
}

impl Default for FilterPipeline {
    /// The thesis's filter: one window pass, no pre-pass.
    fn default() -> Self {
        FilterPipeline::WINDOW
    }
}

impl FilterPipeline {
    /// The thesis's filter: one window pass, no pre-pass.
    pub const WINDOW: FilterPipeline = FilterPipeline {
        outliers: None,
        demodulate: false,
        temporal: None,
        form: Form::Window,
        planefit: None,
        anchor: None,
        pixel_filter: None,
    };

    /// The features the pipeline's own stages read (besides the colour and
    /// the albedo `demodulate` divides by): the normal, for `keep=surface`,
    /// `planefit` and the temporal stage, and the depth and albedo
    /// (`texture`) for the latter (which also reads the motion vectors, no feature).
    pub fn features(&self) -> std::collections::BTreeSet<crate::lang::Feature> {
        use crate::lang::Feature;
        let mut features = std::collections::BTreeSet::new();
        if self.keep() == Some(Keep::Surface) || self.planefit.is_some() || self.temporal.is_some() {
            features.insert(Feature::Normal);
        }
        if self.temporal.is_some() {
            features.extend([Feature::Depth, Feature::Texture]);
        }
        features
    }

    /// Whether the pipeline carries state from frame to frame (a temporal stage).
    pub fn is_temporal(&self) -> bool {
        self.temporal.is_some()
    }

    /// What follows a temporal pipeline's stage: its demodulation, form and
    /// fit, scored on frames that went through the pre-pass and the stage
    /// already (`datasets::accumulated`, which leaves each blend multiplied
    /// back for the demodulation to divide out). Other pipelines are themselves.
    pub fn spatial(&self) -> FilterPipeline {
        match self.temporal {
            Some(_) => FilterPipeline { outliers: None, temporal: None, ..*self },
            None => *self,
        }
    }

    /// The kind of `keep` the pipeline has, if any.
    pub fn keep(&self) -> Option<Keep> {
        self.outliers.and_then(|o| o.keep)
    }

    /// Whether a pre-pass changes the colour before the form runs.
    pub fn has_prepass(&self) -> bool {
        self.outliers.is_some() || self.demodulate
    }

    /// Number of passes of the form.
    pub fn passes(&self) -> u32 {
        match self.form {
            Form::Window => 1,
            Form::Atrous { passes, .. } => passes,
        }
    }

    /// The radius r whose (2r+1)² taps one pass of the form reads: the
    /// window's `radius`, or the à-trous stencil's half-width whatever its step.
    pub fn pass_radius(&self, radius: u32) -> u32 {
        match self.form {
            Form::Window => radius,
            Form::Atrous { stencil, .. } => stencil.half_width() as u32,
        }
    }

    /// The à-trous stencil (the 5×5 one for a window form, which has none).
    pub fn stencil(&self) -> Stencil {
        match self.form {
            Form::Window => Stencil::default(),
            Form::Atrous { stencil, .. } => stencil,
        }
    }

    /// Whether the form is the à-trous cascade.
    pub fn is_atrous(&self) -> bool {
        matches!(self.form, Form::Atrous { .. })
    }

    /// The pixel step of à-trous pass `level`.
    pub fn step(level: u32) -> u32 {
        1 << level
    }

    /// The most passes of the form whose output can be the temporal
    /// stage's history: every pass, unless the last multiplies the albedo
    /// back (a demodulating pipeline's window, or its à-trous form where no
    /// `planefit` does it instead).
    pub fn most_feedback(&self) -> u32 {
        let last_remodulates = self.demodulate && (self.planefit.is_none() || !self.is_atrous());
        if last_remodulates {
            self.passes() - 1
        } else {
            self.passes()
        }
    }

    /// The variance the à-trous form carries through its passes, of those a
    /// weight reading `variables` reads (SVGF's rule: each pass's output has
    /// Σ w² v_j / (Σ w)²): `temporalVariance` where it reads it, else
    /// `colorVariance`; the other, if read, stays the frame's.
    pub fn carried_variance(
        variables: &std::collections::BTreeSet<crate::lang::ScalarVar>,
    ) -> Option<crate::lang::ScalarVar> {
        use crate::lang::ScalarVar;
        [ScalarVar::TemporalVariance, ScalarVar::ColorVariance].into_iter().find(|v| variables.contains(v))
    }
}

/// The luminance of a colour's non-negative part.
pub fn luminance(c: [f64; 3]) -> f64 {
    (0..3).map(|k| LUMINANCE[k] * c[k].max(0.0)).sum()
}

/// The factor demodulation divides by and remodulation multiplies by.
pub fn modulation(albedo: [f64; 3]) -> [f64; 3] {
    albedo.map(|a| a.clamp(0.0, 1.0).max(ALBEDO_FLOOR))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_round_trips() {
        for text in [
            "window",
            "atrous=5",
            "outliers=2,window",
            "outliers=1.5,demodulate,atrous=3",
            "demodulate,window",
            "outliers=2,demodulate,atrous3x3=6",
            "outliers=2,keep,demodulate,atrous3x3=4",
            "outliers=3,keep,window",
            "outliers=2.5,trim,keep,demodulate,atrous=4",
            "outliers=2,trim,window",
            "outliers=2.5,trim,keep=surface,demodulate,atrous=4",
            "outliers=2.5,trim,keep=surface,demodulate,atrous=4,planefit=3",
            "window,planefit=1",
            "outliers=2,demodulate,temporal=0.2,feedback=1,atrous=4",
            "demodulate,temporal=0.1,feedback=0,clamp=2,atrous3x3=3,planefit=3",
            "demodulate,temporal=0.2,feedback=0,clamp=2,antilag=3,atrous=5",
            "temporal=0.05,feedback=1,window",
            "demodulate,temporal=0.2,feedback=0,clamp=2,antilag=3,atrous=5,pixelfilter=0.45",
            "atrous=4,planefit=3,pixelfilter=1",
            "atrous=4,anchor=2",
            "demodulate,temporal=0.2,feedback=1,atrous=5,planefit=3,anchor=2.5,pixelfilter=0.4",
        ] {
            let p: FilterPipeline = text.parse().unwrap();
            assert_eq!(p.to_string(), text);
            assert_eq!(p.to_string().parse::<FilterPipeline>().unwrap(), p);
        }
    }

    #[test]
    fn bad_text_says_what_is_wrong() {
        for (text, needle) in [
            ("atrous=0", "from 1 to"),
            ("atrous3x3", "atrous3x3=N"),
            ("outliers=-1,window", "at least 0"),
            ("demodulate", "no form"),
            ("window,demodulate", "follow the form"),
            ("blur,window", "unknown stage `blur`;"),
            // The name is checked before the order, and a slip gets the nearest.
            ("atrous=5,outlier=2", "unknown stage `outlier` (did you mean `outliers`?)"),
            ("demodulate,outliers=2,window", "first stage"),
            ("keep,window", "after outliers=K"),
            ("outliers=2,demodulate,keep,window", "right after"),
            ("outliers=2,keep,keep,window", "once"),
            ("trim,window", "after outliers=K"),
            ("outliers=2,keep,trim,window", "right after"),
            ("outliers=2,trim,trim,window", "once"),
            ("outliers=2,keep=wide,window", "keep=surface"),
            ("outliers=2,keep,keep=surface,window", "once"),
            ("planefit=3,atrous=4", "after the form"),
            ("atrous=4,planefit", "planefit=R"),
            ("atrous=4,planefit=0", "from 1 to"),
            ("atrous=4,planefit=3,planefit=3", "once"),
            ("atrous=4,planefit=3,demodulate", "only `planefit=R`"),
            ("pixelfilter=0.5,atrous=4", "after the form"),
            ("atrous=4,pixelfilter", "pixelfilter=S"),
            ("atrous=4,pixelfilter=0", "above 0"),
            ("atrous=4,pixelfilter=1.5", "at most 1"),
            ("atrous=4,pixelfilter=wide", "number of pixels"),
            ("atrous=4,pixelfilter=0.5,planefit=3", "last stage"),
            ("anchor=2,atrous=4", "after the form"),
            ("atrous=4,anchor", "anchor=K"),
            ("atrous=4,anchor=0", "above 0"),
            ("atrous=4,anchor=-1", "above 0"),
            ("atrous=4,anchor=1000", "at most 100"),
            ("atrous=4,anchor=bright", "standard errors"),
            ("atrous=4,anchor=2,anchor=2", "once"),
            ("atrous=4,anchor=2,planefit=3", "before `anchor"),
            ("atrous=4,pixelfilter=0.5,anchor=2", "last stage"),
            ("atrous=4,pixelfilter=0.5,pixelfilter=0.5", "last stage"),
            ("temporal,atrous=4", "temporal=A"),
            ("temporal=0,atrous=4", "above 0"),
            ("temporal=0.2,demodulate,atrous=4", "before `temporal`"),
            ("temporal=0.2,outliers=2,atrous=4", "first stage"),
            ("feedback=1,atrous=4", "after temporal=A"),
            ("clamp=2,atrous=4", "after temporal=A"),
            ("temporal=0.2,clamp=0,atrous=4", "above 0"),
            ("demodulate,temporal=0.2,feedback=4,atrous=4", "at most 3 passes"),
            ("temporal=0.2,temporal=0.1,atrous=4", "once"),
            ("temporal=0.2,atrous=4,feedback=1", "only `planefit=R`"),
        ] {
            let e = text.parse::<FilterPipeline>().unwrap_err().to_string();
            assert!(e.contains(needle), "{text}: {e}");
        }
    }

    #[test]
    fn feedback_defaults_to_the_first_pass_where_the_form_allows() {
        let default = |text: &str| text.parse::<FilterPipeline>().unwrap().temporal.unwrap().feedback;
        assert_eq!(default("demodulate,temporal=0.2,atrous=4"), 1);
        // A window that multiplies the albedo back leaves no demodulated pass: the blend is the history.
        assert_eq!(default("demodulate,temporal=0.2,window"), 0);
        assert_eq!(default("demodulate,temporal=0.2,window,planefit=2"), 0);
        assert_eq!(default("demodulate,temporal=0.2,atrous=2,planefit=2"), 1);
        assert_eq!(default("temporal=0.2,window"), 1);
        let p: FilterPipeline = "demodulate,temporal=0.2,atrous=4".parse().unwrap();
        assert_eq!(p.to_string(), "demodulate,temporal=0.2,feedback=1,atrous=4");
        assert!(p.features().contains(&crate::lang::Feature::Depth) && p.is_temporal());
        assert!(p.features().contains(&crate::lang::Feature::Texture), "the history's test compares albedos");
    }

    #[test]
    fn the_same_surface_test_reads_directions_relative_depth_and_albedo() {
        let up = [0.0, 0.0, 1.0];
        let grey = [0.5; 3];
        let at = |normal, depth| Surface { normal, depth, albedo: grey };
        assert!(same_surface(at(up, 1.05), at(up, 1.0)));
        assert!(!same_surface(at(up, 1.2), at(up, 1.0)));
        assert!(!same_surface(at([1.0, 0.0, 0.0], 1.0), at(up, 1.0)));
        // No surface matches no surface only.
        assert!(same_surface(at([0.0; 3], 0.0), at([0.0; 3], 0.0)));
        assert!(!same_surface(at([0.0; 3], 0.0), at(up, 0.0)));
        // An emitter (black) lying flat on a wall is another material.
        assert!(!same_surface(Surface { albedo: [0.0; 3], ..at(up, 1.0) }, at(up, 1.0)));
        // A texture's dark and light squares are one surface: they mix.
        assert!(same_surface(Surface { albedo: [0.9, 0.9, 0.1], ..at(up, 1.0) }, at(up, 1.0)));
        assert!(same_surface(Surface { albedo: [0.06, 0.0, 0.0], ..at(up, 1.0) }, at(up, 1.0)));
        assert_eq!(direction([0.0, 3.0, 4.0]), [0.0, 0.6, 0.8]);
    }

    #[test]
    fn modulation_is_continuous_and_bounded() {
        assert_eq!(modulation([0.0, 0.05, 0.5]), [ALBEDO_FLOOR, ALBEDO_FLOOR, 0.5]);
        assert_eq!(modulation([300.0, -1.0, 1.0]), [1.0, ALBEDO_FLOOR, 1.0]);
        for stencil in [Stencil::Cubic5, Stencil::Linear3] {
            let half = stencil.half_width();
            let sum: f64 = (-half..=half).map(|d| stencil.weight(d)).sum();
            assert!((sum - 1.0).abs() < 1e-15, "{stencil:?}");
        }
        assert_eq!((Stencil::Cubic5.half_width(), Stencil::Linear3.half_width()), (2, 1));
    }

    #[test]
    fn the_spread_hands_out_all_of_each_source() {
        assert_eq!((Keep::Even.reach(), Keep::Surface.reach()), (31, 127));
        for n in [1i64, 2, 3, 40] {
            for step in [1i64, 2, 16] {
                for x in 0..n {
                    let half = KEEP_STENCIL.half_width() as i64;
                    let total: f64 = (-half..=half)
                        .filter(|d| (0..n).contains(&(x + d * step)))
                        .map(|d| spread_share(x, d, step, n))
                        .sum();
                    assert!((total - 1.0).abs() < 1e-15, "n {n} step {step} x {x}: {total}");
                }
            }
        }
        // Inside the image it is the stencil itself.
        assert_eq!(spread_share(20, 1, 1, 40), 0.25);
    }

    #[test]
    fn the_surface_terms_are_bounded_and_total() {
        let up = [0.0, 0.0, 1.0];
        assert_eq!(surface_normal_term(up, up), 1.0);
        assert!((surface_normal_term(up, [1.0, 0.0, 0.0]) - (-5.0f64).exp()).abs() < 1e-15);
        // Opposite or absent normals: bounded below, never zero.
        assert!(surface_normal_term(up, [0.0, 0.0, -1.0]) > 0.0);
        assert!(surface_normal_term([0.0; 3], up) > 0.0);
        assert_eq!(surface_normal_term([0.0, 0.0, 2.5], up), 1.0, "a direction, whatever its length");
        assert_eq!(surface_light_term(0.5, 0.0), 1.0);
        assert_eq!(surface_light_term(0.5, 0.25), 0.75);
    }

    #[test]
    fn the_anchors_blur_keeps_the_light_and_averages_about_a_gaussians_samples() {
        let weights = Anchor::blur_weights();
        assert_eq!(weights.len(), 2 * (2 + 4) + 1, "two levels reach 2 + 4 texels");
        assert!((weights.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        let variance: f64 = weights.iter().enumerate().map(|(i, w)| w * (i as f64 - 6.0).powi(2)).sum();
        assert!((variance - 5.0).abs() < 1e-9, "each level adds step², got {variance}");
        // A Gaussian of variance 5 texels² averages 4π·5 texels of 4 pixels ≈ 251 pixels; the spline, flatter, a few more.
        let samples = Anchor::samples();
        assert!((251.0..280.0).contains(&samples), "{samples}");
    }

    #[test]
    fn the_pixel_filter_keeps_the_light_and_narrows_with_sigma() {
        let mut last_centre = 0.0;
        for sigma in [1.0, 0.7, 0.45, 0.2] {
            let [centre, side] = PixelFilter { sigma }.weights();
            assert!((centre as f64 + 2.0 * side as f64 - 1.0).abs() < 1e-6, "σ {sigma}: sums to 1");
            assert!(centre > side && side > 0.0, "σ {sigma}: {centre} {side}");
            assert!(centre > last_centre, "a smaller σ keeps more of the pixel");
            last_centre = centre;
        }
        // σ 0.4: a side tap is exp(-1 / 0.32) = 0.044 of the centre.
        let [centre, side] = PixelFilter { sigma: 0.4 }.weights();
        assert!((side / centre - (-1.0f32 / 0.32).exp()).abs() < 1e-4);
    }
}
