//! The manifest of an exported pipeline, stage by stage: each stage's
//! shader, its dispatches and the images they bind, and the order in words.

use std::collections::BTreeMap;

use super::bindings::{bindings, Stages};
use super::placement::{Dispatches, Placement, StageDispatch};
use super::translate::translate;
use super::{
    Binding, Code, ExportError, Image, Manifest, Stage, StageName, Step, Supplied, Target, Uniform, MANIFEST_VERSION,
    NORMALISATION, SEMANTICS,
};
use crate::jit::interface::BindingInterface;
use crate::jit::{self, KernelKind, OutputFormat, Role, ValidatedKernel, ValidatedModule, WORKGROUP};
use crate::pipeline::{FilterPipeline, Keep};

/// A stage's manifest entry, its dispatches in a frame and its shader.
pub(super) type Built = (Stage, Dispatches, Code);

/// Stage `name`'s manifest entry, dispatches and shader, where `pipeline`
/// has the stage; `manifest` and `placement` hold the stages before it
/// ([`Placement::place`]d).
pub(super) fn build(
    name: StageName,
    kernel: &ValidatedKernel,
    pipeline: &FilterPipeline,
    (manifest, placement): (&Manifest, &Placement),
    target: Target,
    format: OutputFormat,
) -> Result<Option<Built>, ExportError> {
    let stage = |interface: &BindingInterface, module: &ValidatedModule, wgsl: &str| {
        let (code, entry_point) = translate(module, wgsl, interface, target)?;
        Ok::<_, ExportError>((Stage::of(interface, entry_point, &manifest.dispatch, target, format, name.into()), code))
    };
    let once = Dispatches::once;
    let built = match name {
        StageName::Prepass if pipeline.outliers.is_some() || pipeline.demodulate => {
            let interface = jit::BindingInterface::prepass(Some(format));
            let module = jit::prepass_module(Some(format)).map_err(jit::CompileError::from)?;
            let (stage, code) = stage(&interface, &module, &jit::prepass_wgsl(Some(format)))?;
            let params = jit::PrepassParams::of(pipeline, 0, 0);
            // Each binding takes its role's image.
            (stage, once(&[("k", params.k as f64), ("stages", params.stages as f64)], &[]), code)
        }
        StageName::Spread => {
            let Some(keep) = pipeline.keep() else { return Ok(None) };
            let (interface, wgsl, module) = jit::spread_kernel(keep, Some(format));
            let module = module.map_err(jit::CompileError::from)?;
            let (stage, code) = stage(&interface, &module, &wgsl)?;
            (stage, Dispatches { each: spread_sequence(keep), ..Dispatches::default() }, code)
        }
        StageName::Temporal => {
            let Some(temporal) = pipeline.temporal else { return Ok(None) };
            let interface = jit::BindingInterface::temporal(Some(format));
            let module = jit::temporal_module(Some(format)).map_err(jit::CompileError::from)?;
            let (stage, code) = stage(&interface, &module, &jit::temporal_wgsl(Some(format)))?;
            let params = jit::TemporalParams::of(temporal, 0, 0, true);
            let values = [
                ("alpha", decimal(params.alpha)),
                ("gamma", decimal(params.gamma)),
                ("antilag", decimal(params.antilag)),
                ("history", 1.0),
            ];
            let read = ["geometry", "albedo", "motion", "history", "moments", "previous_geometry", "previous_albedo"];
            let mut pairs: Vec<(&str, &str)> = read.map(|image| (image, image)).to_vec();
            pairs.extend([
                ("color", placement.filters.as_str()),
                ("past_modulation", "past_modulation"),
                ("blend", "blend"),
                ("moments_out", "moments_out"),
                ("temporal_modulation", "temporal_modulation"),
                ("accumulated", "accumulated"),
            ]);
            let dispatches = Dispatches { first_frame: [("history".to_string(), 0.0)].into(), ..once(&values, &pairs) };
            (stage, dispatches, code)
        }
        StageName::TemporalVariance if pipeline.temporal.is_some() => {
            let interface = jit::BindingInterface::temporal_variance(Some(format));
            let module = jit::temporal_variance_module(Some(format)).map_err(jit::CompileError::from)?;
            let (stage, code) = stage(&interface, &module, &jit::temporal_variance_wgsl(Some(format)))?;
            let pairs = [
                ("sample_variance", "accumulated"),
                ("moments", "moments_out"),
                ("temporalVariance", "temporalVariance"),
            ];
            (stage, once(&[], &pairs), code)
        }
        StageName::Guide if kernel.source().layout.reads_guide() => {
            let guide = jit::compile_guide(KernelKind::Export(format))?;
            let (stage, code) = stage(&guide.source().interface, guide.validated(), guide.wgsl())?;
            let values = [("radius", 0.0), ("step", 1.0), ("level", 0.0), ("last", 1.0)];
            (stage, once(&values, &[("color", placement.filters.as_str()), ("guide", "guide")]), code)
        }
        StageName::PlaneFit => {
            let Some(fit) = pipeline.planefit else { return Ok(None) };
            let interface = jit::BindingInterface::planefit(Some(format));
            let module = jit::planefit_module(Some(format)).map_err(jit::CompileError::from)?;
            let (stage, code) = stage(&interface, &module, &jit::planefit_wgsl(Some(format)))?;
            let params = jit::PlaneFitParams::of(pipeline, fit, 0, 0);
            // Without demodulation the modulation is not read: the form's output stands in.
            let modulation = match (pipeline.demodulate, pipeline.temporal) {
                (false, _) => "filtered",
                (true, None) => "modulation",
                (true, Some(_)) => "temporal_modulation",
            };
            let values = [("radius", params.radius as f64), ("demodulate", params.demodulate as f64)];
            let pairs = [("color", "filtered"), ("normal", "normal"), ("modulation", modulation), ("fitted", "fitted")];
            (stage, once(&values, &pairs), code)
        }
        StageName::Anchor => {
            let Some(anchor) = pipeline.anchor else { return Ok(None) };
            let interface = jit::BindingInterface::anchor(Some(format));
            let module = jit::anchor_module(Some(format)).map_err(jit::CompileError::from)?;
            let (stage, code) = stage(&interface, &module, &jit::anchor_wgsl(Some(format)))?;
            (stage, Dispatches { each: anchor_sequence(anchor), ..Dispatches::default() }, code)
        }
        StageName::PixelFilter => {
            let Some(filter) = pipeline.pixel_filter else { return Ok(None) };
            let interface = jit::BindingInterface::pixel_filter(Some(format));
            let module = jit::pixel_filter_module(Some(format)).map_err(jit::CompileError::from)?;
            let (stage, code) = stage(&interface, &module, &jit::pixel_filter_wgsl(Some(format)))?;
            let params = jit::PixelFilterParams::of(filter, 0, 0);
            // The f32 weights widened exactly: a host stores them as the same f32s.
            let values = [("centre", params.centre as f64), ("side", params.side as f64)];
            // `filtered`: the frame so far, which the plan names (`frame::plan`).
            (stage, once(&values, &[("color", "filtered"), ("pixelfiltered", "pixelfiltered")]), code)
        }
        StageName::Prepass | StageName::TemporalVariance | StageName::Guide => return Ok(None),
    };
    Ok(Some(built))
}

