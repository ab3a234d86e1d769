//! `filterjit export`: an expression as a standalone shader for another
//! program, with a manifest of its binding interface.
//!
//! WGSL comes from `templates/export.wgsl.tera` through the same lowering as
//! every filterjit kernel ([`KernelKind::Export`]); GLSL, HLSL, MSL and SPIR-V
//! are naga's back ends run on the validated module, so every target computes
//! what the WGSL computes. examples/README.md describes the interface.

use std::collections::BTreeMap;

use serde::Serialize;

use crate::jit::interface::{BindingInterface, Resource, UniformField};
use crate::jit::{self, Input, KernelKind, OutputFormat, Role, ValidatedKernel, ValidatedModule, WORKGROUP};
use crate::lang::{Expr, Feature, ScalarVar};
use crate::pipeline::{FilterPipeline, Keep};

/// Shading languages an expression can be exported to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Target {
    Wgsl,
    /// GLSL 4.50 core (desktop OpenGL 4.5, Vulkan GLSL).
    Glsl,
    /// HLSL shader model 5.1 (D3D12; FXC or DXC).
    Hlsl,
    /// Metal Shading Language 2.0.
    Msl,
    /// SPIR-V 1.0 binary (Vulkan).
    Spirv,
}

impl Target {
    /// The usual file extension.
    pub fn extension(self) -> &'static str {
        match self {
            Target::Wgsl => "wgsl",
            Target::Glsl => "comp",
            Target::Hlsl => "hlsl",
            Target::Msl => "metal",
            Target::Spirv => "spv",
        }
    }

    fn language(self) -> &'static str {
        match self {
            Target::Wgsl => "WGSL",
            Target::Glsl => "GLSL 4.50 core, compute stage",
            Target::Hlsl => "HLSL shader model 5.1, compute shader (cs_5_1)",
            Target::Msl => "Metal Shading Language 2.0, kernel function",
            Target::Spirv => "SPIR-V 1.0, GLCompute execution model",
        }
    }
}

/// The shader's code: text, or SPIR-V words.
#[derive(Clone, Debug)]
pub enum Code {
    Text(String),
    SpirV(Vec<u32>),
}

impl Code {
    /// What goes into the file (SPIR-V in little-endian words).
    pub fn to_bytes(&self) -> Vec<u8> {
        match self {
            Code::Text(text) => text.clone().into_bytes(),
            Code::SpirV(words) => words.iter().flat_map(|w| w.to_le_bytes()).collect(),
        }
    }
}

/// An exported filter: the form's shader, the pre-pass's and the spread's
/// where the pipeline has them, and the manifest of all.
#[derive(Clone, Debug)]
pub struct Exported {
    pub code: Code,
    pub prepass: Option<Code>,
    /// `keep`'s spread (`outliers=k,keep,…`).
    pub spread: Option<Code>,
    /// The first pass's guide (weights that read `guide`).
    pub guide: Option<Code>,
    /// `planefit`, after the form.
    pub planefit: Option<Code>,
    pub manifest: Manifest,
}

/// The binding interface of an exported shader, written beside it as JSON.
#[derive(Clone, Debug, Serialize)]
pub struct Manifest {
    /// The manifest's layout ([`MANIFEST_VERSION`]): a host checks it before reading the rest.
    pub version: u32,
    pub generator: String,
    pub expression: String,
    pub target: Target,
    pub language: &'static str,
    /// Name of the compute entry point in this target's code.
    pub entry_point: String,
    pub workgroup_size: [u32; 3],
    pub dispatch: String,
    pub output_format: OutputFormat,
    pub uniform: Uniform,
    /// Every resource, group 0, by binding.
    pub bindings: Vec<Binding>,
    pub normalisation: &'static str,
    pub semantics: &'static str,
    /// Sampled textures the shader binds; more than WebGPU's guaranteed 16
    /// per stage ([`PORTABLE_SAMPLED_TEXTURES`]) needs a device that allows them.
    pub sampled_textures: usize,
    /// The window radius the filter was scored with (set `params.radius` to
    /// it), where the expression came with one (a front member).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub radius: Option<u32>,
    /// The filter pipeline (docs/SEMANTICS.md, "The pipeline") this shader is the form of.
    pub pipeline: String,
    /// How many times to dispatch this shader per frame: 1 for the window
    /// form, K for `atrous=K` (pass k with `step` = 2^k, `level` = k, `last`
    /// = 1 when k = K - 1, colour and carried variance ping-ponged; `order`).
    pub passes: u32,
    /// The pre-pass shader, dispatched once before the form, where the pipeline has one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub prepass: Option<Stage>,
    /// `keep`'s spread shader, dispatched after the pre-pass as its
    /// `sequence` says, where the pipeline keeps what its clamp removed.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub spread: Option<Stage>,
    /// The guide's shader (docs/SEMANTICS.md, "The guide"), dispatched once
    /// after the pre-pass and the spread, where the weight reads `guide`: it
    /// reads the image the form filters and writes `guide`, which the form's
    /// first pass binds as its `guide`; later passes bind their own input.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub guide: Option<Stage>,
    /// `planefit`'s shader, dispatched once after the form's last pass, where
    /// the pipeline has it: it reads `filtered` (the last pass's output) and
    /// writes `fitted`, the filtered frame.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub planefit: Option<Stage>,
    /// The image the form's first pass filters: `color` (the noisy colour),
    /// `prepared` (the pre-pass's) or `kept` (the spread's).
    pub filters: String,
    /// What runs in which order and which image each binding is, in words.
    pub order: Vec<String>,
}

