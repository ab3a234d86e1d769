//! The manifest's row for each binding of an exported shader: its role,
//! what it must hold, and where it is in the target's own terms.

use super::translate::target_slot;
use super::{Binding, BindingKind, StageName, Target};
use crate::jit::interface::{BindingInterface, Resource};
use crate::jit::{Input, OutputFormat, Role};
use crate::lang::{Feature, ScalarVar};

fn content(input: Input) -> String {
    match input {
        Input::Feature(f) => match f {
            Feature::WorldPosition => "world-space position of the first hit".into(),
            Feature::Normal => "shading normal at the first hit; only its direction counts (made unit length)".into(),
            Feature::Texture => "albedo (surface colour) at the first hit".into(),
            Feature::SecondaryTexture => "albedo at the second hit".into(),
            Feature::Depth => "distance from the camera to the first hit".into(),
            Feature::DirectIllumination => "visibility of the lights from the first hit (0..1)".into(),
            gradient => format!(
                "per-channel Sobel gradient magnitude of the normalised {}{}",
                gradient.base(),
                if gradient.base() == Feature::Normal { " (made unit length first)" } else { "" }
            ),
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

/// What a temporal pipeline's `geometry` input holds.
pub(super) const GEOMETRY: &str = "the surface at the first hit: xyz the shading normal's direction (unit length; \
     0 where nothing was hit), w the distance from the camera to it (0 where nothing was hit)";

/// What a temporal pipeline's `motion` input holds.
pub(super) const MOTION: &str = "motion vectors in pixels: the pixel's surface was at p + motion.xy in the frame \
     before (x right, y down; Blender's Vector pass X and -Y)";

/// How the manifest names a binding's kind.
fn binding_kind(resource: Resource) -> BindingKind {
    match resource {
        Resource::Uniform => BindingKind::Uniform,
        Resource::SampledTexture => BindingKind::SampledTexture,
        Resource::StorageTexture(_) => BindingKind::StorageTexture,
        Resource::ParamsStorage | Resource::Storage { .. } => unreachable!("exported shaders bind no storage buffers"),
    }
}

/// Which shader a binding list is of.
#[derive(Clone, Copy, PartialEq, Eq)]
pub(super) enum Stages {
    Form,
    Prepass,
    Spread,
    Guide,
    PlaneFit,
    Anchor,
    PixelFilter,
    Temporal,
    TemporalVariance,
}

impl From<StageName> for Stages {
    fn from(name: StageName) -> Stages {
        match name {
            StageName::Prepass => Stages::Prepass,
            StageName::Spread => Stages::Spread,
            StageName::Temporal => Stages::Temporal,
            StageName::TemporalVariance => Stages::TemporalVariance,
            StageName::Guide => Stages::Guide,
            StageName::PlaneFit => Stages::PlaneFit,
            StageName::Anchor => Stages::Anchor,
            StageName::PixelFilter => Stages::PixelFilter,
        }
    }
}

/// The manifest's rows for `interface`'s bindings.
pub(super) fn bindings(
    interface: &BindingInterface,
    target: Target,
    format: OutputFormat,
    stage: Stages,
) -> Vec<Binding> {
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
                (Role::Color, Stages::PixelFilter) => (
                    "color".into(),
                    "xyz",
                    "the frame so far: `fitted` after planefit, else `filtered`, the form's last output".into(),
                    None,
                ),
                (Role::Output, Stages::PixelFilter) => {
                    ("pixelfiltered".into(), "xyzw", written("the filtered frame"), None)
                }
                (Role::Color, Stages::Anchor) => {
                    ("color".into(), "xyz", "noisy colour, linear RGB, as the engine supplied it".into(), None)
                }
                (Role::Image, Stages::Anchor) => (
                    "image".into(),
                    "xyz",
                    "the frame so far: `fitted` after planefit, else `filtered`, the form's last output".into(),
                    None,
                ),
                (Role::Sums, Stages::Anchor) => (
                    "sums".into(),
                    "xyz",
                    "the level before's blurred sums (x the noisy luminance, y its square, z the frame's luminance); \
                     unread in level 0"
                        .into(),
                    None,
                ),
                (Role::Output, Stages::Anchor) => (
                    "output".into(),
                    "xyzw",
                    "the sums in the half-resolution grid's top-left texels (levels 0 … levels: the 2x2 blocks' \
                     average, then each blur), or in the last dispatch the filtered frame; written with \
                     textureStore; format rgba32float"
                        .into(),
                    None,
                ),
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
                (Role::Input(Input::Variance(v)), Stages::Form) if v.from_temporal() => {
                    let component = if v == ScalarVar::HistoryLength { "y" } else { "x" };
                    (v.name().to_string(), component, content(Input::Variance(v)), None)
                }
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
                (Role::Color, Stages::Temporal) => (
                    "color".into(),
                    "xyz",
                    "the frame's colour as the stages before left it (what the form would filter without the \
                     temporal stage)"
                        .into(),
                    None,
                ),
                (Role::Geometry, Stages::Temporal) => ("geometry".into(), "xyzw", GEOMETRY.into(), None),
                (Role::Motion, Stages::Temporal) => ("motion".into(), "xy", MOTION.into(), None),
                (Role::History, Stages::Temporal) => (
                    "history".into(),
                    "xyz",
                    "the image kept from the frame before (the manifest's `history`): the blend, or a pass of the \
                     form"
                        .into(),
                    None,
                ),
                (Role::Moments, Stages::Temporal) => {
                    ("moments".into(), "xyzw", "the moments kept from the frame before".into(), None)
                }
                (Role::PreviousGeometry, Stages::Temporal) => {
                    ("previous_geometry".into(), "xyzw", "the frame before's `geometry`".into(), None)
                }
                (Role::PreviousAlbedo, Stages::Temporal) => {
                    ("previous_albedo".into(), "xyz", "the frame before's `albedo`".into(), None)
                }
                (Role::PastModulation, Stages::Temporal) => (
                    "past_modulation".into(),
                    "xyz",
                    "the blended modulation kept from the frame before".into(),
                    None,
                ),
                (Role::Output, Stages::Temporal) => (
                    "blend".into(),
                    "xyzw",
                    "the history and the frame blended: what the form filters; format rgba32float".into(),
                    None,
                ),
                (Role::MomentsOut, Stages::Temporal) => (
                    "moments_out".into(),
                    "xyzw",
                    "the luminance's moments m1, m2, the blend's sum of squared shares r and the history's \
                     length n; format rgba32float"
                        .into(),
                    None,
                ),
                (Role::ModulationOut, Stages::Temporal) => (
                    "temporal_modulation".into(),
                    "xyz",
                    "the modulation (the albedo, clamped to [0.001, 1]) blended as the colour is: what the form \
                     multiplies back; format rgba32float"
                        .into(),
                    None,
                ),
                (Role::Accumulated, Stages::Temporal) => (
                    "accumulated".into(),
                    "xy",
                    "x the sample variance of the luminance, y historyLength; format rgba32float".into(),
                    None,
                ),
                (Role::SampleVariance, Stages::TemporalVariance) => {
                    ("sample_variance".into(), "x", "the temporal stage's `accumulated`".into(), None)
                }
                (Role::Moments, Stages::TemporalVariance) => {
                    ("moments".into(), "z", "the temporal stage's `moments_out` (z: r)".into(), None)
                }
                (Role::Input(Input::Variance(ScalarVar::TemporalVariance)), Stages::TemporalVariance) => (
                    "temporalVariance".into(),
                    "x",
                    "the variance of the blend's luminance; format r32float".into(),
                    None,
                ),
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
                    | Role::Accumulated
                    | Role::Sums,
                    _,
                )
                | (
                    Role::Modulation,
                    Stages::Guide | Stages::Temporal | Stages::TemporalVariance | Stages::Anchor | Stages::PixelFilter,
                )
                | (Role::Color | Role::Output, Stages::TemporalVariance) => {
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
                image: match b.role {
                    Role::Input(Input::Variance(v)) if v.from_prepass() => Some("local"),
                    Role::Input(Input::Variance(ScalarVar::HistoryLength)) => Some("accumulated"),
                    _ => None,
                },
                target_slot: target_slot(target, interface, b),
            }
        })
        .collect()
}
