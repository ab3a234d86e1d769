//! Scene descriptions: the TOML format of `scenes/*.toml`, parsed with serde,
//! and the flat, checked form the path tracer consumes.
//!
//! The parsed file (`SceneFile`, with source spans) is kept apart from what is
//! built from it (`Description`); errors name the file and the line.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::Deserialize;
use toml::Spanned;

/// Which set a scene belongs to.
#[derive(Clone, Copy, Debug, Deserialize, serde::Serialize, PartialEq, Eq, PartialOrd, Ord)]
#[serde(rename_all = "lowercase")]
pub enum Split {
    Train,
    Test,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct SceneFile {
    split: Split,
    #[serde(default)]
    description: String,
    camera: CameraDef,
    /// Constant environment radiance.
    #[serde(default)]
    environment: [f32; 3],
    /// Longest path in segments, as Mitsuba's `max_depth`.
    #[serde(default = "default_max_depth")]
    max_depth: u32,
    materials: BTreeMap<String, MaterialDef>,
    shapes: Vec<Spanned<ShapeDef>>,
    /// An animation: the scene is a sequence of frames (docs/SCENES.md, "Sequences").
    sequence: Option<SequenceDef>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct SequenceDef {
    frames: u32,
    /// How far the camera's position moves a frame.
    #[serde(default)]
    camera: [f32; 3],
    /// How far the camera's look-at point moves a frame.
    #[serde(default)]
    look_at: [f32; 3],
}

fn default_max_depth() -> u32 {
    8
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct CameraDef {
    position: [f32; 3],
    look_at: [f32; 3],
    #[serde(default = "default_up")]
    up: [f32; 3],
    /// Field of view in degrees along the smaller image axis.
    fov: f32,
}

fn default_up() -> [f32; 3] {
    [0.0, 1.0, 0.0]
}

#[derive(Debug, Deserialize)]
#[serde(tag = "type", rename_all = "lowercase", deny_unknown_fields)]
enum MaterialDef {
    Diffuse {
        albedo: [f32; 3],
        texture: Option<TextureDef>,
    },
    Glossy {
        albedo: [f32; 3],
        roughness: f32,
        texture: Option<TextureDef>,
    },
    Mirror {
        #[serde(default = "white")]
        albedo: [f32; 3],
    },
    Glass {
        ior: f32,
        #[serde(default = "white")]
        albedo: [f32; 3],
    },
}

fn white() -> [f32; 3] {
    [1.0; 3]
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct TextureDef {
    /// checker, stripes or noise: between the material's albedo and `second`.
    pattern: Pattern,
    second: [f32; 3],
    /// Cycles per world unit.
    frequency: f32,
}

#[derive(Clone, Copy, Debug, Deserialize)]
#[serde(rename_all = "lowercase")]
enum Pattern {
    Checker,
    Stripes,
    Noise,
}

#[derive(Debug, Deserialize)]
#[serde(tag = "type", rename_all = "lowercase", deny_unknown_fields)]
enum ShapeDef {
    /// Mitsuba's rectangle: [-1,1]² in the local xy plane, normal +z, mapped by a row-major 3x4 `to_world`.
    Rectangle {
        to_world: [[f32; 4]; 3],
        material: String,
        emission: Option<[f32; 3]>,
        /// How far the shape moves a frame, in a sequence.
        #[serde(default)]
        step: [f32; 3],
    },
    /// Mitsuba's cube: [-1,1]³ mapped by `to_world`; faces point outwards.
    Cube {
        to_world: [[f32; 4]; 3],
        material: String,
        emission: Option<[f32; 3]>,
        /// How far the shape moves a frame, in a sequence.
        #[serde(default)]
        step: [f32; 3],
    },
    /// A parallelogram from a corner and two edges; the normal is u × v.
    Quad {
        origin: [f32; 3],
        u: [f32; 3],
        v: [f32; 3],
        material: String,
        emission: Option<[f32; 3]>,
        /// How far the shape moves a frame, in a sequence.
        #[serde(default)]
        step: [f32; 3],
    },
    Sphere {
        center: [f32; 3],
        radius: f32,
        material: String,
        emission: Option<[f32; 3]>,
        /// How far the shape moves a frame, in a sequence.
        #[serde(default)]
        step: [f32; 3],
    },
}

/// Material kinds as the path tracer numbers them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MaterialKind {
    Diffuse = 0,
    Glossy = 1,
    Mirror = 2,
    Glass = 3,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    pub kind: MaterialKind,
    /// 0 constant, 1 checker, 2 stripes, 3 noise.
    pub texture: u32,
    pub albedo: [f32; 3],
    /// Roughness (glossy) or index of refraction (glass).
    pub parameter: f32,
    pub second: [f32; 3],
    pub frequency: f32,
}

#[derive(Clone, Debug, PartialEq)]
pub enum Geometry {
    Parallelogram { origin: [f32; 3], u: [f32; 3], v: [f32; 3] },
    Sphere { center: [f32; 3], radius: f32 },
}

#[derive(Clone, Debug, PartialEq)]
pub struct Primitive {
    pub geometry: Geometry,
    pub material: usize,
    pub emission: Option<[f32; 3]>,
    /// How far it moves a frame (a sequence's moving object or light).
    pub step: [f32; 3],
}

/// A scene's animation: each frame moves the camera and the moving shapes
/// by their steps (docs/SCENES.md, "Sequences").
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Animation {
    pub frames: u32,
    pub camera_step: [f32; 3],
    pub look_at_step: [f32; 3],
}

#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    pub position: [f32; 3],
    pub look_at: [f32; 3],
    pub up: [f32; 3],
    pub fov_degrees: f32,
}

/// A checked scene, ready for the path tracer.
#[derive(Clone, Debug)]
pub struct Description {
    pub name: String,
    pub split: Split,
    pub summary: String,
    pub camera: Camera,
    pub environment: [f32; 3],
    pub max_depth: u32,
    pub materials: Vec<Material>,
    pub primitives: Vec<Primitive>,
    /// The animation, where the scene is a sequence.
    pub animation: Option<Animation>,
    /// The frame of the animation this description is at (0: as written).
    pub frame: u32,
    /// The file's text, for the dataset cache key.
    pub source: String,
}

#[derive(Debug, thiserror::Error)]
pub enum DescriptionError {
    /// The system's reason in the message (`cause`, not a `source`, which the edges would print again).
    #[error("{}: {cause}", file.display())]
    Io { file: PathBuf, cause: std::io::Error },
    #[error("{}: {message}", file.display())]
    Syntax { file: PathBuf, message: String },
    #[error("{}:{line}: {message}", file.display())]
    Invalid { file: PathBuf, line: usize, message: String },
}

impl Description {
    pub fn load(path: &Path) -> Result<Description, DescriptionError> {
        let text = std::fs::read_to_string(path).map_err(|e| DescriptionError::Io { file: path.into(), cause: e })?;
        let name = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "scene".into());
        Self::parse(&name, &text, path)
    }

    /// Parse a description's text; `file` is only used in messages.
    pub fn parse(name: &str, text: &str, file: &Path) -> Result<Description, DescriptionError> {
        let parsed: SceneFile = toml::from_str(text).map_err(|e| DescriptionError::Syntax {
            file: file.into(),
            message: e.to_string().trim_end().to_string(),
        })?;
        let line_of = |offset: usize| text[..offset.min(text.len())].matches('\n').count() + 1;
        let invalid = |offset: usize, message: String| DescriptionError::Invalid {
            file: file.into(),
            line: line_of(offset),
            message,
        };

        let names: Vec<&String> = parsed.materials.keys().collect();
        let mut materials = Vec::new();
        for def in parsed.materials.values() {
            materials.push(material(def));
        }
        let mut primitives = Vec::new();
        for spanned in &parsed.shapes {
            let (shape, at) = (spanned.get_ref(), spanned.span().start);
            let (material_ref, emission, step) = match shape {
                ShapeDef::Rectangle { material, emission, step, .. }
                | ShapeDef::Cube { material, emission, step, .. }
                | ShapeDef::Quad { material, emission, step, .. }
                | ShapeDef::Sphere { material, emission, step, .. } => (material, *emission, *step),
            };
            if step.iter().any(|c| !c.is_finite()) {
                return Err(invalid(at, "step must be finite".into()));
            }
            if step != [0.0; 3] && parsed.sequence.is_none() {
                return Err(invalid(at, "a shape moves (`step`) only in a sequence: add a [sequence] table".into()));
            }
            let material = names.iter().position(|n| *n == material_ref).ok_or_else(|| {
                invalid(
                    at,
                    format!(
                        "no material `{}`; the file defines: {}",
                        material_ref,
                        names.iter().map(|s| s.as_str()).collect::<Vec<_>>().join(", ")
                    ),
                )
            })?;
            if let Some(e) = emission {
                if e.iter().any(|c| !c.is_finite() || *c < 0.0) {
                    return Err(invalid(at, "emission must be finite and non-negative".into()));
                }
            }
            for geometry in geometries(shape) {
                if let Geometry::Sphere { radius, .. } = geometry {
                    if radius.is_nan() || radius <= 0.0 {
                        return Err(invalid(at, format!("sphere radius must be positive, is {radius}")));
                    }
                }
                primitives.push(Primitive { geometry, material, emission, step });
            }
        }
        if parsed.camera.fov.is_nan() || parsed.camera.fov <= 0.0 || parsed.camera.fov >= 180.0 {
            return Err(invalid(0, format!("camera fov must be in (0, 180) degrees, is {}", parsed.camera.fov)));
        }
        let animation = match &parsed.sequence {
            None => None,
            Some(s) => {
                let at = text.find("[sequence]").unwrap_or(0);
                if !(2..=MAX_FRAMES).contains(&s.frames) {
                    return Err(invalid(at, format!("a sequence has 2 to {MAX_FRAMES} frames, not {}", s.frames)));
                }
                if s.camera.iter().chain(&s.look_at).any(|c| !c.is_finite()) {
                    return Err(invalid(at, "the camera's steps must be finite".into()));
                }
                Some(Animation { frames: s.frames, camera_step: s.camera, look_at_step: s.look_at })
            }
        };
        Ok(Description {
            name: name.to_string(),
            split: parsed.split,
            summary: parsed.description,
            camera: Camera {
                position: parsed.camera.position,
                look_at: parsed.camera.look_at,
                up: parsed.camera.up,
                fov_degrees: parsed.camera.fov,
            },
            environment: parsed.environment,
            max_depth: parsed.max_depth.max(1),
            materials,
            primitives,
            animation,
            frame: 0,
            source: text.to_string(),
        })
    }

    /// This scene at frame `k` of its animation: the camera and every moving
    /// shape advanced by k steps. A still scene is the same at every frame.
    pub fn at_frame(&self, k: u32) -> Description {
        let Some(animation) = self.animation else { return self.clone() };
        let moved = |p: [f32; 3], step: [f32; 3]| std::array::from_fn(|i| p[i] + k as f32 * step[i]);
        let mut d = self.clone();
        d.frame = k;
        d.camera.position = moved(self.camera.position, animation.camera_step);
        d.camera.look_at = moved(self.camera.look_at, animation.look_at_step);
        for p in &mut d.primitives {
            p.geometry = match p.geometry {
                Geometry::Parallelogram { origin, u, v } => {
                    Geometry::Parallelogram { origin: moved(origin, p.step), u, v }
                }
                Geometry::Sphere { center, radius } => Geometry::Sphere { center: moved(center, p.step), radius },
            };
        }
        d
    }
}

impl Description {
    /// The frame before this one's camera, the one its motion vectors
    /// point into: a frame before the first is extrapolated back.
    pub fn at_frame_before(&self) -> Description {
        let Some(animation) = self.animation else { return self.clone() };
        let back = |p: [f32; 3], step: [f32; 3]| std::array::from_fn(|i| p[i] - step[i]);
        let mut d = self.clone();
        d.camera.position = back(self.camera.position, animation.camera_step);
        d.camera.look_at = back(self.camera.look_at, animation.look_at_step);
        d
    }
}

/// The most frames a scene's sequence may have.
pub const MAX_FRAMES: u32 = 10_000;

fn material(def: &MaterialDef) -> Material {
    let (kind, albedo, parameter, texture) = match def {
        MaterialDef::Diffuse { albedo, texture } => (MaterialKind::Diffuse, *albedo, 0.0, texture.as_ref()),
        MaterialDef::Glossy { albedo, roughness, texture } => {
            (MaterialKind::Glossy, *albedo, *roughness, texture.as_ref())
        }
        MaterialDef::Mirror { albedo } => (MaterialKind::Mirror, *albedo, 0.0, None),
        MaterialDef::Glass { ior, albedo } => (MaterialKind::Glass, *albedo, *ior, None),
    };
    let (pattern, second, frequency) = match texture {
        Some(t) => (
            match t.pattern {
                Pattern::Checker => 1,
                Pattern::Stripes => 2,
                Pattern::Noise => 3,
            },
            t.second,
            t.frequency,
        ),
        None => (0, albedo, 1.0),
    };
    Material { kind, texture: pattern, albedo, parameter, second, frequency }
}

/// Apply a row-major 3x4 affine matrix to a point.
fn transform(m: &[[f32; 4]; 3], p: [f32; 3]) -> [f32; 3] {
    std::array::from_fn(|r| m[r][0] * p[0] + m[r][1] * p[1] + m[r][2] * p[2] + m[r][3])
}

fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// Mitsuba's rectangle [-1,1]² × {0} under `m`: corner (-1,-1), edges to (1,-1) and (-1,1).
fn rectangle(m: &[[f32; 4]; 3], corner: [f32; 3], du: [f32; 3], dv: [f32; 3]) -> Geometry {
    let origin = transform(m, corner);
    let u = sub(transform(m, [corner[0] + du[0], corner[1] + du[1], corner[2] + du[2]]), origin);
    let v = sub(transform(m, [corner[0] + dv[0], corner[1] + dv[1], corner[2] + dv[2]]), origin);
    Geometry::Parallelogram { origin, u, v }
}

fn geometries(shape: &ShapeDef) -> Vec<Geometry> {
    match shape {
        ShapeDef::Rectangle { to_world, .. } => {
            vec![rectangle(to_world, [-1.0, -1.0, 0.0], [2.0, 0.0, 0.0], [0.0, 2.0, 0.0])]
        }
        ShapeDef::Cube { to_world, .. } => {
            // Six faces of [-1,1]³, each with u × v pointing outwards.
            let faces: [([f32; 3], [f32; 3], [f32; 3]); 6] = [
                ([-1.0, -1.0, 1.0], [2.0, 0.0, 0.0], [0.0, 2.0, 0.0]),
                ([-1.0, -1.0, -1.0], [0.0, 2.0, 0.0], [2.0, 0.0, 0.0]),
                ([1.0, -1.0, -1.0], [0.0, 2.0, 0.0], [0.0, 0.0, 2.0]),
                ([-1.0, -1.0, -1.0], [0.0, 0.0, 2.0], [0.0, 2.0, 0.0]),
                ([-1.0, 1.0, -1.0], [0.0, 0.0, 2.0], [2.0, 0.0, 0.0]),
                ([-1.0, -1.0, -1.0], [2.0, 0.0, 0.0], [0.0, 0.0, 2.0]),
            ];
            faces.iter().map(|(c, u, v)| rectangle(to_world, *c, *u, *v)).collect()
        }
        ShapeDef::Quad { origin, u, v, .. } => vec![Geometry::Parallelogram { origin: *origin, u: *u, v: *v }],
        ShapeDef::Sphere { center, radius, .. } => vec![Geometry::Sphere { center: *center, radius: *radius }],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
        [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    }

    #[test]
    fn cube_faces_point_outwards() {
        let identity = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]];
        for g in
            geometries(&ShapeDef::Cube { to_world: identity, material: "m".into(), emission: None, step: [0.0; 3] })
        {
            let Geometry::Parallelogram { origin, u, v } = g else { panic!() };
            let centre =
                [origin[0] + (u[0] + v[0]) / 2.0, origin[1] + (u[1] + v[1]) / 2.0, origin[2] + (u[2] + v[2]) / 2.0];
            let n = cross(u, v);
            assert!(n[0] * centre[0] + n[1] * centre[1] + n[2] * centre[2] > 0.0, "face at {centre:?} points inwards");
        }
    }

    #[test]
    fn errors_name_the_file_and_line() {
        let text = "split = \"train\"\n[camera]\nposition = [0,0,1]\nlook_at = [0,0,0]\nfov = 40\n[materials.white]\ntype = \"diffuse\"\nalbedo = [1,1,1]\n[[shapes]]\ntype = \"sphere\"\ncenter = [0,0,0]\nradius = 1\nmaterial = \"whte\"\n";
        let err = Description::parse("x", text, Path::new("scenes/x.toml")).unwrap_err().to_string();
        assert!(err.starts_with("scenes/x.toml:9:") && err.contains("whte") && err.contains("white"), "{err}");
        let err = Description::parse("x", "split = \"train\"\n[camera]\nposition = 3\n", Path::new("y.toml"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("y.toml") && err.contains("line 3"), "{err}");
    }
}
