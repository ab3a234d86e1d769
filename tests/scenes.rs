//! Scene import: the Mitsuba sample, pbrt-style files, absent features, damaged files.

use std::path::{Path, PathBuf};

use filterjit::lang::{Feature, ScalarVar};
use filterjit::metrics;
use filterjit::scene::{self, Absent, Request, SceneError};

use crate::common::mitsuba_sample;

fn request(features: &[Feature], variances: &[ScalarVar]) -> Request {
    Request {
        features: features.iter().copied().collect(),
        variances: variances.iter().copied().collect(),
        reference: true,
        ..Default::default()
    }
}

fn temp_dir(name: &str) -> PathBuf {
    crate::common::temp_dir("test", name)
}

#[test]
fn mitsuba_sample_loads_with_the_noisy_error_its_readme_states() {
    let scene = scene::load(&mitsuba_sample(), &request(&[], &[])).unwrap();
    assert_eq!((scene.width, scene.height, scene.spp), (64, 64, Some(4)));
    assert!(scene.features.is_empty() && scene.variances.is_empty(), "nothing but colour was asked for");
    let e = metrics::errors(&scene.color, scene.reference.as_ref().unwrap(), scene.spp);
    // The sample's README gives the mean over pixels *and channels*; equation 3.5 sums over channels.
    let readme_mean_over_channels = 0.06842629574634661;
    assert!((e.relmse / 3.0 - readme_mean_over_channels).abs() < 1e-6, "relMSE {}", e.relmse);
    assert_eq!(e.relmse_half_spp, Some(e.relmse * 2.0));
}

/// Mitsuba's `moment` integrator: colour, nested AOVs, and a colour variance
/// from first and second moments that predicts where the noisy image is wrong.
#[test]
fn mitsuba_moment_output_gives_a_colour_variance() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scenes/mitsuba-moment-cornell-64");
    let (features, variances) = scene::provides(&dir, None).unwrap();
    for f in [Feature::Normal, Feature::Texture, Feature::WorldPosition, Feature::Depth] {
        assert!(features.contains(&f), "{f} from the nested AOVs");
    }
    assert!(variances.contains(&ScalarVar::ColorVariance));
    let wanted = [Feature::Normal, Feature::Texture];
    let scene = scene::load(&dir, &Request { albedo: true, ..request(&wanted, &[ScalarVar::ColorVariance]) }).unwrap();
    assert_eq!(scene.layout, Some("Mitsuba 3 (moment + aov + path)"));
    let reference = scene.reference.as_ref().unwrap();
    // The README's relMSE of the noisy colour (mean over pixels and channels).
    let e = metrics::errors(&scene.color, reference, scene.spp);
    assert!((e.relmse / 3.0 - 0.0684).abs() < 5e-4, "relMSE {}", e.relmse / 3.0);
    let variance = &scene.variances[&ScalarVar::ColorVariance];
    assert!(variance.iter().all(|v| v.is_finite() && (0.0..=1.0).contains(v)));
    // Pixels the variance calls noisy are the ones far from the reference.
    let squared: Vec<f64> = scene
        .color
        .iter()
        .zip(reference)
        .map(|(c, g)| (0..3).map(|k| (c[k] as f64 - g[k] as f64).powi(2)).sum::<f64>())
        .collect();
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let var: Vec<f64> = variance.iter().map(|v| *v as f64).collect();
    let (mv, ms) = (mean(&var), mean(&squared));
    let cov = var.iter().zip(&squared).map(|(a, b)| (a - mv) * (b - ms)).sum::<f64>();
    let norm = (var.iter().map(|a| (a - mv).powi(2)).sum::<f64>()
        * squared.iter().map(|b| (b - ms).powi(2)).sum::<f64>())
    .sqrt();
    assert!(cov / norm > 0.3, "correlation of variance and squared error {}", cov / norm);
    assert!(scene.albedo.is_some(), "the raw albedo from nested.albedo");
}

