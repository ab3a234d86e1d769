//! A scene's data on the device for one filter pipeline: its colour as the
//! pipeline's stages before the form leave it, the inputs uploaded when a
//! kernel first needs them, the frame's motion for the temporal stage, and
//! the times of the stages a frame records.

use std::collections::HashMap;

use wgpu::util::DeviceExt;

use super::prepass::{PrepassInputs, PrepassPipelines};
use super::{Gpu, GpuError, Span};
use crate::jit::{Input, Role, Shape, ValidatedKernel, TEXTURE_IN_FOURTH_CHANNELS};
use crate::lang::{Feature, ScalarVar};
use crate::pipeline::{FilterPipeline, Keep};
use crate::scene::{Missing, MissingInput, Scene};

/// A scene's data on the device, prepared for one filter pipeline: `color` is
/// what the pipeline's form filters (after its pre-pass). Inputs are uploaded
/// when a kernel first needs them.
pub struct SceneBuffers {
    pub(super) width: u32,
    pub(super) height: u32,
    pub(super) color: wgpu::Buffer,
    pub(super) inputs: HashMap<Input, wgpu::Buffer>,
    pub(super) pipeline: FilterPipeline,
    /// What remodulation multiplies by (pipelines that demodulate).
    pub(super) modulation: Option<wgpu::Buffer>,
    /// Ping-pong images and carried variances of the à-trous passes.
    pub(super) scratch: Option<Scratch>,
    /// The pre-pass's inputs, uploaded, until the pre-pass is recorded: by
    /// the first [`Gpu::filter`] of buffers made by [`SceneBuffers::for_frame`].
    pub(super) pending: Option<PrepassInputs>,
    /// Made by [`SceneBuffers::for_frame`]: the first filter also records
    /// the guide into its submission.
    pub(super) one_submission: bool,
    /// How long the pre-pass's dispatch took (pipelines with a pre-pass).
    pub(super) prepass_dispatch: Option<Span>,
    /// How long the guide's dispatch took, once a kernel that reads it has run.
    pub(super) guide_dispatch: Option<Span>,
    /// Textures of these images, for kernels that sample them.
    pub(super) sampled: super::sampled::Sampled,
    /// A temporal pipeline's frame: its motion vectors and surface, uploaded.
    pub(super) motion: Option<FrameMotion>,
    /// Whether the temporal stage is still to run: the first filter on these
    /// buffers records it (with the state it is given) into its submission.
    pub(super) temporal_pending: bool,
    /// How long the temporal stage's dispatch took, once it ran.
    pub(super) temporal_dispatch: Option<Span>,
    /// The noisy frame as it came, for `anchor`, which samples it (pipelines with the stage).
    pub(super) frame: Option<wgpu::Texture>,
}

/// Intermediate images of the à-trous passes; they never leave the device.
pub(super) struct Scratch {
    pub(super) images: [wgpu::Buffer; 2],
    pub(super) variances: [wgpu::Buffer; 2],
}

impl SceneBuffers {
    /// The buffers of pass `level`'s dispatch, by role: what it reads (the
    /// previous pass's image and variance, or the scene's for pass 0) and
    /// what it writes.
    pub(super) fn pass_resource(
        &self,
        role: Role,
        level: u32,
        carried: Option<ScalarVar>,
    ) -> Option<wgpu::BindingResource<'_>> {
        let scratch = self.scratch.as_ref();
        let (read, write) = ((level as usize + 1) % 2, level as usize % 2);
        Some(match role {
            Role::Color if level > 0 => scratch?.images[read].as_entire_binding(),
            Role::Color => self.color.as_entire_binding(),
            Role::Input(Input::Variance(v)) if level > 0 && carried == Some(v) => {
                scratch?.variances[read].as_entire_binding()
            }
            // The guide stays the frame's: from the second pass on the kernel
            // compares the pass's colour instead (`jit::lower`, `Loads::bind`).
            Role::Input(input) => self.inputs.get(&input)?.as_entire_binding(),
            Role::Modulation => self.modulation.as_ref()?.as_entire_binding(),
            Role::VarianceOut => scratch?.variances[write].as_entire_binding(),
            Role::Image => scratch?.images[write].as_entire_binding(),
            _ => return None,
        })
    }
}

