//! What a run is made of besides the GP settings; kept in its checkpoint, so
//! a resumed run must match it.

use std::collections::BTreeSet;

use serde::{Deserialize, Serialize};

use crate::fitness::{self, FitnessRule, Fusion, TileSampling, Tiles};
use crate::pipeline::FilterPipeline;
use crate::render::RenderSettings;

/// The run's inputs besides the GP settings; a resumed run must match them.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunConfig {
    pub training: Vec<String>,
    pub test: Vec<String>,
    pub render: RenderSettings,
    pub radius: u32,
    pub seed_expr: String,
    /// The pipeline every individual is scored through (runs made before pipelines existed: `window`).
    #[serde(default)]
    pub pipeline: FilterPipeline,
    /// The weights of the modelled cost a multi-objective search trades
    /// against error (runs made before it existed: the operator table's).
    #[serde(default)]
    pub cost_model: crate::cost::CostModel,
    /// Fitness on tiles of each training scene instead of whole images
    /// ([`crate::fitness::tiles`]; runs made before tiles existed: whole images).
    #[serde(default)]
    pub fitness_tiles: Option<TileSampling>,
    /// Only these features and variances are terminals (all the training
    /// scenes provide when `None`): a filter meant for renders with fewer
    /// channels than the training scenes must not learn to read the others.
    /// By name, as written in expressions.
    #[serde(default)]
    pub features: Option<BTreeSet<String>>,
    /// How per-scene errors become the training fitness (runs made before
    /// it existed: the thesis's mean of relMSE / noisy relMSE).
    #[serde(default)]
    pub fitness: FitnessRule,
}

impl RunConfig {
    /// What the training fitness in the log and the hall of fame is measured on.
    pub fn scored_on(&self) -> String {
        match self.fitness_tiles {
            None => self.scored_on_whole_images(),
            Some(t) => {
                format!("{} tiles of {}x{} pixels per training scene{}", t.count, t.size, t.size, self.rule_note())
            }
        }
    }

    /// How the run scores on whole images (`fitness_tiles` is the caller's: the draw needs the GP seed).
    pub fn scoring(&self, threads: usize, workgroup_tiles: Tiles, fusion: Fusion) -> fitness::Settings {
        fitness::Settings {
            workgroup_tiles,
            fusion,
            rule: self.fitness.clone(),
            cost_model: self.cost_model.clone(),
            // A temporal pipeline's frames come with its pre-pass and stage already run (`datasets::accumulated`).
            ..fitness::Settings::for_pipeline(self.radius, self.pipeline.spatial(), threads)
        }
    }

    /// What the hall of fame's rescoring is measured on.
    pub fn scored_on_whole_images(&self) -> String {
        format!("whole training images{}", self.rule_note())
    }

    /// The fitness rule where it is not the thesis's.
    fn rule_note(&self) -> String {
        if self.fitness.is_thesis() {
            String::new()
        } else {
            format!("; {}", self.fitness.describe())
        }
    }
}