/// A shader of the pipeline besides the form's (the pre-pass, the spread).
#[derive(Clone, Debug, Serialize)]
pub struct Stage {
    /// The shader's file, beside this manifest (set by whoever writes the files).
    pub file: String,
    pub entry_point: String,
    pub dispatch: String,
    pub uniform: Uniform,
    /// Values for the uniform's fields other than width and height.
    pub uniform_values: BTreeMap<String, f64>,
    pub bindings: Vec<Binding>,
    /// Its dispatches in order, where there are several (the spread); a
    /// stage without one is dispatched once, its images named by role.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub sequence: Vec<StageDispatch>,
}

/// One dispatch of a stage's shader.
#[derive(Clone, Debug, Serialize)]
pub struct StageDispatch {
    /// Values for the uniform's fields other than width and height.
    pub uniform_values: BTreeMap<String, f64>,
    /// The image each binding role reads or writes: `color` (the noisy
    /// colour), the pre-pass's `prepared` and `modulation`, or a texture of
    /// the stage's own (`spread0`, `spread1`, `kept`), made in the format of
    /// the storage binding that first writes it.
    pub images: BTreeMap<String, String>,
}

/// The version of the manifest's layout, raised whenever a host would have
/// to read it differently (2: `keep`'s `spread` stage and `filters`; 3: the
/// `guide` stage, and the form's `guide` binding, which changes by pass; 4:
/// the `planefit` stage after the form).
pub const MANIFEST_VERSION: u32 = 4;

/// Sampled textures per shader stage every WebGPU device allows.
pub const PORTABLE_SAMPLED_TEXTURES: usize = 16;

#[derive(Clone, Debug, Serialize)]
pub struct Uniform {
    pub binding: u32,
    pub size_bytes: u32,
    pub fields: Vec<UniformField>,
}

/// What a binding is; written `uniform`, `sampled_texture`, `storage_texture`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum BindingKind {
    Uniform,
    SampledTexture,
    StorageTexture,
}

impl std::fmt::Display for BindingKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.pad(match self {
            BindingKind::Uniform => "uniform",
            BindingKind::SampledTexture => "sampled_texture",
            BindingKind::StorageTexture => "storage_texture",
        })
    }
}

#[derive(Clone, Debug, Serialize)]
pub struct Binding {
    pub group: u32,
    pub binding: u32,
    pub kind: BindingKind,
    /// The WGSL declaration's name.
    pub name: String,
    /// The input's name in filterjit's expression language (`color`, `normal`, `wpVariance`…), or `output`/`params`.
    pub role: String,
    /// Texel components read or written.
    pub components: &'static str,
    /// What the texture must hold.
    pub content: String,
    /// Index into `params.scale` (normalised features and variances only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub scale_index: Option<usize>,
    /// A storage texture's texel format.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub format: Option<&'static str>,
    /// The image to bind when it is not the one named by `role` (what the
    /// outlier rule measured: the pre-pass's `local`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub image: Option<&'static str>,
    /// Where this binding is in the target's own terms (GLSL binding, HLSL register, Metal slot),
    /// derived from `binding` and `kind`.
    pub target_slot: String,
}

const NORMALISATION: &str =
    "Each feature or variance texel v is used as v * scale (scale = params.scale[scale_index].x), \
     shortened to length 1 when it is longer. filterjit uses scale = 1 / (99.9th percentile of |v| over the frame); \
     gradients are the per-channel Sobel magnitude of the normalised feature, normalised the same way. A fixed scale \
     (1 / scene extent for world positions, 1 for normals and albedo) is a good engine approximation; pass 1 when the \
     texture already holds normalised values.";

const SEMANTICS: &str = "f_i = sum_j w_ij c_j / sum_j w_ij over the (2r+1)^2 window around i clipped to the image; \
     negative weights count as zero; a zero weight sum keeps the noisy colour; every operator is total (filterjit's \
     docs/SEMANTICS.md). Colour is linear RGB, not normalised; alpha is passed through.";

