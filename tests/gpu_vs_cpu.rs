//! The GPU kernels (f32) against the CPU reference (f64).
//!
//! Tolerances, stated once:
//! * operators: |gpu − cpu| ≤ accuracy + 4·s. `accuracy` is what the WGSL
//!   specification lets an implementation err by for that operator (sin and
//!   cos: 2⁻¹¹ absolute; atan, and asin/acos through it: 4096 ulp; exp:
//!   3 + 2|x| ulp; pow: inherited from exp2 and log2; + − * /: a few ulp);
//!   `s` is how far the f64 result moves when the f32 inputs move by one f32
//!   ulp — the part no f32 implementation can avoid (sin of 1e6, tan near π/2);
//! * filtered images: |gpu − cpu| ≤ 1e-3·(|cpu| + 0.01) per channel for the
//!   curated corpus; for random expressions, which include ill-conditioned
//!   compositions, at least 98% of channels within that bound.
//!
//! NaN and infinity are never acceptable in either result.

use filterjit::cpu;
use filterjit::gpu::{Filtered, Gpu, SceneBuffers};
use filterjit::jit::{self, KernelKind, KernelLayout};
use filterjit::lang::random::Alphabet;
use filterjit::lang::{parse_expr, BinaryOp, Expr, Feature, PairOp, UnaryOp};
use filterjit::rng::Rng;
use filterjit::scene::{self, Absent, Request};
use filterjit::semantics::BIG;
use filterjit::{corpus, metrics, Scene};

use crate::common::{agree_fraction, env_usize, gpu, mitsuba_sample, synthetic_scene};

/// Edge values for operator tests (f32, as the GPU sees them).
fn edges() -> Vec<f32> {
    let mut v = vec![
        0.0,
        1e-40,
        1e-30,
        1e-20,
        1e-7,
        0.001,
        0.25,
        0.5,
        0.999_999,
        1.0,
        1.000_001,
        1.5,
        2.0,
        2.5,
        3.0,
        std::f32::consts::FRAC_PI_2 - 1e-3,
        std::f32::consts::FRAC_PI_2,
        3.0,
        10.0,
        33.0,
        35.0,
        79.0,
        81.0,
        100.0,
        1e4,
        1e6,
        1e10,
        1e15,
    ];
    let negatives: Vec<f32> = v.iter().map(|x| -x).collect();
    v.extend(negatives);
    v
}

/// One row of pixels whose `depth` holds `a` and whose `texture` holds `b`;
/// `dot(depth, normal)` and `dot(texture, normal)` then read them exactly.
fn edge_scene(pairs: &[(f32, f32)]) -> Scene {
    let n = pairs.len();
    let mut scene = Scene::from_color("edges", n, 1, vec![[0.5; 3]; n]);
    scene.features.insert(Feature::Depth, pairs.iter().map(|(a, _)| [*a, 0.0, 0.0]).collect());
    scene.features.insert(Feature::Texture, pairs.iter().map(|(_, b)| [*b, 0.0, 0.0]).collect());
    scene.features.insert(Feature::Normal, vec![[1.0, 0.0, 0.0]; n]);
    scene
}

fn ulp_neighbours(x: f32) -> [f32; 3] {
    [
        x,
        f32::from_bits(x.to_bits().wrapping_add(1)),
        if x == 0.0 { -1e-45 } else { f32::from_bits(x.to_bits().wrapping_sub(1)) },
    ]
}

const ULP: f64 = f32::EPSILON as f64;

