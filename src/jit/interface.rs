//! The binding interface of a kernel: the only place where binding slots,
//! resource types, access and the uniform's fields and offsets are assigned.
//!
//! [`BindingInterface::of`] builds it from the kernel kind and the inputs the
//! expression reads. The templates receive its WGSL declarations, `gpu` builds
//! explicit bind-group and pipeline layouts and fills bind groups by role from
//! it, and `export` derives its manifest and each target's slots from it.

use serde::Serialize;

use super::kernel::{Input, KernelKind, KernelLayout, OutputFormat, Shape, TEMPLATE_VERSION, WORKGROUP};
use crate::lang::{Feature, ScalarVar};

/// Where filterjit's own à-trous kernels find the `texture` feature (the
/// albedo) after their first pass, when they read it at every tap with the
/// world position and the normal and carry no variance: its x in the
/// colour's alpha (written there by every pass), its y and z in the fourth
/// channels of the world position's and the normal's images (written there
/// when those are uploaded, `gpu::SceneBuffers`). One texture load a tap
/// fewer: on lavapipe a tap's loads are most of its cost (docs/JOURNAL.md,
/// "The albedo in the fourth channels").
pub const TEXTURE_IN_FOURTH_CHANNELS: [(Feature, usize); 2] = [(Feature::WorldPosition, 1), (Feature::Normal, 2)];

/// The feature whose image's fourth channel holds component `k` of the
/// texture after the first pass, or `None` for the colour's alpha (the
/// component `TEXTURE_IN_FOURTH_CHANNELS` leaves).
pub fn texture_carrier(k: usize) -> Option<Feature> {
    TEXTURE_IN_FOURTH_CHANNELS.iter().find(|(_, c)| *c == k).map(|(f, _)| *f)
}

/// What a binding is for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Role {
    /// The uniform [`Params`] (export: with one normalisation scale per input).
    Params,
    /// The noisy colour.
    Color,
    /// The filtered colour (filter, probe, export), or per-workgroup relMSE sums (fitness).
    Output,
    /// Per-pixel domain-error bits (filter, probe), or per-workgroup bits (fitness).
    Flags,
    /// A per-pixel input the expression reads.
    Input(Input),
    /// The reference image (fitness).
    Reference,
    /// The factor remodulation multiplies the result by (pipelines that demodulate).
    Modulation,
    /// The colour variance carried to the next à-trous pass (kernels that read `colorVariance`).
    VarianceOut,
    /// The image an à-trous fitness pass hands the next pass.
    Image,
    /// The raw albedo demodulation divides by (the pre-pass).
    Albedo,
    /// What the outlier rule measured, packed (x `localMean`, y `localStd`,
    /// z `clampedShare`): the exported pre-pass writes it as one texture, since
    /// WebGPU guarantees only four storage textures per stage.
    Local,
    /// A fitness kernel's per-pixel relMSE terms, which the reduction reads.
    Terms,
    /// A fitness kernel's per-pixel domain-error bits, which the reduction reads.
    PixelFlags,
    /// The surface spread's one-texel sum of the clamped luminance.
    Total,
    /// The surface spread's per-pixel (normal's direction, clamped luminance),
    /// which its first dispatch writes and every later one's taps read.
    Surface,
    /// A frame's motion vectors to the frame before (the temporal stage).
    Motion,
    /// A frame's surface: the normal's direction and the depth (the temporal stage).
    Geometry,
    /// The frame before's surface, which the history's taps are tested against.
    PreviousGeometry,
    /// The frame before's albedo, likewise (the frame's own is `Albedo`).
    PreviousAlbedo,
    /// Each pixel's sample variance of the luminance, which the temporal
    /// stage writes and its variance kernel blurs into `temporalVariance`.
    SampleVariance,
    /// The history's modulation (the albedo blended over frames), read.
    PastModulation,
    /// The modulation the temporal stage blends, written: what the form's
    /// result is multiplied back by, and what the next frame keeps.
    ModulationOut,
    /// `anchor`'s blurred sums (the frame's luminance, its square, the
    /// filtered image's luminance), which each blur level writes and the next reads.
    Sums,
    /// The temporal stage's history: the colour the frame before kept.
    History,
    /// The history's moments (m1, m2, r, n), read.
    Moments,
    /// The moments the temporal stage keeps for the next frame, written.
    MomentsOut,
    /// What the temporal stage accumulated, packed (x `historyLength`, y
    /// `temporalVariance`): the exported stage writes one texture, as the
    /// pre-pass its `Local`.
    Accumulated,
}