#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    #[error(transparent)]
    Compile(#[from] jit::CompileError),
    #[error("naga's {target:?} back end failed: {message}")]
    Backend { target: Target, message: String },
}

/// What the texture of an input must hold.
fn content(input: Input) -> String {
    match input {
        Input::Feature(f) => match f {
            Feature::WorldPosition => "world-space position of the first hit".into(),
            Feature::Normal => "shading normal at the first hit".into(),
            Feature::Texture => "albedo (surface colour) at the first hit".into(),
            Feature::SecondaryTexture => "albedo at the second hit".into(),
            Feature::Depth => "distance from the camera to the first hit".into(),
            Feature::DirectIllumination => "visibility of the lights from the first hit (0..1)".into(),
            gradient => format!("per-channel Sobel gradient magnitude of the normalised {}", gradient.base()),
        },
        Input::Variance(v) => {
            let of = match v {
                ScalarVar::WpVariance => "world position",
                ScalarVar::NVariance => "normal",
                ScalarVar::TexVariance => "albedo",
                ScalarVar::SecTexVariance => "secondary albedo",
                ScalarVar::DovVariance => "depth",
                ScalarVar::DiVariance => "direct-light visibility",
                ScalarVar::ColorVariance => "colour",
                ScalarVar::Level => unreachable!("`level` is never a bound input"),
                ScalarVar::LocalMean | ScalarVar::LocalStd | ScalarVar::ClampedShare => {
                    return format!("the pre-pass's `local` texture, which holds `{v}` (not normalised)")
                }
                ScalarVar::HistoryLength | ScalarVar::TemporalVariance => {
                    return format!("the temporal stage's `{v}` (not normalised)")
                }
            };
            format!("per-pixel sample variance of the {of}, mean over channels")
        }
    }
}

/// The target's own name for a binding.
fn target_slot(target: Target, interface: &BindingInterface, binding: &jit::interface::Binding) -> String {
    let slot = binding.slot;
    match target {
        Target::Wgsl | Target::Spirv => format!("set 0, binding {slot}"),
        Target::Glsl => format!("layout(binding = {slot})"),
        Target::Hlsl => {
            let register = match binding.resource {
                Resource::Uniform => 'b',
                Resource::StorageTexture(_) | Resource::Storage { writable: true, .. } => 'u',
                Resource::SampledTexture | Resource::ParamsStorage | Resource::Storage { writable: false, .. } => 't',
            };
            format!("register({register}{slot}, space0)")
        }
        Target::Msl => match binding.resource {
            Resource::Uniform | Resource::ParamsStorage | Resource::Storage { .. } => {
                format!("[[buffer({})]]", msl_index(interface, binding))
            }
            _ => format!("[[texture({})]]", msl_index(interface, binding)),
        },
    }
}

/// Metal numbers buffers and textures separately: a binding's index among
/// the bindings of its own class, in slot order.
fn msl_index(interface: &BindingInterface, binding: &jit::interface::Binding) -> u8 {
    let is_buffer = |b: &jit::interface::Binding| {
        matches!(b.resource, Resource::Uniform | Resource::ParamsStorage | Resource::Storage { .. })
    };
    interface.bindings.iter().filter(|b| b.slot < binding.slot && is_buffer(b) == is_buffer(binding)).count() as u8
}

/// How the manifest names a binding's kind.
fn binding_kind(resource: Resource) -> BindingKind {
    match resource {
        Resource::Uniform => BindingKind::Uniform,
        Resource::SampledTexture => BindingKind::SampledTexture,
        Resource::StorageTexture(_) => BindingKind::StorageTexture,
        Resource::ParamsStorage | Resource::Storage { .. } => unreachable!("exported shaders bind no storage buffers"),
    }
}

/// Lower, validate and translate `expr` into a standalone shader for
/// `target`: the window form, without pre-pass ([`export_pipeline`] for others).
pub fn export(expr: &Expr, target: Target, format: OutputFormat) -> Result<Exported, ExportError> {
    export_pipeline(expr, &FilterPipeline::WINDOW, target, format)
}

/// A stored filter as an engine gets it: the cheapest equivalent weight
/// (`simplify`: the same weights), its whole pipeline exported, and the window
/// radius it was stored with in the manifest.
pub fn export_filter(
    expr: &Expr,
    pipeline: &FilterPipeline,
    radius: Option<u32>,
    target: Target,
    format: OutputFormat,
) -> Result<Exported, ExportError> {
    let mut exported = export_pipeline(&crate::simplify::simplify(expr), pipeline, target, format)?;
    exported.manifest.radius = radius;
    Ok(exported)
}

