//! `evolve`: determinism, exact resumption, the terminal set, invalid individuals.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use filterjit::evolve::{self, RunConfig, RunOptions};
use filterjit::fitness::{self, Scorer};
use filterjit::gp::{Evaluator, Settings};
use filterjit::lang::{parse_expr, Feature};
use filterjit::render::{self, RenderSettings};
use filterjit::{corpus, scene};

use crate::common::{gpu, mitsuba_sample};

pub(crate) fn temp_dir(name: &str) -> PathBuf {
    crate::common::temp_dir("evolve", name)
}

/// Two tiny rendered datasets shared by the tests: (training, test).
pub(crate) fn datasets() -> &'static (PathBuf, PathBuf) {
    let gpu = gpu();
    static SETS: OnceLock<(PathBuf, PathBuf)> = OnceLock::new();
    SETS.get_or_init(|| {
        let root = temp_dir("datasets");
        let settings = RenderSettings { width: 16, height: 16, spp: 2, reference_spp: 32, seed: 0 };
        let mut out = Vec::new();
        for name in ["soft-shadows", "cornell"] {
            let d = render::builtin(name).unwrap().unwrap();
            let dir = root.join(name);
            render::render(&gpu, &d, &settings, &mut |_, _| {}).unwrap().write(&dir, &d, &settings).unwrap();
            out.push(dir);
        }
        (out[0].clone(), out[1].clone())
    })
}

pub(crate) fn small() -> Settings {
    Settings {
        islands: 2,
        island_size: 6,
        generations: 4,
        migration_interval: 2,
        hall_of_fame: 3,
        seed: 7,
        ..Settings::default()
    }
}

pub(crate) fn config(training: &Path, test: &Path) -> RunConfig {
    RunConfig {
        training: vec![training.display().to_string()],
        test: vec![test.display().to_string()],
        render: RenderSettings::default(),
        radius: 2,
        seed_expr: parse_expr(corpus::lookup("bilateral").unwrap()).unwrap().to_string(),
        pipeline: Default::default(),
        cost_model: Default::default(),
        fitness_tiles: None,
        features: None,
        fitness: Default::default(),
    }
}

pub(crate) fn run(
    dir: &Path,
    settings: Settings,
    config: RunConfig,
    resume: bool,
    stop_after: Option<u32>,
) -> Option<evolve::Summary> {
    try_run(dir, settings, config, resume, stop_after, fitness::Tiles::On, fitness::Fusion::Members(8)).unwrap()
}

/// A run with the given tiles and fusion (results are the same with any).
fn try_run(
    dir: &Path,
    settings: Settings,
    config: RunConfig,
    resume: bool,
    stop_after: Option<u32>,
    tiles: fitness::Tiles,
    fusion: fitness::Fusion,
) -> anyhow::Result<Option<evolve::Summary>> {
    let gpu = gpu();
    evolve::run(
        &gpu,
        RunOptions {
            settings,
            config,
            output: dir.to_path_buf(),
            resume,
            threads: 2,
            stop_after,
            on_report: &mut |_| {},
            on_render: &mut |_, _| {},
            baselines: Vec::new(),
            tiles,
            fusion,
            cache: crate::common::environment().cache.clone(),
        },
    )
}

