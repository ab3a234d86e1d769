//! The `filterjit` command line: flags (`args`) resolved into the library's
//! configuration types and calls; results printed. Errors are rendered by
//! `main`, with their whole context chain.

mod args;
mod evolve;
mod export;
mod hints;

pub(crate) use hints::flag_for;
mod report;
mod sequence;

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};

use filterjit::denoise::{Choice, Provided};
use filterjit::environment::Environment;
use filterjit::metrics::{self, Errors};
use filterjit::scene::{self, Absent, Request};
use filterjit::{corpus, cpu, datasets, gpu, jit, lang, preview, render, semantics};

use args::*;
pub(crate) use args::{Cli, Command};
use evolve::evolve;
use report::{report, scene_context};

pub(crate) fn run(cli: Cli) -> Result<()> {
    let env = &Environment::read()?;
    match cli.command {
        Command::Compile { expr, output, pipeline } => {
            let resolved = corpus::resolve_with_pipeline(&expr)?;
            let shape = jit::Shape::of(&pipeline.or(resolved.pipeline).unwrap_or_default());
            let kernel = jit::compile_shaped(&resolved.expr, jit::KernelKind::Filter, jit::LowerOptions::ALL, shape)?;
            match output {
                Some(path) => filterjit::io::write_bytes_atomically(&path, kernel.wgsl().as_bytes())
                    .map_err(anyhow::Error::from)
                    .with_context(|| format!("writing {}", path.display()))?,
                None => print!("{}", kernel.wgsl()),
            }
            Ok(())
        }
        Command::Export { expr, target, format, output, pipeline, budget_ms, size } => {
            export::export(&expr, target, format, &output, pipeline, budget_ms, size)
        }
        Command::Check { expr, latex: true } => {
            println!("{}", lang::latex(&resolve_expr(&expr)?));
            Ok(())
        }
        Command::Simplify { expr } => {
            let expr = resolve_expr(&expr)?;
            let simplified = filterjit::simplify::simplify(&expr);
            println!("{simplified}");
            println!(
                "length: {} -> {} nodes; kernel cost {:.1} -> {:.1}",
                expr.len(),
                simplified.len(),
                filterjit::simplify::kernel_cost(&expr),
                filterjit::simplify::kernel_cost(&simplified)
            );
            Ok(())
        }
        Command::Check { expr, latex: false } => {
            let expr = resolve_expr(&expr)?;
            println!("{expr}");
            println!("length: {} nodes", expr.len());
            let names: Vec<&str> =
                expr.features().iter().map(|f| f.name()).chain(expr.variables().iter().map(|v| v.name())).collect();
            println!(
                "reads: {}",
                if names.is_empty() { "nothing but the colour".to_string() } else { names.join(", ") }
            );
            Ok(())
        }
        Command::Filter { expr, radius, scene, output, read, cpu_check, pipeline } => {
            filter(env, expr.as_deref(), radius, &scene, &output, read, cpu_check, pipeline)
        }
        Command::Render { scene, spp, reference_spp, size, seed, output } => {
            render(env, &scene, spp, reference_spp, size, seed, output.as_deref())
        }
        Command::Evolve(args) => evolve(env, *args),
        Command::Report(args) => report(env, *args),
        Command::Tune(args) => {
            let gpu = gpu::Gpu::open(&env.adapter)?;
            let context = scene_context(&args.scene)?;
            let start = args.expr.as_deref().map(corpus::resolve).transpose()?;
            let tuned = report::tune_on_training(
                &gpu,
                env,
                &args.scene,
                &context,
                start.as_ref().map(|(_, e)| e),
                args.fitness_light.and_then(|t| t.0),
            )?;
            let name = match &start {
                None => "crossBilateralTuned".to_string(),
                Some((Some(name), _)) => format!("{name}Tuned"),
                Some((None, _)) => "tuned".to_string(),
            };
            println!("{name} = {}", tuned.expr);
            if let Some(path) = &args.output {
                let mut entry = filterjit::named::Entry::new(name, tuned.expr.to_string());
                entry.notes.push(format!(
                    "tuned on {} at {}x{}, radius {}: training fitness {:.5} (the starting values' {:.5}; {})",
                    tuned.scenes.join(", "),
                    context.render.width,
                    context.render.height,
                    context.radius,
                    tuned.fitness,
                    tuned.hand_set_fitness,
                    tuned.rule,
                ));
                entry.pipeline = Some(context.pipeline);
                let file = filterjit::named::NamedFile { header: Vec::new(), entries: vec![entry] };
                filterjit::io::write_bytes_atomically(path, file.to_string().as_bytes())?;
            }
            Ok(())
        }
        Command::Bench {
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
        } => {
            if !frames.is_empty() {
                return bench_frames(env, &frames, repeats.max(1), no_oidn, &output);
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
        Command::Scenes { stats: false, scenes, .. } if scenes.is_empty() => {
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
        Command::Scenes { size, spp, scenes, .. } => scene_stats(env, size, spp, scenes),
        Command::List => {
            for s in filterjit::denoise::shipped()? {
                println!("@{}  pipeline {}", s.name, s.pipeline);
                println!("    reads     {}", s.reads.join(", "));
                if let Some(rank) = s.rank {
                    println!(
                        "    default   {rank}. choice of `filter` without --expr, where the render has what it reads"
                    );
                }
                if let Some(base) = s.sparse_light_variant_of {
                    println!(
                        "    default   in place of @{base}, where the render's median pixel is below {} of its mean luminance",
                        filterjit::denoise::SPARSE_MEDIAN_OVER_MEAN
                    );
                }
                if let Some(measured) = s.measured {
                    println!("    measured  {measured}");
                }
                match s.weight_of {
                    Some(other) => println!("    weight    @{other}'s"),
                    None => println!("    {}", s.text),
                }
            }
            Ok(())
        }
        Command::Adapters => {
            let backends = env.adapter.backends;
            let adapters = gpu::adapter::available(backends, true);
            if adapters.is_empty() {
                bail!(gpu::GpuError::NoAdapter { backends: format!("{backends:?}") });
            }
            for (k, a) in adapters.iter().enumerate() {
                let info = a.get_info();
                println!(
                    "{} {} ({:?}, {:?}) {}",
                    if k == 0 { "*" } else { " " },
                    info.name,
                    info.backend,
                    info.device_type,
                    info.driver_info
                );
            }
            println!("* = the best; filterjit uses it unless {} names another", filterjit::environment::ADAPTER);
            Ok(())
        }
    }
}

/// An expression from the command line: text, or @name of a shipped one.
pub(crate) fn resolve_expr(arg: &str) -> Result<lang::Expr> {
    Ok(corpus::resolve(arg)?.1)
}

#[allow(clippy::too_many_arguments)]
pub(crate) fn filter(
    env: &Environment,
    expr: Option<&str>,
    radius: Option<u32>,
    scene_path: &Path,
    output: &Path,
    read: ReadScene,
    cpu_check: bool,
    pipeline: Option<filterjit::pipeline::FilterPipeline>,
) -> Result<()> {
    if scene::is_sequence(scene_path) {
        if cpu_check {
            bail!("--cpu-check compares one render with the CPU reference; filter one frame of the sequence for it");
        }
        return sequence::filter_sequence(env, expr, radius, scene_path, output, read, pipeline);
    }
    let choice = match expr {
        Some(expr) => Choice::asked(expr, pipeline, radius)?,
        None => {
            let (features, variances) = scene::provides(scene_path, read.view_layer.as_deref())
                .with_context(|| format!("reading scene {}", scene_path.display()))?;
            Choice::asked_or_best(None, pipeline, radius, &Provided::new(features, variances))?
        }
    };
    refuse_radius(radius, &choice.pipeline)?;
    let ReadScene { reference, spp, absent, view_layer } = read;
    let request = Request { reference_path: reference, spp, absent, view_layer, ..choice.request() };
    let load_start = Instant::now();
    let scene = scene::load(scene_path, &request).with_context(|| format!("loading scene {}", scene_path.display()))?;
    let load_time = load_start.elapsed();
    // A chosen filter may give way to its variant for the render's light (one read by the same request).
    let choice = choice.for_light(&scene.color)?;
    if let Some(because) = &choice.chosen_because {
        eprintln!("filter    {} (pipeline {}): {because}", choice.describe(), choice.pipeline);
    }
    let (expr, pipeline, radius) = (&choice.expr, choice.pipeline, choice.radius);
    for note in &scene.notes {
        if note.contains("absent") || note.contains("non-finite") {
            eprintln!("note: {note}");
        }
    }

    let compile_start = Instant::now();
    let kernel = choice.compile()?;
    let lower_validate = compile_start.elapsed();
    let gpu = gpu::Gpu::open(&env.adapter)?;
    let prepass_start = Instant::now();
    let mut buffers = gpu::SceneBuffers::for_pipeline(&gpu, &scene, &pipeline)?;
    let prepass_time = prepass_start.elapsed();
    let first = gpu.filter(&kernel, &mut buffers, &scene, radius)?;
    // A second, warm run: software drivers compile the pipeline at its first dispatch.
    let warm = gpu.filter(&kernel, &mut buffers, &scene, radius)?;
    let rgb = warm.rgb();

    filterjit::scene::exr_io::write_rgb(output, scene.width, scene.height, &rgb)
        .with_context(|| format!("writing {}", output.display()))?;
    let png = output.with_extension("png");
    preview::write_png(&png, scene.width, scene.height, &rgb)
        .map_err(anyhow::Error::from)
        .with_context(|| format!("writing {}", png.display()))?;

    let megapixels = scene.pixels() as f64 / 1e6;
    println!(
        "scene     {} ({}x{}, {}, spp {})",
        scene.name,
        scene.width,
        scene.height,
        scene.layout.unwrap_or("?"),
        scene.spp.map_or("unknown".into(), |s| s.to_string())
    );
    println!("device    {}", gpu.describe());
    println!(
        "kernel    {} nodes, reads color{}",
        expr.len(),
        kernel.source().layout.inputs.iter().map(|i| format!(", {}", i.describe())).collect::<String>()
    );
    let form = match pipeline.form {
        filterjit::pipeline::Form::Window => format!("radius {radius}"),
        filterjit::pipeline::Form::Atrous { passes, stencil } => {
            let side = 2 * stencil.half_width() + 1;
            format!("{passes} a-trous passes of {side}x{side}")
        }
    };
    let form = match pipeline.planefit {
        Some(fit) => format!("{form}, a plane fitted over {0}x{0}", 2 * fit.radius + 1),
        None => form,
    };
    println!("pipeline  {pipeline}");
    println!(
        "time      load {:.1} ms | lower+validate {:.2} ms | pre-pass {:.1} ms (first, compile included) | pipeline {:.1} ms | first dispatch {:.1} ms | filter {:.1} ms ({:.1} ms/Mpx, {form}, {} dispatch{})",
        ms(load_time),
        ms(lower_validate),
        ms(prepass_time),
        ms(first.pipeline.create),
        ms(first.time.wall),
        ms(warm.time.wall),
        ms(warm.time.wall) / megapixels,
        warm.dispatches,
        if warm.dispatches == 1 { "" } else { "es" }
    );
    if warm.flagged_pixels() > 0 {
        println!(
            "domain    {} of {} pixels had domain errors: {}",
            warm.flagged_pixels(),
            scene.pixels(),
            semantics::flag::describe(warm.all_flags()).join("; ")
        );
    }
    match &scene.reference {
        Some(reference) => {
            let noisy = metrics::errors(&scene.color, reference, scene.spp);
            let filtered = metrics::errors(&rgb, reference, scene.spp);
            let flip =
                |image: &[[f32; 3]]| filterjit::flip::hdr_flip(reference, image, scene.width, scene.height).mean();
            println!(
                "error     {:<10} {:>12} {:>14} {:>12} {:>8} {:>10}",
                "", "relMSE", "relMSE*m/2", "MSE", "light", "HDR-FLIP"
            );
            println!("          (light: the image's mean luminance over the reference's; 1 keeps the light)");
            print_errors("noisy", &noisy, flip(&scene.color));
            print_errors("filtered", &filtered, flip(&rgb));
        }
        None => println!("error     no reference image: errors not computed"),
    }
    if cpu_check {
        let reference = cpu::filter_pipeline(expr, &scene, &pipeline, radius)?;
        let worst = rgb
            .iter()
            .zip(&reference.color)
            .flat_map(|(g, c)| (0..3).map(move |q| (g[q] as f64 - c[q]).abs() / (c[q].abs() + 1e-3)))
            .fold(0.0f64, f64::max);
        println!("cpu       max relative difference GPU f32 vs CPU f64: {worst:.3e}");
    }
    println!("wrote     {} and {}", output.display(), png.display());
    Ok(())
}

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
    let bar = sample_bar(&d.name);
    let mut progress = |done: u64, total: u64| {
        bar.set_length(total);
        bar.set_position(done);
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
fn scene_stats(env: &Environment, size: u32, spp: u32, scenes: Vec<String>) -> Result<()> {
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
    no_oidn: bool,
    output: &Path,
) -> Result<()> {
    let gpu = gpu::Gpu::open(&env.adapter)?;
    let peer = if no_oidn { None } else { filterjit::oidn::Oidn::find(env.oidn.as_deref(), env.path.as_deref()).ok() };
    eprintln!("bench     whole frames on {}", gpu.describe());
    let d = render::builtin("glossy-floor").expect("built in")?;
    let rs = render::RenderSettings { width: 256, height: 256, spp: 4, reference_spp: 64, seed: 0 };
    let dir = render::cached(&gpu, &env.cache, &d, &rs, &mut |_, _| {})?;
    let methods = filterjit::bench::frame_methods()?;
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

pub(crate) fn print_errors(label: &str, e: &Errors, flip: f64) {
    let m2 = e.relmse_half_spp.map_or("-".to_string(), |v| format!("{v:.6}"));
    let light = e.light.map_or("-".to_string(), |l| format!("{l:.4}"));
    println!("          {label:<10} {:>12.6} {:>14} {:>12.6} {light:>8} {flip:>10.6}", e.relmse, m2, e.mse);
    if let Some(l) = e.light.filter(|l| (l - 1.0).abs() > metrics::LIGHT_TOLERANCE) {
        println!(
            "light     {label}: mean luminance {:+.1} % from the reference's (more than {} %): it changes the light",
            (l - 1.0) * 100.0,
            metrics::LIGHT_TOLERANCE * 100.0
        );
    }
}

pub(crate) fn ms(d: std::time::Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

/// `--radius` sets a window's size; an à-trous form has its own stencil and
/// would ignore it: say so rather than run without it.
pub(crate) fn refuse_radius(radius: Option<u32>, pipeline: &filterjit::pipeline::FilterPipeline) -> Result<()> {
    if let (Some(r), true) = (radius, pipeline.is_atrous()) {
        bail!(
            "--radius {r} sets a window's size, and the pipeline `{pipeline}` filters with à-trous passes of a fixed \
             stencil: leave --radius out, or give a pipeline that ends in `window`"
        );
    }
    Ok(())
}
