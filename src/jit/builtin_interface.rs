//! The binding interfaces of the built-in kernels (the blit, the pre-pass,
//! `keep`'s spreads, planefit, the temporal stage, the fitness reduction):
//! [`BindingInterface`] constructors beside [`BindingInterface::of`], which
//! builds an expression kernel's, with the same helpers, so that slots,
//! resources and uniforms are still assigned in one module's terms.

use super::interface::{
    dense, field, image_uniform, own_params, typed_image_uniform, BindingInterface, Element, Resource, Role,
    TexelFormat,
};
use super::kernel::{Input, KernelKind, OutputFormat};
use crate::lang::{Feature, ScalarVar};

impl BindingInterface {
    /// The interface of the blit that copies an image of `element`s (`Vec4F32`
    /// or `F32`) from a storage buffer into a texture of the same values
    /// (`templates/blit.wgsl.tera`), for kernels that sample their images.
    pub fn blit(element: Element) -> BindingInterface {
        let format = match element {
            Element::F32 => TexelFormat::R32float,
            _ => TexelFormat::Color(OutputFormat::Rgba32float),
        };
        let bindings = dense([
            (Role::Params, own_params(), "params".to_string()),
            (Role::Color, Resource::Storage { element, writable: false }, "buf_source".to_string()),
            (Role::Output, Resource::StorageTexture(format), "tex_out".to_string()),
        ]);
        let uniform = image_uniform([("_pad0", "unused"), ("_pad1", "unused")]);
        BindingInterface { kind: KernelKind::Filter, bindings, uniform, uniform_bytes: 16 }
    }

    /// The interface of the pipeline's pre-pass (`jit::prepass`): the uniform
    /// `PrepassParams`, the colour, the raw albedo, the prepared colour and
    /// the modulation it writes. Sampled textures in, and storage buffers out
    /// for filterjit (`None`) or storage textures of `format` out for an
    /// exported pre-pass.
    pub fn prepass(textures: Option<OutputFormat>) -> BindingInterface {
        let (kind, roles) = match textures {
            None => {
                // Sampled, as every image stage of filterjit's filter ([`Self::samples_images`]).
                let read = Resource::SampledTexture;
                let written = Resource::Storage { element: Element::Vec4F32, writable: true };
                (
                    KernelKind::Filter,
                    vec![
                        (Role::Color, read, "tex_color".to_string()),
                        (Role::Albedo, read, "tex_albedo".into()),
                        (Role::Output, written, "buf_prepared".into()),
                        (Role::Modulation, written, "buf_modulation".into()),
                    ]
                    .into_iter()
                    .chain(ScalarVar::FROM_PREPASS.map(|v| {
                        let scalar = Resource::Storage { element: Element::F32, writable: true };
                        (Role::Input(Input::Variance(v)), scalar, format!("buf_{}", v.name().to_ascii_lowercase()))
                    }))
                    .collect::<Vec<_>>(),
                )
            }
            Some(format) => {
                let written = Resource::StorageTexture(TexelFormat::Color(format));
                (
                    KernelKind::Export(format),
                    vec![
                        (Role::Color, Resource::SampledTexture, "tex_color".to_string()),
                        (Role::Albedo, Resource::SampledTexture, "tex_albedo".into()),
                        (Role::Output, written, "tex_prepared".into()),
                        (Role::Modulation, written, "tex_modulation".into()),
                    ]
                    .into_iter()
                    .chain([(
                        Role::Local,
                        Resource::StorageTexture(TexelFormat::Color(OutputFormat::Rgba32float)),
                        "tex_local".to_string(),
                    )])
                    .collect::<Vec<_>>(),
                )
            }
        };
        let params = if textures.is_some() { Resource::Uniform } else { own_params() };
        let bindings = dense(std::iter::once((Role::Params, params, "params".to_string())).chain(roles));
        let uniform = vec![
            field("width", "u32", 0, "image width in pixels"),
            field("height", "u32", 4, "image height in pixels"),
            field("k", "f32", 8, "the outlier rule's k: luminance above mean + k * std is clamped"),
            field("stages", "u32", 12, "bit 0: clamp outliers; bit 1: demodulate by the albedo; bit 2: keep (the colour is left undivided for the spread)"),
        ];
        BindingInterface { kind, bindings, uniform, uniform_bytes: 16 }
    }

    /// The interface of `keep`'s spread kernel (`jit::spread`): the uniform
    /// `SpreadParams`, the image it spreads (`Color`), the clamped colour
    /// (`Image`), the modulation, and its output. Sampled textures in, and a
    /// storage buffer out for filterjit (`None`) or, exported, an
    /// `rgba32float` storage texture (the one-texel `Total` of the surface
    /// spread stays a buffer in filterjit's).
    pub fn spread(textures: Option<OutputFormat>) -> BindingInterface {
        let stage = "0: spread colour - image; 1: spread colour; 2: (colour + image) / modulation";
        Self::spread_with(textures, &[], "pixel step between taps: 2^pass", stage)
    }