fn read(path: PathBuf) -> String {
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

#[test]
fn runs_are_deterministic_and_resume_exactly() {
    let (training, test) = datasets();
    let a = temp_dir("a");
    let summary = run(&a, small(), config(training, test), false, None).expect("finished");
    assert_eq!(summary.generations, 4);
    assert!(summary.best.fitness.invalid.is_none());
    assert!(
        summary.best.fitness.value <= 1.5,
        "filtering should not be far worse than the noisy input: {:?}",
        summary.best
    );

    // The same seed and inputs: the same run, bit for bit, also without
    // workgroup tiles and with a kernel per individual instead of eight.
    let b = temp_dir("b");
    try_run(&b, small(), config(training, test), false, None, fitness::Tiles::Off, fitness::Fusion::Members(1))
        .unwrap()
        .expect("finished");
    let state = |dir: &Path| {
        serde_json::from_str::<serde_json::Value>(&read(dir.join(evolve::CHECKPOINT_FILE))).unwrap()["state"].clone()
    };
    assert_eq!(state(&a), state(&b));
    assert_eq!(read(a.join(evolve::HALL_OF_FAME_FILE)), read(b.join(evolve::HALL_OF_FAME_FILE)));

    // Interrupted after two generations, then resumed: the same end.
    let c = temp_dir("c");
    assert!(run(&c, small(), config(training, test), false, Some(2)).is_none());
    let log_lines = read(c.join(evolve::LOG_FILE)).lines().count();
    assert_eq!(log_lines, 3, "generations 0, 1 and 2 are logged");
    run(&c, small(), config(training, test), true, None).expect("finished");
    assert_eq!(state(&a), state(&c));
    assert_eq!(read(a.join(evolve::HALL_OF_FAME_FILE)), read(c.join(evolve::HALL_OF_FAME_FILE)));
    assert_eq!(read(c.join(evolve::LOG_FILE)).lines().count(), 5);

    // Starting over an existing run, or resuming with other settings, is refused.
    let err =
        try_run(&a, small(), config(training, test), false, None, fitness::Tiles::On, fitness::Fusion::Members(8))
            .unwrap_err();
    assert!(matches!(err.downcast_ref::<evolve::RunDirError>(), Some(evolve::RunDirError::Occupied(_))), "{err}");
    let err = try_run(
        &a,
        Settings { seed: 8, ..small() },
        config(training, test),
        true,
        None,
        fitness::Tiles::On,
        fitness::Fusion::Auto,
    )
    .unwrap_err();
    assert!(err.to_string().contains("other settings"), "{err}");
}

/// A run through the whole pipeline (outliers, demodulation, à-trous) stores
/// its pipeline with its hall of fame, and what it reports on the test scene is
/// what the CPU reference gives for the stored filter through that pipeline.
#[test]
fn a_run_through_a_pipeline_reproduces_what_it_scored() {
    let (training, test) = datasets();
    let dir = temp_dir("pipeline");
    let pipeline: filterjit::pipeline::FilterPipeline = "outliers=2,demodulate,atrous=3".parse().unwrap();
    // `--features` may name what the pipeline's outlier rule measures.
    let features = ["color", "pixel", "normal", "texture", "clampedShare"].map(String::from).into();
    let config = RunConfig { pipeline, features: Some(features), ..config(training, test) };
    let settings = Settings { generations: 2, ..small() };
    let summary = run(&dir, settings, config, false, None).expect("finished");
    let hall = dir.join(evolve::HALL_OF_FAME_FILE);
    assert!(read(hall.clone()).contains("# pipeline: outliers=2,demodulate,atrous=3"));

    let resolved = corpus::resolve_with_pipeline(&format!("@{}", hall.display())).unwrap();
    assert_eq!(resolved.pipeline, Some(pipeline));
    assert_eq!(resolved.expr.to_string(), summary.best.expr);
    let request = scene::Request { albedo: true, ..scene::Request::for_expr(&resolved.expr) };
    let scene = scene::load(test, &request).unwrap();
    let filtered = filterjit::cpu::filter_pipeline(&resolved.expr, &scene, &pipeline, 2).unwrap();
    let rgb: Vec<[f32; 3]> = filtered.color.iter().map(|c| c.map(|v| v as f32)).collect();
    let expected = filterjit::metrics::errors(&rgb, scene.reference.as_ref().unwrap(), None).relmse;
    let scored = summary.test_best.relmse[0];
    assert!((scored - expected).abs() <= 1e-3 * expected, "scored {scored}, CPU reference {expected}");
}

#[test]
fn the_hall_of_fame_reads_back_through_the_grammar() {
    let (training, test) = datasets();
    let dir = temp_dir("hof");
    run(&dir, Settings { generations: 1, ..small() }, config(training, test), false, None).expect("finished");
    let text = read(dir.join(evolve::HALL_OF_FAME_FILE));
    let file = filterjit::named::NamedFile::parse(&text).unwrap();
    let entries = file.resolved();
    assert!(!entries.is_empty() && entries.len() <= 2 * 3, "{text}");
    for (name, expr) in entries {
        assert!(name.starts_with("island"), "{name}");
        parse_expr(expr).unwrap_or_else(|e| panic!("{name}: {e}"));
    }
    let features: serde_json::Value = serde_json::from_str(&read(dir.join(evolve::FEATURES_FILE))).unwrap();
    assert!(features["color"].as_u64().unwrap() > 0, "the bilateral seed compares colours: {features}");
}

#[test]
fn the_terminal_set_is_what_the_training_scenes_provide() {
    let sample = mitsuba_sample();
    let (features, variances) = filterjit::datasets::common_terminals(std::slice::from_ref(&sample)).unwrap();
    assert!(!features.contains(&Feature::SecondaryTexture) && !features.contains(&Feature::DirectIllumination));
    assert!(features.contains(&Feature::Normal) && features.contains(&Feature::WpGradient));
    let dir = temp_dir("mitsuba");
    let mut settings = small();
    settings.generations = 3;
    settings.mutation_weights = vec![1.0, 1.0, 0.0, 0.0]; // insert and replace: the ways new terminals come in
    let config = RunConfig {
        training: vec![sample.display().to_string()],
        test: vec![sample.display().to_string()],
        ..config(&sample, &sample)
    };
    run(&dir, settings, config, false, None).expect("finished");
    let checkpoint = evolve::read_checkpoint(&dir).unwrap();
    let mut seen = std::collections::BTreeSet::new();
    for m in checkpoint.state.islands.iter().flatten() {
        let e = parse_expr(&m.expr).unwrap();
        seen.extend(e.features());
        for v in e.variables() {
            assert!(variances.contains(&v), "`{v}` is not in the Mitsuba sample");
        }
    }
    assert!(seen.is_subset(&features), "proposed {seen:?}, provided {features:?}");
    assert!(seen.len() > 2, "mutations brought in features beyond the seed's: {seen:?}");
}

#[test]
fn invalid_individuals_get_the_worst_fitness_and_a_reason() {
    let gpu = gpu();
    let (training, _) = datasets();
    let request = scene::Request::for_expr(&parse_expr("distance2(color)").unwrap());
    let scenes = vec![scene::load(training, &request).unwrap()];
    let mut evaluator = Scorer::new(&gpu, scenes, &fitness::Settings::window(2, 2)).unwrap();
    let exprs: Vec<_> = ["sqrt(distance2(color) - 1)", "exp(-distance2(color))", "asin(2 + distance2(color))", "1"]
        .iter()
        .map(|t| parse_expr(t).unwrap())
        .collect();
    let fitness = evaluator.evaluate(&filterjit::gp::Candidate::at_run_radius(&exprs)).unwrap();
    // A literal out of range does not lower: that candidate alone is invalid.
    let mut batch = exprs.clone();
    batch.push(filterjit::Expr::binary(
        filterjit::lang::BinaryOp::Mul,
        parse_expr("distance2(color)").unwrap(),
        filterjit::Expr::Const(1e20),
    ));
    let with_bad = evaluator.evaluate(&filterjit::gp::Candidate::at_run_radius(&batch)).unwrap();
    assert_eq!(with_bad[..exprs.len()], fitness[..], "the others are scored as before");
    let bad = &with_bad[exprs.len()];
    assert_eq!(bad.value, filterjit::gp::WORST);
    assert!(bad.invalid.as_deref().unwrap().contains("does not compile"), "{bad:?}");
    assert_eq!(fitness[0].value, filterjit::gp::WORST);
    assert!(fitness[0].invalid.as_deref().unwrap().contains("sqrt"), "{:?}", fitness[0]);
    assert!(fitness[1].invalid.is_none() && fitness[1].value < 1.0, "{:?}", fitness[1]);
    assert!(fitness[2].invalid.as_deref().unwrap().contains("asin"), "{:?}", fitness[2]);
    // Constant weights are a box filter: valid, and comparable with the CPU.
    let box_filter = filterjit::cpu::filter(&exprs[3], &evaluator.scenes()[0], 2).unwrap();
    let reference = evaluator.scenes()[0].reference.clone().unwrap();
    let cpu = filterjit::metrics::errors(&box_filter.color, &reference, None).relmse / evaluator.noisy_relmse()[0];
    assert!((fitness[3].value - cpu).abs() < 1e-4 * cpu.max(1.0), "GPU fitness {} vs CPU {cpu}", fitness[3].value);
}

/// SIGKILL `filterjit evolve` at random moments, resume until it finishes:
/// the hall of fame is always the uninterrupted run's, and the checkpoint is
/// never half-written.
#[test]
fn killed_runs_resume_to_the_same_hall_of_fame() {
    use std::process::{Command, Stdio};
    let (training, test) = datasets();
    let trials = crate::common::env_usize("FILTERJIT_KILL_TRIALS", 5);
    let args = |dir: &Path| -> Vec<String> {
        [
            "evolve",
            "--preset",
            "quick",
            "--scenes",
            &training.display().to_string(),
            "--test-scenes",
            &test.display().to_string(),
            "--islands",
            "2",
            "--island-size",
            "6",
            "--generations",
            "6",
            "--radius",
            "2",
            "--seed",
            "5",
            "-o",
            &dir.display().to_string(),
        ]
        .iter()
        .map(|s| s.to_string())
        .collect()
    };
    let bin = env!("CARGO_BIN_EXE_filterjit");
    let reference = temp_dir("kill-reference");
    let status = Command::new(bin).args(args(&reference)).stdout(Stdio::null()).stderr(Stdio::null()).status().unwrap();
    assert!(status.success());
    let expected = read(reference.join(evolve::HALL_OF_FAME_FILE));
    let mut rng = filterjit::rng::Rng::seeded(2024);
    let mut kills = 0;
    for trial in 0..trials {
        let dir = temp_dir(&format!("kill-{trial}"));
        let mut resume = false;
        // A kill that leaves no newer checkpoint doubles the next wait, so
        // every trial ends however slowly the driver compiles.
        let (mut patience, mut done) = (1u64, None);
        loop {
            let mut a = args(&dir);
            if resume {
                a.push("--resume".into());
            }
            let mut child = Command::new(bin).args(&a).stdout(Stdio::null()).stderr(Stdio::null()).spawn().unwrap();
            let delay = std::time::Duration::from_millis((20 + rng.below(700) as u64) * patience);
            std::thread::sleep(delay);
            match child.try_wait().unwrap() {
                Some(status) => {
                    assert!(status.success(), "trial {trial}: evolve failed");
                    break;
                }
                None => {
                    child.kill().unwrap(); // SIGKILL
                    child.wait().unwrap();
                    kills += 1;
                    // Whatever the moment, a checkpoint present is complete.
                    let mut generation = None;
                    if dir.join(evolve::CHECKPOINT_FILE).is_file() {
                        let checkpoint =
                            evolve::read_checkpoint(&dir).unwrap_or_else(|e| panic!("trial {trial}: {e:#}"));
                        generation = Some(checkpoint.state.generation);
                        resume = true;
                    }
                    patience = if generation > done { 1 } else { patience * 2 };
                    done = done.max(generation);
                }
            }
        }
        assert_eq!(read(dir.join(evolve::HALL_OF_FAME_FILE)), expected, "trial {trial}");
    }
    eprintln!("{kills} kills over {trials} trials");
    assert!(kills > 0, "no run was interrupted");
}

#[test]
fn a_second_run_without_a_directory_gets_a_fresh_one() {
    let root = temp_dir("default-dir");
    let base = root.join("evolve");
    let mark = |dir: &Path| {
        std::fs::create_dir_all(dir).unwrap();
        std::fs::write(dir.join(evolve::CHECKPOINT_FILE), "{}").unwrap();
    };
    assert_eq!(evolve::default_run_dir(&base, false), base, "the first run takes the base name");
    assert_eq!(evolve::default_run_dir(&base, true), base, "nothing to resume: the base name");
    mark(&base);
    assert_eq!(evolve::default_run_dir(&base, false), root.join("evolve-2"));
    assert_eq!(evolve::default_run_dir(&base, true), base, "--resume continues the run that exists");
    mark(&root.join("evolve-2"));
    assert_eq!(evolve::default_run_dir(&base, false), root.join("evolve-3"));
    assert_eq!(evolve::default_run_dir(&base, true), root.join("evolve-2"), "--resume takes the newest");
}

#[test]
fn a_multi_objective_run_writes_a_measured_front_and_resumes_exactly() {
    let (training, test) = datasets();
    let settings = Settings { objectives: filterjit::gp::Objectives::ErrorCost, generations: 4, ..small() };
    let dir = temp_dir("pareto");
    run(&dir, settings.clone(), config(training, test), false, None).expect("finished");
    let front: evolve::Front = serde_json::from_str(&read(dir.join(evolve::FRONT_FILE))).unwrap();
    assert!(!front.members.is_empty());
    for a in &front.members {
        assert!((1..=2).contains(&a.radius), "the radius evolves up to the run's: {}", a.radius);
        assert!(a.fitness < filterjit::gp::NO_CHOICE && a.ms_per_mpx > 0.0 && a.test_normalised.is_finite());
        for b in &front.members {
            assert!(!filterjit::gp::pareto::dominates(&[a.fitness, a.cost], &[b.fitness, b.cost]), "{a:?} {b:?}");
        }
    }
    assert!(front.members.windows(2).all(|w| w[0].cost <= w[1].cost && w[0].fitness >= w[1].fitness));
    // Each member reads back from the hall of fame with the radius it was scored at.
    let hall = dir.join(evolve::HALL_OF_FAME_FILE);
    for m in &front.members {
        let resolved = corpus::resolve_with_pipeline(&format!("@{}:{}", hall.display(), m.name)).unwrap();
        assert_eq!(resolved.expr.to_string(), m.expr);
        assert_eq!(resolved.radius, Some(m.radius), "{}", m.name);
    }

    let resumed = temp_dir("pareto-resumed");
    assert!(run(&resumed, settings.clone(), config(training, test), false, Some(2)).is_none());
    run(&resumed, settings, config(training, test), true, None).expect("finished");
    assert_eq!(read(resumed.join(evolve::HALL_OF_FAME_FILE)), read(hall));
    let again: evolve::Front = serde_json::from_str(&read(resumed.join(evolve::FRONT_FILE))).unwrap();
    let points =
        |f: &evolve::Front| f.members.iter().map(|m| (m.expr.clone(), m.radius, m.fitness)).collect::<Vec<_>>();
    assert_eq!(points(&again), points(&front));
}

/// `bench`'s calibration measures a weight for every operator on this
/// device, on the operator table's scale, and a search run with it keeps it
/// in its checkpoint and its cost objective follows it.
#[test]
fn the_cost_model_is_measured_on_the_device_and_kept_by_the_run() {
    let gpu = gpu();
    let scene = crate::common::synthetic_scene(40, 40, 3);
    let mut buffers = filterjit::gpu::SceneBuffers::new(&gpu, &scene);
    let (model, probes) = filterjit::bench::calibrate(&gpu, &mut buffers, &scene, 4, 3).unwrap();
    let table = filterjit::cost::CostModel::table();
    assert_eq!(model.device, gpu.describe());
    assert_eq!(model.operators.keys().collect::<Vec<_>>(), table.operators.keys().collect::<Vec<_>>());
    assert!(model.operators.values().all(|w| w.is_finite() && *w >= 0.0), "{model:?}");
    let sum = |m: &filterjit::cost::CostModel| m.operators.values().sum::<f64>();
    assert!((sum(&model) - sum(&table)).abs() < 1e-6 * sum(&table), "{model:?}");
    // pow (a log, an exponential and its guards) costs far more than an add on any device.
    assert!(model.operators["pow"] > model.operators["add"], "{model:?} {probes:?}");

    // A run with a model of its own (pow made prohibitive): the checkpoint keeps
    // it and every front member costs what it says.
    let mut heavy = table.clone();
    heavy.device = "a test model".into();
    heavy.operators.insert("pow".into(), 1e6);
    let (training, test) = datasets();
    let dir = temp_dir("cost-model");
    let settings = Settings { objectives: filterjit::gp::Objectives::ErrorCost, generations: 2, ..small() };
    let config = RunConfig { cost_model: heavy.clone(), ..config(training, test) };
    run(&dir, settings, config, false, None).expect("finished");
    let checkpoint = evolve::read_checkpoint(&dir).unwrap();
    assert_eq!(checkpoint.run.cost_model, heavy);
    let front = evolve::Front::read(&dir.join(evolve::FRONT_FILE)).unwrap();
    assert_eq!(front.cost_model, "a test model");
    for m in &front.members {
        let e = parse_expr(&m.expr).unwrap();
        let expected = filterjit::cost::model_with(&e, &front.pipeline, m.radius, &heavy);
        assert!((m.cost - expected).abs() <= 1e-9 * expected, "{}: {} against {expected}", m.expr, m.cost);
    }
}

/// A run on fitness tiles logs what its fitness was measured on, scores its
/// hall of fame again on whole training images, and reports the best there.
#[test]
fn a_run_on_fitness_tiles_is_rescored_on_whole_images() {
    let (training, test) = datasets();
    let dir = temp_dir("fitness-tiles");
    let tiles: fitness::TileSampling = "2x8".parse().unwrap();
    let config = RunConfig { fitness_tiles: Some(tiles), ..config(training, test) };
    let settings = Settings { generations: 2, ..small() };
    let summary = run(&dir, settings, config, false, None).expect("finished");
    assert_eq!(summary.training_scored_on, "2 tiles of 8x8 pixels per training scene");
    let log = read(dir.join(evolve::LOG_FILE));
    let lines: Vec<serde_json::Value> = log.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(lines.len(), 4, "the initial population, two generations, the rescoring");
    assert!(lines[..3].iter().all(|l| l["scored_on"] == summary.training_scored_on.as_str()));
    assert_eq!(lines[3]["scored_on"], "whole training images");
    let rescored = &summary.rescored_hall_of_fame;
    assert!(!rescored.is_empty() && rescored.iter().all(|r| r.fitness.is_some()));
    // Half of each 16x16 scene's cells is not the whole scene.
    assert!(rescored.iter().any(|r| r.fitness != Some(r.fitness_on_tiles)));
    let best = rescored.iter().filter_map(|r| r.fitness.map(|f| (f, &r.expr))).min_by(|a, b| a.0.total_cmp(&b.0));
    assert_eq!(best.map(|(_, e)| e), Some(&summary.best.expr), "the best on whole images is the run's best");
    let hall = read(dir.join(evolve::HALL_OF_FAME_FILE));
    assert!(hall.contains("on the whole training images") && hall.contains("(on tiles "), "{hall}");
    let first = hall.lines().find(|l| l.contains(" = ")).unwrap();
    assert!(first.ends_with(&summary.best.expr), "the first entry is the best: {first}");
}

/// `--scenes FOLDER` takes every dataset in a folder of them, in name order,
/// next to single datasets; a folder with none is an error that names it.
#[test]
fn a_folder_of_datasets_is_its_datasets() {
    let gpu = gpu();
    let (training, test) = datasets();
    let folder = temp_dir("folder-of-datasets");
    for (name, from) in [("b-test", test), ("a-training", training)] {
        let to = folder.join(name);
        std::fs::create_dir_all(&to).unwrap();
        for file in std::fs::read_dir(from).unwrap() {
            let file = file.unwrap().path();
            std::fs::copy(&file, to.join(file.file_name().unwrap())).unwrap();
        }
    }
    std::fs::create_dir_all(folder.join("c-not-a-dataset")).unwrap();
    let args = [folder.display().to_string(), training.display().to_string()];
    let resolved = filterjit::datasets::resolve(
        &gpu,
        &args,
        &RenderSettings::default(),
        &crate::common::environment().cache,
        &mut |_, _| {},
    )
    .unwrap();
    assert_eq!(resolved, vec![folder.join("a-training"), folder.join("b-test"), training.clone()]);
    let empty = folder.join("c-not-a-dataset");
    let error = filterjit::datasets::resolve(
        &gpu,
        &[empty.display().to_string()],
        &RenderSettings::default(),
        &crate::common::environment().cache,
        &mut |_, _| {},
    )
    .unwrap_err()
    .to_string();
    assert!(error.contains("c-not-a-dataset") && error.contains("folder of datasets"), "{error}");
}

/// `--features` limits the terminals: no individual reads another feature,
/// and a feature the training scenes lack is refused by name.
#[test]
fn the_search_reads_only_the_features_it_is_given() {
    let (training, test) = datasets();
    let allowed: std::collections::BTreeSet<Feature> = [Feature::Color, Feature::Pixel, Feature::Normal].into();
    let dir = temp_dir("features");
    let config = RunConfig {
        features: Some(allowed.iter().map(|f| f.name().to_string()).collect()),
        seed_expr: "exp(-(distance2(color) / 0.5 + distance2(pixel) / 8))".into(),
        ..config(training, test)
    };
    run(&dir, Settings { generations: 2, ..small() }, config.clone(), false, None).expect("finished");
    let checkpoint = evolve::read_checkpoint(&dir).unwrap();
    for m in checkpoint.state.islands.iter().flatten() {
        let e = parse_expr(&m.expr).unwrap();
        let read = e.features();
        assert!(read.is_subset(&allowed), "`{}` reads {read:?}", m.expr);
        assert!(e.stored_variables().is_empty(), "`{}` reads a variance none was given", m.expr);
    }
    // The Mitsuba sample has no direct-illumination channel.
    let sample = mitsuba_sample();
    let lacking = RunConfig {
        training: vec![sample.display().to_string()],
        test: vec![sample.display().to_string()],
        features: Some(["color".to_string(), "directIllumination".to_string()].into()),
        ..config
    };
    let (tiles, fusion) = (fitness::Tiles::Off, fitness::Fusion::Auto);
    use filterjit::evolve::TerminalError;
    let error =
        try_run(&temp_dir("features-missing"), small(), lacking.clone(), false, None, tiles, fusion).unwrap_err();
    let typed = error.downcast_ref::<TerminalError>();
    assert!(matches!(typed, Some(TerminalError::NotProvided(n)) if n == "directIllumination"), "{error}");
    // What the outlier rule measures comes with the pipeline: named without one, it is refused as such.
    let measure = RunConfig { features: Some(["color".to_string(), "clampedShare".to_string()].into()), ..lacking };
    let error = try_run(&temp_dir("features-measure"), small(), measure, false, None, tiles, fusion).unwrap_err();
    let typed = error.downcast_ref::<TerminalError>();
    assert!(matches!(typed, Some(TerminalError::NeedsOutliers(n)) if n == "clampedShare"), "{error}");
    assert!(error.to_string().contains("outliers=K"), "{error}");
}

/// `--fitness-relative-to E --fitness-pool worst`: fitness is the largest
/// ratio over the training scenes of a candidate's relMSE to E's, so the seed
/// scores exactly 1 when it is E, and the best's figure can be recomputed
/// from the per-scene errors.
#[test]
fn fitness_relative_to_a_baseline_pools_the_worst_scene() {
    use filterjit::fitness::{FitnessRule, Pool};
    let (training, test) = datasets();
    let dir = temp_dir("fitness-rule");
    let base = config(training, test);
    let rule = FitnessRule { relative_to: Some(base.seed_expr.clone()), pool: Pool::Worst, light_tolerance: None };
    let config = RunConfig {
        training: vec![training.display().to_string(), test.display().to_string()],
        fitness: rule.clone(),
        ..base.clone()
    };
    let summary = run(&dir, Settings { generations: 2, ..small() }, config.clone(), false, None).expect("finished");
    assert!(summary.training_scored_on.contains("worst scene"), "{}", summary.training_scored_on);
    let checkpoint = evolve::read_checkpoint(&dir).unwrap();
    assert_eq!(checkpoint.run.fitness, rule, "the rule is kept for --resume");
    let first: serde_json::Value =
        serde_json::from_str(read(dir.join(evolve::LOG_FILE)).lines().next().unwrap()).unwrap();
    assert!(first["best"].as_f64().unwrap() <= 1.0, "the seed is in generation 0 and scores 1: {first}");
    let hall = read(dir.join(evolve::HALL_OF_FAME_FILE));
    assert!(hall.contains(&format!("# fitness: relMSE / the relMSE of `{}`, worst scene", base.seed_expr)), "{hall}");

    // The same figure from the per-scene errors.
    let gpu = gpu();
    let exprs = [parse_expr(&summary.best.expr).unwrap(), parse_expr(&base.seed_expr).unwrap()];
    let request = scene::Request {
        features: exprs.iter().flat_map(|e| e.features()).collect(),
        variances: exprs.iter().flat_map(|e| e.stored_variables()).collect(),
        reference: true,
        ..Default::default()
    };
    let scenes: Vec<_> = [training, test].iter().map(|d| scene::load(d, &request).unwrap()).collect();
    let mut evaluator = Scorer::new(&gpu, scenes.clone(), &fitness::Settings::window(base.radius, 2)).unwrap();
    let errors = evaluator.errors(&exprs).unwrap();
    let (best, seed) = (errors[0].as_ref().unwrap(), errors[1].as_ref().unwrap());
    let worst = best.iter().zip(seed).map(|(b, s)| b.relmse / s.relmse).fold(0.0, f64::max);
    assert!((summary.best.fitness.value - worst).abs() <= 1e-12 * worst, "{} vs {worst}", summary.best.fitness.value);
    let mut evaluator =
        Scorer::new(&gpu, scenes, &fitness::Settings { rule, ..fitness::Settings::window(base.radius, 2) }).unwrap();
    let seed = filterjit::gp::Candidate { expr: exprs[1].clone(), radius: None };
    assert_eq!(evaluator.evaluate(&[seed]).unwrap()[0].value, 1.0, "the baseline itself scores 1");
}

/// Scoring drops the pipelines of the kernels it compiled (each generation's
/// are new), not what other users of a shared device cached.
#[test]
fn scoring_leaves_what_others_cached_on_a_shared_device() {
    use filterjit::{gpu::Gpu, jit, pipeline::FilterPipeline};
    let (training, _) = datasets();
    let turn = gpu();
    let device = Gpu::open_like(&turn).unwrap();
    let shape = jit::Shape::of(&FilterPipeline::WINDOW);
    let other = jit::compile(&parse_expr("1").unwrap(), jit::KernelSpec { shape, ..jit::KernelSpec::default() });
    device.pipeline(&other.unwrap()).unwrap();
    assert_eq!(device.cached_pipelines(), 1);
    let expr = parse_expr("exp(-distance2(color))").unwrap();
    let scenes = vec![scene::load(training, &scene::Request::for_expr(&expr)).unwrap()];
    let scoring = fitness::Settings { devices: Some(1), ..fitness::Settings::window(2, 1) };
    let mut evaluator = Scorer::new(&device, scenes, &scoring).unwrap();
    assert!(evaluator.errors(&[expr]).unwrap()[0].is_ok());
    assert_eq!(device.cached_pipelines(), 1, "the filter kernel cached before scoring is still there");
}

/// With `elites`, each island's best passes on unchanged: the best fitness
/// of a generation never gets worse, and the seed's score bounds every one.
#[test]
fn elites_keep_the_best_filter_found() {
    let (training, test) = datasets();
    // Small tournaments lose the best now and then; one elite keeps it.
    let bests = |elites: usize| -> Vec<f64> {
        let dir = temp_dir(&format!("elites-{elites}"));
        let settings = Settings { elites, tournament: 2, generations: 8, ..small() };
        run(&dir, settings, config(training, test), false, None).expect("finished");
        read(dir.join(evolve::LOG_FILE))
            .lines()
            .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap()["best"].as_f64().unwrap())
            .collect()
    };
    let monotone = |b: &[f64]| b.windows(2).all(|w| w[1] <= w[0]);
    let (without, with) = (bests(0), bests(1));
    assert!(!monotone(&without), "this seed loses its best without elites: {without:?}");
    assert!(monotone(&with), "with an elite the best never gets worse: {with:?}");
    let too_many = Settings { elites: 7, ..small() };
    let error = evolve::run(
        &gpu(),
        RunOptions {
            settings: too_many,
            config: config(training, test),
            output: temp_dir("elites-too-many"),
            resume: false,
            threads: 1,
            stop_after: None,
            on_report: &mut |_| {},
            on_render: &mut |_, _| {},
            baselines: Vec::new(),
            tiles: fitness::Tiles::Off,
            fusion: fitness::Fusion::Auto,
            cache: crate::common::environment().cache.clone(),
        },
    )
    .unwrap_err()
    .to_string();
    assert!(error.contains("elites: 7"), "{error}");
}

