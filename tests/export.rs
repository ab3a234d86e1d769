//! `filterjit export`: the exported WGSL run by a plain-wgpu host that knows
//! only the manifest (the example's own `host.rs`) matches `filterjit filter`;
//! the other targets pass a reference compiler.

use std::collections::HashMap;
use std::path::Path;
use std::process::Command;

use filterjit::export::{export, Code, StageName, Target};
use filterjit::gpu::SceneBuffers;
use filterjit::jit::{self, OutputFormat};
use filterjit::lang::random::Alphabet;
use filterjit::lang::{Feature, ScalarVar};
use filterjit::rng::Rng;
use filterjit::scene::{self, Request};
use filterjit::{corpus, parse_expr, Expr, Scene};

use crate::common::{gpu, mitsuba_sample, synthetic_scene, temp_dir};

#[path = "../examples/run_exported/host.rs"]
mod host;

fn named(name: &str) -> Expr {
    parse_expr(corpus::lookup(name).unwrap()).unwrap()
}

/// The scene as an engine would hand it over: every input at twice its
/// normalised value, with scale 0.5 in the uniform (exact in binary floating point).
fn frame_of(scene: &Scene, manifest: &serde_json::Value) -> host::Frame {
    let mut inputs = HashMap::new();
    let mut scales = HashMap::new();
    for b in manifest["bindings"].as_array().unwrap() {
        if b.get("scale_index").is_none() {
            continue;
        }
        let role = b["role"].as_str().unwrap();
        let texels: Vec<[f32; 4]> = match (Feature::from_name(role), ScalarVar::from_name(role)) {
            // An engine's normal need not be unit length (an averaged one is shorter): its direction is
            // read. (Not in the temporal test, which holds the export to filter's bits: the direction's
            // rounding of a loaded unit normal, raised to SVGF's 128th power, shows at 6e-6 there.)
            (Some(Feature::Normal), _) if !manifest["temporal"].is_object() => scene
                .feature(Feature::Normal)
                .unwrap()
                .iter()
                .map(|v| [0.6 * v[0], 0.6 * v[1], 0.6 * v[2], 0.0])
                .collect(),
            (Some(f), _) => {
                scene.feature(f).unwrap().iter().map(|v| [2.0 * v[0], 2.0 * v[1], 2.0 * v[2], 0.0]).collect()
            }
            (_, Some(v)) => scene.variance(v).unwrap().iter().map(|x| [2.0 * x, 0.0, 0.0, 0.0]).collect(),
            _ => panic!("the manifest names an unknown input `{role}`"),
        };
        inputs.insert(role.to_string(), texels);
        scales.insert(role.to_string(), 0.5);
    }
    // Stages after the form read the normal whether or not the weight does (only its direction counts).
    if manifest["planefit"].is_object() && !inputs.contains_key("normal") {
        let normal = scene.feature(Feature::Normal).unwrap().iter().map(|v| [v[0], v[1], v[2], 0.0]).collect();
        inputs.insert("normal".to_string(), normal);
    }
    host::Frame {
        width: scene.width as u32,
        height: scene.height as u32,
        color: scene.color.iter().map(|c| [c[0], c[1], c[2], 1.0]).collect(),
        inputs,
        scales,
    }
}

/// Every shader of an export, as the host takes them.
fn shaders_of(exported: &filterjit::export::Exported) -> host::Shaders {
    let text_of = |code: &Code| match code {
        Code::Text(t) => t.clone(),
        Code::SpirV(_) => panic!("WGSL is text"),
    };
    host::Shaders {
        form: text_of(&exported.code),
        stages: exported.stages.iter().map(|(name, code)| (name.key().to_string(), text_of(code))).collect(),
    }
}

/// Largest |exported − filter| / max(1, |filter|) over all channels.
fn compare(expr: &Expr, scene: &Scene, radius: u32, format: OutputFormat) -> f64 {
    let exported = export(expr, Target::Wgsl, format).unwrap();
    let Code::Text(wgsl) = &exported.code else { panic!("WGSL is text") };
    let manifest = serde_json::to_value(&exported.manifest).unwrap();
    let gpu = gpu(); // first: it quiets Mesa's device-select layer for the whole process
    let (device, queue) = host::open_device().expect("a wgpu adapter for the plain host");
    let shaders = host::Shaders { form: wgsl.clone(), stages: HashMap::new() };
    let ours = host::filter(&device, &queue, &shaders, &manifest, &frame_of(scene, &manifest), radius)
        .unwrap_or_else(|e| panic!("the exported shader of `{expr}` fails in plain wgpu: {e}"));

    let kernel = jit::compile(expr, jit::KernelSpec::default()).unwrap();
    let mut buffers = SceneBuffers::new(&gpu, scene);
    let filtered = gpu.filter(&kernel, &mut buffers, scene, radius).unwrap();
    ours.iter()
        .zip(&filtered.color)
        .flat_map(|(a, b)| (0..4).map(move |c| (a[c] as f64 - b[c] as f64).abs() / (b[c] as f64).abs().max(1.0)))
        .fold(0.0, f64::max)
}

