//! Scene arguments into datasets, and datasets into scenes: what `evolve`,
//! `tune`, `report` and `filter` all take on the command line and share.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};

use crate::gpu::Gpu;
use crate::lang::{Feature, ScalarVar};
use crate::pipeline::FilterPipeline;
use crate::render::{self, RenderSettings};
use crate::scene::{self, Request, Scene};

/// The datasets `args` name: built-in scene names and .toml descriptions
/// (rendered into `cache` unless there already; a sequence's into a folder
/// of frames), dataset directories or files, folders of datasets, and
/// sequences (a folder of frames: `scene::Sequence`), which stay one path.
pub fn resolve(
    gpu: &Gpu,
    args: &[String],
    settings: &RenderSettings,
    cache: &Path,
    progress: render::Progress<'_>,
) -> Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    for arg in args {
        let path = Path::new(arg);
        if is_sequence(path) {
            // A sequence (frame files, or frame datasets rendered by filterjit): one source of many frames.
            out.push(path.to_path_buf());
        } else if path.is_dir() && !scene::is_dataset_dir(path) {
            // A folder of datasets: each subfolder that is one, in name order.
            let inside = scene::datasets_in(path)?;
            if inside.is_empty() {
                bail!(
                    "{} is neither a dataset (it has no {}) nor a folder of datasets (no subfolder has one)",
                    path.display(),
                    scene::NOISY_FILE
                );
            }
            out.extend(inside);
        } else if !is_rendered(arg) {
            out.push(path.to_path_buf());
        } else {
            let d = render::describe(arg)?;
            out.push(render::cached(gpu, cache, &d, settings, &mut *progress)?);
        }
    }
    Ok(out)
}

/// Whether [`resolve`] renders `arg` (a built-in name or a .toml description)
/// rather than reading it as stored (a dataset directory or an EXR file).
pub fn is_rendered(arg: &str) -> bool {
    let path = Path::new(arg);
    !(path.is_dir() || path.extension().is_some_and(|e| e == "exr"))
}

/// Whether a source is a sequence: a rendered sequence (its frame datasets
/// and `sequence.json`), or a folder of frame files (`scene::is_sequence`).
/// A folder of datasets without `sequence.json` is that many scenes.
pub fn is_sequence(path: &Path) -> bool {
    path.join(render::SEQUENCE_META).is_file()
        || (scene::is_sequence(path) && scene::datasets_in(path).map_or(true, |inside| inside.is_empty()))
}

/// Features and variances every one of the datasets (a sequence's first frame) provides.
pub fn common_terminals(datasets: &[PathBuf]) -> Result<(BTreeSet<Feature>, BTreeSet<ScalarVar>)> {
    let mut features: Option<BTreeSet<Feature>> = None;
    let mut variances: Option<BTreeSet<ScalarVar>> = None;
    for d in datasets {
        let first;
        let d = if is_sequence(d) {
            let sequence = scene::Sequence::find(d).with_context(|| format!("reading sequence {}", d.display()))?;
            first = sequence.frames.first().map(|f| f.path.clone()).context("the sequence has no frames")?;
            &first
        } else {
            d
        };
        let (f, v) = scene::provides(d, None).with_context(|| format!("reading {}", d.display()))?;
        features = Some(match features {
            Some(all) => all.intersection(&f).copied().collect(),
            None => f,
        });
        variances = Some(match variances {
            Some(all) => all.intersection(&v).copied().collect(),
            None => v,
        });
    }
    Ok((features.unwrap_or_default(), variances.unwrap_or_default()))
}

