//! The manifest written beside an exported shader: its types are the
//! contract every host reads (`web/filterjit.js`, `examples/run_exported`;
//! examples/README.md, "The interface").

use std::collections::BTreeMap;

use serde::Serialize;

use super::Target;
use crate::jit::interface::UniformField;
use crate::jit::OutputFormat;

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
    /// The window radius to set `params.radius` to: the one the filter was
    /// stored or scored with, else `filter`'s default for a window form
    /// (`filterjit export` fills it); absent where the form reads none.
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
    /// `keep`'s spread shader, dispatched after the pre-pass as `frame`
    /// says, where the pipeline keeps what its clamp removed.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub spread: Option<Stage>,
    /// The temporal stage's blend (docs/SEMANTICS.md, "The temporal
    /// stage"), dispatched once after the pre-pass and the spread, where the
    /// pipeline has `temporal=A`: it blends the image the form would filter
    /// into the history and writes `blend` (what the form filters instead),
    /// `moments_out`, `temporal_modulation` (what the form multiplies back)
    /// and `accumulated` (x the sample variance, y historyLength). Its
    /// uniform's `history` is 0 on a sequence's first frame (its dispatch's `first_frame`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub temporal: Option<Stage>,
    /// The temporal stage's second shader, dispatched once after `temporal`:
    /// the sample variance blurred and scaled, `temporalVariance`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub temporal_variance: Option<Stage>,
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
    /// `anchor`'s shader, dispatched once per blur level and once more, after
    /// the form and `planefit`, where the pipeline has it: it reads the noisy
    /// `color` and the frame so far and writes `anchored`, the filtered frame.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub anchor: Option<Stage>,
    /// `pixelfilter`'s shader, dispatched once last, where the pipeline has
    /// it: it reads the frame so far (`anchored` after `anchor`, `fitted` after `planefit`, else
    /// `filtered`, the form's last output) and writes `pixelfiltered`, the
    /// filtered frame.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pixelfilter: Option<Stage>,
    /// What runs in which order and which image each binding is, in words.
    pub order: Vec<String>,
    /// The images the engine supplies every frame, by the name every
    /// binding that reads one uses; every other image a binding names is
    /// made by a stage or kept from the frame before (`images`).
    pub inputs: Vec<Supplied>,
    /// The images the pipeline makes: written by a stage each frame, or
    /// kept from the frame before. Every image, these and the inputs, is
    /// width x height.
    pub images: Vec<Image>,
    /// One frame, step by step: what `order` says in words, as data. A
    /// host runs the steps in order and binds what each names.
    pub frame: Vec<Step>,
    /// The image that holds the filtered frame once `frame` has run.
    pub output: String,
}

/// One step of a frame (`Manifest::frame`).
#[derive(Clone, Debug, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Step {
    /// Dispatch a shader once over the frame (`dispatch` workgroups).
    Dispatch(Dispatch),
    /// Copy image `from` into the kept image `into`, which the next frame's
    /// dispatches read (a texture of `from`'s format).
    Keep { from: String, into: String },
}

/// One dispatch of a shader (`Step::Dispatch`).
#[derive(Clone, Debug, Serialize)]
pub struct Dispatch {
    /// `form` (the manifest's own shader) or a stage's key (`prepass`, `spread`…).
    pub shader: String,
    /// The uniform's fields other than width, height and `scale[k]`; a field
    /// named nowhere (padding) is 0. Whole numbers are written as integers.
    #[serde(serialize_with = "whole_as_integers")]
    pub values: BTreeMap<String, f64>,
    /// Values that replace `values` on a sequence's first frame (and after a
    /// cut): the temporal stage's `history` = 0. On that frame the kept
    /// images hold nothing yet; any texture of a float format will do.
    #[serde(skip_serializing_if = "BTreeMap::is_empty", serialize_with = "whole_as_integers")]
    pub first_frame: BTreeMap<String, f64>,
    /// The image each texture binding of the shader binds, by the binding's `role`.
    pub images: BTreeMap<String, String>,
}

