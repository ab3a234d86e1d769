//! The `filterjit` command line. Flags are parsed here and resolved into
//! library calls; errors are rendered here, with their whole context chain.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand};

use filterjit::environment::Environment;
use filterjit::metrics::{self, Errors};
use filterjit::scene::{self, Absent, Request};
use filterjit::{corpus, cpu, datasets, gpu, jit, lang, preview, render, semantics};

#[derive(Parser)]
#[command(
    name = "filterjit",
    version,
    about = "Compile filter-weight expressions into specialised WGSL kernels and denoise Monte Carlo renders"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Print the validated WGSL kernel of an expression.
    Compile {
        /// The expression, or @name for a shipped one (see `filterjit list`).
        expr: String,
        /// Write the WGSL to this file instead of standard output.
        #[arg(short, long)]
        output: Option<PathBuf>,
        /// Print the form's kernel of this pipeline (an à-trous pass, remodulating)
        /// [default: the one the expression was stored with, else `window`].
        #[arg(long)]
        pipeline: Option<filterjit::pipeline::FilterPipeline>,
    },
    /// Parse and type-check an expression; print its canonical form, length and inputs.
    Check {
        expr: String,
        /// Print the expression as a LaTeX formula instead (for a paper).
        #[arg(long)]
        latex: bool,
    },
    /// Simplify an expression by equality saturation (rules exact under
    /// filterjit's numeric semantics) and print the cheapest equivalent form.
    Simplify { expr: String },
    /// Export an expression as a standalone shader for another program (an
    /// engine): inputs from textures, output to a storage texture; writes a
    /// manifest of the binding interface beside it (FILE.json).
    Export {
        /// The expression, @name for a shipped one, or @FILE[:NAME] (a hall of fame);
        /// with --budget-ms, a multi-objective run's pareto.json (or its run directory).
        expr: String,
        /// Export the most accurate member of the front whose measured time
        /// fits this many milliseconds per frame at --size (on the device the
        /// front was timed on: pareto.json says which).
        #[arg(long, requires = "size")]
        budget_ms: Option<f64>,
        /// The frame size the budget is for, WIDTHxHEIGHT.
        #[arg(long, value_parser = parse_size)]
        size: Option<(u32, u32)>,
        /// Shading language: WGSL from filterjit's templates, the others through naga's back ends.
        #[arg(long, value_enum, default_value_t = filterjit::export::Target::Wgsl)]
        target: filterjit::export::Target,
        /// Texel format of the output storage texture.
        #[arg(long, value_enum, default_value_t = jit::OutputFormat::Rgba16float)]
        format: jit::OutputFormat,
        /// The shader file; its manifest goes to FILE.json.
        #[arg(short, long)]
        output: PathBuf,
        /// The pipeline to export [default: the one the expression was stored with, else `window`].
        /// Only `window` can be exported so far: pass it to export the weight of a filter stored with another.
        #[arg(long)]
        pipeline: Option<filterjit::pipeline::FilterPipeline>,
    },
    /// Filter a scene with an expression on the GPU; write the result as EXR and a PNG preview.
    Filter {
        /// The expression, or @name for a shipped one.
        #[arg(long)]
        expr: String,
        /// Window radius r: the window is (2r+1)² pixels [default: the one
        /// stored with the expression (a front member's `# radius:`), else 5].
        #[arg(long)]
        radius: Option<u32>,
        /// A scene directory (noisy.exr, reference.exr, ...) or a noisy EXR file.
        scene: PathBuf,
        /// Output EXR; a PNG preview is written beside it.
        #[arg(short, long)]
        output: PathBuf,
        /// Reference image, when not beside the noisy image.
        #[arg(long)]
        reference: Option<PathBuf>,
        /// Samples per pixel of the noisy image, when the scene does not say.
        #[arg(long)]
        spp: Option<u32>,
        /// What to do with features the scene lacks.
        #[arg(long, value_enum, default_value_t = Absent::Refuse)]
        absent: Absent,
        /// Also run the f64 CPU reference and report its difference from the GPU result.
        #[arg(long)]
        cpu_check: bool,
        /// The filter pipeline, e.g. `outliers=2,demodulate,atrous=5` or `window`
        /// [default: the one the expression was stored with, else `window`].
        #[arg(long)]
        pipeline: Option<filterjit::pipeline::FilterPipeline>,
    },
    /// Render a scene (a .toml file or a built-in name) into a dataset: noisy
    /// colour, features, variances and a converged reference.
    Render {
        /// A scene description (.toml) or the name of a built-in scene.
        scene: String,
        #[arg(long, default_value_t = 4)]
        spp: u32,
        #[arg(long, default_value_t = 1024)]
        reference_spp: u32,
        /// Image size, WIDTHxHEIGHT.
        #[arg(long, default_value = "128x128", value_parser = parse_size)]
        size: (u32, u32),
        #[arg(long, default_value_t = 0)]
        seed: u32,
        /// Output directory; without it the dataset goes into the cache and its path is printed.
        #[arg(short, long)]
        output: Option<PathBuf>,
    },
    /// Evolve filter expressions with genetic programming (thesis chapter 3), every
    /// individual compiled into its own kernel. With no arguments: the built-in
    /// training scenes, settings that finish in minutes on a 2-core CPU.
    Evolve(Box<EvolveArgs>),
    /// Measure the JIT: compile latency, throughput, against a stack interpreter
    /// and a hand-written kernel, and one GP generation. Prints a table, writes JSON.
    Bench {
        /// Size of the benchmark scene (a render of glossy-floor).
        #[arg(long, default_value = "64x64", value_parser = parse_size)]
        size: (u32, u32),
        #[arg(long, default_value_t = 5)]
        radius: u32,
        /// Repeats of every timing.
        #[arg(long, default_value_t = 5)]
        repeats: usize,
        /// Individuals compiled together for the amortised compile cost, and in the generation.
        #[arg(long, default_value_t = 400)]
        population: usize,
        /// Expression lengths of the corpus (two random expressions each).
        #[arg(long, value_delimiter = ',', default_value = "5,10,20,40,75,100,150")]
        lengths: Vec<usize>,
        /// Square sizes of the one-generation measurement; the flag without values skips it.
        #[arg(long, value_delimiter = ',', num_args = 0.., default_value = "64,128,256")]
        generation_sizes: Vec<u32>,
        #[arg(long, default_value_t = 10)]
        generation_radius: u32,
        /// Individuals per fitness kernel, as `evolve --fuse` (auto: 12 on software adapters, 1 on hardware).
        #[arg(long, default_value = "auto")]
        fuse: filterjit::evolve::Fusion,
        #[arg(short, long, default_value = "bench.json")]
        output: PathBuf,
    },
    /// Compare filters on scenes with references: error (relMSE both ways, MSE)
    /// against device time per megapixel, in tables, scatter plots with the
    /// Pareto front, image crops and an index.html, all in one folder. Scenes,
    /// sizes and radius default to --run's, else 64x64, 4 spp, 1024-spp
    /// references, radius 5.
    Report(Box<ReportArgs>),
    /// Tune the constant sigmas of the cross-bilateral filter on training scenes
    /// (the report's baseline); prints the tuned expression. Sizes and radius
    /// default to --run's, else 64x64, 4 spp, 1024-spp references, radius 5.
    Tune(Box<TuneArgs>),
    /// List the built-in scenes.
    Scenes,
    /// List the shipped expressions.
    List,
    /// List the GPU adapters and say which one filterjit uses.
    Adapters,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum Preset {
    /// 4 islands of 25, 15 generations, 32x32 scenes, radius 3: minutes on a 2-core CPU.
    Quick,
    /// The thesis's settings: 4 islands of 100, 200 generations, 64x64 scenes, radius 10.
    Thesis,
}

