//! The kernel's vocabulary: what a kernel reads (`Input`, `KernelLayout`),
//! what it computes (`KernelKind`), what surrounds its weight (`Shape`), how
//! it may be lowered (`LowerOptions`), and the constants every kernel shares.
//! The binding interface, the IR and the lowering all speak it; it depends on
//! none of them.

use std::collections::BTreeSet;

use serde::Serialize;

use crate::lang::{Expr, Feature, FeatureSource, ScalarVar};
use crate::pipeline::Stencil;

/// Bumped whenever the template or the lowering changes what a kernel computes
/// or how it binds its inputs; part of every pipeline-cache key.
pub const TEMPLATE_VERSION: u32 = 12;

/// Workgroup shape of every filter kernel.
pub const WORKGROUP: [u32; 2] = [8, 8];

/// The pipeline-overridable constant (a `bool`) of an à-trous filter kernel
/// that reads the guide: whether the pipeline runs the first pass, the only
/// one that loads the guide (docs/SEMANTICS.md, "The guide"). A dispatch's
/// role is known when its pipeline is made, so the kernel holds no branch on
/// it: software drivers execute both sides of a branch on a uniform, and
/// the guide's load is one of a tap's few costs (docs/JOURNAL.md).
pub const FIRST_PASS: &str = "FIRST_PASS";

/// Which passes of an à-trous form one pipeline of a kernel runs: the
/// first, or the later ones (see [`FIRST_PASS`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum PassRole {
    First,
    Later,
}

impl PassRole {
    /// The role of pass `level` (0 is the first).
    pub fn of(level: u32) -> Self {
        if level == 0 {
            PassRole::First
        } else {
            PassRole::Later
        }
    }
}

/// Per-pixel data a kernel reads, besides the colour every kernel reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Input {
    /// A stored feature, a gradient, or the guide (never `color` or `pixel`).
    Feature(Feature),
    /// A per-pixel scalar variance.
    Variance(ScalarVar),
}

impl Input {
    /// Number of f32 components per pixel in the bound buffer.
    pub fn components(self) -> usize {
        match self {
            Input::Feature(f) if f.dimension() == 1 => 1,
            Input::Feature(_) => 4,
            Input::Variance(_) => 1,
        }
    }

    pub fn describe(self) -> String {
        match self {
            Input::Feature(f) => f.name().to_string(),
            Input::Variance(v) => v.name().to_string(),
        }
    }

    /// Whether the input is normalised (features and variances, scaled by
    /// their 99.9th percentile); what the outlier pre-pass measures and what
    /// the temporal stage accumulates are in their own units (the colour's,
    /// frames), like the colour.
    pub fn is_normalised(self) -> bool {
        !matches!(self, Input::Variance(v) if v.from_prepass() || v.from_temporal())
            && self != Input::Feature(Feature::Guide)
    }
}

/// The per-pixel inputs a kernel reads besides the colour, in a canonical
/// order; [`super::BindingInterface::of`] gives them their slots.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct KernelLayout {
    pub inputs: Vec<Input>,
}

impl KernelLayout {
    /// Exactly the inputs `expr` reads, in a canonical order.
    pub fn of(expr: &Expr) -> Self {
        Self::of_all(std::slice::from_ref(expr))
    }

    /// Exactly the inputs any of `exprs` reads (a fused kernel's), in a canonical order.
    pub fn of_all(exprs: &[Expr]) -> Self {
        let mut inputs = BTreeSet::new();
        for expr in exprs {
            for f in expr.features() {
                let bound =
                    matches!(f.source(), FeatureSource::Stored(_) | FeatureSource::Gradient(_) | FeatureSource::Guide);
                if bound && f != Feature::Color {
                    inputs.insert(Input::Feature(f));
                }
            }
            for v in expr.bound_variables() {
                inputs.insert(Input::Variance(v));
            }
        }
        KernelLayout { inputs: inputs.into_iter().collect() }
    }

    pub fn describe(&self) -> String {
        self.inputs.iter().map(|i| i.describe()).collect::<Vec<_>>().join(",")
    }

