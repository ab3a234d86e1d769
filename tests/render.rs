//! The built-in path tracer: agreement with Mitsuba, every scene, determinism, the cache.

use filterjit::lang::{Feature, ScalarVar};
use filterjit::render::{self, RenderSettings};
use filterjit::scene::{self, Request};
use filterjit::{metrics, Scene};

use crate::common::{gpu, mitsuba_sample};

fn tiny() -> RenderSettings {
    RenderSettings { width: 16, height: 12, spp: 2, reference_spp: 4, seed: 3 }
}

fn temp_dir(name: &str) -> std::path::PathBuf {
    crate::common::temp_dir("render", name)
}

/// Our Cornell box against Mitsuba 3's reference of the same scene (box filter, 64x64).
#[test]
fn the_cornell_box_agrees_with_mitsuba() {
    let gpu = gpu();
    let d = render::builtin("cornell").unwrap().unwrap();
    let settings = RenderSettings { width: 64, height: 64, spp: 4, reference_spp: 512, seed: 1 };
    let rendered = render::render(&gpu, &d, &settings, &mut |_, _| {}).unwrap();
    let ours = rendered.reference();
    let mitsuba = scene::load(&mitsuba_sample(), &Request { reference: true, ..Default::default() }).unwrap();
    let theirs = mitsuba.reference.as_ref().unwrap();
    let between = metrics::errors(&ours, theirs, None).relmse;
    let noisy_vs_mitsuba = metrics::errors(&mitsuba.color, theirs, None).relmse;
    let our_noisy_vs_ours = metrics::errors(&rendered.noisy(), &ours, None).relmse;
    // Both references carry noise of their own; the estimate says how much ours has.
    let residual = rendered.reference_residual_relmse();
    eprintln!(
        "relMSE ours vs Mitsuba {between:.5} (our residual {residual:.5}); noisy 4 spp vs Mitsuba {noisy_vs_mitsuba:.4}, ours {our_noisy_vs_ours:.4}"
    );
    assert!(between < 0.05 * noisy_vs_mitsuba, "the renderers disagree: {between} vs noisy {noisy_vs_mitsuba}");
    assert!(between < 0.05 * our_noisy_vs_ours);
    assert!(
        between < 4.0 * (residual + 3.0 * 2.8e-4),
        "more than noise separates the two: {between}, residual {residual}"
    );
}

#[test]
fn every_builtin_scene_renders_into_a_loadable_dataset() {
    let gpu = gpu();
    let all_features: Vec<Feature> = Feature::ALL.to_vec();
    let request = Request {
        features: all_features.iter().copied().collect(),
        variances: ScalarVar::ALL.iter().copied().collect(),
        reference: true,
        ..Default::default()
    };
    let mut splits = (0, 0);
    for (name, _) in render::BUILTIN {
        let d = render::builtin(name).unwrap().unwrap_or_else(|e| panic!("{name}: {e}"));
        match d.split {
            render::Split::Train => splits.0 += 1,
            render::Split::Test => splits.1 += 1,
        }
        let dir = temp_dir(name);
        let rendered = render::render(&gpu, &d, &tiny(), &mut |_, _| {}).unwrap();
        rendered.write(&dir, &d, &tiny()).unwrap();
        let scene: Scene = scene::load(&dir, &request).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(scene.spp, Some(2));
        assert!(scene.color.iter().flatten().all(|v| v.is_finite() && *v >= 0.0), "{name}");
        assert!(scene.color.iter().flatten().any(|v| *v > 0.0), "{name} is black");
        assert_eq!(
            scene.features.len(),
            all_features.len() - 3,
            "{name}: every feature but colour, pixel and guide is stored"
        );
        assert!(scene.notes.iter().all(|n| !n.text.contains("non-finite")), "{name}: {:?}", scene.notes);
    }
    assert!(splits.0 >= 12 && splits.1 >= 4, "train/test split {splits:?}");
}

#[test]
fn renders_are_deterministic_for_a_seed() {
    let gpu = gpu();
    let d = render::builtin("glossy-floor").unwrap().unwrap();
    let a = render::render(&gpu, &d, &tiny(), &mut |_, _| {}).unwrap();
    let b = render::render(&gpu, &d, &tiny(), &mut |_, _| {}).unwrap();
    let c = render::render(&gpu, &d, &RenderSettings { seed: 4, ..tiny() }, &mut |_, _| {}).unwrap();
    assert_eq!(a.noisy(), b.noisy());
    assert_eq!(a.reference(), b.reference());
    assert_ne!(a.noisy(), c.noisy());
}

