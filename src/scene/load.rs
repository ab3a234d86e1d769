//! `load`: a dataset's files into a [`Scene`], decoding only the channels a
//! [`Request`] names. In order: plan the noisy image's channels (so it is
//! decoded once), decode them, then the features (stored and gradients), the
//! variances (in the noisy image or `variance.exr`), the reference and the metadata.

use std::collections::{BTreeMap, BTreeSet};
use std::ops::Range;
use std::path::Path;

use super::import::{pick, Layout};
use super::{exr_io, locate, preprocess, Absent, Files, Request, Scene, SceneError};
use crate::lang::{Feature, FeatureSource, ScalarVar};
use crate::semantics::COLOR_LIMIT;

/// Load a scene: a directory holding `noisy.exr` (and `reference.exr`,
/// `variance.exr`, `meta.json` where present), or a noisy EXR file.
pub fn load(path: &Path, request: &Request) -> Result<Scene, SceneError> {
    let files = locate(path, request)?;
    let (channels, width, height) = exr_io::channel_names(&files.noisy)?;
    if width == 0 || height == 0 {
        return Err(SceneError::Empty { file: files.noisy.clone() });
    }
    let layout = Layout::detect(&channels);
    let plan = NoisyPlan::new(layout, &channels, request, &files)?;
    let noisy = exr_io::read_channels(&files.noisy, &plan.names)?;
    let mut loader = Loader { request, files: &files, layout, channels: &channels, width, height, notes: Vec::new() };

    let gathered = |range: &Range<usize>| gather(&noisy.data, range, width * height);
    let color = loader.sanitized("noisy colour", gathered(&plan.color), COLOR_LIMIT);
    let albedo = plan.albedo.as_ref().map(|range| loader.sanitized("albedo", gathered(range), f32::MAX));
    let features = loader.features(&plan, &noisy.data)?;
    let variances = loader.variances(&plan, &noisy.data)?;
    let reference = if request.reference { loader.reference()? } else { None };
    let (meta_spp, meta_name) = match &files.meta {
        Some(meta) => read_meta(meta)?,
        None => (None, None),
    };
    Ok(Scene {
        name: meta_name.unwrap_or_else(|| files.name.clone()),
        width,
        height,
        spp: request.spp.or(meta_spp),
        layout: Some(layout.name()),
        color,
        reference,
        features,
        variances,
        albedo,
        notes: loader.notes,
    })
}

