//! Stage 3: typed [`Expr`] → WGSL source of a complete filter kernel.
//!
//! The expression body is lowered here into straight-line SSA (`let _eN = …`);
//! the kernel skeleton lives in `templates/filter.wgsl.tera` and the operator
//! helpers in `templates/ops.wgsl`.

use std::collections::BTreeSet;
use std::sync::OnceLock;

use serde::Serialize;

use super::helpers;
use super::interface::{BindingInterface, Element, Role};
use super::ir::{self, feature_ident, var_ident};
use crate::lang::{Expr, Feature, FeatureSource, ScalarVar};
use crate::pipeline::Stencil;
use crate::semantics;

/// Bumped whenever the template or the lowering changes what a kernel computes
/// or how it binds its inputs; part of every pipeline-cache key.
pub const TEMPLATE_VERSION: u32 = 4;

/// Workgroup shape of every filter kernel.
pub const WORKGROUP: [u32; 2] = [8, 8];

/// Per-pixel data a kernel reads, besides the colour every kernel reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Input {
    /// A stored feature or a gradient (never `color` or `pixel`).
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
    /// their 99.9th percentile); what the outlier pre-pass measures is in the
    /// colour's own units, like the colour.
    pub fn is_normalised(self) -> bool {
        !matches!(self, Input::Variance(v) if v.from_prepass())
    }
}

/// The per-pixel inputs a kernel reads besides the colour, in a canonical
/// order; [`BindingInterface::of`] gives them their slots.
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
                if matches!(f.source(), FeatureSource::Stored(_) | FeatureSource::Gradient(_)) && f != Feature::Color {
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
    /// several expressions ([`lower_fused`]).
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
    fn template(self) -> &'static str {
        match self {
            KernelKind::Filter => FILTER_TEMPLATE,
            KernelKind::Probe => PROBE_TEMPLATE,
            KernelKind::Fitness => FITNESS_TEMPLATE,
            KernelKind::Export(_) => EXPORT_TEMPLATE,
        }
    }

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
    /// the squared distance without its square root; division by a literal
    /// becomes multiplication by its reciprocal (no zero guard needed).
    pub strength_reduction: bool,
    /// Leave out saturation an operand has already had: every operator's
    /// result and every literal is already in range (saturated and flushed,
    /// docs/SEMANTICS.md), so negating it, taking its absolute value or
    /// clamping the final weight at zero needs no second pass through
    /// `fj_fin`. (Variances are read raw, so they keep the full helpers.)
    pub skip_redundant_checks: bool,
    /// Stage the colour and neighbour features of each workgroup's window in
    /// workgroup memory, for this window radius (the kernel then runs only
    /// with it). Applied to filter and fitness kernels when the tile fits in
    /// [`WORKGROUP_STORAGE_BUDGET`]; see [`KernelSource::tile_radius`].
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

/// WGSL text of a kernel, not yet validated.
#[derive(Clone, Debug)]
pub struct KernelSource {
    pub kind: KernelKind,
    pub options: LowerOptions,
    pub shape: Shape,
    /// The expressions the kernel computes: one, or a fused fitness kernel's
    /// members in the order of their terms ([`lower_fused`]).
    pub exprs: Vec<Expr>,
    /// The expressions' canonical text (members joined by `; `).
    pub canonical: String,
    pub layout: KernelLayout,
    /// Every binding and the uniform; the only owner of slot numbers.
    pub interface: BindingInterface,
    /// The radius the kernel's workgroup tiles were made for, if it has them:
    /// it must be dispatched with exactly this radius.
    pub tile_radius: Option<u32>,
    pub wgsl: String,
}

#[derive(Debug, thiserror::Error)]
pub enum LowerError {
    #[error("literal {0} is out of range: literals must be finite, non-negative and at most {max:e}", max = semantics::BIG)]
    Literal(f64),
    #[error("kernel template failed to render: {0}")]
    Template(String),
    #[error("{0:?} kernels have no à-trous or remodulating form")]
    Shape(KernelKind),
    #[error("only window-form fitness kernels fuse several expressions")]
    Fused,
}

