//! The exported filter in a real browser: headless Chromium's WebGPU (Dawn,
//! its WGSL compiler Tint, SwiftShader underneath) runs `web/filterjit.js`
//! on exports written by `filterjit export`, as a page would.

use std::path::Path;
use std::process::Command;

use serde_json::{json, Value};

use filterjit::corpus;
use filterjit::export::{export_filter, Code, Target};
use filterjit::jit::OutputFormat;
use filterjit::pipeline::FilterPipeline;
use filterjit::scene::{self, Request};

use crate::common::browser::{chromium, Browser, Served};
use crate::common::{mitsuba_sample, temp_dir};

/// The module's output on the Mitsuba sample, against `filterjit filter`'s
/// (lavapipe or llvmpipe), relative to max(1, |value|). SwiftShader computes in
/// f32 too, but its `exp`, `pow`, `sqrt` and division may differ from Mesa's in
/// the last bits (WGSL allows 2.5 ULP for division, more for the
/// transcendental functions), and a weight's few-ULP change moves an output
/// by as much relative to its neighbours' spread. Measured on the default
/// shipped filter: 2.6e-7. 1e-5 leaves a margin for other CPUs and drivers;
/// a wrong binding, scale, stage or pass order moves outputs by whole
/// percent (a scale ignored: 0.19).
const TOLERANCE: f64 = 1e-5;

/// The same in the default output format, `rgba16float`: the pre-pass's
/// image and every pass's are rounded to half precision (2^-11 relative)
/// before the next reads them, and the rounding also moves the colour
/// distances that set the next pass's weights. Measured: 7.2e-3 here, and
/// 6.2e-3 for the same export through the plain-wgpu host on lavapipe, so
/// it is the format's, not the browser's.
const HALF_TOLERANCE: f64 = 2e-2;

/// A page served from `dir` with the module beside it (and whatever else
/// the test wrote there to fetch), open in Chromium.
fn page(dir: &Path) -> (Served, Browser) {
    std::fs::copy(Path::new(env!("CARGO_MANIFEST_DIR")).join("web/filterjit.js"), dir.join("filterjit.js")).unwrap();
    std::fs::write(dir.join("index.html"), "<!doctype html><title>filterjit test</title>\n").unwrap();
    let chromium = chromium("the browser tests").expect("checked by the caller");
    let served = Served::folder(dir);
    let browser = Browser::open(&chromium, &format!("{}index.html", served.url), dir.join("profile"));
    (served, browser)
}

/// A WebGPU device in the page, with WebGPU's default limits (none requested).
const DEVICE: &str = r#"
  const adapter = await navigator.gpu.requestAdapter();
  if (!adapter) throw new Error("no WebGPU adapter");
  const device = await adapter.requestDevice();
"#;

