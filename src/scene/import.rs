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
}

/// Alternative channel-name sets for one quantity, most preferred first.
type Alternatives = &'static [&'static [&'static str]];

impl Layout {
    pub fn name(self) -> &'static str {
        match self {
            Layout::Mitsuba => "Mitsuba 3 (aov + path)",
            Layout::Pbrt => "pbrt-v4 GBufferFilm / filterjit",
        }
    }

    /// Decide the layout from the channel names of the noisy image.
    pub fn detect(channels: &[String]) -> Layout {
        let mitsuba = ["albedo.R", "sh_normal.X", "position.X", "depth.T", "path.R"];
        if channels.iter().any(|c| mitsuba.contains(&c.as_str())) {
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

    /// Channels of a per-pixel variance, and whether they live in the
    /// separate `variance.exr` beside the noisy image.
    pub fn variance(self, v: ScalarVar) -> (Alternatives, bool) {
        match (self, v) {
            (Layout::Mitsuba, ScalarVar::ColorVariance) => (&[&["R", "G", "B"]], true),
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

/// The first alternative whose channels all exist.
pub fn pick(alternatives: Alternatives, channels: &[String]) -> Option<&'static [&'static str]> {
    alternatives.iter().copied().find(|names| names.iter().all(|n| channels.iter().any(|c| c == n)))
}
