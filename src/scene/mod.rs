//! Scene data: noisy colour, features, variances and the reference, loaded
//! from renderers' EXR files with only the channels a run asks for.

pub mod exr_io;
pub mod import;
mod load;
mod needs;
pub mod preprocess;
pub mod sequence;

pub use load::{load, prepare};
pub use needs::{Holds, Missing, MissingInput, Needs};
pub use sequence::{is_sequence, Sequence};

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use crate::lang::{Expr, Feature, FeatureSource, ScalarVar};
use import::{pick, Layout};

#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The system's reason in the message (`cause`, not a `source`, which the edges would print again).
    #[error("{}: {cause}", file.display())]
    Io { file: PathBuf, cause: std::io::Error },
    #[error("{}: not a readable EXR image: {message}", file.display())]
    Exr { file: PathBuf, message: String },
    #[error("{}: no channel `{channel}` (the file has: {})", file.display(), available.join(", "))]
    MissingChannel { file: PathBuf, channel: String, available: Vec<String> },
    #[error("scene `{scene}` has no `{feature}` ({origin} provides: {}); \
             the expression needs it. {}Use an expression without it, or have absent inputs read as 0",
             provided.join(", "), how_to_get.map(|h| format!("The renderer writes it when asked: {h}. ")).unwrap_or_default())]
    MissingFeature {
        scene: String,
        feature: String,
        origin: Origin,
        provided: Vec<String>,
        how_to_get: Option<&'static str>,
    },
    #[error(
        "scene `{scene}` has no albedo ({origin} has no texture/albedo); \
             demodulation divides by it: use a pipeline without `demodulate`"
    )]
    MissingAlbedo { scene: String, origin: Origin },
    #[error("{}: image is {}x{}, but the noisy image {} is {}x{}", file.display(), size.0, size.1, noisy.display(), expected.0, expected.1)]
    SizeMismatch { file: PathBuf, size: (usize, usize), noisy: PathBuf, expected: (usize, usize) },
    #[error(
        "scene `{scene}` has no motion vectors ({origin}), which the temporal stage reprojects the frame before \
         by: render with Blender's Vector pass (View Layer Properties > Passes > Data > Vector, motion blur off) or \
         write `Vector.X`, `Vector.Y` channels (docs/SCENES.md)"
    )]
    MissingMotion { scene: String, origin: Origin },
    #[error("{}: {message}", path.display())]
    Sequence { path: PathBuf, message: String },
    #[error("{}: no noisy image here (expected {} or an .exr file)", path.display(), NOISY_FILE)]
    NotAScene { path: PathBuf },
    #[error("{}: image is empty", file.display())]
    Empty { file: PathBuf },
    #[error("{}: {message}", file.display())]
    Meta { file: PathBuf, message: String },
    #[error("{}: {}", file.display(), match asked {
        Some(asked) => format!("no view layer `{asked}` (the file has: {})", layers.join(", ")),
        None => format!("several view layers ({}): choose one with --view-layer", layers.join(", ")),
    })]
    ViewLayer { file: PathBuf, asked: Option<String>, layers: Vec<String> },
    #[error(transparent)]
    Write(#[from] crate::io::WriteError),
}

impl SceneError {
    pub(crate) fn io(file: &Path, cause: std::io::Error) -> Self {
        SceneError::Io { file: file.to_path_buf(), cause }
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
    /// The view layer of a Blender multilayer file, where it has several.
    pub view_layer: Option<String>,
    /// Load the motion vectors and the raw surface (normal, depth) the
    /// temporal stage reads ([`Motion`]): a frame of a sequence.
    pub motion: bool,
}

impl Request {
    /// Exactly the inputs of `expr`, plus the reference.
    pub fn for_expr(expr: &Expr) -> Self {
        Request { features: expr.features(), variances: expr.stored_variables(), reference: true, ..Default::default() }
    }
}

/// Where a scene's images came from, for messages.
#[derive(Clone, Debug, PartialEq)]
pub enum Origin {
    /// A renderer's EXR files, read by their channel layout.
    File { layout: Layout, file: PathBuf },
    /// Arrays handed over in memory (the Python module's `denoise`).
    Arrays,
}

impl Origin {
    /// The renderer's channel layout, for files.
    pub fn layout(&self) -> Option<&'static str> {
        match self {
            Origin::File { layout, .. } => Some(layout.name()),
            Origin::Arrays => None,
        }
    }
}