impl SceneBuffers {
    /// Upload the scene's colour, for the thesis's filter (no pre-pass, one window).
    pub fn new(gpu: &Gpu, scene: &Scene) -> Self {
        Self::for_pipeline(gpu, scene, &FilterPipeline::WINDOW).expect("the window pipeline has no pre-pass to fail")
    }

    /// Upload the scene's colour and run `pipeline`'s pre-pass on the device,
    /// in a submission of its own, timed ([`SceneBuffers::prepass_time`]).
    pub fn for_pipeline(gpu: &Gpu, scene: &Scene, pipeline: &FilterPipeline) -> Result<Self, GpuError> {
        let mut buffers = Self::upload(gpu, scene, pipeline, false)?;
        if buffers.pending.is_none() {
            return Ok(buffers);
        }
        let pipelines = gpu.prepass_pipelines(pipeline, buffers.width, buffers.height)?;
        let _turn = gpu.gl_turn();
        let ((), span) =
            gpu.timed_submission("running the pre-pass", |encoder| buffers.record_prepass(gpu, encoder, pipelines))?;
        buffers.prepass_dispatch = Some(span);
        Ok(buffers)
    }

    /// Upload the scene's colour (and what `pipeline`'s pre-pass reads), and
    /// leave the pre-pass to the first [`Gpu::filter`] on these buffers: it
    /// records the pre-pass, the guide and the form in one submission,
    /// waited for once, a frame as a renderer would run it. On a hardware GPU
    /// each submit–wait round trip saved is 0.25–0.3 ms (docs/JOURNAL.md,
    /// "One submission a frame").
    pub fn for_frame(gpu: &Gpu, scene: &Scene, pipeline: &FilterPipeline) -> Result<Self, GpuError> {
        Self::upload(gpu, scene, pipeline, true)
    }

