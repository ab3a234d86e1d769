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
    // `temp_dir()` reads TMPDIR: the edge's `Environment::scratch` says where temporary files go.
    let temp_dir_readers: Vec<String> = sources()
        .into_iter()
        .filter(|(_, text)| code_of(text).iter().any(|l| l.contains("temp_dir()")))
        .map(|(path, _)| path)
        .collect();
    assert!(temp_dir_readers.is_empty(), "outside tests, {temp_dir_readers:?} read TMPDIR through temp_dir()");
}

#[test]
fn tests_write_under_the_target_folder_not_the_systems_temporary_folder() {
    // A run writes some 150 MB; `common::temp_dir` keeps it in `target/tmp` and
    // removes ended runs' files, which a direct `std::env::temp_dir()` would not.
    let tests = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests");
    let mut writers = Vec::new();
    for dir in [tests.clone(), tests.join("common")] {
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().is_none_or(|e| e != "rs") {
                continue;
            }
            let text = std::fs::read_to_string(&path).unwrap();
            if code_of(&text).iter().any(|l| l.contains(concat!("env::", "temp_dir("))) {
                writers.push(path.strip_prefix(&tests).unwrap().display().to_string());
            }
        }
    }
    assert!(writers.is_empty(), "{writers:?} write into the system's temporary folder: use common::temp_dir");
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

/// A file's code without its comments and without its `#[cfg(test)]`
/// module (tests may reach anything they check).
fn code_of(text: &str) -> Vec<&str> {
    let mut lines = Vec::new();
    let mut previous = "";
    for line in text.lines() {
        let trimmed = line.trim_start();
        if previous == "#[cfg(test)]" && trimmed.starts_with("mod ") {
            lines.pop();
            break;
        }
        previous = trimmed;
        if !trimmed.starts_with("//") {
            lines.push(line);
        }
    }
    lines
}

/// The names a line reaches through `prefix` (`crate::`, `super::`):
/// `prefix name` and each name of `prefix {a, b::c}`.
fn reached(line: &str, prefix: &str) -> Vec<String> {
    let mut names = Vec::new();
    let mut rest = line;
    while let Some(at) = rest.find(prefix) {
        // `crate::` inside `filterjit::crate::` cannot occur; `super::` inside `super::super::` is the outer one.
        rest = &rest[at + prefix.len()..];
        if let Some(group) = rest.strip_prefix('{') {
            let inner = &group[..group.find('}').unwrap_or(group.len())];
            for item in inner.split(',') {
                let name: String = item.trim().chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect();
                if !name.is_empty() {
                    names.push(name);
                }
            }
        } else {
            let name: String = rest.chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect();
            if !name.is_empty() {
                names.push(name);
            }
        }
    }
    names
}

/// ARCHITECTURE.md's layer table: each top-level module and its layer (0 lowest).
fn layers() -> std::collections::BTreeMap<String, usize> {
    let text = std::fs::read_to_string(PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("ARCHITECTURE.md")).unwrap();
    let section = text.split("\n## Layers").nth(1).expect("ARCHITECTURE.md has a `## Layers` section");
    let section = section.split("\n## ").next().unwrap();
    let mut out = std::collections::BTreeMap::new();
    for row in section.lines().filter(|l| l.starts_with("| ")) {
        let cells: Vec<&str> = row.split('|').map(str::trim).collect();
        let Ok(layer) = cells[1].parse::<usize>() else { continue };
        for module in cells[3].split(',') {
            let module = module.trim().trim_matches('`');
            assert!(out.insert(module.to_string(), layer).is_none(), "`{module}` is in two layers");
        }
    }
    out
}

/// The top-level modules `lib.rs` declares.
fn top_level_modules() -> Vec<String> {
    let lib = sources().into_iter().find(|(p, _)| p == "lib.rs").unwrap().1;
    lib.lines().filter_map(|l| l.strip_prefix("pub mod ")).map(|l| l.trim_end_matches(';').to_string()).collect()
}

/// Which top-level modules each top-level module names (`crate::x`).
fn module_graph() -> std::collections::BTreeMap<String, std::collections::BTreeSet<String>> {
    let modules = top_level_modules();
    let mut graph: std::collections::BTreeMap<String, std::collections::BTreeSet<String>> =
        modules.iter().map(|m| (m.clone(), Default::default())).collect();
    for (path, text) in sources() {
        let owner = path.split('/').next().unwrap().trim_end_matches(".rs").to_string();
        if !modules.contains(&owner) {
            continue; // lib.rs, main.rs and the binary's cli/
        }
        for line in code_of(&text) {
            for name in reached(line, "crate::") {
                assert!(
                    modules.contains(&name),
                    "src/{path} names `crate::{name}`: name items by their module, not by the crate root's re-exports"
                );
                if name != owner {
                    graph.get_mut(&owner).unwrap().insert(name);
                }
            }
        }
    }
    graph
}

/// A cycle in `graph`, if it has one.
fn cycle(graph: &std::collections::BTreeMap<String, std::collections::BTreeSet<String>>) -> Option<Vec<String>> {
    fn visit(
        node: &str,
        graph: &std::collections::BTreeMap<String, std::collections::BTreeSet<String>>,
        state: &mut std::collections::BTreeMap<String, u8>,
        path: &mut Vec<String>,
    ) -> Option<Vec<String>> {
        match state.get(node) {
            Some(2) => return None,
            Some(1) => {
                let start = path.iter().position(|n| n == node).unwrap();
                let mut found = path[start..].to_vec();
                found.push(node.to_string());
                return Some(found);
            }
            _ => {}
        }
        state.insert(node.to_string(), 1);
        path.push(node.to_string());
        for next in graph.get(node).into_iter().flatten() {
            if let Some(found) = visit(next, graph, state, path) {
                return Some(found);
            }
        }
        path.pop();
        state.insert(node.to_string(), 2);
        None
    }
    let mut state = Default::default();
    graph.keys().find_map(|node| visit(node, graph, &mut state, &mut Vec::new()))
}

