//! `load`: a dataset's files into a [`Scene`], decoding only the channels a
//! [`Request`] names, in two steps: the files are decoded into the renderer's
//! raw [`Images`] (the noisy image's channels planned so it is decoded once,
//! then the variances in the noisy image or `variance.exr`, the reference and
//! the metadata), and [`prepare`] makes the scene from them. Images that
//! never were files (arrays handed over from Python) take the second step alone.

use std::collections::{BTreeMap, BTreeSet};
use std::ops::Range;
use std::path::Path;

use super::import::{pick, Channels, Layout};
use super::{exr_io, locate, preprocess, Absent, Images, Motion, Note, Origin, Request, Scene, SceneError};
use crate::lang::{Feature, FeatureSource, ScalarVar};
use crate::semantics::COLOR_LIMIT;

/// Load a scene: a directory holding `noisy.exr` (and `reference.exr`,
/// `variance.exr`, `meta.json` where present), or a noisy EXR file.
pub fn load(path: &Path, request: &Request) -> Result<Scene, SceneError> {
    prepare(decode(path, request)?, request)
}

/// The raw images of the dataset at `path` that `request` needs.
fn decode(path: &Path, request: &Request) -> Result<Images, SceneError> {
    let files = locate(path, request)?;
    let (names, width, height) = exr_io::channel_names(&files.noisy)?;
    if width == 0 || height == 0 {
        return Err(SceneError::Empty { file: files.noisy.clone() });
    }
    let view = Channels::of(&files.noisy, names, request.view_layer.as_deref())?;
    let channels = &view.names;
    let layout = view.layout();
    let plan = NoisyPlan::new(layout, channels, request, &files.noisy)?;
    let noisy = read(&files.noisy, &view, &plan.names)?;
    let pixels = width * height;
    let gathered = |range: &Range<usize>| gather(&noisy.data, range, pixels);
    let mut variances: BTreeMap<ScalarVar, Vec<f32>> =
        plan.variances.iter().map(|(v, range)| (*v, layout.variance_values(&noisy.data[range.clone()]))).collect();
    if let Some(file) = &files.variance {
        if !plan.separate_variances.is_empty() {
            let (names, w, h) = exr_io::channel_names(file)?;
            check_size(file, (w, h), &files.noisy, (width, height))?;
            for (v, alternatives) in &plan.separate_variances {
                if let Some(chosen) = pick(alternatives, &names) {
                    variances.insert(*v, layout.variance_values(&exr_io::read_channels(file, chosen)?.data));
                }
            }
        }
    }
    let reference = match (&files.reference, request.reference) {
        (Some(file), true) => Some(read_reference(file, layout, request, &files.noisy, (width, height))?),
        _ => None,
    };
    let (meta_spp, meta_name) = match &files.meta {
        Some(meta) => read_meta(meta)?,
        None => (None, None),
    };
    // Blender's Vector pass (and filterjit's own) has y up; image rows go down.
    let motion = match (&plan.motion, &plan.surface) {
        (Some(vectors), Some((normal, depth, albedo))) => {
            let (normal, depth) = (gathered(normal), gathered(depth));
            let mut depth: Vec<[f32; 3]> = depth;
            layout.clean(Feature::Depth, &mut depth);
            let albedo = albedo.as_ref().map(gathered);
            let vectors = gathered(vectors).iter().map(|v| [v[0], -v[1]]).collect();
            Some(Motion::new(vectors, &normal, &depth, albedo.as_deref()))
        }
        _ => None,
    };
    Ok(Images {
        name: meta_name.unwrap_or_else(|| files.name.clone()),
        width,
        height,
        spp: meta_spp,
        origin: Origin::File { layout, file: files.noisy.clone() },
        color: gathered(&plan.color),
        features: plan
            .features
            .iter()
            .map(|(f, range)| {
                let mut values = gathered(range);
                layout.clean(*f, &mut values);
                (*f, values)
            })
            .collect(),
        provided: layout.stored_features(channels),
        variances,
        reference,
        motion,
    })
}

