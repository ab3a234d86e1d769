//! `filterjit._filterjit`: the Python binding, thin by design. Arrays become
//! `scene::Images`, and everything else is the library's: the same filter
//! choice (`denoise::Choice`), the same scene preparation (`scene::prepare`),
//! kernels and device code as `filterjit filter`, so that both give the same
//! pixels. `python/filterjit/__init__.py` re-exports these functions.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::sync::{Arc, Mutex};

use clap::ValueEnum;
use numpy::{PyArray1, PyArrayDyn, PyArrayMethods, PyUntypedArray, PyUntypedArrayMethods};
use pyo3::exceptions::{PyRuntimeError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};

use filterjit::denoise::{Choice, InputNames, Provided};
use filterjit::environment::Environment;
use filterjit::export::{Code, Target};
use filterjit::gpu::Gpu;
use filterjit::gpu::TemporalState;
use filterjit::jit::{self, OutputFormat, ValidatedKernel};
use filterjit::lang::{Feature, ScalarVar};
use filterjit::pipeline::FilterPipeline;
use filterjit::scene::{self, import, Images, Missing, Motion, Origin};

/// The device, opened on first use and kept for the process (adapter chosen
/// as the command line chooses it, from `FILTERJIT_BACKEND` and `FILTERJIT_ADAPTER`).
static DEVICE: Mutex<Option<Arc<Gpu>>> = Mutex::new(None);

/// Kernels compiled in this process, by filter, pipeline and radius.
type KernelCache = Mutex<HashMap<(String, String), Arc<ValidatedKernel>>>;
static KERNELS: std::sync::LazyLock<KernelCache> = std::sync::LazyLock::new(Default::default);

fn device() -> PyResult<Arc<Gpu>> {
    let mut held = DEVICE.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
    if let Some(gpu) = held.as_ref() {
        return Ok(gpu.clone());
    }
    let env = Environment::read().map_err(runtime)?;
    let gpu = Arc::new(Gpu::open(&env.adapter).map_err(runtime)?);
    *held = Some(gpu.clone());
    Ok(gpu)
}

fn value(e: impl Into<anyhow::Error>) -> PyErr {
    PyValueError::new_err(format!("{:#}", e.into()))
}

fn runtime(e: impl Into<anyhow::Error>) -> PyErr {
    PyRuntimeError::new_err(format!("{:#}", e.into()))
}

/// An image argument read into row-major pixels: a float32 array of shape
/// (H, W, C) or (H, W) (C = 1), every value finite.
struct Image {
    height: usize,
    width: usize,
    channels: usize,
    /// The array's shape as given, for messages.
    shape: Vec<usize>,
    values: Vec<f32>,
}

/// A shape as Python prints it: `(64, 64, 3)`, `(64,)`.
fn shape_text(shape: &[usize]) -> String {
    match shape {
        [one] => format!("({one},)"),
        _ => format!("({})", shape.iter().map(|d| d.to_string()).collect::<Vec<_>>().join(", ")),
    }
}

impl Image {
    fn read(name: &str, array: &Bound<'_, PyAny>) -> PyResult<Image> {
        let untyped = array.cast::<PyUntypedArray>().map_err(|_| {
            PyTypeError::new_err(format!(
                "`{name}` must be a numpy array of float32, not {}",
                array.get_type().name().map(|n| n.to_string()).unwrap_or_else(|_| "this object".into())
            ))
        })?;
        let typed = untyped.cast::<PyArrayDyn<f32>>().map_err(|_| {
            PyTypeError::new_err(format!(
                "`{name}` has dtype {}, but filterjit takes float32 (convert with `.astype(numpy.float32)`)",
                untyped.dtype()
            ))
        })?;
        let shape = typed.shape().to_vec();
        let (height, width, channels) = match shape[..] {
            [h, w] => (h, w, 1),
            [h, w, c] => (h, w, c),
            _ => {
                return Err(PyValueError::new_err(format!(
                    "`{name}` has shape {}; images are (height, width, channels) or (height, width)",
                    shape_text(&shape)
                )))
            }
        };
        if height == 0 || width == 0 || channels == 0 {
            return Err(PyValueError::new_err(format!("`{name}` is empty (shape {})", shape_text(&shape))));
        }
        let readonly = typed.readonly();
        let values: Vec<f32> = readonly.as_array().iter().copied().collect();
        if let Some(k) = values.iter().position(|v| !v.is_finite()) {
            let c = k % channels;
            let (y, x) = ((k / channels) / width, (k / channels) % width);
            return Err(PyValueError::new_err(format!(
                "`{name}` has a non-finite value ({}) at row {y}, column {x}, channel {c}",
                values[k]
            )));
        }
        Ok(Image { height, width, channels, shape, values })
    }

