//! The filter pipeline (outliers → demodulate → form → remodulate): every
//! stage on the device against the f64 CPU reference, alone and end to end,
//! in filtering and in fitness.

use filterjit::cpu;
use filterjit::gpu::{FitnessScene, SceneBuffers};
use filterjit::jit::{self, KernelKind, LowerOptions, Shape};
use filterjit::lang::{parse_expr, ScalarVar};
use filterjit::pipeline::FilterPipeline;
use filterjit::{metrics, Expr, Scene};

use crate::common::{agree_fraction, gpu, synthetic_scene};

/// The synthetic scene with a raw albedo that has what real renders have:
/// black (emitters, escaped rays), ordinary values, and values far above 1.
fn scene_with_albedo(width: usize, height: usize, seed: u64) -> Scene {
    let mut scene = synthetic_scene(width, height, seed);
    let albedo = (0..scene.pixels())
        .map(|p| match p % 7 {
            0 => [0.0, 0.0, 0.0],
            1 => [250.0, 3.0, 0.5],
            k => [0.1 * k as f32, 0.9 - 0.1 * k as f32, 0.02 * k as f32],
        })
        .collect();
    scene.albedo = Some(albedo);
    scene
}

fn pipeline(text: &str) -> FilterPipeline {
    text.parse().unwrap_or_else(|e| panic!("{e}"))
}

/// Run `expr` through `pipeline` on the device.
fn gpu_filter(gpu: &filterjit::gpu::Gpu, expr: &Expr, scene: &Scene, p: &FilterPipeline, radius: u32) -> Vec<[f32; 3]> {
    let kernel = jit::compile(expr, jit::KernelSpec { shape: Shape::of(p), ..jit::KernelSpec::default() }).unwrap();
    let mut buffers = SceneBuffers::for_pipeline(gpu, scene, p).unwrap();
    gpu.filter(&kernel, &mut buffers, scene, radius).unwrap().rgb()
}

#[test]
fn the_pre_pass_alone_agrees_with_the_cpu() {
    // A window of radius 0 with weight 1 hands back the pre-pass's colour,
    // remodulated. Images narrower than the outlier neighbourhood and the
    // spread's steps included: every tap of both kernels checks the border.
    let gpu = gpu();
    let expr = parse_expr("1").unwrap();
    for (width, height) in [(23, 17), (1, 1), (1, 6), (5, 1), (2, 3)] {
        let scene = scene_with_albedo(width, height, 4);
        for text in [
            "outliers=2,window",
            "outliers=0,window",
            "demodulate,window",
            "outliers=1.5,demodulate,window",
            "outliers=2,keep,window",
            "outliers=1.5,keep,demodulate,window",
            "outliers=2,trim,window",
            "outliers=1,trim,keep,demodulate,window",
            "outliers=2,keep=surface,window",
            "outliers=1,trim,keep=surface,demodulate,window",
        ] {
            let p = pipeline(text);
            let on_gpu = gpu_filter(&gpu, &expr, &scene, &p, 0);
            let on_cpu = cpu::filter_pipeline(&expr, &scene, &p, 0).unwrap();
            let (fraction, worst) = agree_fraction(&on_gpu, &on_cpu.color);
            assert_eq!(fraction, 1.0, "{text} on {width}x{height}: worst relative difference {worst:e}");
        }
    }
}

#[test]
fn the_outlier_rule_tames_a_firefly_and_keeps_a_flat_image() {
    let mut scene = Scene::from_color("firefly", 9, 9, vec![[0.5, 0.5, 0.5]; 81]);
    scene.color[40] = [900.0, 800.0, 1000.0];
    let p = pipeline("outliers=2,window");
    let prepared = cpu::prepass(&scene, &p).unwrap();
    // Its neighbours are all 0.5 (no spread): the firefly becomes their luminance.
    let l = filterjit::pipeline::luminance(prepared.color[40].map(|v| v as f64));
    assert!((l - 0.5).abs() < 1e-6, "the firefly's luminance is {l}");
    let ratio = prepared.color[40][0] / prepared.color[40][2];
    assert!((ratio - 0.9).abs() < 1e-5, "the firefly keeps its hue: {ratio}");
    // Every other pixel is a neighbour of the firefly yet keeps its value.
    for (k, c) in prepared.color.iter().enumerate().filter(|(k, _)| *k != 40) {
        assert_eq!(*c, [0.5, 0.5, 0.5], "pixel {k}");
    }
    let gpu = gpu();
    let on_gpu = gpu_filter(&gpu, &parse_expr("1").unwrap(), &scene, &p, 0);
    assert!((on_gpu[40][1] - prepared.color[40][1]).abs() < 1e-5, "GPU {:?}", on_gpu[40]);
}

#[test]
fn trim_catches_two_fireflies_side_by_side() {
    // Two bright samples next to each other on a flat 9x9 image: each one is
    // in the other's neighbourhood and raises its limit, so the plain rule
    // lets both through; leaving out the brightest neighbour catches both.
    let mut scene = Scene::from_color("pair", 9, 9, vec![[0.5, 0.5, 0.5]; 81]);
    scene.color[40] = [60.0, 60.0, 60.0];
    scene.color[41] = [30.0, 30.0, 30.0];
    let luminance = |c: [f32; 3]| filterjit::pipeline::luminance(c.map(f64::from));
    let plain = cpu::prepass(&scene, &pipeline("outliers=2.5,window")).unwrap();
    assert!(luminance(plain.color[41]) > 10.0, "the plain rule keeps the dimmer one: {:?}", plain.color[41]);
    let trimmed = cpu::prepass(&scene, &pipeline("outliers=2.5,trim,window")).unwrap();
    for k in [40, 41] {
        // Without its partner the neighbourhood is flat: the limit is 0.5.
        let l = luminance(trimmed.color[k]);
        assert!((l - 0.5).abs() < 1e-6, "pixel {k}: luminance {l}");
    }
    // A pixel beside the pair: its two bright neighbours, one left out, still
    // raise its limit far above its own 0.5; it is unchanged.
    assert_eq!(trimmed.color[31], [0.5, 0.5, 0.5]);
    let gpu = gpu();
    let on_gpu = gpu_filter(&gpu, &parse_expr("1").unwrap(), &scene, &pipeline("outliers=2.5,trim,window"), 0);
    let on_cpu = trimmed.color.iter().map(|c| c.map(f64::from)).collect::<Vec<_>>();
    let (fraction, worst) = agree_fraction(&on_gpu, &on_cpu);
    assert_eq!(fraction, 1.0, "worst relative difference {worst:e}");
}

