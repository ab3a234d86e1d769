//! Hard inputs: degenerate scenes, extreme weights, long sums, random and
//! damaged expression text, expressions far past the default length limit.

use filterjit::cpu;
use filterjit::gpu::SceneBuffers;
use filterjit::jit;
use filterjit::lang::random::Alphabet;
use filterjit::lang::{parse_expr, Feature, ScalarVar};
use filterjit::rng::Rng;
use filterjit::{corpus, Scene};

use crate::common::{env_usize, gpu, synthetic_scene};

/// A scene with every feature and variance, from a colour image and a feature generator.
fn scene_with(
    name: &str,
    width: usize,
    height: usize,
    color: impl Fn(usize) -> [f32; 3],
    feature: impl Fn(usize) -> [f32; 3],
) -> Scene {
    let n = width * height;
    let mut scene = Scene::from_color(name, width, height, (0..n).map(&color).collect());
    scene.reference = Some(scene.color.clone());
    for f in Feature::ALL.iter().filter(|f| f.needs_data() && **f != Feature::Color) {
        scene.features.insert(*f, (0..n).map(&feature).collect());
    }
    for v in ScalarVar::ALL {
        scene.variances.insert(*v, vec![0.5; n]);
    }
    scene
}

fn shipped() -> Vec<(&'static str, filterjit::Expr)> {
    corpus::named().into_iter().map(|(n, t)| (n, parse_expr(t).unwrap())).collect()
}

/// GPU output: finite everywhere, and within 5e-3·(|c| + 0.01) of the CPU's (looser
/// than the corpus test in gpu_vs_cpu.rs: thesis3 divides by asin(x)², which
/// amplifies the 4096-ulp error WGSL allows asin, and these scenes reach it).
fn check(scene: &Scene, expr: &filterjit::Expr, radius: u32) -> Vec<[f32; 3]> {
    let gpu = gpu();
    let kernel = jit::compile(expr, jit::KernelSpec::default()).unwrap();
    let mut buffers = SceneBuffers::new(&gpu, scene);
    let out = gpu.filter(&kernel, &mut buffers, scene, radius).unwrap().rgb();
    let reference = cpu::filter(expr, scene, radius).unwrap();
    for (k, (g, c)) in out.iter().zip(&reference.color).enumerate() {
        for q in 0..3 {
            assert!(g[q].is_finite(), "{}: `{expr}` gave {} at pixel {k}", scene.name, g[q]);
            let err = (g[q] as f64 - c[q]).abs() / (c[q].abs() + 0.01);
            assert!(err <= 5e-3, "{}: `{expr}` at pixel {k}: GPU {} vs CPU {}", scene.name, g[q], c[q]);
        }
    }
    out
}

#[test]
fn degenerate_scenes_filter_to_finite_images_that_match_the_cpu() {
    let smooth = |p: usize| [(p % 7) as f32 / 7.0, 0.3, -0.2];
    let cases: Vec<(Scene, u32)> = vec![
        (scene_with("all-black", 9, 7, |_| [0.0; 3], smooth), 3),
        (scene_with("constant", 9, 7, |_| [0.25, 0.5, 2.0], smooth), 3),
        (scene_with("zero-normals", 9, 7, |p| [(p % 5) as f32, 1.0, 0.5], |_| [0.0; 3]), 3),
        (scene_with("single-pixel", 1, 1, |_| [3.0, 2.0, 1.0], smooth), 5),
        (scene_with("one-row", 37, 1, |p| [(p % 3) as f32, 1.0, 0.0], smooth), 4),
        (scene_with("one-column", 1, 29, |p| [(p % 3) as f32, 1.0, 0.0], smooth), 4),
        (scene_with("window-larger-than-image", 3, 3, |p| [p as f32, 1.0, 0.0], smooth), 50),
        (scene_with("fireflies", 16, 16, |p| if p % 37 == 0 { [1e4, 1e4, 1e4] } else { [0.5, 0.4, 0.3] }, smooth), 3),
        (
            scene_with(
                "outlier-features",
                12,
                12,
                |p| [(p % 4) as f32, 0.5, 0.5],
                |p| if p == 5 { [1.0, 1.0, 1.0] } else { [0.0, 0.01, 0.0] },
            ),
            3,
        ),
    ];
    for (scene, radius) in &cases {
        for (name, expr) in shipped() {
            let out = check(scene, &expr, *radius);
            match scene.name.as_str() {
                "all-black" => assert!(out.iter().flatten().all(|v| *v == 0.0), "@{name} keeps black black"),
                // A convex combination of one colour is that colour.
                "constant" => {
                    for v in &out {
                        for (a, b) in v.iter().zip([0.25, 0.5, 2.0]) {
                            assert!((a - b).abs() <= 1e-6 * b, "@{name} keeps a constant image constant: {v:?}");
                        }
                    }
                }
                "fireflies" => assert!(
                    out.iter().flatten().all(|v| *v <= 1e4 && *v >= 0.0),
                    "@{name} stays within the window's range"
                ),
                _ => {}
            }
        }
    }
}

#[test]
fn extreme_weights_behave() {
    let scene = synthetic_scene(10, 8, 2);
    // Negative and zero weights leave the image as it was; huge weights are a box filter.
    for text in ["-(1e15)", "0", "1e-31"] {
        assert_eq!(check(&scene, &parse_expr(text).unwrap(), 3), scene.color, "`{text}`");
    }
    let huge = check(&scene, &parse_expr("1e15 * 1e15").unwrap(), 3);
    let box_filter = check(&scene, &parse_expr("1").unwrap(), 3);
    for (a, b) in huge.iter().zip(&box_filter) {
        for q in 0..3 {
            assert!((a[q] - b[q]).abs() <= 1e-5 * b[q].abs().max(1.0));
        }
    }
}