/// The light the test table states, on a known answer: a filter that keeps
/// each pixel as it is keeps the noisy input's light exactly, and a filter
/// that averages keeps a flat image's.
#[test]
fn test_results_state_each_outputs_light() {
    let (training, test) = datasets();
    let gpu = gpu();
    let request =
        scene::Request { reference: true, ..scene::Request::for_expr(&parse_expr("distance2(color)").unwrap()) };
    let scenes: Vec<_> = [training, test].iter().map(|d| scene::load(d, &request).unwrap()).collect();
    let scorer = Scorer::new(&gpu, scenes, &fitness::Settings::window(2, 1)).unwrap();
    // Only the centre has a weight that is not flushed to zero.
    let identity = parse_expr("exp(-(distance2(pixel) * 1000))").unwrap();
    let kept = scorer.light(&identity, 2).unwrap();
    let noisy = scorer.noisy_light();
    assert_eq!(kept.len(), 2);
    for (k, n) in kept.iter().zip(&noisy) {
        let (k, n) = (k.unwrap(), n.unwrap());
        assert!((k - n).abs() <= 1e-5 * n, "identity {k} against noisy {n}");
        assert!(n > 0.0 && n.is_finite());
    }
    let results = evolve::test(
        &mut Scorer::new(&gpu, scorer.into_scenes(), &fitness::Settings::window(2, 1)).unwrap(),
        &[identity],
    )
    .unwrap();
    assert_eq!(results[0].light, kept);
    assert_eq!(evolve::mean_light(&results[0].light), Some((kept[0].unwrap() + kept[1].unwrap()) / 2.0));
}

