//! `filterjit report` and `tune`: scene settings from flags or a run, the tuned baseline, the report.

use super::*;

/// Scene settings of `report`/`tune`: flags, else the run's checkpoint, else defaults.
pub(crate) struct SceneContext {
    pub(crate) render: render::RenderSettings,
    pub(crate) radius: u32,
    pub(crate) pipeline: filterjit::pipeline::FilterPipeline,
    pub(crate) training: Vec<String>,
    pub(crate) test: Vec<String>,
}

pub(crate) fn scene_context(args: &SceneArgs) -> Result<SceneContext> {
    let run = match &args.run {
        Some(dir) => Some(
            filterjit::evolve::read_checkpoint(dir)
                .with_context(|| format!("reading the run in {}", dir.display()))?
                .run,
        ),
        None => None,
    };
    let pipeline = args.render.pipeline.or(run.as_ref().map(|r| r.pipeline)).unwrap_or_default();
    // A temporal pipeline is tuned and reported on sequences, any other on stills.
    let builtin = |split| match pipeline.is_temporal() {
        true => render::builtin_sequences(split).into_iter().map(|d| d.name).collect::<Vec<_>>(),
        false => render::builtin_split(split).into_iter().map(|d| d.name).collect::<Vec<_>>(),
    };
    let base = run.as_ref().map(|r| r.render).unwrap_or(render::RenderSettings {
        width: 64,
        height: 64,
        spp: 4,
        reference_spp: 1024,
        seed: 0,
    });
    let size = args.render.size.unwrap_or((base.width, base.height));
    Ok(SceneContext {
        render: render::RenderSettings {
            width: size.0,
            height: size.1,
            spp: args.render.spp.unwrap_or(base.spp),
            reference_spp: args.render.reference_spp.unwrap_or(base.reference_spp),
            seed: base.seed,
        },
        radius: args.render.radius.or(run.as_ref().map(|r| r.radius)).unwrap_or(5),
        pipeline,
        training: if !args.training_scenes.is_empty() {
            args.training_scenes.clone()
        } else {
            run.as_ref().map(|r| r.training.clone()).unwrap_or_else(|| builtin(render::Split::Train))
        },
        test: run.as_ref().map(|r| r.test.clone()).unwrap_or_else(|| builtin(render::Split::Test)),
    })
}

pub(crate) fn render_progress() -> impl FnMut(u64, u64) {
    let bar = sample_bar("rendering");
    move |done: u64, total: u64| {
        bar.set_length(total);
        bar.set_position(done);
        if done == total {
            bar.finish_and_clear();
        }
    }
}

pub(crate) fn tune_baseline(
    gpu: &gpu::Gpu,
    env: &Environment,
    args: &SceneArgs,
    context: &SceneContext,
) -> Result<filterjit::tune::Tuned> {
    tune_on_training(gpu, env, args, context, None, None)
}

/// Tune the cross-bilateral's sigmas, or every literal of `start`, on the training scenes.
pub(crate) fn tune_on_training(
    gpu: &gpu::Gpu,
    env: &Environment,
    args: &SceneArgs,
    context: &SceneContext,
    start: Option<&lang::Expr>,
    light_tolerance: Option<f64>,
) -> Result<filterjit::tune::Tuned> {
    let datasets = datasets::resolve(gpu, &context.training, &context.render, &env.cache, &mut render_progress())?;
    let (features, variances) = datasets::common_terminals(&datasets)?;
    let scenes = datasets::load_all(&datasets, &features, &variances, &context.pipeline)?;
    let threads = std::thread::available_parallelism().map_or(2, |n| n.get());
    // A temporal pipeline's frames come with its pre-pass and stage already run (`datasets::accumulated`).
    let mut scoring = filterjit::fitness::Settings::for_pipeline(context.radius, context.pipeline.spatial(), threads);
    scoring.rule.light_tolerance = light_tolerance;
    let mut evaluator = filterjit::fitness::Scorer::new(gpu, scenes, &scoring)?;
    eprintln!(
        "tune      {} on {} ({}x{}, radius {}, pipeline {}; fitness: {})",
        match start {
            None => "cross-bilateral sigmas".to_string(),
            Some(e) => format!("the literals of `{e}`"),
        },
        context.training.join(", "),
        context.render.width,
        context.render.height,
        context.radius,
        context.pipeline,
        scoring.rule.describe()
    );
    let mut on_step = |sigmas: &filterjit::tune::Sigmas, fitness: f64| {
        eprintln!(
            "          {fitness:.5}  {}",
            sigmas.0.iter().map(|(k, v)| format!("{k} {v}")).collect::<Vec<_>>().join(", ")
        );
    };
    let tuned = match start {
        None => filterjit::tune::tune(&mut evaluator, args.sweeps, &mut on_step)?,
        Some(e) => filterjit::tune::tune_literals(&mut evaluator, e, args.sweeps, &mut on_step)?,
    };
    eprintln!(
        "tuned     training fitness {:.5} (the starting values' {:.5}), {} candidates",
        tuned.fitness, tuned.hand_set_fitness, tuned.evaluated
    );
    Ok(tuned)
}

