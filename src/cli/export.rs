//! `filterjit export`: a stored filter (or a front member within a time
//! budget) as shaders for another program, one file per stage and the
//! manifest beside them, written atomically.

use std::path::{Path, PathBuf};

use anyhow::Result;

use filterjit::corpus;
use filterjit::export::{StageName, Target, PORTABLE_SAMPLED_TEXTURES};
use filterjit::jit::OutputFormat;
use filterjit::pipeline::FilterPipeline;

/// The language to write: the one asked for, else the one `output`'s
/// extension names. A file named for another language than the one asked
/// for is refused (`denoise.glsl` holding WGSL misleads whoever loads it),
/// and so is one whose extension names none without `--target`, and a folder.
fn target_for(asked: Option<Target>, output: &Path) -> Result<Target> {
    if output.is_dir() || output.as_os_str().to_string_lossy().ends_with(['/', '\\']) {
        anyhow::bail!(
            "-o {}: a folder; name the shader's file (for example {})",
            output.display(),
            output.join("filter.wgsl").display()
        )
    }
    let named = output.extension().and_then(|e| Target::for_extension(&e.to_string_lossy()));
    if asked.is_none() && named.is_none() {
        let extensions: Vec<String> =
            <Target as clap::ValueEnum>::value_variants().iter().map(|t| format!(".{}", t.extension())).collect();
        anyhow::bail!(
            "-o {}: the file's extension names no shader language; name it {} (or .glsl, .msl), or give --target",
            output.display(),
            extensions.join(", ")
        )
    }
    match (asked, named) {
        (Some(asked), Some(named)) if asked != named => {
            let name =
                |t: Target| clap::ValueEnum::to_possible_value(&t).map_or(String::new(), |v| v.get_name().into());
            anyhow::bail!(
                "-o {}: the file's extension names {} and --target asks for {}; name the file .{} or leave --target out",
                output.display(),
                name(named),
                name(asked),
                asked.extension()
            )
        }
        (asked, named) => Ok(asked.or(named).expect("one of them, checked above")),
    }
}

/// What each stage's file is, as `export` reports it.
fn describe(name: StageName, dispatches: usize) -> String {
    match name {
        StageName::Prepass => "the pre-pass".into(),
        StageName::Spread => format!("keep's spread: {dispatches} dispatches after the pre-pass"),
        StageName::Temporal => "the temporal stage's blend: one dispatch a frame, its history kept".into(),
        StageName::TemporalVariance => "the temporal stage's variance: one dispatch after the blend".into(),
        StageName::Guide => "the guide: one dispatch before the form".into(),
        StageName::PlaneFit => "planefit: one dispatch after the form".into(),
        StageName::Anchor => format!("the light anchor: {dispatches} dispatches after the form"),
        StageName::PixelFilter => "the pixel filter: one dispatch, last".into(),
    }
}

pub(super) fn export(
    expr: &str,
    target: Option<Target>,
    format: OutputFormat,
    output: &Path,
    pipeline: Option<FilterPipeline>,
    budget_ms: Option<f64>,
    size: Option<(u32, u32)>,
) -> Result<()> {
    let target = target_for(target, output)?;
    let resolved = match budget_ms {
        None => corpus::resolve_with_pipeline(expr)?,
        Some(budget) => {
            let front = filterjit::evolve::Front::read(Path::new(expr))?;
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
                expr: filterjit::parse_expr(&member.expr)?,
                pipeline: Some(front.pipeline),
                radius: Some(member.radius),
            }
        }
    };
    let pipeline = pipeline.or(resolved.pipeline).unwrap_or_default();
    let mut exported = filterjit::export::export_filter(&resolved.expr, &pipeline, resolved.radius, target, format)?;
    let manifest_path = manifest_path(output);
    let mut files = vec![(output.to_path_buf(), exported.code.to_bytes())];
    for (name, code) in &exported.stages {
        let path = stage_path(output, name.key());
        let stage = exported.manifest.stage_mut(*name).as_mut().expect("the manifest has every exported stage");
        stage.file = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        files.push((path, code.to_bytes()));
    }
    let manifest = serde_json::to_string_pretty(&exported.manifest)? + "\n";
    files.push((manifest_path.clone(), manifest.into_bytes()));
    for (path, bytes) in &files {
        filterjit::io::write_bytes_atomically(path, bytes)?;
    }
    for (name, _) in &exported.stages {
        let stage = exported.manifest.stage(*name).expect("the manifest has every exported stage");
        println!(
            "wrote {} ({})",
            output.with_file_name(&stage.file).display(),
            describe(*name, exported.manifest.dispatches_of(*name))
        );
    }
    if exported.manifest.passes > 1 {
        println!(
            "pipeline  {pipeline}: dispatch the form's shader {} times (the manifest's `order`)",
            exported.manifest.passes
        );
    }
    let kept: Vec<&str> = exported.manifest.kept().map(|k| k.name.as_str()).collect();
    if !kept.is_empty() {
        println!("sequence  keep {} from frame to frame (the manifest's `keep` steps)", kept.join(", "));
        if pipeline.pixel_filter.is_none() {
            let point_sampled =
                FilterPipeline { pixel_filter: Some(filterjit::pipeline::PixelFilter::POINT_SAMPLED), ..pipeline };
            println!(
                "note      `filter` ends the frames of a renderer that samples each pixel at one point (Cycles at 1 \
                 sample) with the pixel filter; export such a sequence's filter with --pipeline {point_sampled}"
            );
        }
    }
    if let Some(radius) = exported.manifest.radius {
        println!("radius    {radius}: set params.radius to it (the window's (2r+1)^2 taps)");
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
    if exported.manifest.sampled_textures > PORTABLE_SAMPLED_TEXTURES {
        eprintln!(
            "warning: the shader binds {} sampled textures; WebGPU guarantees {} per stage, so it needs a device that allows more",
            exported.manifest.sampled_textures, PORTABLE_SAMPLED_TEXTURES
        );
    }
    Ok(())
}

/// Where a stage of an exported pipeline goes: `NAME.STAGE.EXT` beside
/// `NAME.EXT` (`prepass`, `spread`).
pub(crate) fn stage_path(shader: &Path, stage: &str) -> PathBuf {
    let stem = shader.file_stem().map(|n| n.to_string_lossy().into_owned()).unwrap_or_else(|| "filter".into());
    let name = match shader.extension() {
        Some(ext) => format!("{stem}.{stage}.{}", ext.to_string_lossy()),
        None => format!("{stem}.{stage}"),
    };
    shader.with_file_name(name)
}

/// Where `export` writes the manifest of the shader at `shader`: `shader` + `.json`.
pub(crate) fn manifest_path(shader: &Path) -> PathBuf {
    let mut name = shader.as_os_str().to_owned();
    name.push(".json");
    PathBuf::from(name)
}