/// At 1280x720 the whole image's sums (38 floats a pixel) would be 140 MB,
/// over the 128 MiB a storage binding may hold on Mesa: the tracer binds one
/// band of rows at a time, and every band lands in its own rows.
#[test]
fn a_720p_render_is_traced_in_bands_that_each_land_in_their_rows() {
    let gpu = gpu();
    let d = render::builtin("cornell").unwrap().unwrap();
    let settings = RenderSettings { width: 1280, height: 720, spp: 1, reference_spp: 2, seed: 1 };
    let rendered = render::render(&gpu, &d, &settings, &mut |_, _| {}).unwrap();
    let reference = rendered.reference();
    let rows_per_band = (render::MAX_PATHS_PER_DISPATCH / 1280) as usize / 8 * 8;
    assert!(rows_per_band < 720, "the test must span several bands");
    assert!(reference.iter().flatten().all(|v| v.is_finite()), "a pixel not finite");
    for (band, pixels) in reference.chunks(1280 * rows_per_band).enumerate() {
        let light = pixels.iter().map(|p| p[0] + p[1] + p[2]).sum::<f32>() / pixels.len() as f32;
        // Every band crosses the box's lit walls; one written elsewhere would be black.
        assert!(light > 0.05, "band {band} (from row {}) is dark: {light}", band * rows_per_band);
    }
}

#[test]
fn the_cache_renders_once_per_scene_text_and_settings() {
    let gpu = gpu();
    let root = temp_dir("cache");
    let d = render::builtin("soft-shadows").unwrap().unwrap();
    let settings = RenderSettings { seed: 11, ..tiny() };
    let mut calls = 0;
    let first = render::cached(&gpu, &root, &d, &settings, &mut |_, _| calls += 1).unwrap();
    assert!(calls > 0, "the first call renders");
    let mut again = 0;
    let second = render::cached(&gpu, &root, &d, &settings, &mut |_, _| again += 1).unwrap();
    assert_eq!((first.clone(), again), (second, 0), "the second call reads the cache");
    assert!(first.join("meta.json").is_file());
    let key = |d: &render::Description, s: &RenderSettings| render::cache_dir(&root, d, s);
    assert_ne!(key(&d, &settings), key(&d, &RenderSettings { spp: 3, ..settings }), "settings are part of the key");
    let mut edited = d.clone();
    edited.source.push_str("\n# edited\n");
    assert_ne!(key(&d, &settings), key(&edited, &settings), "the file's text is part of the key");
}

#[test]
fn bad_scene_files_give_file_and_line() {
    let err = render::describe("/nonexistent/scene.toml").unwrap_err().to_string();
    assert!(err.contains("/nonexistent/scene.toml") && err.contains("cornell"), "{err}");
    let dir = temp_dir("bad-toml");
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("bad.toml");
    std::fs::write(&file, "split = \"train\"\n[camera]\nposition = [0, 0]\n").unwrap();
    let err = render::describe(file.to_str().unwrap()).unwrap_err().to_string();
    assert!(err.contains("bad.toml") && err.contains("line 3"), "{err}");
}

/// The built-in training set holds the statistics of a room lit through a
/// small opening (docs/SCENES.md): at 4 spp the median pixel is black while
/// the reference is lit throughout, and the brightest 1 % of pixels hold far
/// more of the light than they do in the reference.
#[test]
fn a_built_in_training_scene_has_a_black_noisy_median_under_a_lit_reference() {
    use filterjit::metrics::tails;
    let gpu = gpu();
    let d = render::builtin("skylight-slot").unwrap().unwrap();
    assert_eq!(d.split, render::Split::Train);
    let settings = RenderSettings { width: 32, height: 32, spp: 4, reference_spp: 256, seed: 0 };
    let dir = temp_dir("skylight-slot");
    render::render(&gpu, &d, &settings, &mut |_, _| {}).unwrap().write(&dir, &d, &settings).unwrap();
    let scene = scene::load(&dir, &Request { reference: true, ..Default::default() }).unwrap();
    let (noisy, reference) = (tails(&scene.color).unwrap(), tails(scene.reference.as_ref().unwrap()).unwrap());
    assert!(noisy.median_over_mean < 0.05, "noisy {noisy:?}");
    assert!(reference.median_over_mean > 0.3, "reference {reference:?}");
    assert!(noisy.top_percent_share > 2.0 * reference.top_percent_share, "{noisy:?} against {reference:?}");
}