    /// Refuses this image unless it is `size` (the size of the argument
    /// `like`) with one of `channels`, saying what it must be and, where the
    /// shape tells, how to get there.
    fn check(&self, name: &str, (size, like): ((usize, usize), &str), channels: &[usize]) -> PyResult<()> {
        if (self.height, self.width) == size && channels.contains(&self.channels) {
            return Ok(());
        }
        // An image sized by itself (the colour) is held to its channels alone.
        let ((h, w), whose) = match name == like {
            true => (("height".to_string(), "width".to_string()), String::new()),
            false => ((size.0.to_string(), size.1.to_string()), format!(" (the height and width of `{like}`)")),
        };
        let wanted: Vec<String> =
            channels.iter().map(|&c| if c == 1 { format!("({h}, {w})") } else { format!("({h}, {w}, {c})") }).collect();
        let hint = if channels.contains(&3) && self.channels == 4 {
            format!("; drop the alpha channel with `{name}[..., :3]`")
        } else if self.shape.len() == 3 && channels.contains(&self.shape[0]) && !channels.contains(&self.shape[2]) {
            format!("; its channels come first: move them last with `{name}.transpose(1, 2, 0)`")
        } else {
            String::new()
        };
        Err(PyValueError::new_err(format!(
            "`{name}` must be {}{whose}, not {}{hint}",
            wanted.join(" or "),
            shape_text(&self.shape)
        )))
    }

    /// This image as RGB pixels, checked to be `size` with one of `channels`
    /// (1 channel fills the first component, as a depth channel is stored).
    fn pixels(&self, name: &str, size: ((usize, usize), &str), channels: &[usize]) -> PyResult<Vec<[f32; 3]>> {
        self.check(name, size, channels)?;
        Ok(self
            .values
            .chunks_exact(self.channels)
            .map(|c| {
                let mut p = [0.0; 3];
                p[..c.len()].copy_from_slice(c);
                p
            })
            .collect())
    }

    /// The per-pixel mean over channels, as every renderer's variance is read.
    fn channel_mean(&self) -> Vec<f32> {
        let planes: Vec<Vec<f32>> =
            (0..self.channels).map(|c| self.values.iter().skip(c).step_by(self.channels).copied().collect()).collect();
        import::channel_mean(&planes)
    }
}

fn rgb(name: &str, array: &Bound<'_, PyAny>) -> PyResult<(usize, usize, Vec<[f32; 3]>)> {
    let image = Image::read(name, array)?;
    let size = (image.height, image.width);
    Ok((size.0, size.1, image.pixels(name, (size, name), &[3])?))
}

fn parse_pipeline(pipeline: Option<&str>) -> PyResult<Option<FilterPipeline>> {
    pipeline.map(|p| p.parse::<FilterPipeline>().map_err(value)).transpose()
}

/// A count argument (`spp`, `radius`) taken as any Python int and refused,
/// by name, where it is negative or too large.
fn count(name: &str, value: Option<i64>) -> PyResult<Option<u32>> {
    value
        .map(|v| {
            u32::try_from(v)
                .map_err(|_| PyValueError::new_err(format!("`{name}` must be from 0 to {}, not {v}", u32::MAX)))
        })
        .transpose()
}

/// The keyword arguments a frame gave, as a caller wrote them.
fn given_names(given: &Provided) -> String {
    let mut names: Vec<&str> = INPUTS
        .iter()
        .filter(|(_, feature)| match feature {
            Some(feature) => given.features.contains(feature),
            None => given.variances.contains(&ScalarVar::ColorVariance),
        })
        .map(|(name, _)| *name)
        .collect();
    if given.motion {
        names.push("motion");
    }
    match names.is_empty() {
        true => "colour alone".to_string(),
        false => format!("colour, {}", names.join(", ")),
    }
}

