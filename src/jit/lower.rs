//! Stage 3: typed [`Expr`] → WGSL source of a complete filter kernel.
//!
//! The expression body is lowered here into straight-line SSA (`let _eN = …`);
//! the kernel skeleton lives in `templates/filter.wgsl.tera` and the operator
//! helpers in `templates/ops.wgsl`.

use std::collections::BTreeSet;
use std::sync::OnceLock;

use super::context::{self, BindingView, KernelContext, MemberCode, Tile, TileArray};
use super::helpers;
use super::interface::{texture_carrier, BindingInterface, Element, Role, TEXTURE_IN_FOURTH_CHANNELS};
use super::ir::{self, feature_ident, var_ident};
use super::kernel::{
    wgsl_f32, Input, KernelKind, KernelLayout, KernelSpec, LowerOptions, Shape, FIRST_PASS, TEMPLATE_VERSION,
    WORKGROUP, WORKGROUP_STORAGE_BUDGET,
};
use crate::lang::{Expr, Feature, ScalarVar};
use crate::semantics;

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
    /// Whether the kernel declares [`FIRST_PASS`]: each pipeline of it runs
    /// the first pass or the later ones ([`super::kernel::PassRole`]).
    pub first_pass_override: bool,
    /// Whether the variance each pass carries rides in the colour's alpha
    /// (read from the stage's own image in the first pass only).
    pub variance_in_alpha: bool,
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

/// Lower an expression to the WGSL source of the kernel `spec` describes.
pub fn lower(expr: &Expr, spec: KernelSpec) -> Result<KernelSource, LowerError> {
    lower_members(std::slice::from_ref(expr), spec)
}

/// Lower several expressions into one window-form fitness kernel (`spec`'s
/// kind must be [`KernelKind::Fitness`]): every neighbour's features are
/// loaded once and each member's weight, sums, terms and domain flags are
/// its own, computed by exactly the code its own kernel would run (member
/// m's terms at `m * width * height + pixel`). Fewer, larger modules are what
/// software drivers compile fastest (docs/JOURNAL.md); the fitness is the
/// same as the members' own kernels'.
pub fn lower_fused(exprs: &[Expr], spec: KernelSpec) -> Result<KernelSource, LowerError> {
    lower_members(exprs, spec)
}

