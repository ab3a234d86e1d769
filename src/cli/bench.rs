//! `filterjit bench`: the JIT corpus and generation timings, or whole frames
//! at given sizes (`--frames`), against the peer.

use super::*;

/// OIDN, the peer every table compares with, unless `--no-oidn` leaves it
/// out; where it is missing the table's OIDN columns stay empty, and this
/// says why (left out, or where it was looked for).
fn peer(env: &Environment, no_oidn: bool) -> Option<filterjit::oidn::Oidn> {
    if no_oidn {
        eprintln!("          OIDN left out (--no-oidn): no OIDN row or ratio");
        return None;
    }
    match filterjit::oidn::Oidn::find(env.oidn.as_deref(), env.path.as_deref()) {
        Ok(oidn) => Some(oidn),
        Err(why) => {
            eprintln!("          OIDN not measured: {why}");
            None
        }
    }
}

pub(crate) fn bench(
    env: &Environment,
    size: (u32, u32),
    settings: &filterjit::bench::BenchSettings,
    no_oidn: bool,
    output: &Path,
) -> Result<()> {
    let gpu = gpu::Gpu::open(&env.adapter)?;
    let peer = peer(env, no_oidn);
    let request = scene::Request {
        features: lang::Feature::ALL.iter().copied().collect(),
        variances: lang::ScalarVar::ALL.iter().copied().collect(),
        reference: true,
        albedo: true,
        ..Default::default()
    };
    eprintln!("bench     on {}", gpu.describe());
    let renders = bench_renders(env, &gpu, size, SEQUENCE_RENDERS, &request)?;
    let mut generation_scene =
        |s: u32| Ok(bench_renders(env, &gpu, (s, s), 1, &request)?.pop().expect("one render asked for"));
    let mut progress = |what: &str| eprintln!("          {what}");
    let report = filterjit::bench::run(&gpu, &renders, &mut generation_scene, settings, peer.as_ref(), &mut progress)?;
    print!("{}", filterjit::bench::table(&report));
    filterjit::io::write_bytes_atomically(output, serde_json::to_string_pretty(&report)?.as_bytes())?;
    println!("wrote     {}", output.display());
    Ok(())
}

/// How many renders of the bench scene, each with its own seed, a temporal
/// filter's frames cycle through: a still camera's sequence, each frame its
/// own noise.
const SEQUENCE_RENDERS: u32 = 4;

/// The bench scene (glossy-floor, 4 spp, 64-spp references) at `size`,
/// rendered `count` times with seeds 0, 1, … (cached), loaded as `request` asks.
fn bench_renders(
    env: &Environment,
    gpu: &gpu::Gpu,
    (width, height): (u32, u32),
    count: u32,
    request: &scene::Request,
) -> Result<Vec<filterjit::Scene>> {
    let d = render::builtin("glossy-floor").expect("built in")?;
    (0..count)
        .map(|seed| {
            let rs = render::RenderSettings { width, height, spp: 4, reference_spp: 64, seed };
            let dir = render::cached(gpu, &env.cache, &d, &rs, &mut |_, _| {})?;
            Ok(scene::load(&dir, request)?)
        })
        .collect()
}

/// `bench --frames SIZES`: whole frames only, from a 256² render of
/// glossy-floor tiled to each size.
pub(crate) fn bench_frames(
    env: &Environment,
    sizes: &[(u32, u32)],
    repeats: usize,
    filters: &[String],
    no_oidn: bool,
    profile: bool,
    output: &Path,
) -> Result<()> {
    let methods = match filters {
        [] => filterjit::bench::frame_methods()?,
        given => given
            .iter()
            .enumerate()
            .map(|(k, arg)| filterjit::bench::FrameMethod::resolve(arg, &format!("filter{}", k + 1)))
            .collect::<Result<_>>()?,
    };
    let gpu = gpu::Gpu::open(&env.adapter)?;
    let peer = peer(env, no_oidn);
    eprintln!("bench     whole frames on {}", gpu.describe());
    let mut features: std::collections::BTreeSet<lang::Feature> =
        methods.iter().flat_map(|m| m.expr.features()).collect();
    features.extend(methods.iter().flat_map(|m| m.pipeline.features()));
    let variances = methods.iter().flat_map(|m| m.expr.stored_variables()).collect();
    let request = scene::Request { features, variances, reference: true, albedo: true, ..Default::default() };
    // Only a temporal filter's frames read more than one render.
    let count = if methods.iter().any(|m| m.pipeline.is_temporal()) { SEQUENCE_RENDERS } else { 1 };
    let renders = bench_renders(env, &gpu, (256, 256), count, &request)?;
    let sizes: Vec<(usize, usize)> = sizes.iter().map(|&(w, h)| (w as usize, h as usize)).collect();
    let mut progress = |what: &str| eprintln!("          {what}");
    let settings = filterjit::bench::FramesSettings { sizes: &sizes, repeats, profile, scratch: &env.scratch };
    let report = filterjit::bench::frames_at(&gpu, &renders, &methods, &settings, peer.as_ref(), &mut progress)?;
    print!("{}", filterjit::bench::frames_report(&report));
    filterjit::io::write_bytes_atomically(output, serde_json::to_string_pretty(&report)?.as_bytes())?;
    println!("wrote     {}", output.display());
    Ok(())
}

/// `bench`: whole frames where `--frames` gives sizes, else the JIT corpus and a generation.
pub(crate) fn bench_command(env: &Environment, args: BenchArgs) -> Result<()> {
    let BenchArgs {
        size,
        radius,
        repeats,
        population,
        lengths,
        generation_sizes,
        generation_radius,
        fuse,
        output,
        no_oidn,
        frames,
        filters,
        profile,
    } = args;
    if !frames.is_empty() {
        return bench_frames(env, &frames, repeats.max(1), &filters, no_oidn, profile, &output);
    }
    if profile {
        bail!("--profile times whole frames' kernels: give the sizes with --frames (e.g. --frames 1920x1080)");
    }
    if !filters.is_empty() {
        bail!("--filter names a filter whose whole frames are timed: give the sizes with --frames (e.g. --frames 1920x1080)");
    }
    let settings = filterjit::bench::BenchSettings {
        radius,
        repeats: repeats.max(1),
        population: population.max(4),
        lengths,
        generation_sizes: generation_sizes.into_iter().filter(|s| *s > 0).collect(),
        generation_radius,
        seed: 0,
        fusion: fuse,
        scratch: env.scratch.clone(),
    };
    bench(env, size, &settings, no_oidn, &output)
}