/// Texel format of a storage texture an exported shader writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum TexelFormat {
    /// A colour image, in the format the user chose.
    Color(OutputFormat),
    /// One float: the colour variance an à-trous pass carries.
    R32float,
}

impl TexelFormat {
    pub fn wgsl(self) -> &'static str {
        match self {
            TexelFormat::Color(format) => format.wgsl(),
            TexelFormat::R32float => "r32float",
        }
    }
}

/// Element type of a storage buffer.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Element {
    F32,
    U32,
    /// A fitness kernel's per-pixel pair: relMSE terms and the output's luminance.
    Vec2F32,
    Vec4F32,
}

impl Element {
    pub fn wgsl(self) -> &'static str {
        match self {
            Element::F32 => "f32",
            Element::U32 => "u32",
            Element::Vec2F32 => "vec2<f32>",
            Element::Vec4F32 => "vec4<f32>",
        }
    }

    pub fn bytes(self) -> u32 {
        match self {
            Element::F32 | Element::U32 => 4,
            Element::Vec2F32 => 8,
            Element::Vec4F32 => 16,
        }
    }

    /// The element a buffer of `input` holds (1-D features and variances: f32).
    pub fn of_input(input: Input) -> Element {
        if input.components() == 1 {
            Element::F32
        } else {
            Element::Vec4F32
        }
    }
}

/// The kind of resource bound at a slot.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Resource {
    /// The `Params` struct in a uniform buffer (exported shaders).
    Uniform,
    /// The `Params` struct in a read-only storage buffer (filterjit's own
    /// kernels): see [`own_params`].
    ParamsStorage,
    Storage {
        element: Element,
        writable: bool,
    },
    /// `texture_2d<f32>`, read with `textureLoad` (no sampler).
    SampledTexture,
    /// `texture_storage_2d<format, write>`.
    StorageTexture(TexelFormat),
}

/// One binding of group 0.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct Binding {
    pub slot: u32,
    pub role: Role,
    /// The WGSL variable's name.
    pub ident: String,
    pub resource: Resource,
}

impl Binding {
    /// The WGSL declaration of this binding.
    pub fn declaration(&self) -> String {
        let (space, ty) = match self.resource {
            Resource::Uniform => ("<uniform>", "Params".to_string()),
            Resource::ParamsStorage => ("<storage, read>", "Params".to_string()),
            Resource::Storage { element, writable: false } => ("<storage, read>", format!("array<{}>", element.wgsl())),
            Resource::Storage { element, writable: true } => {
                ("<storage, read_write>", format!("array<{}>", element.wgsl()))
            }
            Resource::SampledTexture => ("", "texture_2d<f32>".to_string()),
            Resource::StorageTexture(format) => ("", format!("texture_storage_2d<{}, write>", format.wgsl())),
        };
        format!("@group(0) @binding({}) var{space} {}: {ty};", self.slot, self.ident)
    }
}

/// The uniform header every windowed kernel reads (`struct Params` in the
/// templates). An exported shader follows it with one `vec4<f32>` scale per input.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Params {
    pub width: u32,
    pub height: u32,
    pub radius: u32,
    /// First image row of this dispatch (banded dispatches); unused by exported shaders.
    pub row_offset: u32,
}