/// Which channels of the noisy image to decode, and where each input's lie
/// among them.
struct NoisyPlan {
    names: Vec<&'static str>,
    color: Range<usize>,
    /// The stored features the request's features are made from (a gradient
    /// from its base), where the image has them.
    bases: BTreeSet<Feature>,
    features: BTreeMap<Feature, Range<usize>>,
    albedo: Option<Range<usize>>,
    variances: BTreeMap<ScalarVar, Range<usize>>,
    /// Variances the layout keeps in `variance.exr`: their channel alternatives.
    separate_variances: BTreeMap<ScalarVar, &'static [&'static [&'static str]]>,
}

impl NoisyPlan {
    fn new(layout: Layout, channels: &[String], request: &Request, files: &Files) -> Result<NoisyPlan, SceneError> {
        let mut names: Vec<&'static str> = Vec::new();
        let mut plan = |alternatives| -> Option<Range<usize>> {
            let chosen = pick(alternatives, channels)?;
            let start = names.len();
            names.extend_from_slice(chosen);
            Some(start..names.len())
        };
        let color = plan(layout.color()).ok_or_else(|| SceneError::MissingChannel {
            file: files.noisy.clone(),
            channel: "R, G, B".into(),
            available: channels.to_vec(),
        })?;
        let bases: BTreeSet<Feature> = request
            .features
            .iter()
            .filter_map(|f| match f.source() {
                FeatureSource::Stored(b) | FeatureSource::Gradient(b) if b != Feature::Color => Some(b),
                _ => None,
            })
            .collect();
        let mut features = BTreeMap::new();
        for &base in &bases {
            if let Some(range) = plan(layout.feature(base)) {
                features.insert(base, range);
            }
        }
        let albedo = match request.albedo {
            false => None,
            true => Some(
                features
                    .get(&Feature::Texture)
                    .cloned()
                    .or_else(|| plan(layout.feature(Feature::Texture)))
                    .ok_or_else(|| SceneError::MissingAlbedo {
                        scene: files.name.clone(),
                        layout: layout.name(),
                        file: files.noisy.clone(),
                    })?,
            ),
        };
        let mut variances = BTreeMap::new();
        let mut separate_variances = BTreeMap::new();
        // `level` is no stored channel: the pipeline supplies it.
        for &v in request.variances.iter().filter(|v| v.is_stored()) {
            let (alternatives, separate) = layout.variance(v);
            if separate {
                separate_variances.insert(v, alternatives);
            } else if let Some(range) = plan(alternatives) {
                variances.insert(v, range);
            }
        }
        Ok(NoisyPlan { names, color, bases, features, albedo, variances, separate_variances })
    }
}

/// Decoded channels `range` as RGB pixels.
fn gather(data: &[Vec<f32>], range: &Range<usize>, pixels: usize) -> Vec<[f32; 3]> {
    let mut out = vec![[0f32; 3]; pixels];
    for (c, k) in range.clone().enumerate() {
        for (px, v) in out.iter_mut().zip(&data[k]) {
            px[c] = *v;
        }
    }
    out
}

/// An image's values as one flat slice (RGB pixels or scalars).
trait Values {
    fn flat(&mut self) -> &mut [f32];
}

impl Values for Vec<[f32; 3]> {
    fn flat(&mut self) -> &mut [f32] {
        self.as_flattened_mut()
    }
}

impl Values for Vec<f32> {
    fn flat(&mut self) -> &mut [f32] {
        self
    }
}

/// What every step of a load needs, and the notes it collects for the user.
struct Loader<'a> {
    request: &'a Request,
    files: &'a Files,
    layout: Layout,
    channels: &'a [String],
    width: usize,
    height: usize,
    notes: Vec<String>,
}

