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
/// (rendered into `cache` unless there already), dataset directories or
/// files, and folders of datasets.
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
        if path.is_dir() && !scene::is_dataset_dir(path) {
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

/// Features and variances every one of the datasets provides.
pub fn common_terminals(datasets: &[PathBuf]) -> Result<(BTreeSet<Feature>, BTreeSet<ScalarVar>)> {
    let mut features: Option<BTreeSet<Feature>> = None;
    let mut variances: Option<BTreeSet<ScalarVar>> = None;
    for d in datasets {
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

/// Load the datasets with `features` and `variances`, and the raw albedo when `pipeline` demodulates.
pub fn load_all(
    datasets: &[PathBuf],
    features: &BTreeSet<Feature>,
    variances: &BTreeSet<ScalarVar>,
    pipeline: &FilterPipeline,
) -> Result<Vec<Scene>> {
    datasets
        .iter()
        .map(|d| {
            let request = Request {
                features: features.iter().copied().chain(pipeline.features()).collect(),
                variances: variances.clone(),
                reference: true,
                albedo: pipeline.demodulate,
                ..Default::default()
            };
            scene::load(d, &request).with_context(|| format!("loading {}", d.display()))
        })
        .collect()
}
