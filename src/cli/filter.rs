//! `filterjit filter`: one render (or a sequence folder, `sequence`) filtered,
//! written, and scored where it has a reference.

use super::*;

/// How the command line asks `filter` to filter: the same for every render
/// of a folder.
#[derive(Clone)]
pub(crate) struct Asked<'a> {
    pub(crate) expr: Option<&'a str>,
    pub(crate) radius: Option<u32>,
    pub(crate) read: ReadScene,
    pub(crate) cpu_check: bool,
    pub(crate) pipeline: Option<filterjit::pipeline::FilterPipeline>,
}

pub(crate) fn filter(env: &Environment, asked: Asked, scene_path: &Path, output: &Path) -> Result<()> {
    if !scene_path.exists() {
        bail!("{}: no such file or folder", scene_path.display());
    }
    if scene::is_sequence(scene_path) {
        // Its errors name the folder.
        let renders = scene::Sequence::find(scene_path)?;
        // The filtered frames keep their names: written where they were read
        // (the one folder `Sequence::find` lists), they would replace them,
        // or sit beside the frames' own folders as a second copy of each frame.
        if renders.folder().is_some_and(|folder| same_file(folder, output)) {
            bail!(
                "-o {}: the renders are read from this folder, and the filtered ones, of the same names, would replace them or be read as frames again; write them into another folder",
                output.display()
            );
        }
        if !renders.is_numbered() {
            return filter_each(env, &asked, &renders, output);
        }
        if output.extension().is_some_and(|e| e.eq_ignore_ascii_case("exr") || e.eq_ignore_ascii_case("png")) {
            bail!("-o {}: a sequence's frames are written into a folder; name a folder", output.display());
        }
        let Asked { expr, radius, read, cpu_check, pipeline } = asked;
        if cpu_check {
            bail!("--cpu-check compares one render with the CPU reference; filter one frame of the sequence for it");
        }
        return sequence::filter_sequence(env, expr, radius, scene_path, output, read, pipeline);
    }
    filter_one(env, asked, scene_path, output).map(|_| ())
}

/// A folder of renders whose names carry no frame numbers (`tabletop/`,
/// `corridor/`, …): each filtered on its own, as `filter FILE` filters it,
/// into `output_dir/NAME.exr`.
fn filter_each(env: &Environment, asked: &Asked, renders: &scene::Sequence, output_dir: &Path) -> Result<()> {
    if let Some(reference) = &asked.read.reference {
        bail!(
            "--reference {}: the renders of folder {} are filtered one by one, each with the reference beside it",
            reference.display(),
            renders.name
        );
    }
    if output_dir.exists() && !output_dir.is_dir() {
        bail!("-o {}: a folder of renders is written into a folder, and this is a file", output_dir.display());
    }
    std::fs::create_dir_all(output_dir).with_context(|| format!("creating {}", output_dir.display()))?;
    match renders.frames.len() {
        1 => eprintln!("filter    1 render in {} (one render is not a sequence)", renders.name),
        n => eprintln!(
            "filter    {n} renders in {}, each on its own (their names end in no frame number, so they are not a sequence's frames)",
            renders.name
        ),
    }
    let mut done = Vec::new();
    for render in &renders.frames {
        eprintln!("\nrender    {}", render.path.display());
        // A dataset's folder finds its reference itself; a file's is the one the folder found.
        let reference = render.reference.clone().filter(|_| render.path.is_file());
        let asked = Asked { read: ReadScene { reference, ..asked.read.clone() }, ..asked.clone() };
        let output = output_dir.join(format!("{}.exr", render.name));
        let filtered = filter_one(env, asked, &render.path, &output)
            .with_context(|| format!("filtering {}", render.path.display()))?;
        done.push((render.name.as_str(), filtered));
    }
    // The folder at a glance, after each render's own figures.
    println!("\nrenders   {:<24} {:<26} {:>12} {:>12} {:>8}", "", "filter", "noisy relMSE", "relMSE", "light");
    for (name, filtered) in &done {
        let (noisy, relmse, light) = match filtered.scored {
            Some((noisy, filtered, light)) => {
                (format!("{noisy:.5}"), format!("{filtered:.5}"), light.map_or("-".into(), |l| format!("{l:.4}")))
            }
            None => ("-".into(), "-".into(), "no reference".into()),
        };
        println!("          {name:<24} {:<26} {noisy:>12} {relmse:>12} {light:>8}", filtered.filter);
    }
    println!("wrote     {} renders into {} (NAME.exr and NAME.png each)", done.len(), output_dir.display());
    Ok(())
}