/// `filterjit export` → `web/filterjit.js` in Chromium → the same frame as
/// `filterjit filter` writes, through the default shipped filter's whole
/// pipeline (pre-pass, `keep=surface`'s spread with its total, the guide,
/// four à-trous passes, remodulation, `planefit`).
#[test]
fn the_web_module_runs_an_exported_filter_as_filter_does() {
    if chromium("the_web_module_runs_an_exported_filter_as_filter_does").is_none() {
        return;
    }
    let dir = temp_dir("browser", "module");
    let name = "@evolvedAtrous64Plane";
    let bin = env!("CARGO_BIN_EXE_filterjit");
    let shader = dir.join("denoise.wgsl");
    let o = Command::new(bin).args(["export", name, "--format", "rgba32float", "-o"]).arg(&shader).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // And in the default output format, half precision, as an engine would take it.
    let o = Command::new(bin).args(["export", name, "-o"]).arg(dir.join("half.wgsl")).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let manifest: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("denoise.wgsl.json")).unwrap()).unwrap();
    assert!(manifest["spread"].is_object(), "the default filter keeps what its clamp removes");
    assert!(manifest["guide"].is_object(), "the default filter compares the guide");
    assert!(manifest["planefit"].is_object(), "the default filter fits planes after the form");

    // The render's inputs as an engine holds them: what `filter` reads, at
    // twice its normalised value with scale 0.5 (exact in binary floating point).
    let sample = mitsuba_sample();
    let expr = corpus::resolve_with_pipeline(name).unwrap().expr;
    let mut request = Request::for_expr(&expr);
    request.albedo = true;
    let scene = scene::load(&sample, &request).unwrap();
    let rgba = |v: &[f32; 3], k: f32| vec![k * v[0], k * v[1], k * v[2], 1.0];
    let mut inputs = serde_json::Map::new();
    let mut scales = serde_json::Map::new();
    for b in manifest["bindings"].as_array().unwrap().iter().filter(|b| b.get("scale_index").is_some()) {
        let role = b["role"].as_str().unwrap();
        let texels: Vec<f32> =
            match (filterjit::lang::Feature::from_name(role), filterjit::lang::ScalarVar::from_name(role)) {
                (Some(f), _) => scene.feature(f).unwrap().iter().flat_map(|v| rgba(v, 2.0)).collect(),
                (_, Some(v)) => scene.variance(v).unwrap().iter().flat_map(|x| [2.0 * x, 0.0, 0.0, 0.0]).collect(),
                _ => panic!("the manifest names an unknown input `{role}`"),
            };
        inputs.insert(role.into(), json!(texels));
        scales.insert(role.into(), json!(0.5));
    }
    let albedo: Vec<f32> = scene.albedo.as_ref().unwrap().iter().flat_map(|a| rgba(a, 1.0)).collect();
    inputs.insert("albedo".into(), json!(albedo));
    let color: Vec<f32> = scene.color.iter().flat_map(|c| rgba(c, 1.0)).collect();
    let frame =
        json!({ "width": scene.width, "height": scene.height, "color": color, "inputs": inputs, "scales": scales });
    std::fs::write(dir.join("frame.json"), frame.to_string()).unwrap();

    let (_served, mut browser) = page(&dir);
    let seen = browser.evaluate(&format!(
        r#"(async () => {{
  const {{ loadFilter }} = await import("./filterjit.js");
  {DEVICE}
  const filter = await loadFilter(device, "denoise.wgsl.json");
  const frame = await (await fetch("frame.json")).json();
  const inputs = Object.fromEntries(Object.entries(frame.inputs).map(([k, v]) => [k, new Float32Array(v)]));
  // A missing input is named.
  let missing = "";
  try {{ filter.run({{ width: 8, height: 8, textures: {{}} }}); }} catch (e) {{ missing = e.message; }}
  const output = await filter.filterArrays({{ ...frame, color: new Float32Array(frame.color), inputs }});
  const half = await loadFilter(device, "half.wgsl.json");
  const halfOutput = await half.filterArrays({{ ...frame, color: new Float32Array(frame.color), inputs }});
  return {{ output: Array.from(output), half: Array.from(halfOutput), messages: filter.messages.concat(half.messages),
    inputs: filter.inputs, missing }};
}})()"#
    ));
    assert_eq!(seen["messages"], json!([]), "Tint's messages on the exported shaders");
    assert!(seen["missing"].as_str().unwrap().contains("`color`"), "names the missing input: {}", seen["missing"]);
    let inputs: Vec<&str> = seen["inputs"].as_array().unwrap().iter().map(|v| v.as_str().unwrap()).collect();
    assert!(inputs.contains(&"albedo") && inputs.contains(&"color"), "{inputs:?}");

    // `filterjit filter` on the same render.
    let filtered = dir.join("filtered.exr");
    let o = Command::new(bin).args(["filter", "--expr", name]).arg(&sample).arg("-o").arg(&filtered).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let expected = scene::exr_io::read_channels(&filtered, &["R", "G", "B"]).unwrap();
    let worst = |key: &str| {
        let output: Vec<f64> = seen[key].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
        assert_eq!(output.len(), 4 * scene.pixels());
        let mut worst: f64 = 0.0;
        for p in 0..scene.pixels() {
            for c in 0..3 {
                let (ours, theirs) = (output[4 * p + c], expected.data[c][p] as f64);
                worst = worst.max((ours - theirs).abs() / theirs.abs().max(1.0));
            }
        }
        worst
    };
    let (full, half) = (worst("output"), worst("half"));
    eprintln!("the web module on SwiftShader against filter: largest relative difference {full:.2e} (rgba32float), {half:.2e} (rgba16float)");
    assert!(full < TOLERANCE, "the web module's output differs from filter's by {full:e}");
    assert!(half < HALF_TOLERANCE, "the web module's half-precision output differs from filter's by {half:e}");
}