/// Denoise a render on the GPU and return the filtered colour.
///
/// :param color: noisy linear RGB, float32, shape (H, W, 3).
/// :param albedo: the surfaces' albedo (Mitsuba's ``albedo`` AOV), (H, W, 3).
/// :param normal: shading normals (Mitsuba's ``sh_normal``), (H, W, 3).
/// :param position: world positions (Mitsuba's ``position``), (H, W, 3).
/// :param depth: depth (Mitsuba's ``depth``), (H, W) or (H, W, 1).
/// :param variance: per-pixel sample variance of the colour, (H, W), (H, W, 1)
///     or (H, W, 3) (the mean over channels is used, as from files).
/// :param spp: samples per pixel of ``color``: from 8 on, the filter chosen
///     runs two à-trous passes where it has three (from 64, one) on an
///     image of up to 128x128 pixels, from twice as many on one twice as
///     wide, as ``filterjit filter`` does.
/// :param filter: a shipped filter's name (``"@evolvedAtrous3x3"``), an
///     expression, or ``"@FILE:NAME"`` (a hall of fame entry). By default the
///     best shipped filter whose inputs are given, by the rule the command
///     line uses (see :func:`choose`). ``"@realtime"`` without a ``pipeline``
///     runs ``"@realtimeSparse"`` where the colour's median pixel is under 0.15 of its mean.
/// :param pipeline: the filter pipeline, e.g. ``"outliers=2,demodulate,atrous=5"``;
///     by default the one the filter was stored with.
/// :param radius: window radius of the ``window`` form; by default the stored one, else 5.
/// :param point_sampled: whether the renderer sampled every pixel at one
///     point (Blender Cycles at 1 sample: the header's
///     ``cycles.ViewLayer.samples`` is 1) while a reference integrates its
///     pixel filter: the filter then ends with that filter
///     (``pixelfilter=0.4``) unless ``pipeline`` is given, as ``filterjit
///     filter`` does by the header.
/// :param motion, surface_normal: accepted and not read (one image has no
///     history), so that a sequence's frame passes whole; :class:`Denoiser`
///     reads them.
/// :returns: float32 array of shape (H, W, 3).
/// :raises TypeError: an input is not a float32 numpy array.
/// :raises ValueError: a shape differs from ``color``'s, a value is not
///     finite, an expression is invalid (with its line and column), a filter
///     is unknown, or the filter needs an input that was not given.
/// :raises RuntimeError: no GPU adapter, or the device failed.
///
/// The GIL is released while the GPU works.
#[pyfunction]
#[pyo3(signature = (color, *, albedo=None, normal=None, position=None, depth=None, variance=None,
                    spp=None, filter=None, pipeline=None, radius=None, point_sampled=false, motion=None,
                    surface_normal=None))]
#[allow(clippy::too_many_arguments)]
fn denoise<'py>(
    py: Python<'py>,
    color: &Bound<'py, PyAny>,
    albedo: Option<&Bound<'py, PyAny>>,
    normal: Option<&Bound<'py, PyAny>>,
    position: Option<&Bound<'py, PyAny>>,
    depth: Option<&Bound<'py, PyAny>>,
    variance: Option<&Bound<'py, PyAny>>,
    spp: Option<i64>,
    filter: Option<&str>,
    pipeline: Option<&str>,
    radius: Option<i64>,
    point_sampled: bool,
    motion: Option<&Bound<'py, PyAny>>,
    surface_normal: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyAny>> {
    let (spp, radius) = (count("spp", spp)?, count("radius", radius)?);
    // One image has no history: a sequence's frame passed whole brings what only the history reads.
    let _ = (motion, surface_normal);
    let (images, given) = arrays(color, [albedo, normal, position, depth, variance], MotionArguments::default(), spp)?;
    let pipeline = parse_pipeline(pipeline)?;
    let choice = Choice::asked_or_best(filter, pipeline, radius, &given).map_err(value)?;
    check_given(&choice, &given)?;
    let request = scene::Request { reference: false, ..choice.request() };
    let (height, width) = (images.height, images.width);
    let scene = scene::prepare(images, &request).map_err(value)?;
    // As `filterjit filter`: a chosen filter may give way to its variant for
    // the render's light, and run one pass fewer on a render of many samples.
    let choice = choice
        .for_light(&scene.color, pipeline.is_some())
        .map_err(value)?
        .for_point_sampled(point_sampled, pipeline.is_some())
        .for_samples(spp, (width, height), pipeline.is_some());
    let kernel = kernel(&choice)?;
    let gpu = device()?;
    let filtered = py.detach(|| filterjit::denoise::filter(&gpu, &choice, &kernel, &scene)).map_err(runtime)?;
    image_array(py, &filtered.color, height, width)
}