    /// The variance an à-trous form of this kernel carries through its
    /// passes (`FilterPipeline::carried_variance`), if it reads one.
    pub fn carried_variance(&self) -> Option<ScalarVar> {
        let variances = self
            .inputs
            .iter()
            .filter_map(|i| match i {
                Input::Variance(v) => Some(*v),
                Input::Feature(_) => None,
            })
            .collect();
        crate::pipeline::FilterPipeline::carried_variance(&variances)
    }

    /// Whether the kernel binds the first pass's `guide`, which the device
    /// and an exported pipeline make in a dispatch of their own.
    pub fn reads_guide(&self) -> bool {
        self.inputs.contains(&Input::Feature(Feature::Guide))
    }
}

/// Everything that decides which kernel an expression compiles to: the one
/// description [`crate::jit::compile`] and [`crate::jit::lower`] take. The
/// default is today's `filter` kernel: a window pass, every optimisation on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct KernelSpec {
    pub kind: KernelKind,
    pub options: LowerOptions,
    pub shape: Shape,
}

impl Default for KernelSpec {
    fn default() -> Self {
        KernelSpec { kind: KernelKind::Filter, options: LowerOptions::ALL, shape: Shape::WINDOW }
    }
}

impl KernelSpec {
    /// The default kernel of another kind.
    pub fn of(kind: KernelKind) -> Self {
        KernelSpec { kind, ..KernelSpec::default() }
    }
}

/// What a kernel computes. Both kinds share the binding interface.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub enum KernelKind {
    /// The filter: f_i = Σ_j w_ij c_j / Σ_j w_ij.
    #[default]
    Filter,
    /// The raw weight w_ii per pixel, for testing operator semantics.
    Probe,
    /// The filter's relMSE terms and domain errors per pixel (binding 2 the
    /// terms, 3 the flags, member-major; the reference after the inputs),
    /// reduced per workgroup by `jit::reduce`'s kernel. One kernel may score
    /// several expressions ([`super::lower_fused`]).
    Fitness,
    /// The filter as a standalone shader for other programs: inputs are
    /// sampled textures normalised in the shader by scales from the uniform,
    /// the result goes to a storage texture of the given format
    /// (`templates/export.wgsl.tera`, examples/README.md).
    Export(OutputFormat),
}

/// What surrounds the weight in a kernel (`crate::pipeline`): whether it is
/// one à-trous pass (dispatched once per pass with [`super::AtrousParams`])
/// or the window, and whether the result is multiplied back by the albedo.
/// The outlier and demodulation pre-pass is a kernel of its own (`jit::prepass`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub struct Shape {
    pub atrous: bool,
    pub remodulate: bool,
    /// The à-trous pass's taps (the default, and unused, for a window).
    pub stencil: Stencil,
}

impl Shape {
    /// The thesis's kernel: one window pass, nothing multiplied back.
    pub const WINDOW: Shape = Shape { atrous: false, remodulate: false, stencil: Stencil::Cubic5 };

    /// The kernel shape of a pipeline's form.
    pub fn of(pipeline: &crate::pipeline::FilterPipeline) -> Shape {
        Shape { atrous: pipeline.is_atrous(), remodulate: pipeline.demodulate, stencil: pipeline.stencil() }
    }

    /// A stable name, for cache keys.
    pub fn encode(self) -> String {
        let stencil = match self.stencil {
            Stencil::Cubic5 => "",
            Stencil::Linear3 => " stencil=3x3",
        };
        format!("atrous={} remodulate={}{stencil}", self.atrous, self.remodulate)
    }
}

/// Texel format of an exported shader's output storage texture.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default, clap::ValueEnum, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum OutputFormat {
    /// Half floats: what engines keep HDR colour in; about 3 decimal digits.
    #[default]
    Rgba16float,
    /// Full floats: matches `filterjit filter` to f32 rounding.
    Rgba32float,
}

impl OutputFormat {
    /// The WGSL texel format name.
    pub fn wgsl(self) -> &'static str {
        match self {
            OutputFormat::Rgba16float => "rgba16float",
            OutputFormat::Rgba32float => "rgba32float",
        }
    }
}