/// What `filter_one` did, for a folder's summary.
struct Filtered {
    /// The filter, as `Choice::describe` names it.
    filter: String,
    /// relMSE of the noisy input and of the result, and the result's light, where there is a reference.
    scored: Option<(f64, f64, Option<f64>)>,
}

/// One render filtered and written to `output` (or into it, where it is a folder).
fn filter_one(env: &Environment, asked: Asked, scene_path: &Path, output: &Path) -> Result<Filtered> {
    let Asked { expr, radius, read, cpu_check, pipeline } = asked;
    let choice = match expr {
        Some(expr) => Choice::asked(expr, pipeline, radius)?,
        None => {
            let (features, variances) = scene::provides(scene_path, read.view_layer.as_deref())
                .with_context(|| format!("reading scene {}", scene_path.display()))?;
            Choice::asked_or_best(None, pipeline, radius, &Provided::new(features, variances))?
        }
    };
    refuse_radius(radius, &choice.pipeline)?;
    // `-o FOLDER` for one render, as `cp` reads it: the output goes inside,
    // named after the render (`-o NEW/` makes the folder). `-o NAME.png`:
    // the EXR beside the PNG preview, not under its name.
    let named;
    let output = if output.is_dir() || output.as_os_str().to_string_lossy().ends_with(std::path::is_separator) {
        std::fs::create_dir_all(output).with_context(|| format!("creating {}", output.display()))?;
        let name = scene_path.file_stem().unwrap_or(scene_path.as_os_str()).to_string_lossy();
        named = output.join(format!("{name}.exr"));
        named.as_path()
    } else if output.extension().is_some_and(|e| e.eq_ignore_ascii_case("png")) {
        named = output.with_extension("exr");
        named.as_path()
    } else {
        output
    };
    let noisy = if scene_path.is_dir() { scene_path.join(scene::NOISY_FILE) } else { scene_path.to_path_buf() };
    if same_file(&noisy, output) {
        bail!(
            "{}: the result would replace the render being filtered; write it to another file (-o)",
            output.display()
        );
    }
    let ReadScene { reference, spp, absent, view_layer } = read;
    let request = Request { reference_path: reference, spp, absent, view_layer, ..choice.request() };
    let load_start = Instant::now();
    let scene = scene::load(scene_path, &request).with_context(|| format!("loading scene {}", scene_path.display()))?;
    let load_time = load_start.elapsed();
    // A chosen filter may give way to its variant for the render's light (one read by the same request).
    let choice = choice.for_light(&scene.color, pipeline.is_some())?;
    let header_samples = scene::samples_per_pixel(scene_path, request.view_layer.as_deref())
        .with_context(|| format!("reading scene {}", scene_path.display()))?;
    // A render sampled at one point a pixel: the pixel filter its reference integrates, last.
    let choice = choice.for_point_sampled(scene::point_sampled_at(header_samples), pipeline.is_some());
    // A render of many samples (its `meta.json` or its header says how many): fewer passes for the chosen filter.
    let choice = choice.for_samples(scene.spp.or(header_samples), (scene.width, scene.height), pipeline.is_some());
    if let Some(because) = &choice.chosen_because {
        eprintln!("filter    {} (pipeline {}): {because}", choice.describe(), choice.pipeline);
    }
    let (expr, pipeline, radius) = (&choice.expr, choice.pipeline, choice.radius);
    for note in scene.notes.iter().filter(|n| n.warns) {
        eprintln!("note: {note}");
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

    // Their errors name the file.
    filterjit::scene::exr_io::write_rgb(output, scene.width, scene.height, &rgb)?;
    let png = output.with_extension("png");
    preview::write_png(&png, scene.width, scene.height, &rgb)?;

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
    let filter_name = choice.describe();
    let mut scored = None;
    match &scene.reference {
        Some(reference) => {
            let noisy = metrics::errors(&scene.color, reference, scene.spp);
            let filtered = metrics::errors(&rgb, reference, scene.spp);
            scored = Some((noisy.relmse, filtered.relmse, filtered.light));
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
    Ok(Filtered { filter: filter_name, scored })
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

/// Whether `a` and `b` name the same existing file or folder.
pub(crate) fn same_file(a: &Path, b: &Path) -> bool {
    matches!((a.canonicalize(), b.canonicalize()), (Ok(a), Ok(b)) if a == b)
}