/// Lower an expression to the WGSL source of its filter kernel.
pub fn lower(expr: &Expr) -> Result<KernelSource, LowerError> {
    lower_kind(expr, KernelKind::Filter)
}

/// Lower an expression into a kernel of the given kind.
pub fn lower_kind(expr: &Expr, kind: KernelKind) -> Result<KernelSource, LowerError> {
    lower_with(expr, kind, LowerOptions::default())
}

/// Lower with explicit optimisation switches.
pub fn lower_with(expr: &Expr, kind: KernelKind, options: LowerOptions) -> Result<KernelSource, LowerError> {
    lower_shaped(expr, kind, options, Shape::WINDOW)
}

/// Lower a kernel of the given kind and shape.
pub fn lower_shaped(
    expr: &Expr,
    kind: KernelKind,
    options: LowerOptions,
    shape: Shape,
) -> Result<KernelSource, LowerError> {
    lower_members(std::slice::from_ref(expr), kind, options, shape)
}

/// Lower several expressions into one window-form fitness kernel: every
/// neighbour's features are loaded once and each member's weight, sums,
/// terms and domain flags are its own, computed by exactly the code its own
/// kernel would run (member m's terms at `m * width * height + pixel`). Fewer,
/// larger modules are what software drivers compile fastest
/// (docs/BENCHMARKS.md); the fitness is the same as the members' own kernels'.
pub fn lower_fused(exprs: &[Expr], options: LowerOptions, shape: Shape) -> Result<KernelSource, LowerError> {
    lower_members(exprs, KernelKind::Fitness, options, shape)
}

/// One member's code in a kernel: its hoisted per-pixel values, its
/// per-neighbour values and the weight expression, for the templates.
#[derive(Serialize)]
struct MemberCode {
    index: usize,
    /// What the member's names end in: nothing in a kernel of one.
    suffix: String,
    centre_lines: Vec<String>,
    neighbour_lines: Vec<String>,
    /// The SSA value (or literal) of the expression; the weight clamps it.
    result: String,
    weight: String,
    /// The `templates/ops.wgsl` helpers the member's code calls.
    #[serde(skip)]
    helpers: BTreeSet<String>,
}

