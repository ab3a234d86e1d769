//! The README and the docs it links say only what is true today: every
//! shipped name they give exists, the defaults the README's table names are
//! `filter`'s, with the pipelines they are stored with, the built-in scenes
//! its commands render exist, and every page it links is there.

use std::path::Path;

use filterjit::{corpus, denoise, render};

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn read(path: &str) -> String {
    std::fs::read_to_string(root().join(path)).unwrap_or_else(|e| panic!("{path}: {e}"))
}

/// The shipped `@name`s in `text`: not a file's (`@runs/…`, `@FILE`) nor
/// the syntax's placeholders (`@name`, `@other`).
fn shipped_names(text: &str) -> Vec<String> {
    let mut names = Vec::new();
    for (at, _) in text.match_indices('@') {
        let name: String = text[at + 1..].chars().take_while(|c| c.is_ascii_alphanumeric()).collect();
        let path = text[at + 1 + name.len()..].starts_with(['/', '.']);
        let placeholder = ["name", "other"].contains(&name.as_str());
        if !name.is_empty() && name.chars().next().unwrap().is_ascii_lowercase() && !path && !placeholder {
            names.push(name);
        }
    }
    names
}

#[test]
fn the_readme_names_what_ships_and_links_what_exists() {
    let readme = read("README.md");
    let names = shipped_names(&readme);
    assert!(names.len() >= 6, "{names:?}");
    for name in &names {
        assert!(corpus::lookup(name).is_some(), "README names `@{name}`, which `filterjit list` does not have");
    }
    // The table of what ships: each row's filter with the pipeline it is stored with.
    let rows: Vec<&str> = readme.lines().filter(|l| l.starts_with("| `@")).collect();
    assert!(rows.len() >= 5, "the table of shipped filters");
    for row in &rows {
        let cells: Vec<&str> = row.split('|').map(str::trim).collect();
        let pipeline = cells[3].trim_matches('`');
        for name in shipped_names(cells[1]) {
            let resolved = corpus::resolve_with_pipeline(&format!("@{name}")).unwrap();
            let stored = resolved.pipeline.map(|p| p.to_string()).unwrap_or_else(|| "window".into());
            if cells[1].starts_with(&format!("`@{name}`")) {
                assert_eq!(stored, pipeline, "README's pipeline for `@{name}`");
            }
        }
    }
    let default = rows.iter().find(|r| r.contains("`filter`'s default on one image")).expect("the default's row");
    assert!(default.starts_with(&format!("| `@{}`", denoise::SHIPPED_BY_QUALITY[0])), "{default}");
    let temporal = rows.iter().find(|r| r.contains("`filter`'s default on a sequence")).expect("the temporal row");
    assert!(temporal.starts_with(&format!("| `@{}`", denoise::SHIPPED_TEMPORAL_BY_QUALITY[0])), "{temporal}");
    // The scenes its commands render.
    for line in readme.lines().filter(|l| l.trim_start().starts_with("cargo run --release -- render ")) {
        let scene = line.split_whitespace().nth(5).unwrap();
        assert!(render::builtin(scene).is_some(), "README renders `{scene}`, which is not a built-in scene");
    }
    // Every page it links, and every `@name` those pages give.
    for (at, _) in readme.match_indices("](") {
        let target: String = readme[at + 2..].chars().take_while(|c| *c != ')' && *c != '#').collect();
        if target.starts_with("http") {
            continue;
        }
        assert!(root().join(&target).exists(), "README links {target}, which does not exist");
        if target.ends_with(".md") {
            for name in shipped_names(&read(&target)) {
                assert!(corpus::lookup(&name).is_some(), "{target} names `@{name}`, which does not ship");
            }
        }
    }
}

/// The call prepared for a lent GPU (`benches/gpu_session.sh`) times what
/// exists: each experiment it builds is a patch under docs/experiments/
/// that applies to this tree (a patch that has rotted fails here, not on
/// the device's few minutes), and each filter it names ships.
#[test]
fn the_gpu_session_script_names_patches_that_apply_and_filters_that_ship() {
    let script = read("benches/gpu_session.sh");
    // One `"NAME:@filter …"` a line between `EXPERIMENTS=(` and `)`.
    let start = script.find("EXPERIMENTS=(").expect("gpu_session.sh has no EXPERIMENTS");
    let body = &script[start..];
    let experiments: Vec<&str> = body[..body.find(')').unwrap()]
        .lines()
        .skip(1)
        .filter_map(|line| line.trim().trim_matches('"').split_once(':').map(|(name, _)| name))
        .collect();
    assert!(!experiments.is_empty(), "no experiments read from gpu_session.sh");
    for experiment in &experiments {
        let patch = format!("docs/experiments/{experiment}.patch");
        let check = std::process::Command::new("git")
            .args(["apply", "--check", &patch])
            .current_dir(root())
            .output()
            .unwrap_or_else(|e| panic!("git apply --check {patch}: {e}"));
        assert!(check.status.success(), "{patch} no longer applies: {}", String::from_utf8_lossy(&check.stderr));
    }
    let filters = shipped_names(&script);
    assert!(filters.len() >= 5, "{filters:?}");
    for name in &filters {
        assert!(corpus::lookup(name).is_some(), "gpu_session.sh names `@{name}`, which `filterjit list` does not have");
    }
}