impl Manifest {
    /// Stage `name`'s entry.
    pub fn stage(&self, name: StageName) -> Option<&Stage> {
        match name {
            StageName::Prepass => self.prepass.as_ref(),
            StageName::Spread => self.spread.as_ref(),
            StageName::Temporal => self.temporal.as_ref(),
            StageName::TemporalVariance => self.temporal_variance.as_ref(),
            StageName::Guide => self.guide.as_ref(),
            StageName::PlaneFit => self.planefit.as_ref(),
            StageName::Anchor => self.anchor.as_ref(),
            StageName::PixelFilter => self.pixelfilter.as_ref(),
        }
    }

    /// How many times a frame dispatches stage `name`'s shader (`frame`).
    pub fn dispatches_of(&self, name: StageName) -> usize {
        let of = |step: &&Step| matches!(step, Step::Dispatch(d) if d.shader == name.key());
        self.frame.iter().filter(of).count()
    }

    /// The images a sequence keeps from frame to frame (`images` that are `kept_from` another).
    pub fn kept(&self) -> impl Iterator<Item = &Image> {
        self.images.iter().filter(|image| image.kept_from.is_some())
    }

    /// Stage `name`'s entry, to fill in.
    pub fn stage_mut(&mut self, name: StageName) -> &mut Option<Stage> {
        match name {
            StageName::Prepass => &mut self.prepass,
            StageName::Spread => &mut self.spread,
            StageName::Temporal => &mut self.temporal,
            StageName::TemporalVariance => &mut self.temporal_variance,
            StageName::Guide => &mut self.guide,
            StageName::PlaneFit => &mut self.planefit,
            StageName::Anchor => &mut self.anchor,
            StageName::PixelFilter => &mut self.pixelfilter,
        }
    }
}