/// A filtered image as a float32 (H, W, 3) array.
fn image_array<'py>(py: Python<'py>, color: &[[f32; 4]], height: usize, width: usize) -> PyResult<Bound<'py, PyAny>> {
    let flat: Vec<f32> = color.iter().flat_map(|c| [c[0], c[1], c[2]]).collect();
    Ok(PyArray1::from_vec(py, flat).reshape([height, width, 3])?.into_any())
}

/// A frame's motion arguments: its vectors (float32 (H, W, 2), Blender's
/// Vector pass X and Y: where the surface was the frame before minus where
/// it is, in pixels, y up), and the primary hit's normal for the history's
/// surface test where it is not the `normal` given (Blender's Normal pass
/// beside its Denoising Normal, which follows mirrors to what they show).
#[derive(Default)]
struct MotionArguments<'a, 'py> {
    vectors: Option<&'a Bound<'py, PyAny>>,
    surface_normal: Option<&'a Bound<'py, PyAny>>,
}

/// The arrays of a call as a render's raw images, and what they provide:
/// the colour, the images of `INPUTS` in its order, and a frame's motion,
/// whose vectors need the raw normal and depth beside them.
fn arrays(
    color: &Bound<'_, PyAny>,
    inputs: [Option<&Bound<'_, PyAny>>; 5],
    motion: MotionArguments<'_, '_>,
    spp: Option<u32>,
) -> PyResult<(Images, Provided)> {
    let (height, width, color) = rgb("color", color)?;
    let size = (height, width);
    let mut features = BTreeMap::new();
    let mut variances = BTreeMap::new();
    for ((name, feature), array) in INPUTS.iter().zip(inputs) {
        let Some(array) = array else { continue };
        let image = Image::read(name, array)?;
        match feature {
            Some(feature) => {
                features.insert(*feature, image.pixels(name, (size, "color"), &[feature.dimension()])?);
            }
            None => {
                image.check(name, (size, "color"), &[1, 3])?;
                variances.insert(ScalarVar::ColorVariance, image.channel_mean());
            }
        }
    }
    let surface_normal = match motion.surface_normal {
        Some(array) => Some(Image::read("surface_normal", array)?.pixels("surface_normal", (size, "color"), &[3])?),
        None => None,
    };
    let motion = match motion.vectors {
        None => None,
        Some(array) => {
            let image = Image::read("motion", array)?;
            image.check("motion", (size, "color"), &[2])?;
            let vectors = image.values.chunks_exact(2).map(|v| [v[0], -v[1]]).collect();
            // The surface test reads the surface normal (else the normal) and the depth as given.
            let (Some(normal), Some(depth)) =
                (surface_normal.as_ref().or(features.get(&Feature::Normal)), features.get(&Feature::Depth))
            else {
                return Err(PyValueError::new_err(
                    "`motion` needs `normal` and `depth` beside it: the temporal stage tests each pixel's history \
                     against the surface it was on (pass normal= and depth=)",
                ));
            };
            Some(Motion::new(vectors, normal, depth, features.get(&Feature::Texture).map(Vec::as_slice)))
        }
    };
    let provided: BTreeSet<Feature> = features.keys().copied().collect();
    let given =
        Provided { motion: motion.is_some(), ..Provided::new(provided.clone(), variances.keys().copied().collect()) };
    let images = Images {
        name: "arrays".into(),
        width,
        height,
        spp,
        origin: Origin::Arrays,
        color,
        features,
        provided,
        variances,
        reference: None,
        motion,
    };
    Ok((images, given))
}

/// Refuses a filter that reads an input the call does not give, naming the argument.
fn check_given(choice: &Choice, given: &Provided) -> PyResult<()> {
    let missing = choice.missing(given);
    if missing.is_empty() {
        return Ok(());
    }
    let arguments: Vec<String> = missing.iter().map(|m| argument_for(*m, given.sequence)).collect();
    let names: Vec<String> = missing.iter().map(|m| m.to_string()).collect();
    Err(PyValueError::new_err(format!(
        "filter {} (pipeline {}) reads {}, which the call does not give: {}",
        choice.describe(),
        choice.pipeline,
        names.join(", "),
        arguments.join("; ")
    )))
}

/// Denoises the frames of a sequence in order, carrying the temporal
/// state from each frame to the next: what an interactive renderer calls
/// once a frame.
///
/// :param filter: as :func:`denoise`'s; by default the best shipped
///     temporal filter whose inputs the first frame gives (with ``motion``),
///     else the best filter of single renders, frame by frame.
/// :param pipeline: the filter pipeline; by default the filter's own.
/// :param radius: the window form's radius; by default the stored one, else 5.
/// :param point_sampled: whether the renderer sampled every pixel at one
///     point, the same in every frame (Blender Cycles at 1 sample: the
///     header's ``cycles.ViewLayer.samples`` is 1), while the references it
///     is judged against integrate its pixel filter; the filter then ends
///     with that filter (``pixelfilter=0.4``) unless ``pipeline`` is given,
///     as ``filterjit filter`` does for such frames.
///
/// Every frame gives the same inputs as the first. A frame of another size
/// than the one before starts a new history (as after :meth:`reset`,
/// ``frames`` counts from 1 again).
#[pyclass(module = "filterjit")]
struct Denoiser {
    filter: Option<String>,
    pipeline: Option<FilterPipeline>,
    radius: Option<u32>,
    point_sampled: bool,
    /// The filter taken at the first frame, its kernel, and the inputs that frame gave.
    chosen: Option<(Choice, Arc<ValidatedKernel>, Provided)>,
    state: TemporalState,
}

#[pymethods]
impl Denoiser {
    #[new]
    #[pyo3(signature = (filter=None, pipeline=None, radius=None, point_sampled=false))]
    fn new(filter: Option<String>, pipeline: Option<&str>, radius: Option<i64>, point_sampled: bool) -> PyResult<Self> {
        let pipeline = parse_pipeline(pipeline)?;
        let radius = count("radius", radius)?;
        // A filter that does not resolve is refused here, not at the first frame.
        if let Some(filter) = &filter {
            resolve(filter)?;
        }
        Ok(Denoiser { filter, pipeline, radius, point_sampled, chosen: None, state: TemporalState::new() })
    }

    /// Denoise the next frame and return it, float32 (H, W, 3).
    ///
    /// :param color, albedo, normal, position, depth, variance, spp: as :func:`denoise`'s.
    /// :param motion: the frame's motion vectors, float32 (H, W, 2):
    ///     Blender's Vector pass X and Y (where each pixel's surface was in
    ///     the frame before minus where it is, in pixels, y up). A temporal
    ///     filter reads them with the normal and depth.
    /// :param surface_normal: the primary hit's normal, (H, W, 3), where
    ///     ``normal`` is another (Blender: its Normal pass, where ``normal``
    ///     is the Denoising Normal, which follows mirrors to what they show):
    ///     the history's surface test reads it, as ``filterjit filter``
    ///     reads a Cycles frame's Normal pass. By default ``normal``.
    /// :raises ValueError: as :func:`denoise`; or a frame gives other inputs than the first.
    #[pyo3(signature = (color, *, albedo=None, normal=None, position=None, depth=None, motion=None,
                        variance=None, spp=None, surface_normal=None))]
    #[allow(clippy::too_many_arguments)]
    fn denoise<'py>(
        &mut self,
        py: Python<'py>,
        color: &Bound<'py, PyAny>,
        albedo: Option<&Bound<'py, PyAny>>,
        normal: Option<&Bound<'py, PyAny>>,
        position: Option<&Bound<'py, PyAny>>,
        depth: Option<&Bound<'py, PyAny>>,
        motion: Option<&Bound<'py, PyAny>>,
        variance: Option<&Bound<'py, PyAny>>,
        spp: Option<i64>,
        surface_normal: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let spp = count("spp", spp)?;
        let motion = MotionArguments { vectors: motion, surface_normal };
        let (images, mut given) = arrays(color, [albedo, normal, position, depth, variance], motion, spp)?;
        given.sequence = true;
        if self.chosen.is_none() {
            let choice = Choice::asked_or_best(self.filter.as_deref(), self.pipeline, self.radius, &given)
                .map_err(value)?
                .for_point_sampled(self.point_sampled, self.pipeline.is_some());
            check_given(&choice, &given)?;
            let kernel = kernel(&choice)?;
            self.chosen = Some((choice, kernel, given.clone()));
        }
        let (choice, kernel, first) = self.chosen.as_ref().expect("chosen at the first frame");
        if *first != given {
            return Err(PyValueError::new_err(format!(
                "this frame gives other inputs than the sequence's first ({}; the first: {}): give every frame the \
                 same arrays, or call reset() first (a new shot may give others)",
                given_names(&given),
                given_names(first)
            )));
        }
        let request = scene::Request { reference: false, ..choice.request() };
        let (height, width) = (images.height, images.width);
        let scene = scene::prepare(images, &request).map_err(value)?;
        let gpu = device()?;
        let state = &mut self.state;
        let frame =
            py.detach(|| filterjit::denoise::filter_frame(&gpu, choice, kernel, &scene, state)).map_err(runtime)?;
        image_array(py, &frame.filtered.color, height, width)
    }

    /// Forget the history and the filter taken for it: the next frame
    /// starts a sequence (a cut, a new shot), and may give other inputs than
    /// the frames before (the filter is taken again for them).
    fn reset(&mut self) {
        self.state.reset();
        self.chosen = None;
    }

    /// Frames blended into the history since the sequence started or was reset.
    #[getter]
    fn frames(&self) -> u32 {
        self.state.frames()
    }

    /// The filter taken (``"@svgf"``, or the expression) once a frame has
    /// been denoised; before, the one given, or ``None`` (taken at the first frame).
    #[getter]
    fn filter(&self) -> Option<String> {
        self.chosen.as_ref().map(|(choice, ..)| choice.describe()).or_else(|| self.filter.clone())
    }

    /// Its pipeline, once a frame has been denoised.
    #[getter]
    fn pipeline(&self) -> Option<String> {
        self.chosen.as_ref().map(|(choice, ..)| choice.pipeline.to_string())
    }
}