    /// The interface of `keep=surface`'s spread kernel
    /// (`jit::spread_surface_wgsl`): [`BindingInterface::spread`]'s, with
    /// the surface normal (`Input::Feature(Normal)`, of which only the
    /// direction counts), `Surface`, each pixel's direction and clamped
    /// luminance, which its first dispatch writes, and `Total`, their sum,
    /// which its second writes; later ones read both.
    pub fn spread_surface(textures: Option<OutputFormat>) -> BindingInterface {
        let extra = [
            (Role::Input(Input::Feature(Feature::Normal)), "normal"),
            (Role::Surface, "surface"),
            (Role::Total, "total"),
        ];
        let stage = "bit 0: sum the clamped luminance into total; bit 1: spread colour - image; bit 2: gather the \
                     previous level from colour at step / 2; bit 3: write (value + image) / modulation; bit 4: write \
                     the normal's direction and the clamped luminance into surface";
        let step = "pixel step of the level whose shares this dispatch normalises: 2^level";
        Self::spread_with(textures, &extra, step, stage)
    }

    /// A spread's interface: colour, image and modulation read, then `extra`
    /// read (named `buf_NAME` or `tex_NAME`), then the output written.
    fn spread_with(
        textures: Option<OutputFormat>,
        extra: &[(Role, &str)],
        step: &str,
        stage: &str,
    ) -> BindingInterface {
        let reads: Vec<(Role, &str)> =
            [(Role::Color, "color"), (Role::Image, "image"), (Role::Modulation, "modulation")]
                .into_iter()
                .chain(extra.iter().copied())
                .collect();
        // Exported, every image it writes is rgba32float: the total it keeps is not rounded between passes.
        let written = Self::full_precision_written(textures);
        Self::image_stage(textures, true, &reads, written, [("step", step), ("stage", stage)])
    }

    /// The interface of `planefit`'s kernel (`jit::planefit`): the uniform
    /// `PlaneFitParams`, the form's output (`Color`), the surface normal, the
    /// modulation it divides by and multiplies back, and its output. Sampled
    /// textures in, and a storage buffer out for filterjit (`None`) or,
    /// exported, a storage texture of the output format.
    pub fn planefit(textures: Option<OutputFormat>) -> BindingInterface {
        let written = Self::frame_written(textures);
        Self::image_stage(textures, true, &Self::PLANEFIT_READS, written, Self::PLANEFIT_UNIFORM)
    }

    /// The interface of `pixelfilter`'s kernel (`jit::pixel_filter`): the
    /// uniform `PixelFilterParams` (the two 1-D weights as f32), the
    /// filtered image (`Color`, sampled) and its output: a storage buffer for
    /// filterjit (`None`) or, exported, a storage texture of the output format.
    pub fn pixel_filter(textures: Option<OutputFormat>) -> BindingInterface {
        let uniform = typed_image_uniform([
            ("centre", "f32", "the 1-D weight of the centre tap; tap (dx, dy) weighs w(dx) w(dy)"),
            ("side", "f32", "the 1-D weight of a tap one pixel off the centre"),
        ]);
        let written = Self::frame_written(textures);
        Self::image_stage_with(textures, true, &[(Role::Color, "color")], written, uniform)
    }

    /// The interface of `anchor`'s kernel (`jit::anchor`): the uniform
    /// `AnchorParams` (its `gate` an f32), the noisy frame (`Color`), the
    /// filtered image (`Image`) and the blurred sums (`Sums`), sampled, and
    /// its output: a storage buffer for filterjit (`None`) or, exported, a
    /// storage texture of `rgba32float` whatever the output format (the sums
    /// hold squared luminances; the scaled image shares the binding).
    pub fn anchor(textures: Option<OutputFormat>) -> BindingInterface {
        let uniform = typed_image_uniform([
            (
                "level",
                "u32",
                "0: average 2x2 blocks into the half-resolution grid; 1 .. levels: blur there at step \
                 2^(level - 1); levels + 1: scale the image",
            ),
            ("gate", "f32", "K of anchor=K: the standard errors the blurred lights may differ by"),
        ]);
        let reads = [(Role::Color, "color"), (Role::Image, "image"), (Role::Sums, "sums")];
        Self::image_stage_with(textures, true, &reads, Self::full_precision_written(textures), uniform)
    }

