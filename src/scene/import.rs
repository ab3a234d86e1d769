//! Channel layouts of the renderers we read: which EXR channels hold which
//! feature. Features a layout has no channels for are absent, never zero.

use std::path::Path;

use super::SceneError;
use crate::lang::{Feature, ScalarVar};

/// The renderer conventions a dataset follows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layout {
    /// Mitsuba 3: `aov` integrator wrapping `path`; colour variance in `variance.exr` beside.
    Mitsuba,
    /// pbrt-v4 GBufferFilm names, extended with filterjit's own names for the
    /// features pbrt does not write. filterjit's renderer writes this layout.
    Pbrt,
    /// Mitsuba 3's `moment` integrator wrapping `aov` + `path`: every nested
    /// channel's first moment (`nested.*`) and second moment (`m2_nested.*`);
    /// the colour variance comes from the two.
    MitsubaMoment,
    /// Blender's Cycles, an OpenEXR MultiLayer file: `LAYER.PASS.CHANNEL`,
    /// read through one view layer ([`Channels`]); the Combined pass (or
    /// `Noisy Image`, where a denoiser replaced Combined) and the Denoising
    /// Data, Normal, Position and Depth passes. No per-pixel variance.
    Blender,
}

/// Alternative channel-name sets for one quantity, most preferred first.
type Alternatives = &'static [&'static [&'static str]];

impl Layout {
    pub fn name(self) -> &'static str {
        match self {
            Layout::Mitsuba => "Mitsuba 3 (aov + path)",
            Layout::Pbrt => "pbrt-v4 GBufferFilm / filterjit",
            Layout::MitsubaMoment => "Mitsuba 3 (moment + aov + path)",
            Layout::Blender => "Blender Cycles (multilayer EXR)",
        }
    }

    /// Decide the layout from the channel names of the noisy image.
    pub fn detect(channels: &[String]) -> Layout {
        let mitsuba = ["albedo.R", "sh_normal.X", "position.X", "depth.T", "path.R"];
        if channels.iter().any(|c| c == "Combined.R" || c == "Noisy Image.R") {
            Layout::Blender
        } else if channels.iter().any(|c| c.starts_with("m2_nested.")) {
            Layout::MitsubaMoment
        } else if channels.iter().any(|c| mitsuba.contains(&c.as_str())) {
            Layout::Mitsuba
        } else {
            Layout::Pbrt
        }
    }

    /// The noisy colour's channels.
    pub fn color(self) -> Alternatives {
        match self {
            // With a denoiser on, Combined is denoised and the noisy one is `Noisy Image`.
            Layout::Blender => {
                &[&["Noisy Image.R", "Noisy Image.G", "Noisy Image.B"], &["Combined.R", "Combined.G", "Combined.B"]]
            }
            _ => &[&["R", "G", "B"]],
        }
    }

    /// The reference image's colour channels: the renderer's, or a plain
    /// RGB image (a reference saved apart, as Blender's File Output node or
    /// an image editor writes it).
    pub fn reference_color(self) -> Alternatives {
        match self {
            Layout::Blender => &[&["Combined.R", "Combined.G", "Combined.B"], &["R", "G", "B"]],
            _ => self.color(),
        }
    }

    /// What to enable in the renderer to get `f`, where the layout names it.
    pub fn how_to_get(self, f: Feature) -> Option<&'static str> {
        match (self, f) {
            (Layout::Blender, Feature::Texture | Feature::Normal) => {
                Some("View Layer Properties > Passes > Data > Denoising Data (Cycles)")
            }
            (Layout::Blender, Feature::WorldPosition) => Some("View Layer Properties > Passes > Data > Position"),
            (Layout::Blender, Feature::Depth) => Some("View Layer Properties > Passes > Data > Z"),
            _ => None,
        }
    }

    /// Channels of a stored (non-gradient) feature in the noisy image.
    pub fn feature(self, f: Feature) -> Alternatives {
        match (self, f) {
            (Layout::Mitsuba, Feature::Texture) => &[&["albedo.R", "albedo.G", "albedo.B"]],
            (Layout::Mitsuba, Feature::Normal) => &[&["sh_normal.X", "sh_normal.Y", "sh_normal.Z"]],
            (Layout::Mitsuba, Feature::WorldPosition) => &[&["position.X", "position.Y", "position.Z"]],
            (Layout::Mitsuba, Feature::Depth) => &[&["depth.T"]],
            (Layout::MitsubaMoment, Feature::Texture) => &[&["nested.albedo.R", "nested.albedo.G", "nested.albedo.B"]],
            (Layout::MitsubaMoment, Feature::Normal) => {
                &[&["nested.sh_normal.X", "nested.sh_normal.Y", "nested.sh_normal.Z"]]
            }
            (Layout::MitsubaMoment, Feature::WorldPosition) => {
                &[&["nested.position.X", "nested.position.Y", "nested.position.Z"]]
            }
            (Layout::MitsubaMoment, Feature::Depth) => &[&["nested.depth.T"]],
            (Layout::Pbrt, Feature::Texture) => &[&["Albedo.R", "Albedo.G", "Albedo.B"]],
            // Shading normals first (as Mitsuba's sh_normal), then geometric; current names, then pbrt's older ones.
            (Layout::Pbrt, Feature::Normal) => {
                &[&["Ns.X", "Ns.Y", "Ns.Z"], &["Nsx", "Nsy", "Nsz"], &["N.X", "N.Y", "N.Z"], &["Nx", "Ny", "Nz"]]
            }
            (Layout::Pbrt, Feature::WorldPosition) => &[&["P.X", "P.Y", "P.Z"], &["Px", "Py", "Pz"]],
            (Layout::Pbrt, Feature::Depth) => &[&["Z"]],
            (Layout::Pbrt, Feature::SecondaryTexture) => {
                &[&["SecondaryAlbedo.R", "SecondaryAlbedo.G", "SecondaryAlbedo.B"]]
            }
            (Layout::Pbrt, Feature::DirectIllumination) => &[&["DirectVisibility"]],
            // Blender 3.x and 4.x pass names: the denoiser's passes first (world-space normals).
            (Layout::Blender, Feature::Texture) => &[
                &["Denoising Albedo.R", "Denoising Albedo.G", "Denoising Albedo.B"],
                &["DiffCol.R", "DiffCol.G", "DiffCol.B"],
            ],
            (Layout::Blender, Feature::Normal) => &[
                &["Denoising Normal.X", "Denoising Normal.Y", "Denoising Normal.Z"],
                &["Normal.X", "Normal.Y", "Normal.Z"],
            ],
            (Layout::Blender, Feature::WorldPosition) => &[&["Position.X", "Position.Y", "Position.Z"]],
            // Camera-space depth (the Z pass), or the denoiser's.
            (Layout::Blender, Feature::Depth) => &[&["Depth.Z"], &["Denoising Depth.Z"]],
            _ => &[],
        }
    }

    /// The motion vectors' channels (X, Y: the frame before's position minus
    /// this one's, in pixels, y up, as Blender's Vector pass).
    pub fn motion(self) -> Alternatives {
        match self {
            Layout::Blender | Layout::Pbrt => &[&["Vector.X", "Vector.Y"]],
            Layout::Mitsuba | Layout::MitsubaMoment => &[],
        }
    }

    /// The normal the temporal stage's surface test reads: the primary
    /// hit's, which Blender's Normal pass holds (its Denoising Normal
    /// follows mirrors to what they show).
    pub fn surface_normal(self) -> Alternatives {
        match self {
            Layout::Blender => &[
                &["Normal.X", "Normal.Y", "Normal.Z"],
                &["Denoising Normal.X", "Denoising Normal.Y", "Denoising Normal.Z"],
            ],
            _ => self.feature(Feature::Normal),
        }
    }

    /// The stored features (never colour, pixel or gradients) whose channels
    /// are among `channels`.
    pub fn stored_features(self, channels: &[String]) -> std::collections::BTreeSet<Feature> {
        Feature::ALL.iter().copied().filter(|f| f.base() == *f && pick(self.feature(*f), channels).is_some()).collect()
    }

    /// Channels of a per-pixel variance, and whether they live in the
    /// separate `variance.exr` beside the noisy image.
    pub fn variance(self, v: ScalarVar) -> (Alternatives, bool) {
        match (self, v) {
            (Layout::Mitsuba, ScalarVar::ColorVariance) => (&[&["R", "G", "B"]], true),
            // First moments, then second moments: see `variance_values`.
            (Layout::MitsubaMoment, ScalarVar::ColorVariance) => (
                &[&[
                    "nested.path.R",
                    "nested.path.G",
                    "nested.path.B",
                    "m2_nested.path.R",
                    "m2_nested.path.G",
                    "m2_nested.path.B",
                ]],
                false,
            ),
            (Layout::Pbrt, ScalarVar::ColorVariance) => (&[&["Variance.R", "Variance.G", "Variance.B"]], false),
            (Layout::Pbrt, ScalarVar::WpVariance) => (&[&["PVariance"]], false),
            (Layout::Pbrt, ScalarVar::NVariance) => (&[&["NVariance"]], false),
            (Layout::Pbrt, ScalarVar::TexVariance) => (&[&["AlbedoVariance"]], false),
            (Layout::Pbrt, ScalarVar::SecTexVariance) => (&[&["SecondaryAlbedoVariance"]], false),
            (Layout::Pbrt, ScalarVar::DovVariance) => (&[&["ZVariance"]], false),
            (Layout::Pbrt, ScalarVar::DiVariance) => (&[&["DirectVisibilityVariance"]], false),
            _ => (&[], false),
        }
    }
}