/// The uniform of an à-trous kernel: the [`Params`] header, then the pass.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct AtrousParams {
    pub base: Params,
    /// Pixel step between stencil taps: 2^level.
    pub step: u32,
    /// The pass index, from 0.
    pub level: u32,
    /// 1 in the last pass where it remodulates, else 0 (filterjit's form
    /// leaves remodulation to `planefit` where the fit follows).
    pub last: u32,
    pub _pad: u32,
}

/// One field of the uniform, as an exported shader's manifest lists it.
#[derive(Clone, Debug, PartialEq, Eq, Hash, Serialize)]
pub struct UniformField {
    pub name: String,
    #[serde(rename = "type")]
    pub ty: &'static str,
    pub offset: u32,
    pub meaning: String,
}

/// How a pipeline accesses one slot: what its bind-group layout entry needs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Access {
    Uniform,
    StorageRead,
    StorageReadWrite,
    SampledTexture,
    StorageTexture(TexelFormat),
}

/// One slot of group 0 and how it is accessed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Slot {
    pub slot: u32,
    pub access: Access,
}

impl Resource {
    pub fn access(self) -> Access {
        match self {
            Resource::Uniform => Access::Uniform,
            Resource::ParamsStorage | Resource::Storage { writable: false, .. } => Access::StorageRead,
            Resource::Storage { writable: true, .. } => Access::StorageReadWrite,
            Resource::SampledTexture => Access::SampledTexture,
            Resource::StorageTexture(format) => Access::StorageTexture(format),
        }
    }
}

/// Every binding of a kernel and the layout of its uniform.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct BindingInterface {
    pub kind: KernelKind,
    /// Group 0, dense from slot 0, in slot order.
    pub bindings: Vec<Binding>,
    pub uniform: Vec<UniformField>,
    pub uniform_bytes: u32,
}