impl std::fmt::Display for Origin {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Origin::File { layout, file } => write!(f, "{} data from {}", layout.name(), file.display()),
            Origin::Arrays => f.write_str("the arrays given"),
        }
    }
}

/// A scene's images as its renderer made them, before [`prepare`] sanitises
/// and normalises them: what a dataset's files hold, or arrays in memory.
#[derive(Clone, Debug)]
pub struct Images {
    pub name: String,
    pub width: usize,
    pub height: usize,
    /// Samples per pixel of the noisy colour, when known.
    pub spp: Option<u32>,
    pub origin: Origin,
    /// Noisy colour, `width`×`height` pixels, row-major.
    pub color: Vec<[f32; 3]>,
    /// Stored features (never colour, pixel or gradients), zero-padded to 3
    /// components; the texture feature doubles as the albedo demodulation divides by.
    pub features: BTreeMap<Feature, Vec<[f32; 3]>>,
    /// The stored features the source has, decoded or not (for messages).
    pub provided: BTreeSet<Feature>,
    /// Per-pixel scalar variances (a colour variance is the mean over its channels).
    pub variances: BTreeMap<ScalarVar, Vec<f32>>,
    pub reference: Option<Vec<[f32; 3]>>,
    /// What the temporal stage reads ([`Motion`]), where the source has
    /// motion vectors (and the request asked for them).
    pub motion: Option<Motion>,
}

/// One thing loading a render did to it.
#[derive(Clone, Debug, PartialEq)]
pub struct Note {
    pub text: String,
    /// Whether it changed or questions the render's values (non-finite or
    /// limited values, negative colour, an input read as 0), which a
    /// command says before filtering; else a scale a feature was divided by,
    /// told only where asked.
    pub warns: bool,
}

impl Note {
    pub fn warning(text: String) -> Note {
        Note { text, warns: true }
    }

    pub fn info(text: String) -> Note {
        Note { text, warns: false }
    }
}

impl std::fmt::Display for Note {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.text)
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
    /// What the temporal stage reads, when the request asked for it.
    pub motion: Option<Motion>,
    /// What loading did that a user should know: sanitised values, scales, absent features read as zero.
    pub notes: Vec<Note>,
}

/// What the temporal stage reads of a frame besides its colour
/// (docs/SEMANTICS.md, "The temporal stage"), as the renderer wrote it, not
/// normalised: features are normalised frame by frame, and the history's
/// test compares one frame's surface with the next's.
#[derive(Clone, Debug, PartialEq)]
pub struct Motion {
    /// Where the surface seen at a pixel was in the frame before, relative to
    /// the pixel: (dx, dy) in pixels, x right and y down (Blender's Vector
    /// pass X and −Y; docs/SCENES.md).
    pub vectors: Vec<[f32; 2]>,
    /// Each pixel's surface: the normal's direction (unit, or zero where
    /// nothing was hit) and the depth (0 where nothing was hit).
    pub surface: Vec<[f32; 4]>,
    /// Each pixel's albedo clipped to [0, 1] (and a 0): the surface's
    /// material, which the history's test compares too (0 where the render has none).
    pub albedo: Vec<[f32; 4]>,
}

impl Motion {
    /// A frame's motion from its vectors (x right, y down) and its raw
    /// normals, depths (the first component) and albedo (none: 0).
    pub fn new(vectors: Vec<[f32; 2]>, normal: &[[f32; 3]], depth: &[[f32; 3]], albedo: Option<&[[f32; 3]]>) -> Self {
        Motion {
            vectors,
            surface: normal.iter().zip(depth).map(|(n, z)| Self::surface_of(*n, z[0])).collect(),
            albedo: match albedo {
                Some(albedo) => albedo.iter().copied().map(Self::albedo_of).collect(),
                None => vec![[0.0; 4]; normal.len()],
            },
        }
    }

    /// The surface of a pixel from its raw normal and depth.
    pub fn surface_of(normal: [f32; 3], depth: f32) -> [f32; 4] {
        let d = crate::pipeline::direction(normal.map(f64::from));
        [d[0] as f32, d[1] as f32, d[2] as f32, depth.max(0.0)]
    }

