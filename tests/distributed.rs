//! `evolve --mpi`: islands on MPI ranks give the in-process run's result,
//! and a job with a rank killed resumes to it (docs/DISTRIBUTED.md).
//!
//! These tests need Open MPI's `mpirun` and a filterjit built with
//! `--features mpi`, named by `FILTERJIT_MPI_BIN`; `.ci/run` builds one. Without
//! it they say SKIPPED (and fail under CI=true, where they must run). The
//! engine's distribution logic is also tested without MPI, threads standing
//! in for processes (`gp::tests`).

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use filterjit::evolve;

use crate::evolve::{datasets, temp_dir};

/// The MPI build of filterjit, or `None` (after saying so loudly) where there is none.
fn mpi_binary(test: &str) -> Option<PathBuf> {
    match std::env::var_os("FILTERJIT_MPI_BIN") {
        Some(path) => {
            let path = PathBuf::from(path);
            assert!(path.is_file(), "FILTERJIT_MPI_BIN={} is not a file", path.display());
            Some(path)
        }
        None if std::env::var_os("CI").is_some() => {
            panic!("CI must run {test}: build with `cargo build --features mpi` and set FILTERJIT_MPI_BIN")
        }
        None => {
            eprintln!(
                "=== SKIPPED {test}: FILTERJIT_MPI_BIN is not set (build with `cargo build --features mpi`; .ci/run does) ==="
            );
            None
        }
    }
}