#[test]
fn keep_puts_back_what_the_clamp_removed_spread_around_it() {
    // Two fireflies on a dim 9x9 image, one in a corner: smaller than the
    // spread's reach, so every pass hands shares back from the borders.
    let mut scene = Scene::from_color("fireflies", 9, 9, vec![[0.5, 0.4, 0.3]; 81]);
    scene.color[40] = [900.0, 800.0, 1000.0];
    scene.color[0] = [50.0, 60.0, 70.0];
    let total = |image: &[[f32; 3]]| {
        image.iter().map(|c| c.map(f64::from)).fold([0.0; 3], |s, c| [0, 1, 2].map(|q| s[q] + c[q]))
    };
    let raw = total(&scene.color);
    let clamped = total(&cpu::prepass(&scene, &pipeline("outliers=2,window")).unwrap().color);
    let kept = cpu::prepass(&scene, &pipeline("outliers=2,keep,window")).unwrap().color;
    for q in 0..3 {
        assert!(clamped[q] < 0.1 * raw[q], "the clamp alone removes most of the light: {clamped:?} of {raw:?}");
        assert!((total(&kept)[q] - raw[q]).abs() <= 1e-5 * raw[q], "channel {q}: {:?} kept of {raw:?}", total(&kept));
    }
    // Spread, not left where it was: the firefly keeps a small part of its light.
    assert!(kept[40][0] < 0.1 * 900.0 && kept[40][0] > kept[44][0], "{:?} {:?}", kept[40], kept[44]);
    // The device keeps it too, through the whole pipeline with a weight that keeps every pixel.
    let gpu = gpu();
    let on_gpu = gpu_filter(&gpu, &parse_expr("1").unwrap(), &scene, &pipeline("outliers=2,keep,window"), 0);
    for q in 0..3 {
        assert!(
            (total(&on_gpu)[q] - raw[q]).abs() <= 1e-4 * raw[q],
            "device channel {q}: {:?} of {raw:?}",
            total(&on_gpu)
        );
    }
    let (fraction, worst) = agree_fraction(&on_gpu, &kept.iter().map(|c| c.map(f64::from)).collect::<Vec<_>>());
    assert_eq!(fraction, 1.0, "worst relative difference {worst:e}");
}

#[test]
fn keep_surface_hands_the_light_back_along_the_surface_and_toward_the_light() {
    // A 24x16 image: a floor (normal up) on the left, a wall (normal across)
    // on the right, each half dim, with a bright patch on the wall's far side.
    // One firefly on the floor, beside the wall: `keep` hands its light to both
    // sides alike, `keep=surface` mostly to the floor, and within the floor it
    // still spreads (the firefly keeps a small part).
    let (w, h) = (24usize, 16usize);
    let floor = |x: usize| x < 12;
    let mut scene = Scene::from_color("two planes", w, h, vec![[0.2, 0.2, 0.2]; w * h]);
    let normals = (0..w * h).map(|p| if floor(p % w) { [0.0, 1.0, 0.0] } else { [1.0, 0.0, 0.0] }).collect();
    scene.features.insert(filterjit::lang::Feature::Normal, normals);
    for y in 0..h {
        for x in 18..w {
            scene.color[y * w + x] = [2.0, 2.0, 2.0];
        }
    }
    let firefly = 8 * w + 11;
    scene.color[firefly] = [600.0, 500.0, 700.0];
    let total = |image: &[[f32; 3]], on: &dyn Fn(usize) -> bool| {
        image
            .iter()
            .enumerate()
            .filter(|(p, _)| on(*p))
            .map(|(_, c)| c.map(f64::from))
            .fold([0.0; 3], |s, c| [0, 1, 2].map(|q| s[q] + c[q]))
    };
    let all = |_: usize| true;
    let on_floor = |p: usize| floor(p % w);
    let raw = total(&scene.color, &all);
    let even = cpu::prepass(&scene, &pipeline("outliers=2,keep,window")).unwrap().color;
    let surface = cpu::prepass(&scene, &pipeline("outliers=2,keep=surface,window")).unwrap().color;
    for (q, (kept, raw)) in total(&surface, &all).into_iter().zip(raw).enumerate() {
        assert!((kept - raw).abs() <= 1e-5 * raw, "channel {q}: {kept} kept of {raw}");
    }
    // What the floor holds beyond its own dim light.
    let returned = |image: &[[f32; 3]]| total(image, &on_floor)[0] - 0.2 * (w * h / 2) as f64;
    assert!(returned(&surface) > 0.9 * 600.0, "the floor gets the floor's light back: {}", returned(&surface));
    assert!(returned(&even) < 0.8 * 600.0, "the even spread gives the wall much of it: {}", returned(&even));
    assert!(surface[firefly][0] < 0.1 * 600.0, "spread, not left in place: {:?}", surface[firefly]);
    // Without normals the scene cannot keep along the surface, and says so.
    let mut bare = scene.clone();
    bare.features.clear();
    let error = cpu::prepass(&bare, &pipeline("outliers=2,keep=surface,window")).unwrap_err().to_string();
    assert!(error.contains("normal"), "{error}");
    // The device keeps it the same, through a pipeline whose weight keeps every pixel.
    let gpu = gpu();
    let on_gpu = gpu_filter(&gpu, &parse_expr("1").unwrap(), &scene, &pipeline("outliers=2,keep=surface,window"), 0);
    let (fraction, worst) = agree_fraction(&on_gpu, &surface.iter().map(|c| c.map(f64::from)).collect::<Vec<_>>());
    assert_eq!(fraction, 1.0, "worst relative difference {worst:e}");
    for (q, (kept, raw)) in total(&on_gpu, &all).into_iter().zip(raw).enumerate() {
        assert!((kept - raw).abs() <= 1e-4 * raw, "device channel {q}: {kept} of {raw}");
    }
}