#[test]
fn mitsuba_features_are_loaded_normalised_and_only_when_asked() {
    let wanted = [Feature::Normal, Feature::Texture, Feature::WpGradient];
    let scene = scene::load(&mitsuba_sample(), &request(&wanted, &[ScalarVar::ColorVariance])).unwrap();
    let keys: Vec<Feature> = scene.features.keys().copied().collect();
    assert_eq!(keys, vec![Feature::Normal, Feature::Texture, Feature::WpGradient], "world position itself is not kept");
    for (f, values) in &scene.features {
        for v in values {
            let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            assert!(len <= 1.0 + 1e-5, "{f} has a vector of length {len}");
        }
    }
    let variance = scene.variance(ScalarVar::ColorVariance).unwrap();
    assert!(variance.iter().all(|v| (0.0..=1.0).contains(v)));
    assert!(variance.iter().any(|v| *v > 0.5), "normalised to about [0, 1]");
}

#[test]
fn a_missing_feature_is_refused_naming_the_feature_and_the_scene() {
    let err = scene::load(&mitsuba_sample(), &request(&[Feature::DirectIllumination], &[])).unwrap_err();
    let text = err.to_string();
    assert!(matches!(err, SceneError::MissingFeature { .. }), "{text}");
    assert!(text.contains("directIllumination") && text.contains("mitsuba-cornell-64"), "{text}");
    let err = scene::load(&mitsuba_sample(), &request(&[Feature::DiGradient], &[])).unwrap_err();
    assert!(err.to_string().contains("diGradient"), "{err}");
    let err = scene::load(&mitsuba_sample(), &request(&[], &[ScalarVar::NVariance])).unwrap_err();
    assert!(err.to_string().contains("nVariance"), "{err}");

    let zero = Request { absent: Absent::Zero, ..request(&[Feature::DirectIllumination], &[]) };
    let scene = scene::load(&mitsuba_sample(), &zero).unwrap();
    assert!(scene.features[&Feature::DirectIllumination].iter().all(|v| *v == [0.0; 3]));
    assert!(scene.notes.iter().any(|n| n.text.contains("directIllumination") && n.text.contains("absent")));
}

fn write_exr(path: &Path, width: usize, height: usize, channels: &[(&str, Vec<f32>)]) {
    use exr::prelude::*;
    let list: SmallVec<[AnyChannel<FlatSamples>; 4]> =
        channels.iter().map(|(name, data)| AnyChannel::new(*name, FlatSamples::F32(data.clone()))).collect();
    let layer =
        Layer::new((width, height), LayerAttributes::named("main"), Encoding::FAST_LOSSLESS, AnyChannels::sort(list));
    Image::from_layer(layer).write().to_file(path).unwrap();
}

#[test]
fn pbrt_gbuffer_files_load_with_old_and_new_channel_names() {
    let gpu = crate::common::gpu();
    let dir = temp_dir("pbrt");
    let (w, h) = (6, 5);
    let n = w * h;
    let ramp = |k: f32| (0..n).map(|p| p as f32 * k).collect::<Vec<f32>>();
    let mut channels = vec![("R", ramp(0.01)), ("G", ramp(0.02)), ("B", ramp(0.03))];
    for c in [
        "Albedo.R",
        "Albedo.G",
        "Albedo.B",
        "Px",
        "Py",
        "Pz",
        "Nsx",
        "Nsy",
        "Nsz",
        "Variance.R",
        "Variance.G",
        "Variance.B",
    ] {
        channels.push((c, ramp(0.1)));
    }
    write_exr(&dir.join("noisy.exr"), w, h, &channels);
    write_exr(&dir.join("reference.exr"), w, h, &[("R", ramp(0.01)), ("G", ramp(0.02)), ("B", ramp(0.03))]);
    let scene = scene::load(
        &dir,
        &request(&[Feature::Texture, Feature::WorldPosition, Feature::Normal], &[ScalarVar::ColorVariance]),
    )
    .unwrap();
    assert_eq!(scene.layout, Some("pbrt-v4 GBufferFilm / filterjit"));
    assert_eq!(scene.features.len(), 3);
    assert_eq!(metrics::errors(&scene.color, scene.reference.as_ref().unwrap(), None).mse, 0.0);
    let err = scene::load(&dir, &request(&[Feature::Depth], &[])).unwrap_err();
    assert!(err.to_string().contains("`depth`"), "{err}");
    // And it filters.
    let expr =
        filterjit::parse_expr("exp(-(distance2(normal) + distance2(texture) + distance2(worldPosition)))").unwrap();
    let kernel = filterjit::jit::compile(&expr, filterjit::jit::KernelSpec::default()).unwrap();
    let mut buffers = filterjit::gpu::SceneBuffers::new(&gpu, &scene);
    let out = gpu.filter(&kernel, &mut buffers, &scene, 2).unwrap();
    assert!(out.rgb().iter().flatten().all(|v| v.is_finite()));
}