/// [`export`] of `expr` in `pipeline`: the form's shader (one à-trous pass,
/// dispatched K times, for `atrous=K`) and the pre-pass's where there is one.
pub fn export_pipeline(
    expr: &Expr,
    pipeline: &FilterPipeline,
    target: Target,
    format: OutputFormat,
) -> Result<Exported, ExportError> {
    let shape = jit::Shape::of(pipeline);
    let kernel = jit::compile_shaped(expr, KernelKind::Export(format), jit::LowerOptions::default(), shape)?;
    let interface = &kernel.source().interface;
    let (code, entry_point) = translate(kernel.validated(), kernel.wgsl(), interface, target)?;
    let mut manifest = manifest(&kernel, target, format, entry_point, pipeline);
    let prepass = match pipeline.outliers.is_some() || pipeline.demodulate {
        false => None,
        true => {
            let interface = jit::BindingInterface::prepass(Some(format));
            let module = jit::prepass_module(Some(format)).map_err(jit::CompileError::from)?;
            let (code, entry_point) = translate(&module, &jit::prepass_wgsl(Some(format)), &interface, target)?;
            let params = jit::PrepassParams::of(pipeline, 0, 0);
            manifest.prepass = Some(Stage {
                uniform_values: [("k".to_string(), params.k as f64), ("stages".to_string(), params.stages as f64)]
                    .into(),
                ..Stage::of(&interface, entry_point, &manifest.dispatch, target, format, Stages::Prepass)
            });
            manifest.filters = "prepared".into();
            Some(code)
        }
    };
    let spread = match pipeline.keep() {
        None => None,
        Some(keep) => {
            let (interface, wgsl, module) = jit::spread_kernel(keep, Some(format));
            let module = module.map_err(jit::CompileError::from)?;
            let (code, entry_point) = translate(&module, &wgsl, &interface, target)?;
            manifest.spread = Some(Stage {
                sequence: spread_sequence(keep),
                ..Stage::of(&interface, entry_point, &manifest.dispatch, target, format, Stages::Spread)
            });
            manifest.filters = "kept".into();
            Some(code)
        }
    };
    let guide = match kernel.source().layout.reads_guide() {
        false => None,
        true => {
            let guide = jit::compile_guide(KernelKind::Export(format))?;
            let interface = &guide.source().interface;
            let (code, entry_point) = translate(guide.validated(), guide.wgsl(), interface, target)?;
            let values = [("radius", 0.0), ("step", 1.0), ("level", 0.0), ("last", 1.0)];
            manifest.guide = Some(Stage {
                uniform_values: values.map(|(field, value)| (field.to_string(), value)).into(),
                sequence: vec![StageDispatch {
                    uniform_values: BTreeMap::new(),
                    images: [("color", manifest.filters.clone()), ("guide", "guide".to_string())]
                        .map(|(role, image)| (role.to_string(), image))
                        .into(),
                }],
                ..Stage::of(interface, entry_point, &manifest.dispatch, target, format, Stages::Guide)
            });
            Some(code)
        }
    };
    let planefit = match pipeline.planefit {
        None => None,
        Some(fit) => {
            let interface = jit::BindingInterface::planefit(Some(format));
            let module = jit::planefit_module(Some(format)).map_err(jit::CompileError::from)?;
            let (code, entry_point) = translate(&module, &jit::planefit_wgsl(Some(format)), &interface, target)?;
            let params = jit::PlaneFitParams::of(pipeline, fit, 0, 0);
            // Without demodulation the modulation is not read: the form's output stands in.
            let modulation = if pipeline.demodulate { "modulation" } else { "filtered" };
            manifest.planefit = Some(Stage {
                uniform_values: [("radius", params.radius), ("demodulate", params.demodulate)]
                    .map(|(field, value)| (field.to_string(), value as f64))
                    .into(),
                sequence: vec![StageDispatch {
                    uniform_values: BTreeMap::new(),
                    images: [
                        ("color", "filtered"),
                        ("normal", "normal"),
                        ("modulation", modulation),
                        ("fitted", "fitted"),
                    ]
                    .map(|(role, image)| (role.to_string(), image.to_string()))
                    .into(),
                }],
                ..Stage::of(&interface, entry_point, &manifest.dispatch, target, format, Stages::PlaneFit)
            });
            Some(code)
        }
    };
    manifest.order = order(&manifest, pipeline);
    let with_header = |code: Code| match code {
        Code::Text(text) if target != Target::Wgsl => Code::Text(header(&manifest, &text)),
        other => other,
    };
    Ok(Exported {
        code: with_header(code),
        prepass: prepass.map(with_header),
        spread: spread.map(with_header),
        guide: guide.map(with_header),
        planefit: planefit.map(with_header),
        manifest,
    })
}

