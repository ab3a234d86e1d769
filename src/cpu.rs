//! The CPU reference: the same filter as the GPU kernels, evaluated in f64
//! with the semantics of [`crate::semantics`]. Slow and simple on purpose.

use crate::lang::{Expr, Feature, ScalarVar};
use crate::scene::Scene;
use crate::semantics;

/// Output of a filter run on the CPU.
#[derive(Clone, Debug)]
pub struct CpuFiltered {
    pub color: Vec<[f64; 3]>,
    /// Domain-error bits per pixel (see [`semantics::flag`]).
    pub flags: Vec<u32>,
}

/// Missing scene data for a terminal the expression reads.
#[derive(Debug, thiserror::Error)]
#[error("scene `{scene}` has no data for `{name}`")]
pub struct MissingData {
    pub scene: String,
    pub name: String,
}

/// Values one weight evaluation reads.
struct Pixels<'a> {
    scene: &'a Scene,
    i: usize,
    j: usize,
    width: usize,
}

impl Pixels<'_> {
    fn feature(&self, f: Feature, index: usize) -> [f64; 3] {
        match f {
            Feature::Pixel => [(index % self.width) as f64, (index / self.width) as f64, 0.0],
            _ => {
                let v = self.scene.feature(f).expect("checked before filtering")[index];
                // 1-D features are (v, 0, 0) whatever the buffer holds beyond v, as on the GPU.
                if f.dimension() == 1 {
                    [v[0] as f64, 0.0, 0.0]
                } else {
                    [v[0] as f64, v[1] as f64, v[2] as f64]
                }
            }
        }
    }

    fn variance(&self, v: ScalarVar) -> f64 {
        self.scene.variance(v).expect("checked before filtering")[self.i] as f64
    }
}

/// Evaluate `expr` for centre pixel `i` and neighbour `j`.
fn eval(expr: &Expr, px: &Pixels<'_>, flags: &mut u32) -> f64 {
    match expr {
        Expr::Const(c) => semantics::literal(*c),
        Expr::Var(v) => px.variance(*v),
        Expr::Unary(op, a) => op.eval(eval(a, px, flags), flags),
        Expr::Binary(op, a, b) => {
            let a = eval(a, px, flags);
            let b = eval(b, px, flags);
            op.eval(a, b, flags)
        }
        Expr::Pair(op, fi, fj) => op.eval(px.feature(*fi, px.i), px.feature(*fj, px.j)),
    }
}

/// Check that the scene has every input of `expr`.
pub fn check_inputs(expr: &Expr, scene: &Scene) -> Result<(), MissingData> {
    let missing = |name: &str| MissingData { scene: scene.name.clone(), name: name.to_string() };
    for f in expr.features() {
        if f.needs_data() && scene.feature(f).is_none() {
            return Err(missing(f.name()));
        }
    }
    for v in expr.variables() {
        if scene.variance(v).is_none() {
            return Err(missing(v.name()));
        }
    }
    Ok(())
}

/// Filter `scene` with weight expression `expr` over a (2r+1)² window.
pub fn filter(expr: &Expr, scene: &Scene, radius: u32) -> Result<CpuFiltered, MissingData> {
    check_inputs(expr, scene)?;
    let (w, h, r) = (scene.width as i64, scene.height as i64, radius as i64);
    let mut color = Vec::with_capacity(scene.pixels());
    let mut flags = Vec::with_capacity(scene.pixels());
    for y in 0..h {
        for x in 0..w {
            let i = (y * w + x) as usize;
            let mut pixel_flags = 0u32;
            let (mut sum_w, mut sum_c) = (Neumaier::default(), [Neumaier::default(); 3]);
            for yj in (y - r).max(0)..=(y + r).min(h - 1) {
                for xj in (x - r).max(0)..=(x + r).min(w - 1) {
                    let j = (yj * w + xj) as usize;
                    let px = Pixels { scene, i, j, width: scene.width };
                    let weight = semantics::weight(eval(expr, &px, &mut pixel_flags));
                    sum_w.add(weight);
                    for (sum, c) in sum_c.iter_mut().zip(scene.color[j]) {
                        sum.add(weight * c as f64);
                    }
                }
            }
            let centre = scene.color[i];
            let (sum_w, sum_c) = (sum_w.total(), sum_c.map(|s| s.total()));
            color.push(if sum_w > 0.0 {
                [sum_c[0] / sum_w, sum_c[1] / sum_w, sum_c[2] / sum_w]
            } else {
                [centre[0] as f64, centre[1] as f64, centre[2] as f64]
            });
            flags.push(pixel_flags);
        }
    }
    Ok(CpuFiltered { color, flags })
}

/// Neumaier's compensated sum: the reference keeps its sums exact to about
/// one rounding, however large the window.
#[derive(Clone, Copy, Debug, Default)]
pub struct Neumaier {
    sum: f64,
    compensation: f64,
}

impl Neumaier {
    pub fn add(&mut self, x: f64) {
        let t = self.sum + x;
        if self.sum.abs() >= x.abs() {
            self.compensation += (self.sum - t) + x;
        } else {
            self.compensation += (x - t) + self.sum;
        }
        self.sum = t;
    }

    pub fn total(&self) -> f64 {
        self.sum + self.compensation
    }
}

/// Evaluate the weight expression once, for tests of single operators.
pub fn weight_at(expr: &Expr, scene: &Scene, i: usize, j: usize) -> (f64, u32) {
    let mut flags = 0;
    let w = eval(expr, &Pixels { scene, i, j, width: scene.width }, &mut flags);
    (w, flags)
}