/// How a caller gives the input a filter reads, to `Denoiser.denoise`
/// (`sequence`) or to `denoise`.
fn argument_for(input: Missing, sequence: bool) -> String {
    if input == Missing::Motion {
        return if sequence {
            "pass motion= (with normal= and depth=)".to_string()
        } else {
            "a temporal filter runs on a sequence: use filterjit.Denoiser, whose denoise takes motion= frame by frame"
                .to_string()
        };
    }
    match argument_name(input) {
        Some(argument) => format!("pass {argument}="),
        None => format!("`{}` is no input of denoise: choose a filter without it", input.name()),
    }
}

/// The keyword argument of `denoise` that gives `input`, where one does.
fn argument_name(input: Missing) -> Option<&'static str> {
    let feature = match input {
        Missing::Albedo => Some(Feature::Texture),
        Missing::Feature(feature) => Some(feature),
        Missing::Variance(ScalarVar::ColorVariance) => return Some("variance"),
        Missing::Motion => return Some("motion"),
        _ => None,
    };
    INPUTS.iter().find(|(_, f)| f.is_some() && *f == feature).map(|(argument, _)| *argument)
}

/// The inputs a filter reads, as `denoise`'s arguments name them (`choose`'s reasons).
struct ArgumentNames;

impl InputNames for ArgumentNames {
    fn full(&self, missing: Missing) -> String {
        self.short(missing)
    }

