//! `filterjit report` and `filterjit tune`: the folder a user opens, and the
//! tuned baseline.

use std::path::{Path, PathBuf};
use std::process::Command;

use filterjit::fitness::{Scorer, Settings};
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
        // Also a default baseline: listed once.
        "@svgfAtrous",
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
        "--no-oidn",
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
    let noisy_flip = cell("noisy")["flip"].as_f64().unwrap();
    assert!(noisy_flip > 0.0 && noisy_flip < 1.0, "HDR-FLIP lies in (0, 1): {noisy_flip}");
    for method in ["crossBilateralTuned", "svgfAtrous", "bilateral", "island0_rank1", "island1_rank1"] {
        let c = cell(method);
        let relmse = c["relmse"].as_f64().unwrap();
        assert!(relmse < noisy, "{method} filters: {relmse} vs noisy {noisy}");
        assert!(c["ms_per_mpx"].as_f64().unwrap() > 0.0, "{method} is timed");
        let flip = c["flip"].as_f64().unwrap();
        assert!(flip > 0.0 && flip < 1.0, "{method}: HDR-FLIP {flip}");
    }
    // The tuned cross-bilateral keeps edges and looks better than the noisy
    // input; the plain bilateral blurs them and looks worse, for all its lower relMSE.
    assert!(cell("crossBilateralTuned")["flip"].as_f64().unwrap() < noisy_flip);
    assert!(cell("bilateral")["flip"].as_f64().unwrap() > noisy_flip);
    let named = |name: &str| results["methods"].as_array().unwrap().iter().filter(|m| m["name"] == name).count();
    assert_eq!(named("svgfAtrous"), 1, "a method given twice is listed once");
    // Duplicates in the hall of fame are reported once.
    assert!(cells.iter().all(|c| c["method"] != "island2_rank1"));
    // Feature usage counts both hall-of-fame entries' features.
    assert_eq!(results["feature_usage"]["texture"], 2);
    let md = std::fs::read_to_string(out.join("results.md")).unwrap();
    assert!(md.contains("| thesis1 | n/a: the scene has no directIllumination"), "{md}");
    assert!(md.contains("| HDR-FLIP |"), "{md}");
    let html = std::fs::read_to_string(out.join("index.html")).unwrap();
    assert!(html.contains("<th>HDR-FLIP</th>"), "the page shows HDR-FLIP");
    let csv = std::fs::read_to_string(out.join("results.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + cells.len(), "one CSV row per cell");
    assert!(csv.lines().next().unwrap().contains(",hdr_flip,"));
    // The crops: one per method that ran, plus noisy and reference, and the strip.
    let crops = out.join("crops").join("mitsuba-cornell-64");
    assert_eq!(std::fs::read_dir(&crops).unwrap().count(), 2 + 5);
    assert!(out.join("crops/mitsuba-cornell-64.png").is_file());
}

/// Report with OIDN as the peer: `program` is FILTERJIT_OIDN. Returns results.json.
fn report_with_oidn(name: &str, program: &Path) -> serde_json::Value {
    let out = temp_dir("report", name).join("report");
    report_with_oidn_in(&out, program)
}

/// [`report_with_oidn`] into the folder `out`.
fn report_with_oidn_in(out: &Path, program: &Path) -> serde_json::Value {
    let out = out.to_path_buf();
    let sample = mitsuba_sample();
    let o = Command::new(env!("CARGO_BIN_EXE_filterjit"))
        .args(["report", "--scenes", sample.to_str().unwrap(), "--baseline", "@crossBilateralAtrous"])
        .args(["--repeats", "1", "--timing-size", "64", "-o", out.to_str().unwrap()])
        .env("FILTERJIT_OIDN", program)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    assert!(stderr.contains("Intel Open Image Denoise"), "{stderr}");
    links_resolve(&out);
    let md = std::fs::read_to_string(out.join("results.md")).unwrap();
    assert!(md.contains("OIDN colour+albedo+normal"), "{md}");
    let crops = out.join("crops/mitsuba-cornell-64");
    assert!(crops.join("OIDN_colour.png").is_file() && crops.join("OIDN_colour_albedo_normal.png").is_file());
    assert!(!out.join("oidn").exists(), "OIDN's working files are not left in the report");
    serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap()).unwrap()
}

