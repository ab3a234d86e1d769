//! Scene buffers on the device and the filter dispatch.

use std::collections::HashMap;
use std::time::{Duration, Instant};

use wgpu::util::DeviceExt;

use super::prepass::{PrepassInputs, PrepassPipelines};
use super::temporal::{FrameMotion, TemporalState};
use super::{Gpu, GpuError, PipelineTiming, Span};
use crate::jit::interface::Element;
use crate::jit::{AtrousParams, Input, Params, PassRole, Role, Shape, ValidatedKernel, WORKGROUP};
use crate::lang::{Feature, ScalarVar};
use crate::pipeline::{FilterPipeline, Keep};
use crate::scene::{Missing, MissingInput, Scene};

/// Upper bound on weight evaluations in one dispatch. Large images and radii
/// are split into bands of rows so that no single dispatch runs long enough to
/// trip a GPU watchdog (Windows resets a GPU after about 2 s).
pub const MAX_WEIGHTS_PER_DISPATCH: u64 = 1 << 22;

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

/// Result of a filter dispatch.
#[derive(Clone, Debug)]
pub struct Filtered {
    /// Filtered colour, RGBA (alpha copied from the input, 1).
    pub color: Vec<[f32; 4]>,
    /// Domain-error bits per pixel.
    pub flags: Vec<u32>,
    pub pipeline: PipelineTiming,
    /// From recording the first pass until the results were on the device,
    /// all bands and passes: by wall time, and on the device's own clock
    /// where it has one (`Gpu::has_device_clock`).
    pub time: Span,
    /// Number of dispatches the image was split into.
    pub dispatches: usize,
}

impl Filtered {
    pub fn rgb(&self) -> Vec<[f32; 3]> {
        self.color.iter().map(|c| [c[0], c[1], c[2]]).collect()
    }

    /// What the kernel's work took: on the device's clock where it has one,
    /// else by wall time.
    pub fn kernel_time(&self) -> Duration {
        self.time.device.unwrap_or(self.time.wall)
    }

    /// Number of pixels with at least one domain error.
    pub fn flagged_pixels(&self) -> usize {
        self.flags.iter().filter(|f| **f != 0).count()
    }