#[test]
fn damaged_and_mismatched_files_give_clear_errors() {
    let dir = temp_dir("damaged");
    let noisy = std::fs::read(mitsuba_sample().join("noisy.exr")).unwrap();
    // Truncated noisy image.
    std::fs::write(dir.join("noisy.exr"), &noisy[..noisy.len() / 3]).unwrap();
    let err = scene::load(&dir, &request(&[Feature::Normal], &[])).unwrap_err();
    assert!(err.to_string().contains("noisy.exr"), "{err}");
    // Garbage.
    std::fs::write(dir.join("noisy.exr"), b"not an exr at all").unwrap();
    let err = scene::load(&dir, &request(&[], &[])).unwrap_err();
    assert!(matches!(err, SceneError::Exr { .. }), "{err}");
    // Reference of another size.
    std::fs::write(dir.join("noisy.exr"), &noisy).unwrap();
    write_exr(
        &dir.join("reference.exr"),
        32,
        32,
        &[("R", vec![0.0; 1024]), ("G", vec![0.0; 1024]), ("B", vec![0.0; 1024])],
    );
    let err = scene::load(&dir, &request(&[], &[])).unwrap_err();
    assert!(matches!(err, SceneError::SizeMismatch { .. }) && err.to_string().contains("32x32"), "{err}");
    // Reference without colour channels.
    write_exr(&dir.join("reference.exr"), 64, 64, &[("Y", vec![0.0; 4096])]);
    let err = scene::load(&dir, &request(&[], &[])).unwrap_err();
    assert!(err.to_string().contains("reference.exr") && err.to_string().contains("R, G, B"), "{err}");
    // Nothing there.
    let err = scene::load(&dir.join("nope"), &request(&[], &[])).unwrap_err();
    assert!(err.to_string().contains("nope"), "{err}");
}

#[test]
fn non_finite_inputs_are_sanitised_and_reported() {
    let dir = temp_dir("nonfinite");
    let (w, h) = (4, 4);
    let mut r = vec![0.5f32; 16];
    r[3] = f32::NAN;
    r[7] = f32::INFINITY;
    r[5] = -0.25;
    r[9] = 3e9;
    let mut n = vec![0.0f32; 16];
    n[1] = f32::NEG_INFINITY;
    let mut a = vec![0.5f32; 16];
    a[2] = f32::NAN;
    write_exr(
        &dir.join("noisy.exr"),
        w,
        h,
        &[
            ("R", r),
            ("G", vec![0.5; 16]),
            ("B", vec![0.5; 16]),
            ("N.X", n),
            ("N.Y", vec![0.0; 16]),
            ("N.Z", vec![1.0; 16]),
            ("Albedo.R", a),
            ("Albedo.G", vec![0.5; 16]),
            ("Albedo.B", vec![0.5; 16]),
        ],
    );
    let scene =
        scene::load(&dir, &Request { albedo: true, ..request(&[Feature::Normal, Feature::Texture], &[]) }).unwrap();
    assert!(scene.color.iter().flatten().all(|v| v.is_finite()));
    assert!(scene.features[&Feature::Normal].iter().flatten().all(|v| v.is_finite()));
    assert!(scene.notes.iter().any(|n| n.text.contains("noisy colour: 2 non-finite")), "{:?}", scene.notes);
    // Said before filtering, with what is only told where asked (a feature's scale) kept apart.
    for said in ["noisy colour: 1 values beyond ±1e7", "noisy colour: 1 negative values", "normal: 1 non-finite"] {
        assert!(scene.notes.iter().any(|n| n.text.contains(said) && n.warns), "{said}: {:?}", scene.notes);
    }
    assert!(scene.notes.iter().any(|n| n.text.contains("divided by") && !n.warns), "{:?}", scene.notes);
    // The albedo demodulates and is the `texture` feature: its bad value is said once.
    let albedo: Vec<_> = scene.notes.iter().filter(|n| n.text.contains("1 non-finite")).map(|n| &n.text).collect();
    assert_eq!(albedo, ["texture: 1 non-finite values replaced by 0", "normal: 1 non-finite values replaced by 0"]);
}