/// `filterjit evolve ARGS` on the small test datasets, into `dir`: its
/// stdout and stderr, once it succeeded.
fn evolve_on_datasets(args: &[&str], dir: &Path) -> (String, String) {
    let (training, test) = datasets();
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_filterjit"))
        .arg("evolve")
        .args(args)
        .arg("--scenes")
        .arg(training)
        .arg("--test-scenes")
        .arg(test)
        .arg("-o")
        .arg(dir)
        .output()
        .unwrap();
    let (stdout, stderr) =
        (String::from_utf8_lossy(&o.stdout).into_owned(), String::from_utf8_lossy(&o.stderr).into_owned());
    assert!(o.status.success(), "evolve {args:?}: {stderr}");
    (stdout, stderr)
}

/// `filterjit evolve` with no preset shows the search at work: seeded with
/// the hand-set cross-bilateral filter, its best error never rises from one
/// generation to the next (2 elites), and it ends by comparing the best with
/// the seed and with the best shipped filter, naming the search that goes on
/// from that one.
#[test]
fn the_default_search_starts_from_a_cross_bilateral_filter_and_compares_with_what_ships() {
    let dir = temp_dir("start-search");
    let (stdout, stderr) =
        evolve_on_datasets(&["--islands", "2", "--island-size", "6", "--generations", "3", "--seed", "3"], &dir);
    let said = format!("{stdout}{stderr}");
    assert!(said.contains("@crossBilateral,"), "seeded with the cross-bilateral filter: {said}");
    let generations: Vec<&str> = stderr.lines().filter(|l| l.starts_with("gen ")).collect();
    assert_eq!(generations.len(), 4, "a line a generation, the initial population's first: {stderr}");
    assert!(generations[3].starts_with("gen    3  best "), "{}", generations[3]);
    let bests: Vec<f64> = std::fs::read_to_string(dir.join(filterjit::evolve::LOG_FILE))
        .unwrap()
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok()?.get("best")?.as_f64())
        .collect();
    assert_eq!(bests.len(), 4, "the initial population and three generations: {bests:?}");
    assert!(bests.windows(2).all(|w| w[1] <= w[0]), "the best error never rises: {bests:?}");
    let shipped = filterjit::denoise::SHIPPED_BY_QUALITY[0];
    let line = stdout.lines().find(|l| l.starts_with("shipped   ")).unwrap_or_else(|| panic!("{stdout}"));
    assert!(line.starts_with(&format!("shipped   @{shipped}, the best shipped filter")), "{line}");
    assert!(line.contains("`filterjit evolve --preset shipped`"), "{line}");
    assert!(stdout.contains("against   @crossBilateral, the seed"), "{stdout}");
    // The compared filters' columns carry the names they were asked by.
    let header = stdout.lines().find(|l| l.starts_with("test      relMSE")).unwrap_or_else(|| panic!("{stdout}"));
    let columns: Vec<&str> = header.split_whitespace().skip(2).collect();
    assert_eq!(columns, ["noisy", "seed", "best", "@crossBilateralAtrous", &format!("@{shipped}")], "{header}");
    assert!(!stdout.contains("baseline1"), "{stdout}");
    let settings = stderr.lines().find(|l| l.starts_with("evolve    ")).unwrap_or_else(|| panic!("{stderr}"));
    assert!(settings.contains("pipeline outliers=") && !settings.contains("radius"), "an à-trous search: {settings}");
}