    fn short(&self, missing: Missing) -> String {
        argument_name(missing).unwrap_or(missing.name()).to_string()
    }

    fn listing(&self) -> &str {
        "filterjit.check('@NAME')['inputs']"
    }
}

/// `denoise`'s keyword arguments for images, in its order: stored features
/// (as many channels as the feature has) and the colour variance (`None`).
const INPUTS: [(&str, Option<Feature>); 5] = [
    ("albedo", Some(Feature::Texture)),
    ("normal", Some(Feature::Normal)),
    ("position", Some(Feature::WorldPosition)),
    ("depth", Some(Feature::Depth)),
    ("variance", None),
];

/// The choice's kernel, compiled once a process.
fn kernel(choice: &Choice) -> PyResult<Arc<ValidatedKernel>> {
    let key = (choice.expr.to_string(), choice.pipeline.to_string());
    let mut kernels = KERNELS.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
    if let Some(kernel) = kernels.get(&key) {
        return Ok(kernel.clone());
    }
    let kernel = Arc::new(choice.compile().map_err(value)?);
    kernels.insert(key, kernel.clone());
    Ok(kernel)
}

/// The shipped filter :func:`denoise` takes when given ``inputs`` (names
/// among ``albedo``, ``normal``, ``position``, ``depth``, ``variance``; the
/// colour is always there): ``(name, pipeline, why)``. Where the colour's
/// median pixel is black, :func:`denoise` takes its sparse-light variant
/// instead, where it has one (``filterjit list``).
#[pyfunction]
fn choose(inputs: &Bound<'_, PyAny>) -> PyResult<(String, String, String)> {
    if inputs.is_instance_of::<pyo3::types::PyString>() {
        return Err(PyTypeError::new_err("`inputs` is a list of names such as ['albedo', 'normal'], not a string"));
    }
    let mut features = BTreeSet::new();
    let mut variances = BTreeSet::new();
    for input in inputs.try_iter()? {
        let input: String = input?.extract()?;
        match INPUTS.iter().find(|(name, _)| *name == input) {
            Some((_, Some(feature))) => features.insert(*feature),
            Some((_, None)) => variances.insert(ScalarVar::ColorVariance),
            None => {
                return Err(PyValueError::new_err(format!(
                    "unknown input `{input}`: denoise takes albedo, normal, position, depth and variance"
                )))
            }
        };
    }
    let choice = Choice::best_for(&Provided::new(features, variances)).map_err(value)?;
    let because = choice.chosen_because.as_ref().map(|because| because.render(&ArgumentNames)).unwrap_or_default();
    Ok((choice.describe(), choice.pipeline.to_string(), because))
}