impl Layout {
    /// A stored feature's values as filterjit reads them: Blender writes a
    /// depth of 1e10 where a ray hits nothing, which would swamp the depth's
    /// normalisation; like Mitsuba, no hit is 0.
    pub fn clean(self, f: Feature, values: &mut [[f32; 3]]) {
        if self == Layout::Blender && f == Feature::Depth {
            for v in values.iter_mut().filter(|v| v[0] >= BLENDER_NO_HIT) {
                *v = [0.0; 3];
            }
        }
    }

    /// One scalar variance per pixel from the channels [`Layout::variance`]
    /// picked: the mean over the channels, or, from first and second moments
    /// m1, m2 (Mitsuba's `moment` integrator), the mean over colour channels
    /// of the per-sample variance max(m2 − m1², 0) (float rounding can make it
    /// slightly negative). The unbiased n/(n−1) factor is left out: a constant
    /// factor is undone by the normalisation every variance gets.
    pub fn variance_values(self, channels: &[Vec<f32>]) -> Vec<f32> {
        let pixels = channels.first().map_or(0, Vec::len);
        if self == Layout::MitsubaMoment && channels.len() == 6 {
            let (first, second) = channels.split_at(3);
            return (0..pixels)
                .map(|p| {
                    let sum: f64 = (0..3).map(|c| (second[c][p] as f64 - (first[c][p] as f64).powi(2)).max(0.0)).sum();
                    (sum / 3.0) as f32
                })
                .collect();
        }
        channel_mean(channels)
    }
}

