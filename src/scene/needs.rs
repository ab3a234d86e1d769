//! What a filter reads from a render, and what a render lacks of it: the one
//! rule behind every "this render has no …" error (the CPU reference, the
//! device's input buffers, the default filter's choice, a search's seed).

use std::collections::BTreeSet;

use crate::lang::{Expr, Feature, ScalarVar};

use super::Scene;

/// One thing a filter reads that a render lacks.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Missing {
    Feature(Feature),
    Variance(ScalarVar),
    /// What the outlier pre-pass measures: only a pipeline with outliers has it.
    Measured(ScalarVar),
    /// What the temporal stage accumulates: only a pipeline with `temporal=A` has it.
    Accumulated(ScalarVar),
    /// The albedo demodulation divides by.
    Albedo,
    /// The motion vectors the temporal stage reprojects the history by.
    Motion,
}

impl Missing {
    /// The input's name (`texture` for the albedo).
    pub fn name(self) -> &'static str {
        match self {
            Missing::Feature(feature) => feature.name(),
            Missing::Variance(v) | Missing::Measured(v) | Missing::Accumulated(v) => v.name(),
            Missing::Albedo => Feature::Texture.name(),
            Missing::Motion => "motion vectors",
        }
    }

    /// Why a render may lack it, where that is not plain.
    fn note(self) -> Option<&'static str> {
        match self {
            Missing::Measured(_) => Some("what the outlier pre-pass measures: a pipeline with `outliers=k` has it"),
            Missing::Accumulated(_) => {
                Some("what the temporal stage accumulates over a sequence: a pipeline with `temporal=A` has it")
            }
            Missing::Albedo => Some("the albedo `demodulate` divides by"),
            Missing::Motion => Some(
                "the temporal stage reprojects the frame before by them: Blender's Vector pass, or `Vector.X`/`Vector.Y` \
                 channels (docs/SCENES.md)",
            ),
            Missing::Feature(_) | Missing::Variance(_) => None,
        }
    }

    /// The name quoted, with its note: for messages.
    pub fn quoted(self) -> String {
        match self.note() {
            Some(note) => format!("`{}` ({note})", self.name()),
            None => format!("`{}`", self.name()),
        }
    }
}

/// The name with its note, unquoted: `texture (the albedo `demodulate` divides by)`.
impl std::fmt::Display for Missing {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.note() {
            Some(note) => write!(f, "{} ({note})", self.name()),
            None => f.write_str(self.name()),
        }
    }
}

/// A data error: a scene lacks an input its filter reads.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("scene `{scene}` has no {}, which the filter reads", missing.quoted())]
pub struct MissingInput {
    pub scene: String,
    pub missing: Missing,
}

/// What a filter reads from a render besides its colour.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Needs {
    /// Stored features and gradients (never the pixel position).
    pub features: BTreeSet<Feature>,
    /// Per-pixel sample variances.
    pub variances: BTreeSet<ScalarVar>,
    /// What the outlier pre-pass measures.
    pub measured: BTreeSet<ScalarVar>,
    /// What the temporal stage accumulates.
    pub accumulated: BTreeSet<ScalarVar>,
    /// The albedo, where the pipeline demodulates.
    pub albedo: bool,
    /// The motion vectors, where the pipeline has a temporal stage.
    pub motion: bool,
}

/// What a render holds, as [`Needs::missing`] compares it.
#[derive(Clone, Copy, Debug)]
pub struct Holds<'a> {
    pub features: &'a BTreeSet<Feature>,
    pub variances: &'a BTreeSet<ScalarVar>,
    /// Whether the outlier pre-pass's measures are there (a pipeline with
    /// outliers); without, only those among `variances` are.
    pub measured: bool,
    /// Whether the temporal stage's measures are there (a temporal
    /// pipeline); without, only those among `variances` are.
    pub accumulated: bool,
    pub albedo: bool,
    pub motion: bool,
}