impl Stage {
    /// A stage's shader with `interface`, dispatched once with no uniform
    /// values of its own until the caller sets them.
    fn of(
        interface: &BindingInterface,
        entry_point: String,
        dispatch: &str,
        target: Target,
        format: OutputFormat,
        stage: Stages,
    ) -> Stage {
        Stage {
            file: String::new(),
            entry_point,
            dispatch: dispatch.to_string(),
            uniform: Uniform {
                binding: interface.slot(Role::Params),
                size_bytes: interface.uniform_bytes,
                fields: interface.uniform.clone(),
            },
            uniform_values: BTreeMap::new(),
            bindings: bindings(interface, target, format, stage),
            sequence: Vec::new(),
        }
    }
}

/// The spread's dispatches (`jit::SpreadParams::sequence`) with the images
/// each binds: the noisy colour or a scratch image (`spread0`, `spread1`)
/// in, a scratch image out, except the last, which writes `kept`, the colour
/// the form filters. `keep=surface`'s also bind the `normal` input,
/// `surface` and `total`, which its first and second dispatches write
/// (binding `modulation` in their place, unread, until they are written).
fn spread_sequence(keep: Keep) -> Vec<StageDispatch> {
    let sequence = jit::SpreadParams::sequence(keep, 0, 0);
    let last = sequence.len() - 1;
    sequence
        .iter()
        .enumerate()
        .map(|(n, jit::SpreadDispatch { params, source, target })| {
            let source = match source {
                jit::SpreadSource::Noisy => "color".to_string(),
                jit::SpreadSource::Scratch(k) => format!("spread{k}"),
            };
            let output = match target {
                _ if n == last => "kept".to_string(),
                jit::SpreadTarget::Scratch(k) => format!("spread{k}"),
                jit::SpreadTarget::Total => "total".to_string(),
                jit::SpreadTarget::Surface => "surface".to_string(),
            };
            let mut images: BTreeMap<String, String> = [
                ("color", source),
                ("image", "prepared".into()),
                ("modulation", "modulation".into()),
                ("output", output),
            ]
            .map(|(role, image)| (role.to_string(), image))
            .into();
            if keep == Keep::Surface {
                let read = |image, name: &str| {
                    if jit::written_before(&sequence, n, image) { name } else { "modulation" }.to_string()
                };
                images.insert("normal".into(), "normal".into());
                images.insert("surface".into(), read(jit::SpreadTarget::Surface, "surface"));
                images.insert("total".into(), read(jit::SpreadTarget::Total, "total"));
            }
            StageDispatch {
                uniform_values: [("step".to_string(), params.step as f64), ("stage".to_string(), params.stage as f64)]
                    .into(),
                images,
            }
        })
        .collect()
}

/// Which shader a binding list is of.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Stages {
    Form,
    Prepass,
    Spread,
    Guide,
    PlaneFit,
}

/// The steps a host takes per frame, in words.
fn order(manifest: &Manifest, pipeline: &FilterPipeline) -> Vec<String> {
    let mut steps = Vec::new();
    let mut colour = "the noisy colour";
    if let Some(stage) = &manifest.prepass {
        steps.push(format!(
            "pre-pass (`prepass`, k = {}, stages = {}): colour = the noisy colour, albedo = the raw albedo (any \
             texture when the pipeline does not demodulate); writes `prepared` and `modulation` (textures of the \
             output format)",
            stage.uniform_values["k"], stage.uniform_values["stages"]
        ));
        colour = "`prepared`";
    }
    if let Some(stage) = &manifest.spread {
        let surface = match pipeline.keep() {
            Some(Keep::Surface) => {
                " along the surface (the first dispatch writes each pixel's normal direction and clamped luminance \
                 into `surface`, the second their sum into `total`, which the others read; `normal` is the normal \
                 input)"
            }
            _ => "",
        };
        steps.push(format!(
            "spread (`keep`), {} dispatches of the spread shader as its `sequence` says (uniform `step` and `stage`, \
             the image each role binds): what the clamp removed (the noisy colour minus `prepared`) is handed out \
             over the neighbourhood{surface}, then added back and divided by `modulation`; writes `kept` \
             (rgba32float)",
            stage.sequence.len()
        ));
        colour = "`kept`";
    }
    if manifest.guide.is_some() {
        steps.push(format!(
            "guide (`guide`, one dispatch, step = 1, level = 0, last = 1): colour = {colour}; writes `guide`, the \
             colour the form's first pass compares (blurred by the 3x3 B-spline)"
        ));
    }
    if manifest.passes == 1 {
        steps.push(format!(
            "form (window): colour = {colour}{}; writes `output`: the filtered frame",
            if pipeline.demodulate { ", modulation = `modulation`" } else { "" }
        ));
    } else {
        steps.push(format!(
            "form (à-trous), pass k = 0 … {}: params.step = 2^k, params.level = k, params.last = 1 when k = {} \
             else 0; colour = {colour} in pass 0, else pass k-1's `output`; colorVariance (where bound) = the \
             frame's in pass 0, else pass k-1's `variance_out`{}{}; pass {}'s `output` is the filtered frame",
            manifest.passes - 1,
            manifest.passes - 1,
            if manifest.guide.is_some() { "; guide = `guide` in pass 0, else pass k-1's `output`" } else { "" },
            if pipeline.demodulate { "; modulation = `modulation`" } else { "" },
            manifest.passes - 1
        ));
    }
    if let Some(stage) = &manifest.planefit {
        steps.push(format!(
            "planefit (`planefit`, one dispatch, radius = {}, demodulate = {}): colour = `filtered`, the form's \
             last `output`; normal = the normal input (only its direction counts){}; writes `fitted`: the \
             filtered frame",
            stage.uniform_values["radius"],
            stage.uniform_values["demodulate"],
            if pipeline.demodulate { ", modulation = `modulation`" } else { "" }
        ));
    }
    steps
}