/// A scene from a renderer's raw images: every image sanitised (non-finite
/// values to 0, colour limited), stored features normalised, gradients taken,
/// variances normalised, and inputs the request names but the images lack
/// refused or read as zero (`request.absent`). `request.spp` overrides the images'.
pub fn prepare(images: Images, request: &Request) -> Result<Scene, SceneError> {
    let Images {
        name,
        width,
        height,
        spp,
        origin,
        color,
        features: stored,
        provided,
        mut variances,
        reference,
        motion,
    } = images;
    let mut preparer = Preparer { request, name: &name, origin: &origin, provided: &provided, notes: Vec::new() };
    let color = preparer.sanitized("noisy colour", color, COLOR_LIMIT);
    preparer.check_negative("noisy colour", &color);
    let albedo = match request.albedo {
        false => None,
        true => match stored.get(&Feature::Texture) {
            // Named as the feature it also is: one note where both read a bad value.
            Some(albedo) => Some(preparer.sanitized(Feature::Texture, albedo.clone(), f32::MAX)),
            None => return Err(SceneError::MissingAlbedo { scene: name.clone(), origin: origin.clone() }),
        },
    };
    let motion = match (request.motion, motion) {
        (false, _) => None,
        (true, Some(motion)) => Some(preparer.motion(motion)),
        (true, None) => return Err(SceneError::MissingMotion { scene: name.clone(), origin: origin.clone() }),
    };
    let features = preparer.features(stored, width, height)?;
    let mut prepared = BTreeMap::new();
    // `level` and the outlier measures are no stored channels: the pipeline supplies them.
    for &v in request.variances.iter().filter(|v| v.is_stored()) {
        let values = match variances.remove(&v) {
            Some(values) => {
                let mut values = preparer.sanitized(v, values, f32::MAX);
                let scale = preprocess::normalise_scalars(&mut values);
                preparer.note(Note::info(format!("{v}: divided by {scale:.6e}")));
                values
            }
            None => {
                preparer.absent(v.name())?;
                vec![0.0; width * height]
            }
        };
        prepared.insert(v, values);
    }
    let reference = match (reference, request.reference) {
        (Some(reference), true) => Some(preparer.sanitized("reference", reference, COLOR_LIMIT)),
        _ => None,
    };
    let notes = preparer.notes;
    Ok(Scene {
        name,
        width,
        height,
        spp: request.spp.or(spp),
        layout: origin.layout(),
        color,
        reference,
        features,
        variances: prepared,
        albedo,
        motion,
        notes,
    })
}

/// Which channels of the noisy image to decode, and where each input's lie
/// among them.
struct NoisyPlan {
    names: Vec<&'static str>,
    color: Range<usize>,
    /// The stored features the request's features (and the albedo) are made
    /// from (a gradient from its base), where the image has them.
    features: BTreeMap<Feature, Range<usize>>,
    variances: BTreeMap<ScalarVar, Range<usize>>,
    /// Variances the layout keeps in `variance.exr`: their channel alternatives.
    separate_variances: BTreeMap<ScalarVar, &'static [&'static [&'static str]]>,
    /// The motion vectors, where the request asks for them and the image has them.
    motion: Option<Range<usize>>,
    /// The raw normal, depth and albedo (where the image has one) of the
    /// temporal stage's surface test, likewise.
    surface: Option<SurfacePlan>,
}

/// Where the temporal stage's raw normal, depth and albedo lie among the decoded channels.
type SurfacePlan = (Range<usize>, Range<usize>, Option<Range<usize>>);

impl NoisyPlan {
    fn new(layout: Layout, channels: &[String], request: &Request, noisy: &Path) -> Result<NoisyPlan, SceneError> {
        let mut names: Vec<&'static str> = Vec::new();
        // Channels asked for twice (a feature and the temporal stage's raw copy of it) are decoded once.
        let mut plan = |alternatives| -> Option<Range<usize>> {
            let chosen = pick(alternatives, channels)?;
            if let Some(start) = names.windows(chosen.len()).position(|w| w == chosen) {
                return Some(start..start + chosen.len());
            }
            let start = names.len();
            names.extend_from_slice(chosen);
            Some(start..names.len())
        };
        let color = plan(layout.color()).ok_or_else(|| SceneError::MissingChannel {
            file: noisy.to_path_buf(),
            channel: layout.color().iter().map(|names| names.join(", ")).collect::<Vec<_>>().join(" or "),
            available: channels.to_vec(),
        })?;
        let mut bases = stored_bases(request);
        if request.albedo {
            bases.insert(Feature::Texture);
        }
        let mut features = BTreeMap::new();
        for base in bases {
            if let Some(range) = plan(layout.feature(base)) {
                features.insert(base, range);
            }
        }
        let mut variances = BTreeMap::new();
        let mut separate_variances = BTreeMap::new();
        for &v in request.variances.iter().filter(|v| v.is_stored()) {
            let (alternatives, separate) = layout.variance(v);
            if separate {
                separate_variances.insert(v, alternatives);
            } else if let Some(range) = plan(alternatives) {
                variances.insert(v, range);
            }
        }
        let (motion, surface) = match request.motion {
            false => (None, None),
            true => {
                let motion = plan(layout.motion());
                let surface = plan(layout.surface_normal())
                    .zip(plan(layout.feature(Feature::Depth)))
                    .map(|(normal, depth)| (normal, depth, plan(layout.feature(Feature::Texture))));
                (motion, surface)
            }
        };
        Ok(NoisyPlan { names, color, features, variances, separate_variances, motion, surface })
    }
}

/// The stored features the request's features are made from (a gradient from its base).
fn stored_bases(request: &Request) -> BTreeSet<Feature> {
    request
        .features
        .iter()
        .filter_map(|f| match f.source() {
            FeatureSource::Stored(b) | FeatureSource::Gradient(b) if b != Feature::Color => Some(b),
            _ => None,
        })
        .collect()
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

/// What every step of [`prepare`] needs, and the notes it collects for the user.
struct Preparer<'a> {
    request: &'a Request,
    name: &'a str,
    origin: &'a Origin,
    provided: &'a BTreeSet<Feature>,
    notes: Vec<Note>,
}

impl Preparer<'_> {
    /// Note `note` once: an image read for two uses (the albedo that
    /// demodulates and the `texture` feature) is sanitised for each.
    fn note(&mut self, note: Note) {
        if !self.notes.contains(&note) {
            self.notes.push(note);
        }
    }