/// What WGSL allows an implementation to err by, for `op` at inputs `a`, `b` with exact result `c`.
fn wgsl_accuracy(op: &str, a: f64, b: f64, c: f64) -> f64 {
    let trig = 2f64.powi(-11);
    match op {
        "sin" | "cos" => trig,
        // Inherited from sin/cos: tan = sin / cos with each off by up to `trig`.
        // Where cos is that close to 0 its sign is not the device's to keep, and
        // tan may be anything in [−BIG, BIG]: an NVIDIA H200 gives +BIG at f32's
        // π/2, where the exact value is −2.3e7 (docs/SEMANTICS.md).
        "tan" => {
            let (sin, cos) = (a.sin().abs(), a.cos().abs());
            if cos <= 2.0 * trig {
                2.0 * BIG
            } else {
                2.0 * ((sin + trig) / (cos - trig) - sin / cos)
            }
        }
        // The kernel composes two sines and a division by (τπ²s²) for s ≥ SINC_SMALL.
        "sinc" => {
            trig * 4.0
                / (1.0 + 30.0 * a * a).min(1.0 / (3.0 * std::f64::consts::PI.powi(2) * a.abs().max(1e-4).powi(2)) + 1.0)
        }
        // Polynomials whose terms (up to about 30) cancel: a few ulp of the largest term.
        "mitchell" | "epanechnikov" | "biweight" | "tricube" => 8.0 * ULP * c.abs() + 8.0 * ULP,
        "asin" | "acos" | "atan" => 4096.0 * ULP * c.abs().max(1.0),
        "exp" => (3.0 + 2.0 * a.abs()) * ULP * c.abs(),
        // exp2(b·log2(a)): log2 errs by 2⁻²¹ absolute near 1 and 3 ulp elsewhere, scaled by |b|.
        "pow" => {
            ((3.0 + 2.0 * (b * a.abs().max(1e-30).log2()).abs()) * ULP
                + std::f64::consts::LN_2 * b.abs() * (2f64.powi(-21) + 3.0 * ULP * a.abs().max(1e-30).log2().abs()))
                * c.abs()
        }
        // Multiplied out by squaring: each product's half-ulp, doubled by every squaring after it.
        "whole pow" => b * ULP * c.abs(),
        _ => 8.0 * ULP * c.abs().max(1e-30) + 1e-6 * ULP,
    }
}

/// Compare probe results with the CPU for every pixel of `scene`; `perturbed(k)`
/// gives one-pixel scenes whose inputs are pixel k's moved by one f32 ulp.
/// Returns the worst relative error seen on well-conditioned inputs.
fn check_probe(op: &str, expr: &Expr, scene: &Scene, perturbed: impl Fn(usize) -> Vec<Scene>) -> f64 {
    let gpu = gpu();
    let kernel = jit::compile(expr, jit::KernelSpec::of(KernelKind::Probe)).unwrap();
    let mut buffers = SceneBuffers::new(&gpu, scene);
    let (values, flags) = gpu.probe(&kernel, &mut buffers, scene).unwrap();
    let mut worst = 0.0f64;
    for k in 0..scene.pixels() {
        let (cpu_value, cpu_flags) = cpu::weight_at(expr, scene, k, k);
        let g = values[k] as f64;
        assert!(g.is_finite(), "{expr}: GPU gave {g} at pixel {k}");
        assert!(cpu_value.is_finite(), "{expr}: CPU gave {cpu_value} at pixel {k}");
        let neighbours: Vec<(f64, u32)> = perturbed(k).iter().map(|s| cpu::weight_at(expr, s, 0, 0)).collect();
        let spread = neighbours.iter().map(|(v, _)| (v - cpu_value).abs()).fold(0.0, f64::max);
        let boundary = neighbours.iter().any(|(_, f)| *f != cpu_flags);
        let inputs = (scene.features[&Feature::Depth][k][0], scene.features[&Feature::Texture][k][0]);
        let tolerance = wgsl_accuracy(op, inputs.0 as f64, inputs.1 as f64, cpu_value) + 4.0 * spread;
        assert!(
            (g - cpu_value).abs() <= tolerance,
            "{expr} at inputs {inputs:?}: GPU {g:e}, CPU {cpu_value:e}, tolerance {tolerance:e}"
        );
        assert!(
            flags[k] == cpu_flags || boundary,
            "{expr} at inputs {inputs:?}: GPU flags {} vs CPU flags {cpu_flags}",
            flags[k]
        );
        // Well conditioned: one ulp of input moves the result by at most 16 ulp.
        if spread <= 16.0 * ULP * cpu_value.abs().max(1.0) {
            worst = worst.max((g - cpu_value).abs() / cpu_value.abs().max(1.0));
        }
    }
    worst
}