fn lower_members(exprs: &[Expr], spec: KernelSpec) -> Result<KernelSource, LowerError> {
    let KernelSpec { kind, options, shape } = spec;
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
    let needs = members
        .iter()
        .flat_map(|m| m.helpers.iter().cloned())
        .chain(kind.template_helpers().iter().map(|h| h.to_string()));
    let carried = layout.carried_variance().filter(|_| shape.atrous);
    let carry_variance = carried.is_some();
    let variance_in_alpha = carried.is_some_and(|v| loads.variance_in_alpha(v));
    let first_pass_reads =
        context::first_pass_reads(variance_in_alpha, loads.texture_in_fourth_channels(), layout.reads_guide());
    let first_pass_override = loads.specialises_passes() && shape.atrous && !first_pass_reads.is_empty();
    let tile_radius = tile.as_ref().map(|t| t.radius);
    let context = KernelContext {
        crate_version: env!("CARGO_PKG_VERSION"),
        template_version: TEMPLATE_VERSION,
        expression: canonical.clone(),
        length: exprs.iter().map(|e| e.len()).sum(),
        expressions: canonicals,
        ops: helpers::link(needs),
        weight,
        result: first.result.clone(),
        fused,
        shared_centre_lines,
        shared_neighbour_lines,
        scales: bindings.iter().filter(|b| b.scale_index.is_some()).count(),
        unit_length2_slack: (matches!(loads, Loads::Textures(_))
            && interface.bindings.iter().any(|b| b.role == Role::Input(Input::Feature(Feature::Normal))))
        .then(|| wgsl_f32(f64::from(semantics::UNIT_LENGTH2_SLACK))),
        bindings,
        declarations: interface.declarations(),
        relmse_epsilon: wgsl_f32(crate::metrics::RELMSE_EPSILON),
        luminance: crate::pipeline::LUMINANCE.map(wgsl_f32),
        params_struct: interface.params_struct(),
        workgroup_x: WORKGROUP[0],
        workgroup_y: WORKGROUP[1],
        centre_lines,
        neighbour_lines,
        output_format: match kind {
            KernelKind::Export(format) => Some(format.wgsl()),
            _ => None,
        },
        tile,
        atrous: shape.atrous,
        first_pass_override: first_pass_override.then_some(FIRST_PASS),
        remodulate: shape.remodulate,
        shaped: shape != Shape::WINDOW,
        carry_variance,
        variance_in_alpha,
        first_pass_reads,
        alpha_out: loads.alpha_out(carried),
        centre_color: loads.centre_image(Role::Color),
        centre_modulation: shape.remodulate.then(|| loads.centre_image(Role::Modulation)),
        neighbour_variance: carried.map(|v| loads.carried_variance_at_neighbour(v)),
        centre_variance: carried.map(var_ident),
        atrous_half: shape.stencil.half_width(),
        stencil: shape.stencil.weights().iter().copied().map(wgsl_f32).collect(),
        members,
    };
    let context = tera::Context::from_serialize(&context).map_err(|e| LowerError::Template(format!("{e:?}")))?;
    let wgsl = templates().render(template_of(kind), &context).map_err(|e| LowerError::Template(format!("{e:?}")))?;
    Ok(KernelSource {
        kind,
        options,
        shape,
        exprs: exprs.to_vec(),
        canonical,
        layout,
        interface,
        tile_radius,
        first_pass_override,
        variance_in_alpha,
        wgsl,
    })
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

/// The template a kernel of `kind` renders.
fn template_of(kind: KernelKind) -> &'static str {
    match kind {
        KernelKind::Filter => FILTER_TEMPLATE,
        KernelKind::Probe => PROBE_TEMPLATE,
        KernelKind::Fitness => FITNESS_TEMPLATE,
        KernelKind::Export(_) => EXPORT_TEMPLATE,
    }
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

/// How loads are spelled in a kernel of one kind; names come from its interface.
#[derive(Clone, Copy)]
enum Loads<'a> {
    /// Storage buffers indexed by pixel, already normalised (filterjit's own kernels).
    Buffers(&'a BindingInterface),
    /// Sampled textures read with `textureLoad`, normalised in the shader by
    /// `params.scale[k]`, k the input's index among the inputs (exported shaders).
    Textures(&'a BindingInterface),
    /// Sampled textures read with `textureLoad`, already normalised
    /// (filterjit's own à-trous form, [`BindingInterface::samples_images`]).
    OwnTextures(&'a BindingInterface),
    /// The workgroup tile, at cell `t` (neighbour side of tiled kernels).
    Tiled,
}

impl<'a> Loads<'a> {
    fn of(interface: &'a BindingInterface) -> Self {
        if interface.kind.reads_textures() {
            Loads::Textures(interface)
        } else if interface.samples_color() {
            Loads::OwnTextures(interface)
        } else {
            Loads::Buffers(interface)
        }
    }

    /// The whole texel (vec4) of the image bound to `role` at the centre pixel.
    fn centre_image(&self, role: Role) -> String {
        match self {
            Loads::Buffers(i) => format!("{}[i]", i.ident(role)),
            Loads::Textures(i) | Loads::OwnTextures(i) => texel(i.ident(role), ("x", "y")),
            Loads::Tiled => unreachable!("the centre is never read from a tile"),
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
            (Loads::Textures(i) | Loads::OwnTextures(i), Feature::Color) => {
                format!("{}.xyz", texel(i.ident(Role::Color), coords))
            }
            (Loads::OwnTextures(i), Feature::Texture) if self.texture_in_fourth_channels() => {
                let carrier = |k| texture_carrier(k).map_or(Role::Color, |f| Role::Input(Input::Feature(f)));
                let fourth = |k| format!("{}.w", texel(i.ident(carrier(k)), coords));
                let packed = format!("vec3<f32>({}, {}, {})", fourth(0), fourth(1), fourth(2));
                format!("select({packed}, {}.xyz, {FIRST_PASS})", texel(i.ident(input), coords))
            }
            (Loads::OwnTextures(i), _) => {
                let texel = texel(i.ident(input), coords);
                if f.dimension() == 1 {
                    format!("vec3<f32>({texel}.x, 0.0, 0.0)")
                } else {
                    format!("{texel}.xyz")
                }
            }
            // In the colour's own units, like the colour.
            (Loads::Textures(i), Feature::Guide) => format!("{}.xyz", texel(i.ident(input), coords)),
            (Loads::Textures(i), _) => {
                let texel = texel(i.ident(input), coords);
                let raw =
                    if f.dimension() == 1 { format!("vec3<f32>({texel}.x, 0.0, 0.0)") } else { format!("{texel}.xyz") };
                let normalised = format!("fj_normalised({raw}, {})", scale_of(i, Input::Feature(f)));
                match f {
                    // Its direction, as filterjit loads it (`semantics::unit_direction`), whatever the scale.
                    Feature::Normal => format!("fj_direction({normalised})"),
                    _ => normalised,
                }
            }
        }
    }

    /// Whether the kernel runs as à-trous passes, its pass in `params.level`.
    fn has_passes(&self) -> bool {
        match self {
            Loads::Buffers(i) | Loads::Textures(i) | Loads::OwnTextures(i) => {
                i.uniform.iter().any(|f| f.name == "level")
            }
            Loads::Tiled => false,
        }
    }

    /// Whether a pass's role is a pipeline-overridable constant ([`FIRST_PASS`])
    /// rather than read from the uniform: in filterjit's own filter kernels,
    /// which make a pipeline per role. Fitness kernels, compiled one per
    /// candidate, and exported shaders, run by other programs, keep one.
    fn specialises_passes(&self) -> bool {
        matches!(self, Loads::Buffers(i) | Loads::OwnTextures(i) if i.kind == KernelKind::Filter)
    }

    /// Whether the variance `v` each pass carries to the next rides in the
    /// colour's fourth channel (filterjit's own filter kernels on textures):
    /// a pass reads it with the colour it loads at every tap, not from an
    /// image of its own, and only the first pass reads the stage's image
    /// ([`FIRST_PASS`]). On lavapipe a tap's loads are most of its cost
    /// (docs/JOURNAL.md, "The carried variance in the colour's alpha").
    fn variance_in_alpha(&self, v: ScalarVar) -> bool {
        matches!(self, Loads::OwnTextures(i) if i.kind == KernelKind::Filter && i.carried_variance() == Some(v))
            && self.has_passes()
    }

    /// Whether the `texture` feature is read from the fourth channels of
    /// the colour and its carriers after the first pass
    /// ([`TEXTURE_IN_FOURTH_CHANNELS`]): filterjit's own filter kernels on
    /// textures that bind the texture and its carriers, carrying no variance.
    fn texture_in_fourth_channels(&self) -> bool {
        let Loads::OwnTextures(i) = self else { return false };
        let binds = |f| i.binding(Role::Input(Input::Feature(f))).is_some();
        i.kind == KernelKind::Filter
            && self.has_passes()
            && i.carried_variance().is_none()
            && binds(Feature::Texture)
            && TEXTURE_IN_FOURTH_CHANNELS.iter().all(|(f, _)| binds(*f))
    }

    /// What a pass writes to its output's alpha: the variance it carries,
    /// the texture's x (from the first pass on: later passes pass theirs
    /// through), or the input's.
    fn alpha_out(&self, carried: Option<ScalarVar>) -> String {
        match self {
            Loads::OwnTextures(_) if carried.is_some_and(|v| self.variance_in_alpha(v)) => "carried".into(),
            Loads::OwnTextures(i) if self.texture_in_fourth_channels() => {
                let own = texel(i.ident(Role::Input(Input::Feature(Feature::Texture))), ("x", "y"));
                let in_alpha = (0..3).position(|k| texture_carrier(k).is_none()).expect("one in the colour's");
                format!("select(centre.w, {own}.{}, {FIRST_PASS})", ["x", "y", "z"][in_alpha])
            }
            _ => "centre.w".into(),
        }
    }

    /// `v` at (`x`, `y`) where it rides in the colour's alpha: the stage's image in the first pass.
    fn variance_from_alpha(&self, v: ScalarVar, at: (&str, &str)) -> Option<String> {
        let Loads::OwnTextures(i) = self else { return None };
        self.variance_in_alpha(v).then(|| {
            let own = texel(i.ident(Role::Input(Input::Variance(v))), at);
            format!("select({}.w, {own}.x, {FIRST_PASS})", texel(i.ident(Role::Color), at))
        })
    }

    /// The line that binds feature `f` at `side` (`i` or `j`) to `value`;
    /// `color` is how that pixel's colour is read. From the second à-trous pass on the guide
    /// is the pass's own input (docs/SEMANTICS.md, "The guide"), so it is read
    /// from the colour already loaded: on lavapipe a tap's loads are most of
    /// its cost, and the guide is one of them.
    fn bind(&self, side: char, f: Feature, value: String, color: &str) -> String {
        let ident = feature_ident(side, f);
        if f == Feature::Guide && self.has_passes() {
            let first = if self.specialises_passes() { FIRST_PASS } else { "params.level == 0u" };
            format!("var {ident} = {color}; if ({first}) {{ {ident} = {value}; }}")
        } else {
            format!("let {ident} = {value};")
        }
    }

    /// The first lines of the neighbour loop: where neighbour j is, and its colour `color_j`.
    fn neighbour_prelude(&self) -> Vec<String> {
        match self {
            Loads::Buffers(i) => {
                vec!["let j = u32(yj * w + xj);".into(), format!("let color_j = {}[j].xyz;", i.ident(Role::Color))]
            }
            Loads::Textures(i) | Loads::OwnTextures(i) => {
                vec![format!("let color_j = {}.xyz;", texel(i.ident(Role::Color), ("xj", "yj")))]
            }
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
            Loads::Buffers(_) | Loads::Textures(_) | Loads::OwnTextures(_) if v == ScalarVar::Level => {
                if self.has_passes() {
                    "f32(params.level)".into()
                } else {
                    "0.0".into()
                }
            }
            Loads::Buffers(i) => format!("{}[i]", i.ident(Role::Input(input))),
            Loads::OwnTextures(i) => self
                .variance_from_alpha(v, ("x", "y"))
                .unwrap_or_else(|| format!("{}.x", texel(i.ident(Role::Input(input)), ("x", "y")))),
            Loads::Tiled => unreachable!("variances are read at the centre pixel, never from a tile"),
            // Bound to the pre-pass's packed `local` texture: x, y, z in `FROM_PREPASS` order.
            Loads::Textures(i) if v.from_prepass() => {
                let component =
                    ["x", "y", "z"][ScalarVar::FROM_PREPASS.iter().position(|w| *w == v).expect("measured")];
                format!("{}.{component}", texel(i.ident(Role::Input(input)), ("x", "y")))
            }
            // The temporal stage's, raw: historyLength from its packed
            // `accumulated` texture's y, temporalVariance (the frame's, or
            // carried from the last pass) from its own texture's x.
            Loads::Textures(i) if v.from_temporal() => {
                let component = if v == ScalarVar::HistoryLength { "y" } else { "x" };
                format!("{}.{component}", texel(i.ident(Role::Input(input)), ("x", "y")))
            }
            Loads::Textures(i) if i.carried_variance() == Some(v) => {
                let texel = texel(i.ident(Role::Input(input)), ("x", "y"));
                format!("fj_carried({texel}.x, {})", scale_of(i, input))
            }
            Loads::Textures(i) => {
                let texel = texel(i.ident(Role::Input(input)), ("x", "y"));
                format!("fj_normalised(vec3<f32>({texel}.x, 0.0, 0.0), {}).x", scale_of(i, input))
            }
        }
    }

    /// The variance `v` carried from the last à-trous pass at neighbour j:
    /// already normalised in filterjit's buffers; in an exported shader the
    /// frame's (normalised here) in the first pass, the carried one after;
    /// the temporal stage's never normalised.
    fn carried_variance_at_neighbour(&self, v: ScalarVar) -> String {
        let input = Input::Variance(v);
        match self {
            Loads::Buffers(i) => format!("{}[j]", i.ident(Role::Input(input))),
            Loads::OwnTextures(i) => self
                .variance_from_alpha(v, ("xj", "yj"))
                .unwrap_or_else(|| format!("{}.x", texel(i.ident(Role::Input(input)), ("xj", "yj")))),
            Loads::Textures(i) if v.from_temporal() => {
                format!("{}.x", texel(i.ident(Role::Input(input)), ("xj", "yj")))
            }
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
    let colour = loads.feature(Feature::Color, "i", ("x", "y"));
    let features = centre.into_iter().map(|f| loads.bind('i', f, loads.feature(f, "i", ("x", "y")), &colour));
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
            loads.bind('j', f, value, "color_j")
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::OPS_WGSL;
    use crate::jit::{KernelKind, OutputFormat};
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
