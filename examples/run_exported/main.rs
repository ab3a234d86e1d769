//! Runs a filter exported by `filterjit export --target wgsl` in a small wgpu
//! program, the way an engine would (see README.md beside this file): its
//! pre-pass and à-trous passes too, where the filter's pipeline has them.
//!
//!     cargo run --release --example run_exported -- SHADER.wgsl SCENE [RADIUS] OUT.png
//!
//! `host.rs` is the integration: plain wgpu and the manifest, nothing from
//! filterjit. This file only stands in for the engine's G-buffer: it loads a
//! filterjit scene (an EXR dataset) to have colour and features to feed in.

mod host;

use std::collections::HashMap;
use std::path::PathBuf;

use filterjit::lang::{Feature, ScalarVar};

fn main() -> Result<(), String> {
    // Mesa's Vulkan device-select layer looks for a display and complains
    // without one; this program picks its adapter through wgpu anyway.
    if std::env::var_os("NODEVICE_SELECT").is_none() {
        std::env::set_var("NODEVICE_SELECT", "1");
    }
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (shader, scene, radius, out) = match args.as_slice() {
        [shader, scene, out] => (shader, scene, 5, out),
        [shader, scene, radius, out] => (shader, scene, radius.parse().map_err(|_| "RADIUS is a number")?, out),
        _ => return Err("usage: run_exported SHADER.wgsl SCENE [RADIUS] OUT.png".into()),
    };
    let wgsl = std::fs::read_to_string(shader).map_err(|e| format!("{shader}: {e}"))?;
    let manifest_path = format!("{shader}.json");
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&manifest_path).map_err(|e| format!("{manifest_path}: {e}"))?)
            .map_err(|e| format!("{manifest_path}: {e}"))?;

    // The engine's G-buffer stand-in: every input the manifest names.
    let roles: Vec<String> = manifest["bindings"]
        .as_array()
        .into_iter()
        .flatten()
        .filter(|b| b.get("scale_index").is_some())
        .filter_map(|b| b["role"].as_str().map(str::to_string))
        .collect();
    let mut request = filterjit::scene::Request { reference: false, ..Default::default() };
    for role in &roles {
        if let Some(f) = Feature::from_name(role) {
            request.features.insert(f);
        } else if let Some(v) = ScalarVar::from_name(role) {
            request.variances.insert(v);
        }
    }
    // A pre-pass that demodulates divides by the raw albedo.
    let prepass = manifest.get("prepass").filter(|p| !p.is_null());
    request.albedo = prepass.is_some_and(|p| p["uniform_values"]["stages"].as_f64().unwrap_or(0.0) as u32 & 2 != 0);
    let scene = filterjit::scene::load(&PathBuf::from(scene), &request).map_err(|e| e.to_string())?;
    let rgba = |v: &[f32; 3]| [v[0], v[1], v[2], 1.0];
    let mut inputs = HashMap::new();
    for role in &roles {
        let texels: Vec<[f32; 4]> = match (Feature::from_name(role), ScalarVar::from_name(role)) {
            (Some(f), _) => scene.feature(f).ok_or(format!("scene lacks {role}"))?.iter().map(rgba).collect(),
            (_, Some(v)) => {
                scene.variance(v).ok_or(format!("scene lacks {role}"))?.iter().map(|x| [*x, 0.0, 0.0, 0.0]).collect()
            }
            _ => return Err(format!("unknown input `{role}` in the manifest")),
        };
        inputs.insert(role.clone(), texels);
    }
    if let Some(albedo) = &scene.albedo {
        inputs.insert("albedo".to_string(), albedo.iter().map(rgba).collect());
    }
    let frame = host::Frame {
        width: scene.width as u32,
        height: scene.height as u32,
        color: scene.color.iter().map(rgba).collect(),
        inputs,
        // filterjit's scenes hold normalised features already.
        scales: HashMap::new(),
    };

    let (device, queue) = host::open_device()?;
    // The pre-pass's, the spread's, the guide's and planefit's shaders, where the pipeline has them, are files beside the form's.
    let stage = |name: &str| -> Result<Option<String>, String> {
        let Some(stage) = manifest.get(name).filter(|p| !p.is_null()) else { return Ok(None) };
        let file = std::path::Path::new(shader).with_file_name(stage["file"].as_str().ok_or("a stage's file")?);
        Ok(Some(std::fs::read_to_string(&file).map_err(|e| format!("{}: {e}", file.display()))?))
    };
    let shaders = host::Shaders {
        form: wgsl,
        prepass: stage("prepass")?,
        spread: stage("spread")?,
        guide: stage("guide")?,
        planefit: stage("planefit")?,
    };
    let filtered = host::filter(&device, &queue, &shaders, &manifest, &frame, radius)?;
    let rgb: Vec<[f32; 3]> = filtered.iter().map(|c| [c[0], c[1], c[2]]).collect();
    filterjit::preview::write_png(&PathBuf::from(out), scene.width, scene.height, &rgb).map_err(|e| e.to_string())?;
    println!("filtered {}x{} with radius {radius}: wrote {out}", scene.width, scene.height);
    Ok(())
}