    /// The material of a pixel from its raw albedo.
    pub fn albedo_of(albedo: [f32; 3]) -> [f32; 4] {
        let a = albedo.map(|c| if c.is_finite() { c.clamp(0.0, 1.0) } else { 0.0 });
        [a[0], a[1], a[2], 0.0]
    }
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
            motion: None,
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

    /// [`Scene::feature`], or the data error naming this scene and the feature.
    pub fn required_feature(&self, f: Feature) -> Result<&[[f32; 3]], MissingInput> {
        self.feature(f).ok_or_else(|| MissingInput { scene: self.name.clone(), missing: Missing::Feature(f) })
    }

    pub fn variance(&self, v: ScalarVar) -> Option<&[f32]> {
        self.variances.get(&v).map(Vec::as_slice)
    }

    /// This scene repeated to at least `side` pixels each way (colour, features and
    /// variances; no reference): the same content statistics, a larger dispatch.
    pub fn tiled(&self, side: usize) -> Scene {
        self.tiled_to(self.width.max(side), self.height.max(side))
    }

    /// This scene repeated (or cut) to `tw`×`th` pixels: colour, features,
    /// variances and the temporal stage's inputs (no reference).
    pub fn tiled_to(&self, tw: usize, th: usize) -> Scene {
        let (w, h) = (self.width, self.height);
        fn tiled<T: Copy>(data: &[T], (w, h): (usize, usize), (tw, th): (usize, usize)) -> Vec<T> {
            (0..th).flat_map(|y| (0..tw).map(move |x| data[(y % h) * w + x % w])).collect()
        }
        let mut out = Scene::from_color(format!("{} (tiled)", self.name), tw, th, tiled(&self.color, (w, h), (tw, th)));
        out.spp = self.spp;
        out.features = self.features.iter().map(|(f, v)| (*f, tiled(v, (w, h), (tw, th)))).collect();
        out.variances = self.variances.iter().map(|(k, v)| (*k, tiled(v, (w, h), (tw, th)))).collect();
        out.albedo = self.albedo.as_ref().map(|a| tiled(a, (w, h), (tw, th)));
        out.motion = self.motion.as_ref().map(|m| Motion {
            vectors: tiled(&m.vectors, (w, h), (tw, th)),
            surface: tiled(&m.surface, (w, h), (tw, th)),
            albedo: tiled(&m.albedo, (w, h), (tw, th)),
        });
        out
    }

    /// This scene as a frame of a still sequence (a camera and a world that
    /// do not move): no motion, the surface from its normal and depth
    /// features and the albedo from its raw albedo (zero where it has
    /// none), as a temporal stage reads them. For timing and tests of a
    /// temporal pipeline on a still render.
    pub fn still(&self) -> Scene {
        let n = self.pixels();
        let normal = self.features.get(&Feature::Normal);
        let depth = self.features.get(&Feature::Depth);
        let surface = (0..n)
            .map(|p| Motion::surface_of(normal.map_or([0.0; 3], |v| v[p]), depth.map_or(0.0, |v| v[p][0])))
            .collect();
        let albedo = (0..n).map(|p| Motion::albedo_of(self.albedo.as_ref().map_or([0.0; 3], |a| a[p]))).collect();
        Scene { motion: Some(Motion { vectors: vec![[0.0; 2]; n], surface, albedo }), ..self.clone() }
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
            motion: self.motion.as_ref().map(|m| Motion {
                vectors: rows(&m.vectors, self.width, x, y, width, height),
                surface: rows(&m.surface, self.width, x, y, width, height),
                albedo: rows(&m.albedo, self.width, x, y, width, height),
            }),
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
            cause: std::io::Error::new(std::io::ErrorKind::NotFound, "no such file or directory"),
        });
    };
    let beside = |file: &str| Some(dir.join(file)).filter(|p| p.is_file() && *p != noisy);
    // A frame file of a sequence (`noisy/frame_0005.exr`) has its reference
    // of the same name where the sequence's are.
    let in_reference_folder = || {
        let file_name = path.file_name().filter(|_| path.is_file())?;
        sequence::reference_folders(&dir).into_iter().map(|folder| folder.join(file_name)).find(|p| p.is_file())
    };
    let reference = match &request.reference_path {
        Some(p) => Some(p.clone()),
        None => {
            beside(REFERENCE_FILE).or_else(|| beside(&format!("{name}_reference.exr"))).or_else(in_reference_folder)
        }
    };
    Ok(Files { reference, variance: beside(VARIANCE_FILE), meta: beside(META_FILE), noisy, name })
}

