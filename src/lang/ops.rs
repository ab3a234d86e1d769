//! The operator table: every operator and terminal of the expression language,
//! declared once.
//!
//! The parser looks names up here, the printer spells them from here, the
//! checker takes their types from here, the WGSL emitter takes the helper
//! function names from here, the CPU evaluator takes their f64 semantics from
//! here (through [`crate::semantics`]), and the GP engine draws its operators
//! and terminals from the `ALL` lists.

use crate::semantics;

/// The two types of the strongly typed language (thesis section 3.2.1, Figure 3.2).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Type {
    Scalar,
    Vector,
}

macro_rules! name_table {
    (
        $(#[$meta:meta])*
        pub enum $enum:ident { $($variant:ident => $name:literal),* $(,)? }
    ) => {
        $(#[$meta])*
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
        pub enum $enum { $($variant),* }

        impl $enum {
            /// Every member, in declaration order.
            pub const ALL: &'static [$enum] = &[$($enum::$variant),*];

            /// The spelling in the surface syntax.
            pub fn name(self) -> &'static str {
                match self { $($enum::$variant => $name),* }
            }

            /// Look a spelling up.
            pub fn from_name(name: &str) -> Option<Self> {
                match name { $($name => Some($enum::$variant),)* _ => None }
            }
        }

        impl std::fmt::Display for $enum {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str(self.name())
            }
        }
    };
}

name_table! {
    /// Unary scalar operators.
    pub enum UnaryOp {
        Neg => "neg",
        Sin => "sin",
        Cos => "cos",
        Tan => "tan",
        Exp => "exp",
        Asin => "asin",
        Acos => "acos",
        Atan => "atan",
        Sqrt => "sqrt",
        Abs => "abs",
        Mitchell => "mitchell",
        Sinc => "sinc",
        Epanechnikov => "epanechnikov",
        Biweight => "biweight",
        Tricube => "tricube",
    }
}

name_table! {
    /// Binary scalar operators.
    pub enum BinaryOp {
        Add => "add",
        Sub => "sub",
        Mul => "mul",
        Div => "div",
        Pow => "pow",
    }
}

name_table! {
    /// Operators on a feature of the centre pixel i and a feature of the neighbour j.
    pub enum PairOp {
        Dot => "dot",
        Distance2 => "distance2",
        Distance1 => "distance1",
        DistanceMax => "distanceMax",
    }
}

name_table! {
    /// Vector terminals: per-pixel features (thesis Figure 3.2), the noisy
    /// colour, the pixel position, and the guide (the colour a pass's weights
    /// compare, pre-filtered in the first pass: docs/SEMANTICS.md, "The guide").
    pub enum Feature {
        WorldPosition => "worldPosition",
        Normal => "normal",
        Texture => "texture",
        SecondaryTexture => "secondaryTexture",
        Depth => "depth",
        DirectIllumination => "directIllumination",
        WpGradient => "wpGradient",
        NGradient => "nGradient",
        TexGradient => "texGradient",
        SecTexGradient => "secTexGradient",
        DovGradient => "dovGradient",
        DiGradient => "diGradient",
        Color => "color",
        Pixel => "pixel",
        Guide => "guide",
    }
}

name_table! {
    /// Scalar terminals, read at the centre pixel i: per-pixel sample
    /// variances; `level`, the à-trous pass (0 in the window form); and what
    /// the outlier pre-pass measured (docs/SEMANTICS.md, "The pipeline"): the
    /// mean and standard deviation of the luminance around i, and the share
    /// of i's luminance the clamp removed; and what the temporal stage
    /// accumulated (docs/SEMANTICS.md, "The temporal stage"): the frames in
    /// i's history and the variance of its accumulated luminance. Only the
    /// variances are stored.
    pub enum ScalarVar {
        WpVariance => "wpVariance",
        NVariance => "nVariance",
        TexVariance => "texVariance",
        SecTexVariance => "secTexVariance",
        DovVariance => "dovVariance",
        DiVariance => "diVariance",
        ColorVariance => "colorVariance",
        Level => "level",
        LocalMean => "localMean",
        LocalStd => "localStd",
        ClampedShare => "clampedShare",
        HistoryLength => "historyLength",
        TemporalVariance => "temporalVariance",
    }
}