#[test]
fn demodulation_is_undone_and_stays_bounded_where_albedo_is_zero_or_above_one() {
    let scene = scene_with_albedo(14, 9, 8);
    let p = pipeline("demodulate,window");
    let prepared = cpu::prepass(&scene, &p).unwrap();
    let modulation = prepared.modulation.as_ref().unwrap();
    for (k, m) in modulation.iter().enumerate() {
        for q in 0..3 {
            assert!((0.1..=1.0).contains(&m[q]), "pixel {k}: modulation {m:?}");
            let back = prepared.color[k][q] * m[q];
            assert!((back - scene.color[k][q]).abs() <= 1e-5 * scene.color[k][q].abs().max(1.0), "pixel {k}");
        }
    }
    let without = cpu::prepass(&scene, &pipeline("window")).unwrap();
    assert!(without.modulation.is_none());
    assert_eq!(without.color, scene.color);
}

#[test]
fn atrous_and_whole_pipelines_agree_with_the_cpu() {
    let gpu = gpu();
    let scene = scene_with_albedo(40, 27, 6);
    let exprs = [
        "exp(-(distance2(color) / (0.02 + colorVariance) + distance2(normal) / 0.3))",
        "exp(-(distance2(normal) / 0.3 + distance1(pixel) / 20))",
        "1",
        // `level` is the pass: 0 in the window form (the weight is then 0 and the colour kept).
        "level",
        "exp(-(distance2(normal) / 0.3 + distance2(pixel) / (1 + 3 * level)))",
        // What the outlier rule measured (the synthetic scene's own values where the pipeline has no outliers).
        "exp(-(distance2(normal) / 0.3 + clampedShare * 4 + localStd / (localMean + 0.1)))",
        // The guide: blurred in the first pass, the pass's input after; against the colour.
        "exp(-(distance2(guide) / 0.5 + distance2(normal) / 0.3 + distance1(guide, color) / 4))",
        // The texture with the world position and the normal: read from their
        // fourth channels and the colour's after the first pass
        // (`jit::TEXTURE_IN_FOURTH_CHANNELS`), at the centre against another feature too.
        "exp(-(distance2(texture) / 0.1 + distance2(worldPosition) / 2 + distance2(normal) / 0.3 + distance1(texture, color) / 8))",
    ];
    for text in [
        "atrous=1",
        "atrous=4",
        "demodulate,atrous=3",
        "outliers=2,demodulate,atrous=5",
        "outliers=2,demodulate,window",
        "outliers=0.5,atrous=2",
        "outliers=2,demodulate,atrous3x3=4",
        "outliers=2,keep,demodulate,atrous3x3=4",
        "outliers=2.5,trim,keep,demodulate,atrous=4",
        "outliers=2.5,trim,keep=surface,demodulate,atrous=4",
        "outliers=2.5,trim,keep=surface,demodulate,atrous=4,planefit=3",
        "atrous=2,planefit=2",
        "outliers=2,demodulate,window,planefit=1",
        "atrous3x3=2",
        "outliers=2,demodulate,atrous=3,pixelfilter=0.6",
        "atrous=2,planefit=2,pixelfilter=0.3",
        // The anchor: after the form, and between planefit and the pixel
        // filter with a gate low enough that it pulls over much of the frame.
        "outliers=2,demodulate,atrous=3,anchor=2",
        "atrous=2,planefit=2,anchor=0.5,pixelfilter=0.3",
    ] {
        let p = pipeline(text);
        for e in exprs {
            let expr = parse_expr(e).unwrap();
            let on_gpu = gpu_filter(&gpu, &expr, &scene, &p, 2);
            let on_cpu = cpu::filter_pipeline(&expr, &scene, &p, 2).unwrap();
            let (fraction, worst) = agree_fraction(&on_gpu, &on_cpu.color);
            assert!(fraction >= 0.995, "{text} `{e}`: {:.2}% of channels agree, worst {worst:e}", fraction * 100.0);
            assert!(worst < 1e-2, "{text} `{e}`: worst relative difference {worst:e}");
        }
    }
}

#[test]
fn fitness_runs_the_whole_pipeline_on_the_device() {
    let gpu = gpu();
    let scene = scene_with_albedo(32, 24, 2);
    let reference = scene.reference.clone().unwrap();
    let exprs = [
        parse_expr("exp(-(distance2(color) / (0.02 + colorVariance) + distance2(normal) / 0.3))").unwrap(),
        parse_expr("exp(-distance2(texture) / 0.1)").unwrap(),
        parse_expr("exp(-(distance2(guide) / 0.5 + distance2(normal) / 0.3))").unwrap(),
    ];
    for text in [
        "outliers=2,demodulate,atrous=4",
        "atrous=2",
        "demodulate,window",
        "outliers=2,atrous3x3=3",
        "outliers=2,keep,demodulate,atrous3x3=2",
        "outliers=2.5,trim,keep,demodulate,atrous=2",
        "outliers=2.5,trim,keep=surface,demodulate,atrous=2",
        "outliers=2.5,trim,keep=surface,demodulate,atrous=2,planefit=3",
        "atrous=2,planefit=1",
    ] {
        let p = pipeline(text);
        let kernels: Vec<_> = exprs
            .iter()
            .map(|e| {
                jit::compile(
                    e,
                    jit::KernelSpec { kind: KernelKind::Fitness, options: LowerOptions::ALL, shape: Shape::of(&p) },
                )
                .unwrap()
            })
            .collect();
        let refs: Vec<_> = kernels.iter().collect();
        let mut scenes = vec![FitnessScene::for_pipeline(&gpu, &scene, &p).unwrap()];
        let errors = gpu.evaluate_fitness(&refs, &mut scenes, &[&scene], 2).unwrap();
        for (e, row) in exprs.iter().zip(&errors) {
            let filtered = cpu::filter_pipeline(e, &scene, &p, 2).unwrap();
            let rgb: Vec<[f32; 3]> = filtered.color.iter().map(|c| c.map(|v| v as f32)).collect();
            let expected = metrics::errors(&rgb, &reference, None).relmse;
            let got = row[0].relmse;
            assert!((got - expected).abs() <= 1e-3 * expected, "{text} `{e}`: device {got}, CPU {expected}");
            assert_eq!(row[0].flags, 0);
            // The light the fitness rule may charge: the output's mean luminance.
            let (got, expected) = (row[0].luminance, metrics::mean_luminance(&rgb));
            assert!(
                expected > 0.0 && (got - expected).abs() <= 1e-4 * expected,
                "{text} `{e}`: luminance {got}, CPU {expected}"
            );
        }
    }
}

