//! `filterjit tune`: the cross-bilateral filter's sigmas (or a given
//! expression's constants) tuned on training scenes.

use super::*;

pub(crate) fn tune(env: &Environment, args: &TuneArgs) -> Result<()> {
    let gpu = gpu::Gpu::open(&env.adapter)?;
    let context = scene_context(&args.scene)?;
    let start = args.expr.as_deref().map(corpus::resolve).transpose()?;
    let tuned = report::tune_on_training(
        &gpu,
        env,
        &args.scene,
        &context,
        start.as_ref().map(|(_, e)| e),
        args.fitness_light.and_then(|t| t.0),
    )?;
    let name = match &start {
        None => "crossBilateralTuned".to_string(),
        Some((Some(name), _)) => format!("{name}Tuned"),
        Some((None, _)) => "tuned".to_string(),
    };
    println!("{name} = {}", tuned.expr);
    if let Some(path) = &args.output {
        let mut entry = filterjit::named::Entry::new(name, tuned.expr.to_string());
        entry.notes.push(format!(
            "tuned on {} at {}x{}, radius {}: training fitness {:.5} (the starting values' {:.5}; {})",
            tuned.scenes.join(", "),
            context.render.width,
            context.render.height,
            context.radius,
            tuned.fitness,
            tuned.hand_set_fitness,
            tuned.rule,
        ));
        entry.pipeline = Some(context.pipeline);
        let file = filterjit::named::NamedFile { header: Vec::new(), entries: vec![entry] };
        filterjit::io::write_bytes_atomically(path, file.to_string().as_bytes())?;
    }
    Ok(())
}
