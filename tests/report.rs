//! `filterjit report` and `filterjit tune`: the folder a user opens, and the
//! tuned baseline.

use std::path::Path;
use std::process::Command;

use filterjit::evolve::GpuEvaluator;
use filterjit::lang::Feature;
use filterjit::tune::{self, Sigmas};

use crate::common::{gpu, mitsuba_sample, synthetic_scene, temp_dir};

fn filterjit(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_filterjit")).args(args).output().expect("the binary runs")
}

/// Every `src="…"` and `href="…"` of the index names a file in the folder.
fn links_resolve(dir: &Path) {
    let html = std::fs::read_to_string(dir.join("index.html")).unwrap();
    let mut count = 0;
    for attr in ["src=\"", "href=\""] {
        for piece in html.split(attr).skip(1) {
            let target = piece.split('"').next().unwrap();
            assert!(dir.join(target).is_file(), "index.html links {target}, which is missing");
            count += 1;
        }
    }
    assert!(count >= 10, "the index links its tables and pictures ({count} links)");
}

#[test]
fn a_report_on_the_mitsuba_sample_writes_a_complete_folder() {
    let dir = temp_dir("report", "mitsuba");
    let hall = dir.join("hall_of_fame.txt");
    std::fs::write(
        &hall,
        "# fitness 0.1\nisland0_rank1 = exp(-(pow(distance2(pixel), 2) / 8 + pow(distance2(color), 2) / 0.5 + pow(distance2(normal), 2) / 0.02))\n\
         island1_rank1 = exp(-distance2(color) * 4) * exp(-distance1(texture))\nisland2_rank1 = exp(-distance2(color) * 4) * exp(-distance1(texture))\n",
    )
    .unwrap();
    let out = dir.join("report");
    let sample = mitsuba_sample();
    let o = filterjit(&[
        "report",
        "@bilateral",
        "--scenes",
        sample.to_str().unwrap(),
        "--hall-of-fame",
        hall.to_str().unwrap(),
        "--baseline",
        "@crossBilateralTuned",
        "--radius",
        "3",
        "--repeats",
        "1",
        "--timing-size",
        "64",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for file in ["index.html", "results.md", "results.csv", "results.json", "plots/mean.svg", "features.svg"] {
        assert!(out.join(file).is_file(), "{file} is written");
    }
    links_resolve(&out);

    let results: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap()).unwrap();
    let cells = results["cells"].as_array().unwrap();
    let cell = |method: &str| cells.iter().find(|c| c["method"] == method).unwrap_or_else(|| panic!("no {method}"));
    let noisy = cell("noisy")["relmse"].as_f64().unwrap();
    assert!((noisy - 0.2053).abs() < 1e-3, "the sample's noisy relMSE is 0.2053, got {noisy}");
    // The sample has no direct-illumination channel: the thesis's expressions cannot run, and say why.
    let reason = cell("thesis1")["unavailable"].as_str().unwrap();
    assert!(reason.contains("directIllumination"), "{reason}");
    for method in ["crossBilateralTuned", "bilateral", "island0_rank1", "island1_rank1"] {
        let c = cell(method);
        let relmse = c["relmse"].as_f64().unwrap();
        assert!(relmse < noisy, "{method} filters: {relmse} vs noisy {noisy}");
        assert!(c["ms_per_mpx"].as_f64().unwrap() > 0.0, "{method} is timed");
    }
    // Duplicates in the hall of fame are reported once.
    assert!(cells.iter().all(|c| c["method"] != "island2_rank1"));
    // Feature usage counts both hall-of-fame entries' features.
    assert_eq!(results["feature_usage"]["texture"], 2);
    let md = std::fs::read_to_string(out.join("results.md")).unwrap();
    assert!(md.contains("| thesis1 | n/a: the scene has no directIllumination"), "{md}");
    let csv = std::fs::read_to_string(out.join("results.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + cells.len(), "one CSV row per cell");
    // The crops: one per method that ran, plus noisy and reference, and the strip.
    let crops = out.join("crops").join("mitsuba-cornell-64");
    assert_eq!(std::fs::read_dir(&crops).unwrap().count(), 2 + 4);
    assert!(out.join("crops/mitsuba-cornell-64.png").is_file());
}

#[test]
fn tuning_improves_on_the_hand_set_sigmas_and_reports_what_it_found() {
    let gpu = gpu();
    let scenes = vec![synthetic_scene(24, 20, 5), synthetic_scene(20, 24, 6)];
    let mut evaluator = GpuEvaluator::new(&gpu, scenes, 2, 2).unwrap();
    let mut steps = 0;
    let tuned = tune::tune(&mut evaluator, 1, &mut |_, _| steps += 1).unwrap();
    assert!(steps >= 6, "one report per sigma and one at the start");
    assert!(tuned.fitness < tuned.hand_set_fitness, "{} vs {}", tuned.fitness, tuned.hand_set_fitness);
    // The reported fitness is the reported expression's.
    let expr = filterjit::parse_expr(&tuned.expr).unwrap();
    assert_eq!(expr, tuned.sigmas.expr());
    let again = evaluator.errors(std::slice::from_ref(&expr)).unwrap().remove(0).unwrap();
    let noisy = evaluator.noisy_relmse().to_vec();
    let fitness = again.iter().zip(&noisy).map(|(s, n)| s.relmse / n).sum::<f64>() / noisy.len() as f64;
    assert!((fitness - tuned.fitness).abs() < 1e-12, "{fitness} vs {}", tuned.fitness);
    // Every term the scenes provide is tuned.
    let all: std::collections::BTreeSet<Feature> = tune::TERMS.into_iter().collect();
    assert_eq!(tuned.sigmas.0.len(), Sigmas::hand_set(&all).0.len());
}

#[test]
fn report_refuses_bad_input_naming_it() {
    let dir = temp_dir("report", "bad");
    let hall = dir.join("hof.txt");
    std::fs::write(&hall, "a = exp(-distance2(color)\n").unwrap();
    let sample = mitsuba_sample();
    let o = filterjit(&[
        "report",
        "--scenes",
        sample.to_str().unwrap(),
        "--hall-of-fame",
        hall.to_str().unwrap(),
        "--baseline",
        "@crossBilateral",
        "-o",
        dir.join("r").to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("hof.txt") && err.contains("entry `a`"), "{err}");
    let o =
        filterjit(&["report", "--run", dir.join("nothing").to_str().unwrap(), "-o", dir.join("r").to_str().unwrap()]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("nothing"), "names the missing run");
}