/// An expression argument: text, `@name` of a shipped one, or `@FILE[:NAME]`.
fn resolve(expr: &str) -> PyResult<filterjit::corpus::Resolved> {
    filterjit::corpus::resolve_with_pipeline(expr).map_err(value)
}

/// Parse and type-check an expression (text, ``@name`` or ``@FILE[:NAME]``):
/// ``{"canonical": str, "length": int, "inputs": [str]}``.
///
/// :raises ValueError: the expression is invalid; the message gives the line
///     and column with a caret.
#[pyfunction]
fn check<'py>(py: Python<'py>, expr: &str) -> PyResult<Bound<'py, PyDict>> {
    let expr = resolve(expr)?.expr;
    let out = PyDict::new(py);
    out.set_item("canonical", expr.to_string())?;
    out.set_item("length", expr.len())?;
    let inputs: Vec<&str> =
        expr.features().iter().map(|f| f.name()).chain(expr.variables().iter().map(|v| v.name())).collect();
    out.set_item("inputs", inputs)?;
    Ok(out)
}

/// The cheapest equivalent expression (equality saturation with rules
/// exact under filterjit's numeric semantics), as text.
#[pyfunction]
fn simplify(expr: &str) -> PyResult<String> {
    Ok(filterjit::simplify::simplify(&resolve(expr)?.expr).to_string())
}

/// The validated WGSL compute kernel of an expression (the one ``filterjit
/// compile`` prints), shaped for ``pipeline`` (default: the stored one, else ``window``).
#[pyfunction]
#[pyo3(signature = (expr, pipeline=None))]
fn compile(expr: &str, pipeline: Option<&str>) -> PyResult<String> {
    let resolved = resolve(expr)?;
    let pipeline = parse_pipeline(pipeline)?.or(resolved.pipeline).unwrap_or_default();
    let kernel = jit::compile(
        &resolved.expr,
        jit::KernelSpec {
            kind: jit::KernelKind::Filter,
            options: jit::LowerOptions::ALL,
            shape: jit::Shape::of(&pipeline),
        },
    )
    .map_err(value)?;
    Ok(kernel.wgsl().to_string())
}

fn code<'py>(py: Python<'py>, code: &Code) -> Bound<'py, PyAny> {
    match code {
        Code::Text(text) => text.clone().into_pyobject(py).expect("a string converts").into_any(),
        Code::SpirV(_) => PyBytes::new(py, &code.to_bytes()).into_any(),
    }
}

/// A flag-like argument by its command-line spelling (`wgsl`, `rgba16float`).
fn named_value<T: ValueEnum>(what: &str, text: &str) -> PyResult<T> {
    T::from_str(text, true).map_err(|_| {
        let names: Vec<String> =
            T::value_variants().iter().filter_map(|t| t.to_possible_value()).map(|v| v.get_name().into()).collect();
        PyValueError::new_err(format!("unknown {what} `{text}`; there are: {}", names.join(", ")))
    })
}