#[test]
fn every_operator_agrees_with_the_cpu_at_its_edges() {
    let a = || Expr::Pair(PairOp::Dot, Feature::Depth, Feature::Normal);
    let b = || Expr::Pair(PairOp::Dot, Feature::Texture, Feature::Normal);
    let values = edges();
    let mut table = Vec::new();

    let pairs: Vec<(f32, f32)> = values.iter().map(|x| (*x, 0.0)).collect();
    let scene = edge_scene(&pairs);
    let perturb = |k: usize| -> Vec<Scene> {
        ulp_neighbours(pairs[k].0)[1..].iter().map(|x| edge_scene(&[(*x, pairs[k].1)])).collect()
    };
    for op in UnaryOp::ALL {
        let worst = check_probe(op.name(), &Expr::unary(*op, a()), &scene, perturb);
        table.push((op.name(), worst));
    }

    let pairs: Vec<(f32, f32)> = values.iter().flat_map(|x| values.iter().step_by(3).map(move |y| (*x, *y))).collect();
    let scene = edge_scene(&pairs);
    let perturb = |k: usize| -> Vec<Scene> {
        let mut out = Vec::new();
        for x in ulp_neighbours(pairs[k].0) {
            for y in ulp_neighbours(pairs[k].1) {
                out.push(edge_scene(&[(x, y)]));
            }
        }
        out
    };
    for op in BinaryOp::ALL {
        let worst = check_probe(op.name(), &Expr::binary(*op, a(), b()), &scene, perturb);
        table.push((op.name(), worst));
    }
    eprintln!("max GPU-vs-CPU error per operator, relative to max(1, |cpu|), well-conditioned inputs:");
    for (name, worst) in table {
        eprintln!("  {name:<14} {worst:.2e}");
    }
}

/// `pow(a, n)` for a whole literal n is multiplied out by squaring (no
/// `log2`, no `exp2`): at every edge value, negative bases (an odd power's
/// sign), bases whose power passes BIG or falls below TINY, and n up to the
/// largest multiplied out, it agrees with the CPU's `pow` within the
/// products' rounding, (n − 1) half-ulps, and no domain flag is raised.
#[test]
fn whole_powers_multiplied_out_agree_with_the_cpu_at_the_edges() {
    let a = || Expr::Pair(PairOp::Dot, Feature::Depth, Feature::Normal);
    let values = edges();
    let mut worst = 0.0f64;
    for n in [3u32, 4, 5, 7, 8, 31, 64, 127, 128] {
        let expr = parse_expr(&format!("pow({}, {n})", a())).unwrap();
        let kernel = jit::compile(&expr, jit::KernelSpec::of(KernelKind::Probe)).unwrap();
        assert!(!kernel.wgsl().contains("fj_pow"), "pow(·, {n}) still calls fj_pow:\n{}", kernel.wgsl());
        // The texture column carries n for the tolerance (the expression reads the literal).
        let pairs: Vec<(f32, f32)> = values.iter().map(|x| (*x, n as f32)).collect();
        let scene = edge_scene(&pairs);
        let perturb = |k: usize| -> Vec<Scene> {
            ulp_neighbours(pairs[k].0)[1..].iter().map(|x| edge_scene(&[(*x, pairs[k].1)])).collect()
        };
        worst = worst.max(check_probe("whole pow", &expr, &scene, perturb));
    }
    eprintln!("whole pow (n = 3 … 128, multiplied out): max GPU-vs-CPU error {worst:.2e}");
}

#[test]
fn corpus_filters_agree_with_the_cpu() {
    let gpu = gpu();
    let scene = synthetic_scene(20, 14, 3);
    let mut buffers = SceneBuffers::new(&gpu, &scene);
    let mut cases = corpus::named();
    cases.extend(crate::common::named_entries(include_str!("data/corpus.txt")));
    for (name, text) in cases {
        let expr = parse_expr(text).unwrap();
        let kernel = jit::compile(&expr, jit::KernelSpec::default()).unwrap();
        let out = gpu.filter(&kernel, &mut buffers, &scene, 3).unwrap();
        let reference = cpu::filter(&expr, &scene, 3).unwrap();
        let (fraction, worst) = agree_fraction(&out.rgb(), &reference.color);
        assert_eq!(fraction, 1.0, "@{name}: worst relative difference {worst:e}");
        let mismatched = out.flags.iter().zip(&reference.flags).filter(|(g, c)| g != c).count();
        assert!(mismatched <= scene.pixels() / 100, "@{name}: domain flags differ in {mismatched} pixels");
    }
}

