//! `filterjit evolve`: the GP engine wired to scenes and to the device
//! scorer ([`crate::fitness`]); the run checkpoints every generation.
//!
//! `run_with` is the run; the run directory's files (`run_dir`), the hall of
//! fame (`hall`), the front (`front`) and the test results (`results`) are
//! each a file of their own.

mod config;
mod front;
mod hall;
mod results;
mod run_dir;

use std::collections::BTreeSet;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};

pub use config::RunConfig;
pub use front::{time_filters, Front, FrontMember, FRONT_FILE, FRONT_TIMING_SIDE};
pub use hall::{hall_of_fame, Rescored};
pub use results::{mean_light, test, test_each, BaselineResult, Summary, TestResult};
pub use run_dir::{
    append_log, default_run_dir, log_upto, read_checkpoint, write_checkpoint, Checkpoint, RunDirError, CHECKPOINT_FILE,
    DEFAULT_RUN_DIR, FEATURES_FILE, HALL_OF_FAME_FILE, LOG_FILE, SUMMARY_FILE,
};

use crate::datasets;
use crate::fitness::{self, FitnessTiles, Fusion, Scorer, Tiles};
use crate::gp::transport::{InProcess, Transport};
use crate::gp::{self, Settings, State};
use crate::gpu::Gpu;
use crate::lang::{Expr, Feature, ScalarVar};
use crate::pipeline::FilterPipeline;
use crate::render;
use crate::scene::{Holds, Needs};

/// Why a run's terminals cannot be what its configuration asks: domain facts
/// (the command line names its flags).
#[derive(Debug, thiserror::Error)]
pub enum TerminalError {
    #[error("the allowed terminals name `{0}`, which is no feature or variance")]
    Unknown(String),
    #[error("the allowed terminals name `{0}`, which the outlier pre-pass measures, but the pipeline has no outlier stage (`outliers=K`)")]
    NeedsOutliers(String),
    #[error("the allowed terminals name `{0}`, which the temporal stage measures, but the pipeline has no temporal stage (`temporal=A`)")]
    NeedsTemporal(String),
    #[error("the allowed terminals name `{0}`, which the training scenes do not all provide")]
    NotProvided(String),
    #[error("the seed expression reads `{0}`, which the training scenes do not all provide")]
    SeedReads(String),
}

/// A filter the run compares its best with on the test scenes.
#[derive(Clone, Debug)]
pub struct Baseline {
    /// What the user called it (`@svgf`, a file): errors and the test's table name it so.
    pub name: String,
    pub expr: Expr,
    /// Its own pipeline, where it has one; else it runs through the run's.
    pub pipeline: Option<FilterPipeline>,
}

/// Everything `run` needs.
pub struct RunOptions<'a> {
    pub settings: Settings,
    pub config: RunConfig,
    pub output: PathBuf,
    pub resume: bool,
    pub threads: usize,
    /// Stop after this many generations in this process (for tests of resuming); `None` runs to the end.
    pub stop_after: Option<u32>,
    pub on_report: &'a mut dyn FnMut(&gp::Report),
    pub on_render: render::Progress<'a>,
    /// Filters to compare with on the test scenes (they do not affect the
    /// search): each through its own pipeline where it has one (a shipped
    /// filter's), else through the run's.
    pub baselines: Vec<Baseline>,
    /// Whether fitness kernels stage their windows in workgroup memory
    /// (results are identical either way; only the time differs).
    pub tiles: Tiles,
    /// How many individuals each fitness kernel scores (identical results).
    pub fusion: Fusion,
    /// Where built-in and .toml scenes are rendered to and found again.
    pub cache: PathBuf,
}

/// Run (or resume) a search in this process; returns the summary when the last generation is done.
pub fn run(gpu: &Gpu, options: RunOptions<'_>) -> Result<Option<Summary>> {
    run_with(gpu, options, &mut InProcess)
}

