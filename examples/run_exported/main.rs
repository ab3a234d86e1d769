//! Runs a filter exported by `filterjit export --target wgsl` in a small wgpu
//! program, the way an engine would (see README.md beside this file): its
//! pre-pass, temporal stage and à-trous passes too, where the filter's
//! pipeline has them.
//!
//!     cargo run --release --example run_exported -- SHADER.wgsl SCENE [RADIUS] OUT.png
//!     cargo run --release --example run_exported -- SHADER.wgsl SEQ_DIR [RADIUS] OUT_DIR
//!
//! `--repeat N` first filters a single image N more times and prints the
//! median GPU work of a frame (from its submission to its end; the uploads
//! before it and the readback after it left out), what an engine pays.
//!
//! `host.rs` is the integration: plain wgpu and the manifest, nothing from
//! filterjit. This file only stands in for the engine's G-buffer: it loads a
//! filterjit scene (an EXR dataset), or a sequence's frames in order, to have
//! colour, features and motion vectors to feed in.

mod host;

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use filterjit::lang::{Feature, ScalarVar};
use filterjit::scene::{Request, Scene};

fn main() -> Result<(), String> {
    // Mesa's Vulkan device-select layer looks for a display and complains
    // without one; this program picks its adapter through wgpu anyway.
    if std::env::var_os("NODEVICE_SELECT").is_none() {
        std::env::set_var("NODEVICE_SELECT", "1");
    }
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let repeats = match args.iter().position(|a| a == "--repeat") {
        Some(at) => {
            let n = args.get(at + 1).and_then(|n| n.parse::<usize>().ok()).ok_or("--repeat takes a count")?;
            args.drain(at..at + 2);
            n
        }
        None => 0,
    };
    let (shader, input, radius, out) = match args.as_slice() {
        [shader, input, out] => (shader, input, None, out),
        [shader, input, radius, out] => (shader, input, Some(radius.parse().map_err(|_| "RADIUS is a number")?), out),
        _ => return Err("usage: run_exported SHADER.wgsl SCENE|SEQ_DIR [RADIUS] OUT.png|OUT_DIR".into()),
    };
    let manifest_path = format!("{shader}.json");
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&manifest_path).map_err(|e| format!("{manifest_path}: {e}"))?)
            .map_err(|e| format!("{manifest_path}: {e}"))?;
    // wgpu takes WGSL; another language's export is for another host.
    if manifest["target"] != "wgsl" {
        return Err(format!(
            "{shader}: exported for {} ({}); this host runs WGSL (export with -o NAME.wgsl)",
            manifest["target"], manifest["language"]
        ));
    }
    let wgsl = std::fs::read_to_string(shader).map_err(|e| format!("{shader}: {e}"))?;
    // A window form's radius: the one given, else the manifest's (what `filter` takes); à-trous forms read none.
    let radius = radius.or(manifest["radius"].as_u64().map(|r| r as u32)).unwrap_or(0);

    // The other shaders the frame dispatches (the pre-pass's, the spread's…) are files beside the form's.
    let mut stages = HashMap::new();
    for step in manifest["frame"].as_array().ok_or(format!("{manifest_path}: no `frame`"))? {
        let Some(name) = step["dispatch"]["shader"].as_str().filter(|name| *name != "form") else { continue };
        let file = Path::new(shader).with_file_name(manifest[name]["file"].as_str().ok_or("a stage's file")?);
        if !stages.contains_key(name) {
            let code = std::fs::read_to_string(&file).map_err(|e| format!("{}: {e}", file.display()))?;
            stages.insert(name.to_string(), code);
        }
    }
    let temporal = stages.contains_key("temporal");
    let shaders = host::Shaders { form: wgsl, stages };

    // The engine's G-buffer stand-in: every input the manifest names.
    let inputs: Vec<&str> =
        manifest["inputs"].as_array().into_iter().flatten().filter_map(|i| i["image"].as_str()).collect();
    let roles: Vec<String> = manifest["bindings"]
        .as_array()
        .into_iter()
        .flatten()
        .filter(|b| b.get("scale_index").is_some())
        .filter_map(|b| b["role"].as_str().map(str::to_string))
        .collect();
    let mut request = Request { reference: false, motion: temporal, ..Default::default() };
    for role in &roles {
        if let Some(f) = Feature::from_name(role) {
            request.features.insert(f);
        } else if let Some(v) = ScalarVar::from_name(role) {
            request.variances.insert(v);
        }
    }
    // A pre-pass that demodulates divides by the raw albedo; the temporal stage compares it.
    request.albedo = inputs.contains(&"albedo");
    if inputs.contains(&"normal") {
        request.features.insert(Feature::Normal);
    }

    let (device, queue) = host::open_device()?;
    let input = PathBuf::from(input);
    if !filterjit::scene::is_sequence(&input) {
        if temporal {
            return Err(format!("{shader} is a temporal filter: give it a sequence's folder of frames"));
        }
        let scene = filterjit::scene::load(&input, &request).map_err(|e| e.to_string())?;
        let frame = frame(&scene, &roles)?;
        let mut times = Vec::new();
        for _ in 0..repeats {
            let mut alone = host::Sequence::new();
            host::filter_frame(&device, &queue, &shaders, &manifest, &frame, radius, &mut alone)?;
            times.extend(alone.gpu_time);
        }
        if !times.is_empty() {
            times.sort();
            let median = times[times.len() / 2];
            println!(
                "GPU work a frame: {:.1} ms (median of {}; the first compiles; uploads and readback left out)",
                median.as_secs_f64() * 1e3,
                times.len()
            );
        }
        let filtered = host::filter(&device, &queue, &shaders, &manifest, &frame, radius)?;
        write_png(&scene, &filtered, Path::new(out))?;
        println!("filtered {}x{} with radius {radius}: wrote {out}", scene.width, scene.height);
        return Ok(());
    }
    // A sequence: its frames in order, what the manifest's `keep` steps copy kept between them.
    let sequence = filterjit::scene::Sequence::find(&input).map_err(|e| e.to_string())?;
    std::fs::create_dir_all(out).map_err(|e| format!("{out}: {e}"))?;
    let mut kept = host::Sequence::new();
    for k in 0..sequence.frames.len() {
        let scene = sequence.load(k, &request).map_err(|e| e.to_string())?;
        let filtered =
            host::filter_frame(&device, &queue, &shaders, &manifest, &frame(&scene, &roles)?, radius, &mut kept)?;
        let name = sequence.frames[k].path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        write_png(&scene, &filtered, &Path::new(out).join(format!("{name}.png")))?;
    }
    println!("filtered {} frames with radius {radius}: wrote {out}", sequence.frames.len());
    Ok(())
}