/// A standalone shader for an engine, as ``filterjit export`` writes it:
/// ``(shader, manifest)``.
///
/// ``shader`` is text (``bytes`` of SPIR-V words for ``target="spirv"``);
/// ``manifest`` is the manifest as a dict (bindings, uniform, passes, order of
/// dispatches). Each other stage's shader (the pre-pass, the temporal
/// stage…) is its entry's ``source``: ``manifest["prepass"]["source"]``.
///
/// :param target: ``wgsl``, ``glsl``, ``hlsl``, ``msl`` or ``spirv``.
/// :param format: texel format of the output storage texture.
#[pyfunction]
#[pyo3(signature = (expr, target="wgsl", pipeline=None, format="rgba16float"))]
fn export<'py>(
    py: Python<'py>,
    expr: &str,
    target: &str,
    pipeline: Option<&str>,
    format: &str,
) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
    let target: Target = named_value("target", target)?;
    let format: OutputFormat = named_value("format", format)?;
    let resolved = resolve(expr)?;
    let pipeline = parse_pipeline(pipeline)?.or(resolved.pipeline).unwrap_or_default();
    let exported =
        filterjit::export::export_filter(&resolved.expr, &pipeline, resolved.radius, target, format).map_err(value)?;
    let text = serde_json::to_string(&exported.manifest).map_err(value)?;
    let manifest = py.import("json")?.call_method1("loads", (text,))?;
    for (name, stage) in &exported.stages {
        manifest.get_item(name.key())?.set_item("source", code(py, stage))?;
    }
    Ok((code(py, &exported.code), manifest))
}

/// relMSE of ``image`` against ``reference`` (float32 (H, W, 3)): the mean
/// over pixels of sum_rgb (c - g)^2 / (g^2 + 0.01), as the command line reports it.
#[pyfunction]
fn relmse(image: &Bound<'_, PyAny>, reference: &Bound<'_, PyAny>) -> PyResult<f64> {
    let (h, w, image) = rgb("image", image)?;
    let reference = Image::read("reference", reference)?.pixels("reference", ((h, w), "image"), &[3])?;
    Ok(filterjit::metrics::errors(&image, &reference, None).relmse)
}

/// ``image``'s mean luminance over ``reference``'s (float32 (H, W, 3)):
/// 1 keeps the light, below 1 is darker. A denoiser's bias; ``None`` for a
/// black reference.
#[pyfunction]
fn light(image: &Bound<'_, PyAny>, reference: &Bound<'_, PyAny>) -> PyResult<Option<f64>> {
    let (h, w, image) = rgb("image", image)?;
    let reference = Image::read("reference", reference)?.pixels("reference", ((h, w), "image"), &[3])?;
    Ok(filterjit::metrics::light(&image, &reference))
}

/// Mean HDR-FLIP of ``image`` against ``reference`` (float32 (H, W, 3)),
/// as the command line reports it (a port of NVlabs' FLIP 1.7).
#[pyfunction]
fn flip(py: Python<'_>, image: &Bound<'_, PyAny>, reference: &Bound<'_, PyAny>) -> PyResult<f64> {
    let (h, w, image) = rgb("image", image)?;
    let reference = Image::read("reference", reference)?.pixels("reference", ((h, w), "image"), &[3])?;
    Ok(py.detach(|| filterjit::flip::hdr_flip(&reference, &image, w, h).mean()))
}

/// The GPU adapter :func:`denoise` runs on (opening it if needed).
#[pyfunction]
fn device_name() -> PyResult<String> {
    Ok(device()?.describe())
}

#[pymodule]
fn _filterjit(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(denoise, m)?)?;
    m.add_function(wrap_pyfunction!(choose, m)?)?;
    m.add_function(wrap_pyfunction!(check, m)?)?;
    m.add_function(wrap_pyfunction!(simplify, m)?)?;
    m.add_function(wrap_pyfunction!(compile, m)?)?;
    m.add_function(wrap_pyfunction!(export, m)?)?;
    m.add_function(wrap_pyfunction!(relmse, m)?)?;
    m.add_function(wrap_pyfunction!(flip, m)?)?;
    m.add_function(wrap_pyfunction!(light, m)?)?;
    m.add_function(wrap_pyfunction!(device_name, m)?)?;
    m.add_class::<Denoiser>()?;
    // As `filter=` takes them: `@name`.
    let shipped: Vec<String> = filterjit::denoise::SHIPPED_BY_QUALITY.iter().map(|n| format!("@{n}")).collect();
    m.add("SHIPPED_BY_QUALITY", shipped)?;
    Ok(())
}