pub(crate) fn report(env: &Environment, args: ReportArgs) -> Result<()> {
    use filterjit::report::{self, Method, Origin};
    if let Some(dir) = &args.sequence {
        return report_sequence(env, &args, dir);
    }
    let context = scene_context(&args.scene)?;
    let gpu = gpu::Gpu::open(&env.adapter)?;
    let mut methods = Vec::new();
    // Every filter runs through the pipeline it was stored with, else the run's (or --pipeline).
    let (baseline_name, baseline_expr, baseline_pipeline, tuned) = match &args.baseline {
        Some(b) => {
            let resolved = corpus::resolve_with_pipeline(b)?;
            let pipeline = resolved.pipeline.unwrap_or(context.pipeline);
            (resolved.name.unwrap_or_else(|| "baseline".into()), resolved.expr, pipeline, None)
        }
        None => {
            let tuned = tune_baseline(&gpu, env, &args.scene, &context)?;
            let expr = lang::parse_expr(&tuned.expr)?;
            ("crossBilateral (tuned)".to_string(), expr, context.pipeline, Some(tuned))
        }
    };
    methods.push(Method {
        name: baseline_name,
        origin: Origin::Baseline,
        expr: baseline_expr,
        pipeline: baseline_pipeline,
        radius: None,
        sparse_light_variant: None,
    });
    // The SVGF-style à-trous filter, tuned on training scenes, in its own pipeline.
    let svgf = corpus::resolve_with_pipeline("@svgfAtrous")?;
    methods.push(Method {
        name: "svgfAtrous".into(),
        origin: Origin::Baseline,
        expr: svgf.expr,
        pipeline: svgf.pipeline.unwrap_or(context.pipeline),
        radius: None,
        sparse_light_variant: None,
    });
    for name in ["thesis1", "thesis2", "thesis3"] {
        // The thesis's filters as published: one window.
        let expr = resolve_expr(&format!("@{name}"))?;
        methods.push(Method {
            name: name.into(),
            origin: Origin::Thesis,
            expr,
            pipeline: Default::default(),
            radius: None,
            sparse_light_variant: None,
        });
    }
    let given = |name: String, resolved: corpus::Resolved, sparse_light_variant| Method {
        name,
        origin: Origin::Given,
        expr: resolved.expr,
        pipeline: resolved.pipeline.unwrap_or(context.pipeline),
        radius: resolved.radius,
        sparse_light_variant,
    };
    for (k, arg) in args.exprs.iter().enumerate() {
        let resolved = corpus::resolve_with_pipeline(arg)?;
        // A role (`@realtime`) runs as `filter` runs it: its variant where a scene's light is sparse.
        let asked_variant = |n: &str| filterjit::denoise::asked_variant(n, &resolved.expr, false);
        let variant = match resolved.name.as_deref().and_then(asked_variant) {
            Some(rule) => {
                let variant = corpus::resolve_with_pipeline(&format!("@{}", rule.variant))?;
                Some((Box::new(given(rule.variant.to_string(), variant, None)), rule))
            }
            None => None,
        };
        let name = resolved.name.clone().unwrap_or_else(|| format!("expr{}", k + 1));
        methods.push(given(name, resolved, variant));
    }
    let hall_path = args
        .hall_of_fame
        .clone()
        .or_else(|| args.scene.run.as_ref().map(|d| d.join(filterjit::evolve::HALL_OF_FAME_FILE)));
    let mut hall = Vec::new();
    if let Some(path) = &hall_path {
        let content = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        let mut taken = 0;
        let file = filterjit::named::NamedFile::parse(&content).with_context(|| path.display().to_string())?;
        for entry in &file.entries {
            let name = &entry.name;
            let text = file.expression(name).expect("its own entry");
            let expr = lang::parse_expr(text).with_context(|| format!("{}: entry `{name}`", path.display()))?;
            // Reported as people read them: simplified (the same weights).
            let expr = filterjit::simplify::simplify(&expr);
            let pipeline = entry.pipeline.unwrap_or(context.pipeline);
            let radius = entry.radius;
            // A multi-objective run's front is drawn whole: it is the run's answer.
            let on_front = name.starts_with("front");
            let known = methods.iter().any(|m| m.expr == expr && m.pipeline == pipeline && m.radius == radius);
            if (on_front || taken < args.top) && !known {
                taken += usize::from(!on_front);
                methods.push(Method {
                    name: name.to_string(),
                    origin: Origin::Given,
                    expr: expr.clone(),
                    pipeline,
                    radius,
                    sparse_light_variant: None,
                });
            }
            hall.push(expr);
        }
    }
    // A method is its name in every table: one of each, the first given (a
    // named expression also passed by hand, a hall-of-fame entry also given as @FILE:NAME).
    let mut names = std::collections::BTreeSet::new();
    methods.retain(|m| {
        let first = names.insert(m.name.clone());
        if !first {
            eprintln!("note: `{}` is listed once (it was given twice)", m.name);
        }
        first
    });
    let scene_names = if args.scenes.is_empty() { context.test.clone() } else { args.scenes.clone() };
    let datasets = datasets::resolve(&gpu, &scene_names, &context.render, &env.cache, &mut render_progress())?;
    let settings = report::Settings {
        radius: context.radius,
        repeats: args.repeats,
        crop: args.crop,
        timing_size: args.timing_size,
    };
    let oidn = report_peer(env, args.no_oidn);
    let inputs = report::Inputs {
        scenes: &datasets,
        methods: &methods,
        settings,
        baseline: tuned,
        hall_of_fame: hall_path.as_ref().map(|_| hall.as_slice()),
        oidn: oidn.as_ref(),
    };
    let results = report::run(&gpu, inputs, &args.output, &mut |what| eprintln!("measure   {what}"))?;
    println!("{:<26} {:>14} {:>10} {:>10}", "method", "relMSE/noisy", "relMSE", "ms/Mpx");
    for m in &results.methods {
        let f = |v: Option<f64>, d: usize| v.map(|v| format!("{v:.d$}")).unwrap_or_else(|| "-".into());
        println!(
            "{:<26} {:>14} {:>10} {:>10}",
            m.name,
            f(m.mean_normalised, 4),
            f(m.mean_relmse, 4),
            f(m.mean_ms_per_mpx, 1)
        );
    }
    println!("wrote     {}", args.output.join("index.html").display());
    Ok(())
}