fn lower_members(
    exprs: &[Expr],
    kind: KernelKind,
    options: LowerOptions,
    shape: Shape,
) -> Result<KernelSource, LowerError> {
    for expr in exprs {
        expr.validate().map_err(LowerError::Literal)?;
    }
    if shape != Shape::WINDOW && !matches!(kind, KernelKind::Filter | KernelKind::Fitness | KernelKind::Export(_)) {
        return Err(LowerError::Shape(kind));
    }
    let fused = exprs.len() > 1;
    if exprs.is_empty() || (fused && (kind != KernelKind::Fitness || shape.atrous)) {
        return Err(LowerError::Fused);
    }
    let layout = KernelLayout::of_all(exprs);
    let members: Vec<MemberCode> = exprs
        .iter()
        .enumerate()
        .map(|(index, expr)| {
            let prefix = if fused { format!("_m{index}e") } else { "_e".to_string() };
            let body = ir::Body::of(expr, options);
            let (centre_lines, neighbour_lines, result) = body.print(&prefix);
            let mut helpers = body.helpers();
            // Folding never turns a non-variance into a variance or back, so the unfolded root tells.
            let weight = if options.skip_redundant_checks && in_range(expr) {
                format!("max({result}, 0.0)")
            } else {
                helpers.insert("fj_weight".into());
                format!("fj_weight({result})")
            };
            let suffix = if fused { format!("_m{index}") } else { String::new() };
            MemberCode { index, suffix, centre_lines, neighbour_lines, result, weight, helpers }
        })
        .collect();

    let interface = BindingInterface::of(kind, &layout, shape);
    let loads = Loads::of(&interface);
    // An à-trous pass reads taps 2^level apart: a workgroup's window is no tile.
    let tile = options.tile_radius.filter(|_| !shape.atrous).and_then(|radius| Tile::plan(exprs, &interface, radius));
    let neighbour_side = if tile.is_some() { Loads::Tiled } else { loads };
    let shared_centre_lines = centre_loads(exprs, &loads);
    let shared_neighbour_lines: Vec<String> =
        neighbour_side.neighbour_prelude().into_iter().chain(neighbour_loads(exprs, &neighbour_side)).collect();
    // A kernel of one member, as the single-expression templates read it.
    let first = &members[0];
    let centre_lines: Vec<String> = shared_centre_lines.iter().chain(&first.centre_lines).cloned().collect();
    let neighbour_lines: Vec<String> = shared_neighbour_lines.iter().chain(&first.neighbour_lines).cloned().collect();
    let weight = first.weight.clone();

    /// An input binding as the templates' header comments describe it.
    #[derive(Serialize)]
    struct BindingView {
        index: u32,
        element: &'static str,
        describes: String,
        /// Index into the exported shader's `params.scale` (normalised inputs only).
        scale_index: Option<usize>,
    }
    let mut scales = 0..;
    let bindings: Vec<BindingView> = interface
        .inputs()
        .map(|(binding, input)| BindingView {
            index: binding.slot,
            element: Element::of_input(input).wgsl(),
            describes: input.describe(),
            scale_index: input.is_normalised().then(|| scales.next().expect("unbounded")),
        })
        .collect();

    let canonicals: Vec<String> = exprs.iter().map(|e| e.canonical()).collect();
    let canonical = canonicals.join("; ");
    let mut context = tera::Context::new();
    context.insert("crate_version", env!("CARGO_PKG_VERSION"));
    context.insert("template_version", &TEMPLATE_VERSION);
    context.insert("expression", &canonical);
    context.insert("expressions", &canonicals);
    context.insert("length", &exprs.iter().map(|e| e.len()).sum::<usize>());
    let needs = members
        .iter()
        .flat_map(|m| m.helpers.iter().cloned())
        .chain(kind.template_helpers().iter().map(|h| h.to_string()));
    context.insert("ops", &helpers::link(needs));
    context.insert("weight", &weight);
    context.insert("result", &first.result);
    context.insert("members", &members);
    context.insert("fused", &fused);
    context.insert("shared_centre_lines", &shared_centre_lines);
    context.insert("shared_neighbour_lines", &shared_neighbour_lines);
    context.insert("scales", &bindings.iter().filter(|b| b.scale_index.is_some()).count());
    context.insert("bindings", &bindings);
    context.insert("declarations", &interface.declarations());
    context.insert("relmse_epsilon", &format!("{:?}", crate::metrics::RELMSE_EPSILON as f32));
    context.insert("params_struct", &interface.params_struct());
    context.insert("workgroup_x", &WORKGROUP[0]);
    context.insert("workgroup_y", &WORKGROUP[1]);
    context.insert("centre_lines", &centre_lines);
    context.insert("neighbour_lines", &neighbour_lines);
    if let KernelKind::Export(format) = kind {
        context.insert("output_format", format.wgsl());
    }
    context.insert("tile", &tile);
    context.insert("atrous", &shape.atrous);
    context.insert("remodulate", &shape.remodulate);
    context.insert("shaped", &(shape != Shape::WINDOW));
    let carried = Input::Variance(ScalarVar::ColorVariance);
    let carry_variance = shape.atrous && layout.inputs.contains(&carried);
    context.insert("carry_variance", &carry_variance);
    if carry_variance {
        context.insert("neighbour_variance", &Loads::of(&interface).carried_variance_at_neighbour());
        context.insert("centre_variance", &var_ident(ScalarVar::ColorVariance));
    }
    context.insert("atrous_half", &shape.stencil.half_width());
    let stencil: Vec<String> = shape.stencil.weights().iter().copied().map(wgsl_f32).collect();
    context.insert("stencil", &stencil);
    let wgsl = templates().render(kind.template(), &context).map_err(|e| LowerError::Template(format!("{e:?}")))?;
    let tile_radius = tile.map(|t| t.radius);
    Ok(KernelSource { kind, options, shape, exprs: exprs.to_vec(), canonical, layout, interface, tile_radius, wgsl })
}