    /// What a stage whose images another dispatch reads again writes: a
    /// storage buffer for filterjit (`None`), or exported, a storage texture
    /// of `rgba32float` whatever the output format, so that nothing it keeps
    /// between dispatches is rounded to half precision.
    fn full_precision_written(textures: Option<OutputFormat>) -> Resource {
        match textures {
            None => Resource::Storage { element: Element::Vec4F32, writable: true },
            Some(_) => Resource::StorageTexture(TexelFormat::Color(OutputFormat::Rgba32float)),
        }
    }

    /// What a stage that writes the filtered frame writes: a storage buffer
    /// for filterjit (`None`), or exported, a storage texture of the output format.
    fn frame_written(textures: Option<OutputFormat>) -> Resource {
        match textures {
            None => Resource::Storage { element: Element::Vec4F32, writable: true },
            Some(format) => Resource::StorageTexture(TexelFormat::Color(format)),
        }
    }

    /// The interface of `planefit`'s fitness kernel: [`BindingInterface::planefit`]'s
    /// on storage buffers, with the reference read and the relMSE terms and
    /// luminance (`Vec2F32`, as a fitness kernel's) written.
    pub fn planefit_terms() -> BindingInterface {
        let reads: Vec<(Role, &str)> =
            Self::PLANEFIT_READS.into_iter().chain([(Role::Reference, "reference")]).collect();
        let written = Resource::Storage { element: Element::Vec2F32, writable: true };
        Self::image_stage(None, false, &reads, written, Self::PLANEFIT_UNIFORM)
    }