/// Load the datasets with `features` and `variances`, and the raw albedo
/// when `pipeline` demodulates. A sequence's frames are scenes of their own:
/// each as it is, or, where `pipeline` has a temporal stage, as the form
/// receives it ([`accumulated`]).
pub fn load_all(
    datasets: &[PathBuf],
    features: &BTreeSet<Feature>,
    variances: &BTreeSet<ScalarVar>,
    pipeline: &FilterPipeline,
) -> Result<Vec<Scene>> {
    let request = Request {
        features: features.iter().copied().chain(pipeline.features()).collect(),
        variances: variances.iter().copied().filter(|v| !v.from_pipeline()).collect(),
        reference: true,
        albedo: pipeline.demodulate,
        motion: pipeline.is_temporal(),
        ..Default::default()
    };
    let mut scenes = Vec::new();
    for d in datasets {
        if !is_sequence(d) {
            scenes.push(scene::load(d, &request).with_context(|| format!("loading {}", d.display()))?);
            continue;
        }
        let sequence = scene::Sequence::find(d).with_context(|| format!("reading sequence {}", d.display()))?;
        sequence.check(&request).with_context(|| format!("checking sequence {}", d.display()))?;
        let mut frames = (0..sequence.frames.len())
            .map(|k| {
                let mut frame = sequence.load(k, &request)?;
                frame.name = format!("{}/{}", sequence_name(d), frame.name);
                Ok(frame)
            })
            .collect::<Result<Vec<Scene>, scene::SceneError>>()
            .with_context(|| format!("loading sequence {}", d.display()))?;
        if pipeline.is_temporal() {
            frames = accumulated(&frames, pipeline)?;
        }
        scenes.extend(frames);
    }
    Ok(scenes)
}

/// A sequence's name for its frames' scenes: the scene it was rendered from
/// (its `sequence.json`), else its folder's.
fn sequence_name(dir: &Path) -> String {
    let meta = std::fs::read_to_string(dir.join(render::SEQUENCE_META)).ok();
    let scene = meta
        .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
        .and_then(|m| m.get("scene").and_then(|s| s.as_str()).map(str::to_string));
    scene.unwrap_or_else(|| dir.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default())
}

/// Whether frames filtered by `pipeline` can be scored one by one: a
/// temporal pipeline only where its history is the blend (`feedback=0`),
/// since a pass fed back makes each frame's input depend on the weight that
/// filtered the one before.
pub fn check_scorable(pipeline: &FilterPipeline) -> Result<()> {
    match pipeline.temporal {
        Some(stage) if stage.feedback != 0 => bail!(
            "pipeline `{pipeline}` feeds back pass {} of its form: its frames cannot be scored apart from the weight \
             that filtered the frame before; score temporal pipelines whose history is the blend (feedback=0)",
            stage.feedback
        ),
        _ => Ok(()),
    }
}

/// A temporal pipeline's frames as its form receives them, in order: each
/// frame's pre-pass and temporal stage run (the CPU reference's, frame
/// after frame with the history carried), its colour the blend (multiplied
/// back by the modulation where the pipeline demodulates, which the form's
/// pipeline, [`FilterPipeline::spatial`], divides out again) and what the
/// stages measured among its variances. Exact only where the history is the
/// blend itself (`feedback=0`): a pass fed back would make each frame's
/// input depend on the weight that filtered the one before.
pub fn accumulated(frames: &[Scene], pipeline: &FilterPipeline) -> Result<Vec<Scene>> {
    let Some(stage) = pipeline.temporal else { return Ok(frames.to_vec()) };
    check_scorable(pipeline)?;
    let mut history = None;
    let mut out = Vec::with_capacity(frames.len());
    for frame in frames {
        let motion = frame.motion.as_ref().ok_or_else(|| crate::scene::MissingInput {
            scene: frame.name.clone(),
            missing: crate::scene::Missing::Motion,
        })?;
        let prepared = crate::cpu::prepass(frame, pipeline)?;
        let blend = crate::cpu::temporal::accumulate(
            stage,
            &prepared.color,
            motion,
            frame.width,
            frame.height,
            history.as_ref(),
        );
        let mut scene = frame.clone();
        // Demodulating, the form divides by the albedo and multiplies back by
        // it: the blend's albedo, multiplied in here (it lies in [0.1, 1]).
        scene.color = match prepared.modulation {
            Some(_) => {
                scene.albedo = Some(blend.modulation.clone());
                blend
                    .color
                    .iter()
                    .zip(&blend.modulation)
                    .map(|(c, m)| [c[0] * m[0], c[1] * m[1], c[2] * m[2]])
                    .collect()
            }
            None => blend.color.clone(),
        };
        if let Some(local) = prepared.local {
            for (v, values) in ScalarVar::FROM_PREPASS.into_iter().zip(local) {
                scene.variances.insert(v, values);
            }
        }
        scene.variances.insert(ScalarVar::HistoryLength, blend.length.clone());
        scene.variances.insert(ScalarVar::TemporalVariance, blend.variance.clone());
        history = Some(crate::cpu::temporal::keep(&blend, blend.color.clone(), motion, frame.width, frame.height));
        out.push(scene);
    }
    Ok(out)
}
