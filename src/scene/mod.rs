//! Scene data: noisy colour, features, variances and the reference, loaded
//! from renderers' EXR files with only the channels a run asks for.

pub mod exr_io;
pub mod import;
pub mod preprocess;

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use crate::lang::{Expr, Feature, FeatureSource, ScalarVar};
use crate::semantics::COLOR_LIMIT;
use import::{pick, Layout};

#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error("{}: {source}", file.display())]
    Io { file: PathBuf, source: std::io::Error },
    #[error("{}: not a readable EXR image: {message}", file.display())]
    Exr { file: PathBuf, message: String },
    #[error("{}: no channel `{channel}` (the file has: {})", file.display(), available.join(", "))]
    MissingChannel { file: PathBuf, channel: String, available: Vec<String> },
    #[error("scene `{scene}` has no `{feature}` ({layout} data from {} provides: {}); \
             the expression needs it. Use an expression without it, or pass --absent zero to read it as 0",
            file.display(), provided.join(", "))]
    MissingFeature { scene: String, feature: String, layout: &'static str, file: PathBuf, provided: Vec<String> },
    #[error("scene `{scene}` has no albedo ({layout} data from {} has no texture/albedo channels); \
             demodulation divides by it: use a pipeline without `demodulate`", file.display())]
    MissingAlbedo { scene: String, layout: &'static str, file: PathBuf },
    #[error("{}: image is {}x{}, but the noisy image {} is {}x{}", file.display(), size.0, size.1, noisy.display(), expected.0, expected.1)]
    SizeMismatch { file: PathBuf, size: (usize, usize), noisy: PathBuf, expected: (usize, usize) },
    #[error("{}: no noisy image here (expected {} or an .exr file)", path.display(), NOISY_FILE)]
    NotAScene { path: PathBuf },
    #[error("{}: image is empty", file.display())]
    Empty { file: PathBuf },
    #[error("{}: {message}", file.display())]
    Meta { file: PathBuf, message: String },
}

impl SceneError {
    pub(crate) fn io(file: &Path, source: std::io::Error) -> Self {
        SceneError::Io { file: file.to_path_buf(), source }
    }
    pub(crate) fn exr(file: &Path, e: exr::error::Error) -> Self {
        SceneError::Exr { file: file.to_path_buf(), message: e.to_string() }
    }
}

pub const NOISY_FILE: &str = "noisy.exr";
pub const REFERENCE_FILE: &str = "reference.exr";
pub const VARIANCE_FILE: &str = "variance.exr";
pub const META_FILE: &str = "meta.json";

/// What to do when an expression needs a feature the scene does not provide.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum Absent {
    /// Refuse, naming the feature and the scene.
    #[default]
    Refuse,
    /// Read it as zero everywhere, with a note in the scene's report.
    Zero,
}

/// What a run needs from a scene.
#[derive(Clone, Debug, Default)]
pub struct Request {
    pub features: BTreeSet<Feature>,
    pub variances: BTreeSet<ScalarVar>,
    /// Load the reference image if there is one.
    pub reference: bool,
    /// Overrides the reference image's location.
    pub reference_path: Option<PathBuf>,
    /// Overrides the samples per pixel of the noisy image.
    pub spp: Option<u32>,
    pub absent: Absent,
    /// Load the raw albedo (the `texture` feature's channels, not normalised),
    /// which demodulation divides by (`pipeline`).
    pub albedo: bool,
}

impl Request {
    /// Exactly the inputs of `expr`, plus the reference.
    pub fn for_expr(expr: &Expr) -> Self {
        Request { features: expr.features(), variances: expr.stored_variables(), reference: true, ..Default::default() }
    }
}

/// A loaded scene. Features are normalised and zero-padded to 3 components.
#[derive(Clone, Debug)]
pub struct Scene {
    pub name: String,
    pub width: usize,
    pub height: usize,
    /// Samples per pixel of the noisy colour, when known.
    pub spp: Option<u32>,
    pub layout: Option<&'static str>,
    /// Noisy colour, sanitised.
    pub color: Vec<[f32; 3]>,
    pub reference: Option<Vec<[f32; 3]>>,
    pub features: BTreeMap<Feature, Vec<[f32; 3]>>,
    pub variances: BTreeMap<ScalarVar, Vec<f32>>,
    /// The raw albedo (sanitised, not normalised), when the request asked for it.
    pub albedo: Option<Vec<[f32; 3]>>,
    /// What loading did that a user should know: sanitised values, scales, absent features read as zero.
    pub notes: Vec<String>,
}

impl Scene {
    pub fn pixels(&self) -> usize {
        self.width * self.height
    }