    const PLANEFIT_READS: [(Role, &'static str); 3] = [
        (Role::Color, "color"),
        (Role::Input(Input::Feature(Feature::Normal)), "normal"),
        (Role::Modulation, "modulation"),
    ];

    const PLANEFIT_UNIFORM: [(&'static str, &'static str); 2] = [
        ("radius", "R of planefit=R: the fit's (2R+1)^2 neighbourhood"),
        ("demodulate", "1: divide by modulation before the fit and multiply after; 0: modulation is not read"),
    ];

    /// A built-in image stage's interface (the spreads, `planefit`, `pixelfilter`): the
    /// uniform (width, height, then two u32 `fields`), `reads` (sampled
    /// textures `tex_NAME` where `sampled` or exported, as
    /// [`Self::samples_images`] says why; else storage buffers `buf_NAME`),
    /// then the output `written` (`buf_out`, or exported `tex_out`).
    fn image_stage(
        textures: Option<OutputFormat>,
        sampled: bool,
        reads: &[(Role, &str)],
        written: Resource,
        fields: [(&str, &str); 2],
    ) -> BindingInterface {
        Self::image_stage_with(textures, sampled, reads, written, image_uniform(fields))
    }

    /// [`Self::image_stage`] with its 16-byte uniform given whole (fields of other types than u32).
    fn image_stage_with(
        textures: Option<OutputFormat>,
        sampled: bool,
        reads: &[(Role, &str)],
        written: Resource,
        uniform: Vec<super::interface::UniformField>,
    ) -> BindingInterface {
        let (kind, params, out) = match textures {
            None => (KernelKind::Filter, own_params(), "buf_out"),
            Some(format) => (KernelKind::Export(format), Resource::Uniform, "tex_out"),
        };
        // The one-texel total stays a buffer in filterjit's own kernels: every invocation reads the same texel.
        let reads = reads.iter().map(|&(role, name)| {
            if textures.is_some() || (sampled && role != Role::Total) {
                (role, Resource::SampledTexture, format!("tex_{name}"))
            } else {
                (role, Resource::Storage { element: Element::Vec4F32, writable: false }, format!("buf_{name}"))
            }
        });
        let bindings = dense(std::iter::once((Role::Params, params, "params".to_string())).chain(reads).chain([(
            Role::Output,
            written,
            out.to_string(),
        )]));
        BindingInterface { kind, bindings, uniform, uniform_bytes: 16 }
    }

    /// The interface of the temporal stage (`jit::temporal`): the uniform
    /// `TemporalParams`; the frame's colour (as the pre-pass left it), its
    /// surface, albedo and motion vectors, the history's colour and moments
    /// and the frame before's surface and albedo, all sampled; then what it writes: the blend
    /// the form filters, the moments kept for the next frame, and
    /// `historyLength` and `temporalVariance` (filterjit's storage buffers,
    /// `None`), or exported (`Some`), storage textures: the blend and the
    /// moments `rgba32float` whatever the output format (the history is
    /// blended again every frame: half floats would round it away), and the
    /// two measures packed into one (`Accumulated`).
    pub fn temporal(textures: Option<OutputFormat>) -> BindingInterface {
        let read = [
            (Role::Color, "color"),
            (Role::Geometry, "geometry"),
            (Role::Albedo, "albedo"),
            (Role::Motion, "motion"),
            (Role::History, "history"),
            (Role::Moments, "moments"),
            (Role::PreviousGeometry, "previous_geometry"),
            (Role::PreviousAlbedo, "previous_albedo"),
            (Role::PastModulation, "past_modulation"),
        ]
        .map(|(role, name)| (role, Resource::SampledTexture, format!("tex_{name}")));
        let (kind, params, written): (_, _, Vec<(Role, Resource, String)>) = match textures {
            None => {
                let buffer = |element| Resource::Storage { element, writable: true };
                let length = Role::Input(Input::Variance(ScalarVar::HistoryLength));
                let images = [
                    (Role::Output, buffer(Element::Vec4F32), "buf_out".to_string()),
                    (Role::MomentsOut, buffer(Element::Vec4F32), "buf_moments_out".to_string()),
                    (Role::ModulationOut, buffer(Element::Vec4F32), "buf_modulation_out".to_string()),
                    (length, buffer(Element::F32), "buf_historylength".to_string()),
                    (Role::SampleVariance, buffer(Element::F32), "buf_sample_variance".to_string()),
                ];
                (KernelKind::Filter, own_params(), images.into_iter().collect())
            }
            Some(format) => {
                let texture = Resource::StorageTexture(TexelFormat::Color(OutputFormat::Rgba32float));
                let images = [
                    (Role::Output, texture, "tex_out".to_string()),
                    (Role::MomentsOut, texture, "tex_moments_out".to_string()),
                    (Role::ModulationOut, texture, "tex_modulation_out".to_string()),
                    (Role::Accumulated, texture, "tex_accumulated".to_string()),
                ];
                (KernelKind::Export(format), Resource::Uniform, images.into_iter().collect())
            }
        };
        let bindings = dense(std::iter::once((Role::Params, params, "params".to_string())).chain(read).chain(written));
        let uniform = vec![
            field("width", "u32", 0, "image width in pixels"),
            field("height", "u32", 4, "image height in pixels"),
            field("alpha", "f32", 8, "alpha_min: a frame's share of the blend is max(alpha_min, 1/n)"),
            field("gamma", "f32", 12, "the history's clamp: within the frame's 3x3 mean +- gamma std; 0: no clamp"),
            field("history", "u32", 16, "1 where the history textures hold the frame before's; 0 for a first frame"),
            field(
                "antilag",
                "f32",
                20,
                "kappa of the history's test: cut to one frame where its luminance is off; 0: none",
            ),
            field("_pad0", "u32", 24, "unused"),
            field("_pad1", "u32", 28, "unused"),
        ];
        BindingInterface { kind, bindings, uniform, uniform_bytes: 32 }
    }

    /// The interface of the temporal stage's variance kernel
    /// (`jit::temporal_variance`): the uniform (width, height), the sample
    /// variance the stage wrote and its moments (for r), sampled; the
    /// `temporalVariance` it writes: a storage buffer (filterjit's, `None`)
    /// or, exported, an `r32float` storage texture.
    pub fn temporal_variance(textures: Option<OutputFormat>) -> BindingInterface {
        let written = match textures {
            None => Resource::Storage { element: Element::F32, writable: true },
            Some(_) => Resource::StorageTexture(TexelFormat::R32float),
        };
        let reads = [(Role::SampleVariance, "sample_variance"), (Role::Moments, "moments")];
        let mut interface =
            Self::image_stage(textures, true, &reads, written, [("_pad0", "unused"), ("_pad1", "unused")]);
        let out = interface.bindings.last_mut().expect("the output is bound last");
        out.role = Role::Input(Input::Variance(ScalarVar::TemporalVariance));
        out.ident = if textures.is_some() { "tex_temporal_variance" } else { "buf_temporalvariance" }.to_string();
        interface
    }

    /// The interface of the fitness reduction (`jit::reduce`): the uniform
    /// `ReduceParams`, a member's per-pixel terms and flags, and the
    /// per-workgroup partial sums and flags it writes (`Output`, `Flags`).
    pub fn reduce() -> BindingInterface {
        let read = |element| Resource::Storage { element, writable: false };
        let written = |element| Resource::Storage { element, writable: true };
        let bindings = dense(
            [
                (Role::Params, own_params(), "params"),
                (Role::Terms, read(Element::Vec2F32), "buf_terms"),
                (Role::PixelFlags, read(Element::U32), "buf_pixel_flags"),
                (Role::Output, written(Element::Vec2F32), "buf_partials"),
                (Role::Flags, written(Element::U32), "buf_partial_flags"),
            ]
            .map(|(role, resource, ident)| (role, resource, ident.to_string())),
        );
        let uniform =
            image_uniform([("member", "which member's terms: from member * width * height"), ("_pad", "unused")]);
        BindingInterface { kind: KernelKind::Fitness, bindings, uniform, uniform_bytes: 16 }
    }
}