/// The guide (docs/SEMANTICS.md, "The guide"): in the first pass the
/// colour blurred by the 3×3 B-spline, each pixel the mean of its taps inside
/// the image; from the second pass on the pass's input. A weight that reads
/// only the guide sees a lone bright sample at a quarter of its value.
#[test]
fn the_guide_is_the_colour_blurred_in_the_first_pass_and_the_input_after() {
    let mut scene = synthetic_scene(9, 7, 3);
    scene.color = vec![[0.0; 3]; scene.pixels()];
    let (w, firefly) = (scene.width, 3 * scene.width + 4);
    scene.color[firefly] = [8.0, 4.0, 2.0];
    let guide = cpu::guide(&scene);
    assert_eq!(guide[firefly], [2.0, 1.0, 0.5], "a quarter of the sample at its own pixel");
    assert_eq!(guide[firefly + 1], [1.0, 0.5, 0.25], "an eighth beside it");
    assert_eq!(guide[firefly + w + 1], [0.5, 0.25, 0.125], "a sixteenth across the corner");
    assert_eq!(guide[firefly + 2], [0.0; 3], "nothing two pixels away");
    // A corner's taps inside the image are (1/2, 1/4) each way, renormalised.
    scene.color[0] = [9.0, 0.0, 0.0];
    assert_eq!(cpu::guide(&scene)[0][0], 9.0 * 4.0 / 9.0);
    // The weight `distance2(guide)` is 0 between a pixel and itself whatever
    // the pass, and the same on the device: a probe of the first pass.
    let gpu = gpu();
    for text in ["atrous3x3=1", "window"] {
        let expr = parse_expr("distance2(guide, color)").unwrap();
        let p = pipeline(text);
        let mut buffers = SceneBuffers::for_pipeline(&gpu, &scene, &p).unwrap();
        let kernel = jit::compile(&expr, jit::KernelSpec::of(KernelKind::Probe)).unwrap();
        let (weights, _) = gpu.probe(&kernel, &mut buffers, &scene).unwrap();
        let guide = cpu::guide(&scene);
        for (i, ((c, g), weight)) in scene.color.iter().zip(&guide).zip(&weights).enumerate() {
            let expected = ((0..3).map(|k| (c[k] - g[k]) as f64 * (c[k] - g[k]) as f64).sum::<f64>()).sqrt();
            assert!((*weight as f64 - expected).abs() <= 1e-5 * expected.max(1.0), "{text} pixel {i}");
        }
    }
}

#[test]
fn a_3x3_pass_reads_only_the_taps_one_step_away() {
    // One bright pixel, weight 1: pass k of the 3x3 stencil spreads it 2^k
    // pixels each way and no further, with the linear B-spline's weights.
    let gpu = gpu();
    let mut scene = synthetic_scene(9, 9, 1);
    scene.color = vec![[0.0; 3]; 81];
    scene.color[4 * 9 + 4] = [16.0; 3];
    let expr = parse_expr("1").unwrap();
    let at = |image: &[[f32; 3]], x: usize, y: usize| image[y * 9 + x][0];
    let one = gpu_filter(&gpu, &expr, &scene, &pipeline("atrous3x3=1"), 2);
    assert_eq!(at(&one, 4, 4), 16.0 * 0.25, "the centre keeps h(0)^2 = 1/4 of itself");
    assert_eq!(at(&one, 5, 4), 16.0 * 0.125, "a step away: h(0) h(1) = 1/8");
    assert_eq!(at(&one, 5, 5), 16.0 / 16.0, "diagonal: h(1)^2 = 1/16");
    assert_eq!((at(&one, 6, 4), at(&one, 4, 2)), (0.0, 0.0), "two pixels away is outside a 3x3 pass");
    let cubic = gpu_filter(&gpu, &expr, &scene, &pipeline("atrous=1"), 2);
    assert!(at(&cubic, 6, 4) > 0.0, "the 5x5 stencil reaches two pixels");
    let two = gpu_filter(&gpu, &expr, &scene, &pipeline("atrous3x3=2"), 2);
    let on_cpu = cpu::filter_pipeline(&expr, &scene, &pipeline("atrous3x3=2"), 2).unwrap();
    assert_eq!(agree_fraction(&two, &on_cpu.color).0, 1.0);
    assert!(at(&two, 7, 4) > 0.0 && at(&two, 8, 4) == 0.0, "two passes reach 1 + 2 pixels");
}

#[test]
fn level_is_the_pass_index() {
    // Weight `level`: pass 0 keeps every colour (all weights 0), pass 1 averages.
    let gpu = gpu();
    let scene = scene_with_albedo(12, 10, 3);
    let expr = parse_expr("level").unwrap();
    let window = gpu_filter(&gpu, &expr, &scene, &pipeline("window"), 2);
    assert_eq!(window, scene.color, "the window form's level is 0: the noisy colour is kept");
    let one = gpu_filter(&gpu, &expr, &scene, &pipeline("atrous=1"), 2);
    assert_eq!(one, scene.color, "pass 0 alone keeps the noisy colour");
    let two = gpu_filter(&gpu, &expr, &scene, &pipeline("atrous=2"), 2);
    assert_ne!(two, scene.color, "pass 1 filters");
    let on_cpu = cpu::filter_pipeline(&expr, &scene, &pipeline("atrous=2"), 2).unwrap();
    assert_eq!(agree_fraction(&two, &on_cpu.color).0, 1.0);
}

#[test]
fn a_kernel_runs_only_on_scenes_prepared_for_its_shape() {
    let gpu = gpu();
    let scene = scene_with_albedo(8, 8, 1);
    let window = jit::compile(&parse_expr("1").unwrap(), jit::KernelSpec::default()).unwrap();
    let mut buffers = SceneBuffers::for_pipeline(&gpu, &scene, &pipeline("atrous=2")).unwrap();
    let error = gpu.filter(&window, &mut buffers, &scene, 1).unwrap_err().to_string();
    assert!(error.contains("prepared for pipeline `atrous=2`"), "{error}");
    let mut plain = scene.clone();
    plain.albedo = None;
    let error = SceneBuffers::for_pipeline(&gpu, &plain, &pipeline("demodulate,window")).err().unwrap().to_string();
    assert!(error.contains("has no `texture` (the albedo `demodulate` divides by)"), "{error}");
}

