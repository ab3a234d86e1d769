//! The frame an exported pipeline runs, as data: every dispatch and copy in
//! order with the image each binding uses ([`Step`]), and the images the
//! pipeline makes ([`Image`]). A host walks `frame` and needs no rule of its
//! own about which stage runs when or which image a pass reads.

use std::collections::BTreeMap;

use super::placement::Placement;
use super::{Binding, BindingKind, Dispatch, Image, Manifest, StageName, Step};
use crate::jit::interface::UniformField;

/// The manifest's shader name for the form's.
const FORM: &str = "form";

/// The steps of one frame, the images they make, and the image that holds
/// the filtered frame at the end, for `manifest` once every stage is placed
/// (`placement`) and its inputs known.
pub(super) fn plan(manifest: &Manifest, placement: &Placement) -> (Vec<Step>, Vec<Image>, String) {
    let mut plan = Plan { steps: Vec::new(), images: Vec::new(), manifest, placement };
    for name in
        [StageName::Prepass, StageName::Spread, StageName::Temporal, StageName::TemporalVariance, StageName::Guide]
    {
        plan.stage(name, None);
    }
    let mut colour = plan.form();
    if plan.stage(StageName::PlaneFit, Some(&colour)) {
        colour = "fitted".into();
    }
    if plan.stage(StageName::Anchor, Some(&colour)) {
        colour = "anchored".into();
    }
    if plan.stage(StageName::PixelFilter, Some(&colour)) {
        colour = "pixelfiltered".into();
    }
    plan.keep(None);
    let Plan { steps, mut images, .. } = plan;
    for kept in &placement.history {
        images.push(Image {
            name: kept.image.clone(),
            format: None,
            written_by: None,
            kept_from: Some(kept.from.clone()),
            content: kept.content.clone(),
        });
    }
    (steps, images, colour)
}

struct Plan<'m> {
    steps: Vec<Step>,
    images: Vec<Image>,
    manifest: &'m Manifest,
    placement: &'m Placement,
}

impl Plan<'_> {
    /// Stage `name`'s dispatches, where the manifest has the stage; `filtered`
    /// is the image the name `filtered` stands for (the form's last output).
    /// Whether it has.
    fn stage(&mut self, name: StageName, filtered: Option<&str>) -> bool {
        let (Some(stage), Some(dispatches)) = (self.manifest.stage(name), self.placement.of(name)) else {
            return false;
        };
        for dispatch in &dispatches.each {
            let mut values = dispatches.values.clone();
            values.extend(dispatch.values.clone());
            let images = dispatch
                .images
                .iter()
                .map(|(role, image)| {
                    let image = match (image.as_str(), filtered) {
                        ("filtered", Some(last)) => last.to_string(),
                        _ => image.clone(),
                    };
                    (role.clone(), image)
                })
                .collect();
            let first_frame = dispatches.first_frame.clone();
            self.dispatch(name.key(), (&stage.uniform.fields, &stage.bindings), values, first_frame, images);
        }
        true
    }

    /// The form's passes, each followed by what a sequence keeps of it; the
    /// image the last one writes.
    fn form(&mut self) -> String {
        let manifest = self.manifest;
        let form = (&manifest.uniform.fields[..], &manifest.bindings[..]);
        let mut colour = self.placement.filters.clone();
        // The variance the passes carry, where the weight reads one: pass 0 binds the frame's.
        let carried = self.placement.carries.clone();
        let mut variance = carried.clone();
        for k in 0..manifest.passes {
            let (out, variance_out) = (format!("image{}", k % 2), format!("variance{}", k % 2));
            let values = [
                ("radius", manifest.radius.unwrap_or(0) as f64),
                ("step", (1u64 << k) as f64),
                ("level", k as f64),
                ("last", if k + 1 == manifest.passes { 1.0 } else { 0.0 }),
            ];
            let mut images: BTreeMap<String, String> = [
                ("color", colour.clone()),
                ("output", out.clone()),
                ("variance_out", variance_out.clone()),
                // The guide stage's in pass 0, the pass's own colour after.
                ("guide", if k == 0 { "guide".to_string() } else { colour.clone() }),
            ]
            .map(|(role, image)| (role.to_string(), image))
            .into();
            if let (Some(role), Some(image)) = (&carried, &variance) {
                images.insert(role.clone(), image.clone());
            }
            let values = values.map(|(field, value)| (field.to_string(), value)).into();
            self.dispatch(FORM, form, values, BTreeMap::new(), images);
            // The pass the temporal stage feeds back, kept before a later pass writes its texture again.
            self.keep(Some(k));
            colour = out;
            variance = carried.as_ref().map(|_| variance_out);
        }
        colour
    }

    /// One dispatch of `shader`, whose uniform has `fields` and which has
    /// `bindings`: every texture binding's image (the one `images` names for
    /// its role, else the binding's own `image`, else its role), and the
    /// fields of `values` the uniform has.
    fn dispatch(
        &mut self,
        shader: &str,
        (fields, bindings): (&[UniformField], &[Binding]),
        values: BTreeMap<String, f64>,
        first_frame: BTreeMap<String, f64>,
        images: BTreeMap<String, String>,
    ) {
        let has_field = |name: &String| fields.iter().any(|f| &f.name == name);
        let mut bound = BTreeMap::new();
        for binding in bindings.iter().filter(|b| b.kind != BindingKind::Uniform) {
            let image = images.get(&binding.role).cloned().or(binding.image.map(str::to_string));
            let mut image = image.unwrap_or_else(|| binding.role.clone());
            // An input the pipeline does not read (the albedo of a pre-pass that
            // does not demodulate) is bound to the colour: any texture will do.
            if self.unsupplied(&image) {
                image = "color".into();
            }
            if binding.kind == BindingKind::StorageTexture && !self.images.iter().any(|i| i.name == image) {
                self.images.push(Image {
                    name: image.clone(),
                    format: binding.format,
                    written_by: Some(shader.to_string()),
                    kept_from: None,
                    content: what_it_holds(&image, &binding.content),
                });
            }
            bound.insert(binding.role.clone(), image);
        }
        self.steps.push(Step::Dispatch(Dispatch {
            shader: shader.to_string(),
            values: values.into_iter().filter(|(field, _)| has_field(field)).collect(),
            first_frame,
            images: bound,
        }));
    }

    /// Whether `image` names an engine input the manifest does not ask for.
    fn unsupplied(&self, image: &str) -> bool {
        image == "albedo" && !self.manifest.inputs.iter().any(|input| input.image == image)
    }

    /// What a sequence keeps right after form pass `after_pass`, or at the end of the frame.
    fn keep(&mut self, after_pass: Option<u32>) {
        for kept in self.placement.history.iter().filter(|k| k.after_pass == after_pass) {
            self.steps.push(Step::Keep { from: kept.from.clone(), into: kept.image.clone() });
        }
    }
}

