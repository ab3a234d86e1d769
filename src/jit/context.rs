//! What the kernel templates read, as one typed value. Every key a template
//! names is a field here: the lowering fills a struct, so a key it forgets or
//! misspells fails to compile rather than when a template renders.

use std::collections::BTreeSet;

use serde::Serialize;

/// One member's code in a kernel: its hoisted per-pixel values, its
/// per-neighbour values and the weight expression, for the templates.
#[derive(Serialize)]
pub(super) struct MemberCode {
    pub index: usize,
    /// What the member's names end in: nothing in a kernel of one.
    pub suffix: String,
    pub centre_lines: Vec<String>,
    pub neighbour_lines: Vec<String>,
    /// The SSA value (or literal) of the expression; the weight clamps it.
    pub result: String,
    pub weight: String,
    /// The `templates/ops.wgsl` helpers the member's code calls.
    #[serde(skip)]
    pub helpers: BTreeSet<String>,
}

/// An input binding as the templates' header comments describe it.
#[derive(Serialize)]
pub(super) struct BindingView {
    pub index: u32,
    pub element: &'static str,
    pub describes: String,
    /// Index into the exported shader's `params.scale` (normalised inputs only).
    pub scale_index: Option<usize>,
}

/// A workgroup tile: the (8 + 2r)² window of colour and neighbour features
/// that a workgroup's invocations read, for `templates/tile_decl.wgsl.tera`.
#[derive(Serialize)]
pub(super) struct Tile {
    pub radius: u32,
    pub width: u32,
    pub count: u32,
    pub arrays: Vec<TileArray>,
}

#[derive(Serialize)]
pub(super) struct TileArray {
    pub ident: String,
    pub source: String,
    pub element: &'static str,
}

/// Everything a kernel template reads (`templates/*.wgsl.tera`).
#[derive(Serialize)]
pub(super) struct KernelContext {
    pub crate_version: &'static str,
    pub template_version: u32,
    /// The members' canonical text joined by `; `, and each member's.
    pub expression: String,
    pub expressions: Vec<String>,
    /// Nodes in all members together.
    pub length: usize,
    /// The linked `templates/ops.wgsl` helpers.
    pub ops: String,
    /// A kernel of one member, as the single-expression templates read it.
    pub weight: String,
    pub result: String,
    pub centre_lines: Vec<String>,
    pub neighbour_lines: Vec<String>,
    /// Every member, for the fused fitness template.
    pub members: Vec<MemberCode>,
    pub fused: bool,
    pub shared_centre_lines: Vec<String>,
    pub shared_neighbour_lines: Vec<String>,
    /// How many inputs the exported shader scales (`params.scale`).
    pub scales: usize,
    /// An exported shader that reads the normal: `UNIT_LENGTH2_SLACK` for its
    /// `fj_direction` (`semantics::unit_direction`, which filterjit applies on loading).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub unit_length2_slack: Option<String>,
    pub bindings: Vec<BindingView>,
    /// The interface's binding declarations and its `struct Params`.
    pub declarations: String,
    pub params_struct: String,
    pub relmse_epsilon: String,
    /// The luminance weights (`pipeline::LUMINANCE`): a fitness kernel also writes its output's luminance.
    pub luminance: [String; 3],
    pub workgroup_x: u32,
    pub workgroup_y: u32,
    /// An exported shader's texel format.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub output_format: Option<&'static str>,
    pub tile: Option<Tile>,
    pub atrous: bool,
    /// The pipeline-overridable constant the kernel declares for its pass's role, if any.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub first_pass_override: Option<&'static str>,
    pub remodulate: bool,
    pub shaped: bool,
    /// Whether an à-trous pass carries the colour variance to the next.
    pub carry_variance: bool,
    /// Whether the carried variance rides in the colour's alpha (written
    /// there by every pass, read from there after the first).
    pub variance_in_alpha: bool,
    /// What only the first pass reads (where the kernel declares `FIRST_PASS`).
    pub first_pass_reads: String,
    /// What a pass writes to its output's alpha.
    pub alpha_out: String,
    /// The centre pixel's colour texel, and its modulation's (remodulating kernels).
    pub centre_color: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub centre_modulation: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub neighbour_variance: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub centre_variance: Option<String>,
    pub atrous_half: i32,
    pub stencil: Vec<String>,
}

/// What only the first pass of an à-trous kernel reads, each with what the
/// later passes read instead, for the comment on `FIRST_PASS` (empty where
/// every pass reads the same).
pub(super) fn first_pass_reads(variance_in_alpha: bool, texture_in_fourth_channels: bool, guide: bool) -> String {
    [
        (variance_in_alpha, "the stage's variance image (later passes read the\n// carried variance from their input's alpha)"),
        (
            texture_in_fourth_channels,
            "the texture's image (later passes read the texture from the\n// fourth channels of their input, the world position and the normal)",
        ),
        (guide, "the guide (later passes read their own input in its place)"),
    ]
    .iter()
    .filter_map(|(read, what)| read.then_some(*what))
    .collect::<Vec<_>>()
    .join(" and ")
}
