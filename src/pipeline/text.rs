//! The pipeline's text form: `outliers=2,demodulate,atrous=5` parsed with
//! every stage's rule checked and a message naming what is wrong, and
//! printed canonically (`parse(print(p)) == p`), which runs, halls of fame
//! and `tune` store.

use std::fmt;
use std::str::FromStr;

use super::{
    Anchor, FilterPipeline, Form, Keep, Outliers, PixelFilter, PlaneFit, Stencil, Temporal, MAX_ANCHOR_GATE,
    MAX_ATROUS_PASSES, MAX_PIXEL_FILTER_SIGMA, MAX_PLANEFIT_RADIUS, TEMPORAL_MAX_ALPHA,
};

/// Text that is not a pipeline.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("pipeline `{text}`: {message} (write stages separated by commas, e.g. `outliers=2,demodulate,atrous=5` or `window`)")]
pub struct PipelineError {
    pub text: String,
    pub message: String,
}

/// Every stage's name, in the order a pipeline writes them.
const STAGE_NAMES: [&str; 14] = [
    "outliers",
    "trim",
    "keep",
    "demodulate",
    "temporal",
    "feedback",
    "clamp",
    "antilag",
    "window",
    "atrous",
    "atrous3x3",
    "planefit",
    "anchor",
    "pixelfilter",
];

/// The message for a stage name no stage has, with the nearest one where it is a slip.
fn unknown_stage(name: &str) -> String {
    let nearest =
        crate::spelling::nearest(name, STAGE_NAMES).map(|n| format!(" (did you mean `{n}`?)")).unwrap_or_default();
    format!(
        "unknown stage `{name}`{nearest}; the stages are outliers=K, trim, keep, keep=surface, demodulate, temporal=A, \
         feedback=K, clamp=G, antilag=K, window, atrous=N, atrous3x3=N, planefit=R, anchor=K, pixelfilter=S"
    )
}