/// Features of a normalised scene are at most unit length (the interface's
/// promise); the synthetic scene clamps per component, so shorten it here.
fn unit_length(mut scene: Scene) -> Scene {
    for (feature, values) in scene.features.iter_mut() {
        for v in values.iter_mut() {
            // Normals are their direction, as filterjit loads them.
            if *feature == Feature::Normal {
                *v = filterjit::semantics::unit_direction(*v);
                continue;
            }
            let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            if l > 0.999 {
                *v = v.map(|c| c / l * 0.999);
            }
        }
    }
    scene
}

#[test]
fn exported_wgsl_in_plain_wgpu_matches_filter() {
    let synthetic = unit_length(synthetic_scene(37, 29, 3));
    let variances =
        parse_expr("exp(-(distance2(wpGradient) + wpVariance + colorVariance * distance1(texGradient)))").unwrap();
    let mut worst: f64 = 0.0;
    for (expr, radius) in [(named("thesis1"), 3), (named("thesis2"), 2), (named("thesis3"), 4), (variances, 3)] {
        let error = compare(&expr, &synthetic, radius, OutputFormat::Rgba32float);
        eprintln!("rgba32float, radius {radius}: max relative difference {error:.2e} for {expr}");
        assert!(error < 2e-5, "exported `{expr}` differs from filter by {error:e}");
        worst = worst.max(error);
        let half = compare(&expr, &synthetic, radius, OutputFormat::Rgba16float);
        assert!(half < 1e-3, "rgba16float output of `{expr}` differs by {half:e} (half precision is 4.9e-4)");
    }
    // The real render, with features normalised as filterjit loads them.
    let thesis = named("crossBilateral");
    let sample = scene::load(&mitsuba_sample(), &Request::for_expr(&thesis)).unwrap();
    let error = compare(&thesis, &sample, 5, OutputFormat::Rgba32float);
    eprintln!("Mitsuba sample, crossBilateral, radius 5: {error:.2e}");
    assert!(error < 2e-5, "{error:e}");
}