#[test]
fn random_expressions_agree_with_the_cpu() {
    let gpu = gpu();
    let count = env_usize("FILTERJIT_RANDOM_EXPRS", 40);
    let scene = synthetic_scene(12, 10, 9);
    let mut buffers = SceneBuffers::new(&gpu, &scene);
    let alphabet = Alphabet::full();
    let mut rng = Rng::seeded(77);
    let mut fractions = Vec::new();
    for _ in 0..count {
        let depth = 2 + rng.below(6);
        let expr = alphabet.grow(&mut rng, depth);
        let kernel = jit::compile(&expr, jit::KernelSpec::default()).unwrap_or_else(|e| panic!("{expr}: {e}"));
        let out = gpu.filter(&kernel, &mut buffers, &scene, 2).unwrap();
        let reference = cpu::filter(&expr, &scene, 2).unwrap();
        let (fraction, worst) = agree_fraction(&out.rgb(), &reference.color);
        assert!(fraction >= 0.98, "`{expr}`: only {:.1}% of channels agree (worst {worst:e})", fraction * 100.0);
        fractions.push(fraction);
    }
    let exact = fractions.iter().filter(|f| **f == 1.0).count();
    eprintln!("{exact} of {count} random expressions agree on every channel");
}

#[test]
fn split_dispatches_and_windows_larger_than_the_image_match_the_cpu() {
    let gpu = gpu();
    let scene = synthetic_scene(64, 20, 5);
    let radius = 40; // window of 81x81 over a 64x20 image: several bands, every window clipped
    let expr = parse_expr("exp(-(distance2(normal) / 0.3 + distance1(pixel) / 20))").unwrap();
    let kernel = jit::compile(&expr, jit::KernelSpec::default()).unwrap();
    let mut buffers = SceneBuffers::new(&gpu, &scene);
    let out = gpu.filter(&kernel, &mut buffers, &scene, radius).unwrap();
    assert!(out.dispatches > 1, "expected several dispatches, got {}", out.dispatches);
    let reference = cpu::filter(&expr, &scene, radius).unwrap();
    let (fraction, worst) = agree_fraction(&out.rgb(), &reference.color);
    assert_eq!(fraction, 1.0, "worst relative difference {worst:e}");
}

#[test]
fn zero_weights_keep_the_noisy_colour_and_negative_weights_count_as_zero() {
    let gpu = gpu();
    let scene = synthetic_scene(8, 8, 1);
    let mut buffers = SceneBuffers::new(&gpu, &scene);
    for text in ["0", "-1", "0 * distance2(normal)", "-exp(distance2(color))"] {
        let kernel = jit::compile(&parse_expr(text).unwrap(), jit::KernelSpec::default()).unwrap();
        let out = gpu.filter(&kernel, &mut buffers, &scene, 2).unwrap();
        assert_eq!(out.rgb(), scene.color, "`{text}` leaves the image as it was");
    }
}

#[test]
fn thesis1_on_the_mitsuba_sample_beats_the_noisy_input() {
    let gpu = gpu();
    let expr = parse_expr(corpus::lookup("thesis1").unwrap()).unwrap();
    let request = Request { absent: Absent::Zero, ..Request::for_expr(&expr) };
    let scene = scene::load(&mitsuba_sample(), &request).unwrap();
    let kernel = jit::compile(&expr, jit::KernelSpec::default()).unwrap();
    let mut buffers = SceneBuffers::new(&gpu, &scene);
    let out = gpu.filter(&kernel, &mut buffers, &scene, 5).unwrap();
    let reference = scene.reference.as_ref().unwrap();
    let noisy = metrics::errors(&scene.color, reference, scene.spp);
    let filtered = metrics::errors(&out.rgb(), reference, scene.spp);
    eprintln!("thesis1 on mitsuba-cornell-64, r=5: relMSE {:.4} -> {:.4}", noisy.relmse, filtered.relmse);
    assert!(filtered.relmse < 0.5 * noisy.relmse, "filtered {filtered:?} vs noisy {noisy:?}");
    assert_eq!(out.flagged_pixels(), 0);
    let cpu_result = cpu::filter(&expr, &scene, 5).unwrap();
    assert_eq!(agree_fraction(&out.rgb(), &cpu_result.color).0, 1.0);
}

#[test]
fn a_kernel_binds_only_what_its_expression_reads() {
    let expr = parse_expr("exp(-distance2(normal)) * mitchell(colorVariance) + distance1(pixel) + dot(color)").unwrap();
    let layout = KernelLayout::of(&expr);
    assert_eq!(layout.describe(), "normal,colorVariance");
    let kernel = jit::compile(&expr, jit::KernelSpec::default()).unwrap();
    let bindings = kernel.wgsl().matches("@binding(").count();
    assert_eq!(bindings, 4 + 2, "params, colour, output, flags and the two inputs");
    for f in Feature::ALL.iter().filter(|f| **f != Feature::Normal) {
        assert!(!kernel.wgsl().contains(&format!("buf_{} ", f.name().to_ascii_lowercase())), "{f} is not bound");
    }
}