/// Kernels run as trusted modules (wgpu's run-time bounds checks and loop
/// bounding off, the default) compute exactly what they compute with them.
#[test]
fn trusted_kernels_give_the_same_bits_as_checked_ones() {
    let turn = gpu();
    // A device of its own: switching the checks empties its pipeline cache.
    let gpu = filterjit::gpu::Gpu::open_like(&turn).unwrap();
    let scene = scene_with_albedo(37, 21, 5);
    let expr = parse_expr("exp(-(distance2(color) / (0.02 + colorVariance) + distance2(normal) / 0.3))").unwrap();
    for (text, options) in [
        ("window", LowerOptions::ALL),
        ("window", LowerOptions::ALL.with_tiles(3)),
        ("outliers=2,demodulate,atrous=4", LowerOptions::ALL),
    ] {
        let p = pipeline(text);
        let kernel =
            jit::compile(&expr, jit::KernelSpec { kind: KernelKind::Filter, options, shape: Shape::of(&p) }).unwrap();
        let run = |checks: bool| {
            gpu.set_kernel_runtime_checks(checks);
            let mut buffers = SceneBuffers::for_pipeline(&gpu, &scene, &p).unwrap();
            gpu.filter(&kernel, &mut buffers, &scene, 3).unwrap()
        };
        let (trusted, checked) = (run(false), run(true));
        assert_eq!(trusted.color, checked.color, "{text}");
        assert_eq!(trusted.flags, checked.flags, "{text}");
    }
    gpu.set_kernel_runtime_checks(false);
}

/// Fused fitness kernels (several individuals, one kernel) give every member
/// the relMSE and domain flags of its own kernel, bit for bit: in the window
/// form and the remodulating one, with tiles and without, on scenes of
/// several dispatch bands, with members that read different inputs and raise
/// different domain errors.
#[test]
fn fused_fitness_kernels_score_each_member_as_its_own_kernel() {
    let gpu = gpu();
    let exprs: Vec<Expr> = [
        "exp(-(distance2(color) / (0.02 + colorVariance) + distance2(normal) / 0.3))",
        "sqrt(dot(normal, color) - 0.5)",
        "exp(-distance2(texture) / 0.1)",
        "acos(distance1(pixel) / 2) + pow(distance2(color) - 0.3, 0.5)",
        "1",
    ]
    .iter()
    .map(|t| parse_expr(t).unwrap())
    .collect();
    // Small scenes, and one tall enough for several dispatch bands at radius 10.
    let scenes = [scene_with_albedo(19, 13, 4), scene_with_albedo(16, 620, 5)];
    for (text, radius) in [("window", 2), ("demodulate,window", 3), ("window", 10)] {
        let p = pipeline(text);
        for tiles in [None, Some(radius)] {
            let options = LowerOptions { tile_radius: tiles, ..LowerOptions::ALL };
            let shape = Shape::of(&p);
            let singles: Vec<_> = exprs
                .iter()
                .map(|e| jit::compile(e, jit::KernelSpec { kind: KernelKind::Fitness, options, shape }).unwrap())
                .collect();
            let fused = [
                jit::compile_fused(&exprs[..3], jit::KernelSpec { kind: jit::KernelKind::Fitness, options, shape })
                    .unwrap(),
                jit::compile_fused(&exprs[3..], jit::KernelSpec { kind: jit::KernelKind::Fitness, options, shape })
                    .unwrap(),
            ];
            assert_eq!(fused[0].source().exprs.len(), 3);
            let data: Vec<&Scene> = scenes.iter().collect();
            let mut prepared: Vec<_> =
                scenes.iter().map(|s| FitnessScene::for_pipeline(&gpu, s, &p).unwrap()).collect();
            let one_by_one =
                gpu.evaluate_fitness(&singles.iter().collect::<Vec<_>>(), &mut prepared, &data, radius).unwrap();
            let together =
                gpu.evaluate_fitness(&fused.iter().collect::<Vec<_>>(), &mut prepared, &data, radius).unwrap();
            assert_eq!(together.len(), exprs.len(), "one row per member");
            for ((e, a), b) in exprs.iter().zip(&one_by_one).zip(&together) {
                for (s, (x, y)) in a.iter().zip(b).enumerate() {
                    let what = format!("{text} r{radius} tiles {tiles:?} scene {s} `{e}`");
                    assert_eq!(x.relmse.to_bits(), y.relmse.to_bits(), "{what}: {} against {}", x.relmse, y.relmse);
                    assert_eq!(x.luminance.to_bits(), y.luminance.to_bits(), "{what}: luminance");
                    assert_eq!(x.flags, y.flags, "{what}: domain flags");
                }
            }
            // The members raise different flags: sqrt of a negative, acos out of range.
            let flags: Vec<u32> = one_by_one.iter().map(|row| row[0].flags).collect();
            assert!(flags[1] != 0 && flags[3] != 0 && flags[1] != flags[3], "{flags:?}");
            assert_eq!(flags[0] | flags[2] | flags[4], 0, "{flags:?}");
        }
    }
}