/// An image the pipeline makes (`Manifest::images`).
#[derive(Clone, Debug, Serialize)]
pub struct Image {
    pub name: String,
    /// Its texel format (a storage texture's); absent for a kept image,
    /// which takes its source's (an input's: the one the engine supplies).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub format: Option<&'static str>,
    /// The shader whose dispatch writes it first in a frame.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub written_by: Option<String>,
    /// The image of the frame before it holds: a `keep` step copies it in.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub kept_from: Option<String>,
    pub content: String,
}

/// A uniform's values with whole numbers as JSON integers, so that a host
/// that reads a `u32` field as an integer reads `1`, not `1.0`.
fn whole_as_integers<S: serde::Serializer>(values: &BTreeMap<String, f64>, serializer: S) -> Result<S::Ok, S::Error> {
    use serde::ser::SerializeMap;
    let mut map = serializer.serialize_map(Some(values.len()))?;
    for (name, value) in values {
        if value.fract() == 0.0 && value.abs() < 9.007_199_254_740_992e15 {
            map.serialize_entry(name, &(*value as i64))?;
        } else {
            map.serialize_entry(name, value)?;
        }
    }
    map.end()
}

/// An image the engine supplies every frame (`Manifest::inputs`).
#[derive(Clone, Debug, Serialize)]
pub struct Supplied {
    /// The name the bindings read it by (`color`, `albedo`, `normal`, `geometry`, `motion`…).
    pub image: String,
    /// The channels some dispatch of `frame` reads (`x`, `xy`, `xyz`, `xyzw`):
    /// every input is read with `textureLoad` from a `texture_2d<f32>`, so
    /// any float format with at least these channels will do
    /// (`rgba32float`, `rgba16float`; `r32float` for `x`). filterjit's own
    /// are `rgba32float`, `r32float` for one channel.
    pub components: String,
    /// What it must hold.
    pub content: String,
}

/// A shader of the pipeline besides the form's (the pre-pass, the spread);
/// `frame` says when it runs, with which values and images.
#[derive(Clone, Debug, Serialize)]
pub struct Stage {
    /// The shader's file, beside this manifest (set by whoever writes the files).
    pub file: String,
    pub entry_point: String,
    pub dispatch: String,
    pub uniform: Uniform,
    pub bindings: Vec<Binding>,
}

/// The version of the manifest's layout, raised whenever a host would have
/// to read it differently (2: `keep`'s `spread` stage and `filters`; 3: the
/// `guide` stage, and the form's `guide` binding, which changes by pass; 4:
/// the `planefit` stage after the form; 5: the temporal stage, its
/// `history`, `carries` and a stage's `first_frame`; 6: the `pixelfilter`
/// stage, last; 7: `inputs`, the images the engine supplies; 8: `frame`,
/// `images` and `output`, the frame as data, in place of each stage's
/// `sequence` and values, `history`, `filters` and `carries`). The `anchor`
/// stage came within 8: a host that walks `frame` runs it unchanged.
pub const MANIFEST_VERSION: u32 = 8;

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

pub(super) const NORMALISATION: &str =
    "Each feature or variance texel v is used as v * scale (scale = params.scale[scale_index].x), \
     shortened to length 1 when it is longer. filterjit uses scale = 1 / (99.9th percentile of |v| over the frame); \
     gradients are the per-channel Sobel magnitude of the normalised feature, normalised the same way. A fixed scale \
     (1 / scene extent for world positions, 1 for normals and albedo) is a good engine approximation; pass 1 when the \
     texture already holds normalised values.";

pub(super) const SEMANTICS: &str =
    "f_i = sum_j w_ij c_j / sum_j w_ij over the (2r+1)^2 window around i clipped to the image; \
     negative weights count as zero; a zero weight sum keeps the noisy colour; every operator is total (filterjit's \
     docs/SEMANTICS.md). Colour is linear RGB, not normalised; alpha is passed through.";