/// A workgroup tile: the (8 + 2r)² window of colour and neighbour features
/// that a workgroup's invocations read, for `templates/tile_decl.wgsl.tera`.
#[derive(Serialize)]
struct Tile {
    radius: u32,
    width: u32,
    count: u32,
    arrays: Vec<TileArray>,
}

#[derive(Serialize)]
struct TileArray {
    ident: String,
    source: String,
    element: &'static str,
}

impl Tile {
    /// The tile of `expr`'s neighbour-side features for `radius`, if the
    /// kind reads storage buffers through a window and the tile fits.
    fn plan(exprs: &[Expr], interface: &BindingInterface, radius: u32) -> Option<Tile> {
        if !matches!(interface.kind, KernelKind::Filter | KernelKind::Fitness) {
            return None;
        }
        let (_, neighbour) = pair_sides(exprs);
        let elements: Vec<(Feature, Element)> = neighbour
            .into_iter()
            .filter(|f| !matches!(f, Feature::Color | Feature::Pixel))
            .map(|f| (f, Element::of_input(Input::Feature(f))))
            .collect();
        let width = WORKGROUP[0] + 2 * radius;
        let count = width * (WORKGROUP[1] + 2 * radius);
        let bytes_per_cell = Element::Vec4F32.bytes() + elements.iter().map(|(_, e)| e.bytes()).sum::<u32>();
        let arrays = elements
            .into_iter()
            .map(|(f, element)| TileArray {
                ident: tile_ident(f),
                source: interface.ident(Role::Input(Input::Feature(f))).to_string(),
                element: element.wgsl(),
            })
            .collect();
        let bytes_per_cell = bytes_per_cell as usize;
        (count as usize * bytes_per_cell <= WORKGROUP_STORAGE_BUDGET).then_some(Tile { radius, width, count, arrays })
    }
}

fn tile_ident(f: Feature) -> String {
    format!("tile_{}", f.name().to_ascii_lowercase())
}

pub use super::helpers::OPS_WGSL;

/// Whether the value of `e` (constants already folded) is in range by
/// construction: every operator's helper ends in `fj_fin` and literals are
/// saturated and flushed when emitted; only variances are read raw.
fn in_range(e: &Expr) -> bool {
    !matches!(e, Expr::Var(_))
}

const FILTER_TEMPLATE: &str = "filter.wgsl";
const PROBE_TEMPLATE: &str = "probe.wgsl";
const FITNESS_TEMPLATE: &str = "fitness.wgsl";
const EXPORT_TEMPLATE: &str = "export.wgsl";

fn templates() -> &'static tera::Tera {
    static TERA: OnceLock<tera::Tera> = OnceLock::new();
    TERA.get_or_init(|| {
        let mut tera = tera::Tera::default();
        // Partials first: the kernel templates include them.
        tera.add_raw_templates([
            ("window.wgsl", include_str!("../../templates/window.wgsl.tera")),
            ("atrous.wgsl", include_str!("../../templates/atrous.wgsl.tera")),
            ("tile_decl.wgsl", include_str!("../../templates/tile_decl.wgsl.tera")),
            ("tile_load.wgsl", include_str!("../../templates/tile_load.wgsl.tera")),
        ])
        .expect("built-in partial templates parse");
        tera.add_raw_template(FILTER_TEMPLATE, include_str!("../../templates/filter.wgsl.tera"))
            .expect("built-in kernel template parses");
        tera.add_raw_template(PROBE_TEMPLATE, include_str!("../../templates/probe.wgsl.tera"))
            .expect("built-in probe template parses");
        tera.add_raw_template(FITNESS_TEMPLATE, include_str!("../../templates/fitness.wgsl.tera"))
            .expect("built-in fitness template parses");
        tera.add_raw_template(EXPORT_TEMPLATE, include_str!("../../templates/export.wgsl.tera"))
            .expect("built-in export template parses");
        tera
    })
}