    /// The scene's colour and the pre-pass's inputs on the device, the pre-pass pending.
    fn upload(gpu: &Gpu, scene: &Scene, pipeline: &FilterPipeline, one_submission: bool) -> Result<Self, GpuError> {
        // The pre-pass, an à-trous form and `planefit` sample their images (`BindingInterface::samples_images`).
        let samples =
            pipeline.has_prepass() || pipeline.is_atrous() || pipeline.planefit.is_some() || pipeline.anchor.is_some();
        let limit = gpu.max_image_side();
        if samples && (scene.width as u64 > limit as u64 || scene.height as u64 > limit as u64) {
            return Err(GpuError::ImageTooLarge {
                scene: scene.name.clone(),
                width: scene.width as u32,
                height: scene.height as u32,
                pipeline: Box::new(*pipeline),
                limit,
                adapter: gpu.info().name.clone(),
            });
        }
        let upload = |label, c: &[[f32; 3]]| {
            let rgba: Vec<[f32; 4]> = c.iter().map(|c| [c[0], c[1], c[2], 1.0]).collect();
            gpu.device().create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: bytemuck::cast_slice(&rgba),
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            })
        };
        let color = upload("color", &scene.color);
        let (width, height) = (scene.width as u32, scene.height as u32);
        // Only `anchor` reads the frame as it came, and it samples it: a texture from the start.
        let frame = pipeline.anchor.map(|_| {
            let rgba: Vec<[f32; 4]> = scene.color.iter().map(|c| [c[0], c[1], c[2], 1.0]).collect();
            gpu.uploaded_texture(&rgba, (width, height))
        });
        let motion = match (pipeline.is_temporal(), &scene.motion) {
            (false, _) => None,
            (true, Some(motion)) => {
                // Only the temporal stage reads these, and it samples them: textures from the start.
                let vectors: Vec<[f32; 4]> = motion.vectors.iter().map(|v| [v[0], v[1], 0.0, 0.0]).collect();
                let size = (scene.width as u32, scene.height as u32);
                Some(FrameMotion {
                    vectors: gpu.uploaded_texture(&vectors, size),
                    surface: gpu.uploaded_texture(&motion.surface, size),
                    albedo: gpu.uploaded_texture(&motion.albedo, size),
                })
            }
            (true, None) => {
                let missing = MissingInput { scene: scene.name.clone(), missing: Missing::Motion };
                return Err(GpuError::MissingInput(missing));
            }
        };
        if pipeline.planefit.is_some() {
            // `planefit` reads the normals after the form: a scene without them fails here, before any work.
            scene.required_feature(Feature::Normal)?;
        }
        let (color, pending) = if pipeline.has_prepass() {
            let albedo = match (&scene.albedo, pipeline.demodulate) {
                (Some(albedo), true) => Some(upload("albedo", albedo)),
                (None, true) => {
                    let missing = MissingInput { scene: scene.name.clone(), missing: Missing::Albedo };
                    return Err(GpuError::MissingInput(missing));
                }
                (_, false) => None,
            };
            let normals = match pipeline.keep() {
                Some(Keep::Surface) => Some(upload("normals", scene.required_feature(Feature::Normal)?)),
                _ => None,
            };
            // Bound nowhere until the pre-pass replaces it with its output.
            let placeholder = gpu.device().create_buffer(&wgpu::BufferDescriptor {
                label: Some("colour before the pre-pass"),
                size: 16,
                usage: wgpu::BufferUsages::STORAGE,
                mapped_at_creation: false,
            });
            (placeholder, Some(PrepassInputs { color, albedo, normals, width, height }))
        } else {
            (color, None)
        };
        let scratch = pipeline.is_atrous().then(|| {
            let make = |label, bytes| {
                gpu.device().create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size: (width * height) as u64 * bytes,
                    usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                    mapped_at_creation: false,
                })
            };
            Scratch {
                images: [make("a-trous image", 16), make("a-trous image", 16)],
                variances: [make("a-trous variance", 4), make("a-trous variance", 4)],
            }
        });
        Ok(SceneBuffers {
            width,
            height,
            color,
            inputs: HashMap::new(),
            pipeline: *pipeline,
            modulation: None,
            scratch,
            pending,
            one_submission,
            prepass_dispatch: None,
            guide_dispatch: None,
            sampled: Default::default(),
            temporal_pending: motion.is_some(),
            motion,
            temporal_dispatch: None,
            frame,
        })
    }

    /// Make `color` the colour the form filters (the pre-pass's or the
    /// temporal stage's output), forgetting any texture of the one before.
    /// Views of the textures pass `level` of a sampling kernel reads for
    /// `roles` ([`super::sampled::Sampled::views`]), made from these buffers.
    pub(super) fn sampled_views(
        &mut self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        roles: &[Role],
        level: u32,
        carried: Option<ScalarVar>,
    ) -> Result<HashMap<Role, wgpu::TextureView>, GpuError> {
        let sources = super::sampled::Sources {
            size: (self.width, self.height),
            color: &self.color,
            modulation: self.modulation.as_ref(),
            inputs: &self.inputs,
            passes: self.scratch.as_ref().map(|s| (&s.images, &s.variances)),
        };
        self.sampled.views(gpu, encoder, sources, roles, level, carried)
    }

    pub(super) fn replace_color(&mut self, color: wgpu::Buffer) {
        self.color = color;
        self.sampled.forget(Role::Color);
    }

    /// Make `modulation` what the result is multiplied back by (the
    /// temporal stage's blend of it), forgetting any texture of the one before.
    pub(super) fn replace_modulation(&mut self, modulation: wgpu::Buffer) {
        self.modulation = Some(modulation);
        self.sampled.forget(Role::Modulation);
    }

    /// Record the pending pre-pass into `encoder`; its outputs become these
    /// buffers' colour, modulation and pre-pass measures. Callers hold the GL turn.
    pub(super) fn record_prepass(
        &mut self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        pipelines: PrepassPipelines,
    ) -> Result<(), GpuError> {
        let inputs = self.pending.take().expect("a pre-pass is pending");
        let prepared = gpu.record_prepass(encoder, pipelines, &self.pipeline, &inputs)?;
        if self.pipeline.outliers.is_some() {
            // What the outlier rule measured is an input like any other, already on the device.
            for (v, buffer) in ScalarVar::FROM_PREPASS.into_iter().zip(prepared.local) {
                self.inputs.insert(Input::Variance(v), buffer);
            }
        }
        self.replace_color(prepared.color);
        self.modulation = self.pipeline.demodulate.then_some(prepared.modulation);
        Ok(())
    }

    /// The pipeline these buffers were prepared for.
    pub fn pipeline(&self) -> &FilterPipeline {
        &self.pipeline
    }

    /// Time of the pre-pass's dispatch when these buffers were prepared
    /// (recording to completion; uploads excluded), or `None` without a
    /// pre-pass: with [`Filtered::time`], a frame's time. Buffers made by
    /// [`SceneBuffers::for_frame`] run it in their first filter's
    /// submission: there its wall time is the recording's alone, and the
    /// filter's time holds the rest.
    pub fn prepass_time(&self) -> Option<Span> {
        self.prepass_dispatch
    }

    /// Time of the guide's dispatch (docs/SEMANTICS.md, "The guide"),
    /// made when a kernel that reads `guide` first ran on these buffers, or
    /// `None` before: a frame of such a kernel also costs this. As for
    /// [`SceneBuffers::prepass_time`], buffers made by
    /// [`SceneBuffers::for_frame`] record it into that filter's submission.
    pub fn guide_time(&self) -> Option<Span> {
        self.guide_dispatch
    }

    /// Time of the temporal stage's dispatch, once the first filter on these
    /// buffers ran it (in that filter's submission), or `None` without one.
    pub fn temporal_time(&self) -> Option<Span> {
        self.temporal_dispatch
    }

    /// Every input of `kernel` that `scene` lacks, checked before any is bound
    /// (`scene::Needs`, the one rule): a data error naming scene and input.
    pub(super) fn check_inputs(&self, kernel: &ValidatedKernel, scene: &Scene) -> Result<(), GpuError> {
        for expr in &kernel.source().exprs {
            crate::scene::Needs::of(expr, false).check(scene, &self.pipeline)?;
        }
        Ok(())
    }

    /// A kernel runs on buffers prepared for a pipeline of its shape.
    pub(super) fn check_shape(&self, kernel: &ValidatedKernel) -> Result<(), GpuError> {
        let (wanted, got) = (Shape::of(&self.pipeline), kernel.source().shape);
        if kernel.source().kind == crate::jit::KernelKind::Probe || wanted == got {
            return Ok(());
        }
        Err(GpuError::Shape { expression: kernel.source().canonical.clone(), shape: got, pipeline: self.pipeline })
    }

    /// Upload `input` of `scene` unless it is on the device already. Callers
    /// run [`SceneBuffers::check_inputs`] first: an absent input is a data
    /// error there, never here.
    pub(super) fn ensure(&mut self, gpu: &Gpu, scene: &Scene, input: Input) -> Result<(), GpuError> {
        if self.inputs.contains_key(&input) {
            return Ok(());
        }
        if input == Input::Feature(Feature::Guide) {
            // Made from the colour on the device, once, in a submission of its own.
            let ((), span) = gpu.timed_submission("blurring the guide", |encoder| self.record_guide(gpu, encoder))?;
            self.guide_dispatch = Some(span);
            return Ok(());
        }
        const CHECKED: &str = "check_inputs found every input the kernel binds";
        let data: Vec<f32> = match input {
            Input::Feature(f) => {
                let values = scene.feature(f).expect(CHECKED);
                // A carrier's fourth channel holds a component of the texture
                // (for filter kernels that read it from there after their first pass).
                let component = TEXTURE_IN_FOURTH_CHANNELS.iter().find(|(carrier, _)| *carrier == f);
                let texture = component.and_then(|(_, k)| Some((scene.feature(Feature::Texture)?, *k)));
                if input.components() == 1 {
                    values.iter().map(|v| v[0]).collect()
                } else {
                    let fourth = |p: usize| texture.map_or(0.0, |(t, k)| t[p][k]);
                    values.iter().enumerate().flat_map(|(p, v)| [v[0], v[1], v[2], fourth(p)]).collect()
                }
            }
            Input::Variance(v) => scene.variance(v).expect(CHECKED).to_vec(),
        };
        let buffer = gpu.device().create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("input"),
            contents: bytemuck::cast_slice(&data),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        });
        self.inputs.insert(input, buffer);
        Ok(())
    }
}

/// The frame's own inputs to the stage, uploaded with its colour.
pub(super) struct FrameMotion {
    /// (dx, dy, 0, 0) per pixel.
    pub(super) vectors: wgpu::Texture,
    /// The normal's direction and the depth per pixel.
    pub(super) surface: wgpu::Texture,
    /// The albedo clipped to [0, 1] per pixel.
    pub(super) albedo: wgpu::Texture,
}
