//! The run directory: the checkpoint (written atomically each generation),
//! the log (one JSON line per generation, appended; cut back to the
//! checkpoint on resuming), and the choice of a fresh directory.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};

use super::RunConfig;
use crate::gp::{self, Settings, State};

/// The checkpoint file: the state after a generation, and what produced it.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Checkpoint {
    pub version: u32,
    pub settings: Settings,
    pub run: RunConfig,
    pub state: State,
}

pub const CHECKPOINT_FILE: &str = "checkpoint.json";
pub const LOG_FILE: &str = "log.jsonl";
pub const HALL_OF_FAME_FILE: &str = "hall_of_fame.txt";
pub const FEATURES_FILE: &str = "features.json";
pub const SUMMARY_FILE: &str = "summary.json";

/// Why a run directory cannot be used as asked; the command line says
/// which of its flags changes that.
#[derive(Debug, thiserror::Error)]
pub enum RunDirError {
    /// Resuming a checkpoint made with other settings or scenes.
    #[error("{} was made with other settings or scenes", .0.display())]
    OtherSettings(std::path::PathBuf),
    /// A new run where one is already.
    #[error("{} holds a run already", .0.display())]
    Occupied(std::path::PathBuf),
    /// Resuming where nothing was checkpointed.
    #[error("nothing to resume: {} has no {CHECKPOINT_FILE}", .0.display())]
    NothingToResume(std::path::PathBuf),
}

pub fn write_checkpoint(dir: &Path, checkpoint: &Checkpoint) -> Result<()> {
    let text = serde_json::to_string(checkpoint)?;
    crate::io::write_bytes_atomically(&dir.join(CHECKPOINT_FILE), text.as_bytes()).map_err(anyhow::Error::from)
}

pub fn read_checkpoint(dir: &Path) -> Result<Checkpoint> {
    let path = dir.join(CHECKPOINT_FILE);
    let text = std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    let checkpoint: Checkpoint =
        serde_json::from_str(&text).with_context(|| format!("{} is not a filterjit checkpoint", path.display()))?;
    if checkpoint.version != 1 {
        bail!("{}: checkpoint version {} is not supported", path.display(), checkpoint.version);
    }
    Ok(checkpoint)
}

/// The log keeps one JSON line per generation; rewrite it to end at `generation`
/// (a resumed run may have logged generations after its last checkpoint).
pub fn log_upto(dir: &Path, generation: u32) -> Result<()> {
    let path = dir.join(LOG_FILE);
    let Ok(text) = std::fs::read_to_string(&path) else { return Ok(()) };
    let kept: String = text
        .lines()
        .filter(|l| {
            serde_json::from_str::<serde_json::Value>(l)
                .ok()
                .and_then(|v| v["generation"].as_u64())
                .is_some_and(|g| g <= generation as u64)
        })
        .map(|l| format!("{l}\n"))
        .collect();
    crate::io::write_bytes_atomically(&path, kept.as_bytes()).map_err(anyhow::Error::from)
}

/// One generation's line: the report, and what its fitness was measured on.
pub fn append_log(dir: &Path, report: &gp::Report, scored_on: &str) -> Result<()> {
    let mut line = serde_json::to_value(report)?;
    line["scored_on"] = scored_on.into();
    append_log_line(dir, &line)
}

pub(super) fn append_log_line(dir: &Path, line: &serde_json::Value) -> Result<()> {
    use std::io::Write;
    let mut file = std::fs::OpenOptions::new().create(true).append(true).open(dir.join(LOG_FILE))?;
    writeln!(file, "{}", serde_json::to_string(line)?)?;
    Ok(())
}

/// Where `filterjit evolve` writes when no run directory is named.
pub const DEFAULT_RUN_DIR: &str = "runs/evolve";

/// The run directory used when none is named: `base` itself, or, once it holds
/// a run, the first of `base-2`, `base-3`, … that does not, so that running
/// the same command twice starts a second run instead of stopping at an error.
/// With `resume`, the newest of them that holds a run (or `base`).
pub fn default_run_dir(base: &Path, resume: bool) -> PathBuf {
    let numbered = |n: u32| match n {
        1 => base.to_path_buf(),
        n => {
            let mut name = base.file_name().unwrap_or_default().to_os_string();
            name.push(format!("-{n}"));
            base.with_file_name(name)
        }
    };
    let holds_run = |dir: &Path| dir.join(CHECKPOINT_FILE).is_file();
    let first_free = (1..).find(|&n| !holds_run(&numbered(n))).expect("some number is free");
    if resume && first_free > 1 {
        numbered(first_free - 1)
    } else {
        numbered(first_free)
    }
}

/// The state to resume from, if any, after checking the run directory: the root's job.
pub(super) fn prepare_run_dir(
    output: &Path,
    resume: bool,
    settings: &Settings,
    config: &RunConfig,
) -> Result<Option<State>> {
    std::fs::create_dir_all(output).with_context(|| format!("creating {}", output.display()))?;
    crate::io::remove_stale_temporaries(output);
    let existing = output.join(CHECKPOINT_FILE).is_file();
    match (existing, resume) {
        (true, true) => {
            let checkpoint = read_checkpoint(output)?;
            if checkpoint.settings != *settings || checkpoint.run != *config {
                return Err(RunDirError::OtherSettings(output.join(CHECKPOINT_FILE)).into());
            }
            log_upto(output, checkpoint.state.generation)?;
            Ok(Some(checkpoint.state))
        }
        (true, false) => Err(RunDirError::Occupied(output.to_path_buf()).into()),
        (false, true) => Err(RunDirError::NothingToResume(output.to_path_buf()).into()),
        (false, false) => {
            let _ = std::fs::remove_file(output.join(LOG_FILE));
            Ok(None)
        }
    }
}