#[test]
fn every_module_has_a_layer_and_imports_go_down() {
    let layers = layers();
    let modules = top_level_modules();
    for module in &modules {
        assert!(layers.contains_key(module), "src/{module} is in no layer of ARCHITECTURE.md's table");
    }
    for module in layers.keys() {
        assert!(
            modules.contains(module) || module == "cli",
            "ARCHITECTURE.md's layers name `{module}`, which lib.rs does not declare"
        );
    }
    let graph = module_graph();
    let mut upward = Vec::new();
    for (from, names) in &graph {
        for to in names {
            if layers[to] > layers[from] {
                upward.push(format!("{from} (layer {}) → {to} (layer {})", layers[from], layers[to]));
            }
        }
    }
    assert!(upward.is_empty(), "imports that go up the layer table:\n{}", upward.join("\n"));
    assert_eq!(cycle(&graph), None, "a cycle between top-level modules");
}

/// Which files of the folder `dir` (relative to `src/`, without a
/// trailing slash) each of its files names: `super::x` and `crate::dir::x`,
/// where `x` is a sibling file or folder, or an item its `mod.rs`
/// re-exports (`pub use file::{…}`), counted as that file's. A subfolder
/// is one node.
fn folder_graph(dir: &str) -> std::collections::BTreeMap<String, std::collections::BTreeSet<String>> {
    let prefix = format!("{dir}/");
    let files: Vec<(String, String, bool)> = sources()
        .into_iter()
        .filter_map(|(p, t)| {
            let rest = p.strip_prefix(&prefix)?.to_string();
            let direct = !rest.contains('/');
            let node = rest.split('/').next().unwrap().trim_end_matches(".rs").to_string();
            Some((node, t, direct))
        })
        .collect();
    let siblings: std::collections::BTreeSet<String> =
        files.iter().map(|(n, _, _)| n.clone()).filter(|n| n != "mod").collect();
    let mut defined_in = std::collections::BTreeMap::new();
    if let Some((_, facade, _)) = files.iter().find(|(n, _, direct)| n == "mod" && *direct) {
        for line in facade.lines().filter_map(|l| l.trim().strip_prefix("pub use ")) {
            let Some((file, items)) = line.split_once("::") else { continue };
            for item in items.trim_matches(|c| "{};".contains(c)).split(',') {
                defined_in.insert(item.trim().to_string(), file.to_string());
            }
        }
    }
    let through_crate = format!("crate::{}::", dir.replace('/', "::"));
    let mut graph: std::collections::BTreeMap<String, std::collections::BTreeSet<String>> = Default::default();
    for (node, text, direct) in files.iter().filter(|(n, _, _)| n != "mod") {
        let edges = graph.entry(node.clone()).or_default();
        for line in code_of(text) {
            // `super::` in a subfolder's file is that subfolder: only `crate::dir::` leaves it.
            let supers = if *direct { reached(line, "super::") } else { Vec::new() };
            for name in supers.into_iter().chain(reached(line, &through_crate)) {
                let target = if siblings.contains(&name) { Some(name) } else { defined_in.get(&name).cloned() };
                if let Some(target) = target.filter(|t| t != node) {
                    edges.insert(target);
                }
            }
        }
    }
    graph
}

/// No folder's files import each other round in a circle (a cycle inside a
/// folder is a cycle between two things that should have been one, or one
/// thing that should have been two).
#[test]
fn no_folder_has_an_import_cycle() {
    let mut folders: std::collections::BTreeSet<String> =
        sources().into_iter().filter_map(|(p, _)| Some(p.rsplit_once('/')?.0.to_string())).collect();
    folders.insert("jit".into());
    assert!(folders.contains("gpu") && folders.contains("export"), "{folders:?}");
    for dir in folders {
        let graph = folder_graph(&dir);
        assert_eq!(cycle(&graph), None, "a cycle between files of src/{dir}: {graph:?}");
    }
}

/// No source file holds more than 600 lines of code before its tests
/// (blank and comment lines not counted): a file does one thing.
#[test]
fn no_file_holds_more_than_600_lines_of_code() {
    for (path, text) in sources() {
        let before_tests = text.split("\n#[cfg(test)]").next().unwrap();
        let lines = code_of(before_tests).len();
        assert!(lines <= 600, "src/{path} has {lines} lines of code before its tests (at most 600)");
    }
}

/// Files that each do one thing stay small enough to read: the search's and
/// the scorer's files, and the lowering, by their non-test lines.
#[test]
fn the_search_the_scorer_and_the_lowering_stay_small() {
    for (path, text) in sources() {
        let lines = code_of(&text).len();
        let limit = match path.as_str() {
            "jit/lower.rs" => 500,
            p if p.starts_with("evolve/") || p.starts_with("fitness/") || p.starts_with("bench/") => 400,
            _ => continue,
        };
        assert!(lines <= limit, "src/{path} has {lines} non-test lines (at most {limit})");
    }
}
