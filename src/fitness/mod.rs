//! Scoring: the fitness of expressions on scenes, on the device.
//!
//! A [`Scorer`] is made once from a device, scenes with references and one
//! [`Settings`] value; it compiles each batch of expressions into fitness
//! kernels ([`batch`]: fused where the device benefits, member by member
//! where a group fails), spreads them over devices, and reduces each
//! kernel's per-pixel terms to one relMSE (and output luminance) per scene. Fitness tiles
//! ([`tiles`]) and their pooling ([`pool`]) and the rule that turns per-scene
//! errors into one number ([`rule`]) are pure functions, tested without a
//! device. Why a candidate has no fitness is data ([`Invalid`]); `gp` sees it
//! as text only through [`crate::gp::Evaluator`].

mod batch;
mod invalid;
mod pool;
pub mod rule;
mod scorer;
mod settings;
pub mod tiles;

pub use invalid::Invalid;
pub use rule::{charged, FitnessRule, Pool};
pub use scorer::{domain_flags, normalised_error, ScoredErrors, Scorer};
pub use settings::{FitnessTiles, Fusion, Settings, Tiles, FUSED_ON_SOFTWARE};
pub use tiles::TileSampling;