#[test]
fn equal_canonical_text_hits_the_pipeline_cache() {
    let gpu = gpu();
    let a = jit::compile(&parse_expr("1 + 2 * distance2(normal)").unwrap(), jit::KernelSpec::default()).unwrap();
    let b = jit::compile(&parse_expr("(1) + (2 * distance2( normal ))").unwrap(), jit::KernelSpec::default()).unwrap();
    let c = jit::compile(&parse_expr("2 + 2 * distance2(normal)").unwrap(), jit::KernelSpec::default()).unwrap();
    assert_eq!(a.key(), b.key());
    assert_ne!(a.key(), c.key());
    let (_, first) = gpu.pipeline(&a).unwrap();
    let (_, second) = gpu.pipeline(&b).unwrap();
    assert!(!first.cache_hit || second.cache_hit);
    assert!(second.cache_hit, "the same canonical text reuses the pipeline");
}

/// The expressions the lowering's rewrites are checked on: the shipped
/// filters, the test corpus and `random` random ones over the whole operator
/// table, of depth 3 to 3 + `depths` - 1.
fn rewrite_corpus(seed: u64, random: usize, depths: usize) -> Vec<Expr> {
    let mut exprs: Vec<Expr> = corpus::named().iter().map(|(_, t)| parse_expr(t).unwrap()).collect();
    exprs.extend(
        crate::common::named_entries(include_str!("data/corpus.txt")).iter().map(|(_, t)| parse_expr(t).unwrap()),
    );
    let alphabet = Alphabet::full();
    let mut rng = Rng::seeded(seed);
    for _ in 0..random {
        let depth = 3 + rng.below(depths);
        exprs.push(alphabet.grow(&mut rng, depth));
    }
    exprs
}

/// `e` lowered with `options` and filtered over `scene` at radius 2.
fn filtered_with(
    gpu: &Gpu,
    e: &Expr,
    options: jit::LowerOptions,
    buffers: &mut SceneBuffers,
    scene: &Scene,
) -> (jit::ValidatedKernel, Filtered) {
    let kernel =
        jit::validate(jit::lower(e, jit::KernelSpec { options, ..jit::KernelSpec::default() }).unwrap()).unwrap();
    let filtered = gpu.filter(&kernel, buffers, scene, 2).unwrap();
    (kernel, filtered)
}

#[test]
fn each_optimisation_gives_the_plain_kernels_results() {
    let gpu = gpu();
    use filterjit::jit::LowerOptions;
    let scene = synthetic_scene(16, 12, 8);
    let mut buffers = SceneBuffers::new(&gpu, &scene);
    let exprs = rewrite_corpus(404, env_usize("FILTERJIT_RANDOM_EXPRS", 40) / 4, 4);
    let variants = [
        ("fold", LowerOptions { fold_constants: true, ..LowerOptions::NONE }),
        ("cse", LowerOptions { common_subexpressions: true, ..LowerOptions::NONE }),
        ("hoist", LowerOptions { hoist_centre_terms: true, ..LowerOptions::NONE }),
        ("strength", LowerOptions { strength_reduction: true, ..LowerOptions::NONE }),
        ("skip-checks", LowerOptions { skip_redundant_checks: true, ..LowerOptions::NONE }),
        ("tiles", LowerOptions::NONE.with_tiles(2)),
        ("all", LowerOptions::ALL),
        ("all+tiles", LowerOptions::ALL.with_tiles(2)),
    ];
    let run = |e: &Expr, options: LowerOptions, buffers: &mut SceneBuffers| {
        filtered_with(&gpu, e, options, buffers, &scene).1
    };
    for e in &exprs {
        let plain = run(e, LowerOptions::NONE, &mut buffers);
        for (name, options) in variants {
            let optimised = run(e, options, &mut buffers);
            let plain_rgb = plain.rgb();
            for (k, (a, b)) in optimised.rgb().iter().zip(&plain_rgb).enumerate() {
                for q in 0..3 {
                    let err = (a[q] - b[q]).abs() / (b[q].abs() + 0.01);
                    assert!(err <= 1e-4, "{name} changes `{e}` at pixel {k}: {} vs {}", a[q], b[q]);
                }
            }
            assert_eq!(optimised.flags, plain.flags, "{name} changes the domain flags of `{e}`");
        }
    }
}