/// The plumbing, with a stand-in for `oidnDenoise` that hands back its input:
/// OIDN's rows are in every table with the program's own times, its images are
/// read back in the right orientation (the stand-in's output is the noisy input).
/// A stand-in for `oidnDenoise` in `dir` that hands back its input and reports 2.5 ms per run.
fn fake_oidn(dir: &Path) -> PathBuf {
    let program = dir.join("oidnDenoise");
    std::fs::write(
        &program,
        "#!/bin/sh\nout=''; n=1\nwhile [ $# -gt 0 ]; do case \"$1\" in --hdr) in=\"$2\"; shift;; -o) out=\"$2\"; shift;; -n) n=\"$2\"; shift;; esac; shift; done\n\
         cp \"$in\" \"$out\"\ni=0; while [ $i -lt $n ]; do echo Denoising; echo \"  msec=2.5, hash=0\"; i=$((i+1)); done\n",
    )
    .unwrap();
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&program, std::fs::Permissions::from_mode(0o755)).unwrap();
    }
    program
}

#[test]
fn the_report_runs_oidn_as_the_peer_through_its_program() {
    let program = fake_oidn(&temp_dir("report", "fake-oidn"));
    let results = report_with_oidn("fake", &program);
    let cells = results["cells"].as_array().unwrap();
    let cell = |method: &str| cells.iter().find(|c| c["method"] == method).unwrap_or_else(|| panic!("no {method}"));
    let noisy = cell("noisy")["relmse"].as_f64().unwrap();
    for method in ["OIDN colour", "OIDN colour+albedo+normal"] {
        let c = cell(method);
        let relmse = c["relmse"].as_f64().unwrap();
        assert!((relmse - noisy).abs() < 1e-6 * noisy, "{method}: the stand-in returns the input, {relmse} vs {noisy}");
        let mpx = 64.0 * 64.0 / 1e6;
        assert!((c["ms_per_mpx"].as_f64().unwrap() - 2.5 / mpx).abs() < 1e-6, "the program's own time per run");
    }
    let peers: Vec<&serde_json::Value> =
        results["methods"].as_array().unwrap().iter().filter(|m| m["origin"] == "peer").collect();
    assert_eq!(peers.len(), 2);
    // Every error against the peer's, scene by scene and on the mean.
    let peer = cell("OIDN colour+albedo+normal")["relmse"].as_f64().unwrap();
    for c in cells.iter().filter(|c| c["relmse"].is_f64()) {
        let ratio = c["vs_peer"].as_f64().unwrap();
        assert!((ratio - c["relmse"].as_f64().unwrap() / peer).abs() < 1e-9, "{c}");
    }
    let oidn = peers.iter().find(|m| m["name"] == "OIDN colour+albedo+normal").unwrap();
    assert!((oidn["mean_vs_peer"].as_f64().unwrap() - 1.0).abs() < 1e-12);
}

/// The real OIDN where it is installed (CI installs `pyoidn`; FILTERJIT_REQUIRE_OIDN=1 makes its absence a failure).
#[test]
fn the_real_oidn_denoises_the_mitsuba_sample() {
    let env = crate::common::environment();
    let program = match filterjit::oidn::Oidn::find(env.oidn.as_deref(), env.path.as_deref()) {
        Ok(oidn) => oidn.program,
        Err(why) if std::env::var_os("FILTERJIT_REQUIRE_OIDN").is_some() => panic!("OIDN is required here: {why}"),
        Err(why) => {
            eprintln!("SKIPPED the_real_oidn_denoises_the_mitsuba_sample: {why}");
            return;
        }
    };
    let results = report_with_oidn("real", &program);
    let cells = results["cells"].as_array().unwrap();
    let relmse = |method: &str| cells.iter().find(|c| c["method"] == method).unwrap()["relmse"].as_f64().unwrap();
    let noisy = relmse("noisy");
    // On this 64² render OIDN reaches 0.18 (colour) and 0.37 (with its noisy 4-spp albedo and normals) of the
    // noisy relMSE; on the 256² Mitsuba renders this plumbing reproduces BASELINES.md's figures to 3 digits.
    let flip = |method: &str| cells.iter().find(|c| c["method"] == method).unwrap()["flip"].as_f64().unwrap();
    for method in ["OIDN colour", "OIDN colour+albedo+normal"] {
        assert!(relmse(method) < 0.5 * noisy, "{method}: {} against noisy {noisy}", relmse(method));
        assert!(flip(method) < flip("noisy"), "{method}: HDR-FLIP {} against noisy {}", flip(method), flip("noisy"));
    }
}

