//! The temporal stage on the device (`jit::temporal`): the state a sequence
//! keeps from frame to frame ([`TemporalState`]), and the stage recorded into
//! a frame's submission, after the pre-pass and before the form; the form's
//! pass that the pipeline feeds back becomes the next frame's history.
//! `cpu::temporal` is its reference.

use super::buffers::SceneBuffers;
use super::{Gpu, GpuError};
use crate::jit::interface::Element;
use crate::jit::{BindingInterface, BuiltIn, Input, Role, TemporalParams, WORKGROUP};
use crate::lang::ScalarVar;
use crate::pipeline::Temporal;

/// What a sequence keeps on the device from one frame for the next: the
/// history's colour, its moments and the frame's surface. One value a
/// caller keeps between the frames of a sequence and hands to every
/// [`Gpu::filter_frame`]; a new one (or [`TemporalState::reset`]) starts a
/// sequence.
#[derive(Default)]
pub struct TemporalState {
    kept: Option<Kept>,
    frames: u32,
}

/// One frame's history on the device, kept as the sampled textures the
/// next frame's stage reads: the frame made each of them for a kernel of
/// its own, so the next frame copies none (docs/JOURNAL.md, "The temporal
/// stage keeps textures").
struct Kept {
    width: u32,
    height: u32,
    /// The image the pipeline feeds back (rgba, demodulated where it demodulates).
    color: wgpu::Texture,
    /// m1, m2, r, n per pixel.
    moments: wgpu::Texture,
    /// The frame's surface: the normal's direction and the depth; and its albedo.
    surface: wgpu::Texture,
    albedo: wgpu::Texture,
    /// The modulation blended over frames.
    modulation: wgpu::Texture,
}

impl TemporalState {
    /// A state with no history: the next frame starts a sequence.
    pub fn new() -> Self {
        Self::default()
    }

    /// Forget the history (a cut in the sequence, a new scene).
    pub fn reset(&mut self) {
        *self = Self::default();
    }

    /// How many frames have been blended since the state was made or reset.
    pub fn frames(&self) -> u32 {
        self.frames
    }

    /// The history, where it holds a frame of `width` × `height` (a frame
    /// of another size starts a new history: nothing of the old one lines up).
    fn history_for(&self, width: u32, height: u32) -> Option<&Kept> {
        self.kept.as_ref().filter(|k| k.width == width && k.height == height)
    }
}

/// What the stage recorded into a frame, kept once the frame's submission is done.
pub(super) struct Recorded {
    moments: wgpu::Texture,
    surface: wgpu::Texture,
    albedo: wgpu::Texture,
    modulation: wgpu::Texture,
    /// The passes of the form after which the image is the next history.
    pub(super) feedback: u32,
    /// The image fed back, once recorded.
    pub(super) color: Option<wgpu::Texture>,
}