/// WGSL spelling of an f32 literal (always with a `.` or an exponent).
pub fn wgsl_f32(value: f64) -> String {
    format!("{:?}", value as f32)
}

/// How loads are spelled in a kernel of one kind; names come from its interface.
#[derive(Clone, Copy)]
enum Loads<'a> {
    /// Storage buffers indexed by pixel, already normalised (filterjit's own kernels).
    Buffers(&'a BindingInterface),
    /// Sampled textures read with `textureLoad`, normalised in the shader by
    /// `params.scale[k]`, k the input's index among the inputs (exported shaders).
    Textures(&'a BindingInterface),
    /// The workgroup tile, at cell `t` (neighbour side of tiled kernels).
    Tiled,
}

impl<'a> Loads<'a> {
    fn of(interface: &'a BindingInterface) -> Self {
        if interface.kind.reads_textures() {
            Loads::Textures(interface)
        } else {
            Loads::Buffers(interface)
        }
    }

    /// Load of feature `f` at pixel index `index` / coordinates `coords`, as a zero-padded vec3.
    fn feature(&self, f: Feature, index: &str, coords: (&str, &str)) -> String {
        let input = Role::Input(Input::Feature(f));
        match (self, f) {
            (_, Feature::Pixel) => format!("vec3<f32>(f32({}), f32({}), 0.0)", coords.0, coords.1),
            (Loads::Buffers(i), Feature::Color) => format!("{}[{index}].xyz", i.ident(Role::Color)),
            (Loads::Buffers(i), _) if f.dimension() == 1 => {
                format!("vec3<f32>({}[{index}], 0.0, 0.0)", i.ident(input))
            }
            (Loads::Buffers(i), _) => format!("{}[{index}].xyz", i.ident(input)),
            (Loads::Tiled, Feature::Color) => "tile_color[t].xyz".to_string(),
            (Loads::Tiled, _) if f.dimension() == 1 => format!("vec3<f32>({}[t], 0.0, 0.0)", tile_ident(f)),
            (Loads::Tiled, _) => format!("{}[t].xyz", tile_ident(f)),
            (Loads::Textures(i), Feature::Color) => format!("{}.xyz", texel(i.ident(Role::Color), coords)),
            (Loads::Textures(i), _) => {
                let texel = texel(i.ident(input), coords);
                let raw =
                    if f.dimension() == 1 { format!("vec3<f32>({texel}.x, 0.0, 0.0)") } else { format!("{texel}.xyz") };
                format!("fj_normalised({raw}, {})", scale_of(i, Input::Feature(f)))
            }
        }
    }

    /// The first lines of the neighbour loop: where neighbour j is, and its colour `color_j`.
    fn neighbour_prelude(&self) -> Vec<String> {
        match self {
            Loads::Buffers(i) => {
                vec!["let j = u32(yj * w + xj);".into(), format!("let color_j = {}[j].xyz;", i.ident(Role::Color))]
            }
            Loads::Textures(i) => vec![format!("let color_j = {}.xyz;", texel(i.ident(Role::Color), ("xj", "yj")))],
            Loads::Tiled => vec![
                "let t = u32((yj - tile_y) * TILE_W + (xj - tile_x));".into(),
                "let color_j = tile_color[t].xyz;".into(),
            ],
        }
    }

    /// Load of variance `v` at the centre pixel; `level` is the à-trous
    /// pass from the uniform, 0 in kernels without passes.
    fn variance(&self, v: ScalarVar) -> String {
        let input = Input::Variance(v);
        match self {
            Loads::Buffers(i) | Loads::Textures(i) if v == ScalarVar::Level => {
                if i.uniform.iter().any(|f| f.name == "level") {
                    "f32(params.level)".into()
                } else {
                    "0.0".into()
                }
            }
            Loads::Buffers(i) => format!("{}[i]", i.ident(Role::Input(input))),
            Loads::Tiled => unreachable!("variances are read at the centre pixel, never from a tile"),
            // Bound to the pre-pass's packed `local` texture: x, y, z in `FROM_PREPASS` order.
            Loads::Textures(i) if v.from_prepass() => {
                let component =
                    ["x", "y", "z"][ScalarVar::FROM_PREPASS.iter().position(|w| *w == v).expect("measured")];
                format!("{}.{component}", texel(i.ident(Role::Input(input)), ("x", "y")))
            }
            Loads::Textures(i) if v == ScalarVar::ColorVariance && i.binding(Role::VarianceOut).is_some() => {
                let texel = texel(i.ident(Role::Input(input)), ("x", "y"));
                format!("fj_carried({texel}.x, {})", scale_of(i, input))
            }
            Loads::Textures(i) => {
                let texel = texel(i.ident(Role::Input(input)), ("x", "y"));
                format!("fj_normalised(vec3<f32>({texel}.x, 0.0, 0.0), {}).x", scale_of(i, input))
            }
        }
    }

    /// The colour variance carried from the last à-trous pass at neighbour j:
    /// already normalised in filterjit's buffers; in an exported shader the
    /// frame's (normalised here) in the first pass, the carried one after.
    fn carried_variance_at_neighbour(&self) -> String {
        let input = Input::Variance(ScalarVar::ColorVariance);
        match self {
            Loads::Buffers(i) => format!("{}[j]", i.ident(Role::Input(input))),
            Loads::Textures(i) => {
                let texel = texel(i.ident(Role::Input(input)), ("xj", "yj"));
                format!("fj_carried({texel}.x, {})", scale_of(i, input))
            }
            Loads::Tiled => unreachable!("à-trous kernels have no tiles"),
        }
    }
}

fn texel(texture: &str, coords: (&str, &str)) -> String {
    format!("textureLoad({texture}, vec2<i32>(i32({}), i32({})), 0)", coords.0, coords.1)
}

fn scale_of(interface: &BindingInterface, input: Input) -> String {
    let k = interface
        .inputs()
        .filter(|(_, i)| i.is_normalised())
        .position(|(_, i)| i == input)
        .expect("every normalised input of the expression is bound");
    format!("params.scale[{k}].x")
}

/// The features read at the centre and at the neighbour by any of `exprs`.
fn pair_sides(exprs: &[Expr]) -> (BTreeSet<Feature>, BTreeSet<Feature>) {
    let (mut centre, mut neighbour) = (BTreeSet::new(), BTreeSet::new());
    for expr in exprs {
        expr.visit(&mut |e| {
            if let Expr::Pair(_, i, j) = e {
                centre.insert(*i);
                neighbour.insert(*j);
            }
        });
    }
    (centre, neighbour)
}

fn centre_loads(exprs: &[Expr], loads: &Loads<'_>) -> Vec<String> {
    let (centre, _) = pair_sides(exprs);
    let features =
        centre.into_iter().map(|f| format!("let {} = {};", feature_ident('i', f), loads.feature(f, "i", ("x", "y"))));
    let variables: BTreeSet<ScalarVar> = exprs.iter().flat_map(|e| e.variables()).collect();
    let vars = variables.into_iter().map(|v| format!("let {} = {};", var_ident(v), loads.variance(v)));
    features.chain(vars).collect()
}

fn neighbour_loads(exprs: &[Expr], loads: &Loads<'_>) -> Vec<String> {
    let (_, neighbour) = pair_sides(exprs);
    neighbour
        .into_iter()
        .map(|f| {
            let value = if f == Feature::Color { "color_j".to_string() } else { loads.feature(f, "j", ("xj", "yj")) };
            format!("let {} = {};", feature_ident('j', f), value)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::{KernelKind, OutputFormat, OPS_WGSL};
    use crate::semantics;

    /// A template calls only the library helpers its kind declares
    /// (`template_helpers`); the partials every kernel includes call none.
    #[test]
    fn templates_declare_the_helpers_they_call() {
        let called = |text: &str| -> Vec<String> {
            super::helpers::names().into_iter().filter(|name| text.contains(&format!("{name}("))).collect()
        };
        let kinds = [
            (include_str!("../../templates/filter.wgsl.tera"), KernelKind::Filter),
            (include_str!("../../templates/fitness.wgsl.tera"), KernelKind::Fitness),
            (include_str!("../../templates/probe.wgsl.tera"), KernelKind::Probe),
            (include_str!("../../templates/export.wgsl.tera"), KernelKind::Export(OutputFormat::Rgba16float)),
        ];
        for (text, kind) in kinds {
            let declared: Vec<String> = kind.template_helpers().iter().map(|h| h.to_string()).collect();
            assert_eq!(called(text), declared, "{kind:?}");
        }
        for partial in [
            include_str!("../../templates/window.wgsl.tera"),
            include_str!("../../templates/atrous.wgsl.tera"),
            include_str!("../../templates/tile_decl.wgsl.tera"),
            include_str!("../../templates/tile_load.wgsl.tera"),
        ] {
            assert!(called(partial).is_empty(), "a partial calls {:?}", called(partial));
        }
        // Linking follows the library's own calls.
        let linked = super::helpers::link(["fj_weight".to_string()]);
        assert!(linked.contains("fn fj_weight(") && linked.contains("fn fj_fin("), "{linked}");
        assert!(!linked.contains("fn fj_pow("));
    }

    /// `templates/ops.wgsl` restates the semantics' constants in WGSL: they must agree.
    #[test]
    fn the_wgsl_constants_are_the_semantics_constants() {
        let constant = |name: &str| -> f64 {
            let line = OPS_WGSL
                .lines()
                .find(|l| l.starts_with(&format!("const {name}: ")))
                .unwrap_or_else(|| panic!("ops.wgsl declares {name}"));
            let value = line.split('=').nth(1).unwrap().trim().trim_end_matches(';').trim_end_matches('u');
            value.parse().unwrap_or_else(|_| panic!("{name} = {value}"))
        };
        let f32_eq = |name: &str, value: f64| {
            assert_eq!(constant(name) as f32, value as f32, "{name} in ops.wgsl differs from semantics.rs");
        };
        f32_eq("FJ_BIG", semantics::BIG);
        f32_eq("FJ_TINY", semantics::TINY);
        f32_eq("FJ_DIV_EPS", semantics::DIV_EPS);
        f32_eq("FJ_EXP_MIN", semantics::EXP_MIN);
        f32_eq("FJ_EXP_MAX", semantics::EXP_MAX);
        f32_eq("FJ_LOG2_BIG", semantics::BIG.log2());
        f32_eq("FJ_SINC_SMALL", semantics::SINC_SMALL);
        f32_eq("FJ_SINC_TAU", semantics::SINC_TAU);
        f32_eq("FJ_PI", std::f64::consts::PI);
        f32_eq("FJ_TAU", std::f64::consts::TAU);
        for (name, bit) in [
            ("FJ_FLAG_SQRT", semantics::flag::SQRT),
            ("FJ_FLAG_ASIN", semantics::flag::ASIN),
            ("FJ_FLAG_ACOS", semantics::flag::ACOS),
            ("FJ_FLAG_POW", semantics::flag::POW),
        ] {
            assert_eq!(constant(name), bit as f64, "{name}");
        }
    }
}