/// Render settings and radius; unset ones come from `evolve`'s preset, or
/// for `report`/`tune` from `--run`'s checkpoint, else 64x64, 4 spp, 1024 spp
/// references, radius 5.
#[derive(clap::Args, Clone)]
struct RenderArgs {
    /// Size scenes are rendered at, WIDTHxHEIGHT.
    #[arg(long, value_parser = parse_size)]
    size: Option<(u32, u32)>,
    /// Samples per pixel of rendered noisy images.
    #[arg(long)]
    spp: Option<u32>,
    /// Samples per pixel of rendered references.
    #[arg(long)]
    reference_spp: Option<u32>,
    /// Filter window radius (the window form's).
    #[arg(long)]
    radius: Option<u32>,
    /// The filter pipeline around the expression: stages separated by commas,
    /// `outliers=K` (firefly pre-pass), `demodulate` (filter colour/albedo),
    /// then the form, `window` or `atrous=PASSES` [window].
    #[arg(long)]
    pipeline: Option<filterjit::pipeline::FilterPipeline>,
}

/// How scenes are made and filtered, for `report` and `tune`; unset values
/// come from `--run`'s checkpoint, else the defaults shown.
#[derive(clap::Args, Clone)]
struct SceneArgs {
    #[command(flatten)]
    render: RenderArgs,
    /// Training scenes, for tuning the baseline [the run's, else the built-in training scenes].
    #[arg(long, value_delimiter = ',')]
    training_scenes: Vec<String>,
    /// An evolve run directory: its test and training scenes, render settings and radius are the defaults.
    #[arg(long)]
    run: Option<PathBuf>,
    /// Passes of coordinate descent over the sigmas.
    #[arg(long, default_value_t = 3)]
    sweeps: usize,
}

#[derive(clap::Args)]
struct ReportArgs {
    /// Expressions to report on: text, @name, or @FILE[:NAME]; with --run, the best of its hall of fame are added.
    exprs: Vec<String>,
    /// Scenes to report on: built-in names, .toml files or datasets [the run's test scenes, else the built-in test scenes].
    #[arg(long, value_delimiter = ',')]
    scenes: Vec<String>,
    /// How many of the hall of fame's best to include (with --run or --hall-of-fame).
    #[arg(long, default_value_t = 3)]
    top: usize,
    /// A hall-of-fame file (default with --run: its hall_of_fame.txt); also drawn as a feature-usage chart.
    #[arg(long)]
    hall_of_fame: Option<PathBuf>,
    /// Use this expression as the cross-bilateral baseline instead of tuning one.
    #[arg(long)]
    baseline: Option<String>,
    #[command(flatten)]
    scene: SceneArgs,
    /// Timed dispatches per filter and scene, after a warm-up.
    #[arg(long, default_value_t = 5)]
    repeats: usize,
    /// Side of the square image crops, pixels.
    #[arg(long, default_value_t = 48)]
    crop: usize,
    /// Filters are timed on each scene tiled to at least this many pixels per side.
    #[arg(long, default_value_t = 256)]
    timing_size: usize,
    /// The report folder.
    #[arg(short, long, default_value = "runs/report")]
    output: PathBuf,
    /// Leave out Intel Open Image Denoise even where its `oidnDenoise` is found
    /// (FILTERJIT_OIDN, PATH, or the pyoidn Python package).
    #[arg(long)]
    no_oidn: bool,
}

#[derive(clap::Args)]
struct TuneArgs {
    #[command(flatten)]
    scene: SceneArgs,
    /// Also write the result as a `name = expression` file (readable with @FILE).
    #[arg(short, long)]
    output: Option<PathBuf>,
}

