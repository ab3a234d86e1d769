//! Channel layouts of the renderers we read: which EXR channels hold which
//! feature. Features a layout has no channels for are absent, never zero.

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
}

/// Alternative channel-name sets for one quantity, most preferred first.
type Alternatives = &'static [&'static [&'static str]];

impl Layout {
    pub fn name(self) -> &'static str {
        match self {
            Layout::Mitsuba => "Mitsuba 3 (aov + path)",
            Layout::Pbrt => "pbrt-v4 GBufferFilm / filterjit",
            Layout::MitsubaMoment => "Mitsuba 3 (moment + aov + path)",
        }
    }

    /// Decide the layout from the channel names of the noisy image.
    pub fn detect(channels: &[String]) -> Layout {
        let mitsuba = ["albedo.R", "sh_normal.X", "position.X", "depth.T", "path.R"];
        if channels.iter().any(|c| c.starts_with("m2_nested.")) {
            Layout::MitsubaMoment
        } else if channels.iter().any(|c| mitsuba.contains(&c.as_str())) {
            Layout::Mitsuba
        } else {
            Layout::Pbrt
        }
    }

    pub fn color(self) -> Alternatives {
        &[&["R", "G", "B"]]
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
            _ => &[],
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