impl Gpu {
    /// Record the temporal stage of `buffers`' frame into `encoder`: the
    /// blend becomes the colour the form filters, and `historyLength` and
    /// `temporalVariance` join its inputs. The history comes from `state`;
    /// what the next frame keeps is returned, to be committed with
    /// [`Recorded::commit`] once the frame is done. Callers hold the GL turn
    /// and made the pipelines ([`Gpu::temporal_pipelines`]).
    pub(super) fn record_temporal(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        buffers: &mut SceneBuffers,
        state: &TemporalState,
        stage: Temporal,
    ) -> Result<Recorded, GpuError> {
        let (width, height) = (buffers.width, buffers.height);
        let motion = buffers.motion.as_ref().expect("a temporal pipeline's buffers hold the frame's motion");
        let (vectors, surface, albedo) = (motion.vectors.clone(), motion.surface.clone(), motion.albedo.clone());
        let kernel = self.built_in(BuiltIn::Temporal, 0)?;
        let interface = BindingInterface::temporal(None);
        let history = state.history_for(width, height);
        let params = TemporalParams::of(stage, width, height, history.is_some());
        let uniform = self.params_buffer(interface.params(), "temporal params", bytemuck::bytes_of(&params));
        let device = self.device();
        let make = |label, bytes: u64| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: (width * height) as u64 * bytes,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            })
        };
        let (blend, moments) = (make("temporal blend", 16), make("temporal moments", 16));
        let modulation = make("temporal modulation", 16);
        let (length, samples) = (make("history length", 4), make("sample variance", 4));
        let size = (width, height);
        let texture = |encoder: &mut wgpu::CommandEncoder, buffer: &wgpu::Buffer| {
            self.blitted(encoder, buffer, Element::Vec4F32, size)
        };
        let view = |texture: &wgpu::Texture| texture.create_view(&Default::default());
        let color = view(&texture(encoder, &buffers.color)?);
        // The frame's surface and albedo (uploaded as textures): this frame's
        // test reads them, and the next frame's as its past.
        let (geometry, material) = (view(&surface), view(&albedo));
        let motion = view(&vectors);
        // A first frame reads no history: the frame's own images stand in for it.
        let (past, past_moments, past_surface, past_albedo, past_modulation) = match history {
            Some(kept) => (
                view(&kept.color),
                view(&kept.moments),
                view(&kept.surface),
                view(&kept.albedo),
                view(&kept.modulation),
            ),
            None => (color.clone(), color.clone(), geometry.clone(), material.clone(), material.clone()),
        };
        let bind_group = self.bind_in_slot_order(
            &kernel,
            interface
                .bindings
                .iter()
                .map(|b| match b.role {
                    Role::Params => uniform.as_entire_binding(),
                    Role::Color => wgpu::BindingResource::TextureView(&color),
                    Role::Geometry => wgpu::BindingResource::TextureView(&geometry),
                    Role::Albedo => wgpu::BindingResource::TextureView(&material),
                    Role::PreviousAlbedo => wgpu::BindingResource::TextureView(&past_albedo),
                    Role::Motion => wgpu::BindingResource::TextureView(&motion),
                    Role::History => wgpu::BindingResource::TextureView(&past),
                    Role::Moments => wgpu::BindingResource::TextureView(&past_moments),
                    Role::PreviousGeometry => wgpu::BindingResource::TextureView(&past_surface),
                    Role::PastModulation => wgpu::BindingResource::TextureView(&past_modulation),
                    Role::ModulationOut => modulation.as_entire_binding(),
                    Role::Output => blend.as_entire_binding(),
                    Role::MomentsOut => moments.as_entire_binding(),
                    Role::Input(Input::Variance(ScalarVar::HistoryLength)) => length.as_entire_binding(),
                    Role::SampleVariance => samples.as_entire_binding(),
                    other => unreachable!("the temporal stage has no {other:?} binding"),
                })
                .collect(),
        );
        let groups = (width.div_ceil(WORKGROUP[0]), height.div_ceil(WORKGROUP[1]));
        {
            let mut pass = self.compute_pass(encoder, "temporal: reprojection and blend");
            pass.set_pipeline(&kernel.pipeline);
            pass.set_bind_group(0, &bind_group, &[]);
            pass.dispatch_workgroups(groups.0, groups.1, 1);
        }
        // The sample variance, prefiltered and scaled to the blend's: `temporalVariance`.
        let prefilter = self.built_in(BuiltIn::TemporalVariance, 0)?;
        let interface = BindingInterface::temporal_variance(None);
        let sizes = crate::jit::BlitParams { width, height, _pad: [0; 2] };
        let uniform = self.params_buffer(interface.params(), "temporal variance params", bytemuck::bytes_of(&sizes));
        let sample_view = self.blitted(encoder, &samples, Element::F32, size)?.create_view(&Default::default());
        // The moments' texture: this kernel's, then the next frame's history.
        let moments = texture(encoder, &moments)?;
        let moments_view = view(&moments);
        let variance = make("temporal variance", 4);
        let bind_group = self.bind_group(&prefilter, &interface, |role| match role {
            Role::Params => uniform.as_entire_binding(),
            Role::SampleVariance => wgpu::BindingResource::TextureView(&sample_view),
            Role::Moments => wgpu::BindingResource::TextureView(&moments_view),
            Role::Input(Input::Variance(ScalarVar::TemporalVariance)) => variance.as_entire_binding(),
            other => unreachable!("the temporal variance has no {other:?} binding"),
        });
        {
            let mut pass = self.compute_pass(encoder, "temporal: variance prefilter");
            pass.set_pipeline(&prefilter.pipeline);
            pass.set_bind_group(0, &bind_group, &[]);
            pass.dispatch_workgroups(groups.0, groups.1, 1);
        }
        buffers.inputs.insert(Input::Variance(ScalarVar::HistoryLength), length);
        buffers.inputs.insert(Input::Variance(ScalarVar::TemporalVariance), variance);
        // The blend and the blended modulation as textures: the form samples
        // them, and the next frame reads them as its history.
        let modulation_texture = texture(encoder, &modulation)?;
        let blend_texture = texture(encoder, &blend)?;
        // The form's result is multiplied back by the albedo blended over frames.
        if buffers.modulation.is_some() {
            buffers.replace_modulation(modulation);
            buffers.sampled.provide(Role::Modulation, modulation_texture.clone());
        }
        buffers.replace_color(blend);
        buffers.sampled.provide(Role::Color, blend_texture.clone());
        let feedback = stage.feedback;
        let color = (feedback == 0).then_some(blend_texture);
        Ok(Recorded { moments, surface, albedo, modulation: modulation_texture, feedback, color })
    }

    /// Record a copy of `image` (a pass's output, a frame of `size`) as the history's colour.
    pub(super) fn record_feedback(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        recorded: &mut Recorded,
        image: &wgpu::Buffer,
        size: (u32, u32),
    ) -> Result<(), GpuError> {
        recorded.color = Some(self.blitted(encoder, image, Element::Vec4F32, size)?);
        Ok(())
    }
}

impl Recorded {
    /// Make what this frame recorded `state`'s history, once its submission is done.
    pub(super) fn commit(self, state: &mut TemporalState, width: u32, height: u32) {
        let color = self.color.expect("the fed-back pass is among the form's passes (`most_feedback`)");
        // A frame of another size than the history's started a new one.
        let continued = state.history_for(width, height).is_some();
        state.frames = if continued { state.frames + 1 } else { 1 };
        state.kept = Some(Kept {
            width,
            height,
            color,
            moments: self.moments,
            surface: self.surface,
            albedo: self.albedo,
            modulation: self.modulation,
        });
    }
}