/// The shipped temporal filter exported: `web/filterjit.js` in Chromium
/// keeps the manifest's `history` from frame to frame and gives, frame after
/// frame of the committed Cycles sequence, what `filterjit filter SEQ_DIR`
/// writes (with the pixel filter its 1-sample frames get); `reset()` starts
/// the sequence again.
#[test]
fn the_web_module_filters_a_sequence_as_filter_does() {
    if chromium("the_web_module_filters_a_sequence_as_filter_does").is_none() {
        return;
    }
    let dir = temp_dir("browser", "sequence");
    let bin = env!("CARGO_BIN_EXE_filterjit");
    // As `filter` runs it on the committed frames, Cycles' at one sample: the pixel filter last.
    let stored = corpus::resolve_with_pipeline("@temporal").unwrap().pipeline.unwrap();
    let pipeline = format!("{stored},pixelfilter=0.4");
    let o = Command::new(bin)
        .args(["export", "@temporal", "--format", "rgba32float", "--pipeline", &pipeline, "-o"])
        .arg(dir.join("temporal.wgsl"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let manifest: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("temporal.wgsl.json")).unwrap()).unwrap();
    let keeps = manifest["frame"].as_array().unwrap().iter().filter(|s| s.get("keep").is_some()).count();
    assert!(manifest["temporal"].is_object() && keeps > 0, "a temporal export");
    assert!(manifest["pixelfilter"].is_object(), "the pixel filter, last");

    let noisy = crate::temporal::committed().join("noisy");
    let expr = corpus::resolve_with_pipeline("@temporal").unwrap().expr;
    let mut request = Request::for_expr(&expr);
    request.albedo = true;
    request.motion = true;
    let sequence = scene::Sequence::find(&noisy).unwrap();
    let rgba = |v: &[f32; 3], k: f32| vec![k * v[0], k * v[1], k * v[2], 1.0];
    let mut frames = Vec::new();
    let mut scenes = Vec::new();
    for k in 0..sequence.frames.len() {
        let scene = sequence.load(k, &request).unwrap();
        // As an engine holds them: the features at twice their normalised value with scale 0.5.
        let mut inputs = serde_json::Map::new();
        let mut scales = serde_json::Map::new();
        for b in manifest["bindings"].as_array().unwrap().iter().filter(|b| b.get("scale_index").is_some()) {
            let role = b["role"].as_str().unwrap();
            let f = filterjit::lang::Feature::from_name(role).expect("the filter reads features");
            inputs.insert(
                role.into(),
                json!(scene.feature(f).unwrap().iter().flat_map(|v| rgba(v, 2.0)).collect::<Vec<_>>()),
            );
            scales.insert(role.into(), json!(0.5));
        }
        let motion = scene.motion.as_ref().unwrap();
        let albedo: Vec<f32> = scene.albedo.as_ref().unwrap().iter().flat_map(|a| rgba(a, 1.0)).collect();
        inputs.insert("albedo".into(), json!(albedo));
        inputs.insert("geometry".into(), json!(motion.surface.iter().flatten().collect::<Vec<_>>()));
        let vectors: Vec<f32> = motion.vectors.iter().flat_map(|v| [v[0], v[1], 0.0, 0.0]).collect();
        inputs.insert("motion".into(), json!(vectors));
        let color: Vec<f32> = scene.color.iter().flat_map(|c| rgba(c, 1.0)).collect();
        frames.push(
            json!({ "width": scene.width, "height": scene.height, "color": color, "inputs": inputs, "scales": scales }),
        );
        scenes.push(scene);
    }
    std::fs::write(dir.join("frames.json"), Value::Array(frames).to_string()).unwrap();

    let (_served, mut browser) = page(&dir);
    let seen = browser.evaluate(&format!(
        r#"(async () => {{
  const {{ loadFilter }} = await import("./filterjit.js");
  {DEVICE}
  const filter = await loadFilter(device, "temporal.wgsl.json");
  const frames = await (await fetch("frames.json")).json();
  const arrays = (frame) => ({{ ...frame, color: new Float32Array(frame.color),
    inputs: Object.fromEntries(Object.entries(frame.inputs).map(([k, v]) => [k, new Float32Array(v)])) }});
  const outputs = [];
  for (const frame of frames) outputs.push(Array.from(await filter.filterArrays(arrays(frame))));
  const counted = filter.frames;
  filter.reset();
  const again = Array.from(await filter.filterArrays(arrays(frames[frames.length - 1])));
  const fresh = await loadFilter(device, "temporal.wgsl.json");
  const alone = Array.from(await fresh.filterArrays(arrays(frames[frames.length - 1])));
  return {{ outputs, counted, again, alone, inputs: filter.inputs, messages: filter.messages }};
}})()"#
    ));
    assert_eq!(seen["messages"], json!([]), "Tint's messages on the exported shaders");
    let inputs: Vec<&str> = seen["inputs"].as_array().unwrap().iter().map(|v| v.as_str().unwrap()).collect();
    for role in ["geometry", "motion", "albedo"] {
        assert!(inputs.contains(&role), "a temporal filter asks for `{role}`: {inputs:?}");
    }
    assert_eq!(seen["counted"], json!(scenes.len()), "the module counts the sequence's frames");
    assert_eq!(seen["again"], seen["alone"], "after reset(), a frame is a sequence's first, bit for bit");
    assert_ne!(seen["again"], seen["outputs"][scenes.len() - 1], "the history changes the last frame");

    // `filterjit filter` on the same sequence.
    let out = dir.join("filtered");
    let o = Command::new(bin).arg("filter").arg(&noisy).arg("-o").arg(&out).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for (k, frame) in sequence.frames.iter().enumerate() {
        let expected =
            scene::exr_io::read_channels(&out.join(frame.path.file_name().unwrap()), &["R", "G", "B"]).unwrap();
        let output: Vec<f64> = seen["outputs"][k].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
        let mut worst: f64 = 0.0;
        for p in 0..scenes[k].pixels() {
            for c in 0..3 {
                let (ours, theirs) = (output[4 * p + c], expected.data[c][p] as f64);
                worst = worst.max((ours - theirs).abs() / theirs.abs().max(1.0));
            }
        }
        eprintln!("frame {}: the web module on SwiftShader against filter: {worst:.2e}", k + 1);
        // Measured: 5.4e-7 at worst over the three frames; the history carries a frame's last bits into
        // the next, so a sequence meets the same tolerance as one frame only while it is short.
        assert!(worst < TOLERANCE, "frame {}: the web module differs from filter by {worst:e}", k + 1);
    }
}