/// A whole pipeline exported: the pre-pass shader once, then the form's
/// shader `passes` times with ping-ponged images, run by the plain host from
/// the manifest alone, gives what `filterjit filter` gives through that pipeline.
#[test]
fn an_exported_pipeline_in_plain_wgpu_matches_filter() {
    use filterjit::export::export_pipeline;
    use filterjit::jit::Shape;
    let mut scene = unit_length(synthetic_scene(37, 29, 5));
    // Albedo as real renders have it: black (emitters), ordinary, far above 1.
    scene.albedo = Some(
        (0..scene.pixels())
            .map(|p| match p % 7 {
                0 => [0.0, 0.0, 0.0],
                1 => [250.0, 3.0, 0.5],
                k => [0.1 * k as f32, 0.9 - 0.1 * k as f32, 0.02 * k as f32],
            })
            .collect(),
    );
    let carrying =
        parse_expr("exp(-(distance2(color) / (colorVariance + 0.05) + distance2(normal) * 4 + level / 8))").unwrap();
    let cases = [
        (named("crossBilateral"), "outliers=2,demodulate,atrous=5"),
        (carrying.clone(), "outliers=1.5,atrous=3"),
        (carrying, "demodulate,window"),
        (named("bilateral"), "atrous=2"),
        (named("crossBilateral"), "outliers=2,demodulate,atrous3x3=4"),
        // What the clamp removed, kept: the spread's dispatches between the pre-pass and the form.
        (named("evolvedAtrous3x3"), "outliers=2,keep,demodulate,atrous3x3=4"),
        (named("crossBilateral"), "outliers=1.5,keep,atrous=2"),
        // The guide: its own dispatch before the form, bound in pass 0 only;
        // after the whole pre-pass, and without one.
        (named("evolvedAtrous128Guide"), "outliers=2,keep,demodulate,atrous=4"),
        (named("evolvedAtrous64Trim"), "outliers=2.5,trim,keep,demodulate,atrous=4"),
        // `keep=surface`: its total's one-workgroup dispatch, the normal the
        // spread reads as a direction (the frame's are scaled by 2).
        (named("evolvedAtrous64Surface"), "outliers=2.5,trim,keep=surface,demodulate,atrous=4"),
        // `planefit` after the form: with the modulation divided out and multiplied back, and without.
        (named("evolvedAtrous64Surface"), "outliers=2.5,trim,keep=surface,demodulate,atrous=4,planefit=3"),
        (named("bilateral"), "atrous=2,planefit=2"),
        // `pixelfilter`, last: after planefit's `fitted`, and after the form's `filtered`.
        (named("bilateral"), "atrous=2,planefit=2,pixelfilter=0.6"),
        (named("crossBilateral"), "outliers=2,demodulate,atrous=3,pixelfilter=0.3"),
        // `anchor`: after the form's `filtered`, and between planefit's `fitted` and the pixel filter.
        (named("crossBilateral"), "outliers=2,demodulate,atrous=3,anchor=2"),
        (named("bilateral"), "atrous=2,planefit=2,anchor=0.5,pixelfilter=0.6"),
        (parse_expr("exp(-(distance2(guide) * 2 + distance2(normal) * 4))").unwrap(), "atrous3x3=3"),
        (parse_expr("exp(-(distance2(guide, color) + distance2(pixel) / 8))").unwrap(), "window"),
        // What the outlier rule measured, from the exported pre-pass's packed `local` texture.
        (
            parse_expr("exp(-(distance2(normal) * 4 + clampedShare * 8 + localStd / (localMean + 0.1)))").unwrap(),
            "outliers=2,atrous=3",
        ),
    ];
    let gpu = gpu();
    let (device, queue) = host::open_device().expect("a wgpu adapter for the plain host");
    for (expr, text) in cases {
        let pipeline: filterjit::pipeline::FilterPipeline = text.parse().unwrap();
        let exported = export_pipeline(&expr, &pipeline, Target::Wgsl, OutputFormat::Rgba32float).unwrap();
        let manifest = serde_json::to_value(&exported.manifest).unwrap();
        assert_eq!(
            exported.stage(StageName::Prepass).is_some(),
            ![
                "atrous=2",
                "atrous3x3=3",
                "window",
                "atrous=2,planefit=2",
                "atrous=2,planefit=2,pixelfilter=0.6",
                "atrous=2,planefit=2,anchor=0.5,pixelfilter=0.6"
            ]
            .contains(&text),
            "{text}: a pre-pass exactly where the pipeline has one"
        );
        let measures = ["localMean", "localStd", "clampedShare"];
        for b in exported.manifest.bindings.iter().filter(|b| measures.contains(&b.role.as_str())) {
            assert_eq!((b.image, b.scale_index), (Some("local"), None), "{b:?}: read raw from the pre-pass's `local`");
        }
        assert_eq!(
            exported.stage(StageName::Spread).is_some(),
            text.contains("keep"),
            "{text}: a spread exactly where it keeps"
        );
        let guided = expr.features().contains(&filterjit::lang::Feature::Guide);
        assert_eq!(
            exported.stage(StageName::Guide).is_some(),
            guided,
            "{expr}: a guide stage exactly where the weight reads it"
        );
        let filters = match (text.contains("keep"), exported.stage(StageName::Prepass).is_some()) {
            (true, _) => "kept",
            (false, true) => "prepared",
            (false, false) => "color",
        };
        let passes: Vec<&serde_json::Value> =
            manifest["frame"].as_array().unwrap().iter().filter(|s| s["dispatch"]["shader"] == "form").collect();
        assert_eq!(
            passes.len() as u32,
            exported.manifest.passes,
            "{text}: the frame dispatches the form `passes` times"
        );
        assert_eq!(
            passes[0]["dispatch"]["images"]["color"], filters,
            "{text}: the image the form's first pass filters"
        );
        let shaders = shaders_of(&exported);
        assert_eq!(
            exported.stage(StageName::PlaneFit).is_some(),
            text.contains("planefit"),
            "{text}: planefit exactly where it fits"
        );
        assert_eq!(
            exported.stage(StageName::PixelFilter).is_some(),
            text.contains("pixelfilter"),
            "{text}: the pixel filter exactly where the pipeline has it"
        );
        assert_eq!(
            exported.manifest.dispatches_of(StageName::Anchor),
            if text.contains("anchor") { filterjit::jit::ANCHOR_DISPATCHES } else { 0 },
            "{text}: the anchor's levels and its scaling exactly where the pipeline has it"
        );
        let mut frame = frame_of(&scene, &manifest);
        frame
            .inputs
            .insert("albedo".into(), scene.albedo.as_ref().unwrap().iter().map(|a| [a[0], a[1], a[2], 1.0]).collect());
        let ours = host::filter(&device, &queue, &shaders, &manifest, &frame, 2)
            .unwrap_or_else(|e| panic!("the exported `{text}` pipeline fails in plain wgpu: {e}"));

        let kernel =
            jit::compile(&expr, jit::KernelSpec { shape: Shape::of(&pipeline), ..jit::KernelSpec::default() }).unwrap();
        let mut buffers = SceneBuffers::for_pipeline(&gpu, &scene, &pipeline).unwrap();
        let staged = gpu.filter(&kernel, &mut buffers, &scene, 2).unwrap();
        let filtered = staged.rgb();
        // A frame in one submission (pre-pass, guide and passes recorded
        // together) computes the same bits as a submission a stage, and
        // times the same stages; its second filter reuses what the first made.
        let mut frame_buffers = SceneBuffers::for_frame(&gpu, &scene, &pipeline).unwrap();
        let bits = |c: &[[f32; 4]]| c.iter().flatten().map(|v| v.to_bits()).collect::<Vec<_>>();
        for run in 0..2 {
            let one = gpu.filter(&kernel, &mut frame_buffers, &scene, 2).unwrap();
            assert!(bits(&one.color) == bits(&staged.color), "{text}, run {run}: one submission changed the image");
            assert_eq!(one.flags, staged.flags, "{text}, run {run}");
        }
        assert_eq!(
            frame_buffers.prepass_time().is_some(),
            exported.stage(StageName::Prepass).is_some(),
            "{text}: the pre-pass timed"
        );
        assert_eq!(frame_buffers.guide_time().is_some(), guided, "{text}: the guide timed where it ran");
        let error = ours
            .iter()
            .zip(&filtered)
            .flat_map(|(a, b)| (0..3).map(move |c| (a[c] as f64 - b[c] as f64).abs() / (b[c] as f64).abs().max(1.0)))
            .fold(0.0, f64::max);
        eprintln!("{text}: max relative difference {error:.2e} for {expr}");
        assert!(error < 1e-4, "the exported `{text}` pipeline differs from filter by {error:e}");
        let passes = manifest["passes"].as_u64().unwrap();
        assert_eq!(passes, pipeline.passes() as u64);
        let form = text
            .split(',')
            .rfind(|stage| !["planefit", "anchor", "pixelfilter"].iter().any(|s| stage.starts_with(s)))
            .unwrap();
        assert_eq!(passes, form.split_once('=').map_or(1, |(_, k)| k.parse().unwrap()), "{text}");
    }
}