    /// `values` with non-finite entries replaced by 0 and magnitudes limited
    /// to `limit`, noting how many there were.
    fn sanitized<T: Values>(&mut self, what: impl std::fmt::Display, mut values: T, limit: f32) -> T {
        let preprocess::Sanitized { non_finite, limited } = preprocess::sanitize(values.flat(), limit);
        if non_finite > 0 {
            self.note(Note::warning(format!("{what}: {non_finite} non-finite values replaced by 0")));
        }
        if limited > 0 {
            self.note(Note::warning(format!("{what}: {limited} values beyond ±{limit:e} limited to it")));
        }
        values
    }

    /// A colour (`what`) with negative values, said: a renderer's radiance
    /// never is, and the light figures measure luminance from 0 up.
    fn check_negative(&mut self, what: &str, color: &[[f32; 3]]) {
        let negative = color.iter().flatten().filter(|c| **c < 0.0).count();
        if negative > 0 {
            self.note(Note::warning(format!(
                "{what}: {negative} negative values (kept; filterjit measures light from 0 up)"
            )));
        }
    }

    /// An input the scene lacks: refused, or read as 0 with a note (`Absent`).
    fn absent(&mut self, what: &str) -> Result<(), SceneError> {
        match self.request.absent {
            Absent::Refuse => Err(SceneError::MissingFeature {
                how_to_get: match self.origin {
                    Origin::File { layout, .. } => Feature::from_name(what).and_then(|f| layout.how_to_get(f.base())),
                    Origin::Arrays => None,
                },
                scene: self.name.to_string(),
                feature: what.to_string(),
                origin: self.origin.clone(),
                provided: self
                    .provided
                    .iter()
                    .map(|f| f.name().to_string())
                    .chain(["color".into(), "pixel".into()])
                    .collect(),
            }),
            Absent::Zero => {
                self.note(Note::warning(format!("`{what}` is absent from this scene and is read as 0")));
                Ok(())
            }
        }
    }