impl BindingInterface {
    /// The interface of a `kind` kernel reading `layout`'s inputs: slot 0 the
    /// uniform, 1 the colour, 2 the output, then (except exported shaders) 3 the
    /// flags, then the inputs in `layout` order, then (fitness) the reference;
    /// then what the `shape` needs: the modulation (remodulating kernels), the
    /// carried variance (à-trous kernels reading `colorVariance`) and the
    /// pass's image (à-trous fitness kernels).
    pub fn of(kind: KernelKind, layout: &KernelLayout, shape: Shape) -> BindingInterface {
        let textures = matches!(kind, KernelKind::Export(_));
        // What the kernel reads: textures in exported shaders and in
        // filterjit's à-trous form ([`Self::samples_images`]), storage buffers elsewhere.
        let sampled = Self::samples_images(kind, shape);
        let prefix = if sampled { "tex_" } else { "buf_" };
        let read = |element| {
            if sampled {
                Resource::SampledTexture
            } else {
                Resource::Storage { element, writable: false }
            }
        };
        let written = |element| Resource::Storage { element, writable: true };
        let mut roles: Vec<(Role, Resource, String)> = vec![
            (Role::Params, if textures { Resource::Uniform } else { own_params() }, "params".into()),
            (Role::Color, read(Element::Vec4F32), format!("{prefix}color")),
        ];
        match kind {
            KernelKind::Filter | KernelKind::Probe => {
                roles.push((Role::Output, written(Element::Vec4F32), "buf_out".into()));
                roles.push((Role::Flags, written(Element::U32), "buf_flags".into()));
            }
            KernelKind::Fitness => {
                // Per pixel and member; `jit::reduce` sums them per workgroup.
                roles.push((Role::Output, written(Element::Vec2F32), "buf_terms".into()));
                roles.push((Role::Flags, written(Element::U32), "buf_pixel_flags".into()));
            }
            KernelKind::Export(format) => {
                roles.push((Role::Output, Resource::StorageTexture(TexelFormat::Color(format)), "tex_out".into()))
            }
        }
        for input in &layout.inputs {
            let ident = format!("{prefix}{}", input.describe().to_ascii_lowercase());
            roles.push((Role::Input(*input), read(Element::of_input(*input)), ident));
        }
        if kind == KernelKind::Fitness {
            // Read at the pixel itself, as the fitness kernels after the form read it.
            let reference = Resource::Storage { element: Element::Vec4F32, writable: false };
            roles.push((Role::Reference, reference, "buf_reference".into()));
        }
        if shape.remodulate {
            roles.push((Role::Modulation, read(Element::Vec4F32), format!("{prefix}modulation")));
        }
        if shape.atrous && layout.carried_variance().is_some() {
            roles.push(match textures {
                true => (Role::VarianceOut, Resource::StorageTexture(TexelFormat::R32float), "tex_variance_out".into()),
                false => (Role::VarianceOut, written(Element::F32), "buf_variance_out".into()),
            });
        }
        if shape.atrous && kind == KernelKind::Fitness {
            roles.push((Role::Image, written(Element::Vec4F32), "buf_image".into()));
        }
        let bindings = dense(roles);

        let mut uniform = vec![
            field("width", "u32", 0, "image width in pixels"),
            field("height", "u32", 4, "image height in pixels"),
            field("radius", "u32", 8, "window radius r: (2r+1)^2 pixels"),
        ];
        if textures {
            uniform.push(field("_pad", "u32", 12, "unused"));
        } else {
            uniform.push(field("row_offset", "u32", 12, "first image row of this dispatch"));
        }
        if shape.atrous {
            uniform.push(field("step", "u32", 16, "pixel step between stencil taps: 2^level"));
            uniform.push(field("level", "u32", 20, "the a-trous pass, from 0"));
            uniform.push(field("last", "u32", 24, "1 in the last pass, else 0"));
            // (`_pad` is taken at offset 12 in an exported shader's header.)
            uniform.push(field(if textures { "_pad2" } else { "_pad" }, "u32", 28, "unused"));
        }
        let header = if shape.atrous { std::mem::size_of::<AtrousParams>() } else { std::mem::size_of::<Params>() };
        if textures {
            // An exported shader's scales follow the header, one vec4 per input.
            for (k, input) in layout.inputs.iter().filter(|i| i.is_normalised()).enumerate() {
                uniform.push(UniformField {
                    name: format!("scale[{k}]"),
                    ty: "vec4<f32>",
                    offset: header as u32 + 16 * k as u32,
                    meaning: format!("x: normalisation scale of {}; y, z, w unused", input.describe()),
                });
            }
        }
        let scales = layout.inputs.iter().filter(|i| i.is_normalised()).count() as u32;
        let uniform_bytes = header as u32 + if textures { 16 * scales } else { 0 };
        BindingInterface { kind, bindings, uniform, uniform_bytes }
    }

    /// Whether a `kind` kernel of `shape` reads its images (colour, inputs,
    /// modulation) as sampled textures: exported shaders, and filterjit's own
    /// à-trous filter and fitness kernels, whose taps are most of a frame's loads. A
    /// texel fetch loads a pixel's channels for every lane at once on software
    /// drivers, where a storage-buffer load goes lane by lane, channel by
    /// channel (docs/JOURNAL.md, "Textures for the form's taps"). Window
    /// kernels keep storage buffers: their workgroup tiles stage them.
    pub fn samples_images(kind: KernelKind, shape: Shape) -> bool {
        match kind {
            KernelKind::Export(_) => true,
            KernelKind::Filter | KernelKind::Fitness => shape.atrous,
            KernelKind::Probe => false,
        }
    }

    /// The variance an à-trous kernel carries from pass to pass (one that
    /// writes `VarianceOut`), if any: `KernelLayout::carried_variance`'s.
    pub fn carried_variance(&self) -> Option<ScalarVar> {
        self.binding(Role::VarianceOut)?;
        let variances = self
            .inputs()
            .filter_map(|(_, input)| match input {
                Input::Variance(v) => Some(v),
                Input::Feature(_) => None,
            })
            .collect();
        crate::pipeline::FilterPipeline::carried_variance(&variances)
    }