/// Channels by which a Blender multilayer file is known, and its view layers
/// found: `LAYER` + one of these.
const BLENDER_PASSES: &[&str] =
    &[".Combined.R", ".Noisy Image.R", ".Denoising Albedo.R", ".Denoising Normal.X", ".Normal.X", ".Depth.Z"];

/// Blender's depth where nothing was hit is 1e10; anything this far is no hit.
const BLENDER_NO_HIT: f32 = 1e9;

/// The channels of one EXR file as a layout reads them. A Blender multilayer
/// file names its channels `LAYER.PASS.CHANNEL`: it is read through one view
/// layer, whose prefix is stripped here and put back when reading; other
/// renderers' files are read as they are.
#[derive(Clone, Debug)]
pub struct Channels {
    /// The channel names, without the view layer's prefix.
    pub names: Vec<String>,
    /// `LAYER.`, or empty.
    prefix: String,
}

impl Channels {
    /// `names` (all of `file`'s channels) through the view layer asked for,
    /// or the only one there is.
    pub fn of(file: &Path, names: Vec<String>, view_layer: Option<&str>) -> Result<Channels, SceneError> {
        let layers: Vec<String> = names
            .iter()
            .filter_map(|n| BLENDER_PASSES.iter().find_map(|pass| n.strip_suffix(pass)))
            .map(str::to_string)
            .collect::<std::collections::BTreeSet<_>>()
            .into_iter()
            .collect();
        let layer = match (view_layer, layers.as_slice()) {
            (None, []) => return Ok(Channels { names, prefix: String::new() }),
            (Some(asked), _) if layers.iter().any(|l| l == asked) => asked.to_string(),
            (None, [only]) => only.clone(),
            (asked, _) => {
                return Err(SceneError::ViewLayer {
                    file: file.to_path_buf(),
                    asked: asked.map(str::to_string),
                    layers,
                })
            }
        };
        let prefix = format!("{layer}.");
        let names = names.iter().filter_map(|n| n.strip_prefix(&prefix)).map(str::to_string).collect();
        Ok(Channels { names, prefix })
    }

    /// The layout to read these channels by.
    pub fn layout(&self) -> Layout {
        match self.prefix.is_empty() {
            true => Layout::detect(&self.names),
            false => Layout::Blender,
        }
    }

    /// The file's own names of `chosen` (channels named as in [`Channels::names`]).
    pub fn in_file(&self, chosen: &[&str]) -> Vec<String> {
        chosen.iter().map(|n| format!("{}{n}", self.prefix)).collect()
    }
}

/// The per-pixel mean over `channels` (a colour variance's R, G and B), in f32
/// in channel order, as every renderer's variance is read.
pub fn channel_mean(channels: &[Vec<f32>]) -> Vec<f32> {
    let pixels = channels.first().map_or(0, Vec::len);
    let n = channels.len().max(1) as f32;
    (0..pixels).map(|p| channels.iter().map(|c| c[p]).sum::<f32>() / n).collect()
}

/// The first alternative whose channels all exist.
pub fn pick(alternatives: Alternatives, channels: &[String]) -> Option<&'static [&'static str]> {
    alternatives.iter().copied().find(|names| names.iter().all(|n| channels.iter().any(|c| c == n)))
}