impl Loader<'_> {
    /// `values` with non-finite entries replaced by 0 and magnitudes limited
    /// to `limit`, noting how many there were.
    fn sanitized<T: Values>(&mut self, what: impl std::fmt::Display, mut values: T, limit: f32) -> T {
        let bad = preprocess::sanitize(values.flat(), limit);
        if bad > 0 {
            self.notes.push(format!("{what}: {bad} non-finite values replaced by 0"));
        }
        values
    }

    /// An input the scene lacks: refused, or read as 0 with a note (`--absent`).
    fn absent(&mut self, what: &str) -> Result<(), SceneError> {
        match self.request.absent {
            Absent::Refuse => Err(SceneError::MissingFeature {
                scene: self.files.name.clone(),
                feature: what.to_string(),
                layout: self.layout.name(),
                file: self.files.noisy.clone(),
                provided: Feature::ALL
                    .iter()
                    .filter(|f| {
                        f.source() == FeatureSource::Stored(**f)
                            && pick(self.layout.feature(**f), self.channels).is_some()
                    })
                    .map(|f| f.name().to_string())
                    .chain(["color".into(), "pixel".into()])
                    .collect(),
            }),
            Absent::Zero => {
                self.notes.push(format!("`{what}` is absent from this scene and is read as 0 (--absent zero)"));
                Ok(())
            }
        }
    }

    /// The requested features: stored ones normalised, gradients by Sobel of
    /// their normalised base; a base the image lacks is zero (and absent).
    fn features(
        &mut self,
        plan: &NoisyPlan,
        data: &[Vec<f32>],
    ) -> Result<BTreeMap<Feature, Vec<[f32; 3]>>, SceneError> {
        let pixels = self.width * self.height;
        let mut stored = BTreeMap::new();
        for &base in &plan.bases {
            let Some(range) = plan.features.get(&base) else {
                stored.insert(base, vec![[0f32; 3]; pixels]);
                continue;
            };
            let mut values = self.sanitized(base, gather(data, range, pixels), f32::MAX);
            let scale = preprocess::normalise_vectors(&mut values);
            self.notes.push(format!("{base}: divided by {scale:.6} (99.9th percentile of lengths)"));
            stored.insert(base, values);
        }
        let mut features = BTreeMap::new();
        for &f in &self.request.features {
            match f.source() {
                FeatureSource::Stored(Feature::Color) | FeatureSource::Coordinates => {}
                FeatureSource::Stored(base) => {
                    if !plan.features.contains_key(&base) {
                        self.absent(f.name())?;
                    }
                    features.insert(f, stored[&base].clone());
                }
                FeatureSource::Gradient(base) => {
                    let mut g = preprocess::sobel(&stored[&base], self.width, self.height);
                    if plan.features.contains_key(&base) {
                        let scale = preprocess::normalise_vectors(&mut g);
                        self.notes.push(format!("{f}: Sobel magnitude divided by {scale:.6}"));
                    } else {
                        self.absent(f.name())?;
                    }
                    features.insert(f, g);
                }
            }
        }
        Ok(features)
    }

    /// The requested stored variances, from the noisy image or `variance.exr`, normalised.
    fn variances(&mut self, plan: &NoisyPlan, data: &[Vec<f32>]) -> Result<BTreeMap<ScalarVar, Vec<f32>>, SceneError> {
        let mut variances = BTreeMap::new();
        // `level` is no stored channel: the pipeline supplies it.
        for &v in self.request.variances.iter().filter(|v| v.is_stored()) {
            let values = if let Some(range) = plan.variances.get(&v) {
                Some(self.layout.variance_values(&data[range.clone()]))
            } else if let (Some(alternatives), Some(file)) = (plan.separate_variances.get(&v), &self.files.variance) {
                let (channels, w, h) = exr_io::channel_names(file)?;
                self.check_size(file, (w, h))?;
                match pick(alternatives, &channels) {
                    Some(chosen) => Some(self.layout.variance_values(&exr_io::read_channels(file, chosen)?.data)),
                    None => None,
                }
            } else {
                None
            };
            let values = match values {
                Some(values) => {
                    let mut values = self.sanitized(v, values, f32::MAX);
                    let scale = preprocess::normalise_scalars(&mut values);
                    self.notes.push(format!("{v}: divided by {scale:.6e}"));
                    values
                }
                None => {
                    self.absent(v.name())?;
                    vec![0.0; self.width * self.height]
                }
            };
            variances.insert(v, values);
        }
        Ok(variances)
    }

    /// The reference image, where the dataset has one.
    fn reference(&mut self) -> Result<Option<Vec<[f32; 3]>>, SceneError> {
        let Some(file) = &self.files.reference else { return Ok(None) };
        let (channels, w, h) = exr_io::channel_names(file)?;
        self.check_size(file, (w, h))?;
        let chosen = pick(self.layout.color(), &channels).ok_or_else(|| SceneError::MissingChannel {
            file: file.clone(),
            channel: "R, G, B".into(),
            available: channels.clone(),
        })?;
        let data = exr_io::read_channels(file, chosen)?.data;
        let rgb: Vec<[f32; 3]> = (0..w * h).map(|p| [data[0][p], data[1][p], data[2][p]]).collect();
        Ok(Some(self.sanitized("reference", rgb, COLOR_LIMIT)))
    }

    fn check_size(&self, file: &Path, size: (usize, usize)) -> Result<(), SceneError> {
        let expected = (self.width, self.height);
        if size != expected {
            return Err(SceneError::SizeMismatch {
                file: file.to_path_buf(),
                size,
                noisy: self.files.noisy.clone(),
                expected,
            });
        }
        Ok(())
    }
}

/// Samples per pixel and scene name from Mitsuba's `meta.json` (`noisy.spp`,
/// `scene`) or filterjit's (`spp`, `scene`).
fn read_meta(meta: &Path) -> Result<(Option<u32>, Option<String>), SceneError> {
    let text = std::fs::read_to_string(meta).map_err(|e| SceneError::io(meta, e))?;
    let json: serde_json::Value = serde_json::from_str(&text)
        .map_err(|e| SceneError::Meta { file: meta.to_path_buf(), message: e.to_string() })?;
    let spp = json.pointer("/noisy/spp").or_else(|| json.get("spp")).and_then(|v| v.as_u64());
    let name = json.get("scene").and_then(|v| v.as_str()).map(str::to_string);
    Ok((spp.map(|s| s as u32), name))
}
