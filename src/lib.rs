//! filterjit: filter-weight expressions compiled into specialised WGSL
//! compute kernels, for removing Monte Carlo noise from rendered images.
//!
//! The stages, each its own module (see ARCHITECTURE.md):
//! text → [`lang::parse`] → [`lang::check`] → [`jit::lower`] → [`jit::validate`] → [`gpu::Gpu::pipeline`].

pub mod bench;
pub mod corpus;
pub mod cost;
pub mod cpu;
pub mod datasets;
pub mod denoise;
pub mod environment;
pub mod evolve;
pub mod export;
pub mod fitness;
pub mod flip;
pub mod gp;
pub mod gpu;
pub mod io;
pub mod jit;
pub mod lang;
pub mod metrics;
pub mod named;
pub mod oidn;
pub mod parallel;
pub mod pipeline;
pub mod preview;
pub mod render;
pub mod report;
pub mod rng;
pub mod scene;
pub mod semantics;
pub mod simplify;
pub mod spelling;
pub mod tune;

pub use jit::{compile, ValidatedKernel};
pub use lang::{parse_expr, Expr, ExprError};
pub use scene::Scene;