/// `filterjit evolve --preset temporal` improves on what a sequence gets
/// (`@temporal`, seeded and scored against), on the built-in sequences; a
/// baseline it cannot score frame by frame (SVGF's pipeline feeds a pass
/// back) is refused by the name it was asked by, before anything is rendered.
#[test]
fn the_temporal_preset_starts_from_the_shipped_temporal_filter() {
    let dir = temp_dir("temporal-preset");
    let run = |extra: &[&str]| {
        std::process::Command::new(env!("CARGO_BIN_EXE_filterjit"))
            .args(["evolve", "--preset", "temporal", "--islands", "1", "--island-size", "4", "--generations", "1"])
            .args(["--size", "32x32", "--reference-spp", "8", "--seed", "3"])
            .args(extra)
            .arg("-o")
            .arg(dir.join("run"))
            .env("FILTERJIT_CACHE", dir.join("cache"))
            .output()
            .unwrap()
    };
    let o = run(&["--baseline", "@svgf"]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && stderr.contains("baseline @svgf: pipeline"), "{stderr}");
    assert!(stderr.contains("feeds back pass 1"), "{stderr}");
    assert!(!dir.join("cache").exists() && !dir.join("run").exists(), "refused before anything is rendered");

    let o = run(&[]);
    let (stdout, stderr) = (String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    assert!(o.status.success(), "{stderr}");
    let temporal = filterjit::denoise::SHIPPED_TEMPORAL_BY_QUALITY[0];
    assert!(stdout.contains(&format!("against   @{temporal}, the seed")), "{stdout}");
    let settings = stderr.lines().find(|l| l.starts_with("evolve    ")).unwrap_or_else(|| panic!("{stderr}"));
    let stored = filterjit::corpus::resolve_with_pipeline(&format!("@{temporal}")).unwrap().pipeline.unwrap();
    // Less the light anchor, which a search does not score.
    let pipeline = filterjit::pipeline::FilterPipeline { anchor: None, ..stored };
    assert!(stored.anchor.is_some() && !settings.contains("anchor"), "{settings}");
    assert!(settings.contains(&format!("pipeline {pipeline},")), "the shipped filter's pipeline: {settings}");
    assert!(stdout.contains("seq-orbit-desk/frame_0008"), "tested on the built-in test sequence: {stdout}");
}

/// `--objectives error,cost` on a search scored against a baseline filter
/// (the default and the shipped presets): members worse than the baseline
/// still filter, so the front is written (it was left empty, silently).
#[test]
fn a_search_scored_against_a_baseline_writes_its_front() {
    for preset in ["start", "shipped"] {
        let dir = temp_dir(&format!("front-{preset}"));
        let args = ["--preset", preset, "--objectives", "error,cost", "--islands", "2", "--island-size", "6"];
        evolve_on_datasets(&[&args[..], &["--generations", "2", "--seed", "3"]].concat(), &dir);
        let front: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join(filterjit::evolve::FRONT_FILE)).unwrap()).unwrap();
        let members = front["members"].as_array().unwrap();
        assert!(!members.is_empty(), "{preset}: a front of at least one member");
    }
}