#[test]
fn large_windows_sum_accurately_in_f32() {
    let gpu = gpu();
    // A 61x61 window: 3721 terms per pixel, compared with the CPU's compensated f64 sum.
    let scene = synthetic_scene(48, 40, 13);
    let mut worst = 0.0f64;
    for text in ["1", "exp(-distance2(color))", "biweight(distance2(normal) / 4) + 1e-6"] {
        let expr = parse_expr(text).unwrap();
        let kernel = jit::compile(&expr, jit::KernelSpec::default()).unwrap();
        let mut buffers = SceneBuffers::new(&gpu, &scene);
        let out = gpu.filter(&kernel, &mut buffers, &scene, 30).unwrap().rgb();
        let reference = cpu::filter(&expr, &scene, 30).unwrap();
        for (g, c) in out.iter().zip(&reference.color) {
            for q in 0..3 {
                worst = worst.max((g[q] as f64 - c[q]).abs() / c[q].abs().max(1e-3));
            }
        }
    }
    eprintln!("large windows: largest relative difference of the GPU's plain f32 sum from the compensated f64 sum: {worst:.2e}");
    assert!(worst < 1e-4, "plain f32 sums lose too much: {worst:e}");
}

#[test]
fn the_parser_survives_random_and_mutated_text() {
    let cases = env_usize("FILTERJIT_PARSE_FUZZ_CASES", 20_000);
    let mut rng = Rng::seeded(99);
    let seeds: Vec<String> = corpus::named().iter().map(|(_, t)| t.to_string()).collect();
    let alphabet: Vec<char> = "()+-*/,. 0123456789eEπ_abcdefghijklmnopqrstuvwxyzADGIMNTV\n\t#@é".chars().collect();
    for k in 0..cases {
        let text: String = if k % 3 == 0 {
            (0..rng.below(40)).map(|_| *rng.pick(&alphabet)).collect()
        } else {
            let mut chars: Vec<char> = rng.pick(&seeds).chars().collect();
            for _ in 0..1 + rng.below(4) {
                let at = rng.below(chars.len() + 1);
                match rng.below(3) {
                    0 if at < chars.len() => {
                        chars.remove(at);
                    }
                    1 => chars.insert(at, *rng.pick(&alphabet)),
                    _ if at < chars.len() => chars[at] = *rng.pick(&alphabet),
                    _ => {}
                }
            }
            chars.into_iter().collect()
        };
        match parse_expr(&text) {
            Ok(e) => assert_eq!(parse_expr(&e.to_string()).unwrap(), e, "round trip of `{text}`"),
            Err(err) => {
                let lines = text.split('\n').count();
                assert!(
                    err.line >= 1 && err.line <= lines && err.column >= 1,
                    "position {}:{} in `{text:?}`",
                    err.line,
                    err.column
                );
                assert!(err.offset <= text.len());
                assert!(!err.message.is_empty() && err.to_string().contains(&format!("{}:{}", err.line, err.column)));
            }
        }
    }
}

#[test]
fn random_expressions_far_past_the_length_limit_compile_and_run() {
    let gpu = gpu();
    let scene = synthetic_scene(8, 6, 4);
    let mut buffers = SceneBuffers::new(&gpu, &scene);
    let alphabet = Alphabet::full();
    let mut rng = Rng::seeded(31);
    for length in [5, 20, 50, 75, 100, 150, 250, 400] {
        let expr = alphabet.of_length(&mut rng, length);
        assert!(expr.len() >= length);
        let kernel = jit::compile(&expr, jit::KernelSpec::default()).unwrap_or_else(|e| panic!("length {length}: {e}"));
        match gpu.filter(&kernel, &mut buffers, &scene, 1) {
            Ok(out) => assert!(out.rgb().iter().flatten().all(|v| v.is_finite()), "length {}", expr.len()),
            // Some devices (llvmpipe through GL: 16) allow fewer storage buffers than a
            // kernel reading 19 inputs needs: a clear error, not a crash.
            Err(e @ filterjit::gpu::GpuError::TooManyBindings { .. }) => {
                assert!(e.to_string().contains("storage buffers"), "{e}");
                eprintln!("length {}: {e}", expr.len());
            }
            Err(e) => panic!("length {}: {e}", expr.len()),
        }
    }
}

#[test]
fn deeply_nested_overflows_saturate_identically_on_cpu_and_gpu() {
    let scene = synthetic_scene(8, 6, 21);
    for text in [
        "exp(exp(exp(exp(exp(distance2(color))))))",
        "pow(pow(10, 10), pow(10, 10)) * pow(pow(10, 10), pow(10, 10))",
        "1 / (1 / (1 / (0 * distance2(normal))))",
        "tan(pi / 2) * tan(pi / 2) * tan(pi / 2)",
        "exp(-exp(exp(exp(distance2(color) * 100))))",
        "sqrt(-pow(-2, 0.5) * 1e15 * 1e15)",
        "mitchell(1e15 * 1e15) + sinc(1e15) + tricube(-1e15) + biweight(1e15) + epanechnikov(1e15)",
        "pow(0, -distance2(color) - 1) / pow(0, -1)",
    ] {
        let expr = parse_expr(text).unwrap();
        let out = check(&scene, &expr, 2);
        assert!(out.iter().flatten().all(|v| v.is_finite()), "`{text}`");
    }
}