/// Fitness on tiles: a tile's interior is filtered from the same data as in
/// the whole image (its halo holds what the pipeline reads), so tiles that
/// cover a scene give its whole-image error, through every pipeline stage.
#[test]
fn fitness_tiles_covering_a_scene_give_its_whole_image_error() {
    use filterjit::fitness::{FitnessTiles, Scorer, Settings, TileSampling};
    let gpu = gpu();
    let exprs: Vec<Expr> = [
        "exp(-(distance2(color) / (0.02 + colorVariance) + distance2(normal) / 0.3 + distance2(pixel) / 4))",
        "exp(-distance2(texture) / 0.1) * tricube(distance1(pixel) / 3)",
        "sqrt(dot(normal, color) - 0.5)",
        // The guide reads one pixel beyond the first pass's taps.
        "exp(-(distance2(guide) / 0.3 + distance2(normal) / 0.3))",
    ]
    .iter()
    .map(|t| parse_expr(t).unwrap())
    .collect();
    let scenes = vec![scene_with_albedo(48, 40, 9), scene_with_albedo(32, 24, 10)];
    // A window of radius 8 reaches exactly one workgroup: a halo without slack.
    for (text, radius) in [("window", 2), ("outliers=2,demodulate,atrous=3", 2), ("window", 8)] {
        let p = pipeline(text);
        let whole_images = Settings { devices: Some(1), ..Settings::for_pipeline(radius, p, 1) };
        let on_tiles = |sampling| Settings { tiles: Some(FitnessTiles { sampling, seed: 3 }), ..whole_images.clone() };
        let mut whole = Scorer::new(&gpu, scenes.clone(), &whole_images).unwrap();
        let every_cell = TileSampling { count: 1000, size: 8 };
        let mut tiled = Scorer::new(&gpu, scenes.clone(), &on_tiles(every_cell)).unwrap();
        assert!(tiled.on_tiles_only() && !whole.on_tiles_only());
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * a.abs().max(b.abs()).max(1e-30);
        for (a, b) in whole.noisy_relmse().iter().zip(tiled.noisy_relmse()) {
            assert!(close(*a, *b), "{text}: noisy relMSE {a} whole, {b} on tiles");
        }
        let (w, t) = (whole.errors(&exprs).unwrap(), tiled.errors(&exprs).unwrap());
        for ((e, w), t) in exprs.iter().zip(&w).zip(&t) {
            let (w, t) = (w.as_ref().unwrap(), t.as_ref().unwrap());
            assert_eq!(w.len(), scenes.len(), "one error per scene, not per tile");
            for (s, (w, t)) in w.iter().zip(t).enumerate() {
                assert!(close(w.relmse, t.relmse), "{text} scene {s} `{e}`: {} whole, {} on tiles", w.relmse, t.relmse);
                let close_f32 = (w.luminance - t.luminance).abs() <= 1e-5 * w.luminance;
                assert!(close_f32, "{text} scene {s} `{e}`: luminance {} whole, {} on tiles", w.luminance, t.luminance);
                assert_eq!(w.flags, t.flags, "{text} scene {s} `{e}`: flags");
            }
        }
        // The square-root member flags on these scenes; the check above compared something.
        assert_ne!(w[2].as_ref().unwrap()[0].flags, 0);
        // A few tiles are a sample, not the whole.
        let mut sampled = Scorer::new(&gpu, scenes.clone(), &on_tiles(TileSampling { count: 3, size: 8 })).unwrap();
        let s = sampled.errors(&exprs[..1]).unwrap();
        assert_ne!(s[0].as_ref().unwrap()[0].relmse, w[0].as_ref().unwrap()[0].relmse, "{text}: three tiles of thirty");
    }
}

/// A few tiles score their cells as the whole image filters them, whether
/// each cell has a crop of its own or, where the pipeline reaches far
/// (`keep=surface`), the cells share one crop around them all.
#[test]
fn a_few_tiles_score_their_cells_as_the_whole_image_filters_them() {
    use filterjit::fitness::{tiles, FitnessTiles, Scorer, Settings, TileSampling};
    let gpu = gpu();
    let expr = parse_expr("exp(-(distance2(color) / 0.3 + distance2(normal) / 0.3 + distance2(pixel) / 4))").unwrap();
    let scene = scene_with_albedo(96, 96, 11);
    let (sampling, seed, radius) = (TileSampling { count: 2, size: 16 }, 1, 2);
    for (text, crops) in [("outliers=2,demodulate,atrous=2", 2), ("outliers=2,keep=surface,demodulate,atrous=2", 1)] {
        let p = pipeline(text);
        let cut = tiles::cut(std::slice::from_ref(&scene), sampling, &p, radius, seed);
        assert_eq!(cut.len(), crops, "{text}: crops for two cells");
        let settings = Settings {
            devices: Some(1),
            tiles: Some(FitnessTiles { sampling, seed }),
            ..Settings::for_pipeline(radius, p, 1)
        };
        let mut scorer = Scorer::new(&gpu, vec![scene.clone()], &settings).unwrap();
        let on_tiles = scorer.errors(std::slice::from_ref(&expr)).unwrap()[0].as_ref().unwrap()[0];
        // The same cells' pixels, from the whole image filtered at once.
        let whole = gpu_filter(&gpu, &expr, &scene, &p, radius);
        let reference = scene.reference.as_ref().unwrap();
        let (mut image, mut truth) = (Vec::new(), Vec::new());
        for t in &cut {
            let (x0, y0) = t.crop.name.rsplit_once('@').unwrap().1.split_once(',').unwrap();
            let (x0, y0): (usize, usize) = (x0.parse().unwrap(), y0.parse().unwrap());
            for r in t.counted.as_ref().unwrap() {
                for y in y0 + r.y as usize..y0 + (r.y + r.height) as usize {
                    for x in x0 + r.x as usize..x0 + (r.x + r.width) as usize {
                        image.push(whole[y * scene.width + x]);
                        truth.push(reference[y * scene.width + x]);
                    }
                }
            }
        }
        assert_eq!(image.len(), 2 * 16 * 16, "{text}");
        let expected = metrics::errors(&image, &truth, scene.spp).relmse;
        let close = (on_tiles.relmse - expected).abs() <= 1e-5 * expected;
        assert!(close, "{text}: {} on tiles, {expected} from the whole image", on_tiles.relmse);
    }
}