/// Run (or resume) a search whose islands are shared among the processes
/// `transport` reaches (docs/DISTRIBUTED.md). Every process calls this with
/// the same options. Only the root (rank 0) touches the run directory:
/// it checkpoints the whole population each generation, writes the log, the
/// hall of fame and the summary, and scores the test scenes; it returns the
/// summary, the others `None`.
pub fn run_with(gpu: &Gpu, options: RunOptions<'_>, transport: &mut dyn Transport) -> Result<Option<Summary>> {
    let start = Instant::now();
    let RunOptions {
        settings,
        config,
        output,
        resume,
        threads,
        stop_after,
        on_report,
        on_render,
        baselines,
        tiles,
        fusion,
        cache,
    } = options;
    settings.check().map_err(anyhow::Error::msg)?;
    // Every pipeline the run scores, before anything is rendered or searched.
    datasets::check_scorable(&config.pipeline)?;
    for Baseline { name, pipeline, .. } in &baselines {
        if let Some(pipeline) = pipeline {
            datasets::check_scorable(pipeline).with_context(|| format!("baseline {name}"))?;
        }
    }
    let root = transport.is_root();
    let resumed = if root { run_dir::prepare_run_dir(&output, resume, &settings, &config)? } else { None };
    let resumed: Option<State> = serde_json::from_slice(&transport.broadcast(serde_json::to_vec(&resumed)?)?)?;

    // The root renders missing scenes into the cache first; the others then
    // find them there (or, on a node that does not share it, render their own).
    let mut training = Vec::new();
    if root {
        training = datasets::resolve(gpu, &config.training, &config.render, &cache, &mut *on_render)?;
    }
    transport.barrier();
    if !root {
        training = datasets::resolve(gpu, &config.training, &config.render, &cache, &mut *on_render)?;
    }
    let (mut features, mut variances) = datasets::common_terminals(&training)?;
    if let Some(names) = &config.features {
        let (mut allowed, mut allowed_variances) = (BTreeSet::new(), BTreeSet::new());
        for name in names {
            let provided = match (Feature::from_name(name), ScalarVar::from_name(name)) {
                // What the outlier rule measured comes with the pipeline, not the scenes.
                (None, Some(v)) if v.from_prepass() => {
                    if config.pipeline.outliers.is_none() {
                        return Err(TerminalError::NeedsOutliers(name.clone()).into());
                    }
                    true
                }
                (None, Some(v)) if v.from_temporal() => {
                    if !config.pipeline.is_temporal() {
                        return Err(TerminalError::NeedsTemporal(name.clone()).into());
                    }
                    true
                }
                (Some(f), _) => features.contains(&f) && allowed.insert(f),
                (None, Some(v)) => variances.contains(&v) && allowed_variances.insert(v),
                (None, None) => return Err(TerminalError::Unknown(name.clone()).into()),
            };
            if !provided {
                return Err(TerminalError::NotProvided(name.clone()).into());
            }
        }
        features.retain(|f| allowed.contains(f));
        variances.retain(|v| allowed_variances.contains(v));
    }
    let seed_expr = crate::lang::parse_expr(&config.seed_expr).context("seed expression")?;
    let holds = Holds {
        features: &features,
        variances: &variances,
        measured: config.pipeline.outliers.is_some(),
        accumulated: config.pipeline.is_temporal(),
        albedo: true,
        motion: true,
    };
    if let Some(missing) = Needs::of(&seed_expr, false).missing(holds).into_iter().next() {
        return Err(TerminalError::SeedReads(missing.to_string()).into());
    }
    let scenes = datasets::load_all(&training, &features, &variances, &config.pipeline)?;
    let scoring = config.scoring(threads, tiles, fusion);
    let on_tiles = fitness::Settings {
        tiles: config.fitness_tiles.map(|sampling| FitnessTiles { sampling, seed: settings.seed }),
        ..scoring.clone()
    };
    let mut evaluator = Scorer::new(gpu, scenes, &on_tiles)?;
    // `level` (the à-trous pass) is a terminal where there are passes: a filter may change with scale.
    let level = config.pipeline.is_atrous().then_some(ScalarVar::Level);
    // What the outlier rule measured, where the pipeline has it: a weight may adapt to fireflies;
    // what the temporal stage accumulated, where it has one: a weight may trust a long history.
    let measures = config.pipeline.outliers.map(|_| ScalarVar::FROM_PREPASS.to_vec()).into_iter().flatten();
    let accumulated = config.pipeline.temporal.map(|_| ScalarVar::FROM_TEMPORAL.to_vec()).into_iter().flatten();
    let measures = measures.chain(accumulated);
    let terminals = gp::operators::Terminals {
        features: features.iter().copied().collect(),
        variables: variances.iter().copied().chain(level).chain(measures).collect(),
        constants: crate::lang::ops::THESIS_CONSTANTS.to_vec(),
    };
    let mut engine = gp::Engine::with_transport(
        settings.clone(),
        terminals,
        seed_expr.clone(),
        &mut evaluator,
        Box::new(transport),
    )?;
    // Trading error for cost, a window's radius is the largest lever: it evolves too (up to the run's).
    if settings.objectives == gp::Objectives::ErrorCost && config.pipeline.form == crate::pipeline::Form::Window {
        engine.set_radii(1..=config.radius);
    }

    // A generation is done once it is logged and checkpointed, in that order: a
    // resumed run drops log lines past its checkpoint.
    let mut record = |state: &State, report: &gp::Report| -> Result<()> {
        append_log(&output, report, &config.scored_on())?;
        write_checkpoint(
            &output,
            &Checkpoint { version: 1, settings: settings.clone(), run: config.clone(), state: state.clone() },
        )?;
        on_report(report);
        Ok(())
    };
    // Only the root holds the whole population.
    let mut state = match resumed {
        Some(state) => {
            engine.resume(&state)?;
            Some(state)
        }
        None => engine.initial()?.map(|(state, report)| record(&state, &report).map(|()| state)).transpose()?,
    };
    let mut done_here = 0;
    while engine.generation().expect("a generation is done") < settings.generations {
        if stop_after.is_some_and(|n| done_here >= n) {
            return Ok(None);
        }
        if let Some((next, report)) = engine.step()? {
            record(&next, &report)?;
            state = Some(next);
        }
        done_here += 1;
    }
    drop(engine);
    // The others end here: the run directory, the hall of fame and the test scenes are the root's.
    let Some(state) = state.filter(|_| root) else { return Ok(None) };

    // Fitness on tiles picked the hall of fame; whole images say which of it is best.
    let rescored = if evaluator.on_tiles_only() {
        let mut whole = Scorer::new(gpu, evaluator.into_scenes(), &scoring)?;
        let rescored = hall::rescore(&mut whole, &gp::hall_of_fame(&state, settings.hall_of_fame))?;
        run_dir::append_log_line(
            &output,
            &serde_json::json!({
                "generation": state.generation,
                "scored_on": config.scored_on_whole_images(),
                "rescored_hall_of_fame": rescored,
            }),
        )?;
        rescored
    } else {
        drop(evaluator);
        Vec::new()
    };
    let front = match settings.objectives {
        gp::Objectives::Error => Vec::new(),
        gp::Objectives::ErrorCost => gp::pareto_front(&state),
    };
    let hall = hall_of_fame(&state, settings.hall_of_fame, &config.pipeline, &config.fitness, &front, &rescored);
    crate::io::write_bytes_atomically(&output.join(HALL_OF_FAME_FILE), hall.to_string().as_bytes())?;
    let frequencies = gp::feature_frequencies(&state);
    crate::io::write_bytes_atomically(
        &output.join(FEATURES_FILE),
        serde_json::to_string_pretty(&frequencies)?.as_bytes(),
    )?;
    let best_whole = rescored.iter().filter_map(|r| r.fitness.map(|f| (f, r))).min_by(|a, b| a.0.total_cmp(&b.0));
    let best = match best_whole.map(|(_, r)| r) {
        Some(r) => gp::hall_of_fame(&state, settings.hall_of_fame)
            .into_iter()
            .map(|(_, m)| m)
            .find(|m| m.expr == r.expr)
            .expect("rescored members are the hall of fame's"),
        None => gp::hall_of_fame(&state, 1)
            .into_iter()
            .map(|(_, m)| m)
            .min_by(|a, b| a.fitness.value.total_cmp(&b.fitness.value))
            .expect("a non-empty population"),
    };

    let test_sets = datasets::resolve(gpu, &config.test, &config.render, &cache, &mut *on_render)?;
    let test_scenes = datasets::load_all(&test_sets, &features, &variances, &config.pipeline)?;
    let names = test_scenes.iter().map(|s| s.name.clone()).collect();
    let scoring = fitness::Settings::for_pipeline(config.radius, config.pipeline.spatial(), threads);
    let mut tester = Scorer::new(gpu, test_scenes, &scoring)?;
    let best_expr = crate::lang::parse_expr(&best.expr)?;
    let compared = vec![best_expr, seed_expr];
    let mut results = test(&mut tester, &compared)?.into_iter();
    let test_best = results.next().expect("best");
    let test_seed = results.next().expect("seed");
    let mut test_baselines = Vec::new();
    for Baseline { name, expr: baseline, pipeline } in baselines {
        let named =
            |results: Vec<TestResult>| results.into_iter().map(|result| BaselineResult { name: name.clone(), result });
        match pipeline.filter(|p| *p != config.pipeline) {
            // Through the run's pipeline, where the scenes hold what it reads (a feature the
            // pipeline derives, as the guide, is there wherever the colour is).
            None if baseline.features().iter().filter(|f| f.needs_data()).all(|f| features.contains(f))
                && baseline.stored_variables().is_subset(&variances) =>
            {
                test_baselines.extend(named(test(&mut tester, std::slice::from_ref(&baseline))?))
            }
            None => {}
            // Through its own: the test scenes loaded again with what it reads.
            Some(own) => {
                let reads: BTreeSet<Feature> = baseline.features().into_iter().filter(|f| f.needs_data()).collect();
                let scenes = datasets::load_all(&test_sets, &reads, &baseline.stored_variables(), &own)?;
                let scoring = fitness::Settings::for_pipeline(config.radius, own.spatial(), threads);
                let mut own_tester = Scorer::new(gpu, scenes, &scoring)?;
                test_baselines.extend(named(test(&mut own_tester, std::slice::from_ref(&baseline))?));
            }
        }
    }
    if !front.is_empty() {
        let front = front::measure_front(gpu, &mut tester, &front, &config)?;
        crate::io::write_bytes_atomically(&output.join(FRONT_FILE), serde_json::to_string_pretty(&front)?.as_bytes())?;
    }
    let summary = Summary {
        generations: state.generation,
        training_scored_on: config.scored_on(),
        rescored_hall_of_fame: rescored,
        best_simplified: crate::simplify::simplify(&compared[0]).to_string(),
        best,
        test_scenes: names,
        test_noisy_relmse: tester.noisy_relmse().to_vec(),
        test_noisy_light: tester.noisy_light(),
        test_best,
        test_seed,
        test_baselines,
        feature_frequencies: frequencies,
        seconds: start.elapsed().as_secs_f64(),
    };
    crate::io::write_bytes_atomically(&output.join(SUMMARY_FILE), serde_json::to_string_pretty(&summary)?.as_bytes())?;
    Ok(Some(summary))
}