impl Stage {
    /// A stage's shader with `interface`.
    pub(super) fn of(
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
            bindings: bindings(interface, target, format, stage),
        }
    }
}

/// The spread's dispatches (`jit::SpreadParams::sequence`) with the images
/// each binds: the noisy colour or a scratch image (`spread0`, `spread1`)
/// in, a scratch image out, except the last, which writes `kept`, the colour
/// the form filters. `keep=surface`'s also bind the `normal` input,
/// `surface` and `total`, which its first and second dispatches write
/// (binding `modulation` in their place, unread, until they are written).
pub(super) fn spread_sequence(keep: Keep) -> Vec<StageDispatch> {
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
                values: [("step".to_string(), params.step as f64), ("stage".to_string(), params.stage as f64)].into(),
                images,
            }
        })
        .collect()
}

/// `anchor`'s dispatches (`jit::AnchorParams::sequence`) with the images
/// each binds: the noisy `color` and the frame so far (`filtered`, which the
/// plan replaces by `fitted` after `planefit`) in every one; the sums of the
/// level before (`anchor_sums0`, `anchor_sums1` in turn; level 0 binds the
/// frame in their place, unread); the last writes `anchored`.
pub(super) fn anchor_sequence(anchor: crate::pipeline::Anchor) -> Vec<StageDispatch> {
    jit::AnchorParams::sequence(anchor, 0, 0)
        .iter()
        .map(|params| {
            let level = params.level as usize;
            let sums = if level == 0 { "filtered".to_string() } else { format!("anchor_sums{}", (level - 1) % 2) };
            let output = if params.scales() { "anchored".to_string() } else { format!("anchor_sums{}", level % 2) };
            let images =
                [("color", "color".to_string()), ("image", "filtered".into()), ("sums", sums), ("output", output)]
                    .map(|(role, image)| (role.to_string(), image))
                    .into();
            let values =
                [("level".to_string(), params.level as f64), ("gate".to_string(), decimal(params.gate))].into();
            StageDispatch { values, images }
        })
        .collect()
}

/// An f32 parameter as written (0.2, not 0.2's f32 widened); a host stores it as f32 again.
fn decimal(v: f32) -> f64 {
    v.to_string().parse::<f64>().expect("a float's text")
}

