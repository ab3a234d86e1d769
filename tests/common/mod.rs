//! Shared test helpers: one GPU for the whole binary, synthetic scenes, the Mitsuba sample.

pub mod browser;

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use parking_lot::{ReentrantMutex, ReentrantMutexGuard};

use filterjit::gpu::Gpu;
use filterjit::lang::{Feature, ScalarVar};
use filterjit::rng::Rng;
use filterjit::Scene;

/// The `(name, expression)` entries of a named-expression file the tests
/// hold for their whole run (`tests/data/corpus.txt`), aliases followed.
pub fn named_entries(text: &'static str) -> Vec<(&'static str, &'static str)> {
    let file: &'static filterjit::named::NamedFile =
        Box::leak(Box::new(filterjit::named::NamedFile::parse(text).expect("the test corpus reads")));
    file.resolved()
}

/// The device every GPU test shares, held for as long as the returned value
/// lives. Call it first in a test (`let gpu = gpu();`) so the turn covers the
/// whole test, drops of its buffers included.
///
/// On GL the tests take turns: wgpu's GL backend keeps one context per device
/// and holds it for a whole dispatch or program link (on llvmpipe: the driver's
/// compile), and a thread that waits for it longer than a few seconds panics
/// ("Could not lock adapter context"). Whether a test passes must not depend on
/// how fast the driver compiles, so GPU tests run one at a time on GL and in
/// parallel elsewhere. The lock is re-entrant, so helpers may call `gpu()` too.
///
/// There is no skipping: without an adapter the GPU tests fail, saying what to install.
pub fn gpu() -> GpuTurn {
    static GPU: OnceLock<Gpu> = OnceLock::new();
    static GL_TESTS: ReentrantMutex<()> = ReentrantMutex::new(());
    let gpu = GPU.get_or_init(|| {
        // As the binary does: Mesa's Vulkan device-select layer probes for a display
        // and prints warnings without one. std's environment lock guards this write.
        if std::env::var_os("NODEVICE_SELECT").is_none() {
            std::env::set_var("NODEVICE_SELECT", "1");
        }
        open()
    });
    let turn = (gpu.info().backend == wgpu::Backend::Gl).then(|| GL_TESTS.lock());
    GpuTurn { gpu, _turn: turn }
}

/// The shared test device and, on GL, this test's turn on it.
pub struct GpuTurn {
    gpu: &'static Gpu,
    _turn: Option<ReentrantMutexGuard<'static, ()>>,
}

impl std::ops::Deref for GpuTurn {
    type Target = Gpu;
    fn deref(&self) -> &Gpu {
        self.gpu
    }
}

/// The environment as the tests' edge reads it, once.
pub fn environment() -> &'static filterjit::environment::Environment {
    static ENV: std::sync::OnceLock<filterjit::environment::Environment> = std::sync::OnceLock::new();
    ENV.get_or_init(|| filterjit::environment::Environment::read().expect("FILTERJIT_BACKEND names a backend"))
}

fn open() -> Gpu {
    match Gpu::open(&environment().adapter) {
        Ok(gpu) => {
            eprintln!("GPU tests run on {}", gpu.describe());
            gpu
        }
        Err(e) => panic!("GPU tests need an adapter: {e}"),
    }
}

/// The Mitsuba render shipped in `scenes/` (tests read only what the repository holds).
pub fn mitsuba_sample() -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scenes/mitsuba-cornell-64");
    assert!(dir.join("noisy.exr").is_file(), "the Mitsuba sample is missing at {}", dir.display());
    dir
}