/// `filterjit evolve --preset shipped` improves on the best shipped filter:
/// it is the seed, scored against, and kept (2 elites), so the best's
/// training fitness is at most the seed's (1), and the last lines compare
/// the two (then, where the seed stayed best, say how to search longer).
#[test]
fn the_shipped_search_starts_from_the_shipped_filter_and_says_how_it_compares() {
    let dir = temp_dir("default-search");
    let args = ["--preset", "shipped", "--islands", "2", "--island-size", "6", "--generations", "2", "--seed", "3"];
    let (stdout, stderr) = evolve_on_datasets(&args, &dir);
    let shipped = filterjit::denoise::SHIPPED_BY_QUALITY[0];
    let said = format!("{stdout}{stderr}");
    let pipeline = filterjit::corpus::resolve_with_pipeline(&format!("@{shipped}")).unwrap().pipeline.unwrap();
    assert!(said.contains(&format!("pipeline {pipeline},")), "in the shipped filter's pipeline ({pipeline}): {said}");
    let lines: Vec<&str> = stdout.lines().collect();
    let against = lines.iter().rposition(|l| l.starts_with("against   ")).expect("an `against` line");
    assert!(lines[against].starts_with(&format!("against   @{shipped}, the seed: on the test scenes")), "{stdout}");
    // What follows it: nothing where the best beat the seed, else how to search longer.
    let figures: Vec<f64> = lines[against]
        .split(" is ")
        .nth(1)
        .and_then(|rest| rest.split(" (").next())
        .map(|pair| pair.split(" against ").filter_map(|x| x.trim().parse().ok()).collect())
        .unwrap_or_default();
    let [best, seed] = figures[..] else { panic!("`best against seed` in {}", lines[against]) };
    match &lines[against + 1..] {
        [] => assert!(best <= seed, "nothing beat the seed and nothing says how to search longer: {stdout}"),
        [longer] => {
            assert!(best >= seed, "the best beat the seed, yet: {longer}");
            assert!(
                longer.starts_with("longer    nothing beat the seed on the test scenes in 2 generations"),
                "{longer}"
            );
            assert!(longer.contains("`--generations 20`"), "{longer}");
        }
        more => panic!("lines after the comparison: {more:?}"),
    }
    let fitness: f64 = stdout
        .lines()
        .find_map(|l| l.strip_prefix("fitness   ")?.split_whitespace().next()?.parse().ok())
        .unwrap_or_else(|| panic!("a fitness line: {stdout}"));
    assert!(fitness <= 1.0 + 1e-9, "never worse than the seed it is scored against: {fitness}");
}