/// The steps a host takes per frame, in words.
pub(super) fn order(manifest: &Manifest, placement: &Placement, pipeline: &FilterPipeline) -> Vec<String> {
    let values = |name: StageName| &placement.of(name).expect("a placed stage has its dispatches").values;
    let mut steps = Vec::new();
    let mut colour = "the noisy colour";
    if manifest.prepass.is_some() {
        let values = values(StageName::Prepass);
        steps.push(format!(
            "pre-pass (`prepass`, k = {}, stages = {}): colour = the noisy colour, albedo = the raw albedo (any \
             texture when the pipeline does not demodulate); writes `prepared` and `modulation` (textures of the \
             output format)",
            values["k"], values["stages"]
        ));
        colour = "`prepared`";
    }
    if let Some(spread) = placement.of(StageName::Spread) {
        let surface = match pipeline.keep() {
            Some(Keep::Surface) => {
                " along the surface (the first dispatch writes each pixel's normal direction and clamped luminance \
                 into `surface`, the second their sum into `total`, which the others read; `normal` is the normal \
                 input)"
            }
            _ => "",
        };
        steps.push(format!(
            "spread (`keep`), {} dispatches of the spread shader as `frame` says (uniform `step` and `stage`, the \
             image each role binds): what the clamp removed (the noisy colour minus `prepared`) is handed out \
             over the neighbourhood{surface}, then added back and divided by `modulation`; writes `kept` \
             (rgba32float)",
            spread.each.len()
        ));
        colour = "`kept`";
    }
    if manifest.temporal.is_some() {
        let values = values(StageName::Temporal);
        let kept: Vec<String> =
            placement.history.iter().map(|k| format!("`{}` (from `{}`)", k.image, k.from)).collect();
        steps.push(format!(
            "temporal (`temporal`, one dispatch, alpha = {}, gamma = {}, antilag = {}, history = 1, or 0 on a \
             sequence's first frame): colour = {colour}; geometry, albedo and motion = the frame's inputs; the \
             history's images as the frame before kept them; writes `blend`, `moments_out`, \
             `temporal_modulation` and `accumulated` (rgba32float)",
            values["alpha"], values["gamma"], values["antilag"]
        ));
        steps.push(
            "temporal variance (`temporal_variance`, one dispatch): sample_variance = `accumulated`, moments = \
             `moments_out`; writes `temporalVariance` (r32float)"
                .into(),
        );
        steps.push(format!(
            "at the end of the frame (or right after the form's pass `after_pass`), keep for the next: {}",
            kept.join(", ")
        ));
        colour = "`blend`";
    }
    let modulation = if manifest.temporal.is_some() { "`temporal_modulation`" } else { "`modulation`" };
    let carried = placement.carries.as_deref().unwrap_or("colorVariance");
    if manifest.guide.is_some() {
        steps.push(format!(
            "guide (`guide`, one dispatch, step = 1, level = 0, last = 1): colour = {colour}; writes `guide`, the \
             colour the form's first pass compares (blurred by the 3x3 B-spline)"
        ));
    }
    if manifest.passes == 1 {
        steps.push(format!(
            "form (window): colour = {colour}{}; writes `output`: the filtered frame",
            if pipeline.demodulate { format!(", modulation = {modulation}") } else { String::new() }
        ));
    } else {
        steps.push(format!(
            "form (à-trous), pass k = 0 … {}: params.step = 2^k, params.level = k, params.last = 1 when k = {} \
             else 0; colour = {colour} in pass 0, else pass k-1's `output`; {carried} (where bound) = the \
             frame's in pass 0, else pass k-1's `variance_out`{}{}; pass {}'s `output` is the filtered frame",
            manifest.passes - 1,
            manifest.passes - 1,
            if manifest.guide.is_some() { "; guide = `guide` in pass 0, else pass k-1's `output`" } else { "" },
            if pipeline.demodulate { format!("; modulation = {modulation}") } else { String::new() },
            manifest.passes - 1
        ));
    }
    if manifest.planefit.is_some() {
        let values = values(StageName::PlaneFit);
        steps.push(format!(
            "planefit (`planefit`, one dispatch, radius = {}, demodulate = {}): colour = `filtered`, the form's \
             last `output`; normal = the normal input (only its direction counts){}; writes `fitted`: the \
             filtered frame",
            values["radius"],
            values["demodulate"],
            if pipeline.demodulate { format!(", modulation = {modulation}") } else { String::new() }
        ));
    }
    if manifest.anchor.is_some() {
        steps.push(format!(
            "anchor (`anchor`, {} dispatches, gate = {}): level = 0 averages 2x2 blocks of colour = the noisy \
             colour and image = {} into the top-left quarter of `anchor_sums0` (sums = the image, unread); level \
             = 1 … {} blur those sums (read from the level before's `anchor_sums0` / `anchor_sums1`, written in \
             turn); level = {} scales the image by them and writes `anchored`: the filtered frame",
            jit::ANCHOR_DISPATCHES,
            pipeline.anchor.map_or(0.0, |a| a.gate),
            if manifest.planefit.is_some() { "`fitted`" } else { "`filtered`, the form's last `output`" },
            crate::pipeline::ANCHOR_LEVELS,
            crate::pipeline::ANCHOR_LEVELS + 1,
        ));
    }
    if manifest.pixelfilter.is_some() {
        let values = values(StageName::PixelFilter);
        steps.push(format!(
            "pixelfilter (`pixelfilter`, one dispatch, centre = {}, side = {}): colour = {}; writes \
             `pixelfiltered`: the filtered frame",
            values["centre"],
            values["side"],
            if manifest.anchor.is_some() {
                "`anchored`"
            } else if manifest.planefit.is_some() {
                "`fitted`"
            } else {
                "`filtered`, the form's last `output`"
            }
        ));
    }
    steps
}