#[test]
fn tuning_improves_on_the_hand_set_sigmas_and_reports_what_it_found() {
    let gpu = gpu();
    let scenes = vec![synthetic_scene(24, 20, 5), synthetic_scene(20, 24, 6)];
    let mut evaluator = Scorer::new(&gpu, scenes, &Settings::window(2, 2)).unwrap();
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

/// A role asked for by name (`@realtime`) is reported as `filter` runs it:
/// on a scene whose median pixel is black (the built-in slot room at 4 spp)
/// its sparse-light variant runs under its name, and the CSV says so; on an
/// evenly lit one (the built-in Cornell box) it runs as itself.
#[test]
fn a_role_is_reported_as_filter_runs_it() {
    let filterjit::denoise::SparseLightVariant { base: role, variant, .. } = filterjit::denoise::SPARSE_LIGHT_VARIANTS
        .iter()
        .find(|v| filterjit::denoise::FOLLOWS_THE_LIGHT_WHEN_ASKED.contains(&v.base))
        .expect("a role with a variant");
    let dir = temp_dir("report", "role");
    let out = dir.join("r");
    let (role_arg, variant_arg) = (format!("@{role}"), format!("@{variant}"));
    let o = filterjit(&[
        "report",
        &role_arg,
        &variant_arg,
        "--scenes",
        "skylight-slot,cornell",
        "--size",
        "32x32",
        "--reference-spp",
        "64",
        "--baseline",
        "@crossBilateral",
        "--repeats",
        "1",
        "--timing-size",
        "32",
        "--no-oidn",
        "-o",
        out.to_str().unwrap(),
    ]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    assert!(stderr.contains(&format!("skylight-slot: {role} (as {variant}: its variant for sparse light")), "{stderr}");
    let csv = std::fs::read_to_string(out.join("results.csv")).unwrap();
    let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    let column = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let cell = |scene: &str, method: &str, name: &str| -> String {
        let row = csv.lines().find(|l| l.starts_with(&format!("{scene},{method},"))).unwrap_or_else(|| panic!("{csv}"));
        row.split(',').nth(column(name)).unwrap().to_string()
    };
    assert_eq!(cell("skylight-slot", role, "ran_instead"), *variant, "{csv}");
    assert_eq!(cell("skylight-slot", role, "relmse"), cell("skylight-slot", variant, "relmse"), "{csv}");
    assert_eq!(cell("cornell", role, "ran_instead"), "", "{csv}");
    assert_ne!(cell("cornell", role, "relmse"), cell("cornell", variant, "relmse"), "{csv}");
    // The summary and the expressions say what ran in its place.
    let md = std::fs::read_to_string(out.join("results.md")).unwrap();
    assert!(md.contains(&format!("{role} (as {variant} on 1 of its scenes")), "{md}");
    assert!(md.contains(&format!("{variant} (in {role}'s place where the light is sparse)")), "{md}");
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

/// The report opened as a person would: headless Chromium loads `index.html`
/// over HTTP, and the rendered page has the OIDN rows, the HDR-FLIP column,
/// its plots and its crops, every picture decoded; each scene's viewer shows
/// whole frames at full resolution, changes what it shows when a method is
/// chosen, the split is moved, the picture is clicked (it flips) or a crop is
/// clicked. Runs where Chromium is found (`chromium`, or FILTERJIT_CHROMIUM);
/// CI installs it and requires it (FILTERJIT_REQUIRE_CHROMIUM).
#[test]
fn the_report_renders_in_a_browser_with_its_rows_plots_crops_and_viewer() {
    use crate::common::browser::{chromium, Browser, Served};
    let Some(chromium) = chromium("the_report_renders_in_a_browser_with_its_rows_plots_crops_and_viewer") else {
        return;
    };
    let dir = temp_dir("report", "browser");
    let out = dir.join("report");
    report_with_oidn_in(&out, &fake_oidn(&dir));
    let served = Served::folder(&out);
    let mut browser = Browser::open(&chromium, &format!("{}index.html", served.url), dir.join("profile"));
    const LOADED: &str = "const loaded = (img) => img.complete ? (img.naturalWidth > 0 ? Promise.resolve() : \
        Promise.reject(new Error('broken: ' + img.src))) : new Promise((ok, fail) => { img.onload = ok; \
        img.onerror = () => fail(new Error('broken: ' + img.src)); });";
    let seen = browser.evaluate(&format!(
        r#"(async () => {{
  {LOADED}
  const images = [...document.images];
  await Promise.allSettled(images.map(loaded));
  return {{
    images: images.length,
    broken: images.filter(i => !(i.complete && i.naturalWidth > 0)).map(i => i.getAttribute("src")),
    svg: images.filter(i => i.getAttribute("src").endsWith(".svg")).length,
    crops: images.filter(i => i.getAttribute("src").startsWith("crops/")).length,
    headers: [...document.querySelectorAll("th")].map(t => t.textContent),
    rows: [...document.querySelectorAll("tr td:first-child")].map(t => t.textContent),
    height: document.body.scrollHeight,
  }};
}})()"#
    ));
    let strings = |seen: &serde_json::Value, key: &str| -> Vec<String> {
        seen[key].as_array().unwrap().iter().map(|v| v.as_str().unwrap().to_string()).collect()
    };
    assert!(strings(&seen, "broken").is_empty(), "pictures that did not load: {:?}", strings(&seen, "broken"));
    assert!(seen["svg"].as_u64().unwrap() >= 2, "the mean and per-scene scatter plots: {seen}");
    // noisy, the baseline, the OIDN peers and the reference, at least.
    assert!(seen["crops"].as_u64().unwrap() >= 5, "the crop strip: {seen}");
    let headers = strings(&seen, "headers");
    assert!(
        headers.iter().filter(|h| *h == "HDR-FLIP").count() >= 2,
        "HDR-FLIP in the mean and scene tables: {headers:?}"
    );
    let rows = strings(&seen, "rows");
    for peer in ["OIDN colour", "OIDN colour+albedo+normal"] {
        assert!(rows.iter().filter(|r| *r == peer).count() >= 2, "{peer} in the mean and scene tables: {rows:?}");
    }
    assert!(seen["height"].as_u64().unwrap() > 900, "a laid-out page, taller than one screen: {seen}");

    // The viewer, as a person uses it; what it shows, read from the page and from screenshots.
    let state = format!(
        r#"(async () => {{
  {LOADED}
  const viewer = document.querySelector(".viewer");
  const [a, b] = [viewer.querySelector("img.a"), viewer.querySelector("img.b")];
  await loaded(a); await loaded(b);
  viewer.scrollIntoView();
  return {{ a: a.getAttribute("src"), b: b.getAttribute("src"), clip: b.style.clipPath, label: viewer.querySelector(".label").textContent,
    natural: [a.naturalWidth, a.naturalHeight, b.naturalWidth], frame: [+viewer.dataset.width, +viewer.dataset.height] }};
}})()"#
    );
    let start = browser.evaluate(&state);
    assert_eq!(start["a"], "full/mitsuba-cornell-64/noisy.png", "{start}");
    assert_eq!(start["b"], "full/mitsuba-cornell-64/reference.png", "{start}");
    let (natural, frame) = (&start["natural"], &start["frame"]);
    assert_eq!([&natural[0], &natural[1]], [&frame[0], &frame[1]], "whole frames at full resolution: {start}");
    assert_eq!(start["clip"], "inset(0px 0px 0px 50%)", "split in the middle: {start}");
    let shot_split = browser.screenshot(1000, 800);
    // Click: the whole picture flips to one side; again: to the other.
    browser.evaluate("document.querySelector('.viewer .stage').click()");
    let flipped = browser.evaluate(&state);
    let shot_flipped = browser.screenshot(1000, 800);
    browser.evaluate("document.querySelector('.viewer .stage').click()");
    let back = browser.evaluate(&state);
    let shot_back = browser.screenshot(1000, 800);
    assert_ne!(flipped["clip"], start["clip"], "a click flips: {flipped}");
    assert_ne!(back["clip"], flipped["clip"], "a second click flips back: {back}");
    assert!(shot_split != shot_flipped && shot_flipped != shot_back, "flipping changes what the page shows");
    // A method chosen for the left side, then a crop clicked.
    browser
        .evaluate("document.querySelector('.viewer button[data-side=a][data-view=OIDN_colour_albedo_normal]').click()");
    let chosen = browser.evaluate(&state);
    assert_eq!(chosen["a"], "full/mitsuba-cornell-64/OIDN_colour_albedo_normal.png", "{chosen}");
    assert!(chosen["label"].as_str().unwrap().contains("left: OIDN colour+albedo+normal"), "{chosen}");
    browser.evaluate("document.querySelector('.crops figure[data-view=crossBilateralAtrous]').click()");
    let cropped = browser.evaluate(&state);
    assert_eq!(cropped["a"], "full/mitsuba-cornell-64/crossBilateralAtrous.png", "a crop clicked: {cropped}");
    let shot = dir.join("viewer.png");
    std::fs::write(&shot, browser.screenshot(1000, 800)).unwrap();
    eprintln!("the viewer, as shown: {}", shot.display());
}
