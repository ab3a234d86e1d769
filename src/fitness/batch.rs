//! A batch of expressions into fitness kernels: grouped in order into kernels
//! of up to `fuse` members within the device's binding limit, each compiled;
//! a group whose kernel fails is compiled member by member, so that a
//! candidate that does not compile, or binds more than the device allows, is
//! an invalid individual with its reason, never a failed batch.

use crate::gpu::{Gpu, GpuError};
use crate::jit::{self, BindingInterface, KernelKind, KernelLayout, LowerOptions, Shape};
use crate::lang::Expr;

use super::invalid::Invalid;

/// `exprs` in order, in groups of at most `fuse` whose fused fitness kernel
/// binds at most `limit` storage buffers (a group of one may exceed it: its
/// compile says so). À-trous kernels are never fused.
pub(super) fn groups(exprs: &[Expr], fuse: usize, limit: u32, shape: Shape) -> Vec<Vec<Expr>> {
    let fuse = if shape.atrous { 1 } else { fuse.max(1) };
    let mut groups: Vec<Vec<Expr>> = Vec::new();
    for e in exprs {
        let fits = groups.last().is_some_and(|g: &Vec<Expr>| {
            let mut with = g.clone();
            with.push(e.clone());
            let layout = KernelLayout::of_all(&with);
            g.len() < fuse && BindingInterface::of(KernelKind::Fitness, &layout, shape).storage_buffers() <= limit
        });
        match groups.last_mut() {
            Some(g) if fits => g.push(e.clone()),
            _ => groups.push(vec![e.clone()]),
        }
    }
    groups
}

/// The batch's fitness kernels, in order, and for each expression `None`
/// where a kernel scores it or the reason none does.
pub(super) fn kernels(
    gpu: &Gpu,
    exprs: &[Expr],
    fuse: usize,
    options: LowerOptions,
    shape: Shape,
    threads: usize,
) -> (Vec<jit::ValidatedKernel>, Vec<Option<Invalid>>) {
    let groups = groups(exprs, fuse, gpu.storage_buffer_limit(), shape);
    let kernel_for = |g: &[Expr]| -> Result<jit::ValidatedKernel, Invalid> {
        let kernel = jit::compile_fused(g, jit::KernelSpec { kind: jit::KernelKind::Fitness, options, shape })
            .map_err(|e| Invalid::DoesNotCompile(e.to_string()))?;
        gpu.check_bindings(&kernel).map_err(|e| match e {
            GpuError::TooManyBindings { expression, needed, limit, adapter } => {
                Invalid::TooManyBindings { expression, needed, limit, adapter }
            }
            other => Invalid::DoesNotCompile(other.to_string()),
        })?;
        Ok(kernel)
    };
    let compiled = crate::parallel::map(&groups, threads, |g| match kernel_for(g) {
        Ok(kernel) => vec![Ok(kernel)],
        Err(_) if g.len() > 1 => g.iter().map(|e| kernel_for(std::slice::from_ref(e))).collect(),
        Err(reason) => vec![Err(reason)],
    });
    let mut kernels = Vec::new();
    let mut unsupported = Vec::new();
    for result in compiled.into_iter().flatten() {
        match result {
            Ok(k) => {
                unsupported.extend(std::iter::repeat_n(None, k.source().exprs.len()));
                kernels.push(k);
            }
            Err(reason) => unsupported.push(Some(reason)),
        }
    }
    (kernels, unsupported)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lang::parse_expr;

    fn exprs(texts: &[&str]) -> Vec<Expr> {
        texts.iter().map(|t| parse_expr(t).unwrap()).collect()
    }

    #[test]
    fn groups_keep_order_and_size() {
        let batch = exprs(&["1", "distance2(normal)", "2", "3", "4"]);
        let g = groups(&batch, 2, 8, Shape::WINDOW);
        assert_eq!(g.iter().map(Vec::len).collect::<Vec<_>>(), [2, 2, 1]);
        assert_eq!(g.concat(), batch);
    }

    #[test]
    fn a_group_stays_within_the_binding_limit_and_atrous_kernels_are_alone() {
        let batch = exprs(&["distance2(normal)", "distance2(worldPosition)", "distance2(texture)"]);
        let one = BindingInterface::of(KernelKind::Fitness, &KernelLayout::of_all(&batch[..1]), Shape::WINDOW)
            .storage_buffers();
        // A limit one member just meets: no two members with different inputs fit together.
        let g = groups(&batch, 12, one, Shape::WINDOW);
        assert_eq!(g.len(), 3);
        let atrous = Shape { atrous: true, ..Shape::WINDOW };
        assert_eq!(groups(&batch, 12, 100, atrous).len(), 3);
        assert_eq!(groups(&batch, 12, 100, Shape::WINDOW).len(), 1);
    }
}
