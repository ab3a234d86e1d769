//! `filterjit list` and `filterjit adapters`: what ships, and what it can run on.

use super::*;

/// `list`: the shipped filters, each one's pipeline, what it reads and what it was measured to do.
pub(crate) fn list(brief: bool) -> Result<()> {
    if brief {
        return list_brief();
    }
    for s in filterjit::denoise::shipped()? {
        println!("@{}  pipeline {}", s.name, s.pipeline);
        println!("    reads     {}", s.reads.join(", "));
        if let Some(rank) = s.rank {
            println!("    default   {rank}. choice of `filter` without --expr, where the render has what it reads");
        }
        if let Some(rule) = s.sparse_light_variant_of {
            println!(
                "    sparse    in place of @{}, where the render's median pixel is below {} of its mean luminance",
                rule.base, rule.under
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

/// `list --brief`: a line a filter, those `filter` chooses first (in its
/// order: for renders, then for sequences), then the rest as shipped.
fn list_brief() -> Result<()> {
    use filterjit::denoise::{SHIPPED_REALTIME, SHIPPED_REALTIME_TEMPORAL, SHIPPED_TEMPORAL_BY_QUALITY};
    let shipped = filterjit::denoise::shipped()?;
    // A filter's role and its place: the group its role falls in, then its rank there.
    let role = |s: &filterjit::denoise::Shipped| -> ((u8, usize), String) {
        let temporal = SHIPPED_TEMPORAL_BY_QUALITY.iter().position(|n| *n == s.name);
        match (s.rank, temporal, s.sparse_light_variant_of) {
            (Some(rank), _, _) => ((0, rank), format!("render: filter's choice {rank}")),
            (_, Some(k), _) => ((1, k), format!("sequence: filter's choice {}", k + 1)),
            _ if s.name == SHIPPED_REALTIME => ((2, 0), format!("render, real time: --expr @{SHIPPED_REALTIME}")),
            _ if s.name == SHIPPED_REALTIME_TEMPORAL => {
                ((2, 1), format!("sequence, real time: --expr @{SHIPPED_REALTIME_TEMPORAL}"))
            }
            (_, _, Some(rule)) => ((3, 0), format!("render: @{} where the light is sparse", rule.base)),
            _ => ((4, 0), String::new()),
        }
    };
    // A stable sort: within a group of equal places, the shipped file's order.
    let mut rows: Vec<_> = shipped.iter().map(|s| (role(s), s)).collect();
    rows.sort_by_key(|((place, _), _)| *place);
    let width = shipped.iter().map(|s| s.name.len() + 1).max().unwrap_or(0);
    let pipeline_width = shipped.iter().map(|s| s.pipeline.to_string().len()).max().unwrap_or(0);
    for ((_, role), s) in rows {
        let name = format!("@{}", s.name);
        let pipeline = s.pipeline.to_string();
        println!("{}", format!("{name:<width$}  {pipeline:<pipeline_width$}  {role}").trim_end());
    }
    println!("(`filterjit list` gives each one's inputs, measured error and expression)");
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