/// `localMean`, `localStd` and `clampedShare` are what the outlier rule
/// measured: a firefly's clamped share is most of it, a flat image measures
/// its own luminance and no spread, and a pipeline without outliers has none
/// of them (an error that says so, on the device and on the CPU).
#[test]
fn the_outlier_rule_s_measures_are_terminals() {
    let gpu = gpu();
    let (w, h) = (9, 9);
    let mut scene = synthetic_scene(w, h, 2);
    for v in ScalarVar::FROM_PREPASS {
        scene.variances.remove(&v);
    }
    scene.color = vec![[0.5, 0.5, 0.5]; w * h];
    scene.color[4 * w + 4] = [50.0, 50.0, 50.0];
    let p = pipeline("outliers=2,window");
    let probe = |text: &str| {
        let expr = parse_expr(text).unwrap();
        // A weight of 1 at the centre only (radius 0): the filtered colour is
        // the prepared colour, and the measure times 0 keeps the weight 1.
        let cpu = cpu::filter_pipeline(&expr, &scene, &p, 0).unwrap();
        let gpu = gpu_filter(&gpu, &expr, &scene, &p, 0);
        (cpu, gpu)
    };
    let (cpu, gpu_out) = probe("1 + 0 * (localMean + localStd + clampedShare)");
    assert!((cpu.color[4 * w + 4][0] - 0.5).abs() < 1e-6 && (gpu_out[4 * w + 4][0] - 0.5).abs() < 1e-6);
    // The measures themselves, through the CPU reference's prepass.
    let prepared = cpu::prepass(&scene, &p).unwrap();
    let local = prepared.local.expect("outliers measure");
    let l = filterjit::pipeline::luminance([50.0, 50.0, 50.0]);
    assert!((local[2][4 * w + 4] as f64 - (l - 0.5) / l).abs() < 1e-6, "the firefly's clamped share");
    assert!((local[0][0] - 0.5).abs() < 1e-6 && local[1][0] == 0.0 && local[2][0] == 0.0, "a flat corner");
    assert!(local[1][4 * w + 3] > 1.0, "next to the firefly the spread is large");
    // Without outliers there is nothing to read.
    let plain = pipeline("atrous=2");
    let expr = parse_expr("exp(-clampedShare)").unwrap();
    let kernel =
        jit::compile(&expr, jit::KernelSpec { shape: Shape::of(&plain), ..jit::KernelSpec::default() }).unwrap();
    let mut buffers = SceneBuffers::for_pipeline(&gpu, &scene, &plain).unwrap();
    let error = gpu.filter(&kernel, &mut buffers, &scene, 2).unwrap_err().to_string();
    assert!(error.contains("clampedShare") && error.contains("outliers=k"), "{error}");
    let error = cpu::filter_pipeline(&expr, &scene, &plain, 2).unwrap_err().to_string();
    assert!(error.contains("clampedShare") && error.contains("outlier pre-pass"), "{error}");
}

/// A scene that lacks an input is the user's data error, named as such
/// (scene and input), by one rule on the device and on the CPU alike.
#[test]
fn a_missing_input_is_a_data_error_naming_scene_and_input() {
    use filterjit::gpu::GpuError;
    use filterjit::lang::Feature;
    use filterjit::scene::{Missing, MissingInput};
    let gpu = gpu();
    let mut scene = synthetic_scene(16, 16, 3);
    scene.features.remove(&Feature::Normal);
    scene.name = "lacking".into();
    let expr = parse_expr("exp(-distance2(normal))").unwrap();
    let want = MissingInput { scene: "lacking".into(), missing: Missing::Feature(Feature::Normal) };
    let kernel = jit::compile(&expr, jit::KernelSpec::default()).unwrap();
    let mut buffers = SceneBuffers::new(&gpu, &scene);
    match gpu.filter(&kernel, &mut buffers, &scene, 2) {
        Err(GpuError::MissingInput(got)) => assert_eq!(got, want),
        other => panic!("not a data error: {:?}", other.map(|_| ())),
    }
    assert_eq!(cpu::filter(&expr, &scene, 2).err(), Some(want.clone()));
    // What the outlier pre-pass measures is missing without outliers (or the scene's own), and says so.
    scene.variances.remove(&ScalarVar::LocalStd);
    let mut buffers = SceneBuffers::new(&gpu, &scene);
    let measured = parse_expr("exp(-localStd)").unwrap();
    let err =
        gpu.filter(&jit::compile(&measured, jit::KernelSpec::default()).unwrap(), &mut buffers, &scene, 2).unwrap_err();
    assert!(matches!(&err, GpuError::MissingInput(m) if m.missing == Missing::Measured(ScalarVar::LocalStd)), "{err}");
    assert!(err.to_string().contains("outliers=k"), "{err}");
}

/// With `light_tolerance`, each scene's error is charged for the light the
/// candidate moved against the noisy input's, candidates' and the baseline's
/// alike; without it fitness is relMSE alone.
#[test]
fn the_fitness_rule_charges_the_light_a_filter_moves() {
    use filterjit::fitness::{charged, FitnessRule, Pool, Scorer, Settings};
    let gpu = gpu();
    let scenes = vec![scene_with_albedo(40, 32, 11), scene_with_albedo(32, 24, 12)];
    // The clamp removes light and nothing puts it back.
    let p = pipeline("outliers=2,window");
    let expr = parse_expr("exp(-(distance2(color) / 0.05 + distance2(pixel) / 4))").unwrap();
    let rule = |light_tolerance| FitnessRule { relative_to: None, pool: Pool::Mean, light_tolerance };
    let settings = |light| Settings { devices: Some(1), rule: rule(light), ..Settings::for_pipeline(2, p, 1) };
    let mut plain = Scorer::new(&gpu, scenes.clone(), &settings(None)).unwrap();
    let mut charging = Scorer::new(&gpu, scenes.clone(), &settings(Some(0.05))).unwrap();
    let errors = plain.errors(std::slice::from_ref(&expr)).unwrap().pop().unwrap();
    let per_scene = errors.as_ref().unwrap();
    let light = plain.light_moved(per_scene);
    assert!(light.iter().all(|l| l.is_some_and(|l| l < 0.999)), "the clamp darkens: {light:?}");
    // The device's luminance is the CPU's on the filtered image, over the noisy input's.
    for (scene, l) in scenes.iter().zip(&light) {
        let filtered = cpu::filter_pipeline(&expr, scene, &p, 2).unwrap();
        let on_cpu = metrics::mean_luminance(&filtered.color) / metrics::mean_luminance(&scene.color);
        assert!((l.unwrap() - on_cpu).abs() < 1e-4, "device {l:?}, CPU {on_cpu}");
    }
    let f_plain = plain.fitness(&errors).unwrap();
    let charged_errors = charging.errors(std::slice::from_ref(&expr)).unwrap().pop().unwrap();
    let f_charged = charging.fitness(&charged_errors).unwrap();
    let expected: f64 = per_scene
        .iter()
        .zip(plain.noisy_relmse())
        .zip(&light)
        .map(|((e, noisy), l)| charged(e.relmse, l.unwrap(), 1.0, Some(0.05)) / noisy)
        .sum::<f64>()
        / scenes.len() as f64;
    assert!(f_charged > f_plain, "{f_charged} against {f_plain}");
    assert!((f_charged - expected).abs() <= 1e-9 * expected, "{f_charged} against {expected}");
    // Relative to a baseline, the baseline is charged too: it scores exactly 1 against itself.
    let against_itself =
        Settings { rule: FitnessRule { relative_to: Some(expr.to_string()), ..rule(Some(0.05)) }, ..settings(None) };
    let mut baseline = Scorer::new(&gpu, scenes, &against_itself).unwrap();
    let own = baseline.errors(std::slice::from_ref(&expr)).unwrap().pop().unwrap();
    assert_eq!(baseline.fitness(&own).unwrap(), 1.0);
}