impl KernelKind {
    /// The `templates/ops.wgsl` helpers the kind's template calls itself:
    /// the probe saturates its raw value with `fj_fin`.
    pub(crate) fn template_helpers(self) -> &'static [&'static str] {
        match self {
            KernelKind::Probe => &["fj_fin"],
            KernelKind::Filter | KernelKind::Fitness | KernelKind::Export(_) => &[],
        }
    }

    /// A stable name of the kind, for cache keys.
    pub fn encode(self) -> String {
        match self {
            KernelKind::Filter => "filter".into(),
            KernelKind::Probe => "probe".into(),
            KernelKind::Fitness => "fitness".into(),
            KernelKind::Export(format) => format!("export-{}", format.wgsl()),
        }
    }

    /// Whether the kernel reads its inputs from textures (else from storage buffers).
    pub fn reads_textures(self) -> bool {
        matches!(self, KernelKind::Export(_))
    }
}

/// What the lowering may do beyond a literal translation. Every switch keeps
/// the kernel's results (tests compare each against the plain kernel); the
/// benchmark shows what each is worth.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct LowerOptions {
    /// Evaluate operators whose operands are all literals at compile time
    /// (not those that would raise a domain error).
    pub fold_constants: bool,
    /// Compute identical subexpressions once (`distance2(normal)` used twice).
    pub common_subexpressions: bool,
    /// Compute terms that depend only on the centre pixel once per pixel,
    /// outside the neighbour loop.
    pub hoist_centre_terms: bool,
    /// Square by multiplying: pow(x, 2) becomes x·x, and pow(distance2(f), 2)
    /// the squared distance without its square root; pow(x, 1) is x; division by a literal
    /// becomes multiplication by its reciprocal (no zero guard needed).
    pub strength_reduction: bool,
    /// Leave out saturation an operand has already had: every operator's
    /// result and every literal is already in range (saturated and flushed,
    /// docs/SEMANTICS.md), so negating it, taking its absolute value or
    /// clamping the final weight at zero needs no second pass through
    /// `fj_fin`; and where the operands' ranges prove the clamp or the flush
    /// of a sum, product, quotient, `exp` or `sqrt` idle, leave that part out
    /// (`super::range`: the same f32 results). (Variances are read raw, so
    /// they keep the full helpers.)
    pub skip_redundant_checks: bool,
    /// Stage the colour and neighbour features of each workgroup's window in
    /// workgroup memory, for this window radius (the kernel then runs only
    /// with it). Applied to filter and fitness kernels when the tile fits in
    /// [`WORKGROUP_STORAGE_BUDGET`]; see [`super::KernelSource::tile_radius`].
    pub tile_radius: Option<u32>,
}

impl LowerOptions {
    /// Everything on: what filterjit uses.
    pub const ALL: LowerOptions = LowerOptions {
        fold_constants: true,
        common_subexpressions: true,
        hoist_centre_terms: true,
        strength_reduction: true,
        skip_redundant_checks: true,
        tile_radius: None,
    };
    /// A literal translation: one SSA value per node, all inside the loop.
    pub const NONE: LowerOptions = LowerOptions {
        fold_constants: false,
        common_subexpressions: false,
        hoist_centre_terms: false,
        strength_reduction: false,
        skip_redundant_checks: false,
        tile_radius: None,
    };

    /// These options with workgroup tiles for `radius`.
    pub const fn with_tiles(self, radius: u32) -> Self {
        LowerOptions { tile_radius: Some(radius), ..self }
    }
}

/// Bytes of workgroup memory a tile may take: WebGPU's guaranteed 16 KiB
/// (`maxComputeWorkgroupStorageSize`), less the fitness kernel's reduction arrays.
pub const WORKGROUP_STORAGE_BUDGET: usize = 16384 - 1024;

impl Default for LowerOptions {
    fn default() -> Self {
        LowerOptions::ALL
    }
}

/// WGSL spelling of an f32 literal (always with a `.` or an exponent).
pub fn wgsl_f32(value: f64) -> String {
    format!("{:?}", value as f32)
}
