//! One integration-test binary, a module per area (keeps link times down).

mod common;

mod architecture;
mod blender;
mod browser;
mod cli;
mod distributed;
mod evolve;
mod export;
mod flip;
mod gpu_vs_cpu;
mod lang;
mod pipeline;
mod readme;
mod render;
mod report;
mod scenes;
mod simplify;
mod snapshots;
mod stability;
mod temporal;
