//! The temporal stage on the device (`jit::temporal`): the state a sequence
//! keeps from frame to frame ([`TemporalState`]), and the stage recorded into
//! a frame's submission, after the pre-pass and before the form; the form's
//! pass that the pipeline feeds back becomes the next frame's history.
//! `cpu::temporal` is its reference.

use super::filter::SceneBuffers;
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

/// One frame's history on the device.
struct Kept {
    width: u32,
    height: u32,
    /// The image the pipeline feeds back (rgba, demodulated where it demodulates).
    color: wgpu::Buffer,
    /// m1, m2, r, n per pixel.
    moments: wgpu::Buffer,
    /// The frame's surface: the normal's direction and the depth.
    surface: wgpu::Buffer,
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
    moments: wgpu::Buffer,
    surface: wgpu::Buffer,
    /// The passes of the form after which the image is the next history.
    pub(super) feedback: u32,
    /// The image fed back, once recorded.
    pub(super) color: Option<wgpu::Buffer>,
}

/// The frame's own inputs to the stage, uploaded with its colour.
pub(super) struct FrameMotion {
    /// (dx, dy, 0, 0) per pixel.
    pub(super) vectors: wgpu::Buffer,
    /// The normal's direction and the depth per pixel.
    pub(super) surface: wgpu::Buffer,
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
        let (vectors, surface) = (motion.vectors.clone(), motion.surface.clone());
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
        let measures = ScalarVar::FROM_TEMPORAL.map(|_| make("temporal measure", 4));
        let size = (width, height);
        let view = |encoder: &mut wgpu::CommandEncoder, buffer: &wgpu::Buffer| {
            Ok::<_, GpuError>(self.blitted(encoder, buffer, Element::Vec4F32, size)?.create_view(&Default::default()))
        };
        let color = view(encoder, &buffers.color)?;
        let geometry = view(encoder, &surface)?;
        let motion = view(encoder, &vectors)?;
        // A first frame reads no history: the frame's own images stand in for it.
        let (past, past_moments, past_surface) = match history {
            Some(kept) => (view(encoder, &kept.color)?, view(encoder, &kept.moments)?, view(encoder, &kept.surface)?),
            None => (color.clone(), color.clone(), geometry.clone()),
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
                    Role::Motion => wgpu::BindingResource::TextureView(&motion),
                    Role::History => wgpu::BindingResource::TextureView(&past),
                    Role::Moments => wgpu::BindingResource::TextureView(&past_moments),
                    Role::PreviousGeometry => wgpu::BindingResource::TextureView(&past_surface),
                    Role::Output => blend.as_entire_binding(),
                    Role::MomentsOut => moments.as_entire_binding(),
                    Role::Input(Input::Variance(v)) if v.from_temporal() => {
                        let k = ScalarVar::FROM_TEMPORAL.iter().position(|w| *w == v).expect("a temporal measure");
                        measures[k].as_entire_binding()
                    }
                    other => unreachable!("the temporal stage has no {other:?} binding"),
                })
                .collect(),
        );
        {
            let mut pass = encoder.begin_compute_pass(&Default::default());
            pass.set_pipeline(&kernel.pipeline);
            pass.set_bind_group(0, &bind_group, &[]);
            pass.dispatch_workgroups(width.div_ceil(WORKGROUP[0]), height.div_ceil(WORKGROUP[1]), 1);
        }
        for (v, buffer) in ScalarVar::FROM_TEMPORAL.into_iter().zip(measures) {
            buffers.inputs.insert(Input::Variance(v), buffer);
        }
        buffers.replace_color(blend);
        let feedback = stage.feedback;
        let color = (feedback == 0).then(|| buffers.color.clone());
        Ok(Recorded { moments, surface, feedback, color })
    }

    /// Record a copy of `image` (a pass's output) as the history's colour.
    pub(super) fn record_feedback(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        recorded: &mut Recorded,
        image: &wgpu::Buffer,
        pixels: u64,
    ) {
        let copy = self.device().create_buffer(&wgpu::BufferDescriptor {
            label: Some("temporal history"),
            size: pixels * 16,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        encoder.copy_buffer_to_buffer(image, 0, &copy, 0, pixels * 16);
        recorded.color = Some(copy);
    }
}

impl Recorded {
    /// Make what this frame recorded `state`'s history, once its submission is done.
    pub(super) fn commit(self, state: &mut TemporalState, width: u32, height: u32) {
        let color = self.color.expect("the fed-back pass is among the form's passes (`most_feedback`)");
        state.kept = Some(Kept { width, height, color, moments: self.moments, surface: self.surface });
        state.frames += 1;
    }
}