/// How an operator is written in the surface syntax.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fixity {
    /// `name(args)`.
    Call,
    /// `a op b`, left associative; larger binds tighter.
    Infix { symbol: &'static str, precedence: u8 },
    /// `-a`, binding tighter than every infix operator.
    Prefix { symbol: &'static str },
}

/// Binding power of prefix minus, above every infix operator.
pub const PREFIX_PRECEDENCE: u8 = 3;

impl UnaryOp {
    pub fn fixity(self) -> Fixity {
        match self {
            UnaryOp::Neg => Fixity::Prefix { symbol: "-" },
            _ => Fixity::Call,
        }
    }

    /// Whether the operator can raise a domain-error flag on some input.
    pub fn can_flag(self) -> bool {
        matches!(self, UnaryOp::Sqrt | UnaryOp::Asin | UnaryOp::Acos)
    }

    /// Relative cost in a kernel, in units of one add: transcendental
    /// functions and the reconstruction kernels cost several (see
    /// `filterjit bench`); what the simplifier minimises.
    pub fn cost(self) -> f64 {
        match self {
            UnaryOp::Neg | UnaryOp::Abs => 1.0,
            UnaryOp::Sqrt => 4.0,
            UnaryOp::Exp => 6.0,
            UnaryOp::Sin | UnaryOp::Cos | UnaryOp::Atan => 8.0,
            UnaryOp::Tan | UnaryOp::Asin | UnaryOp::Acos => 10.0,
            UnaryOp::Epanechnikov | UnaryOp::Biweight => 3.0,
            UnaryOp::Tricube | UnaryOp::Mitchell => 5.0,
            UnaryOp::Sinc => 12.0,
        }
    }

    /// The f64 semantics, shared with the GPU by construction of
    /// `templates/ops.wgsl` (see docs/SEMANTICS.md).
    pub fn eval(self, a: f64, flags: &mut u32) -> f64 {
        use semantics as s;
        match self {
            UnaryOp::Neg => s::neg(a),
            UnaryOp::Sin => s::sin(a),
            UnaryOp::Cos => s::cos(a),
            UnaryOp::Tan => s::tan(a),
            UnaryOp::Exp => s::exp(a),
            UnaryOp::Asin => s::asin(a, flags),
            UnaryOp::Acos => s::acos(a, flags),
            UnaryOp::Atan => s::atan(a),
            UnaryOp::Sqrt => s::sqrt(a, flags),
            UnaryOp::Abs => s::abs(a),
            UnaryOp::Mitchell => s::mitchell(a),
            UnaryOp::Sinc => s::sinc(a),
            UnaryOp::Epanechnikov => s::epanechnikov(a),
            UnaryOp::Biweight => s::biweight(a),
            UnaryOp::Tricube => s::tricube(a),
        }
    }
}

impl BinaryOp {
    pub fn fixity(self) -> Fixity {
        match self {
            BinaryOp::Add => Fixity::Infix { symbol: "+", precedence: 1 },
            BinaryOp::Sub => Fixity::Infix { symbol: "-", precedence: 1 },
            BinaryOp::Mul => Fixity::Infix { symbol: "*", precedence: 2 },
            BinaryOp::Div => Fixity::Infix { symbol: "/", precedence: 2 },
            BinaryOp::Pow => Fixity::Call,
        }
    }

    /// Whether the operator can raise a domain-error flag on some input.
    pub fn can_flag(self) -> bool {
        self == BinaryOp::Pow
    }

    /// Relative cost in a kernel, in units of one add (see [`UnaryOp::cost`]).
    pub fn cost(self) -> f64 {
        match self {
            BinaryOp::Add | BinaryOp::Sub | BinaryOp::Mul => 1.0,
            BinaryOp::Div => 2.0,
            BinaryOp::Pow => 12.0,
        }
    }

    pub fn eval(self, a: f64, b: f64, flags: &mut u32) -> f64 {
        use semantics as s;
        match self {
            BinaryOp::Add => s::add(a, b),
            BinaryOp::Sub => s::sub(a, b),
            BinaryOp::Mul => s::mul(a, b),
            BinaryOp::Div => s::div(a, b),
            BinaryOp::Pow => s::pow(a, b, flags),
        }
    }
}

impl PairOp {
    /// Relative cost in a kernel, in units of one add, loads of the two
    /// features included (see [`UnaryOp::cost`]).
    pub fn cost(self) -> f64 {
        match self {
            PairOp::Dot | PairOp::Distance1 | PairOp::DistanceMax => 5.0,
            PairOp::Distance2 => 6.0,
        }
    }

    pub fn eval(self, u: [f64; 3], v: [f64; 3]) -> f64 {
        use semantics as s;
        match self {
            PairOp::Dot => s::dot(u, v),
            PairOp::Distance2 => s::distance2(u, v),
            PairOp::Distance1 => s::distance1(u, v),
            PairOp::DistanceMax => s::distance_max(u, v),
        }
    }
}

/// The per-pixel data a vector terminal is computed from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum FeatureSource {
    /// A stored, normalised feature.
    Stored(Feature),
    /// The Sobel gradient magnitude of a stored feature, per channel.
    Gradient(Feature),
    /// The pixel's integer coordinates, computed in the kernel.
    Coordinates,
    /// The colour the form filters, blurred by the 3×3 linear B-spline in
    /// the first pass (`cpu::guide`, the `guide` terminal); from the second
    /// pass on, the pass's input itself.
    Guide,
}

