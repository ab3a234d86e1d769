//! Encoding expressions for the benchmark's stack interpreter
//! (`templates/interpreter.wgsl`). Built for comparison only.

use super::timing::{ms, stat, Stat};
use crate::gpu::{Gpu, RawBuffer};
use crate::lang::{BinaryOp, Expr, Feature, FeatureSource, PairOp, ScalarVar, UnaryOp};
use crate::scene::Scene;
use crate::semantics;

/// The interpreter's source: the operator helpers, then the interpreter.
pub fn source() -> String {
    format!("{}\n{}", crate::jit::helpers::OPS_WGSL, include_str!("../../templates/interpreter.wgsl"))
}

/// Feature slots the interpreter reads the pixel position and colour from.
pub const SLOT_PIXEL: u32 = 254;
pub const SLOT_COLOR: u32 = 255;
/// The interpreter's stack depth.
pub const STACK: usize = 128;

/// A program in postfix order.
pub struct Program {
    pub code: Vec<u32>,
    pub constants: Vec<f32>,
    pub max_depth: usize,
}

fn index<T: PartialEq>(all: &[T], x: &T) -> u32 {
    all.iter().position(|y| y == x).expect("listed in its table") as u32
}

/// Encode `e`; `slot` gives the packed slot of a stored feature, `variance` of a variance.
pub fn encode(e: &Expr, slot: &dyn Fn(Feature) -> u32, variance: &dyn Fn(ScalarVar) -> u32) -> Program {
    let mut p = Program { code: Vec::new(), constants: Vec::new(), max_depth: 0 };
    fn go(e: &Expr, p: &mut Program, depth: usize, slot: &dyn Fn(Feature) -> u32, variance: &dyn Fn(ScalarVar) -> u32) {
        let feature_slot = |f: Feature| match f {
            Feature::Pixel => SLOT_PIXEL,
            Feature::Color => SLOT_COLOR,
            other => slot(other),
        };
        match e {
            Expr::Const(c) => {
                p.code.push((p.constants.len() as u32) << 16);
                p.constants.push(semantics::literal(*c) as f32);
            }
            Expr::Var(v) => p.code.push(1 | (variance(*v) << 8)),
            Expr::Unary(op, a) => {
                go(a, p, depth, slot, variance);
                p.code.push(2 | (index(UnaryOp::ALL, op) << 8));
            }
            Expr::Binary(op, a, b) => {
                go(a, p, depth, slot, variance);
                go(b, p, depth + 1, slot, variance);
                p.code.push(3 | (index(BinaryOp::ALL, op) << 8));
            }
            Expr::Pair(op, i, j) => {
                p.code.push(4 | (index(PairOp::ALL, op) << 8) | (feature_slot(*i) << 16) | (feature_slot(*j) << 24));
            }
        }
        p.max_depth = p.max_depth.max(depth + 1);
    }
    go(e, &mut p, 0, slot, variance);
    p
}

/// The interpreter's inputs for a scene: features and variances packed by slot.
pub(super) struct Packed {
    features: Vec<Feature>,
    variances: Vec<ScalarVar>,
    feature_data: Vec<u8>,
    variance_data: Vec<u8>,
}

pub(super) fn pack(scene: &Scene) -> Packed {
    let features: Vec<Feature> = scene
        .features
        .keys()
        .copied()
        .filter(|f| matches!(f.source(), FeatureSource::Stored(_) | FeatureSource::Gradient(_)))
        .collect();
    let variances: Vec<ScalarVar> = scene.variances.keys().copied().collect();
    let mut fdata: Vec<[f32; 4]> = Vec::new();
    for f in &features {
        fdata.extend(scene.features[f].iter().map(|v| {
            if f.dimension() == 1 {
                [v[0], 0.0, 0.0, 0.0]
            } else {
                [v[0], v[1], v[2], 0.0]
            }
        }));
    }
    if fdata.is_empty() {
        fdata.push([0.0; 4]);
    }
    let mut vdata: Vec<f32> = variances.iter().flat_map(|v| scene.variances[v].iter().copied()).collect();
    if vdata.is_empty() {
        vdata.push(0.0);
    }
    Packed {
        features,
        variances,
        feature_data: bytemuck::cast_slice(&fdata).to_vec(),
        variance_data: bytemuck::cast_slice(&vdata).to_vec(),
    }
}

pub(super) fn interpret(
    gpu: &Gpu,
    kernel: &crate::gpu::RawKernel,
    packed: &Packed,
    expr: &Expr,
    scene: &Scene,
    radius: u32,
    repeats: usize,
) -> anyhow::Result<Option<Stat>> {
    let slot = |f: Feature| packed.features.iter().position(|g| *g == f).expect("the scene has it") as u32;
    let variance = |v: ScalarVar| packed.variances.iter().position(|w| *w == v).expect("the scene has it") as u32;
    let program = encode(expr, &slot, &variance);
    if program.max_depth > STACK {
        return Ok(None);
    }
    let (w, h) = (scene.width as u32, scene.height as u32);
    let params: [u32; 8] = [w, h, radius, 0, program.code.len() as u32, w * h, 0, 0];
    let color: Vec<[f32; 4]> = scene.color.iter().map(|c| [c[0], c[1], c[2], 1.0]).collect();
    let constants = if program.constants.is_empty() { vec![0.0] } else { program.constants.clone() };
    let pixels = (w * h) as u64;
    let mut times = Vec::new();
    for _ in 0..repeats + 1 {
        let buffers = [
            RawBuffer::Read(bytemuck::cast_slice(&color)),
            RawBuffer::Write(pixels * 16),
            RawBuffer::Write(pixels * 4),
            RawBuffer::Read(bytemuck::cast_slice(&program.code)),
            RawBuffer::Read(bytemuck::cast_slice(&constants)),
            RawBuffer::Read(&packed.feature_data),
            RawBuffer::Read(&packed.variance_data),
        ];
        let (t, _) = gpu.run_raw(kernel, bytemuck::cast_slice(&params), &buffers, (w.div_ceil(8), h.div_ceil(8)))?;
        times.push(ms(t));
    }
    times.remove(0); // the first dispatch compiles
    Ok(Some(stat(times)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::jit::Helper;

    #[test]
    fn the_operator_orders_match_the_interpreter() {
        // templates/interpreter.wgsl switches on these positions.
        let wgsl = include_str!("../../templates/interpreter.wgsl");
        for (k, op) in UnaryOp::ALL.iter().enumerate().take(UnaryOp::ALL.len() - 1) {
            assert!(wgsl.contains(&format!("case {k}u: {{ return {}(a); }}", op.helper())), "{op}");
        }
        for (k, op) in BinaryOp::ALL.iter().enumerate().take(BinaryOp::ALL.len() - 1) {
            assert!(wgsl.contains(&format!("case {k}u: {{ return {}(a, b); }}", op.helper())), "{op}");
        }
        for (k, op) in PairOp::ALL.iter().enumerate().take(PairOp::ALL.len() - 1) {
            assert!(wgsl.contains(&format!("case {k}u: {{ return {}(u, v); }}", op.helper())), "{op}");
        }
    }
}