/// An empty directory for one test: `area` and `name` keep tests apart.
///
/// It lies in this run's folder under Cargo's scratch folder for integration
/// tests (`target/tmp/filterjit-tests/PID`), never the system's temporary
/// folder: a run writes some 150 MB, and a run that failed keeps its files to
/// be looked at. So nothing piles up, the first call of a run removes the
/// folders of runs that have ended.
pub fn temp_dir(area: &str, name: &str) -> PathBuf {
    let dir = this_run_scratch().join(format!("{area}-{name}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("temporary directory");
    dir
}

/// This process's folder of test directories; the folders of ended runs are
/// removed the first time it is asked for.
fn this_run_scratch() -> &'static Path {
    static RUN: OnceLock<PathBuf> = OnceLock::new();
    RUN.get_or_init(|| {
        let root = Path::new(env!("CARGO_TARGET_TMPDIR")).join("filterjit-tests");
        let this = std::process::id();
        for entry in std::fs::read_dir(&root).into_iter().flatten().flatten() {
            let pid = entry.file_name().to_str().and_then(|name| name.parse::<u32>().ok());
            if pid.is_some_and(|pid| pid != this && !may_be_running(pid)) {
                let _ = std::fs::remove_dir_all(entry.path());
            }
        }
        root.join(this.to_string())
    })
}

/// Whether process `pid` may still be running. Linux says so in `/proc`;
/// where there is no `/proc`, every process may be, and no run's files go.
fn may_be_running(pid: u32) -> bool {
    let proc = Path::new("/proc");
    !proc.join("self").exists() || proc.join(pid.to_string()).exists()
}

/// Limits read from the environment so CI can shrink or grow a run.
pub fn env_usize(name: &str, default: usize) -> usize {
    std::env::var(name).ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}

/// A synthetic scene with every feature and variance: smooth regions with
/// edges, noisy colour, some strong outliers. Values are already normalised.
pub fn synthetic_scene(width: usize, height: usize, seed: u64) -> Scene {
    let mut rng = Rng::seeded(seed);
    let n = width * height;
    let region = |x: usize, y: usize| usize::from(x * 2 >= width) + 2 * usize::from(y * 3 >= height);
    let mut reference = Vec::with_capacity(n);
    let mut color = Vec::with_capacity(n);
    for y in 0..height {
        for x in 0..width {
            let r = region(x, y) as f32;
            let base = [0.2 + 0.2 * r, 0.1 + 0.05 * r, 0.5 - 0.1 * r];
            reference.push(base);
            let noise = |rng: &mut Rng| (rng.unit() as f32 - 0.5) * 0.6;
            let mut c = [base[0] + noise(&mut rng), base[1] + noise(&mut rng), base[2] + noise(&mut rng)];
            if rng.chance(0.02) {
                c = c.map(|v| v.abs() * 50.0); // a firefly
            }
            color.push(c.map(|v| v.max(0.0)));
        }
    }
    let mut scene = Scene::from_color(format!("synthetic-{width}x{height}-{seed}"), width, height, color);
    scene.reference = Some(reference);
    scene.spp = Some(4);
    for f in Feature::ALL {
        if !f.needs_data() || *f == Feature::Color {
            continue;
        }
        let dim = f.dimension();
        let data: Vec<[f32; 3]> = (0..n)
            .map(|p| {
                let (x, y) = (p % width, p / width);
                let r = region(x, y) as f32;
                let mut v = [0f32; 3];
                for (c, value) in v.iter_mut().enumerate().take(dim) {
                    let smooth = ((x as f32 * 0.3 + c as f32).sin() * 0.1 + r * 0.25 - 0.3 + y as f32 * 0.01)
                        * (1.0 + *f as usize as f32 * 0.05);
                    *value = (smooth + (rng.unit() as f32 - 0.5) * 0.02).clamp(-1.0, 1.0);
                }
                v
            })
            .collect();
        scene.features.insert(*f, data);
    }
    for v in ScalarVar::ALL {
        scene.variances.insert(*v, (0..n).map(|_| (rng.unit() as f32).powi(3)).collect());
    }
    scene
}

/// Fraction of channels of a GPU image within 1e-3 relative (+0.01 absolute in
/// the denominator) of the CPU reference's, and the worst difference.
pub fn agree_fraction(gpu_rgb: &[[f32; 3]], cpu_rgb: &[[f64; 3]]) -> (f64, f64) {
    let mut within = 0usize;
    let mut worst = 0.0f64;
    for (g, c) in gpu_rgb.iter().zip(cpu_rgb) {
        for q in 0..3 {
            assert!(g[q].is_finite(), "GPU output is not finite");
            let err = (g[q] as f64 - c[q]).abs() / (c[q].abs() + 0.01);
            worst = worst.max(err);
            within += usize::from(err <= 1e-3);
        }
    }
    (within as f64 / (3 * gpu_rgb.len()) as f64, worst)
}
