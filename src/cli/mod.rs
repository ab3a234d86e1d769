//! The `filterjit` command line: flags (`args`) resolved into the library's
//! configuration types and calls; results printed. Errors are rendered by
//! `main`, with their whole context chain.

// One file per command (`sequence`: `filter` on a folder of frames); `args`
// holds every flag, `hints` the flag to name for a library error.
mod args;
mod bench;
mod evolve;
mod export;
mod expression;
mod filter;
mod hints;
mod list;
mod report;
mod scenes;
mod sequence;
mod tune;

pub(crate) use hints::flag_for;

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};

use filterjit::denoise::{Choice, Provided};
use filterjit::environment::Environment;
use filterjit::metrics::{self, Errors};
use filterjit::scene::{self, Absent, Request};
use filterjit::{corpus, cpu, datasets, gpu, jit, lang, preview, render, semantics};

use args::*;
pub(crate) use args::{Cli, Command};
use evolve::evolve;
use filter::{filter, refuse_radius, same_file};
use report::{report, scene_context};
use scenes::{render, sample_bar, scene_stats};

pub(crate) fn run(cli: Cli) -> Result<()> {
    let env = &Environment::read()?;
    match cli.command {
        Command::Compile { expr, output, pipeline } => expression::compile(&expr, output.as_deref(), pipeline),
        Command::Export { expr, target, format, output, pipeline, budget_ms, size } => {
            export::export(&expr, target, format, &output, pipeline, budget_ms, size)
        }
        Command::Check { expr, latex } => expression::check(&expr, latex),
        Command::Simplify { expr } => expression::simplify(&expr),
        Command::Filter { expr, radius, scene, output, read, cpu_check, pipeline } => {
            filter(env, filter::Asked { expr: expr.as_deref(), radius, read, cpu_check, pipeline }, &scene, &output)
        }
        Command::Render { scene, spp, reference_spp, size, seed, output } => {
            render(env, &scene, spp, reference_spp, size, seed, output.as_deref())
        }
        Command::Evolve(args) => evolve(env, *args),
        Command::Report(args) => report(env, *args),
        Command::Tune(args) => tune::tune(env, &args),
        Command::Bench(args) => bench::bench_command(env, *args),
        Command::Scenes { stats: false, scenes, .. } if scenes.is_empty() => scenes::list_scenes(),
        Command::Scenes { size, spp, scenes, .. } => scene_stats(env, size, spp, scenes),
        Command::List { brief } => list::list(brief),
        Command::Adapters => list::adapters(env),
    }
}

/// An expression from the command line: text, or @name of a shipped one.
pub(crate) fn resolve_expr(arg: &str) -> Result<lang::Expr> {
    Ok(corpus::resolve(arg)?.1)
}

pub(crate) fn ms(d: std::time::Duration) -> f64 {
    d.as_secs_f64() * 1e3
}