/// Whether `dir` is a dataset: it holds a noisy image.
pub fn is_dataset_dir(dir: &Path) -> bool {
    dir.join(NOISY_FILE).is_file()
}

/// The datasets among `dir`'s subfolders, in name order (for `--scenes FOLDER`).
pub fn datasets_in(dir: &Path) -> Result<Vec<PathBuf>, SceneError> {
    let io = |cause| SceneError::Io { file: dir.to_path_buf(), cause };
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

/// `stored` features with what every scene derives from them: colour, pixel
/// position, the guide (from the colour), and the gradient of each stored feature.
pub fn with_derived(stored: BTreeSet<Feature>) -> BTreeSet<Feature> {
    let mut features = stored;
    features.extend([Feature::Color, Feature::Pixel, Feature::Guide]);
    for f in Feature::ALL {
        if let FeatureSource::Gradient(base) = f.source() {
            if features.contains(&base) {
                features.insert(*f);
            }
        }
    }
    features
}

/// Whether a render on disk has motion vectors (the temporal stage's input),
/// from its channel names alone.
pub fn has_motion(path: &Path, view_layer: Option<&str>) -> Result<bool, SceneError> {
    let files = locate(path, &Request::default())?;
    let (names, _, _) = exr_io::channel_names(&files.noisy)?;
    let view = import::Channels::of(&files.noisy, names, view_layer)?;
    Ok(pick(view.layout().motion(), &view.names).is_some())
}

/// The samples per pixel a render on disk says it took, where its header
/// says (Cycles writes `cycles.<view layer>.samples`; through `view_layer`,
/// else the first layer that says).
pub fn samples_per_pixel(path: &Path, view_layer: Option<&str>) -> Result<Option<u32>, SceneError> {
    let files = locate(path, &Request::default())?;
    let attributes = exr_io::text_attributes(&files.noisy)?;
    let mut said: Vec<(&String, &String)> = attributes
        .iter()
        .filter(|(name, _)| {
            name.strip_prefix("cycles.")
                .and_then(|rest| rest.strip_suffix(".samples"))
                .is_some_and(|layer| view_layer.is_none_or(|wanted| wanted == layer))
        })
        .collect();
    said.sort();
    Ok(said.first().and_then(|(_, value)| value.trim().parse().ok()))
}

/// Whether a render on disk sampled each pixel at one point, the same in
/// every frame: Cycles at one sample, as its header says (from two samples
/// on it jitters over the pixel; docs/JOURNAL.md, "The 1-spp frames are not
/// what their references average"). No other renderer is known to.
pub fn point_sampled(path: &Path, view_layer: Option<&str>) -> Result<bool, SceneError> {
    Ok(point_sampled_at(samples_per_pixel(path, view_layer)?))
}

/// [`point_sampled`] for a render whose header gave `samples` ([`samples_per_pixel`]).
pub fn point_sampled_at(samples: Option<u32>) -> bool {
    samples == Some(1)
}

/// The features and variances a scene on disk provides, from its channel
/// names alone (through `view_layer` in a Blender multilayer file).
pub fn provides(path: &Path, view_layer: Option<&str>) -> Result<(BTreeSet<Feature>, BTreeSet<ScalarVar>), SceneError> {
    let files = locate(path, &Request::default())?;
    let (names, _, _) = exr_io::channel_names(&files.noisy)?;
    let view = import::Channels::of(&files.noisy, names, view_layer)?;
    let (channels, layout) = (&view.names, view.layout());
    let features = with_derived(layout.stored_features(channels));
    let separate = match &files.variance {
        Some(file) => exr_io::channel_names(file)?.0,
        None => Vec::new(),
    };
    let variances = ScalarVar::ALL
        .iter()
        .copied()
        .filter(|v| {
            let (alternatives, in_separate_file) = layout.variance(*v);
            pick(alternatives, if in_separate_file { &separate } else { channels }).is_some()
        })
        .collect();
    Ok((features, variances))
}
