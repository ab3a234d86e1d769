//! Blender Cycles renders, as Blender writes them: the committed 64² render
//! (`tests/data/cycles-64`, made by `scenes/blender/render.py`), a fresh one
//! from the Blender on this machine, and files with other view layers and
//! passes than filterjit expects.

use std::path::{Path, PathBuf};
use std::process::Command;

use filterjit::scene::exr_io;

use crate::cli::{filterjit, relmse};
use crate::common::temp_dir;

fn committed() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/cycles-64")
}

/// `filterjit filter DATASET -o OUT` with no other flag: it picks a shipped
/// filter, says which and why, and lowers relMSE against the reference.
fn filters_and_beats_noisy(dataset: &Path) -> (f64, f64, String) {
    let out = temp_dir("blender", "filtered").join("out.exr");
    let o = filterjit(&["filter", dataset.to_str().unwrap(), "-o", out.to_str().unwrap()]);
    let (stdout, stderr) = (String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    assert!(o.status.success(), "{stderr}");
    assert!(stdout.contains("Blender Cycles (multilayer EXR)"), "read as a Cycles render: {stdout}");
    let chosen = stderr.lines().find(|l| l.starts_with("filter ")).unwrap_or_else(|| panic!("says which: {stderr}"));
    // Cycles writes no per-pixel variance: the filter taken reads none.
    let name = chosen.split_whitespace().nth(1).unwrap_or_default();
    let expr = filterjit::corpus::resolve_with_pipeline(name).unwrap_or_else(|e| panic!("{chosen}: {e}")).expr;
    let variance = filterjit::lang::ScalarVar::ColorVariance;
    assert!(!expr.stored_variables().contains(&variance), "reads no variance: {chosen}");
    let (noisy, filtered) = (relmse(&stdout, "noisy"), relmse(&stdout, "filtered"));
    assert!(filtered < 0.5 * noisy, "{}: relMSE {filtered} against the noisy input's {noisy}", dataset.display());
    assert!(out.is_file() && out.with_extension("png").is_file());
    (noisy, filtered, chosen.to_string())
}

#[test]
fn a_committed_cycles_render_filters_end_to_end_with_no_flag() {
    let (noisy, filtered, chosen) = filters_and_beats_noisy(&committed());
    eprintln!("cycles-64: relMSE {noisy:.3} → {filtered:.3} with {chosen}");
}

/// The Blender on this machine renders the scene anew (32², 4 spp, a
/// 64-spp reference: seconds), and filterjit reads what it writes today: the
/// same channels as the committed file, filtered end to end. Runs where
/// `blender` is on PATH; CI installs it and requires it.
#[test]
fn blender_renders_a_dataset_that_filterjit_reads() {
    let found = Command::new("blender").arg("--version").output().is_ok_and(|o| o.status.success());
    if !found {
        assert!(
            std::env::var_os("CI").is_none() && std::env::var_os("FILTERJIT_REQUIRE_BLENDER").is_none(),
            "blender is required in CI (.ci/run installs it) and not found"
        );
        eprintln!("\n*** SKIPPED blender_renders_a_dataset_that_filterjit_reads: no blender on PATH ***\n");
        return;
    }
    let dir = temp_dir("blender", "render").join("dataset");
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/blender/render.py");
    let o = Command::new("blender")
        .args(["-b", "--factory-startup", "-P"])
        .arg(&script)
        .arg("--")
        .arg(&dir)
        .args(["32", "4", "64"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    for file in ["noisy.exr", "reference.exr"] {
        let (fresh, ..) = exr_io::channel_names(&dir.join(file)).unwrap();
        let (kept, ..) = exr_io::channel_names(&committed().join(file)).unwrap();
        assert_eq!(fresh, kept, "{file}: the committed render has the channels Blender writes today");
    }
    // As a user names a render: the noisy file itself, its reference found beside it.
    filters_and_beats_noisy(&dir.join("noisy.exr"));
}

/// A copy of the committed render's noisy image, each channel saved under
/// the names `rename` gives it (none: dropped).
fn renamed(name: &str, rename: impl Fn(&str) -> Vec<String>) -> PathBuf {
    let source = committed().join("noisy.exr");
    let (names, width, height) = exr_io::channel_names(&source).unwrap();
    let refs: Vec<&str> = names.iter().map(String::as_str).collect();
    let data = exr_io::read_channels(&source, &refs).unwrap().data;
    let channels: Vec<(String, Vec<f32>)> = names
        .iter()
        .zip(&data)
        .flat_map(|(n, values)| rename(n).into_iter().map(move |new| (new, values.clone())))
        .collect();
    let borrowed: Vec<(&str, Vec<f32>)> = channels.iter().map(|(n, v)| (n.as_str(), v.clone())).collect();
    let file = temp_dir("blender", name).join("noisy.exr");
    exr_io::write_channels(&file, width, height, &borrowed).unwrap();
    file
}

#[test]
fn a_blender_file_with_other_layers_or_passes_is_named_in_the_error() {
    let out = temp_dir("blender", "errors").join("out.exr");
    let out = out.to_str().unwrap();
    let filter = |args: &[&str], file: &Path| {
        let file = file.to_str().unwrap();
        let o = filterjit(&[&["filter"], args, &[file, "-o", out]].concat());
        (o.status.success(), String::from_utf8_lossy(&o.stderr).into_owned())
    };
    // Two view layers: the one asked for is read; without asking, or asking
    // for one that is not there, the file and its layers are named.
    let two = renamed("two-layers", |n| {
        let pass = n.strip_prefix("ViewLayer.").unwrap();
        vec![format!("Left.{pass}"), format!("Right.{pass}")]
    });
    let (ok, stderr) = filter(&["--expr", "@crossBilateralAtrous"], &two);
    assert!(!ok && stderr.contains("several view layers (Left, Right)") && stderr.contains("--view-layer"), "{stderr}");
    assert!(stderr.contains(two.to_str().unwrap()), "names the file: {stderr}");
    let (ok, stderr) = filter(&["--expr", "@crossBilateralAtrous", "--view-layer", "Middle"], &two);
    assert!(!ok && stderr.contains("no view layer `Middle` (the file has: Left, Right)"), "{stderr}");
    let (ok, stderr) = filter(&["--expr", "@crossBilateralAtrous", "--view-layer", "Right"], &two);
    assert!(ok, "{stderr}");

    // Without the Denoising Data and Normal passes: the missing pass is named, and where Blender enables it.
    let bare = renamed("bare", |n| if n.contains("Normal") { vec![] } else { vec![n.to_string()] });
    let (ok, stderr) = filter(&["--expr", "@crossBilateralAtrous"], &bare);
    assert!(!ok && stderr.contains("no `normal`") && stderr.contains("Denoising Data"), "{stderr}");
    assert!(stderr.contains(bare.to_str().unwrap()), "names the file: {stderr}");
    // No Combined pass at all: the file and the passes looked for are named.
    let dark = renamed("no-combined", |n| if n.contains("Combined") { vec![] } else { vec![n.to_string()] });
    let (ok, stderr) = filter(&["--expr", "@bilateral"], &dark);
    assert!(!ok && stderr.contains(dark.to_str().unwrap()) && stderr.contains("Combined.R"), "{stderr}");
}

/// Today's Blender renders short sequences (`render_cycles.py`, 3 frames at
/// 48² and 128², 16 spp: seconds each): `colonnade-climb`, whose camera climbs as it
/// slides, and `study`, whose camera dollies in at an angle past a moving
/// object. Each one's Vector pass, read as filterjit reads it (x right, y
/// up), moves the frame before's albedo onto the frame's, and read with y
/// down does not; and each sequence filters end to end with no flag. Runs
/// where `blender` is on PATH; CI installs it and requires it.
#[test]
fn blenders_vector_pass_reads_y_up_on_a_sequence_rendered_today() {
    let found = Command::new("blender").arg("--version").output().is_ok_and(|o| o.status.success());
    if !found {
        assert!(
            std::env::var_os("CI").is_none() && std::env::var_os("FILTERJIT_REQUIRE_BLENDER").is_none(),
            "blender is required in CI (.ci/run installs it) and not found"
        );
        eprintln!(
            "\n*** SKIPPED blenders_vector_pass_reads_y_up_on_a_sequence_rendered_today: no blender on PATH ***\n"
        );
        return;
    }
    // The study's dolly moves its pixels less than a pixel a frame at 48².
    for (scene, side) in [("colonnade-climb", "48"), ("study", "128")] {
        vector_pass_reads_y_up(scene, side);
    }
}

fn vector_pass_reads_y_up(scene: &str, side: &str) {
    let dir = temp_dir("blender", &format!("{scene}-sequence"));
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/blender/render_cycles.py");
    let noisy = dir.join("noisy");
    let o = Command::new("blender")
        .args(["-b", "--factory-startup", "-noaudio", "-P"])
        .arg(&script)
        .arg("--")
        .arg(scene)
        .arg(&noisy)
        .args(["16", "7", side, "3"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    let sequence = filterjit::scene::Sequence::find(&noisy).unwrap();
    assert_eq!(sequence.frames.len(), 3);
    let request = filterjit::scene::Request { motion: true, albedo: true, ..Default::default() };
    let scenes: Vec<_> = (0..3).map(|k| sequence.load(k, &request).unwrap()).collect();
    for pair in scenes.windows(2) {
        let (a0, a1) = (pair[0].albedo.as_ref().unwrap(), pair[1].albedo.as_ref().unwrap());
        let moved = crate::temporal::moved_difference((a0, a1), &pair[1], [1.0, 1.0]);
        let down = crate::temporal::moved_difference((a0, a1), &pair[1], [1.0, -1.0]);
        let still = crate::temporal::moved_difference((a0, a1), &pair[1], [0.0, 0.0]);
        eprintln!("{scene} {}: moved {moved:.4}, with y down {down:.4}, still {still:.4}", pair[1].name);
        assert!(
            moved < 0.8 * down && moved < 0.8 * still,
            "{scene} {}: moved {moved}, y down {down}, still {still}",
            pair[1].name
        );
    }
    let out = dir.join("out");
    let o = filterjit(&["filter", noisy.to_str().unwrap(), "-o", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(out.join("frame_0003.exr").is_file() && out.join("animation.png").is_file(), "{scene}");
}