    /// A scene with only a colour image; features and variances are added by the caller.
    pub fn from_color(name: impl Into<String>, width: usize, height: usize, color: Vec<[f32; 3]>) -> Self {
        assert_eq!(color.len(), width * height, "colour has width*height pixels");
        Scene {
            name: name.into(),
            width,
            height,
            spp: None,
            layout: None,
            color,
            reference: None,
            features: BTreeMap::new(),
            variances: BTreeMap::new(),
            albedo: None,
            notes: Vec::new(),
        }
    }

    /// Data of a vector terminal: the noisy colour for `color`, `None` for `pixel` and absent features.
    pub fn feature(&self, f: Feature) -> Option<&[[f32; 3]]> {
        match f {
            Feature::Color => Some(&self.color),
            _ => self.features.get(&f).map(Vec::as_slice),
        }
    }

    pub fn variance(&self, v: ScalarVar) -> Option<&[f32]> {
        self.variances.get(&v).map(Vec::as_slice)
    }

    /// The `width`×`height` pixels from (`x`, `y`) of every image the scene
    /// holds, as a scene of their own named `name@x,y`. Features were
    /// preprocessed on the whole image, so the crop's values are the whole's.
    pub fn crop(&self, x: usize, y: usize, width: usize, height: usize) -> Scene {
        assert!(x + width <= self.width && y + height <= self.height, "the crop lies inside the scene");
        fn rows<T: Copy>(data: &[T], stride: usize, x: usize, y: usize, width: usize, height: usize) -> Vec<T> {
            (y..y + height).flat_map(|row| data[row * stride + x..row * stride + x + width].iter().copied()).collect()
        }
        let cut = |data: &[[f32; 3]]| rows(data, self.width, x, y, width, height);
        Scene {
            name: format!("{}@{x},{y}", self.name),
            width,
            height,
            spp: self.spp,
            layout: self.layout,
            color: cut(&self.color),
            reference: self.reference.as_deref().map(cut),
            features: self.features.iter().map(|(f, v)| (*f, cut(v))).collect(),
            variances: self.variances.iter().map(|(k, v)| (*k, rows(v, self.width, x, y, width, height))).collect(),
            albedo: self.albedo.as_deref().map(cut),
            notes: Vec::new(),
        }
    }
}

struct Files {
    noisy: PathBuf,
    reference: Option<PathBuf>,
    variance: Option<PathBuf>,
    meta: Option<PathBuf>,
    name: String,
}

fn locate(path: &Path, request: &Request) -> Result<Files, SceneError> {
    let (dir, noisy, name) = if path.is_dir() {
        let noisy = path.join(NOISY_FILE);
        if !noisy.is_file() {
            return Err(SceneError::NotAScene { path: path.to_path_buf() });
        }
        let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_else(|| "scene".into());
        (path.to_path_buf(), noisy, name)
    } else if path.is_file() {
        let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
        let name = path.file_stem().map(|n| n.to_string_lossy().into_owned()).unwrap_or_else(|| "scene".into());
        (dir, path.to_path_buf(), name)
    } else {
        return Err(SceneError::Io {
            file: path.to_path_buf(),
            source: std::io::Error::new(std::io::ErrorKind::NotFound, "no such file or directory"),
        });
    };
    let beside = |file: &str| Some(dir.join(file)).filter(|p| p.is_file() && *p != noisy);
    let reference = match &request.reference_path {
        Some(p) => Some(p.clone()),
        None => beside(REFERENCE_FILE).or_else(|| beside(&format!("{name}_reference.exr"))),
    };
    Ok(Files { reference, variance: beside(VARIANCE_FILE), meta: beside(META_FILE), noisy, name })
}

/// Whether `dir` is a dataset: it holds a noisy image.
pub fn is_dataset_dir(dir: &Path) -> bool {
    dir.join(NOISY_FILE).is_file()
}

/// The datasets among `dir`'s subfolders, in name order (for `--scenes FOLDER`).
pub fn datasets_in(dir: &Path) -> Result<Vec<PathBuf>, SceneError> {
    let io = |source| SceneError::Io { file: dir.to_path_buf(), source };
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(io)? {
        let path = entry.map_err(io)?.path();
        if path.is_dir() && is_dataset_dir(&path) {
            out.push(path);
        }
    }
    out.sort();
    Ok(out)
}