/// Raw `evolve` flags; unset ones take the preset's values.
#[derive(clap::Args)]
struct EvolveArgs {
    /// Values for every flag not given.
    #[arg(long, value_enum, default_value_t = Preset::Quick)]
    preset: Preset,
    /// Training scenes: built-in names, .toml files, dataset directories, or folders whose subfolders are datasets (each is a scene) [default: the built-in training scenes].
    #[arg(long, value_delimiter = ',')]
    scenes: Vec<String>,
    /// Test scenes, likewise [default: the built-in test scenes].
    #[arg(long, value_delimiter = ',')]
    test_scenes: Vec<String>,
    #[command(flatten)]
    render: RenderArgs,
    /// The expression the population is seeded from.
    #[arg(long, default_value = "@bilateral")]
    seed_expr: String,
    /// Number of islands [quick, thesis: 4].
    #[arg(long)]
    islands: Option<usize>,
    /// Individuals per island [quick: 25, thesis: 100].
    #[arg(long)]
    island_size: Option<usize>,
    /// Generations to run: the stopping rule [quick: 15, thesis: 200].
    #[arg(long)]
    generations: Option<u32>,
    /// Longest expression, in nodes [75].
    #[arg(long)]
    max_length: Option<usize>,
    /// Tournament size [8].
    #[arg(long)]
    tournament: Option<usize>,
    /// Share of each generation copied unchanged.
    #[arg(long)]
    replication: Option<f64>,
    /// Share made by crossover (the rest by mutation).
    #[arg(long)]
    crossover: Option<f64>,
    /// Probability that a crossover child is mutated.
    #[arg(long)]
    crossover_mutation: Option<f64>,
    /// Weights of the mutations insert,replace,swap,delete.
    #[arg(long, value_delimiter = ',')]
    mutation_weights: Option<Vec<f64>>,
    /// Generations between migrations.
    #[arg(long)]
    migration_interval: Option<u32>,
    /// Share of each initial island that is the seed itself.
    #[arg(long)]
    seed_share: Option<f64>,
    /// Expressions per island in the hall of fame.
    #[arg(long)]
    hall_of_fame: Option<usize>,
    /// Random seed of the search (and of rendering).
    #[arg(long)]
    seed: Option<u64>,
    /// Simplify every new individual before it is evaluated (the same
    /// weights, shorter trees; docs/BENCHMARKS.md measures the effect).
    #[arg(long)]
    simplify_offspring: bool,
    /// What the search minimises: `error` (the thesis) or `error,cost`:
    /// NSGA-II over error and the modelled cost per pixel (src/cost.rs); the
    /// run's result is a front of filters, fast to accurate (pareto.json).
    #[arg(long, default_value_t = filterjit::gp::Objectives::Error)]
    objectives: filterjit::gp::Objectives,
    /// With `--objectives error,cost`: how many islands (the first) keep
    /// minimising error alone at the run's radius, feeding the front's
    /// accurate end through migration [default: all but one, as measured in
    /// docs/BENCHMARKS.md].
    #[arg(long)]
    error_islands: Option<usize>,
    /// Run directory: checkpoint, log, hall of fame, summary [default: runs/evolve, or
    /// runs/evolve-2, -3, … when it holds a run already; with --resume the newest of them].
    #[arg(short, long)]
    output: Option<PathBuf>,
    /// Continue the run in --output from its last checkpoint.
    #[arg(long)]
    resume: bool,
    /// Threads that compile kernels [default: the number of cores].
    #[arg(long)]
    threads: Option<usize>,
    /// Filters to compare with on the test scenes at the end (repeatable).
    #[arg(long, default_value = "@crossBilateral")]
    baseline: Vec<String>,
    /// Stage fitness kernels' windows in workgroup memory: auto = on hardware GPUs, off on software adapters (same results either way).
    #[arg(long, value_enum, default_value_t = filterjit::evolve::Tiles::Auto)]
    tiles: filterjit::evolve::Tiles,
    /// The weights of the modelled cost that `--objectives error,cost` trades
    /// against error, as `filterjit bench` measured them on this device
    /// (its `bench.json`, or a file holding just its `cost_model`) [default:
    /// the operator table's]. Kept in the run's checkpoint.
    #[arg(long, value_name = "FILE")]
    cost_model: Option<PathBuf>,
    /// Score fitness on COUNT tiles of SIZExSIZE pixels per training scene
    /// (e.g. `8x32`), each with the halo the pipeline reads, drawn once from
    /// the seed, instead of on whole images: a generation on 256x256 renders
    /// then costs about what one on small scenes does. The hall of fame is
    /// scored on whole images at the end [default: whole images].
    #[arg(long, value_name = "COUNTxSIZE")]
    fitness_tiles: Option<filterjit::fitness_tiles::TileSampling>,
    /// The only features and variances the search may read, e.g.
    /// `color,pixel,normal,texture,worldPosition,depth` for filters meant for
    /// Mitsuba renders (no direct illumination, secondary albedo or per-feature
    /// variances) [default: every one the training scenes provide]. Kept in the checkpoint.
    #[arg(long, value_delimiter = ',', value_parser = parse_terminal)]
    features: Vec<String>,
    /// Divide each training scene's relMSE by this filter's relMSE on it
    /// (an expression, `@NAME` or `@FILE:NAME`; scored once, through the run's
    /// pipeline, on the same pixels) instead of by the noisy input's: fitness 1
    /// is the baseline's [default: the noisy input, the thesis's rule]. Kept in the checkpoint.
    #[arg(long, value_name = "EXPR")]
    fitness_relative_to: Option<String>,
    /// Pool the per-scene ratios by their mean or by the worst scene (with
    /// `--fitness-relative-to`, a fitness below 1 is then better than the
    /// baseline on every training scene). Kept in the checkpoint.
    #[arg(long, default_value = "mean", value_name = "mean|worst")]
    fitness_pool: filterjit::fitness_rule::Pool,
    /// Individuals per fitness kernel: auto = 12 on software adapters (their compile cost is per module), 1 on hardware GPUs; a number forces it (same results either way).
    #[arg(long, default_value = "auto")]
    fuse: filterjit::evolve::Fusion,
    /// Share the islands among the ranks of the MPI job this process was
    /// started in (`mpirun -n 4 filterjit evolve --mpi …`; a filterjit built
    /// with `--features mpi`; docs/DISTRIBUTED.md). Same seed, same result as one process.
    #[arg(long)]
    mpi: bool,
}