    /// Whether the kernel reads its colour (and its other images) as sampled textures.
    pub fn samples_color(&self) -> bool {
        self.binding(Role::Color).is_some_and(|b| b.resource == Resource::SampledTexture)
    }

    /// The binding that plays `role`, if the kernel has one.
    pub fn binding(&self, role: Role) -> Option<&Binding> {
        self.bindings.iter().find(|b| b.role == role)
    }

    /// How the kernel binds its `Params` (a uniform or a storage buffer).
    pub fn params(&self) -> Resource {
        self.binding(Role::Params).map_or_else(|| panic!("a {:?} kernel has no Params", self.kind), |b| b.resource)
    }

    /// The WGSL name of `role`'s binding; panics if the kernel has none (a filterjit bug).
    pub fn ident(&self, role: Role) -> &str {
        &self.binding(role).unwrap_or_else(|| panic!("a {:?} kernel has no {role:?} binding", self.kind)).ident
    }

    /// The slot of `role`; panics if the kernel has none (a filterjit bug).
    pub fn slot(&self, role: Role) -> u32 {
        self.binding(role).unwrap_or_else(|| panic!("a {:?} kernel has no {role:?} binding", self.kind)).slot
    }

    /// Every slot and its access, in slot order.
    pub fn slots(&self) -> Vec<Slot> {
        self.bindings.iter().map(|b| Slot { slot: b.slot, access: b.resource.access() }).collect()
    }

    /// The per-pixel inputs, in slot order.
    pub fn inputs(&self) -> impl Iterator<Item = (&Binding, Input)> {
        self.bindings.iter().filter_map(|b| match b.role {
            Role::Input(input) => Some((b, input)),
            _ => None,
        })
    }

    /// Storage buffers the kernel binds (device limits count them per stage).
    pub fn storage_buffers(&self) -> u32 {
        self.bindings
            .iter()
            .filter(|b| matches!(b.resource, Resource::Storage { .. } | Resource::ParamsStorage))
            .count() as u32
    }

    /// Sampled textures the kernel binds.
    pub fn sampled_textures(&self) -> usize {
        self.bindings.iter().filter(|b| b.resource == Resource::SampledTexture).count()
    }

    /// What every built-in kernel's template (pre-pass, spread, reduction)
    /// is rendered with: the versions, the workgroup, and this interface's
    /// `struct Params` and declarations. Each kernel adds its own constants.
    pub fn template_context(&self) -> InterfaceContext {
        InterfaceContext {
            crate_version: env!("CARGO_PKG_VERSION"),
            template_version: TEMPLATE_VERSION,
            workgroup_x: WORKGROUP[0],
            workgroup_y: WORKGROUP[1],
            params_struct: self.params_struct(),
            declarations: self.declarations(),
        }
    }

    /// The WGSL declarations of every binding, one line each.
    pub fn declarations(&self) -> String {
        self.bindings.iter().map(|b| b.declaration() + "\n").collect()
    }

    /// The WGSL `struct Params` of the uniform: the [`Params`] header, and in
    /// exported shaders one `vec4<f32>` normalisation scale per input.
    pub fn params_struct(&self) -> String {
        let mut text = String::from("struct Params {\n");
        for f in self.uniform.iter().filter(|f| !f.name.starts_with("scale[")) {
            text.push_str(&format!("    {}: {},\n", f.name, f.ty));
        }
        let scales = self.uniform.iter().filter(|f| f.name.starts_with("scale[")).count();
        if scales > 0 {
            text.push_str(&format!("    scale: array<vec4<f32>, {scales}>,\n"));
        }
        text.push_str("}\n");
        text
    }

    /// A stable text encoding, for cache keys.
    pub fn encode(&self) -> String {
        self.bindings
            .iter()
            .map(|b| format!("{}:{}:{}", b.slot, b.ident, b.declaration()))
            .collect::<Vec<_>>()
            .join("\n")
    }
}