/// The manifest's rows for `interface`'s bindings.
fn bindings(interface: &BindingInterface, target: Target, format: OutputFormat, stage: Stages) -> Vec<Binding> {
    let mut scale_index = 0;
    interface
        .bindings
        .iter()
        .map(|b| {
            let written = |what: &str| format!("{what}, written with textureStore; format {}", format.wgsl());
            let (role, components, content, scale) = match (b.role, stage) {
                (Role::Params, _) => ("params".into(), "", "the Params struct of the uniform section".into(), None),
                (Role::Color, Stages::Prepass) => ("color".into(), "xyz", "noisy colour, linear RGB".into(), None),
                (Role::Color, Stages::Spread) => (
                    "color".into(),
                    "xyz",
                    "what this dispatch spreads: the noisy colour in the first, the previous dispatch's output after"
                        .into(),
                    None,
                ),
                (Role::Image, Stages::Spread) => {
                    ("image".into(), "xyz", "the pre-pass's `prepared`: the clamped colour, undivided".into(), None)
                }
                (Role::Output, Stages::Spread) => (
                    "output".into(),
                    "xyzw",
                    "the spread so far, or in the last dispatch the colour the form filters; written with \
                     textureStore; format rgba32float"
                        .into(),
                    None,
                ),
                (Role::Input(Input::Feature(Feature::Normal)), Stages::Spread | Stages::PlaneFit) => (
                    "normal".into(),
                    "xyz",
                    "the surface normal; only its direction counts (any length, no normalisation scale)".into(),
                    None,
                ),
                (Role::Total, Stages::Spread) => (
                    "total".into(),
                    "x",
                    "texel (0, 0): the sum of the clamped colour's luminance over the frame, which the second \
                     dispatch writes"
                        .into(),
                    None,
                ),
                (Role::Surface, Stages::Spread) => (
                    "surface".into(),
                    "xyzw",
                    "each pixel's normal direction (xyz) and clamped luminance (w), which the first dispatch writes"
                        .into(),
                    None,
                ),
                (Role::Color, Stages::Guide) => ("color".into(), "xyzw", "the colour the form filters".into(), None),
                (Role::Color, Stages::PlaneFit) => {
                    ("color".into(), "xyz", "`filtered`: the form's last pass's output".into(), None)
                }
                (Role::Modulation, Stages::PlaneFit) => (
                    "modulation".into(),
                    "xyz",
                    "the pre-pass's `modulation`, divided out before the fit and multiplied back after".into(),
                    None,
                ),
                (Role::Output, Stages::PlaneFit) => ("fitted".into(), "xyzw", written("the filtered frame"), None),
                (Role::Output, Stages::Guide) => ("guide".into(), "xyzw", written("the guide"), None),
                (Role::Color, Stages::Form) => {
                    ("color".into(), "xyzw", "noisy colour, linear RGB; alpha is copied to the output".into(), None)
                }
                (Role::Albedo, _) => (
                    "albedo".into(),
                    "xyz",
                    "raw albedo at the first hit (not normalised; clamped to [0, 1] and floored in the shader)".into(),
                    None,
                ),
                (Role::Output, Stages::Prepass) => {
                    ("prepared".into(), "xyzw", written("the colour the form filters"), None)
                }
                (Role::Output, Stages::Form) => ("output".into(), "xyzw", written("filtered colour"), None),
                (Role::Modulation, Stages::Prepass) => {
                    ("modulation".into(), "xyzw", written("the albedo divided out, 1 without demodulation"), None)
                }
                (Role::Modulation, Stages::Form | Stages::Spread) => {
                    ("modulation".into(), "xyz", "the pre-pass's `modulation`, multiplied back".into(), None)
                }
                (Role::VarianceOut, _) => (
                    "variance_out".into(),
                    "x",
                    "the colour variance carried to the next pass, written with textureStore; format r32float".into(),
                    None,
                ),
                (Role::Local, _) => (
                    "local".into(),
                    "xyz",
                    "what the outlier rule measured: x localMean, y localStd, z clampedShare (0 without outliers), \
                     written with textureStore; format rgba32float"
                        .into(),
                    None,
                ),
                (Role::Input(Input::Feature(Feature::Guide)), Stages::Form) => (
                    "guide".into(),
                    "xyz",
                    "in pass 0 the guide stage's `guide`, from pass 1 on the pass's colour (the image bound as `color`)"
                        .into(),
                    None,
                ),
                (Role::Input(input), Stages::Form) if !input.is_normalised() => {
                    let Input::Variance(v) = input else { unreachable!("only measures are not normalised") };
                    let k = ScalarVar::FROM_PREPASS.iter().position(|w| *w == v).expect("a measure");
                    (input.describe(), ["x", "y", "z"][k], content(input), None)
                }
                (Role::Input(input), Stages::Form) => {
                    scale_index += 1;
                    let components = if input.components() == 1 { "x" } else { "xyz" };
                    (input.describe(), components, content(input), Some(scale_index - 1))
                }
                (
                    Role::Flags
                    | Role::Reference
                    | Role::Image
                    | Role::Terms
                    | Role::PixelFlags
                    | Role::Input(_)
                    | Role::Total
                    | Role::Surface
                    | Role::Motion
                    | Role::Geometry
                    | Role::PreviousGeometry
                    | Role::PreviousAlbedo
                    | Role::SampleVariance
                    | Role::PastModulation
                    | Role::ModulationOut
                    | Role::History
                    | Role::Moments
                    | Role::MomentsOut
                    | Role::Accumulated,
                    _,
                )
                | (Role::Modulation, Stages::Guide) => {
                    unreachable!("exported shaders bind no {:?}", b.role)
                }
            };
            Binding {
                group: 0,
                binding: b.slot,
                kind: binding_kind(b.resource),
                name: b.ident.clone(),
                role,
                components,
                content,
                scale_index: scale,
                format: match b.resource {
                    Resource::StorageTexture(format) => Some(format.wgsl()),
                    _ => None,
                },
                image: matches!(b.role, Role::Input(Input::Variance(v)) if v.from_prepass()).then_some("local"),
                target_slot: target_slot(target, interface, b),
            }
        })
        .collect()
}

