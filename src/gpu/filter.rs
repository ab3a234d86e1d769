//! The filter dispatch: a frame's stages and the form's passes recorded into
//! one submission, on a scene's buffers (`buffers`).

use std::collections::HashMap;
use std::time::{Duration, Instant};

use super::buffers::SceneBuffers;
use super::temporal::TemporalState;
use super::{Gpu, GpuError, PipelineTiming, Span};
use crate::jit::interface::Element;
use crate::jit::{AtrousParams, Input, Params, PassRole, Role, ValidatedKernel, WORKGROUP};
use crate::lang::Feature;
use crate::pipeline::FilterPipeline;
use crate::scene::Scene;

/// Upper bound on weight evaluations in one dispatch. Large images and radii
/// are split into bands of rows so that no single dispatch runs long enough to
/// trip a GPU watchdog (Windows resets a GPU after about 2 s).
pub const MAX_WEIGHTS_PER_DISPATCH: u64 = 1 << 22;

/// Result of a filter dispatch.
#[derive(Clone, Debug)]
pub struct Filtered {
    /// Filtered colour, RGBA: alpha copied from the input (1), or what an
    /// à-trous form's passes hand on in it (the variance they carry,
    /// `jit::KernelSource::variance_in_alpha`, or the texture's x,
    /// `jit::TEXTURE_IN_FOURTH_CHANNELS`). Only the RGB is an image.
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
        let anchor = buffers.pipeline.anchor;
        if anchor.is_some() {
            self.prepare_anchor()?;
        }
        let pixel_filter = buffers.pipeline.pixel_filter;
        if pixel_filter.is_some() {
            self.prepare_pixel_filter()?;
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
        // 256² pass's own work (docs/JOURNAL.md, "On a GPU"). Bands keep
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
                // A variance riding in the colour's alpha is read from the
                // stage's image in the first pass only: later passes bind that
                // image again rather than copy theirs into a texture.
                let copied = carried.filter(|_| !kernel.source().variance_in_alpha);
                buffers.sampled_views(self, &mut encoder, &sampled, level, copied)?
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
                    let mut pass = if atrous {
                        self.compute_pass(&mut encoder, format_args!("form: à-trous pass {level}"))
                    } else {
                        self.compute_pass(&mut encoder, "form: window")
                    };
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
                self.record_feedback(&mut encoder, recorded, image, (buffers.width, buffers.height))?;
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
        // `anchor`: the sums averaged into the half-resolution grid, blurred there, then the image scaled.
        let out = match anchor {
            Some(anchor) => {
                let frame = buffers.frame.as_ref().expect("uploaded for a pipeline with `anchor`");
                let anchored = self.anchor(&mut encoder, anchor, frame, &out, (buffers.width, buffers.height))?;
                dispatches += crate::jit::ANCHOR_DISPATCHES;
                anchored
            }
            None => out,
        };
        // `pixelfilter`, last: one dispatch over the whole image.
        let out = match pixel_filter {
            Some(filter) => {
                let filtered = self.pixel_filter(&mut encoder, filter, &out, (buffers.width, buffers.height))?;
                dispatches += 1;
                filtered
            }
            None => out,
        };
        stopwatch.stop(&mut encoder);
        // The results' copy for reading back goes in the same submission: one wait less a call.
        encoder.copy_buffer_to_buffer(&out, 0, &staging, 0, pixels * 16);
        encoder.copy_buffer_to_buffer(&flags, 0, &staging, pixels * 16, pixels * 4);
        self.resolve_profile(&mut encoder);
        self.queue().submit([encoder.finish()]);
        self.wait("filtering")?;
        self.collect_profile()?;
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
        mut encoder: wgpu::CommandEncoder,
        scope: wgpu::ErrorScopeGuard,
        during: &'static str,
        staging: &wgpu::Buffer,
    ) -> Result<Vec<u8>, GpuError> {
        self.resolve_profile(&mut encoder);
        self.queue().submit([encoder.finish()]);
        if let Some(error) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Runtime { during, message: error.to_string() });
        }
        let read = self.read(staging);
        self.collect_profile()?;
        read
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