/// The channels of `image` that some dispatch of `manifest`'s frame reads,
/// in `xyzw` order: the union of the components of every binding it is bound to.
pub(super) fn components_read(manifest: &Manifest, image: &str) -> String {
    let mut read = [false; 4];
    for step in &manifest.frame {
        let Step::Dispatch(dispatch) = step else { continue };
        let bindings = match dispatch.shader.as_str() {
            FORM => &manifest.bindings,
            key => match StageName::ALL.iter().find(|name| name.key() == key).and_then(|name| manifest.stage(*name)) {
                Some(stage) => &stage.bindings,
                None => continue,
            },
        };
        for (role, bound) in &dispatch.images {
            let Some(binding) = bindings.iter().find(|b| &b.role == role) else { continue };
            if bound == image && binding.kind == BindingKind::SampledTexture {
                for (k, channel) in "xyzw".chars().enumerate() {
                    read[k] |= binding.components.contains(channel);
                }
            }
        }
    }
    "xyzw".chars().zip(read).filter(|(_, r)| *r).map(|(c, _)| c).collect()
}

/// What image `image` holds: its writing binding's `content` without how it
/// is written (`images` gives the format), except where one binding writes
/// several images (the spread's `output`, the form's passes).
fn what_it_holds(image: &str, content: &str) -> String {
    let named = match image {
        "spread0" | "spread1" => "the spread so far, read by its next dispatch",
        "kept" => "the colour the form filters: the clamped colour with what the clamp removed handed back",
        "surface" => "each pixel's normal direction and clamped luminance, for the spread along the surface",
        "total" => "texel (0, 0): the clamped luminance summed over the frame, for the spread along the surface",
        "image0" | "image1" => "the output of a form pass (pass k writes `image{k mod 2}`)",
        "variance0" | "variance1" => "the variance a form pass carries to the next (pass k writes `variance{k mod 2}`)",
        _ => "",
    };
    if !named.is_empty() {
        return named.to_string();
    }
    let cut = [", written with textureStore", "; written with textureStore", "; format "]
        .iter()
        .filter_map(|tail| content.find(tail))
        .min()
        .unwrap_or(content.len());
    content[..cut].to_string()
}