pub(super) fn manifest(
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
        temporal: None,
        temporal_variance: None,
        guide: None,
        planefit: None,
        anchor: None,
        pixelfilter: None,
        order: Vec::new(),
        inputs: Vec::new(),
        images: Vec::new(),
        frame: Vec::new(),
        output: String::new(),
    }
}

/// The images the engine supplies every frame (`Manifest::inputs`), once
/// every stage is placed: the noisy colour; the raw albedo where the
/// pre-pass demodulates or the temporal stage reads it; every feature and
/// variance the form normalises; the normal `keep=surface`'s spread and
/// `planefit` read; the temporal stage's geometry and motion. What each must
/// hold is what the first binding that reads it says.
pub(super) fn inputs(manifest: &Manifest, pipeline: &FilterPipeline) -> Vec<Supplied> {
    let stages = StageName::ALL.iter().filter_map(|name| manifest.stage(*name));
    let every: Vec<&Binding> = stages.flat_map(|stage| stage.bindings.iter()).chain(manifest.bindings.iter()).collect();
    let mut names = vec!["color".to_string()];
    if pipeline.demodulate || manifest.temporal.is_some() {
        names.push("albedo".into());
    }
    names.extend(manifest.bindings.iter().filter(|b| b.scale_index.is_some()).map(|b| b.role.clone()));
    let surface = [&manifest.spread, &manifest.planefit].into_iter().flatten();
    if surface.flat_map(|stage| stage.bindings.iter()).any(|b| b.role == "normal") {
        names.push("normal".into());
    }
    if manifest.temporal.is_some() {
        names.extend(["geometry".into(), "motion".into()]);
    }
    let mut seen = std::collections::BTreeSet::new();
    names
        .into_iter()
        .filter(|name| seen.insert(name.clone()))
        .map(|image| {
            let content = match image.as_str() {
                "color" => "the noisy colour, linear RGB (HDR, not normalised; alpha passed through)".to_string(),
                _ => every.iter().find(|b| b.role == image).map(|b| b.content.clone()).unwrap_or_default(),
            };
            // What the frame reads of it is known once the frame is planned.
            Supplied { image, components: String::new(), content }
        })
        .collect()
}