fn manifest(
    kernel: &ValidatedKernel,
    target: Target,
    format: OutputFormat,
    entry_point: String,
    pipeline: &FilterPipeline,
) -> Manifest {
    let interface = &kernel.source().interface;
    let bindings = bindings(interface, target, format, Stages::Form);
    Manifest {
        version: MANIFEST_VERSION,
        generator: format!("filterjit {}", env!("CARGO_PKG_VERSION")),
        expression: kernel.source().canonical.clone(),
        target,
        language: target.language(),
        entry_point,
        workgroup_size: [WORKGROUP[0], WORKGROUP[1], 1],
        dispatch: format!("ceil(width / {}) x ceil(height / {}) x 1 workgroups", WORKGROUP[0], WORKGROUP[1]),
        output_format: format,
        uniform: Uniform {
            binding: interface.slot(Role::Params),
            size_bytes: interface.uniform_bytes,
            fields: interface.uniform.clone(),
        },
        sampled_textures: interface.sampled_textures(),
        bindings,
        normalisation: NORMALISATION,
        semantics: SEMANTICS,
        radius: None,
        pipeline: pipeline.to_string(),
        passes: match pipeline.form {
            crate::pipeline::Form::Window => 1,
            crate::pipeline::Form::Atrous { passes, .. } => passes,
        },
        prepass: None,
        spread: None,
        guide: None,
        planefit: None,
        filters: "color".into(),
        order: Vec::new(),
    }
}

/// A comment block naming the interface, for targets whose back end drops comments.
fn header(manifest: &Manifest, code: &str) -> String {
    let mut out = format!(
        "// Generated by {} from the filter-weight expression\n//   {}\n// {}. Entry point `{}`, workgroup {}x{}x1; dispatch {}.\n// Bindings (group/set 0):\n",
        manifest.generator,
        manifest.expression,
        manifest.language,
        manifest.entry_point,
        manifest.workgroup_size[0],
        manifest.workgroup_size[1],
        manifest.dispatch
    );
    for b in &manifest.bindings {
        out.push_str(&format!("//   {:<26} {:<16} {:<14} {}\n", b.target_slot, b.kind, b.role, b.content));
    }
    out.push_str(&format!(
        "// Uniform: {} bytes: width, height, radius, pad (u32), then one vec4 per input, .x its scale.\n// The manifest beside this file has the details.\n\n",
        manifest.uniform.size_bytes
    ));
    out.push_str(code);
    out
}