/// Leaving out the parts of `fin` a value's range proves idle
/// (`src/jit/range.rs`) computes the same f32s: the same bits as the kernel
/// with every guard, on the shipped filters, the corpus and random
/// expressions over the whole operator table, with and without the other
/// rewrites.
#[test]
fn guards_a_range_proves_idle_change_no_bit() {
    let gpu = gpu();
    use filterjit::jit::LowerOptions;
    let scene = synthetic_scene(16, 12, 9);
    let mut buffers = SceneBuffers::new(&gpu, &scene);
    let exprs = rewrite_corpus(405, env_usize("FILTERJIT_RANDOM_EXPRS", 40), 5);
    let run = |e: &Expr, options: LowerOptions, buffers: &mut SceneBuffers| {
        let (kernel, filtered) = filtered_with(&gpu, e, options, buffers, &scene);
        let guarded =
            ["fj_fin_pos(", "fj_flush", "fj_exp_nonpos(", "FJ_BIG)"].iter().any(|h| kernel.wgsl().contains(h));
        (filtered, guarded)
    };
    let mut elided = 0;
    for e in &exprs {
        for base in [LowerOptions::NONE, LowerOptions::ALL] {
            let (full, _) = run(e, LowerOptions { skip_redundant_checks: false, ..base }, &mut buffers);
            let (ranged, guarded) = run(e, LowerOptions { skip_redundant_checks: true, ..base }, &mut buffers);
            elided += guarded as usize;
            assert_eq!(ranged.color, full.color, "the ranges change `{e}`");
            assert_eq!(ranged.flags, full.flags, "the ranges change the domain flags of `{e}`");
        }
    }
    assert!(elided > exprs.len() / 4, "guards were left out in only {elided} kernels");
    // The real-time weight's sums are all of non-negative terms: none keeps `fj_add`.
    let realtime = parse_expr(corpus::lookup("realtime").unwrap()).unwrap();
    let kernel = jit::lower(&realtime, jit::KernelSpec::default()).unwrap();
    assert!(!kernel.wgsl.contains("fj_add("), "{}", kernel.wgsl);
}

#[test]
fn tiled_kernels_agree_across_bands_and_edges() {
    let gpu = gpu();
    use filterjit::jit::LowerOptions;
    let check = |scene: &Scene, name: &str, radius: u32| {
        let mut buffers = SceneBuffers::new(&gpu, scene);
        let e = parse_expr(corpus::lookup(name).unwrap()).unwrap();
        let lower = |options| {
            jit::validate(jit::lower(&e, jit::KernelSpec { options, ..jit::KernelSpec::default() }).unwrap()).unwrap()
        };
        let (plain, tiled) = (lower(LowerOptions::ALL), lower(LowerOptions::ALL.with_tiles(radius)));
        assert_eq!(tiled.source().tile_radius, Some(radius), "{name} fits in workgroup memory at radius {radius}");
        assert!(tiled.wgsl().contains("var<workgroup> tile_color"));
        let a = gpu.filter(&plain, &mut buffers, scene, radius).unwrap();
        let b = gpu.filter(&tiled, &mut buffers, scene, radius).unwrap();
        assert_eq!(a.color, b.color, "{name}: tiles read the same data, so the same bits");
        assert_eq!(a.flags, b.flags);
        // A tiled kernel refuses any other radius instead of reading outside its tile.
        let err = gpu.filter(&tiled, &mut buffers, scene, radius + 1).unwrap_err().to_string();
        assert!(err.contains(&format!("radius {radius}")), "{err}");
        b.dispatches
    };
    // 37x29 is not a multiple of the workgroup: tiles hang over every edge.
    let scene = synthetic_scene(37, 29, 12);
    for (name, radius) in [("thesis1", 4), ("thesis3", 3), ("crossBilateral", 3)] {
        check(&scene, name, radius);
    }
    // Radius 10 over 512 columns splits the image into bands of rows: tiles start mid-image.
    let wide = synthetic_scene(512, 40, 13);
    assert!(check(&wide, "bilateral", 10) > 1, "the image is split into bands");
    // Too large to fit: the kernel is made without tiles and says so.
    let e = parse_expr(corpus::lookup("thesis1").unwrap()).unwrap();
    let source =
        jit::lower(&e, jit::KernelSpec { options: LowerOptions::ALL.with_tiles(30), ..jit::KernelSpec::default() })
            .unwrap();
    assert_eq!(source.tile_radius, None);
}