    /// The temporal stage's inputs, sanitised: a non-finite motion vector
    /// points outside the image (that pixel starts a new history), a
    /// non-finite normal or depth is no surface.
    fn motion(&mut self, mut motion: Motion) -> Motion {
        let mut bad = 0;
        for v in &mut motion.vectors {
            if !(v[0].is_finite() && v[1].is_finite()) {
                *v = [NO_HISTORY, NO_HISTORY];
                bad += 1;
            }
            *v = v.map(|c| c.clamp(-NO_HISTORY, NO_HISTORY));
        }
        if bad > 0 {
            self.note(Note::warning(format!(
                "motion vectors: {bad} non-finite vectors; those pixels start a new history"
            )));
        }
        let mut bad = 0;
        for s in motion.surface.iter_mut().chain(&mut motion.albedo) {
            if s.iter().any(|c| !c.is_finite()) {
                *s = [0.0; 4];
                bad += 1;
            }
        }
        if bad > 0 {
            self.note(Note::warning(format!("normal, depth or albedo: {bad} non-finite values read as no surface")));
        }
        motion
    }

    /// The requested features: stored ones normalised, gradients by Sobel of
    /// their normalised base; a base the images lack is zero (and absent).
    fn features(
        &mut self,
        mut raw: BTreeMap<Feature, Vec<[f32; 3]>>,
        width: usize,
        height: usize,
    ) -> Result<BTreeMap<Feature, Vec<[f32; 3]>>, SceneError> {
        let pixels = width * height;
        let mut stored = BTreeMap::new();
        for base in stored_bases(self.request) {
            let Some(values) = raw.remove(&base) else {
                stored.insert(base, None);
                continue;
            };
            let mut values = self.sanitized(base, values, f32::MAX);
            if base == Feature::Normal {
                let changed = preprocess::unit_normals(&mut values);
                if changed > 0 {
                    self.note(Note::info(format!("normal: {changed} made unit length (their direction kept)")));
                }
            }
            let scale = preprocess::normalise_vectors(&mut values);
            self.note(Note::info(format!("{base}: divided by {scale:.6} (99.9th percentile of lengths)")));
            stored.insert(base, Some(values));
        }
        let zeros = || vec![[0f32; 3]; pixels];
        let mut features = BTreeMap::new();
        for &f in &self.request.features {
            match f.source() {
                FeatureSource::Stored(Feature::Color) | FeatureSource::Coordinates | FeatureSource::Guide => {}
                FeatureSource::Stored(base) => {
                    let values = match &stored[&base] {
                        Some(values) => values.clone(),
                        None => {
                            self.absent(f.name())?;
                            zeros()
                        }
                    };
                    features.insert(f, values);
                }
                FeatureSource::Gradient(base) => {
                    let g = match &stored[&base] {
                        Some(values) => {
                            let mut g = preprocess::sobel(values, width, height);
                            let scale = preprocess::normalise_vectors(&mut g);
                            self.note(Note::info(format!("{f}: Sobel magnitude divided by {scale:.6}")));
                            g
                        }
                        None => {
                            self.absent(f.name())?;
                            preprocess::sobel(&zeros(), width, height)
                        }
                    };
                    features.insert(f, g);
                }
            }
        }
        Ok(features)
    }
}

/// `chosen` channels (named as in `view`) of `file`.
fn read(file: &Path, view: &Channels, chosen: &[&str]) -> Result<exr_io::ImageChannels, SceneError> {
    let names = view.in_file(chosen);
    exr_io::read_channels(file, &names.iter().map(String::as_str).collect::<Vec<_>>())
}

/// The reference image's colour.
fn read_reference(
    file: &Path,
    layout: Layout,
    request: &Request,
    noisy: &Path,
    expected: (usize, usize),
) -> Result<Vec<[f32; 3]>, SceneError> {
    let (names, w, h) = exr_io::channel_names(file)?;
    check_size(file, (w, h), noisy, expected)?;
    let view = Channels::of(file, names, request.view_layer.as_deref())?;
    let chosen = pick(layout.reference_color(), &view.names).ok_or_else(|| SceneError::MissingChannel {
        file: file.to_path_buf(),
        channel: layout.reference_color()[0].join(", "),
        available: view.names.clone(),
    })?;
    let data = read(file, &view, chosen)?.data;
    Ok((0..w * h).map(|p| [data[0][p], data[1][p], data[2][p]]).collect())
}

fn check_size(file: &Path, size: (usize, usize), noisy: &Path, expected: (usize, usize)) -> Result<(), SceneError> {
    if size != expected {
        return Err(SceneError::SizeMismatch { file: file.to_path_buf(), size, noisy: noisy.to_path_buf(), expected });
    }
    Ok(())
}

/// A motion vector component that points outside any image: where a vector
/// was not finite, the pixel has no history to take.
const NO_HISTORY: f32 = 1e7;

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
