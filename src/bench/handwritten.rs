//! The generated kernel against a hand-written one for the bilateral seed's
//! formula (plain, optimised, tiled), in interleaved rounds.

use serde::Serialize;

use super::timing::{interleaved, Stat};
use super::BenchSettings;
use crate::gpu::{Gpu, SceneBuffers};
use crate::jit::{self, KernelKind, KernelLayout, KernelSource, LowerOptions};
use crate::lang::parse_expr;
use crate::scene::Scene;

/// The hand-written cross-bilateral kernel a person would write for `@bilateral`.
pub const HANDWRITTEN_BILATERAL: &str = include_str!("../../templates/handwritten_bilateral.wgsl");

#[derive(Clone, Debug, Serialize)]
pub struct HandWrittenResult {
    pub handwritten_ms: Stat,
    pub generated_ms: Stat,
    pub generated_plain_ms: Stat,
    /// The generated kernel with workgroup tiles.
    pub generated_tiled_ms: Stat,
    pub tiled_ratio: f64,
    /// generated / hand-written.
    pub ratio: f64,
    pub plain_ratio: f64,
}

pub(super) fn measure(
    gpu: &Gpu,
    scene: &Scene,
    buffers: &mut SceneBuffers,
    settings: &BenchSettings,
) -> anyhow::Result<HandWrittenResult> {
    let bilateral = parse_expr(crate::corpus::lookup("bilateral").expect("shipped"))?;
    let layout = KernelLayout::of(&bilateral);
    let handwritten = jit::validate(KernelSource {
        kind: KernelKind::Filter,
        options: LowerOptions::NONE,
        shape: jit::Shape::WINDOW,
        canonical: "<hand-written bilateral>".into(),
        interface: jit::BindingInterface::of(KernelKind::Filter, &layout, jit::Shape::WINDOW),
        layout,
        tile_radius: None,
        first_pass_override: false,
        variance_in_alpha: false,
        exprs: vec![bilateral.clone()],
        wgsl: HANDWRITTEN_BILATERAL.to_string(),
    })?;
    let generated = jit::compile(&bilateral, jit::KernelSpec::default())?;
    let generated_plain = jit::validate(jit::lower(
        &bilateral,
        jit::KernelSpec { options: LowerOptions::NONE, ..jit::KernelSpec::default() },
    )?)?;
    let generated_tiled = jit::validate(jit::lower(
        &bilateral,
        jit::KernelSpec { options: LowerOptions::ALL.with_tiles(settings.radius), ..jit::KernelSpec::default() },
    )?)?;
    let kernels = [&handwritten, &generated, &generated_plain, &generated_tiled];
    for k in kernels {
        gpu.filter(k, buffers, scene, settings.radius)?;
    }
    let [handwritten_ms, generated_ms, generated_plain_ms, generated_tiled_ms]: [Stat; 4] =
        interleaved(gpu, &kernels, buffers, scene, settings.radius, settings.repeats * 4)?
            .try_into()
            .expect("four kernels");
    Ok(HandWrittenResult {
        tiled_ratio: generated_tiled_ms.median / handwritten_ms.median,
        generated_tiled_ms,
        ratio: generated_ms.median / handwritten_ms.median,
        plain_ratio: generated_plain_ms.median / handwritten_ms.median,
        handwritten_ms,
        generated_ms,
        generated_plain_ms,
    })
}