/// Group 0's bindings from `roles` in order: slots dense from 0.
/// Where filterjit's own kernels (not exported shaders) read their `Params`:
/// a read-only storage buffer, not a uniform buffer. Mesa's lavapipe (22.x,
/// Debian 12's) specialises a compute shader on the values of uniforms that
/// steer its control flow (the à-trous pass's `last`, loop bounds) and
/// recompiles it with LLVM at every dispatch that binds new values, with no
/// cache of the variants: a small kernel was compiled again in every à-trous
/// pass and for every scene of a fitness batch. Storage loads are opaque to
/// that pass, so each pipeline compiles once (docs/JOURNAL.md, "Uniforms
/// that recompile"). A few scalars read from a storage buffer cost a real GPU
/// nothing measurable; exported shaders keep the uniform an engine expects.
pub const fn own_params() -> Resource {
    Resource::ParamsStorage
}

/// The 16-byte uniform of a kernel over whole images: width, height, then two u32 `fields` (name, meaning).
pub(super) fn image_uniform(fields: [(&str, &str); 2]) -> Vec<UniformField> {
    typed_image_uniform(fields.map(|(name, meaning)| (name, "u32", meaning)))
}

/// [`image_uniform`] with each of the two fields' WGSL type given (name, type, meaning).
pub(super) fn typed_image_uniform(fields: [(&str, &'static str, &str); 2]) -> Vec<UniformField> {
    let [(a, a_type, a_meaning), (b, b_type, b_meaning)] = fields;
    vec![
        field("width", "u32", 0, "image width in pixels"),
        field("height", "u32", 4, "image height in pixels"),
        field(a, a_type, 8, a_meaning),
        field(b, b_type, 12, b_meaning),
    ]
}

pub(super) fn dense(roles: impl IntoIterator<Item = (Role, Resource, String)>) -> Vec<Binding> {
    roles
        .into_iter()
        .enumerate()
        .map(|(slot, (role, resource, ident))| Binding { slot: slot as u32, role, ident, resource })
        .collect()
}

pub(super) fn field(name: &str, ty: &'static str, offset: u32, meaning: &str) -> UniformField {
    UniformField { name: name.into(), ty, offset, meaning: meaning.into() }
}

/// What every kernel's template reads from its interface: the versions that
/// head the WGSL, the workgroup, the uniform's struct and the bindings.
#[derive(Clone, Debug, serde::Serialize)]
pub struct InterfaceContext {
    pub crate_version: &'static str,
    pub template_version: u32,
    pub workgroup_x: u32,
    pub workgroup_y: u32,
    pub params_struct: String,
    pub declarations: String,
}

/// A built-in kernel's template context: its interface's values and its own
/// (`values`, a struct of the kernel's: the names its template reads).
#[derive(serde::Serialize)]
struct BuiltinContext<'a, T: serde::Serialize> {
    #[serde(flatten)]
    interface: InterfaceContext,
    #[serde(flatten)]
    values: &'a T,
}

/// A built-in kernel's template rendered with its interface's values and its
/// own: it ships in the binary, so a template that does not parse or render
/// is filterjit's bug.
pub fn render_builtin<T: serde::Serialize>(
    name: &str,
    template: &str,
    interface: &BindingInterface,
    values: &T,
) -> String {
    let context = BuiltinContext { interface: interface.template_context(), values };
    let context = tera::Context::from_serialize(&context).unwrap_or_else(|e| panic!("built-in {name} context: {e}"));
    let mut tera = tera::Tera::default();
    tera.add_raw_template(name, template).unwrap_or_else(|e| panic!("built-in {name} template parses: {e}"));
    tera.render(name, &context).unwrap_or_else(|e| panic!("built-in {name} template renders: {e}"))
}

/// The values of a built-in kernel that reads nothing but its interface.
#[derive(serde::Serialize)]
pub struct NoValues {}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lang::{Feature, ScalarVar};

    #[test]
    fn slots_are_dense_and_roles_unique() {
        let layout =
            KernelLayout { inputs: vec![Input::Feature(Feature::Normal), Input::Variance(ScalarVar::ColorVariance)] };
        for kind in
            [KernelKind::Filter, KernelKind::Probe, KernelKind::Fitness, KernelKind::Export(OutputFormat::Rgba16float)]
        {
            let interface = BindingInterface::of(kind, &layout, Shape::WINDOW);
            for (k, b) in interface.bindings.iter().enumerate() {
                assert_eq!(b.slot, k as u32, "{kind:?}");
                assert_eq!(interface.bindings.iter().filter(|o| o.role == b.role).count(), 1, "{kind:?}");
            }
            assert_eq!(interface.inputs().count(), 2);
        }
        let fitness = BindingInterface::of(KernelKind::Fitness, &layout, Shape::WINDOW);
        assert_eq!(fitness.slot(Role::Reference), 6);
        // Colour, terms, flags, two inputs, reference, and the Params.
        assert_eq!(fitness.storage_buffers(), 7);
        assert_eq!(fitness.params(), Resource::ParamsStorage);
        assert_eq!(BindingInterface::reduce().params(), Resource::ParamsStorage);
        assert_eq!(BindingInterface::prepass(None).params(), Resource::ParamsStorage);
        let export = BindingInterface::of(KernelKind::Export(OutputFormat::Rgba16float), &layout, Shape::WINDOW);
        assert_eq!(export.params(), Resource::Uniform);
        assert_eq!(BindingInterface::prepass(Some(OutputFormat::Rgba16float)).params(), Resource::Uniform);
        assert_eq!(export.binding(Role::Flags), None);
        assert_eq!(export.uniform_bytes, 16 + 32);
        assert_eq!(export.sampled_textures(), 3);
    }

    #[test]
    fn the_a_trous_form_samples_its_images_and_writes_buffers() {
        let layout =
            KernelLayout { inputs: vec![Input::Feature(Feature::Normal), Input::Variance(ScalarVar::ColorVariance)] };
        let atrous = Shape { atrous: true, remodulate: true, stencil: crate::pipeline::Stencil::Cubic5 };
        for kind in [KernelKind::Filter, KernelKind::Fitness] {
            let interface = BindingInterface::of(kind, &layout, atrous);
            assert!(interface.samples_color(), "{kind:?}");
            // Colour, the two inputs and the modulation are read per tap or at the pixel.
            assert_eq!(interface.sampled_textures(), 4, "{kind:?}");
            for role in [Role::Output, Role::Flags, Role::VarianceOut] {
                let written = interface.binding(role).expect("written").resource;
                assert!(matches!(written, Resource::Storage { writable: true, .. }), "{kind:?} {role:?}");
            }
            let window = BindingInterface::of(kind, &layout, Shape::WINDOW);
            assert!(!window.samples_color() && window.sampled_textures() == 0, "{kind:?}: tiles stage buffers");
        }
        let fitness = BindingInterface::of(KernelKind::Fitness, &layout, atrous);
        assert!(matches!(fitness.binding(Role::Reference).unwrap().resource, Resource::Storage { .. }));
        // The built-in stages of filterjit's pipeline sample too; the surface spread's total stays a buffer.
        assert!(BindingInterface::prepass(None).samples_color());
        assert!(BindingInterface::planefit(None).samples_color());
        assert!(!BindingInterface::planefit_terms().samples_color());
        let surface = BindingInterface::spread_surface(None);
        assert!(surface.samples_color());
        assert!(matches!(surface.binding(Role::Total).unwrap().resource, Resource::Storage { .. }));
        let blit = BindingInterface::blit(Element::F32);
        assert_eq!(blit.binding(Role::Output).unwrap().resource, Resource::StorageTexture(TexelFormat::R32float));
    }
}