/// `planefit` (docs/SEMANTICS.md, "The pipeline"): a plane is kept as it is,
/// a blotch on a flat surface is flattened, a step in the light (a shadow's
/// edge, ten times brighter on one side) stays a step, and so does a step in
/// the normal; where the plane is steep the pixel keeps its value.
#[test]
fn planefit_keeps_planes_and_edges_and_flattens_blotches() {
    use filterjit::pipeline::PlaneFit;
    let (w, h) = (24usize, 20usize);
    let fit = PlaneFit { radius: 3 };
    let up = vec![[0.0f32, 0.0, 1.0]; w * h];
    let at = |x: usize, y: usize| y * w + x;
    let run = |image: &[[f32; 3]], normals: &[[f32; 3]]| cpu::planefit(image, normals, None, w, h, fit);

    // A gentle ramp (1 % a pixel) is a plane: kept where the window is whole, and near it at the border.
    let ramp: Vec<[f32; 3]> = (0..w * h).map(|i| [1.0 + 0.01 * (i % w) as f32; 3]).collect();
    let out = run(&ramp, &up);
    for y in 0..h {
        for x in 0..w {
            let (got, want) = (out[at(x, y)][0], ramp[at(x, y)][0] as f64);
            let inside = (3..w - 3).contains(&x) && (3..h - 3).contains(&y);
            let tolerance = if inside { 1e-6 } else { 2e-3 };
            assert!((got - want).abs() < tolerance * want, "({x}, {y}): {got} for {want}");
        }
    }

    // A blotch (+20 % over 3x3 pixels) on a flat wall loses most of its excess.
    let mut blotch = vec![[1.0f32; 3]; w * h];
    for y in 9..12 {
        for x in 10..13 {
            blotch[at(x, y)] = [1.2; 3];
        }
    }
    let out = run(&blotch, &up);
    assert!(out[at(11, 10)][0] < 1.1, "the blotch's centre: {}", out[at(11, 10)][0]);

    // A step in the light from 1 to 10 at x = 12: both sides keep their level.
    let step: Vec<[f32; 3]> = (0..w * h).map(|i| if i % w < 12 { [1.0; 3] } else { [10.0; 3] }).collect();
    let out = run(&step, &up);
    for y in 0..h {
        assert!((out[at(11, y)][0] - 1.0).abs() < 0.02, "dark side: {}", out[at(11, y)][0]);
        assert!((out[at(12, y)][0] - 10.0).abs() < 0.2, "bright side: {}", out[at(12, y)][0]);
    }

    // A fold (the normal turns at x = 12), the same light on both sides but a
    // blotch on one: the other side does not take it.
    let fold: Vec<[f32; 3]> = (0..w * h).map(|i| if i % w < 12 { [0.0, 0.0, 1.0] } else { [1.0, 0.0, 0.0] }).collect();
    let mut lit = vec![[1.0f32; 3]; w * h];
    for y in 0..h {
        lit[at(10, y)] = [1.3; 3];
        lit[at(11, y)] = [1.3; 3];
    }
    let out = run(&lit, &fold);
    for y in 3..h - 3 {
        assert!((out[at(12, y)][0] - 1.0).abs() < 0.01, "across the fold: {}", out[at(12, y)][0]);
    }

    // A steep ramp (a contact shadow's falloff): the fit is not trusted, the pixel keeps its value.
    let steep: Vec<[f32; 3]> = (0..w * h).map(|i| [(0.02 + ((i % w) as f32 / 8.0).powi(3)) * 4.0; 3]).collect();
    let out = run(&steep, &up);
    let (x, y) = (6, 10);
    let (got, was) = (out[at(x, y)][0], steep[at(x, y)][0] as f64);
    assert!((got - was).abs() < 0.02 * was, "steep: {got} for {was}");

    // The modulation is divided out and multiplied back: with the ramp as its
    // albedo, a flat light times the ramp comes back unchanged.
    let albedo: Vec<[f32; 3]> = ramp.iter().map(|c| c.map(|v| v / 3.0)).collect();
    let out = cpu::planefit(&albedo, &up, Some(&albedo), w, h, fit);
    for (o, a) in out.iter().zip(&albedo) {
        assert!((o[0] - a[0] as f64).abs() < 1e-6, "{} for {}", o[0], a[0]);
    }
}

/// An image wider than the device's textures is refused by name before any
/// work, where the pipeline samples its images; a window without a pre-pass
/// (storage buffers) still filters it.
#[test]
fn an_image_wider_than_a_texture_is_refused_naming_it() {
    use filterjit::gpu::GpuError;
    let gpu = gpu();
    let mut scene = synthetic_scene(gpu.max_image_side() as usize + 1, 1, 5);
    scene.name = "panorama".into();
    let err = SceneBuffers::for_pipeline(&gpu, &scene, &pipeline("atrous=2")).err().expect("refused");
    assert!(matches!(err, GpuError::ImageTooLarge { .. }), "{err}");
    let message = err.to_string();
    assert!(message.contains("panorama") && message.contains(&format!("{}x1", scene.width)), "{message}");
    let window = gpu_filter(&gpu, &parse_expr("exp(-distance2(color))").unwrap(), &scene, &FilterPipeline::WINDOW, 1);
    assert_eq!(window.len(), scene.width);
}

#[test]
fn a_search_refuses_the_pixel_filter_by_name() {
    let gpu = gpu();
    let scene = scene_with_albedo(16, 16, 2);
    let error = FitnessScene::for_pipeline(&gpu, &scene, &pipeline("atrous=2,pixelfilter=0.4"))
        .err()
        .expect("a search's pipeline has no pixel filter")
        .to_string();
    assert!(error.contains("pixelfilter") && error.contains("one point"), "{error}");
}

#[test]
fn a_search_refuses_the_light_anchor_by_name() {
    let gpu = gpu();
    let scene = scene_with_albedo(16, 16, 2);
    let error = FitnessScene::for_pipeline(&gpu, &scene, &pipeline("atrous=2,anchor=2"))
        .err()
        .expect("a search's pipeline has no anchor")
        .to_string();
    assert!(error.contains("`anchor` is not scored") && error.contains("atrous=2,anchor=2"), "{error}");
}