/// The shipped filters a sequence report runs when it is given none: the
/// temporal default, the real-time one and SVGF in its paper's pipeline.
const SEQUENCE_FILTERS: [&str; 3] = ["@temporal", "@realtimeTemporal", "@svgf"];

/// `report --sequence SEQ_DIR`: `report::sequence` on one folder of frames.
fn report_sequence(env: &Environment, args: &ReportArgs, dir: &std::path::Path) -> Result<()> {
    // What describes scenes to render, a run or a baseline has no meaning for a sequence's frames.
    let refused = [
        ("--scenes", !args.scenes.is_empty()),
        ("--run", args.scene.run.is_some()),
        ("--hall-of-fame", args.hall_of_fame.is_some()),
        ("--baseline", args.baseline.is_some()),
        ("--training-scenes", !args.scene.training_scenes.is_empty()),
        ("--size", args.scene.render.size.is_some()),
        ("--reference-spp", args.scene.render.reference_spp.is_some()),
    ];
    if let Some((flag, _)) = refused.iter().find(|(_, given)| *given) {
        bail!("{flag} describes scenes to render; with --sequence the frames are the sequence's own");
    }
    let sequence = filterjit::scene::Sequence::find(dir)?;
    // The report's files (`sequence.json`, `frames/`) would mix with the frames' own.
    if super::same_file(dir, &args.output) || sequence.folder().is_some_and(|f| super::same_file(f, &args.output)) {
        bail!(
            "-o {}: the sequence's frames are read from this folder, and the report's files would mix with them; \
             write the report into another folder",
            args.output.display()
        );
    }
    let asked: Vec<&str> = match args.exprs.is_empty() {
        true => SEQUENCE_FILTERS.to_vec(),
        false => args.exprs.iter().map(String::as_str).collect(),
    };
    let render = &args.scene.render;
    // Frames sampled at one point a pixel: every filter ends with the pixel filter, as `filter` runs them.
    let first = &sequence.frames.first().context("the sequence has no frames")?.path;
    let point_sampled =
        filterjit::scene::point_sampled(first, None).with_context(|| format!("reading frame {}", first.display()))?;
    let mut filters = Vec::new();
    for (k, arg) in asked.iter().enumerate() {
        let choice = filterjit::denoise::Choice::asked(arg, render.pipeline, render.radius)
            .with_context(|| format!("filter {arg}"))?
            .for_point_sampled(point_sampled, render.pipeline.is_some());
        let name = if arg.starts_with('@') { arg.to_string() } else { format!("expr{}", k + 1) };
        filters.push((name, choice));
    }
    if let Some((_, filterjit::denoise::Choice { chosen_because: Some(because), .. })) = filters.first() {
        eprintln!("filters   {because}");
    }
    let oidn = report_peer(env, args.no_oidn);
    let gpu = gpu::Gpu::open(&env.adapter)?;
    let read = filterjit::scene::Request { spp: render.spp, ..Default::default() };
    let inputs =
        filterjit::report::sequence::SequenceInputs { sequence: &sequence, filters, oidn: oidn.as_ref(), read };
    let report =
        filterjit::report::sequence::run(&gpu, inputs, &args.output, &mut |what| eprintln!("measure   {what}"))?;
    let f = |v: Option<f64>, d: usize| v.map(|v| format!("{v:.d$}")).unwrap_or_else(|| "-".into());
    let settled = match report.frames.len() >= report.settled_from {
        true => format!("settled: frames {}–{}", report.settled_from, report.frames.len()),
        false => format!("too short to settle (from frame {})", report.settled_from),
    };
    println!(
        "sequence  {} ({} frames, {}x{}); {settled}",
        report.sequence,
        report.frames.len(),
        report.width,
        report.height
    );
    println!(
        "{:<30} {:>10} {:>10} {:>10} {:>10} {:>9} {:>13} {:>9}",
        "method", "relMSE", "settled", "flicker", "settled", "HDR-FLIP", "light", "ms"
    );
    for e in &report.entrants {
        let s = &e.summary;
        println!(
            "{:<30} {:>10} {:>10} {:>10} {:>10} {:>9} {:>13} {:>9}",
            e.name,
            f(s.relmse, 5),
            f(s.relmse_settled, 5),
            f(s.flicker, 5),
            f(s.flicker_settled, 5),
            f(s.hdr_flip, 4),
            match (s.light_min, s.light_max) {
                (Some(lo), Some(hi)) => format!("{lo:.3}–{hi:.3}"),
                _ => "-".into(),
            },
            f(s.frame_ms, 1)
        );
    }
    println!("wrote     {}", args.output.join("index.html").display());
    Ok(())
}

/// The peer a report compares with: OIDN where its `oidnDenoise` is found and
/// not left out; where it is not found, the report goes on and says so.
fn report_peer(env: &Environment, left_out: bool) -> Option<filterjit::oidn::Oidn> {
    if left_out {
        return None;
    }
    match filterjit::oidn::Oidn::find(env.oidn.as_deref(), env.path.as_deref()) {
        Ok(oidn) => {
            eprintln!("peer      Intel Open Image Denoise: {}", oidn.program.display());
            Some(oidn)
        }
        Err(why) => {
            eprintln!("note: the report goes on without Intel Open Image Denoise: {why}");
            None
        }
    }
}