fn backend_error(target: Target) -> impl Fn(String) -> ExportError {
    move |message| ExportError::Backend { target, message }
}

fn translate(
    validated: &ValidatedModule,
    wgsl: &str,
    interface: &BindingInterface,
    target: Target,
) -> Result<(Code, String), ExportError> {
    use naga::back;
    let err = backend_error(target);
    let (module, info) = (validated.module(), validated.info());
    let bindings = || interface.bindings.iter().map(|b| (naga::ResourceBinding { group: 0, binding: b.slot }, b));
    match target {
        Target::Wgsl => Ok((Code::Text(wgsl.to_string()), "main".into())),
        Target::Glsl => {
            let options = back::glsl::Options {
                version: back::glsl::Version::Desktop(450),
                writer_flags: back::glsl::WriterFlags::empty(),
                binding_map: bindings().map(|(r, b)| (r, b.slot as u8)).collect(),
                zero_initialize_workgroup_memory: true,
            };
            let pipeline = back::glsl::PipelineOptions {
                shader_stage: naga::ShaderStage::Compute,
                entry_point: "main".into(),
                multiview: None,
            };
            let mut text = String::new();
            let mut writer = back::glsl::Writer::new(
                &mut text,
                module,
                info,
                &options,
                &pipeline,
                naga::proc::BoundsCheckPolicies::default(),
            )
            .map_err(|e| err(e.to_string()))?;
            writer.write().map_err(|e| err(e.to_string()))?;
            Ok((Code::Text(text), "main".into()))
        }
        Target::Hlsl => {
            // No zero-initialisation of workgroup memory: naga writes it as
            // `(float[64])0`, which glslang's HLSL front end cannot parse, and
            // the one exported kernel that has workgroup memory (`keep=surface`'s
            // total) writes every element before any invocation reads it.
            let options = back::hlsl::Options {
                shader_model: back::hlsl::ShaderModel::V5_1,
                zero_initialize_workgroup_memory: false,
                ..Default::default()
            };
            let pipeline = back::hlsl::PipelineOptions::default();
            let mut text = String::new();
            let mut writer = back::hlsl::Writer::new(&mut text, &options, &pipeline);
            let reflection = writer.write(module, info, None).map_err(|e| err(e.to_string()))?;
            let entry =
                reflection.entry_point_names.into_iter().next().and_then(Result::ok).unwrap_or_else(|| "main".into());
            Ok((Code::Text(text), entry))
        }
        Target::Msl => {
            let resources = bindings()
                .map(|(r, b)| {
                    let index = Some(msl_index(interface, b));
                    let target = match b.resource {
                        Resource::Uniform | Resource::ParamsStorage | Resource::Storage { .. } => {
                            back::msl::BindTarget { buffer: index, ..Default::default() }
                        }
                        Resource::SampledTexture => back::msl::BindTarget { texture: index, ..Default::default() },
                        Resource::StorageTexture(_) => {
                            back::msl::BindTarget { texture: index, mutable: true, ..Default::default() }
                        }
                    };
                    (r, target)
                })
                .collect();
            let mut options =
                back::msl::Options { lang_version: (2, 0), fake_missing_bindings: false, ..Default::default() };
            options.per_entry_point_map.insert(
                "main".into(),
                back::msl::EntryPointResources { resources, immediates_buffer: None, sizes_buffer: None },
            );
            let pipeline = back::msl::PipelineOptions::default();
            let (text, translation) =
                back::msl::write_string(module, info, &options, &pipeline).map_err(|e| err(e.to_string()))?;
            let entry =
                translation.entry_point_names.into_iter().next().and_then(Result::ok).unwrap_or_else(|| "main_".into());
            Ok((Code::Text(text), entry))
        }
        Target::Spirv => {
            let options = back::spv::Options {
                lang_version: (1, 0),
                flags: back::spv::WriterFlags::empty(),
                ..Default::default()
            };
            let pipeline =
                back::spv::PipelineOptions { shader_stage: naga::ShaderStage::Compute, entry_point: "main".into() };
            let words =
                back::spv::write_vec(module, info, &options, Some(&pipeline)).map_err(|e| err(e.to_string()))?;
            Ok((Code::SpirV(words), "main".into()))
        }
    }
}