    /// Union of all domain-error bits.
    pub fn all_flags(&self) -> u32 {
        self.flags.iter().fold(0, |a, f| a | f)
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
    /// each submit–wait round trip saved is 0.25–0.3 ms (docs/BENCHMARKS.md,
    /// "One submission a frame").
    pub fn for_frame(gpu: &Gpu, scene: &Scene, pipeline: &FilterPipeline) -> Result<Self, GpuError> {
        Self::upload(gpu, scene, pipeline, true)
    }

    /// The scene's colour and the pre-pass's inputs on the device, the pre-pass pending.
    fn upload(gpu: &Gpu, scene: &Scene, pipeline: &FilterPipeline, one_submission: bool) -> Result<Self, GpuError> {
        // The pre-pass, an à-trous form and `planefit` sample their images (`BindingInterface::samples_images`).
        let samples = pipeline.has_prepass() || pipeline.is_atrous() || pipeline.planefit.is_some();
        let limit = gpu.max_image_side();
        if samples && (scene.width as u64 > limit as u64 || scene.height as u64 > limit as u64) {
            return Err(GpuError::ImageTooLarge {
                scene: scene.name.clone(),
                width: scene.width as u32,
                height: scene.height as u32,
                pipeline: *pipeline,
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
        let motion = match (pipeline.is_temporal(), &scene.motion) {
            (false, _) => None,
            (true, Some(motion)) => {
                let vectors: Vec<[f32; 4]> = motion.vectors.iter().map(|v| [v[0], v[1], 0.0, 0.0]).collect();
                let buffer = |label, data: &[[f32; 4]]| {
                    gpu.device().create_buffer_init(&wgpu::util::BufferInitDescriptor {
                        label: Some(label),
                        contents: bytemuck::cast_slice(data),
                        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                    })
                };
                Some(FrameMotion {
                    vectors: buffer("motion", &vectors),
                    surface: buffer("surface", &motion.surface),
                    albedo: buffer("albedo of the surface", &motion.albedo),
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
        })
    }

    /// Make `color` the colour the form filters (the pre-pass's or the
    /// temporal stage's output), forgetting any texture of the one before.
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
    fn record_prepass(
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
                if input.components() == 1 {
                    values.iter().map(|v| v[0]).collect()
                } else {
                    values.iter().flat_map(|v| [v[0], v[1], v[2], 0.0]).collect()
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

/// A stage a frame's first filter records before the form ([`SceneBuffers::for_frame`]).
enum Part {
    Prepass,
    Temporal,
    Guide,
}

/// The uniform of pass `level` of `passes`; `remodulates` whether the last
/// pass multiplies the modulation back (not where `planefit` follows: the
/// fit reads the demodulated image and multiplies it back itself).
pub(super) fn uniform_bytes(atrous: bool, base: Params, level: u32, passes: u32, remodulates: bool) -> Vec<u8> {
    if atrous {
        let p = AtrousParams {
            base,
            step: FilterPipeline::step(level),
            level,
            last: u32::from(remodulates && level + 1 == passes),
            _pad: 0,
        };
        bytemuck::bytes_of(&p).to_vec()
    } else {
        bytemuck::bytes_of(&base).to_vec()
    }
}

/// Rows per dispatch for an image `width` wide filtered with `radius`: a
/// multiple of the workgroup height, at least one workgroup.
pub fn rows_per_dispatch(width: u32, radius: u32) -> u32 {
    let window = (2 * radius as u64 + 1).pow(2);
    let rows = MAX_WEIGHTS_PER_DISPATCH / (width as u64 * window).max(1);
    let rows = (rows / WORKGROUP[1] as u64) * WORKGROUP[1] as u64;
    rows.clamp(WORKGROUP[1] as u64, u32::MAX as u64) as u32
}

impl Gpu {
    /// Filter a scene with a compiled kernel and read the result back.
    pub fn filter(
        &self,
        kernel: &ValidatedKernel,
        buffers: &mut SceneBuffers,
        scene: &Scene,
        radius: u32,
    ) -> Result<Filtered, GpuError> {
        self.filter_frame(kernel, buffers, scene, radius, &mut TemporalState::new())
    }

    /// [`Gpu::filter`] on a frame of a sequence: a temporal pipeline's first
    /// filter on `buffers` blends the frame into `state`'s history and, once
    /// the frame is done, leaves in `state` what the next frame blends into
    /// (a fresh state: the frame starts the sequence). Later filters on the
    /// same buffers filter the same blend and leave `state` alone.
    pub fn filter_frame(
        &self,
        kernel: &ValidatedKernel,
        buffers: &mut SceneBuffers,
        scene: &Scene,
        radius: u32,
        state: &mut TemporalState,
    ) -> Result<Filtered, GpuError> {
        super::check_radius(kernel, radius)?;
        buffers.check_shape(kernel)?;
        buffers.check_inputs(kernel, scene)?;
        let (first, mut timing) = self.pipeline_for(kernel, PassRole::First)?;
        let atrous = kernel.source().shape.atrous;
        let passes = if atrous { buffers.pipeline.passes() } else { 1 };
        let carried = kernel.source().interface.carried_variance();
        // Made before the clock starts, like the first pass's (and outside the GL turn, which creation takes).
        let later = if passes > 1 {
            let (later, made) = self.pipeline_for(kernel, PassRole::Later)?;
            timing =
                PipelineTiming { create: timing.create + made.create, cache_hit: timing.cache_hit && made.cache_hit };
            Some(later)
        } else {
            None
        };
        self.prepare_guide_for(kernel)?;
        let prepass = match buffers.pending {
            Some(_) => Some(self.prepass_pipelines(&buffers.pipeline, buffers.width, buffers.height)?),
            None => None,
        };
        let temporal = buffers.pipeline.temporal.filter(|_| buffers.temporal_pending);
        if temporal.is_some() {
            self.built_in(crate::jit::BuiltIn::Temporal, 0)?;
            self.built_in(crate::jit::BuiltIn::TemporalVariance, 0)?;
            self.blit_pipeline(Element::Vec4F32)?;
            self.blit_pipeline(Element::F32)?;
        }
        let guide = Input::Feature(Feature::Guide);
        // Made in this submission: a frame's first filter on buffers from
        // `for_frame`, or after the temporal stage, whose blend it blurs.
        let records_guide = (buffers.one_submission || temporal.is_some())
            && kernel.source().layout.reads_guide()
            && !buffers.inputs.contains_key(&guide);
        let planefit = buffers.pipeline.planefit;
        if planefit.is_some() {
            self.planefit_pipeline(!buffers.pipeline.is_atrous())?;
        }
        let sampled = super::sampled::sampled_roles(kernel);
        if !sampled.is_empty() || planefit.is_some() {
            self.blit_pipeline(Element::Vec4F32)?;
            self.blit_pipeline(Element::F32)?;
        }
        let _turn = self.gl_turn();
        for (_, input) in kernel.source().interface.inputs() {
            // Uploads stay outside the frame's time; what the pre-pass and the guide make is recorded below.
            let made_here = (matches!(input, Input::Variance(v) if v.from_prepass()) && prepass.is_some())
                || (matches!(input, Input::Variance(v) if v.from_temporal()) && temporal.is_some())
                || (records_guide && input == guide);
            if !made_here {
                buffers.ensure(self, scene, input)?;
            }
        }
        if planefit.is_some() {
            buffers.ensure(self, scene, Input::Feature(Feature::Normal))?;
        }
        let device = self.device();
        let pixels = (buffers.width * buffers.height) as u64;
        let out = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("filtered"),
            size: pixels * 16,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let flags = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("flags"),
            size: pixels * 4,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let staging = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: pixels * 20,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });

        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let band = rows_per_dispatch(buffers.width, buffers.pipeline.pass_radius(radius));
        let stopwatch = self.stopwatch();
        let start = Instant::now();
        let mut dispatches = 0;
        // The whole frame is one submission, waited for once: on a hardware
        // GPU each submit–wait round trip costs 0.25–0.3 ms, several times a
        // 256² pass's own work (docs/BENCHMARKS.md, "On a GPU"). Bands keep
        // each dispatch short for watchdogs; they need no wait between them.
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        stopwatch.start(&mut encoder);
        // A frame's pre-pass, temporal stage and guide, each timed on the device's clock where it has one.
        let mut parts = Vec::new();
        if let Some(pipelines) = prepass {
            let (part, recording) = (self.stopwatch(), Instant::now());
            part.start(&mut encoder);
            buffers.record_prepass(self, &mut encoder, pipelines)?;
            part.stop(&mut encoder);
            parts.push((Part::Prepass, recording.elapsed(), part));
        }
        let mut recorded = match temporal {
            Some(stage) => {
                let (part, recording) = (self.stopwatch(), Instant::now());
                part.start(&mut encoder);
                let recorded = self.record_temporal(&mut encoder, buffers, state, stage)?;
                part.stop(&mut encoder);
                parts.push((Part::Temporal, recording.elapsed(), part));
                Some(recorded)
            }
            None => None,
        };
        if records_guide {
            let (part, recording) = (self.stopwatch(), Instant::now());
            part.start(&mut encoder);
            buffers.record_guide(self, &mut encoder)?;
            part.stop(&mut encoder);
            parts.push((Part::Guide, recording.elapsed(), part));
        }
        for level in 0..passes {
            let pipeline = if level == 0 { &first } else { later.as_ref().expect("made for every later pass") };
            // The textures this pass samples, copied first where they are new.
            let views = if sampled.is_empty() {
                HashMap::new()
            } else {
                buffers.sampled_views(self, &mut encoder, &sampled, level, carried)?
            };
            let mut row = 0;
            while row < buffers.height {
                let rows = band.min(buffers.height - row);
                let params = uniform_bytes(
                    atrous,
                    Params { width: buffers.width, height: buffers.height, radius, row_offset: row },
                    level,
                    passes,
                    planefit.is_none(),
                );
                let params = self.params_buffer(kernel.source().interface.params(), "params", &params);
                let buffers = &*buffers;
                let bind_group = self.bind_group(pipeline, &kernel.source().interface, |role| match role {
                    Role::Params => params.as_entire_binding(),
                    // The filtered image: the last pass's goes to `out`, the others to the ping-pong images.
                    Role::Output if atrous && level + 1 < passes => {
                        buffers.pass_resource(Role::Image, level, carried).expect("à-trous buffers")
                    }
                    Role::Output => out.as_entire_binding(),
                    Role::Flags => flags.as_entire_binding(),
                    Role::Reference | Role::Image => unreachable!("filter kernels bind no {role:?}"),
                    role if views.contains_key(&role) => wgpu::BindingResource::TextureView(&views[&role]),
                    role => buffers.pass_resource(role, level, carried).expect("inputs are uploaded before binding"),
                });
                {
                    let mut pass = encoder
                        .begin_compute_pass(&wgpu::ComputePassDescriptor { label: None, timestamp_writes: None });
                    pass.set_pipeline(&pipeline.pipeline);
                    pass.set_bind_group(0, &bind_group, &[]);
                    pass.dispatch_workgroups(buffers.width.div_ceil(WORKGROUP[0]), rows.div_ceil(WORKGROUP[1]), 1);
                }
                dispatches += 1;
                row += rows;
            }
            // The pass the temporal stage feeds back: its image is the next frame's history.
            if let Some(recorded) = recorded.as_mut().filter(|r| r.feedback == level + 1) {
                let image = match &buffers.scratch {
                    Some(scratch) if level + 1 < passes => &scratch.images[level as usize % 2],
                    _ => &out,
                };
                self.record_feedback(&mut encoder, recorded, image, pixels);
            }
        }
        // `planefit` after the form: one dispatch over the last pass's whole image.
        let out = match planefit {
            Some(fit) => {
                let fitted = self.planefit(&mut encoder, buffers, fit, &out)?;
                dispatches += 1;
                fitted
            }
            None => out,
        };
        stopwatch.stop(&mut encoder);
        // The results' copy for reading back goes in the same submission: one wait less a call.
        encoder.copy_buffer_to_buffer(&out, 0, &staging, 0, pixels * 16);
        encoder.copy_buffer_to_buffer(&flags, 0, &staging, pixels * 16, pixels * 4);
        self.queue().submit([encoder.finish()]);
        self.wait("filtering")?;
        let time = Span { wall: start.elapsed(), device: stopwatch.read(self)? };
        for (part, recording, stopwatch) in parts {
            let span = Some(Span { wall: recording, device: stopwatch.read(self)? });
            match part {
                Part::Prepass => buffers.prepass_dispatch = span,
                Part::Temporal => buffers.temporal_dispatch = span,
                Part::Guide => buffers.guide_dispatch = span,
            }
        }

        if let Some(error) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Runtime { during: "filtering", message: error.to_string() });
        }
        if let Some(recorded) = recorded {
            buffers.temporal_pending = false;
            recorded.commit(state, buffers.width, buffers.height);
        }
        let bytes = self.read(&staging)?;
        let color: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(&bytes[..(pixels * 16) as usize]);
        let flags: Vec<u32> = bytemuck::pod_collect_to_vec(&bytes[(pixels * 16) as usize..]);
        Ok(Filtered { color, flags, pipeline: timing, time, dispatches })
    }

    /// Run a probe kernel ([`crate::jit::KernelKind::Probe`]): the raw weight
    /// w_ii and the domain-error bits of every pixel.
    pub fn probe(
        &self,
        kernel: &ValidatedKernel,
        buffers: &mut SceneBuffers,
        scene: &Scene,
    ) -> Result<(Vec<f32>, Vec<u32>), GpuError> {
        assert_eq!(kernel.source().kind, crate::jit::KernelKind::Probe, "probe() runs probe kernels");
        let out = self.filter(kernel, buffers, scene, 0)?;
        Ok((out.color.iter().map(|c| c[0]).collect(), out.flags))
    }

    pub(super) fn wait(&self, during: &'static str) -> Result<(), GpuError> {
        self.device()
            .poll(wgpu::PollType::wait_indefinitely())
            .map(|_| ())
            .map_err(|e| GpuError::Runtime { during, message: e.to_string() })
    }

    /// Submit a job's last commands, turn a validation error caught by its
    /// error scope into a [`GpuError`], and read `staging` back.
    pub(super) fn finish_and_read(
        &self,
        encoder: wgpu::CommandEncoder,
        scope: wgpu::ErrorScopeGuard,
        during: &'static str,
        staging: &wgpu::Buffer,
    ) -> Result<Vec<u8>, GpuError> {
        self.queue().submit([encoder.finish()]);
        if let Some(error) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Runtime { during, message: error.to_string() });
        }
        self.read(staging)
    }

    /// Map a MAP_READ buffer and copy its contents out.
    pub(super) fn read(&self, staging: &wgpu::Buffer) -> Result<Vec<u8>, GpuError> {
        let slice = staging.slice(..);
        let (sender, receiver) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |result| {
            let _ = sender.send(result);
        });
        self.wait("reading results back")?;
        receiver
            .recv()
            .map_err(|e| GpuError::Runtime { during: "reading results back", message: e.to_string() })?
            .map_err(|e| GpuError::Runtime { during: "reading results back", message: e.to_string() })?;
        let bytes = slice
            .get_mapped_range()
            .map_err(|e| GpuError::Runtime { during: "reading results back", message: e.to_string() })?
            .to_vec();
        staging.unmap();
        Ok(bytes)
    }
}
