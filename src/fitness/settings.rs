//! How a [`super::Scorer`] scores: one value, given once at construction.

use crate::cost::CostModel;
use crate::gpu::Gpu;
use crate::pipeline::FilterPipeline;

use super::rule::FitnessRule;
use super::tiles::TileSampling;

/// Everything a scorer is made with besides its device and scenes.
#[derive(Clone, Debug)]
pub struct Settings {
    /// The window radius expressions are scored at when they carry none.
    pub radius: u32,
    /// The pipeline around every kernel; the scenes' buffers are prepared for it.
    pub pipeline: FilterPipeline,
    /// Threads for lowering, validation and pipeline creation.
    pub threads: usize,
    /// Devices each batch is spread over: `None` gives one per thread on a
    /// software adapter (its driver compiles a pipeline at the first dispatch,
    /// on its queue's thread) and one on hardware.
    pub devices: Option<usize>,
    /// Score on fitness tiles instead of whole scenes (`None`: whole scenes).
    pub tiles: Option<FitnessTiles>,
    /// Whether fitness kernels stage their windows in workgroup memory.
    pub workgroup_tiles: Tiles,
    /// How many expressions one fitness kernel scores.
    pub fusion: Fusion,
    /// How per-scene errors become one fitness.
    pub rule: FitnessRule,
    /// The weights of the modelled cost (multi-objective searches).
    pub cost_model: CostModel,
}

impl Settings {
    /// The window form at `radius`, on whole scenes, the thesis's fitness.
    pub fn window(radius: u32, threads: usize) -> Settings {
        Settings::for_pipeline(radius, FilterPipeline::WINDOW, threads)
    }

    /// Every expression scored through `pipeline` (`radius` is the window form's).
    pub fn for_pipeline(radius: u32, pipeline: FilterPipeline, threads: usize) -> Settings {
        Settings {
            radius,
            pipeline,
            threads,
            devices: None,
            tiles: None,
            workgroup_tiles: Tiles::Auto,
            fusion: Fusion::Auto,
            rule: FitnessRule::default(),
            cost_model: CostModel::table(),
        }
    }

    /// How many devices a batch is spread over on `gpu`.
    pub fn devices_on(&self, gpu: &Gpu) -> usize {
        match self.devices {
            Some(n) => n.max(1),
            None if gpu.is_software() => self.threads.max(1),
            None => 1,
        }
    }
}

/// Fitness tiles: the cells `sampling` draws once from `seed` ([`super::tiles`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FitnessTiles {
    pub sampling: TileSampling,
    pub seed: u64,
}

/// When fitness kernels get workgroup tiles.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum Tiles {
    /// On hardware adapters; off on software ones, whose compilers make
    /// barriers expensive (`filterjit bench` shows it: docs/JOURNAL.md).
    #[default]
    Auto,
    On,
    Off,
}

impl Tiles {
    pub fn enabled(self, gpu: &Gpu) -> bool {
        match self {
            Tiles::Auto => !gpu.is_software(),
            Tiles::On => true,
            Tiles::Off => false,
        }
    }
}

/// How many individuals one fitness kernel scores. Fitness is the same
/// either way (tests/evolve.rs); only the driver's compile time differs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Fusion {
    /// [`FUSED_ON_SOFTWARE`] on software adapters, whose compile cost is per
    /// module and grows with its size more slowly than linearly; one per
    /// kernel on hardware, which compiles fast and runs each kernel apart.
    #[default]
    Auto,
    /// This many per kernel (1: a kernel per individual, the thesis's design).
    Members(usize),
}

/// Individuals per fitness kernel on software adapters, by measurement
/// (docs/JOURNAL.md, "Fused fitness kernels").
pub const FUSED_ON_SOFTWARE: usize = 12;

impl Fusion {
    pub fn members(self, gpu: &Gpu) -> usize {
        match self {
            Fusion::Auto if gpu.is_software() => FUSED_ON_SOFTWARE,
            Fusion::Auto => 1,
            Fusion::Members(n) => n.max(1),
        }
    }
}

impl std::str::FromStr for Fusion {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "auto" => Ok(Fusion::Auto),
            n => match n.parse::<usize>() {
                Ok(n) if n >= 1 => Ok(Fusion::Members(n)),
                _ => Err(format!("`{s}` is not `auto` or a number of individuals per kernel (1 or more)")),
            },
        }
    }
}
