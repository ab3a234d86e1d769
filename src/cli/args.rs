//! The command line's flags (clap), presets and value parsers.

use super::*;
use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "filterjit",
    version,
    about = "Compile filter-weight expressions into specialised WGSL kernels and denoise Monte Carlo renders"
)]
pub(crate) struct Cli {
    #[command(subcommand)]
    pub(crate) command: Command,
}

/// How `filter` reads its scene.
#[derive(clap::Args, Clone, Debug)]
pub(crate) struct ReadScene {
    /// Reference image, when not beside the noisy image.
    #[arg(long)]
    pub(crate) reference: Option<PathBuf>,
    /// Samples per pixel of the noisy image, when the scene does not say.
    #[arg(long)]
    pub(crate) spp: Option<u32>,
    /// What to do with features the scene lacks.
    #[arg(long, value_enum, default_value_t = Absent::Refuse)]
    pub(crate) absent: Absent,
    /// The view layer of a Blender multilayer EXR that has several
    /// [default: the only one].
    #[arg(long)]
    pub(crate) view_layer: Option<String>,
}

#[derive(Subcommand)]
pub(crate) enum Command {
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
        /// Shading language: WGSL from filterjit's templates, the others through naga's back ends
        /// [default: the one -o's extension names (.wgsl, .comp or .glsl, .hlsl, .metal or .msl, .spv), else WGSL].
        #[arg(long, value_enum)]
        target: Option<filterjit::export::Target>,
        /// Texel format of the output storage texture.
        #[arg(long, value_enum, default_value_t = jit::OutputFormat::Rgba16float)]
        format: jit::OutputFormat,
        /// The shader file; its manifest goes to FILE.json.
        #[arg(short, long)]
        output: PathBuf,
        /// The pipeline to export [default: the one the expression was stored with, else `window`]:
        /// every stage is exported, each a shader of its own beside the form's (examples/README.md).
        #[arg(long)]
        pipeline: Option<filterjit::pipeline::FilterPipeline>,
    },
    /// Filter a scene with an expression on the GPU; write the result as EXR and a PNG preview.
    Filter {
        /// The expression, @name for a shipped one, or @FILE[:NAME] [default:
        /// the best shipped filter whose inputs the scene has; stderr says which and why].
        /// `@realtime` without --pipeline runs `@realtimeSparse` where the render's median pixel is under 0.15 of its mean.
        #[arg(long)]
        expr: Option<String>,
        /// Window radius r: the window is (2r+1)² pixels [default: the one
        /// stored with the expression (a front member's `# radius:`), else 5].
        #[arg(long)]
        radius: Option<u32>,
        /// A scene directory (noisy.exr, reference.exr, ...) or a noisy EXR
        /// file; or a folder of them: a sequence's frames where their names
        /// are numbered (frame_0001, …), filtered in order with the state
        /// carried, else renders of their own, each filtered alone.
        scene: PathBuf,
        /// Output EXR, or an existing folder to write NAME.exr into (NAME: the
        /// render's file or folder name); a PNG preview is written beside it.
        /// For a sequence, the folder its frames are written into.
        #[arg(short, long)]
        output: PathBuf,
        #[command(flatten)]
        read: ReadScene,
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
    Bench(Box<BenchArgs>),
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
    /// List the built-in scenes; with --stats, how heavy-tailed each one's
    /// light is (or the named scenes': built-in names, .toml files, datasets).
    Scenes {
        /// Render (or find in the cache) and measure: the median pixel's
        /// luminance over the mean, and the share of the light the brightest
        /// 1 % of pixels hold, of the noisy input and of the reference.
        #[arg(long)]
        stats: bool,
        /// Size of the renders measured (square), and their samples per pixel.
        #[arg(long, default_value_t = 64)]
        size: u32,
        #[arg(long, default_value_t = 4)]
        spp: u32,
        scenes: Vec<String>,
    },
    /// List the shipped filters: each one's pipeline, what it reads, where
    /// `filter` ranks it, its measured error on the public renders, its expression.
    List {
        /// One line a filter, the ones `filter` chooses first: name, pipeline, when it is chosen.
        #[arg(long)]
        brief: bool,
    },
    /// List the GPU adapters and say which one filterjit uses.
    Adapters,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum Preset {
    /// The search at work, in about a minute on a 2-core CPU with the scenes
    /// rendered: seeded with the hand-set cross-bilateral filter
    /// (`@crossBilateral`) in the tuned one's pipeline
    /// (`outliers=2,demodulate,atrous=5`) and scored against it
    /// (`--fitness-pool guarded`, the light charged), 4 islands of 20, 12
    /// generations, 2 elites, 64x64 scenes with 256-spp references (the
    /// shipped preset's renders), only what a Mitsuba or engine G-buffer
    /// holds. The test compares the best with the seed, the tuned
    /// cross-bilateral filter and the best shipped filter, each through its
    /// own pipeline; `--preset shipped` searches from that one.
    Start,
    /// Improve on the best shipped filter (`filter`'s default): seeded with it
    /// in its pipeline and scored against it (`--fitness-pool guarded`, 2
    /// elites, so the best is never worse than it on the training scenes; the
    /// light it moves charged, `--fitness-light 0.05`), 4
    /// islands of 12, 6 generations, expressions up to 150 nodes (the seed has
    /// 103), 64x64 scenes with 256-spp references, only what a Mitsuba or
    /// engine G-buffer holds plus the outlier rule's measures. About two minutes
    /// on a 2-core CPU with the first renders, a minute and a quarter once they are cached.
    Shipped,
    /// 4 islands of 25, 15 generations, 32x32 scenes, radius 3, the thesis's
    /// window and rules, seeded with `@bilateral`: minutes on a 2-core CPU.
    Quick,
    /// The thesis's settings: 4 islands of 100, 200 generations, 64x64 scenes, radius 10.
    Thesis,
    /// The run that made `@evolvedAtrous3x3`, for filters that hold up on real
    /// renders at a real-time cost: pipeline `outliers=2,demodulate,atrous3x3=4`,
    /// 128x128 scenes with 1024-spp references, seeded with `@svgfAtrous` and
    /// scored against it (`--fitness-pool guarded`), 4 islands of 40, 30
    /// generations, 2 elites, `--objectives error,cost` with the cost model
    /// measured on lavapipe, and only what a Mitsuba or engine G-buffer holds
    /// (colour, position, normal, albedo, depth, colour variance) plus the
    /// outlier rule's measures. About 9 minutes on a 2-core CPU once the scenes are rendered.
    Realtime,
    /// Improve on the best shipped temporal filter (`filter SEQ_DIR`'s
    /// default, `@temporal`) for sequences at one sample per pixel: the
    /// built-in training sequences (96x96, 1 spp, 256-spp references, each
    /// frame scored after the temporal stage), `@temporal`'s pipeline,
    /// seeded with it and scored against it (`--fitness-pool guarded`, 2
    /// elites, the light charged), 4 islands of 20, 10 generations,
    /// expressions up to 100 nodes, only what an engine's G-buffer holds plus
    /// the temporal stage's measures; the test compares the best with it on
    /// the built-in test sequence. About 11 minutes on a 2-core CPU with the
    /// first renders.
    Temporal,
}

/// Render settings and radius; unset ones come from `evolve`'s preset, or
/// for `report`/`tune` from `--run`'s checkpoint, else 64x64, 4 spp, 1024 spp
/// references, radius 5.
#[derive(clap::Args, Clone)]
pub(crate) struct RenderArgs {
    /// Size scenes are rendered at, WIDTHxHEIGHT.
    #[arg(long, value_parser = parse_size)]
    pub(crate) size: Option<(u32, u32)>,
    /// Samples per pixel of rendered noisy images.
    #[arg(long)]
    pub(crate) spp: Option<u32>,
    /// Samples per pixel of rendered references.
    #[arg(long)]
    pub(crate) reference_spp: Option<u32>,
    /// Filter window radius (the window form's).
    #[arg(long)]
    pub(crate) radius: Option<u32>,
    /// The filter pipeline around the expression: stages separated by commas,
    /// `outliers=K` (firefly pre-pass), `trim` (its rule without the brightest neighbour),
    /// `keep` (put back what it clamped, spread evenly) or `keep=surface` (along the normals and toward the light),
    /// `demodulate` (filter colour/albedo), for sequences the temporal stage `temporal=ALPHA` (with `feedback=K`,
    /// `clamp=G`, `antilag=K`), then the form, `window`, `atrous=PASSES` (5x5 taps a pass) or `atrous3x3=PASSES` (3x3),
    /// then `planefit=R`, `anchor=K` and `pixelfilter=S` (docs/SEMANTICS.md, "The pipeline") [evolve: the preset's
    /// (shipped: the best shipped filter's, quick, thesis: window; temporal: @temporal's without its `anchor`);
    /// report, tune: the run's, else window].
    #[arg(long)]
    pub(crate) pipeline: Option<filterjit::pipeline::FilterPipeline>,
}

/// How scenes are made and filtered, for `report` and `tune`; unset values
/// come from `--run`'s checkpoint, else the defaults shown.
#[derive(clap::Args, Clone)]
pub(crate) struct SceneArgs {
    #[command(flatten)]
    pub(crate) render: RenderArgs,
    /// Training scenes, for tuning the baseline [the run's, else the built-in training scenes].
    #[arg(long, value_delimiter = ',')]
    pub(crate) training_scenes: Vec<String>,
    /// An evolve run directory: its test and training scenes, render settings and radius are the defaults.
    #[arg(long)]
    pub(crate) run: Option<PathBuf>,
    /// Passes of coordinate descent over the sigmas.
    #[arg(long, default_value_t = 3)]
    pub(crate) sweeps: usize,
}

#[derive(clap::Args)]
pub(crate) struct ReportArgs {
    /// Expressions to report on: text, @name, or @FILE[:NAME]; with --run, the best of its hall of fame are added.
    pub(crate) exprs: Vec<String>,
    /// Scenes to report on: built-in names, .toml files or datasets [the run's test scenes, else the built-in test scenes].
    #[arg(long, value_delimiter = ',')]
    pub(crate) scenes: Vec<String>,
    /// How many of the hall of fame's best to include (with --run or --hall-of-fame).
    #[arg(long, default_value_t = 3)]
    pub(crate) top: usize,
    /// A hall-of-fame file (default with --run: its hall_of_fame.txt); also drawn as a feature-usage chart.
    #[arg(long)]
    pub(crate) hall_of_fame: Option<PathBuf>,
    /// Use this expression as the cross-bilateral baseline instead of tuning one.
    #[arg(long)]
    pub(crate) baseline: Option<String>,
    #[command(flatten)]
    pub(crate) scene: SceneArgs,
    /// Timed dispatches per filter and scene, after a warm-up.
    #[arg(long, default_value_t = 5)]
    pub(crate) repeats: usize,
    /// Side of the square image crops, pixels.
    #[arg(long, default_value_t = 48)]
    pub(crate) crop: usize,
    /// Filters are timed on each scene tiled to at least this many pixels per side.
    #[arg(long, default_value_t = 256)]
    pub(crate) timing_size: usize,
    /// The report folder.
    #[arg(short, long, default_value = "runs/report")]
    pub(crate) output: PathBuf,
    /// Leave out Intel Open Image Denoise even where its `oidnDenoise` is found
    /// (FILTERJIT_OIDN, PATH, or the pyoidn Python package).
    #[arg(long)]
    pub(crate) no_oidn: bool,
    /// Report on a sequence's folder of frames instead of scenes: the filters
    /// (default: the shipped temporal ones) over every frame in order, beside
    /// the noisy input and OIDN on each frame; per frame and for the
    /// sequence relMSE, light, HDR-FLIP and flicker, plots over the frames,
    /// an animated comparison.
    #[arg(long, value_name = "SEQ_DIR")]
    pub(crate) sequence: Option<PathBuf>,
}

#[derive(clap::Args)]
pub(crate) struct BenchArgs {
    /// Size of the benchmark scene (a render of glossy-floor).
    #[arg(long, default_value = "64x64", value_parser = parse_size)]
    pub(crate) size: (u32, u32),
    #[arg(long, default_value_t = 5)]
    pub(crate) radius: u32,
    /// Repeats of every timing.
    #[arg(long, default_value_t = 5)]
    pub(crate) repeats: usize,
    /// Individuals compiled together for the amortised compile cost, and in the generation.
    #[arg(long, default_value_t = 400)]
    pub(crate) population: usize,
    /// Expression lengths of the corpus (two random expressions each).
    #[arg(long, value_delimiter = ',', default_value = "5,10,20,40,75,100,150")]
    pub(crate) lengths: Vec<usize>,
    /// Square sizes of the one-generation measurement; the flag without values skips it.
    #[arg(long, value_delimiter = ',', num_args = 0.., default_value = "64,128,256")]
    pub(crate) generation_sizes: Vec<u32>,
    #[arg(long, default_value_t = 10)]
    pub(crate) generation_radius: u32,
    /// Individuals per fitness kernel, as `evolve --fuse` (auto: 12 on software adapters, 1 on hardware).
    #[arg(long, default_value = "auto")]
    pub(crate) fuse: filterjit::fitness::Fusion,
    #[arg(short, long, default_value = "bench.json")]
    pub(crate) output: PathBuf,
    /// Leave out Intel Open Image Denoise's whole-frame time even where its
    /// `oidnDenoise` is found (FILTERJIT_OIDN, PATH, or the pyoidn Python package).
    #[arg(long)]
    pub(crate) no_oidn: bool,
    /// Whole frames only, at these sizes (e.g. `256x256,1920x1080`): `filter`'s
    /// default, `@evolvedAtrous3x3`, the best temporal filter and OIDN, on
    /// a 256² render of glossy-floor tiled to each size; `bench.json` gets their `frames`.
    #[arg(long, value_delimiter = ',', value_parser = parse_size)]
    pub(crate) frames: Vec<(u32, u32)>,
    /// With --frames: time this filter instead of the default three (repeat
    /// the flag for more): @name, @FILE[:NAME] or an expression, each in the
    /// pipeline stored with it (else `filter`'s default pipeline).
    #[arg(long = "filter")]
    pub(crate) filters: Vec<String>,
    /// With --frames: also time each filter's kernels pass by pass on the
    /// device's clock (three more frames each), and print where each frame goes.
    #[arg(long)]
    pub(crate) profile: bool,
}

#[derive(clap::Args)]
pub(crate) struct TuneArgs {
    #[command(flatten)]
    pub(crate) scene: SceneArgs,
    /// Also write the result as a `name = expression` file (readable with @FILE).
    #[arg(short, long)]
    pub(crate) output: Option<PathBuf>,
    /// Tune every literal of this expression (its form kept; `@NAME` of a
    /// shipped one, e.g. `@svgfAtrous`) instead of the cross-bilateral's sigmas.
    #[arg(long, value_name = "EXPR")]
    pub(crate) expr: Option<String>,
    /// Charge each training scene's error for the light the filter moves, as
    /// `evolve --fitness-light` does [off].
    #[arg(long, value_name = "TOL|off")]
    pub(crate) fitness_light: Option<LightTolerance>,
}

/// Raw `evolve` flags; unset ones take the preset's values.
#[derive(clap::Args)]
pub(crate) struct EvolveArgs {
    /// Values for every flag not given.
    #[arg(long, value_enum, default_value_t = Preset::Start)]
    pub(crate) preset: Preset,
    /// Training scenes: built-in names, .toml files, dataset directories, or folders whose subfolders are datasets (each is a scene) [default: the built-in training scenes].
    #[arg(long, value_delimiter = ',')]
    pub(crate) scenes: Vec<String>,
    /// Test scenes, likewise [default: the built-in test scenes].
    #[arg(long, value_delimiter = ',')]
    pub(crate) test_scenes: Vec<String>,
    #[command(flatten)]
    pub(crate) render: RenderArgs,
    /// The expression the population is seeded from [shipped: the best shipped filter, @evolvedAtrous64Plane; quick, thesis: @bilateral; realtime: @svgfAtrous; temporal: the best shipped temporal filter, @temporal].
    #[arg(long)]
    pub(crate) seed_expr: Option<String>,
    /// Number of islands [every preset: 4].
    #[arg(long)]
    pub(crate) islands: Option<usize>,
    /// Individuals per island [shipped: 12, quick: 25, thesis: 100, realtime: 40, temporal: 20].
    #[arg(long)]
    pub(crate) island_size: Option<usize>,
    /// Generations to run: the stopping rule [shipped: 6, quick: 15, thesis: 200, realtime: 30, temporal: 10].
    #[arg(long)]
    pub(crate) generations: Option<u32>,
    /// Longest expression, in nodes [shipped: 150; temporal: 100; quick, thesis, realtime: 75, the thesis's].
    #[arg(long)]
    pub(crate) max_length: Option<usize>,
    /// Tournament size [8].
    #[arg(long)]
    pub(crate) tournament: Option<usize>,
    /// Share of each generation copied unchanged.
    #[arg(long)]
    pub(crate) replication: Option<f64>,
    /// Share made by crossover (the rest by mutation).
    #[arg(long)]
    pub(crate) crossover: Option<f64>,
    /// Probability that a crossover child is mutated.
    #[arg(long)]
    pub(crate) crossover_mutation: Option<f64>,
    /// Weights of the mutations insert,replace,swap,delete.
    #[arg(long, value_delimiter = ',')]
    pub(crate) mutation_weights: Option<Vec<f64>>,
    /// Generations between migrations.
    #[arg(long)]
    pub(crate) migration_interval: Option<u32>,
    /// Share of each initial island that is the seed itself.
    #[arg(long)]
    pub(crate) seed_share: Option<f64>,
    /// Expressions per island in the hall of fame.
    #[arg(long)]
    pub(crate) hall_of_fame: Option<usize>,
    /// Random seed of the search (and of rendering).
    #[arg(long)]
    pub(crate) seed: Option<u64>,
    /// Simplify every new individual before it is evaluated (the same
    /// weights, shorter trees; docs/JOURNAL.md measures the effect).
    #[arg(long)]
    pub(crate) simplify_offspring: bool,
    /// What the search minimises: `error` (the thesis) or `error,cost`:
    /// NSGA-II over error and the modelled cost per pixel (src/cost.rs); the
    /// run's result is a front of filters, fast to accurate (pareto.json)
    /// [shipped, quick, thesis, temporal: error; realtime: error,cost].
    #[arg(long)]
    pub(crate) objectives: Option<filterjit::gp::Objectives>,
    /// With `--objectives error,cost`: how many islands (the first) keep
    /// minimising error alone at the run's radius, feeding the front's
    /// accurate end through migration [default: all but one, as measured in
    /// docs/JOURNAL.md].
    #[arg(long)]
    pub(crate) error_islands: Option<usize>,
    /// The best N of each island pass to the next generation unchanged, so
    /// that the best filter found is never lost to tournament chance
    /// [quick, thesis: 0, the thesis's search, which can lose it; shipped, realtime: 2].
    #[arg(long)]
    pub(crate) elites: Option<usize>,
    /// Run directory: checkpoint, log, hall of fame, summary [default: runs/evolve, or
    /// runs/evolve-2, -3, … when it holds a run already; with --resume the newest of them].
    #[arg(short, long)]
    pub(crate) output: Option<PathBuf>,
    /// Continue the run in --output from its last checkpoint.
    #[arg(long)]
    pub(crate) resume: bool,
    /// Threads that compile kernels [default: the number of cores].
    #[arg(long)]
    pub(crate) threads: Option<usize>,
    /// Filters to compare with on the test scenes at the end (repeatable), a shipped one through its own pipeline [start: @crossBilateralTuned and the best shipped filter; temporal: none, the seed is compared; others: @crossBilateral].
    #[arg(long)]
    pub(crate) baseline: Vec<String>,
    /// Stage fitness kernels' windows in workgroup memory: auto = on hardware GPUs, off on software adapters (same results either way).
    #[arg(long, value_enum, default_value_t = filterjit::fitness::Tiles::Auto)]
    pub(crate) tiles: filterjit::fitness::Tiles,
    /// The weights of the modelled cost that `--objectives error,cost` trades
    /// against error, as `filterjit bench` measured them on this device
    /// (its `bench.json`, or a file holding just its `cost_model`) [shipped, quick,
    /// thesis: the operator table's; realtime: data/cost-model-lavapipe.json]. Kept in the run's checkpoint.
    #[arg(long, value_name = "FILE")]
    pub(crate) cost_model: Option<PathBuf>,
    /// Score fitness on COUNT tiles of SIZExSIZE pixels per training scene
    /// (e.g. `8x32`), each with the halo the pipeline reads, drawn once from
    /// the seed, instead of on whole images: a generation on 256x256 renders
    /// then costs about what one on small scenes does. The hall of fame is
    /// scored on whole images at the end [default: whole images].
    #[arg(long, value_name = "COUNTxSIZE")]
    pub(crate) fitness_tiles: Option<filterjit::fitness::TileSampling>,
    /// The only features and variances the search may read, e.g.
    /// `color,pixel,normal,texture,worldPosition,depth` for filters meant for
    /// Mitsuba renders (no direct illumination, secondary albedo or per-feature
    /// variances) [quick, thesis: every one the training scenes provide; shipped, realtime:
    /// color,pixel,normal,texture,worldPosition,depth,colorVariance and the outlier measures]. Kept in the checkpoint.
    #[arg(long, value_delimiter = ',', value_parser = parse_terminal)]
    pub(crate) features: Vec<String>,
    /// Divide each training scene's relMSE by this filter's relMSE on it
    /// (an expression, `@NAME` or `@FILE:NAME`; scored once, through the run's
    /// pipeline, on the same pixels) instead of by the noisy input's: fitness 1
    /// is the baseline's [quick, thesis: the noisy input, the thesis's rule; shipped: the seed; realtime: @svgfAtrous]. Kept in the checkpoint.
    #[arg(long, value_name = "EXPR")]
    pub(crate) fitness_relative_to: Option<String>,
    /// Pool the per-scene ratios by their mean, by the worst scene (with
    /// `--fitness-relative-to`, a fitness below 1 is then better than the
    /// baseline on every training scene), or `guarded`: the mean plus every
    /// scene's loss against the baseline in full [quick, thesis: mean;
    /// shipped, realtime: guarded]. Kept in the checkpoint.
    #[arg(long, value_name = "mean|worst|guarded")]
    pub(crate) fitness_pool: Option<filterjit::fitness::Pool>,
    /// Charge each training scene's error for the light the filter moves:
    /// relMSE × (1 + (ln(light) / TOL)²), light being the output's mean
    /// luminance over the noisy input's on the scored pixels (0.05: a 5 %
    /// loss doubles a scene's error), or `off` for relMSE alone [shipped: 0.05;
    /// quick, thesis, realtime: off; docs/JOURNAL.md, "Fitness that charges the light"].
    /// Kept in the checkpoint.
    #[arg(long, value_name = "TOL|off")]
    pub(crate) fitness_light: Option<LightTolerance>,
    /// Individuals per fitness kernel: auto = 12 on software adapters (their compile cost is per module), 1 on hardware GPUs; a number forces it (same results either way).
    #[arg(long, default_value = "auto")]
    pub(crate) fuse: filterjit::fitness::Fusion,
    /// Share the islands among the ranks of the MPI job this process was
    /// started in (`mpirun -n 4 filterjit evolve --mpi …`; a filterjit built
    /// with `--features mpi`; docs/DISTRIBUTED.md). Same seed, same result as one process.
    #[arg(long)]
    pub(crate) mpi: bool,
}

/// A feature's or a variance's name, as expressions write it.
pub(crate) fn parse_terminal(text: &str) -> Result<String, String> {
    if lang::Feature::from_name(text).is_some() || lang::ScalarVar::from_name(text).is_some() {
        return Ok(text.to_string());
    }
    let features = lang::Feature::ALL.iter().map(|f| f.name());
    let variances = lang::ScalarVar::ALL.iter().filter(|v| v.is_stored()).map(|v| v.name());
    let names: Vec<&str> = features.chain(variances).collect();
    Err(format!("`{text}` is no feature or variance; they are {}", names.join(", ")))
}

pub(crate) fn parse_size(text: &str) -> Result<(u32, u32), String> {
    // `64x64`, `64X64` and `64×64` alike.
    let (w, h) = text.split_once(['x', 'X', '×']).ok_or_else(|| format!("`{text}` is not WIDTHxHEIGHT"))?;
    let parse = |v: &str| v.trim().parse::<u32>().map_err(|_| format!("`{text}` is not WIDTHxHEIGHT"));
    let (w, h) = (parse(w)?, parse(h)?);
    if w == 0 || h == 0 {
        return Err(format!("`{text}`: the size must be at least 1x1"));
    }
    Ok((w, h))
}

/// `--fitness-light`: a positive tolerance, or `off`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct LightTolerance(pub(crate) Option<f64>);

impl std::str::FromStr for LightTolerance {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        if s == "off" {
            return Ok(LightTolerance(None));
        }
        match s.parse::<f64>() {
            Ok(t) if t.is_finite() && t > 0.0 => Ok(LightTolerance(Some(t))),
            _ => Err(format!("`{s}` is neither a positive tolerance (e.g. 0.05) nor `off`")),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::parse_size;

    #[test]
    fn a_size_is_width_by_height_however_the_by_is_written() {
        for text in ["64x48", "64X48", "64×48", "64 x 48"] {
            assert_eq!(parse_size(text), Ok((64, 48)), "{text}");
        }
        assert!(parse_size("64").unwrap_err().contains("not WIDTHxHEIGHT"));
        assert!(parse_size("0x4").unwrap_err().contains("at least 1x1"));
    }
}