#[test]
fn the_manifest_names_exactly_the_inputs_the_expression_reads() {
    let expr = named("thesis1");
    let manifest = export(&expr, Target::Hlsl, OutputFormat::Rgba16float).unwrap().manifest;
    let roles: Vec<&str> = manifest.bindings.iter().map(|b| b.role.as_str()).collect();
    assert_eq!(roles, ["params", "color", "output", "normal", "texture", "depth", "directIllumination"]);
    let bindings: Vec<u32> = manifest.bindings.iter().map(|b| b.binding).collect();
    assert_eq!(bindings, (0..7).collect::<Vec<_>>(), "bindings are dense from 0");
    assert_eq!(manifest.uniform.size_bytes, 16 + 16 * 4);
    assert_eq!(manifest.bindings[3].target_slot, "register(t3, space0)");
    assert_eq!(manifest.bindings[2].target_slot, "register(u2, space0)");
    // An expression of colour and pixel distance alone binds no feature texture.
    let bilateral = export(&named("bilateral"), Target::Wgsl, OutputFormat::Rgba16float).unwrap().manifest;
    assert_eq!(bilateral.bindings.len(), 3);
    assert_eq!(bilateral.uniform.size_bytes, 16);
}

/// A reference compiler from Debian's packages (glslang-tools, spirv-tools;
/// `.ci/run` installs them). Missing locally: said loudly, not silently passed.
fn tool(name: &str) -> Option<&'static str> {
    let found = Command::new(name).arg("--version").output().is_ok();
    match (found, std::env::var_os("CI").is_some()) {
        (true, _) => Some(Box::leak(name.to_string().into_boxed_str())),
        (false, true) => panic!("{name} is missing in CI: .ci/run installs glslang-tools and spirv-tools"),
        (false, false) => {
            eprintln!("\n*** SKIPPED: {name} not installed (apt-get install glslang-tools spirv-tools); exported shaders NOT checked by it ***\n");
            None
        }
    }
}