/// The features and variances a scene on disk provides, from its channel names alone.
pub fn provides(path: &Path) -> Result<(BTreeSet<Feature>, BTreeSet<ScalarVar>), SceneError> {
    let files = locate(path, &Request::default())?;
    let (channels, _, _) = exr_io::channel_names(&files.noisy)?;
    let layout = Layout::detect(&channels);
    let mut features: BTreeSet<Feature> = [Feature::Color, Feature::Pixel].into_iter().collect();
    for f in Feature::ALL {
        if f.source() == FeatureSource::Stored(*f)
            && *f != Feature::Color
            && pick(layout.feature(*f), &channels).is_some()
        {
            features.insert(*f);
        }
    }
    for f in Feature::ALL {
        if let FeatureSource::Gradient(base) = f.source() {
            if features.contains(&base) {
                features.insert(*f);
            }
        }
    }
    let separate = match &files.variance {
        Some(file) => exr_io::channel_names(file)?.0,
        None => Vec::new(),
    };
    let variances = ScalarVar::ALL
        .iter()
        .copied()
        .filter(|v| {
            let (alternatives, in_separate_file) = layout.variance(*v);
            pick(alternatives, if in_separate_file { &separate } else { &channels }).is_some()
        })
        .collect();
    Ok((features, variances))
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

/// Load a scene: a directory holding `noisy.exr` (and `reference.exr`,
/// `variance.exr`, `meta.json` where present), or a noisy EXR file.
pub fn load(path: &Path, request: &Request) -> Result<Scene, SceneError> {
    let files = locate(path, request)?;
    let (channels, width, height) = exr_io::channel_names(&files.noisy)?;
    if width == 0 || height == 0 {
        return Err(SceneError::Empty { file: files.noisy.clone() });
    }
    let layout = Layout::detect(&channels);
    let mut notes = Vec::new();

    // Plan every channel to read from the noisy image, so it is decoded once.
    let mut names: Vec<&'static str> = Vec::new();
    let mut plan = |alternatives| -> Option<std::ops::Range<usize>> {
        let chosen = pick(alternatives, &channels)?;
        let start = names.len();
        names.extend_from_slice(chosen);
        Some(start..names.len())
    };
    let color_range = plan(layout.color()).ok_or_else(|| SceneError::MissingChannel {
        file: files.noisy.clone(),
        channel: "R, G, B".into(),
        available: channels.clone(),
    })?;
    let bases: BTreeSet<Feature> = request
        .features
        .iter()
        .filter_map(|f| match f.source() {
            FeatureSource::Stored(b) | FeatureSource::Gradient(b) if b != Feature::Color => Some(b),
            _ => None,
        })
        .collect();
    let mut feature_ranges = BTreeMap::new();
    for &base in &bases {
        if let Some(range) = plan(layout.feature(base)) {
            feature_ranges.insert(base, range);
        }
    }
    let albedo_range = if request.albedo {
        let range = feature_ranges.get(&Feature::Texture).cloned().or_else(|| plan(layout.feature(Feature::Texture)));
        Some(range.ok_or_else(|| SceneError::MissingAlbedo {
            scene: files.name.clone(),
            layout: layout.name(),
            file: files.noisy.clone(),
        })?)
    } else {
        None
    };
    let mut variance_ranges = BTreeMap::new();
    let mut separate_variances = BTreeMap::new();
    // `level` is no stored channel: the pipeline supplies it.
    for &v in request.variances.iter().filter(|v| v.is_stored()) {
        let (alternatives, separate) = layout.variance(v);
        if separate {
            separate_variances.insert(v, alternatives);
        } else if let Some(range) = plan(alternatives) {
            variance_ranges.insert(v, range);
        }
    }
    let noisy = exr_io::read_channels(&files.noisy, &names)?;

    let provided = |layout: Layout| -> Vec<String> {
        Feature::ALL
            .iter()
            .filter(|f| f.source() == FeatureSource::Stored(**f) && pick(layout.feature(**f), &channels).is_some())
            .map(|f| f.name().to_string())
            .chain(["color".into(), "pixel".into()])
            .collect()
    };
    let absent = |what: String, notes: &mut Vec<String>| -> Result<(), SceneError> {
        match request.absent {
            Absent::Refuse => Err(SceneError::MissingFeature {
                scene: files.name.clone(),
                feature: what,
                layout: layout.name(),
                file: files.noisy.clone(),
                provided: provided(layout),
            }),
            Absent::Zero => {
                notes.push(format!("`{what}` is absent from this scene and is read as 0 (--absent zero)"));
                Ok(())
            }
        }
    };

    let gather = |range: &std::ops::Range<usize>| -> Vec<[f32; 3]> {
        let mut out = vec![[0f32; 3]; width * height];
        for (c, k) in range.clone().enumerate() {
            for (px, v) in out.iter_mut().zip(&noisy.data[k]) {
                px[c] = *v;
            }
        }
        out
    };

    let mut color = gather(&color_range);
    let bad = preprocess::sanitize(color.as_flattened_mut(), COLOR_LIMIT);
    if bad > 0 {
        notes.push(format!("noisy colour: {bad} non-finite values replaced by 0"));
    }

    let albedo = albedo_range.map(|range| {
        let mut values = gather(&range);
        let bad = preprocess::sanitize(values.as_flattened_mut(), f32::MAX);
        if bad > 0 {
            notes.push(format!("albedo: {bad} non-finite values replaced by 0"));
        }
        values
    });

    let mut stored = BTreeMap::new();
    for &base in &bases {
        let Some(range) = feature_ranges.get(&base) else {
            stored.insert(base, vec![[0f32; 3]; width * height]);
            continue;
        };
        let mut values = gather(range);
        let bad = preprocess::sanitize(values.as_flattened_mut(), f32::MAX);
        if bad > 0 {
            notes.push(format!("{base}: {bad} non-finite values replaced by 0"));
        }
        let scale = preprocess::normalise_vectors(&mut values);
        notes.push(format!("{base}: divided by {scale:.6} (99.9th percentile of lengths)"));
        stored.insert(base, values);
    }
    let mut features = BTreeMap::new();
    for &f in &request.features {
        match f.source() {
            FeatureSource::Stored(Feature::Color) | FeatureSource::Coordinates => {}
            FeatureSource::Stored(base) => {
                if !feature_ranges.contains_key(&base) {
                    absent(f.name().to_string(), &mut notes)?;
                }
                features.insert(f, stored[&base].clone());
            }
            FeatureSource::Gradient(base) => {
                let mut g = preprocess::sobel(&stored[&base], width, height);
                if feature_ranges.contains_key(&base) {
                    let scale = preprocess::normalise_vectors(&mut g);
                    notes.push(format!("{f}: Sobel magnitude divided by {scale:.6}"));
                } else {
                    absent(f.name().to_string(), &mut notes)?;
                }
                features.insert(f, g);
            }
        }
    }

    let mut variances = BTreeMap::new();
    // `level` is no stored channel: the pipeline supplies it.
    for &v in request.variances.iter().filter(|v| v.is_stored()) {
        let values = if let Some(range) = variance_ranges.get(&v) {
            Some(layout.variance_values(&noisy.data[range.clone()]))
        } else if let (Some(alternatives), Some(file)) = (separate_variances.get(&v), &files.variance) {
            let (vchannels, vw, vh) = exr_io::channel_names(file)?;
            check_size(file, (vw, vh), &files.noisy, (width, height))?;
            match pick(alternatives, &vchannels) {
                Some(chosen) => Some(layout.variance_values(&exr_io::read_channels(file, chosen)?.data)),
                None => None,
            }
        } else {
            None
        };
        let values = match values {
            Some(mut values) => {
                let bad = preprocess::sanitize(&mut values, f32::MAX);
                if bad > 0 {
                    notes.push(format!("{v}: {bad} non-finite values replaced by 0"));
                }
                let scale = preprocess::normalise_scalars(&mut values);
                notes.push(format!("{v}: divided by {scale:.6e}"));
                values
            }
            None => {
                absent(v.name().to_string(), &mut notes)?;
                vec![0.0; width * height]
            }
        };
        variances.insert(v, values);
    }

    let reference = match (&files.reference, request.reference) {
        (Some(file), true) => {
            let (rchannels, rw, rh) = exr_io::channel_names(file)?;
            check_size(file, (rw, rh), &files.noisy, (width, height))?;
            let chosen = pick(layout.color(), &rchannels).ok_or_else(|| SceneError::MissingChannel {
                file: file.clone(),
                channel: "R, G, B".into(),
                available: rchannels.clone(),
            })?;
            let data = exr_io::read_channels(file, chosen)?.data;
            let mut rgb: Vec<[f32; 3]> = (0..width * height).map(|p| [data[0][p], data[1][p], data[2][p]]).collect();
            let bad = preprocess::sanitize(rgb.as_flattened_mut(), COLOR_LIMIT);
            if bad > 0 {
                notes.push(format!("reference: {bad} non-finite values replaced by 0"));
            }
            Some(rgb)
        }
        _ => None,
    };

    let (meta_spp, meta_name) = match &files.meta {
        Some(meta) => read_meta(meta)?,
        None => (None, None),
    };
    let spp = request.spp.or(meta_spp);

    Ok(Scene {
        name: meta_name.unwrap_or(files.name),
        width,
        height,
        spp,
        layout: Some(layout.name()),
        color,
        reference,
        features,
        variances,
        albedo,
        notes,
    })
}

fn check_size(file: &Path, size: (usize, usize), noisy: &Path, expected: (usize, usize)) -> Result<(), SceneError> {
    if size != expected {
        return Err(SceneError::SizeMismatch { file: file.to_path_buf(), size, noisy: noisy.to_path_buf(), expected });
    }
    Ok(())
}