/// The same image written twice gives the same bytes: exr compresses blocks
/// in parallel, and filterjit writes them in order, not as they finish.
#[test]
fn an_exr_written_twice_has_the_same_bytes() {
    let dir = temp_dir("same-bytes");
    let (width, height) = (1024, 512);
    // Noise, so every block's compression takes its own time.
    let mut state = 12345u32;
    let rgb: Vec<[f32; 3]> = (0..width * height)
        .map(|_| {
            let mut next = || {
                state = state.wrapping_mul(1664525).wrapping_add(1013904223);
                (state >> 8) as f32 / (1 << 24) as f32
            };
            [next(), next(), next()]
        })
        .collect();
    let first = dir.join("first.exr");
    scene::exr_io::write_rgb(&first, width, height, &rgb).unwrap();
    let bytes = std::fs::read(&first).unwrap();
    for k in 0..6 {
        let again = dir.join(format!("again{k}.exr"));
        scene::exr_io::write_rgb(&again, width, height, &rgb).unwrap();
        assert!(std::fs::read(&again).unwrap() == bytes, "write {k} differs from the first");
    }
}

/// A normal is read as its direction: a render whose normals are averaged
/// over a pixel's samples (shorter at a seam) loads as one whose normals are
/// unit length, and a normal of zero (nothing hit) stays zero
/// (docs/SEMANTICS.md, `semantics::unit_direction`).
#[test]
fn normals_load_as_their_direction_whatever_their_length() {
    let (w, h) = (8, 8);
    let directions: Vec<[f32; 3]> = (0..w * h)
        .map(|k| match k % 7 {
            0 => [0.0; 3],
            _ => {
                let (a, b) = (k as f32 * 0.37, k as f32 * 0.11);
                [a.cos() * b.sin(), a.sin() * b.sin(), b.cos()]
            }
        })
        .collect();
    let load = |length: &dyn Fn(usize) -> f32, name: &str| {
        let dir = temp_dir(name);
        let axis = |c: usize| directions.iter().enumerate().map(|(k, v)| v[c] * length(k)).collect::<Vec<f32>>();
        let colour = vec![0.5f32; w * h];
        let channels = [
            ("R", colour.clone()),
            ("G", colour.clone()),
            ("B", colour),
            ("N.X", axis(0)),
            ("N.Y", axis(1)),
            ("N.Z", axis(2)),
        ];
        write_exr(&dir.join("noisy.exr"), w, h, &channels);
        scene::load(&dir, &request(&[Feature::Normal], &[])).unwrap()
    };
    let unit = load(&|_| 1.0, "normals-unit");
    // Averaged normals: between 0.3 and 0.95 of unit length, pixel by pixel.
    let short = load(&|k| 0.3 + 0.65 * ((k * 13) % 10) as f32 / 10.0, "normals-short");
    for (k, v) in unit.features[&Feature::Normal].iter().enumerate() {
        let length = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        let expected = if directions[k] == [0.0; 3] { 0.0 } else { 1.0 };
        assert!((length - expected).abs() < 1e-5, "pixel {k}: a normal of length {length}");
    }
    let bits =
        |s: &scene::Scene| s.features[&Feature::Normal].iter().flatten().map(|c| c.to_bits()).collect::<Vec<_>>();
    let (unit_bits, short_bits) = (bits(&unit), bits(&short));
    let differing = unit_bits.iter().zip(&short_bits).filter(|(a, b)| a != b).count();
    // Each direction is rounded on its own (a unit vector is left as it is, a short one divided):
    // they may differ in the last bits, never more.
    let worst = unit.features[&Feature::Normal]
        .iter()
        .flatten()
        .zip(short.features[&Feature::Normal].iter().flatten())
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    assert!(worst <= 2.0 * f32::EPSILON, "short normals load {worst} from unit ones ({differing} values differ)");
    assert!(short.notes.iter().any(|n| n.text.contains("made unit length")), "{:?}", short.notes);
    assert!(!unit.notes.iter().any(|n| n.text.contains("made unit length")), "{:?}", unit.notes);
}