fn check_with(tool: &str, args: &[&str], file: &Path, expr: &Expr) {
    let out = Command::new(tool).args(args).arg(file).output().unwrap();
    assert!(
        out.status.success(),
        "{tool} rejects {} for `{expr}`:\n{}{}",
        file.display(),
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn glsl_hlsl_and_spirv_exports_pass_reference_compilers() {
    let (Some(glslang), Some(spirv_val)) = (tool("glslangValidator"), tool("spirv-val")) else { return };
    let dir = temp_dir("export", "targets");
    let mut exprs: Vec<Expr> = corpus::named().iter().map(|(_, text)| parse_expr(text).unwrap()).collect();
    let alphabet = Alphabet::full();
    let mut rng = Rng::seeded(11);
    exprs.extend((0..12).map(|k| alphabet.of_length(&mut rng, 5 + 10 * k)));
    // Every expression as a window; the shipped ones also as a whole pipeline
    // (pre-pass and à-trous pass), and one with each `keep`'s spread (and `planefit`).
    let atrous: filterjit::pipeline::FilterPipeline = "outliers=2,demodulate,atrous=5".parse().unwrap();
    let keep: filterjit::pipeline::FilterPipeline = "outliers=2,keep,demodulate,atrous3x3=4".parse().unwrap();
    let surface: filterjit::pipeline::FilterPipeline =
        "outliers=2,keep=surface,demodulate,atrous=4,planefit=3".parse().unwrap();
    // The temporal stage's two kernels, in the shipped sequence filter's pipeline.
    let temporal = corpus::resolve_with_pipeline("@temporal").unwrap();
    let named = corpus::named().len();
    let cases = exprs
        .iter()
        .map(|e| (e, filterjit::pipeline::FilterPipeline::WINDOW))
        .chain(exprs[..named].iter().map(|e| (e, atrous)))
        .chain(exprs[..1].iter().map(|e| (e, keep)))
        .chain(exprs[..1].iter().map(|e| (e, surface)))
        .chain(std::iter::once((&temporal.expr, temporal.pipeline.unwrap())));
    for (k, (expr, pipeline)) in cases.enumerate() {
        for target in [Target::Glsl, Target::Hlsl, Target::Spirv, Target::Msl] {
            let exported =
                filterjit::export::export_pipeline(expr, &pipeline, target, OutputFormat::Rgba16float).unwrap();
            let shaders = std::iter::once(("", &exported.code))
                .chain(exported.stages.iter().map(|(name, code)| (name.key(), code)));
            for (stage, code) in shaders {
                let file = dir.join(format!("e{k}{stage}.{}", target.extension()));
                std::fs::write(&file, code.to_bytes()).unwrap();
                match target {
                    Target::Glsl => check_with(glslang, &[], &file, expr),
                    Target::Hlsl => {
                        let spv = dir.join(format!("e{k}{stage}.hlsl.spv"));
                        let out = spv.to_str().unwrap();
                        check_with(glslang, &["-V", "-D", "-e", "main", "-S", "comp", "-o", out], &file, expr);
                    }
                    Target::Spirv => check_with(spirv_val, &["--target-env", "vulkan1.0"], &file, expr),
                    // No Metal compiler runs on Linux: MSL is only produced by naga
                    // from the validated module, and its entry point checked.
                    Target::Msl => assert_eq!(exported.manifest.entry_point, "main_"),
                    Target::Wgsl => unreachable!(),
                }
            }
        }
    }
    eprintln!("{} expressions (and {named} as a whole pipeline) × GLSL, HLSL, SPIR-V passed glslangValidator / spirv-val; MSL generated only (no Metal compiler on Linux)", exprs.len());
}

/// A temporal pipeline exported: the plain host keeps the manifest's
/// `history` between frames and gives, frame after frame, what
/// `Gpu::filter_frame` gives with its `TemporalState`; a reset host starts
/// the sequence again.
#[test]
fn an_exported_temporal_pipeline_filters_a_sequence_as_filter_does() {
    use filterjit::export::export_pipeline;
    use filterjit::gpu::TemporalState;
    use filterjit::jit::Shape;
    let scenes =
        crate::temporal::frames(&crate::temporal::committed().join("noisy"), &crate::temporal::temporal_request());
    let cases = [
        // SVGF's pipeline: the first pass fed back, the temporal variance carried over the passes.
        (
            "demodulate,temporal=0.2,feedback=1,atrous=3",
            "exp(-(distanceMax(color) / (4 * sqrt(temporalVariance) + 0.001) + distance2(normal) / historyLength))",
            0,
        ),
        ("outliers=2,keep,demodulate,temporal=0.1,feedback=0,clamp=2,antilag=3,window", "exp(-distance2(color))", 2),
        ("temporal=0.5,feedback=2,atrous=2,planefit=2", "exp(-(distance2(color) + historyLength))", 0),
        ("@temporal", "", 0),
        // What `filter` runs on frames sampled at one point: the pixel filter last.
        (
            "outliers=2.5,trim,keep,demodulate,temporal=0.2,feedback=0,clamp=2,antilag=3,atrous=3,anchor=2,pixelfilter=0.4",
            "@temporal",
            0,
        ),
    ];
    let gpu = gpu();
    let (device, queue) = host::open_device().expect("a wgpu adapter for the plain host");
    for (text, weight, radius) in cases {
        let (expr, pipeline) = match text.strip_prefix('@') {
            Some(_) => {
                let resolved = corpus::resolve_with_pipeline(text).unwrap();
                (resolved.expr, resolved.pipeline.unwrap())
            }
            None if weight.starts_with('@') => {
                (corpus::resolve_with_pipeline(weight).unwrap().expr, text.parse().unwrap())
            }
            None => (parse_expr(weight).unwrap(), text.parse().unwrap()),
        };
        let exported = export_pipeline(&expr, &pipeline, Target::Wgsl, OutputFormat::Rgba32float).unwrap();
        let manifest = serde_json::to_value(&exported.manifest).unwrap();
        assert!(exported.stage(StageName::Temporal).is_some() && exported.stage(StageName::TemporalVariance).is_some());
        let steps = manifest["frame"].as_array().unwrap();
        let dispatches_of = |shader: &str| -> Vec<usize> {
            (0..steps.len()).filter(|&n| steps[n]["dispatch"]["shader"] == shader).collect()
        };
        let passes = dispatches_of("form");
        assert_eq!(steps[passes[0]]["dispatch"]["images"]["color"], "blend", "{text}: the form filters the blend");
        let temporal = &steps[dispatches_of("temporal")[0]]["dispatch"];
        assert_eq!(
            (temporal["values"]["history"].as_u64(), temporal["first_frame"]["history"].as_u64()),
            (Some(1), Some(0)),
            "{text}: `history` is a u32, 0 on a first frame"
        );
        // What the engine supplies, with the channels the frame reads of it.
        let read = |image: &str| {
            let inputs = manifest["inputs"].as_array().unwrap();
            let input = inputs.iter().find(|i| i["image"] == image);
            input.map(|i| i["components"].as_str().unwrap().to_string())
        };
        assert_eq!(
            (read("geometry").as_deref(), read("motion").as_deref(), read("albedo").as_deref()),
            (Some("xyzw"), Some("xy"), Some("xyz")),
            "{text}: the normal and depth of each pixel, its motion, its albedo"
        );
        assert_eq!(exported.manifest.dispatches_of(StageName::Temporal), 1, "{text}");
        assert_eq!(exported.manifest.kept().count(), 5, "{text}: five images kept for the next frame");
        let feedback = pipeline.temporal.unwrap().feedback;
        let fed_back = steps.iter().position(|s| s["keep"]["into"] == "history").expect("the history kept");
        match feedback {
            0 => assert!(
                steps[fed_back]["keep"]["from"] == "blend" && steps[fed_back..].iter().all(|s| s.get("keep").is_some()),
                "{text}: the blend kept at the end of the frame"
            ),
            k => assert_eq!(fed_back, passes[k as usize - 1] + 1, "{text}: kept right after the pass fed back"),
        }
        let shaders = shaders_of(&exported);
        let kernel =
            jit::compile(&expr, jit::KernelSpec { shape: Shape::of(&pipeline), ..jit::KernelSpec::default() }).unwrap();
        let mut state = TemporalState::new();
        let mut sequence = host::Sequence::new();
        let frame_of_scene = |scene: &Scene| {
            let mut frame = frame_of(scene, &manifest);
            let rgba = |v: &[f32; 3]| [v[0], v[1], v[2], 0.0];
            let motion = scene.motion.as_ref().unwrap();
            frame.inputs.insert("albedo".into(), scene.albedo.as_ref().unwrap().iter().map(rgba).collect());
            frame.inputs.insert("geometry".into(), motion.surface.clone());
            frame.inputs.insert("motion".into(), motion.vectors.iter().map(|v| [v[0], v[1], 0.0, 0.0]).collect());
            if !frame.inputs.contains_key("normal") {
                frame
                    .inputs
                    .insert("normal".into(), scene.feature(Feature::Normal).unwrap().iter().map(rgba).collect());
            }
            frame
        };
        let mut last = Vec::new();
        for (k, scene) in scenes.iter().enumerate() {
            let ours =
                host::filter_frame(&device, &queue, &shaders, &manifest, &frame_of_scene(scene), radius, &mut sequence)
                    .unwrap_or_else(|e| {
                        panic!("the exported `{text}` pipeline fails in plain wgpu, frame {}: {e}", k + 1)
                    });
            assert_eq!(sequence.frames as usize, k + 1, "{text}: the host counts its frames");
            assert!(sequence.gpu_time.is_some_and(|t| !t.is_zero()), "{text}: the host times the frame's GPU work");
            let mut buffers = SceneBuffers::for_frame(&gpu, scene, &pipeline).unwrap();
            let filtered = gpu.filter_frame(&kernel, &mut buffers, scene, radius, &mut state).unwrap().rgb();
            let error = relative_difference(&ours, &filtered);
            eprintln!("{text}, frame {}: max relative difference {error:.2e}", k + 1);
            // The same kernels on the same inputs: the same bits on lavapipe; llvmpipe through GL
            // rounds the two bindings' paths apart by an ulp or two (measured up to 8.1e-7 in three
            // frames). Where a test at a threshold meets a pair of values at it to the last bit, one
            // ulp decides it, and the two programs may decide it apart: the short history's 5×5
            // window did, at (x, y) = (13, 36) and (15, 35) of the committed crop's first frame, whose
            // albedo luminances 0.3031752 and 0.37896898 are in the ratio 0.8 to the last bit
            // (`TEMPORAL_ALIKE_ALBEDO`; the luminance's multiply-adds fused say "alike", unfused
            // "unlike"), and GL's two programs differed by 2.6e-4 around them. The 3×3 window
            // keeps them apart (docs/JOURNAL.md, "The colour term's σ on seven sequences", its
            // last paragraph).
            assert!(error <= 5e-6, "{text}, frame {}: the export differs from filter by {error:e}", k + 1);
            last = ours;
        }
        // The history made the last frame; after a reset, the same frame comes out as a sequence's first.
        sequence.reset();
        let scene = scenes.last().unwrap();
        let again =
            host::filter_frame(&device, &queue, &shaders, &manifest, &frame_of_scene(scene), radius, &mut sequence)
                .unwrap();
        let mut buffers = SceneBuffers::for_frame(&gpu, scene, &pipeline).unwrap();
        let alone = gpu.filter_frame(&kernel, &mut buffers, scene, radius, &mut TemporalState::new()).unwrap().rgb();
        assert!(relative_difference(&again, &alone) <= 5e-6, "{text}: a reset host starts the sequence again");
        assert!(relative_difference(&again, &last.iter().map(|c| [c[0], c[1], c[2]]).collect::<Vec<_>>()) > 1e-3);
    }
}

/// Largest |a − b| / max(1, |b|) over the colour channels.
fn relative_difference(a: &[[f32; 4]], b: &[[f32; 3]]) -> f64 {
    a.iter()
        .zip(b)
        .flat_map(|(a, b)| (0..3).map(move |c| (a[c] as f64 - b[c] as f64).abs() / (b[c] as f64).abs().max(1.0)))
        .fold(0.0, f64::max)
}
