//! ARCHITECTURE.md's invariants that a reading of the source can check.

use std::path::{Path, PathBuf};

/// Every `.rs` file under `src/`, with its path relative to `src/` and its text.
fn sources() -> Vec<(String, String)> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                walk(&path, out);
            } else if path.extension().is_some_and(|e| e == "rs") {
                out.push(path);
            }
        }
    }
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    walk(&root, &mut files);
    files.sort();
    files
        .into_iter()
        .map(|p| {
            let text = std::fs::read_to_string(&p).unwrap();
            (p.strip_prefix(&root).unwrap().display().to_string(), text)
        })
        .collect()
}

/// The files (relative to `src/`) whose code, comments aside, contains `needle`.
fn files_with(needle: &str) -> Vec<String> {
    sources()
        .into_iter()
        .filter(|(_, text)| text.lines().any(|l| !l.trim_start().starts_with("//") && l.contains(needle)))
        .map(|(path, _)| path)
        .collect()
}

#[test]
fn only_the_edge_reads_or_sets_the_environment() {
    let mut readers = files_with("env::var");
    readers.extend(files_with("env::set_var"));
    readers.sort();
    readers.dedup();
    assert_eq!(readers, ["environment.rs", "main.rs"], "the library reads no environment variable");
}

#[test]
fn naga_validates_in_one_place_and_no_pipeline_infers_its_layout() {
    assert_eq!(files_with("Validator::new"), ["jit/validate.rs"]);
    // `scene/mod.rs` has a `layout: None` of its own: a scene's renderer layout, not wgpu's.
    let inferring: Vec<String> = files_with("layout: None").into_iter().filter(|f| f.starts_with("gpu/")).collect();
    assert!(inferring.is_empty(), "{inferring:?}");
}

#[test]
fn lang_holds_no_wgsl() {
    for (path, text) in sources().into_iter().filter(|(p, _)| p.starts_with("lang/")) {
        for marker in ["fj_", "@group", "@binding", "var<", "vec3<f32>", "array<"] {
            assert!(!text.contains(marker), "src/{path} mentions `{marker}`");
        }
    }
}

/// filterjit's own modules read their parameters from a read-only storage
/// buffer; only exported shaders bind a uniform (lavapipe recompiles a
/// shader whose uniform values steer its control flow at every dispatch).
#[test]
fn only_exported_shaders_bind_a_uniform() {
    assert_eq!(files_with("BufferUsages::UNIFORM"), ["gpu/mod.rs"], "params buffers are made by Gpu::params_buffer");
    let templates = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("templates");
    for entry in std::fs::read_dir(&templates).unwrap() {
        let path = entry.unwrap().path();
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(!text.contains("var<uniform>"), "{} declares a uniform of its own", path.display());
    }
    use filterjit::jit::interface::{BindingInterface, Resource};
    assert_eq!(BindingInterface::prepass(None).params(), Resource::ParamsStorage);
    assert_eq!(BindingInterface::prepass(Some(filterjit::jit::OutputFormat::Rgba16float)).params(), Resource::Uniform);
}

#[test]
fn the_python_binding_is_thin() {
    // python/src/lib.rs turns arrays into `scene::Images` and calls the
    // library; it reaches no device, compiler or file format of its own, so
    // `denoise` and `filterjit filter` cannot drift apart.
    let binding = std::fs::read_to_string(PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("python/src/lib.rs")).unwrap();
    for needle in ["wgpu::", "naga::", "exr::", "std::fs", "jit::lower", "SceneBuffers"] {
        let lines: Vec<&str> =
            binding.lines().filter(|l| !l.trim_start().starts_with("//") && l.contains(needle)).collect();
        assert!(lines.is_empty(), "python/src/lib.rs uses `{needle}`: {lines:?}");
    }
    assert!(binding.contains("scene::prepare(") && binding.contains("filterjit::denoise::filter("));
}
