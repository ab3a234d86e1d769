//! `filterjit compile`, `check` and `simplify`: what one expression is, and
//! the kernel it compiles to.

use super::*;

/// `compile`: the expression's filter kernel, in WGSL.
pub(crate) fn compile(
    expr: &str,
    output: Option<&Path>,
    pipeline: Option<filterjit::pipeline::FilterPipeline>,
) -> Result<()> {
    let resolved = corpus::resolve_with_pipeline(expr)?;
    let shape = jit::Shape::of(&pipeline.or(resolved.pipeline).unwrap_or_default());
    let kernel = jit::compile(&resolved.expr, jit::KernelSpec { shape, ..jit::KernelSpec::default() })?;
    match output {
        Some(path) => filterjit::io::write_bytes_atomically(path, kernel.wgsl().as_bytes())?,
        None => print!("{}", kernel.wgsl()),
    }
    Ok(())
}

/// `check`: the expression as parsed, its length and what it reads (`--latex`: as LaTeX).
pub(crate) fn check(expr: &str, latex: bool) -> Result<()> {
    if latex {
        println!("{}", lang::latex(&resolve_expr(expr)?));
        return Ok(());
    }
    let expr = resolve_expr(expr)?;
    println!("{expr}");
    println!("length: {} nodes", expr.len());
    let names: Vec<&str> =
        expr.features().iter().map(|f| f.name()).chain(expr.variables().iter().map(|v| v.name())).collect();
    println!("reads: {}", if names.is_empty() { "nothing but the colour".to_string() } else { names.join(", ") });
    Ok(())
}

/// `simplify`: the same weights in fewer nodes.
pub(crate) fn simplify(expr: &str) -> Result<()> {
    let expr = resolve_expr(expr)?;
    let simplified = filterjit::simplify::simplify(&expr);
    println!("{simplified}");
    println!(
        "length: {} -> {} nodes; kernel cost {:.1} -> {:.1}",
        expr.len(),
        simplified.len(),
        filterjit::simplify::kernel_cost(&expr),
        filterjit::simplify::kernel_cost(&simplified)
    );
    Ok(())
}