/// Every shipped filter exported as WGSL, in its own pipeline, as a window
/// and with keep's spread, in both output formats, compiled by Tint with no
/// message at all and built into pipelines on a device with WebGPU's default
/// limits (which the module checks and Dawn enforces).
#[test]
fn every_shipped_export_compiles_through_tint_within_default_limits() {
    if chromium("every_shipped_export_compiles_through_tint_within_default_limits").is_none() {
        return;
    }
    let dir = temp_dir("browser", "tint");
    let keep: FilterPipeline = "outliers=2,keep,demodulate,atrous3x3=4".parse().unwrap();
    let mut exports = Vec::new();
    for (name, _) in corpus::named() {
        let resolved = corpus::resolve_with_pipeline(&format!("@{name}")).unwrap();
        let stored = resolved.pipeline.unwrap_or_default();
        for pipeline in [stored, FilterPipeline::WINDOW, keep] {
            for format in [OutputFormat::Rgba16float, OutputFormat::Rgba32float] {
                let exported = export_filter(&resolved.expr, &pipeline, resolved.radius, Target::Wgsl, format).unwrap();
                let text = |code: &Code| match code {
                    Code::Text(t) => t.clone(),
                    Code::SpirV(_) => unreachable!("WGSL is text"),
                };
                exports.push(json!({
                    "label": format!("@{name} in {pipeline}, {format:?}"),
                    "manifest": exported.manifest,
                    "shaders": std::iter::once(("form", text(&exported.code)))
                        .chain(exported.stages.iter().map(|(name, code)| (name.key(), text(code))))
                        .collect::<std::collections::BTreeMap<_, _>>(),
                }));
            }
        }
    }
    std::fs::write(dir.join("exports.json"), Value::Array(exports.clone()).to_string()).unwrap();
    let (_served, mut browser) = page(&dir);
    let seen = browser.evaluate(&format!(
        r#"(async () => {{
  const {{ createFilter }} = await import("./filterjit.js");
  {DEVICE}
  const exports = await (await fetch("exports.json")).json();
  const failures = [];
  for (const e of exports) {{
    const shaders = Object.fromEntries(Object.entries(e.shaders).filter(([, v]) => v !== null));
    device.pushErrorScope("validation");
    try {{
      const filter = await createFilter(device, e.manifest, shaders);
      for (const m of filter.messages) failures.push(`${{e.label}}: ${{m.stage}} line ${{m.line}}: ${{m.type}}: ${{m.text}}`);
    }} catch (error) {{
      failures.push(`${{e.label}}: ${{error.message}}`);
    }}
    const error = await device.popErrorScope();
    if (error) failures.push(`${{e.label}}: ${{error.message}}`);
  }}
  return {{ failures, compiled: exports.length, limits: {{
    storage: device.limits.maxStorageTexturesPerShaderStage, sampled: device.limits.maxSampledTexturesPerShaderStage }} }};
}})()"#
    ));
    assert_eq!(seen["limits"], json!({ "storage": 4, "sampled": 16 }), "WebGPU's default limits");
    assert_eq!(seen["failures"], json!([]), "exports Tint or Dawn refused or warned about");
    assert_eq!(seen["compiled"].as_u64().unwrap() as usize, exports.len());
    eprintln!(
        "{} exports (every shipped filter × 3 pipelines × 2 formats) compiled through Tint with no message",
        exports.len()
    );
}