fn main() -> ExitCode {
    // Mesa's Vulkan device-select layer probes for a Wayland/X display and
    // prints errors without one; filterjit chooses its adapter itself
    // (gpu::adapter). Set before any thread exists.
    if std::env::var_os("NODEVICE_SELECT").is_none() {
        std::env::set_var("NODEVICE_SELECT", "1");
    }
    // A reader that stops early (`filterjit simplify E | head -1`) ends the
    // program quietly, as it does other command-line tools, instead of
    // making `println!` panic on the closed pipe.
    #[cfg(unix)]
    // SAFETY: restoring the default action of one signal, before any thread exists.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    let cli = Cli::parse();
    // Compile timings must include the driver's compilation: Mesa would
    // otherwise answer from its on-disk shader cache.
    if matches!(cli.command, Command::Bench { .. }) && std::env::var_os("MESA_SHADER_CACHE_DISABLE").is_none() {
        std::env::set_var("MESA_SHADER_CACHE_DISABLE", "true");
    }
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli) -> Result<()> {
    let env = &Environment::read()?;
    match cli.command {
        Command::Compile { expr, output, pipeline } => {
            let resolved = corpus::resolve_with_pipeline(&expr)?;
            let shape = jit::Shape::of(&pipeline.or(resolved.pipeline).unwrap_or_default());
            let kernel = jit::compile_shaped(&resolved.expr, jit::KernelKind::Filter, jit::LowerOptions::ALL, shape)?;
            match output {
                Some(path) => filterjit::io::write_bytes_atomically(&path, kernel.wgsl().as_bytes())
                    .map_err(anyhow::Error::msg)
                    .with_context(|| format!("writing {}", path.display()))?,
                None => print!("{}", kernel.wgsl()),
            }
            Ok(())
        }
        Command::Export { expr, target, format, output, pipeline, budget_ms, size } => {
            let resolved = match budget_ms {
                None => corpus::resolve_with_pipeline(&expr)?,
                Some(budget) => {
                    let front = filterjit::evolve::Front::read(Path::new(&expr))?;
                    let (w, h) = size.expect("clap requires --size with --budget-ms");
                    let member = front.within_budget(budget, w as f64 * h as f64)?;
                    eprintln!(
                        "chose     {} (radius {}, fitness {:.5}, {:.2} ms at {w}x{h} on {}) of {} members",
                        member.name,
                        member.radius,
                        member.fitness,
                        member.ms_per_mpx * (w * h) as f64 / 1e6,
                        front.device,
                        front.members.len()
                    );
                    corpus::Resolved {
                        name: Some(member.name.clone()),
                        expr: filterjit::parse_expr(&member.expr).map_err(|e| anyhow::anyhow!("{e}"))?,
                        pipeline: Some(front.pipeline),
                        radius: Some(member.radius),
                    }
                }
            };
            let pipeline = pipeline.or(resolved.pipeline).unwrap_or_default();
            if pipeline != filterjit::pipeline::FilterPipeline::WINDOW {
                bail!(
                    "`{expr}` is filtered through the pipeline `{pipeline}`, and export writes the window form only \
                     (one pass, no pre-pass) so far; pass --pipeline window to export its weight as a single window pass"
                );
            }
            // An engine gets the cheapest equivalent form (the same weights).
            let expr = filterjit::simplify::simplify(&resolved.expr);
            let mut exported = filterjit::export::export(&expr, target, format)?;
            exported.manifest.radius = resolved.radius;
            let manifest_path = manifest_path(&output);
            let manifest = serde_json::to_string_pretty(&exported.manifest)? + "\n";
            for (path, bytes) in [(&output, exported.code.to_bytes()), (&manifest_path, manifest.into_bytes())] {
                filterjit::io::write_bytes_atomically(path, &bytes)
                    .map_err(anyhow::Error::msg)
                    .with_context(|| format!("writing {}", path.display()))?;
            }
            println!(
                "wrote {} ({}) and its manifest {}",
                output.display(),
                exported.manifest.language,
                manifest_path.display()
            );
            println!("entry point `{}`, workgroup 8x8x1; bindings:", exported.manifest.entry_point);
            for b in &exported.manifest.bindings {
                println!("  {:<26} {:<16} {}", b.target_slot, b.kind, b.role);
            }
            if exported.manifest.sampled_textures > filterjit::export::PORTABLE_SAMPLED_TEXTURES {
                eprintln!(
                    "warning: the shader binds {} sampled textures; WebGPU guarantees {} per stage, so it needs a device that allows more",
                    exported.manifest.sampled_textures,
                    filterjit::export::PORTABLE_SAMPLED_TEXTURES
                );
            }
            Ok(())
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
        Command::Filter { expr, radius, scene, output, reference, spp, absent, cpu_check, pipeline } => {
            filter(env, &expr, radius, &scene, &output, reference, spp, absent, cpu_check, pipeline)
        }
        Command::Render { scene, spp, reference_spp, size, seed, output } => {
            render(env, &scene, spp, reference_spp, size, seed, output.as_deref())
        }
        Command::Evolve(args) => evolve(env, *args),
        Command::Report(args) => report(env, *args),
        Command::Tune(args) => {
            let gpu = gpu::Gpu::open(&env.adapter)?;
            let context = scene_context(&args.scene)?;
            let tuned = tune_baseline(&gpu, env, &args.scene, &context)?;
            println!("crossBilateralTuned = {}", tuned.expr);
            if let Some(path) = &args.output {
                let text = format!(
                    "# tuned on {} at {}x{}, radius {}: training relMSE/noisy {:.5} (hand-set {:.5})\n{} {}\ncrossBilateralTuned = {}\n",
                    tuned.scenes.join(", "),
                    context.render.width,
                    context.render.height,
                    context.radius,
                    tuned.fitness,
                    tuned.hand_set_fitness,
                    corpus::PIPELINE_PREFIX,
                    context.pipeline,
                    tuned.expr
                );
                filterjit::io::write_bytes_atomically(path, text.as_bytes()).map_err(anyhow::Error::msg)?;
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
        } => {
            let settings = filterjit::bench::BenchSettings {
                radius,
                repeats: repeats.max(1),
                population: population.max(4),
                lengths,
                generation_sizes: generation_sizes.into_iter().filter(|s| *s > 0).collect(),
                generation_radius,
                seed: 0,
                fusion: fuse,
            };
            bench(env, size, &settings, &output)
        }
        Command::Scenes => {
            for (name, _) in render::BUILTIN {
                let d = render::builtin(name).expect("listed")?;
                println!("{name:<16} {:<6} {}", format!("{:?}", d.split).to_lowercase(), d.summary);
            }
            Ok(())
        }
        Command::List => {
            for (name, text) in corpus::named() {
                match corpus::pipeline_of(corpus::EXPRESSIONS, name) {
                    Some(pipeline) => println!("@{name} (pipeline {})\n    {text}", pipeline?),
                    None => println!("@{name}\n    {text}"),
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
fn resolve_expr(arg: &str) -> Result<lang::Expr> {
    Ok(corpus::resolve(arg)?.1)
}

#[allow(clippy::too_many_arguments)]
fn filter(
    env: &Environment,
    expr: &str,
    radius: Option<u32>,
    scene_path: &Path,
    output: &Path,
    reference: Option<PathBuf>,
    spp: Option<u32>,
    absent: Absent,
    cpu_check: bool,
    pipeline: Option<filterjit::pipeline::FilterPipeline>,
) -> Result<()> {
    let resolved = corpus::resolve_with_pipeline(expr)?;
    let expr = resolved.expr;
    let pipeline = pipeline.or(resolved.pipeline).unwrap_or_default();
    let radius = radius.or(resolved.radius).unwrap_or(5);
    let request =
        Request { reference_path: reference, spp, absent, albedo: pipeline.demodulate, ..Request::for_expr(&expr) };
    let load_start = Instant::now();
    let scene = scene::load(scene_path, &request).with_context(|| format!("loading scene {}", scene_path.display()))?;
    let load_time = load_start.elapsed();
    for note in &scene.notes {
        if note.contains("absent") || note.contains("non-finite") {
            eprintln!("note: {note}");
        }
    }

    let compile_start = Instant::now();
    let shape = jit::Shape::of(&pipeline);
    let kernel = jit::compile_shaped(&expr, jit::KernelKind::Filter, jit::LowerOptions::ALL, shape)?;
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
        .map_err(anyhow::Error::msg)
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
        filterjit::pipeline::Form::Atrous { passes } => format!("{passes} a-trous passes"),
    };
    println!("pipeline  {pipeline}");
    println!(
        "time      load {:.1} ms | lower+validate {:.2} ms | pre-pass {:.1} ms (first, compile included) | pipeline {:.1} ms | first dispatch {:.1} ms | filter {:.1} ms ({:.1} ms/Mpx, {form}, {} dispatch{})",
        ms(load_time),
        ms(lower_validate),
        ms(prepass_time),
        ms(first.pipeline.create),
        ms(first.dispatch),
        ms(warm.dispatch),
        ms(warm.dispatch) / megapixels,
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
            println!("error     {:<10} {:>12} {:>14} {:>12} {:>10}", "", "relMSE", "relMSE*m/2", "MSE", "HDR-FLIP");
            print_errors("noisy", &noisy, flip(&scene.color));
            print_errors("filtered", &filtered, flip(&rgb));
        }
        None => println!("error     no reference image: errors not computed"),
    }
    if cpu_check {
        let reference = cpu::filter_pipeline(&expr, &scene, &pipeline, radius)?;
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

/// A feature's or a variance's name, as expressions write it.
fn parse_terminal(text: &str) -> Result<String, String> {
    if lang::Feature::from_name(text).is_some() || lang::ScalarVar::from_name(text).is_some() {
        return Ok(text.to_string());
    }
    let features = lang::Feature::ALL.iter().map(|f| f.name());
    let variances = lang::ScalarVar::ALL.iter().filter(|v| **v != lang::ScalarVar::Level).map(|v| v.name());
    let names: Vec<&str> = features.chain(variances).collect();
    Err(format!("`{text}` is no feature or variance; they are {}", names.join(", ")))
}

fn parse_size(text: &str) -> Result<(u32, u32), String> {
    let (w, h) = text.split_once('x').ok_or_else(|| format!("`{text}` is not WIDTHxHEIGHT"))?;
    let parse = |v: &str| v.trim().parse::<u32>().map_err(|_| format!("`{text}` is not WIDTHxHEIGHT"));
    let (w, h) = (parse(w)?, parse(h)?);
    if w == 0 || h == 0 {
        return Err(format!("`{text}`: the size must be at least 1x1"));
    }
    Ok((w, h))
}

/// A progress bar counting pixel samples, with samples per second.
fn sample_bar(label: &str) -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::new(0);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{prefix:>14} {bar:30} {percent:>3}% {per_sec:>14} eta {eta}")
            .expect("valid template"),
    );
    bar.set_prefix(label.to_string());
    bar
}

fn render(
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
        Some(dir) => {
            let rendered = render::render(&gpu, &d, &settings, &mut progress)?;
            rendered.write(dir, &d, &settings)?;
            dir.to_path_buf()
        }
        None => render::cached(&gpu, &env.cache, &d, &settings, &mut progress)?,
    };
    bar.finish_and_clear();
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

/// Ranks of the MPI job this process was started in, as its launcher says
/// (Open MPI's mpirun and srun, MPICH's hydra); 1 without one.
fn launched_ranks() -> usize {
    ["OMPI_COMM_WORLD_SIZE", "PMI_SIZE"].iter().find_map(|v| std::env::var(v).ok()?.parse().ok()).unwrap_or(1)
}

fn evolve(env: &Environment, args: EvolveArgs) -> Result<()> {
    let launched = launched_ranks();
    if !args.mpi {
        if launched > 1 {
            bail!(
                "this process is one of {launched} MPI ranks, but --mpi is not given: every rank would run the \
                 whole search into the same run directory; pass --mpi"
            );
        }
        let cores = std::thread::available_parallelism().map_or(2, |n| n.get());
        return evolve_on(env, args, &mut filterjit::gp::transport::InProcess, 0, cores);
    }
    #[cfg(feature = "mpi")]
    {
        use filterjit::gp::transport::Transport;
        let mut mpi = filterjit::gp::mpi::Mpi::init()?;
        // Ranks on one node share its cores (software adapters compile on them) and its GPUs.
        let cores = std::thread::available_parallelism().map_or(2, |n| n.get());
        let (node_rank, threads) = (mpi.node_rank(), (cores / mpi.node_ranks()).max(1));
        let result = evolve_on(env, args, &mut mpi, node_rank, threads);
        if let Err(e) = &result {
            if mpi.ranks() > 1 {
                // The other ranks would wait for this one forever.
                eprintln!("error (rank {} of {}): {e:#}", mpi.rank(), mpi.ranks());
                mpi.abort(1);
            }
        }
        result
    }
    #[cfg(not(feature = "mpi"))]
    bail!(
        "this filterjit was built without MPI: build it with `cargo build --release --features mpi` \
         (Debian: apt-get install openmpi-bin libopenmpi-dev libclang-dev); docs/DISTRIBUTED.md"
    )
}

/// `evolve` as one of the processes `transport` reaches: the `node_rank`-th
/// on its machine, with `cores` cores to itself. Only the root prints.
fn evolve_on(
    env: &Environment,
    args: EvolveArgs,
    transport: &mut dyn filterjit::gp::transport::Transport,
    node_rank: usize,
    cores: usize,
) -> Result<()> {
    use filterjit::evolve as ev;
    let root = transport.is_root();
    let base = filterjit::gp::Settings::default();
    let (preset, size, spp, reference_spp, radius) = match args.preset {
        Preset::Quick => {
            (filterjit::gp::Settings { island_size: 25, generations: 15, ..base.clone() }, (32, 32), 4, 512, 3)
        }
        Preset::Thesis => (base.clone(), (64, 64), 4, 1024, 10),
    };
    let settings = filterjit::gp::Settings {
        islands: args.islands.unwrap_or(preset.islands),
        island_size: args.island_size.unwrap_or(preset.island_size),
        generations: args.generations.unwrap_or(preset.generations),
        max_length: args.max_length.unwrap_or(preset.max_length),
        tournament: args.tournament.unwrap_or(preset.tournament),
        replication: args.replication.unwrap_or(preset.replication),
        crossover: args.crossover.unwrap_or(preset.crossover),
        crossover_mutation: args.crossover_mutation.unwrap_or(preset.crossover_mutation),
        mutation_weights: args.mutation_weights.clone().unwrap_or(preset.mutation_weights.clone()),
        migration_interval: args.migration_interval.unwrap_or(preset.migration_interval),
        seed_share: args.seed_share.unwrap_or(preset.seed_share),
        hall_of_fame: args.hall_of_fame.unwrap_or(preset.hall_of_fame),
        seed: args.seed.unwrap_or(preset.seed),
        simplify_offspring: args.simplify_offspring,
        objectives: args.objectives,
        error_islands: match (args.objectives, args.error_islands) {
            (_, Some(n)) => n,
            (filterjit::gp::Objectives::ErrorCost, None) => args.islands.unwrap_or(preset.islands).saturating_sub(1),
            (filterjit::gp::Objectives::Error, None) => 0,
        },
    };
    let size = args.render.size.unwrap_or(size);
    let builtin = |split| render::builtin_split(split).into_iter().map(|d| d.name).collect::<Vec<_>>();
    let seed_text = resolve_expr(&args.seed_expr)?.to_string();
    let config = ev::RunConfig {
        training: if args.scenes.is_empty() { builtin(render::Split::Train) } else { args.scenes.clone() },
        test: if args.test_scenes.is_empty() { builtin(render::Split::Test) } else { args.test_scenes.clone() },
        render: render::RenderSettings {
            width: size.0,
            height: size.1,
            spp: args.render.spp.unwrap_or(spp),
            reference_spp: args.render.reference_spp.unwrap_or(reference_spp),
            seed: settings.seed as u32,
        },
        radius: args.render.radius.unwrap_or(radius),
        seed_expr: seed_text,
        pipeline: args.render.pipeline.unwrap_or_default(),
        cost_model: match &args.cost_model {
            Some(path) => filterjit::cost::CostModel::read(path).map_err(anyhow::Error::msg)?,
            None => filterjit::cost::CostModel::table(),
        },
        fitness_tiles: args.fitness_tiles,
        features: (!args.features.is_empty()).then(|| args.features.iter().cloned().collect()),
        fitness: filterjit::fitness_rule::FitnessRule {
            relative_to: args.fitness_relative_to.as_deref().map(resolve_expr).transpose()?.map(|e| e.to_string()),
            pool: args.fitness_pool,
        },
    };
    let threads = args.threads.unwrap_or(cores);
    let output = match &args.output {
        Some(dir) => dir.clone(),
        None => {
            let base = Path::new(ev::DEFAULT_RUN_DIR);
            let dir = ev::default_run_dir(base, args.resume);
            if dir != base && root {
                eprintln!(
                    "run dir   {} ({} holds an earlier run; -o DIR names another)",
                    dir.display(),
                    base.display()
                );
            }
            dir
        }
    };
    let gpu = gpu::Gpu::open_for(&env.adapter, node_rank)?;
    let islands = filterjit::gp::transport::share(settings.islands, transport.rank(), transport.ranks());
    if transport.ranks() > 1 {
        // One line per rank: where its islands run.
        eprintln!(
            "rank {}/{} islands {}..{} on {}, {threads} threads",
            transport.rank(),
            transport.ranks(),
            islands.start,
            islands.end,
            gpu.describe()
        );
    }
    if root {
        eprintln!(
            "evolve    {} islands x {}, {} generations, max length {}, radius {}, pipeline {}, scenes {}x{}{}, {} per fitness kernel, on {}{}{}",
            settings.islands,
            settings.island_size,
            settings.generations,
            settings.max_length,
            config.radius,
            config.pipeline,
            size.0,
            size.1,
            match config.fitness_tiles {
                Some(t) => format!(" scored on {} tiles of {}x{} each", t.count, t.size, t.size),
                None => String::new(),
            },
            // A cascade's passes each read the last one's output: its kernels are never fused.
            match if config.pipeline.is_atrous() { 1 } else { args.fuse.members(&gpu) } {
                1 => "one individual".to_string(),
                n => format!("up to {n} individuals"),
            },
            gpu.describe(),
            match transport.ranks() {
                1 => String::new(),
                n => format!(" (rank 0 of {n} MPI ranks)"),
            },
            match config.fitness.is_thesis() {
                true => String::new(),
                false => format!("\nfitness   {}", config.fitness.describe()),
            }
        );
    }
    let render_bar = if root { sample_bar("rendering") } else { indicatif::ProgressBar::hidden() };
    let mut on_render = |done: u64, total: u64| {
        render_bar.set_length(total);
        render_bar.set_position(done);
        if done == total {
            render_bar.finish_and_clear();
        }
    };
    let bar =
        if root { indicatif::ProgressBar::new(settings.generations as u64) } else { indicatif::ProgressBar::hidden() };
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "generation {pos:>4}/{len} {bar:20} {elapsed} elapsed, {eta} left | {msg}",
        )
        .expect("valid template"),
    );
    let mut first_report = true;
    let mut on_report = |r: &filterjit::gp::Report| {
        bar.set_position(r.generation as u64);
        if std::mem::take(&mut first_report) {
            // A resumed run starts at its checkpoint: time left counts from here.
            bar.reset_eta();
        }
        bar.set_message(format!(
            "best {:.4} median {:.4} invalid {} | compile {:.1}s evaluate {:.1}s gp {:.2}s",
            r.best, r.median, r.invalid, r.compile_s, r.evaluate_s, r.gp_s
        ));
    };
    let summary = ev::run_with(
        &gpu,
        ev::RunOptions {
            settings,
            config,
            output: output.clone(),
            resume: args.resume,
            threads,
            stop_after: None,
            on_report: &mut on_report,
            on_render: &mut on_render,
            baselines: args.baseline.iter().map(|b| resolve_expr(b)).collect::<Result<_>>()?,
            tiles: args.tiles,
            fusion: args.fuse,
            cache: env.cache.clone(),
        },
        transport,
    )?;
    // Ranks other than the root end with the last generation.
    let Some(summary) = summary else { return Ok(()) };
    bar.finish();
    println!("best      {}", summary.best.expr);
    if summary.best_simplified != summary.best.expr {
        println!("          = {} (simplified)", summary.best_simplified);
    }
    let length = lang::parse_expr(&summary.best.expr).map(|e| e.len()).unwrap_or(0);
    match summary.rescored_hall_of_fame.iter().find(|r| r.expr == summary.best.expr).and_then(|r| r.fitness) {
        Some(whole) => println!(
            "fitness   {whole:.5} (training, whole images: mean relMSE / noisy relMSE; {:.5} on the search's {}), length {length}",
            summary.best.fitness.value, summary.training_scored_on
        ),
        None => println!(
            "fitness   {:.5} (training: mean relMSE / noisy relMSE), length {length}",
            summary.best.fitness.value
        ),
    }
    let baseline_names: Vec<String> = (0..summary.test_baselines.len()).map(|k| format!("baseline{}", k + 1)).collect();
    println!(
        "test      {:<16} {:>12} {:>12} {:>12}{}",
        "relMSE",
        "noisy",
        "seed",
        "best",
        baseline_names.iter().map(|n| format!(" {n:>12}")).collect::<String>()
    );
    for (k, name) in summary.test_scenes.iter().enumerate() {
        println!(
            "          {:<16} {:>12.5} {:>12.5} {:>12.5}{}",
            name,
            summary.test_noisy_relmse[k],
            summary.test_seed.relmse[k],
            summary.test_best.relmse[k],
            summary.test_baselines.iter().map(|b| format!(" {:>12.5}", b.relmse[k])).collect::<String>()
        );
    }
    println!(
        "          {:<16} {:>12} {:>12.5} {:>12.5}{}   (mean of relMSE / noisy relMSE)",
        "normalised",
        "1",
        summary.test_seed.normalised,
        summary.test_best.normalised,
        summary.test_baselines.iter().map(|b| format!(" {:>12.5}", b.normalised)).collect::<String>()
    );
    for (name, b) in baseline_names.iter().zip(&summary.test_baselines) {
        println!("          {name} = {}", b.expr);
    }
    let mut used: Vec<(&String, &usize)> = summary.feature_frequencies.iter().filter(|(_, n)| **n > 0).collect();
    used.sort_by(|a, b| b.1.cmp(a.1));
    println!("features  {}", used.iter().map(|(f, n)| format!("{f} {n}")).collect::<Vec<_>>().join(", "));
    println!("time      {:.1} s", summary.seconds);
    println!(
        "wrote     {}/{{{},{},{},{},{}}}",
        output.display(),
        ev::HALL_OF_FAME_FILE,
        ev::LOG_FILE,
        ev::CHECKPOINT_FILE,
        ev::FEATURES_FILE,
        ev::SUMMARY_FILE
    );
    Ok(())
}

fn bench(env: &Environment, size: (u32, u32), settings: &filterjit::bench::BenchSettings, output: &Path) -> Result<()> {
    let gpu = gpu::Gpu::open(&env.adapter)?;
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
    let report = filterjit::bench::run(&gpu, &scene, &mut generation_scene, settings, &mut progress)?;
    print!("{}", filterjit::bench::table(&report));
    filterjit::io::write_bytes_atomically(output, serde_json::to_string_pretty(&report)?.as_bytes())
        .map_err(anyhow::Error::msg)?;
    println!("wrote     {}", output.display());
    Ok(())
}

fn print_errors(label: &str, e: &Errors, flip: f64) {
    let m2 = e.relmse_half_spp.map_or("-".to_string(), |v| format!("{v:.6}"));
    println!("          {label:<10} {:>12.6} {:>14} {:>12.6} {flip:>10.6}", e.relmse, m2, e.mse);
}

fn ms(d: std::time::Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

/// Where `export` writes the manifest of the shader at `shader`: `shader` + `.json`.
fn manifest_path(shader: &Path) -> PathBuf {
    let mut name = shader.as_os_str().to_owned();
    name.push(".json");
    PathBuf::from(name)
}

/// Scene settings of `report`/`tune`: flags, else the run's checkpoint, else defaults.
struct SceneContext {
    render: render::RenderSettings,
    radius: u32,
    pipeline: filterjit::pipeline::FilterPipeline,
    training: Vec<String>,
    test: Vec<String>,
}

fn scene_context(args: &SceneArgs) -> Result<SceneContext> {
    let run = match &args.run {
        Some(dir) => Some(
            filterjit::evolve::read_checkpoint(dir)
                .with_context(|| format!("reading the run in {}", dir.display()))?
                .run,
        ),
        None => None,
    };
    let builtin = |split| render::builtin_split(split).into_iter().map(|d| d.name).collect::<Vec<_>>();
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
        pipeline: args.render.pipeline.or(run.as_ref().map(|r| r.pipeline)).unwrap_or_default(),
        training: if !args.training_scenes.is_empty() {
            args.training_scenes.clone()
        } else {
            run.as_ref().map(|r| r.training.clone()).unwrap_or_else(|| builtin(render::Split::Train))
        },
        test: run.as_ref().map(|r| r.test.clone()).unwrap_or_else(|| builtin(render::Split::Test)),
    })
}

fn render_progress() -> impl FnMut(u64, u64) {
    let bar = sample_bar("rendering");
    move |done: u64, total: u64| {
        bar.set_length(total);
        bar.set_position(done);
        if done == total {
            bar.finish_and_clear();
        }
    }
}

fn tune_baseline(
    gpu: &gpu::Gpu,
    env: &Environment,
    args: &SceneArgs,
    context: &SceneContext,
) -> Result<filterjit::tune::Tuned> {
    use filterjit::evolve as ev;
    let datasets = datasets::resolve(gpu, &context.training, &context.render, &env.cache, &mut render_progress())?;
    let (features, variances) = datasets::common_terminals(&datasets)?;
    let scenes = datasets::load_all(&datasets, &features, &variances, &context.pipeline)?;
    let threads = std::thread::available_parallelism().map_or(2, |n| n.get());
    let mut evaluator = ev::GpuEvaluator::for_pipeline(gpu, scenes, context.radius, context.pipeline, threads)?;
    eprintln!(
        "tune      cross-bilateral sigmas on {} ({}x{}, radius {}, pipeline {})",
        context.training.join(", "),
        context.render.width,
        context.render.height,
        context.radius,
        context.pipeline
    );
    let tuned = filterjit::tune::tune(&mut evaluator, args.sweeps, &mut |sigmas, fitness| {
        eprintln!(
            "          {fitness:.5}  {}",
            sigmas.0.iter().map(|(k, v)| format!("{k} {v}")).collect::<Vec<_>>().join(", ")
        );
    })?;
    eprintln!(
        "tuned     training relMSE/noisy {:.5} (hand-set sigmas {:.5}), {} candidates",
        tuned.fitness, tuned.hand_set_fitness, tuned.evaluated
    );
    Ok(tuned)
}

fn report(env: &Environment, args: ReportArgs) -> Result<()> {
    use filterjit::report::{self, Method, Origin};
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
            let expr = lang::parse_expr(&tuned.expr).map_err(|e| anyhow::anyhow!("{e}"))?;
            ("crossBilateral (tuned)".to_string(), expr, context.pipeline, Some(tuned))
        }
    };
    methods.push(Method {
        name: baseline_name,
        origin: Origin::Baseline,
        expr: baseline_expr,
        pipeline: baseline_pipeline,
        radius: None,
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
        });
    }
    for (k, arg) in args.exprs.iter().enumerate() {
        let resolved = corpus::resolve_with_pipeline(arg)?;
        methods.push(Method {
            name: resolved.name.unwrap_or_else(|| format!("expr{}", k + 1)),
            origin: Origin::Given,
            expr: resolved.expr,
            pipeline: resolved.pipeline.unwrap_or(context.pipeline),
            radius: resolved.radius,
        });
    }
    let hall_path = args
        .hall_of_fame
        .clone()
        .or_else(|| args.scene.run.as_ref().map(|d| d.join(filterjit::evolve::HALL_OF_FAME_FILE)));
    let mut hall = Vec::new();
    if let Some(path) = &hall_path {
        let content = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        let mut taken = 0;
        for (name, text) in corpus::parse_named(&content) {
            let expr =
                lang::parse_expr(text).map_err(|e| anyhow::anyhow!("{}: entry `{name}`:\n{e}", path.display()))?;
            // Reported as people read them: simplified (the same weights).
            let expr = filterjit::simplify::simplify(&expr);
            let pipeline = corpus::pipeline_of(&content, name)
                .transpose()
                .with_context(|| format!("{}: the pipeline of `{name}`", path.display()))?
                .unwrap_or(context.pipeline);
            let radius = corpus::radius_of(&content, name)
                .transpose()
                .with_context(|| format!("{}: the radius of `{name}`", path.display()))?;
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
                });
            }
            hall.push(expr);
        }
    }
    let scene_names = if args.scenes.is_empty() { context.test.clone() } else { args.scenes.clone() };
    let datasets = datasets::resolve(&gpu, &scene_names, &context.render, &env.cache, &mut render_progress())?;
    let settings = report::Settings {
        radius: context.radius,
        repeats: args.repeats,
        crop: args.crop,
        timing_size: args.timing_size,
    };
    let oidn = match (args.no_oidn, report::oidn::Oidn::find(env.oidn.as_deref(), env.path.as_deref())) {
        (true, _) => None,
        (false, Ok(oidn)) => {
            eprintln!("peer      Intel Open Image Denoise: {}", oidn.program.display());
            Some(oidn)
        }
        (false, Err(why)) => {
            eprintln!("note: the report goes on without Intel Open Image Denoise: {why}");
            None
        }
    };
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
