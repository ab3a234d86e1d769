//! What placing the stages decides for a frame, before it is written as
//! data: each stage's dispatches with their values and images, the image
//! the form filters, the variance its passes carry and what a sequence
//! keeps. [`super::frame::plan`] turns it into the manifest's `frame` and
//! `images`; none of it is written as it is.

use std::collections::BTreeMap;

use super::{Manifest, Stage, StageName};
use crate::pipeline::{FilterPipeline, Temporal};

/// The stages placed so far and what they change for the ones after them.
pub(super) struct Placement {
    /// Each placed stage's dispatches, by stage.
    pub dispatches: BTreeMap<StageName, Dispatches>,
    /// The image the form's first pass filters: `color` (the noisy colour),
    /// `prepared` (the pre-pass's), `kept` (the spread's) or `blend` (the
    /// temporal stage's).
    pub filters: String,
    /// The variance the form's passes carry (`colorVariance` or
    /// `temporalVariance`), where its weight reads one and it has passes:
    /// pass 0 binds the frame's, pass k the `variance_out` of pass k - 1.
    pub carries: Option<String>,
    /// What a sequence keeps from frame to frame (empty without the temporal
    /// stage): each image takes what `from` holds, in `from`'s format,
    /// copied at the end of the frame or right after form pass `after_pass`.
    pub history: Vec<Kept>,
}

/// A stage's dispatches in a frame.
#[derive(Clone, Debug, Default)]
pub(super) struct Dispatches {
    /// Values for the uniform's fields other than width and height, in every dispatch.
    pub values: BTreeMap<String, f64>,
    /// Values that replace `values` on a sequence's first frame (and after a
    /// cut): the temporal stage's `history` = 0.
    pub first_frame: BTreeMap<String, f64>,
    /// The dispatches in order: one, or the spread's several.
    pub each: Vec<StageDispatch>,
}

impl Dispatches {
    /// One dispatch with `values`, binding the image `pairs` names for a role
    /// (a role not named binds its own name).
    pub fn once(values: &[(&str, f64)], pairs: &[(&str, &str)]) -> Dispatches {
        Dispatches {
            values: values.iter().map(|(field, value)| (field.to_string(), *value)).collect(),
            first_frame: BTreeMap::new(),
            each: vec![StageDispatch {
                values: BTreeMap::new(),
                images: pairs.iter().map(|(role, image)| (role.to_string(), image.to_string())).collect(),
            }],
        }
    }
}

/// One dispatch of a stage's shader.
#[derive(Clone, Debug)]
pub(super) struct StageDispatch {
    /// Values for the uniform's fields, over the stage's own.
    pub values: BTreeMap<String, f64>,
    /// The image each binding role reads or writes where it is not the
    /// role's own name: `color` (the noisy colour), the pre-pass's `prepared`
    /// and `modulation`, or an image of the stage's own (`spread0`,
    /// `spread1`, `kept`), made in the format of the storage binding that
    /// first writes it.
    pub images: BTreeMap<String, String>,
}

/// An image a sequence keeps for its next frame.
#[derive(Clone, Debug)]
pub(super) struct Kept {
    /// The name the next frame's bindings read it by (`history`, `moments`…).
    pub image: String,
    /// The image of this frame it takes: a stage's output or an input.
    pub from: String,
    /// Copied right after this pass of the form (`from` is that pass's
    /// output, which a later pass overwrites); else at the end of the frame.
    pub after_pass: Option<u32>,
    pub content: String,
}

impl Placement {
    /// Nothing placed yet: the form filters the noisy colour and carries the
    /// variance its weight reads, if any.
    pub fn new(carries: Option<String>) -> Placement {
        Placement { dispatches: BTreeMap::new(), filters: "color".into(), carries, history: Vec::new() }
    }

    /// Stage `name`'s dispatches, where it is placed.
    pub fn of(&self, name: StageName) -> Option<&Dispatches> {
        self.dispatches.get(&name)
    }

    /// Put stage `name` into `manifest`, with what it changes for the stages
    /// after it: the image the form filters, the modulation it multiplies
    /// back, what a sequence keeps.
    pub fn place(
        &mut self,
        manifest: &mut Manifest,
        name: StageName,
        (stage, dispatches): (Stage, Dispatches),
        pipeline: &FilterPipeline,
    ) {
        match name {
            StageName::Prepass => self.filters = "prepared".into(),
            StageName::Spread => self.filters = "kept".into(),
            StageName::Temporal => {
                self.filters = "blend".into();
                if let Some(modulation) = manifest.bindings.iter_mut().find(|b| b.role == "modulation") {
                    modulation.image = Some("temporal_modulation");
                    modulation.content = "the temporal stage's `temporal_modulation`, multiplied back".into();
                }
                let temporal = pipeline.temporal.expect("a temporal stage where the pipeline has one");
                self.history = history(temporal);
            }
            StageName::TemporalVariance
            | StageName::Guide
            | StageName::PlaneFit
            | StageName::Anchor
            | StageName::PixelFilter => {}
        }
        *manifest.stage_mut(name) = Some(stage);
        self.dispatches.insert(name, dispatches);
    }
}

/// What a sequence keeps: the image fed back (the blend, or form pass
/// `feedback - 1`'s output), the moments and the blended modulation, and
/// the frame's surface and albedo to test the next frame's against.
fn history(temporal: Temporal) -> Vec<Kept> {
    let kept = |image: &str, from: String, after_pass, content: &str| Kept {
        image: image.into(),
        from,
        after_pass,
        content: content.into(),
    };
    let fed_back = match temporal.feedback {
        0 => kept("history", "blend".into(), None, "the blend"),
        k => kept(
            "history",
            // The form's passes write `image0`, `image1`, `image0`… (the manifest's `order`).
            format!("image{}", (k - 1) % 2),
            Some(k - 1),
            "the output of the form's pass feedback - 1 (demodulated)",
        ),
    };
    vec![
        fed_back,
        kept("moments", "moments_out".into(), None, "the luminance's moments"),
        kept("past_modulation", "temporal_modulation".into(), None, "the blended modulation"),
        kept("previous_geometry", "geometry".into(), None, "the frame's `geometry` input"),
        kept("previous_albedo", "albedo".into(), None, "the frame's `albedo` input"),
    ]
}