impl FromStr for FilterPipeline {
    type Err = PipelineError;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        let error = |message: String| PipelineError { text: text.to_string(), message };
        let mut pipeline = FilterPipeline::WINDOW;
        let mut form_seen = false;
        // `feedback=K` as written, checked against the form once it is known.
        let mut feedback: Option<u32> = None;
        for stage in text.split(',').map(str::trim) {
            let (name, value) = match stage.split_once('=') {
                Some((n, v)) => (n.trim(), Some(v.trim())),
                None => (stage, None),
            };
            // A name no stage has is named as such before any rule of order.
            if !STAGE_NAMES.contains(&name) {
                return Err(error(unknown_stage(name)));
            }
            if form_seen && !["planefit", "anchor", "pixelfilter"].contains(&name) {
                return Err(error(format!(
                    "`{stage}` comes after the form; only `planefit=R`, `anchor=K` and `pixelfilter=S` follow the \
                     form (window or atrous)"
                )));
            }
            if pipeline.pixel_filter.is_some() {
                return Err(error(format!("`{stage}` comes after `pixelfilter=S`, which is the last stage")));
            }
            match (name, value) {
                ("pixelfilter", Some(v)) => {
                    let sigma: f32 =
                        v.parse().map_err(|_| error(format!("pixelfilter={v}: σ must be a number of pixels")))?;
                    if !(sigma > 0.0 && sigma <= MAX_PIXEL_FILTER_SIGMA) {
                        return Err(error(format!(
                            "pixelfilter={v}: σ must be above 0 and at most {MAX_PIXEL_FILTER_SIGMA} pixels"
                        )));
                    }
                    if !form_seen {
                        return Err(error("`pixelfilter=S` comes after the form (window or atrous)".into()));
                    }
                    pipeline.pixel_filter = Some(PixelFilter { sigma });
                }
                ("pixelfilter", None) => {
                    return Err(error("`pixelfilter` needs its σ in pixels: pixelfilter=S".into()))
                }
                ("anchor", Some(v)) => {
                    let gate: f32 =
                        v.parse().map_err(|_| error(format!("anchor={v}: K must be a number of standard errors")))?;
                    if !(gate > 0.0 && gate <= MAX_ANCHOR_GATE) {
                        return Err(error(format!(
                            "anchor={v}: K must be above 0 and at most {MAX_ANCHOR_GATE} standard errors"
                        )));
                    }
                    if !form_seen {
                        return Err(error("`anchor=K` comes after the form (window or atrous)".into()));
                    }
                    if pipeline.anchor.is_some() {
                        return Err(error("`anchor` appears once".into()));
                    }
                    pipeline.anchor = Some(Anchor { gate });
                }
                ("anchor", None) => {
                    return Err(error("`anchor` needs its gate in standard errors: anchor=K (2 is shipped)".into()))
                }
                ("planefit", Some(v)) => {
                    let radius: u32 =
                        v.parse().map_err(|_| error(format!("planefit={v}: the radius must be a whole number")))?;
                    if !(1..=MAX_PLANEFIT_RADIUS).contains(&radius) {
                        return Err(error(format!("planefit={v}: the radius must be from 1 to {MAX_PLANEFIT_RADIUS}")));
                    }
                    if !form_seen {
                        return Err(error("`planefit=R` comes after the form (window or atrous)".into()));
                    }
                    if pipeline.planefit.is_some() {
                        return Err(error("`planefit` appears once".into()));
                    }
                    if pipeline.anchor.is_some() {
                        return Err(error("`planefit=R` comes before `anchor=K`".into()));
                    }
                    pipeline.planefit = Some(PlaneFit { radius });
                }
                ("planefit", None) => return Err(error("`planefit` needs its radius: planefit=R".into())),
                ("outliers", Some(v)) => {
                    let k: f32 = v.parse().map_err(|_| error(format!("outliers={v}: k must be a number")))?;
                    if !(k.is_finite() && k >= 0.0) {
                        return Err(error(format!("outliers={v}: k must be finite and at least 0")));
                    }
                    if pipeline.outliers.is_some() || pipeline.demodulate || pipeline.temporal.is_some() {
                        return Err(error("`outliers` is the first stage, and appears once".into()));
                    }
                    pipeline.outliers = Some(Outliers { k, trim: false, keep: None });
                }
                ("trim", None) => match &mut pipeline.outliers {
                    Some(outliers)
                        if !outliers.trim
                            && outliers.keep.is_none()
                            && !pipeline.demodulate
                            && pipeline.temporal.is_none() =>
                    {
                        outliers.trim = true
                    }
                    Some(_) => return Err(error("`trim` comes once, right after `outliers=K`".into())),
                    None => {
                        return Err(error("`trim` changes the rule of `outliers=K`: write it after outliers=K".into()))
                    }
                },
                ("keep", None | Some("surface")) => match &mut pipeline.outliers {
                    Some(outliers)
                        if outliers.keep.is_none() && !pipeline.demodulate && pipeline.temporal.is_none() =>
                    {
                        outliers.keep = Some(if value.is_some() { Keep::Surface } else { Keep::Even })
                    }
                    Some(_) => return Err(error("`keep` comes once, right after `outliers=K` (and `trim`)".into())),
                    None => {
                        return Err(error(
                            "`keep` puts back what `outliers=K` removes: write it after outliers=K".into(),
                        ))
                    }
                },
                ("keep", Some(v)) => return Err(error(format!("keep={v}: write `keep` (evenly) or `keep=surface`"))),
                ("temporal", Some(v)) => {
                    let alpha: f32 =
                        v.parse().map_err(|_| error(format!("temporal={v}: the blend's α_min must be a number")))?;
                    if !(alpha > 0.0 && alpha <= TEMPORAL_MAX_ALPHA) {
                        return Err(error(format!(
                            "temporal={v}: α_min must be above 0 and at most {TEMPORAL_MAX_ALPHA}"
                        )));
                    }
                    if pipeline.temporal.is_some() {
                        return Err(error("`temporal` appears once".into()));
                    }
                    pipeline.temporal = Some(Temporal { alpha, feedback: 0, clamp: None, antilag: None });
                }
                ("temporal", None) => {
                    return Err(error("`temporal` needs its α_min, the least share of a frame: temporal=A".into()))
                }
                ("feedback", Some(v)) => {
                    let passes: u32 =
                        v.parse().map_err(|_| error(format!("feedback={v}: the passes must be a whole number")))?;
                    match pipeline.temporal {
                        Some(_) if feedback.is_none() => feedback = Some(passes),
                        Some(_) => return Err(error("`feedback` appears once".into())),
                        None => {
                            return Err(error(
                                "`feedback=K` says which pass the temporal stage keeps: write it after temporal=A"
                                    .into(),
                            ))
                        }
                    }
                }
                ("clamp", Some(v)) => {
                    let gamma: f32 = v.parse().map_err(|_| error(format!("clamp={v}: γ must be a number")))?;
                    if !(gamma.is_finite() && gamma > 0.0) {
                        return Err(error(format!("clamp={v}: γ must be finite and above 0")));
                    }
                    match &mut pipeline.temporal {
                        Some(temporal) if temporal.clamp.is_none() => temporal.clamp = Some(gamma),
                        Some(_) => return Err(error("`clamp` appears once".into())),
                        None => {
                            return Err(error(
                                "`clamp=G` clamps the temporal stage's history: write it after temporal=A".into(),
                            ))
                        }
                    }
                }
                ("antilag", Some(v)) => {
                    let kappa: f32 = v.parse().map_err(|_| error(format!("antilag={v}: κ must be a number")))?;
                    if !(kappa.is_finite() && kappa > 0.0) {
                        return Err(error(format!("antilag={v}: κ must be finite and above 0")));
                    }
                    match &mut pipeline.temporal {
                        Some(temporal) if temporal.antilag.is_none() => temporal.antilag = Some(kappa),
                        Some(_) => return Err(error("`antilag` appears once".into())),
                        None => {
                            return Err(error(
                                "`antilag=K` cuts the temporal stage's history where the light changed: write it after temporal=A"
                                    .into(),
                            ))
                        }
                    }
                }
                ("feedback" | "clamp" | "antilag", None) => {
                    return Err(error(format!("`{name}` needs its value: {name}=N")));
                }
                ("outliers", None) => return Err(error("`outliers` needs its strength: outliers=K".into())),
                ("demodulate", None) => {
                    if pipeline.demodulate {
                        return Err(error("`demodulate` appears twice".into()));
                    }
                    if pipeline.temporal.is_some() {
                        return Err(error("`demodulate` comes before `temporal`: the history is demodulated".into()));
                    }
                    pipeline.demodulate = true;
                }
                ("window", None) => {
                    pipeline.form = Form::Window;
                    form_seen = true;
                }
                ("atrous" | "atrous3x3", Some(v)) => {
                    let stencil = if name == "atrous" { Stencil::Cubic5 } else { Stencil::Linear3 };
                    let passes: u32 =
                        v.parse().map_err(|_| error(format!("{name}={v}: passes must be a whole number")))?;
                    if !(1..=MAX_ATROUS_PASSES).contains(&passes) {
                        return Err(error(format!("{name}={v}: passes must be from 1 to {MAX_ATROUS_PASSES}")));
                    }
                    pipeline.form = Form::Atrous { passes, stencil };
                    form_seen = true;
                }
                ("atrous" | "atrous3x3", None) => {
                    return Err(error(format!("`{name}` needs its number of passes: {name}=N")))
                }
                (other, _) => return Err(error(unknown_stage(other))),
            }
        }
        if !form_seen {
            return Err(error("no form: end with `window`, `atrous=N` or `atrous3x3=N`".into()));
        }
        let most = pipeline.most_feedback();
        if let Some(temporal) = &mut pipeline.temporal {
            temporal.feedback = match feedback {
                Some(k) if k > most => {
                    return Err(error(format!(
                        "feedback={k}: the history is a demodulated image after at most {most} passes of this form{}",
                        if most < pipeline.passes() { " (its last pass multiplies the albedo back)" } else { "" }
                    )))
                }
                Some(k) => k,
                // SVGF's: the first pass's output.
                None => most.min(1),
            };
        }
        Ok(pipeline)
    }
}

