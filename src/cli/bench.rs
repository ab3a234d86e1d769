//! `filterjit bench`: the JIT corpus and generation timings, or whole frames
//! at given sizes (`--frames`), against the peer.

use super::*;

pub(crate) fn bench(
    env: &Environment,
    size: (u32, u32),
    settings: &filterjit::bench::BenchSettings,
    no_oidn: bool,
    output: &Path,
) -> Result<()> {
    let gpu = gpu::Gpu::open(&env.adapter)?;
    let peer = if no_oidn { None } else { filterjit::oidn::Oidn::find(env.oidn.as_deref(), env.path.as_deref()).ok() };
    let scene_at = |gpu: &gpu::Gpu, w: u32, h: u32| -> Result<filterjit::Scene> {
        let d = render::builtin("glossy-floor").expect("built in")?;
        let rs = render::RenderSettings { width: w, height: h, spp: 4, reference_spp: 64, seed: 0 };
        let dir = render::cached(gpu, &env.cache, &d, &rs, &mut |_, _| {})?;
        let request = scene::Request {
            features: lang::Feature::ALL.iter().copied().collect(),
            variances: lang::ScalarVar::ALL.iter().copied().collect(),
            reference: true,
            albedo: true,
            ..Default::default()
        };
        Ok(scene::load(&dir, &request)?)
    };
    eprintln!("bench     on {}", gpu.describe());
    let scene = scene_at(&gpu, size.0, size.1)?;
    let mut generation_scene = |s: u32| scene_at(&gpu, s, s);
    let mut progress = |what: &str| eprintln!("          {what}");
    let report = filterjit::bench::run(&gpu, &scene, &mut generation_scene, settings, peer.as_ref(), &mut progress)?;
    print!("{}", filterjit::bench::table(&report));
    filterjit::io::write_bytes_atomically(output, serde_json::to_string_pretty(&report)?.as_bytes())?;
    println!("wrote     {}", output.display());
    Ok(())
}

/// `bench --frames SIZES`: whole frames only, from a 256² render of
/// glossy-floor tiled to each size.
pub(crate) fn bench_frames(
    env: &Environment,
    sizes: &[(u32, u32)],
    repeats: usize,
    filters: &[String],
    no_oidn: bool,
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
    let peer = if no_oidn { None } else { filterjit::oidn::Oidn::find(env.oidn.as_deref(), env.path.as_deref()).ok() };
    eprintln!("bench     whole frames on {}", gpu.describe());
    let d = render::builtin("glossy-floor").expect("built in")?;
    let rs = render::RenderSettings { width: 256, height: 256, spp: 4, reference_spp: 64, seed: 0 };
    let dir = render::cached(&gpu, &env.cache, &d, &rs, &mut |_, _| {})?;
    let mut features: std::collections::BTreeSet<lang::Feature> =
        methods.iter().flat_map(|m| m.expr.features()).collect();
    features.extend(methods.iter().flat_map(|m| m.pipeline.features()));
    let variances = methods.iter().flat_map(|m| m.expr.stored_variables()).collect();
    let request = scene::Request { features, variances, reference: true, albedo: true, ..Default::default() };
    let scene = scene::load(&dir, &request)?;
    let sizes: Vec<(usize, usize)> = sizes.iter().map(|&(w, h)| (w as usize, h as usize)).collect();
    let mut progress = |what: &str| eprintln!("          {what}");
    let settings = filterjit::bench::FramesSettings { sizes: &sizes, repeats, scratch: &env.scratch };
    let report = filterjit::bench::frames_at(&gpu, &scene, &methods, &settings, peer.as_ref(), &mut progress)?;
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
    } = args;
    if !frames.is_empty() {
        return bench_frames(env, &frames, repeats.max(1), &filters, no_oidn, &output);
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
