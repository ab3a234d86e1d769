//! `filterjit export`: an expression as a standalone shader for another
//! program, with a manifest of its binding interface.
//!
//! WGSL comes from `templates/export.wgsl.tera` through the same lowering as
//! every filterjit kernel ([`KernelKind::Export`]); GLSL, HLSL, MSL and SPIR-V
//! are naga's back ends run on the validated module, so every target computes
//! what the WGSL computes. examples/README.md describes the interface.
//!
//! One module per part: [`manifest`] holds the manifest's types (the
//! contract `web/filterjit.js` and `examples/run_exported` read), `stages`
//! builds the manifest stage by stage, `placement` holds what placing them
//! decides, `frame` writes that as the frame's steps, `bindings` describes
//! each binding, `translate` runs naga's back ends.

mod bindings;
mod frame;
mod manifest;
mod placement;
mod stages;
mod translate;

pub use manifest::*;

use serde::Serialize;

use crate::jit::{self, KernelKind, OutputFormat};
use crate::lang::Expr;
use crate::pipeline::FilterPipeline;
use placement::Placement;
use stages::{manifest, order};
use translate::{header, translate};

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

    /// The target a shader file's extension names (`extension`'s, and
    /// `glsl`, `msl`), case aside.
    pub fn for_extension(extension: &str) -> Option<Target> {
        Some(match extension.to_ascii_lowercase().as_str() {
            "wgsl" => Target::Wgsl,
            "comp" | "glsl" => Target::Glsl,
            "hlsl" => Target::Hlsl,
            "metal" | "msl" => Target::Msl,
            "spv" => Target::Spirv,
            _ => return None,
        })
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

/// The shaders of a pipeline besides the form's, in the order a frame runs
/// them (the form's passes come after the guide, planefit after the form,
/// anchor after it, pixelfilter last).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum StageName {
    Prepass,
    /// `keep`'s spread (`outliers=k,keep,…`).
    Spread,
    /// The temporal stage's blend (`temporal=A`).
    Temporal,
    /// The temporal stage's variance, after its blend.
    TemporalVariance,
    /// The first pass's guide (weights that read `guide`).
    Guide,
    /// `planefit`, after the form.
    PlaneFit,
    /// `anchor`, after `planefit`.
    Anchor,
    /// `pixelfilter`, last.
    PixelFilter,
}

impl StageName {
    pub const ALL: [StageName; 8] = [
        StageName::Prepass,
        StageName::Spread,
        StageName::Temporal,
        StageName::TemporalVariance,
        StageName::Guide,
        StageName::PlaneFit,
        StageName::Anchor,
        StageName::PixelFilter,
    ];

    /// The stage's key in the manifest, and the suffix of its shader's file.
    pub fn key(self) -> &'static str {
        match self {
            StageName::Prepass => "prepass",
            StageName::Spread => "spread",
            StageName::Temporal => "temporal",
            StageName::TemporalVariance => "temporal_variance",
            StageName::Guide => "guide",
            StageName::PlaneFit => "planefit",
            StageName::Anchor => "anchor",
            StageName::PixelFilter => "pixelfilter",
        }
    }
}

/// An exported filter: the form's shader, the other stages' where the
/// pipeline has them, and the manifest of all.
#[derive(Clone, Debug)]
pub struct Exported {
    pub code: Code,
    /// The other stages' shaders, in [`StageName::ALL`]'s order.
    pub stages: Vec<(StageName, Code)>,
    pub manifest: Manifest,
}

impl Exported {
    /// The shader of stage `name`, where the pipeline has it.
    pub fn stage(&self, name: StageName) -> Option<&Code> {
        self.stages.iter().find(|(n, _)| *n == name).map(|(_, code)| code)
    }
}

#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    #[error(transparent)]
    Compile(#[from] jit::CompileError),
    #[error("naga's {target:?} back end failed: {message}")]
    Backend { target: Target, message: String },
}

/// Lower, validate and translate `expr` into a standalone shader for
/// `target`: the window form, without pre-pass ([`export_pipeline`] for others).
pub fn export(expr: &Expr, target: Target, format: OutputFormat) -> Result<Exported, ExportError> {
    export_pipeline(expr, &FilterPipeline::WINDOW, target, format)
}

/// A stored filter as an engine gets it: the cheapest equivalent weight
/// (`simplify`: the same weights), its whole pipeline exported, and, for a
/// window form, the radius `filter` takes in the manifest: the one it was
/// stored with, else the default (an à-trous form reads none).
pub fn export_filter(
    expr: &Expr,
    pipeline: &FilterPipeline,
    radius: Option<u32>,
    target: Target,
    format: OutputFormat,
) -> Result<Exported, ExportError> {
    let radius = (!pipeline.is_atrous()).then(|| radius.unwrap_or(crate::denoise::DEFAULT_RADIUS));
    export_with_radius(&crate::simplify::simplify(expr), pipeline, radius, target, format)
}

/// [`export`] of `expr` in `pipeline`: the form's shader (one à-trous pass,
/// dispatched K times, for `atrous=K`) and the pre-pass's where there is one.
pub fn export_pipeline(
    expr: &Expr,
    pipeline: &FilterPipeline,
    target: Target,
    format: OutputFormat,
) -> Result<Exported, ExportError> {
    export_with_radius(expr, pipeline, None, target, format)
}

/// [`export_pipeline`] with the window radius its manifest states (and its
/// frame sets), where the form reads one.
fn export_with_radius(
    expr: &Expr,
    pipeline: &FilterPipeline,
    radius: Option<u32>,
    target: Target,
    format: OutputFormat,
) -> Result<Exported, ExportError> {
    let shape = jit::Shape::of(pipeline);
    let kernel =
        jit::compile(expr, jit::KernelSpec { kind: KernelKind::Export(format), shape, ..jit::KernelSpec::default() })?;
    let interface = &kernel.source().interface;
    let (code, entry_point) = translate(kernel.validated(), kernel.wgsl(), interface, target)?;
    let mut manifest = manifest(&kernel, target, format, entry_point, pipeline);
    manifest.radius = radius;
    let mut placement = Placement::new(interface.carried_variance().map(|v| v.name().to_string()));
    let mut stages = Vec::new();
    for name in StageName::ALL {
        if let Some((stage, dispatches, code)) =
            stages::build(name, &kernel, pipeline, (&manifest, &placement), target, format)?
        {
            placement.place(&mut manifest, name, (stage, dispatches), pipeline);
            stages.push((name, code));
        }
    }
    manifest.order = order(&manifest, &placement, pipeline);
    manifest.inputs = stages::inputs(&manifest, pipeline);
    (manifest.frame, manifest.images, manifest.output) = frame::plan(&manifest, &placement);
    let read: Vec<String> =
        manifest.inputs.iter().map(|input| frame::components_read(&manifest, &input.image)).collect();
    for (input, components) in manifest.inputs.iter_mut().zip(read) {
        input.components = components;
    }
    let with_header = |code: Code| match code {
        Code::Text(text) if target != Target::Wgsl => Code::Text(header(&manifest, &text)),
        other => other,
    };
    Ok(Exported {
        code: with_header(code),
        stages: stages.into_iter().map(|(name, code)| (name, with_header(code))).collect(),
        manifest,
    })
}