impl Feature {
    /// Number of meaningful components; vectors are zero-padded to 3
    /// (docs/SEMANTICS.md, "Vectors").
    pub fn dimension(self) -> usize {
        match self.base() {
            Feature::Depth | Feature::DirectIllumination => 1,
            Feature::Pixel => 2,
            _ => 3,
        }
    }

    /// The stored feature a gradient is taken of, or the feature itself.
    pub fn base(self) -> Feature {
        match self {
            Feature::WpGradient => Feature::WorldPosition,
            Feature::NGradient => Feature::Normal,
            Feature::TexGradient => Feature::Texture,
            Feature::SecTexGradient => Feature::SecondaryTexture,
            Feature::DovGradient => Feature::Depth,
            Feature::DiGradient => Feature::DirectIllumination,
            other => other,
        }
    }

    pub fn source(self) -> FeatureSource {
        match self {
            Feature::Pixel => FeatureSource::Coordinates,
            Feature::Guide => FeatureSource::Guide,
            f if f.base() != f => FeatureSource::Gradient(f.base()),
            f => FeatureSource::Stored(f),
        }
    }

    /// Whether a scene must provide data for this terminal (the pixel
    /// position and the guide, made from the colour, never need any).
    pub fn needs_data(self) -> bool {
        !matches!(self, Feature::Pixel | Feature::Guide)
    }
}

impl ScalarVar {
    /// The stored feature whose sample variance this is; `None` for the colour.
    pub fn of_feature(self) -> Option<Feature> {
        match self {
            ScalarVar::WpVariance => Some(Feature::WorldPosition),
            ScalarVar::NVariance => Some(Feature::Normal),
            ScalarVar::TexVariance => Some(Feature::Texture),
            ScalarVar::SecTexVariance => Some(Feature::SecondaryTexture),
            ScalarVar::DovVariance => Some(Feature::Depth),
            ScalarVar::DiVariance => Some(Feature::DirectIllumination),
            ScalarVar::ColorVariance | ScalarVar::Level => None,
            ScalarVar::LocalMean | ScalarVar::LocalStd | ScalarVar::ClampedShare => None,
            ScalarVar::HistoryLength | ScalarVar::TemporalVariance => None,
        }
    }