impl fmt::Display for FilterPipeline {
    /// The canonical text: `parse(print(p)) == p`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if let Some(Outliers { k, trim, keep }) = self.outliers {
            write!(f, "outliers={k},")?;
            if trim {
                write!(f, "trim,")?;
            }
            if let Some(keep) = keep {
                write!(f, "{},", keep.text())?;
            }
        }
        if self.demodulate {
            write!(f, "demodulate,")?;
        }
        if let Some(Temporal { alpha, feedback, clamp, antilag }) = self.temporal {
            write!(f, "temporal={alpha},feedback={feedback},")?;
            if let Some(gamma) = clamp {
                write!(f, "clamp={gamma},")?;
            }
            if let Some(kappa) = antilag {
                write!(f, "antilag={kappa},")?;
            }
        }
        match self.form {
            Form::Window => write!(f, "window")?,
            Form::Atrous { passes, stencil } => write!(f, "{}={passes}", stencil.stage_name())?,
        }
        if let Some(PlaneFit { radius }) = self.planefit {
            write!(f, ",planefit={radius}")?;
        }
        if let Some(Anchor { gate }) = self.anchor {
            write!(f, ",anchor={gate}")?;
        }
        if let Some(PixelFilter { sigma }) = self.pixel_filter {
            write!(f, ",pixelfilter={sigma}")?;
        }
        Ok(())
    }
}

impl serde::Serialize for FilterPipeline {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&self.to_string())
    }
}

impl<'de> serde::Deserialize<'de> for FilterPipeline {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let text = String::deserialize(d)?;
        text.parse().map_err(serde::de::Error::custom)
    }
}