/// Every built-in sequence renders (at a tiny size) into a folder of frame
/// datasets that `scene::Sequence` reads in order, each with motion vectors;
/// and the vectors mean what Blender's do: on the dolly, whose motion is
/// both sideways and vertical, moving the frame before's reference by them
/// (y up) lines it up with the frame's, and moving it with y down does not.
#[test]
fn built_in_sequences_render_with_motion_vectors_in_blenders_convention() {
    let gpu = gpu();
    for (name, _) in render::BUILTIN_SEQUENCES {
        // The dolly's motion is a pixel a frame at 64²: large enough to tell the vectors' signs.
        let side = if *name == "seq-dolly-room" { 64 } else { 24 };
        let settings = RenderSettings { width: side, height: side, spp: 4, reference_spp: 8, seed: 5 };
        let d = render::builtin(name).unwrap().unwrap();
        let frames = d.animation.expect("a sequence").frames as usize;
        let dir = temp_dir(name);
        render::render_sequence(&gpu, &d, &settings, &dir, &mut |_, _| {}).unwrap();
        assert!(dir.join(render::SEQUENCE_META).is_file(), "{name}: marked complete");
        let sequence = scene::Sequence::find(&dir).unwrap();
        assert_eq!(sequence.frames.len(), frames, "{name}");
        let request = Request {
            motion: true,
            reference: true,
            albedo: true,
            features: [Feature::Normal, Feature::Depth].into(),
            ..Default::default()
        };
        assert_eq!(sequence.check(&request).unwrap(), (side as usize, side as usize), "{name}");
        let scenes: Vec<Scene> = (0..frames).map(|k| sequence.load(k, &request).unwrap()).collect();
        // Each frame its own noise.
        assert_ne!(scenes[0].color, scenes[1].color, "{name}");
        if *name == "seq-dolly-room" {
            // The albedo: the textures' edges, without the light's noise.
            for pair in scenes.windows(2) {
                let (r0, r1) = (pair[0].albedo.as_ref().unwrap(), pair[1].albedo.as_ref().unwrap());
                let moved = crate::temporal::moved_difference((r0, r1), &pair[1], [1.0, 1.0]);
                let still = crate::temporal::moved_difference((r0, r1), &pair[1], [0.0, 0.0]);
                let down = crate::temporal::moved_difference((r0, r1), &pair[1], [1.0, -1.0]);
                assert!(
                    moved < 0.8 * still && moved < 0.8 * down,
                    "{}: moved {moved}, still {still}, y down {down}",
                    pair[1].name
                );
            }
        }
        // A still camera and scene but for the moving shape: zero motion where nothing moved.
        if *name == "seq-moving-ball" {
            let motion = scenes[3].motion.as_ref().unwrap();
            let still = motion.vectors.iter().filter(|v| v[0].abs() < 1e-4 && v[1].abs() < 1e-4).count();
            assert!(still > motion.vectors.len() / 2, "{name}: most pixels see nothing move ({still})");
            assert!(motion.vectors.iter().any(|v| v[0] < -0.5), "{name}: the ball was to the left the frame before");
        }
    }
}

/// The scene files the sparse-light thresholds were chosen on parse, each a
/// still, and their comments say what they vary.
#[test]
fn the_sparse_light_scene_files_parse() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/sparse-light");
    let mut files: Vec<_> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().path()).collect();
    files.sort();
    assert_eq!(files.len(), 11, "{files:?}");
    for file in files {
        let scene = filterjit::render::Description::load(&file).unwrap_or_else(|e| panic!("{e}"));
        assert!(scene.animation.is_none(), "{}", file.display());
        let text = std::fs::read_to_string(&file).unwrap();
        assert!(text.starts_with("# `scenes/") && text.contains("SPARSE_MEDIAN_OVER_MEAN"), "{}", file.display());
    }
}
