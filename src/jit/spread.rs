//! `keep`'s spread kernel: what the outlier clamp removed, spread over the
//! neighbourhood and put back before demodulation. One module for every
//! pipeline, rendered from `templates/spread.wgsl.tera` with the stencil
//! `crate::pipeline` owns; `cpu::spread` is its reference.

use super::interface::{render_builtin, BindingInterface};
use super::kernel::{wgsl_f32, OutputFormat};
use super::validate::{validate_with_interface, ValidateError, ValidatedModule};
use crate::pipeline;

/// What one pass of the spread kernel does: bits of `params.stage`.
pub struct SpreadStage;

impl SpreadStage {
    /// The first pass spreads raw colour − clamped colour; later ones the previous pass's output.
    pub const FIRST: u32 = 1;
    /// The last pass writes (spread + clamped) / modulation, the colour the
    /// form filters, instead of the spread alone: no dispatch of its own.
    pub const FINISH: u32 = 2;
}

/// The spread kernel's uniform (`struct Params` of its module; fields in [`BindingInterface::spread`]).
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct SpreadParams {
    pub width: u32,
    pub height: u32,
    /// Pixel step between taps: 2^pass.
    pub step: u32,
    /// [`SpreadStage`] bits.
    pub stage: u32,
}

/// What a spread dispatch reads as its `Color`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SpreadSource {
    /// The noisy colour (the first dispatch spreads it minus the clamped colour).
    Noisy,
    /// Scratch image k (0 or 1), which the dispatch before wrote.
    Scratch(usize),
}

/// One dispatch of a spread: its uniform, the image it reads and the
/// scratch image it writes. Two scratch images are ping-ponged; the last
/// dispatch's is the colour the form filters.
#[derive(Clone, Copy, Debug)]
pub struct SpreadDispatch {
    pub params: SpreadParams,
    pub source: SpreadSource,
    pub target: usize,
}

impl SpreadParams {
    /// The dispatches of one spread, in order.
    pub fn sequence(width: u32, height: u32) -> Vec<SpreadDispatch> {
        let last = pipeline::KEEP_PASSES - 1;
        (0..pipeline::KEEP_PASSES)
            .map(|level| SpreadParams {
                width,
                height,
                step: pipeline::FilterPipeline::step(level),
                stage: if level == 0 { SpreadStage::FIRST } else { 0 }
                    | if level == last { SpreadStage::FINISH } else { 0 },
            })
            .enumerate()
            .map(|(n, params)| SpreadDispatch {
                params,
                source: if n == 0 { SpreadSource::Noisy } else { SpreadSource::Scratch((n - 1) % 2) },
                target: n % 2,
            })
            .collect()
    }
}

/// The spread kernel's WGSL: on storage buffers (filterjit's, `None`), or
/// exported, on textures (its output `rgba32float` whatever `format` is).
pub fn spread_wgsl(textures: Option<OutputFormat>) -> String {
    let mut context = BindingInterface::spread(textures).template_context();
    let half = pipeline::KEEP_STENCIL.half_width();
    context.insert("passes", &pipeline::KEEP_PASSES);
    context.insert("textures", &textures.is_some());
    // Each tap's offset and weight h(offset), across the stencil in order.
    let taps: Vec<(i32, String)> = (-half..=half).map(|d| (d, wgsl_f32(pipeline::KEEP_STENCIL.weight(d)))).collect();
    context.insert("taps", &taps);
    context.insert("first", &SpreadStage::FIRST);
    context.insert("finish", &SpreadStage::FINISH);
    render_builtin("spread", include_str!("../../templates/spread.wgsl.tera"), &context)
}

/// The spread kernel, validated by naga; its bindings are checked against its interface.
pub fn spread_module(textures: Option<OutputFormat>) -> Result<ValidatedModule, ValidateError> {
    validate_with_interface(&spread_wgsl(textures), "<spread>", &BindingInterface::spread(textures))
}