/// A small search on the shared test datasets, written to `dir`.
fn evolve_args(dir: &Path, generations: u32) -> Vec<String> {
    let (training, test) = datasets();
    let mut args: Vec<String> = [
        "evolve",
        "--preset",
        "quick",
        "--islands",
        "4",
        "--island-size",
        "6",
        "--migration-interval",
        "2",
        "--radius",
        "2",
        "--seed",
        "9",
        "--threads",
        "1",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    args.extend(["--generations".into(), generations.to_string()]);
    args.extend(["--scenes".into(), training.display().to_string()]);
    args.extend(["--test-scenes".into(), test.display().to_string()]);
    args.extend(["-o".into(), dir.display().to_string()]);
    args
}

/// `mpirun` starting `ranks` copies of `bin` on this machine, talking over
/// loopback TCP as ranks on different machines would, one software-renderer
/// thread each so that they do not thrash two cores.
fn mpirun(ranks: usize, bin: &Path, args: &[String]) -> Command {
    let mut command = Command::new("mpirun");
    command
        .args(["--oversubscribe", "--bind-to", "none", "-n", &ranks.to_string()])
        .args(["--mca", "btl", "self,tcp", "--mca", "btl_tcp_if_include", "lo", "--mca", "oob_tcp_if_include", "lo"])
        .arg(bin)
        .args(args)
        .arg("--mpi")
        .env("OMPI_ALLOW_RUN_AS_ROOT", "1")
        .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
        .env("LP_NUM_THREADS", "1")
        .stdout(Stdio::null());
    command
}

/// The in-process run every MPI run must reproduce, by generations.
fn in_process(generations: u32) -> PathBuf {
    let dir = temp_dir(&format!("mpi-reference-{generations}"));
    let output = Command::new(env!("CARGO_BIN_EXE_filterjit")).args(evolve_args(&dir, generations)).output().unwrap();
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    dir
}

fn read(path: PathBuf) -> String {
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn population(dir: &Path) -> serde_json::Value {
    serde_json::to_value(evolve::read_checkpoint(dir).unwrap().state).unwrap()
}

#[test]
fn ranks_give_the_in_process_hall_of_fame() {
    let Some(bin) = mpi_binary("ranks_give_the_in_process_hall_of_fame") else { return };
    let reference = in_process(4);
    // Four ranks of one island each, and three of uneven shares (2, 1, 1).
    for ranks in [4, 3] {
        let dir = temp_dir(&format!("mpi-{ranks}"));
        let output = mpirun(ranks, &bin, &evolve_args(&dir, 4)).output().unwrap();
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(output.status.success(), "mpirun -n {ranks}: {stderr}");
        assert_eq!(
            read(dir.join(evolve::HALL_OF_FAME_FILE)),
            read(reference.join(evolve::HALL_OF_FAME_FILE)),
            "{ranks} ranks"
        );
        assert_eq!(population(&dir), population(&reference), "{ranks} ranks: the final population");
        assert!(stderr.contains(&format!("rank 0 of {ranks} MPI ranks")), "{stderr}");
        // Only the root writes the run directory; its log says how many ranks there were.
        let log = read(dir.join(evolve::LOG_FILE));
        assert_eq!(log.lines().count(), 5);
        assert!(log.lines().all(|l| l.contains(&format!("\"ranks\":{ranks}"))), "{log}");
    }
}

#[test]
fn a_job_with_a_killed_rank_resumes_to_the_same_result() {
    let Some(bin) = mpi_binary("a_job_with_a_killed_rank_resumes_to_the_same_result") else { return };
    let generations = 8;
    let reference = in_process(generations);
    let dir = temp_dir("mpi-killed");
    let args = evolve_args(&dir, generations);
    let mut job = mpirun(4, &bin, &args).stderr(Stdio::null()).spawn().unwrap();
    // Once generation 1 is checkpointed, SIGKILL one rank (a process mpirun started).
    let logged = |dir: &Path| std::fs::read_to_string(dir.join(evolve::LOG_FILE)).map_or(0, |l| l.lines().count());
    let start = std::time::Instant::now();
    while logged(&dir) < 2 {
        assert!(job.try_wait().unwrap().is_none(), "the job ended before it could be killed");
        assert!(start.elapsed().as_secs() < 600, "no generation after 10 minutes");
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    let ranks = Command::new("pgrep").args(["-P", &job.id().to_string()]).output().unwrap();
    let ranks: Vec<String> = String::from_utf8_lossy(&ranks.stdout).lines().map(str::to_string).collect();
    assert_eq!(ranks.len(), 4, "mpirun's children: {ranks:?}");
    let killed = Command::new("kill").args(["-KILL", &ranks[2]]).status().unwrap();
    assert!(killed.success());
    let status = job.wait().unwrap();
    assert!(!status.success(), "MPI ends the whole job when a rank dies");
    assert!(!dir.join(evolve::SUMMARY_FILE).exists(), "the killed job must not have finished");
    let checkpointed = evolve::read_checkpoint(&dir).expect("a complete checkpoint").state.generation;
    assert!(checkpointed >= 1 && checkpointed < generations, "checkpoint at generation {checkpointed}");

    let mut resumed = args.clone();
    resumed.push("--resume".into());
    let output = mpirun(4, &bin, &resumed).output().unwrap();
    assert!(output.status.success(), "resume: {}", String::from_utf8_lossy(&output.stderr));
    assert_eq!(read(dir.join(evolve::HALL_OF_FAME_FILE)), read(reference.join(evolve::HALL_OF_FAME_FILE)));
    // The log holds every generation once.
    assert_eq!(logged(&dir), generations as usize + 1);
}

#[test]
fn without_mpi_a_launched_rank_refuses_to_run() {
    // Started by a launcher but not told --mpi, every rank would run the whole
    // search into one directory: refuse, naming the flag.
    let dir = temp_dir("mpi-no-flag");
    let output = Command::new(env!("CARGO_BIN_EXE_filterjit"))
        .args(evolve_args(&dir, 1))
        .env("OMPI_COMM_WORLD_SIZE", "4")
        .output()
        .unwrap();
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("one of 4 MPI ranks") && stderr.contains("--mpi"), "{stderr}");
    assert!(!dir.join(evolve::CHECKPOINT_FILE).exists());
}

#[cfg(not(feature = "mpi"))]
#[test]
fn mpi_without_the_feature_says_how_to_build_it() {
    let dir = temp_dir("mpi-no-feature");
    let mut args = evolve_args(&dir, 1);
    args.push("--mpi".into());
    let output = Command::new(env!("CARGO_BIN_EXE_filterjit")).args(args).output().unwrap();
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("built without MPI") && stderr.contains("--features mpi"), "{stderr}");
}