impl Needs {
    /// What `expr` reads; `demodulate`: whether its pipeline divides by the albedo.
    pub fn of(expr: &Expr, demodulate: bool) -> Needs {
        let variables = expr.bound_variables();
        Needs {
            features: expr.features().into_iter().filter(|f| f.needs_data()).collect(),
            variances: variables.iter().copied().filter(|v| !v.from_pipeline()).collect(),
            measured: variables.iter().copied().filter(|v| v.from_prepass()).collect(),
            accumulated: variables.into_iter().filter(|v| v.from_temporal()).collect(),
            albedo: demodulate,
            motion: false,
        }
    }

    /// What `expr` reads in `pipeline`: its own needs, the albedo where the
    /// pipeline demodulates, and what the pipeline's stages read themselves
    /// (the normal, for `keep=surface`; the normal, depth and motion vectors
    /// for the temporal stage).
    pub fn of_filter(expr: &Expr, pipeline: &crate::pipeline::FilterPipeline) -> Needs {
        let mut needs = Needs::of(expr, pipeline.demodulate);
        needs.features.extend(pipeline.features());
        needs.motion = pipeline.is_temporal();
        needs
    }

    /// Everything these needs ask that `holds` lacks, in a fixed order.
    pub fn missing(&self, holds: Holds<'_>) -> Vec<Missing> {
        let mut out: Vec<Missing> = self.features.difference(holds.features).map(|f| Missing::Feature(*f)).collect();
        out.extend(self.variances.difference(holds.variances).map(|v| Missing::Variance(*v)));
        if !holds.measured {
            out.extend(self.measured.difference(holds.variances).map(|v| Missing::Measured(*v)));
        }
        if !holds.accumulated {
            out.extend(self.accumulated.difference(holds.variances).map(|v| Missing::Accumulated(*v)));
        }
        if self.albedo && !holds.albedo && !out.contains(&Missing::Feature(Feature::Texture)) {
            out.push(Missing::Albedo);
        }
        if self.motion && !holds.motion {
            out.push(Missing::Motion);
        }
        out
    }

    /// The first input `scene` lacks, as a data error. `pipeline`: the
    /// filter's, whose stages may make what the outlier pre-pass and the
    /// temporal stage measure (without them, a scene may hold those among
    /// its variances, as the CPU reference's stages and test scenes do).
    pub fn check(&self, scene: &Scene, pipeline: &crate::pipeline::FilterPipeline) -> Result<(), MissingInput> {
        let features: BTreeSet<Feature> =
            Feature::ALL.iter().copied().filter(|f| scene.feature(*f).is_some()).collect();
        let variances: BTreeSet<ScalarVar> =
            ScalarVar::ALL.iter().copied().filter(|v| scene.variance(*v).is_some()).collect();
        let holds = Holds {
            features: &features,
            variances: &variances,
            measured: pipeline.outliers.is_some(),
            accumulated: pipeline.is_temporal(),
            albedo: scene.albedo.is_some(),
            motion: scene.motion.is_some(),
        };
        match self.missing(holds).into_iter().next() {
            None => Ok(()),
            Some(missing) => Err(MissingInput { scene: scene.name.clone(), missing }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lang::parse_expr;

    #[test]
    fn needs_name_what_is_absent_in_order() {
        let e = parse_expr("distance2(normal) + colorVariance + localMean + distance2(pixel)").unwrap();
        let needs = Needs::of(&e, true);
        assert!(!needs.features.contains(&Feature::Pixel), "the pixel position is no input");
        let (none, none_v) = (BTreeSet::new(), BTreeSet::new());
        let holds = Holds {
            features: &none,
            variances: &none_v,
            measured: false,
            accumulated: false,
            albedo: false,
            motion: false,
        };
        assert_eq!(
            needs.missing(holds),
            [
                Missing::Feature(Feature::Normal),
                Missing::Variance(ScalarVar::ColorVariance),
                Missing::Measured(ScalarVar::LocalMean),
                Missing::Albedo
            ]
        );
        let normal = BTreeSet::from([Feature::Normal]);
        let colour = BTreeSet::from([ScalarVar::ColorVariance]);
        let all = Holds {
            features: &normal,
            variances: &colour,
            measured: true,
            accumulated: true,
            albedo: true,
            motion: true,
        };
        assert!(needs.missing(all).is_empty());
    }
}