    /// Whether a scene stores it: the variances; `level` comes from the
    /// form's uniform, the rest from the outlier pre-pass and the temporal stage.
    pub fn is_stored(self) -> bool {
        !matches!(self, ScalarVar::Level) && !self.from_prepass() && !self.from_temporal()
    }

    /// Whether a kernel reads it from a per-pixel buffer (everything but `level`).
    pub fn is_bound(self) -> bool {
        self != ScalarVar::Level
    }

    /// Whether the outlier pre-pass measures it (`outliers=k` in the pipeline).
    pub fn from_prepass(self) -> bool {
        matches!(self, ScalarVar::LocalMean | ScalarVar::LocalStd | ScalarVar::ClampedShare)
    }

    /// The terminals the outlier pre-pass supplies.
    pub const FROM_PREPASS: [ScalarVar; 3] = [ScalarVar::LocalMean, ScalarVar::LocalStd, ScalarVar::ClampedShare];

    /// Whether the temporal stage supplies it (`temporal=A` in the pipeline).
    pub fn from_temporal(self) -> bool {
        matches!(self, ScalarVar::HistoryLength | ScalarVar::TemporalVariance)
    }

    /// The terminals the temporal stage supplies.
    pub const FROM_TEMPORAL: [ScalarVar; 2] = [ScalarVar::HistoryLength, ScalarVar::TemporalVariance];

    /// Whether the pipeline makes it rather than the scene storing it: the
    /// outlier pre-pass's and the temporal stage's measures.
    pub fn from_pipeline(self) -> bool {
        self.from_prepass() || self.from_temporal()
    }
}

/// The thesis's constants (Figure 3.2); any other literal may be written too.
pub const THESIS_CONSTANTS: &[f64] =
    &[0.1, 0.2, 0.3, 0.3333, 1.0, 2.0, 3.0, std::f64::consts::PI, 5.0, 7.0, 11.0, 13.0];

/// Spellings of π in the surface syntax; the first is canonical.
pub const PI_NAMES: &[&str] = &["pi", "π"];

/// What a name used as a call (`name(...)`) refers to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CallOp {
    Unary(UnaryOp),
    Binary(BinaryOp),
    Pair(PairOp),
}

impl CallOp {
    pub fn from_name(name: &str) -> Option<Self> {
        UnaryOp::from_name(name)
            .map(CallOp::Unary)
            .or_else(|| BinaryOp::from_name(name).map(CallOp::Binary))
            .or_else(|| PairOp::from_name(name).map(CallOp::Pair))
    }

    /// Argument types, for the checker and for error messages.
    pub fn arguments(self) -> &'static [Type] {
        match self {
            CallOp::Unary(_) => &[Type::Scalar],
            CallOp::Binary(_) => &[Type::Scalar, Type::Scalar],
            CallOp::Pair(_) => &[Type::Vector, Type::Vector],
        }
    }
}

/// What a bare name refers to.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Terminal {
    Feature(Feature),
    Var(ScalarVar),
    Const(f64),
}

impl Terminal {
    pub fn from_name(name: &str) -> Option<Self> {
        if PI_NAMES.contains(&name) {
            return Some(Terminal::Const(std::f64::consts::PI));
        }
        Feature::from_name(name).map(Terminal::Feature).or_else(|| ScalarVar::from_name(name).map(Terminal::Var))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_unique_across_tables() {
        let mut names: Vec<&str> = Vec::new();
        names.extend(UnaryOp::ALL.iter().map(|o| o.name()));
        names.extend(BinaryOp::ALL.iter().map(|o| o.name()));
        names.extend(PairOp::ALL.iter().map(|o| o.name()));
        names.extend(Feature::ALL.iter().map(|o| o.name()));
        names.extend(ScalarVar::ALL.iter().map(|o| o.name()));
        names.extend(PI_NAMES);
        let count = names.len();
        names.sort();
        names.dedup();
        assert_eq!(names.len(), count, "a name is declared twice");
    }
}