/// The frame as the host takes it: colour, the manifest's inputs, and for
/// the temporal stage the albedo, the surface and the motion vectors.
fn frame(scene: &Scene, roles: &[String]) -> Result<host::Frame, String> {
    let rgba = |v: &[f32; 3]| [v[0], v[1], v[2], 1.0];
    let mut inputs = HashMap::new();
    for role in roles {
        let texels: Vec<[f32; 4]> = match (Feature::from_name(role), ScalarVar::from_name(role)) {
            (Some(f), _) => scene.feature(f).ok_or(format!("scene lacks {role}"))?.iter().map(rgba).collect(),
            (_, Some(v)) => {
                scene.variance(v).ok_or(format!("scene lacks {role}"))?.iter().map(|x| [*x, 0.0, 0.0, 0.0]).collect()
            }
            _ => return Err(format!("unknown input `{role}` in the manifest")),
        };
        inputs.insert(role.clone(), texels);
    }
    if let Some(normal) = scene.feature(Feature::Normal) {
        inputs.entry("normal".to_string()).or_insert_with(|| normal.iter().map(rgba).collect());
    }
    if let Some(albedo) = &scene.albedo {
        inputs.insert("albedo".to_string(), albedo.iter().map(rgba).collect());
    }
    if let Some(motion) = &scene.motion {
        inputs.insert("geometry".to_string(), motion.surface.clone());
        inputs.insert("motion".to_string(), motion.vectors.iter().map(|v| [v[0], v[1], 0.0, 0.0]).collect());
    }
    Ok(host::Frame {
        width: scene.width as u32,
        height: scene.height as u32,
        color: scene.color.iter().map(rgba).collect(),
        inputs,
        // filterjit's scenes hold normalised features already.
        scales: HashMap::new(),
    })
}

fn write_png(scene: &Scene, filtered: &[[f32; 4]], out: &Path) -> Result<(), String> {
    let rgb: Vec<[f32; 3]> = filtered.iter().map(|c| [c[0], c[1], c[2]]).collect();
    filterjit::preview::write_png(out, scene.width, scene.height, &rgb).map_err(|e| e.to_string())
}
