//! `filterjit list` and `filterjit adapters`: what ships, and what it can run on.

use super::*;

/// `list`: the shipped filters, each one's pipeline, what it reads and what it was measured to do.
pub(crate) fn list() -> Result<()> {
    for s in filterjit::denoise::shipped()? {
        println!("@{}  pipeline {}", s.name, s.pipeline);
        println!("    reads     {}", s.reads.join(", "));
        if let Some(rank) = s.rank {
            println!("    default   {rank}. choice of `filter` without --expr, where the render has what it reads");
        }
        if let Some(base) = s.sparse_light_variant_of {
            println!(
                "    default   in place of @{base}, where the render's median pixel is below {} of its mean luminance",
                filterjit::denoise::SPARSE_MEDIAN_OVER_MEAN
            );
        }
        if let Some(measured) = s.measured {
            println!("    measured  {measured}");
        }
        match s.weight_of {
            Some(other) => println!("    weight    @{other}'s"),
            None => println!("    {}", s.text),
        }
    }
    Ok(())
}

/// `adapters`: the GPU adapters wgpu finds, the one filterjit uses first.
pub(crate) fn adapters(env: &Environment) -> Result<()> {
    let backends = env.adapter.backends;
    let adapters = gpu::adapter::available(backends, true);
    if adapters.is_empty() {
        bail!(gpu::GpuError::NoAdapter { backends: format!("{backends:?}") });
    }
    for (k, a) in adapters.iter().enumerate() {
        let info = a.get_info();
        println!(
            "{} {} ({:?}, {:?}) {}",
            if k == 0 { "*" } else { " " },
            info.name,
            info.backend,
            info.device_type,
            info.driver_info
        );
    }
    println!("* = the best; filterjit uses it unless {} names another", filterjit::environment::ADAPTER);
    Ok(())
}
