//! `filterjit render` and `filterjit scenes`: the built-in tracer's scenes
//! rendered, listed, and measured for how heavy-tailed their light is.

use super::*;

/// A progress bar counting pixel samples, with samples per second.
pub(crate) fn sample_bar(label: &str) -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::new(0);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{prefix:>14} {bar:30} {percent:>3}% {per_sec:>14} eta {eta}")
            .expect("valid template"),
    );
    bar.set_prefix(label.to_string());
    bar
}

pub(crate) fn render(
    env: &Environment,
    scene: &str,
    spp: u32,
    reference_spp: u32,
    size: (u32, u32),
    seed: u32,
    output: Option<&Path>,
) -> Result<()> {
    let d = render::describe(scene)?;
    let settings = render::RenderSettings { width: size.0, height: size.1, spp, reference_spp, seed };
    let gpu = gpu::Gpu::open(&env.adapter)?;
    // Refused before the tracer allocates its images (a typo's size would
    // abort on memory): no larger than the device filters.
    let side = gpu.max_image_side();
    if size.0 > side || size.1 > side {
        bail!(
            "--size {}x{}: larger than the {side} pixels a side {} can filter; render at most {side}x{side}",
            size.0,
            size.1,
            gpu.describe()
        );
    }
    let bar = sample_bar(&d.name);
    let start = Instant::now();
    let mut said = 0;
    let mut progress = |done: u64, total: u64| {
        bar.set_length(total);
        bar.set_position(done);
        // Where stderr is no terminal the bar draws nothing: a line at each
        // tenth, so a render of minutes is not silent in a log.
        let tenths = (done * 10).checked_div(total).unwrap_or(0);
        if bar.is_hidden() && tenths > said {
            said = tenths;
            eprintln!("render    {} {}% ({:.0} s)", d.name, tenths * 10, start.elapsed().as_secs_f64());
        }
    };
    let dir = match output {
        Some(dir) if d.animation.is_some() => {
            render::render_sequence(&gpu, &d, &settings, dir, &mut progress)?;
            dir.to_path_buf()
        }
        Some(dir) => {
            let rendered = render::render(&gpu, &d, &settings, &mut progress)?;
            rendered.write(dir, &d, &settings)?;
            dir.to_path_buf()
        }
        None => render::cached(&gpu, &env.cache, &d, &settings, &mut progress)?,
    };
    bar.finish_and_clear();
    if let Some(animation) = d.animation {
        println!(
            "scene     {} ({:?}, a sequence of {} frames) on {}",
            d.name,
            d.split,
            animation.frames,
            gpu.describe()
        );
        println!("wrote     {} (frame_0001 … frame_{:04}, each a dataset)", dir.display(), animation.frames);
        return Ok(());
    }
    let meta: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.join(scene::META_FILE))?)?;
    println!("scene     {} ({:?}) on {}", d.name, d.split, gpu.describe());
    println!(
        "render    {}x{}, {} spp noisy, {} spp reference: {:.2} s, {:.3} M samples/s",
        size.0,
        size.1,
        spp,
        reference_spp,
        meta["render_seconds"].as_f64().unwrap_or(0.0),
        meta["samples_per_second"].as_f64().unwrap_or(0.0) / 1e6
    );
    println!(
        "reference estimated residual relMSE {:.3e} (from its two half-buffers)",
        meta["reference_residual_relmse"].as_f64().unwrap_or(0.0)
    );
    println!("wrote     {}", dir.display());
    Ok(())
}

/// How heavy-tailed each scene's light is, noisy and reference (`scenes --stats`).
pub(crate) fn scene_stats(env: &Environment, size: u32, spp: u32, scenes: Vec<String>) -> Result<()> {
    let gpu = gpu::Gpu::open(&env.adapter)?;
    let names: Vec<String> =
        if scenes.is_empty() { render::BUILTIN.iter().map(|(n, _)| n.to_string()).collect() } else { scenes };
    let settings = render::RenderSettings { width: size, height: size, spp, ..Default::default() };
    let datasets = datasets::resolve(&gpu, &names, &settings, &env.cache, &mut report::render_progress())?;
    println!(
        "{:<28} {:>9} {:>5}   {:>14} {:>12}   {:>14} {:>12}",
        "scene", "size", "spp", "noisy median", "noisy top 1%", "ref median", "ref top 1%"
    );
    let share = |t: Option<metrics::Tails>| match t {
        Some(t) => (format!("{:.3}", t.median_over_mean), format!("{:.1} %", t.top_percent_share * 100.0)),
        None => ("black".into(), "-".into()),
    };
    for dir in datasets {
        let scene = scene::load(&dir, &scene::Request { reference: true, ..Default::default() })?;
        let (nm, nt) = share(metrics::tails(&scene.color));
        let (rm, rt) = share(scene.reference.as_deref().and_then(metrics::tails));
        println!(
            "{:<28} {:>9} {:>5}   {nm:>14} {nt:>12}   {rm:>14} {rt:>12}",
            scene.name,
            format!("{}x{}", scene.width, scene.height),
            scene.spp.map_or("?".into(), |s| s.to_string()),
        );
    }
    println!("(median: the median pixel's luminance over the mean; top 1%: the share of the light the brightest 1 % of pixels hold)");
    Ok(())
}

/// `scenes` without `--stats`: the built-in scenes and sequences.
pub(crate) fn list_scenes() -> Result<()> {
    for (name, _) in render::BUILTIN {
        let d = render::builtin(name).expect("listed")?;
        println!("{name:<16} {:<6} {}", format!("{:?}", d.split).to_lowercase(), d.summary);
    }
    println!("sequences (frames rendered with motion vectors; `filter` on one runs the temporal stage):");
    for (name, _) in render::BUILTIN_SEQUENCES {
        let d = render::builtin(name).expect("listed")?;
        let frames = d.animation.map_or(0, |a| a.frames);
        println!("{name:<16} {:<6} {frames} frames: {}", format!("{:?}", d.split).to_lowercase(), d.summary);
    }
    Ok(())
}
