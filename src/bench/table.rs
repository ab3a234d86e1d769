//! The report as the text table `filterjit bench` prints.

use super::{Clock, Report, FRAME_SIDE, THESIS_TABLE_4_1};

pub fn table(r: &Report) -> String {
    let mut t = String::new();
    t += &format!(
        "device  {}\nscene   {} ({}x{}), radius {}, {} repeats per figure (median [min, max])\n",
        r.device, r.scene, r.width, r.height, r.settings.radius, r.settings.repeats
    );
    t += match r.clock {
        Clock::Device => {
            "clock   warm kernels on the device's own clock (timestamps around the commands); whole frames by wall time and on it\n\n"
        }
        Clock::Wall => "clock   wall time, submission to completion (this device has no timestamps)\n\n",
    };
    t += "compile latency and throughput per expression (ms)\n";
    t += &format!(
        "{:>4} {:>7} {:>8} {:>9} {:>9} {:>10} {:>10} {:>11} {:>9} {:>10}\n",
        "len", "lower", "validate", "pipeline", "1st disp", "jit", "jit plain", "interpreter", "interp/jit", "Gops/s"
    );
    for e in &r.corpus.expressions {
        t += &format!(
            "{:>4} {:>7.2} {:>8.2} {:>9.2} {:>9.1} {:>10.2} {:>10.2} {:>11} {:>9} {:>10.2}\n",
            e.length,
            e.lower_ms,
            e.validate_ms,
            e.pipeline_ms,
            e.first_dispatch_ms,
            e.jit_ms.median,
            e.jit_plain_ms.median,
            e.interpreter_ms.as_ref().map_or("-".into(), |s| format!("{:.2}", s.median)),
            e.interpreter_ratio.map_or("-".into(), |x| format!("{x:.1}x")),
            e.gp_ops_per_second / 1e9
        );
    }
    t += &format!(
        "\nmedian: interpreter / JIT {:.1}x; unoptimised / optimised {:.2}x; {:.3} G weights/s; {:.2} G GP ops/s\n",
        r.corpus.interpreter_ratio_median,
        r.corpus.optimisation_ratio_median,
        r.corpus.weights_per_second_median / 1e9,
        r.corpus.gp_ops_per_second_median / 1e9
    );
    t += "what each optimisation is worth (median over the corpus of the variant's time / the default kernel's):\n";
    for (name, ratio) in &r.corpus.variant_ratio_median {
        let meaning = if name.starts_with('-') { "without" } else { "with" };
        t += &format!("  {name:<13} {ratio:.3}x  ({meaning} {})\n", name.trim_start_matches(['-', '+']));
    }
    let p = &r.population;
    t += &format!(
        "\npopulation of {} ({} distinct) compiled together: lower+validate {:.0} ms, pipelines {:.0} ms, first evaluation {:.0} ms => {:.2} ms per individual\n",
        p.individuals, p.distinct, p.lower_validate_ms, p.pipelines_ms, p.first_evaluation_ms, p.per_individual_ms
    );
    t += &format!(
        "  trusted modules (no run-time checks, the default) {:.2} ms per individual; with wgpu's checks {:.2} ms ({:.2}x)\n",
        p.per_individual_ms,
        p.checked_per_individual_ms,
        p.checked_per_individual_ms / p.per_individual_ms
    );
    t += &format!(
        "  as evolve scores them (every queue): a kernel per individual {:.2} ms per individual; {} per kernel {:.2} ms ({:.2}x faster; results {})\n",
        p.evolve_single_per_individual_ms,
        p.fused_members,
        p.evolve_fused_per_individual_ms,
        p.evolve_single_per_individual_ms / p.evolve_fused_per_individual_ms,
        if p.fused_identical { "identical" } else { "DIFFER" }
    );
    let c = &r.calibration;
    t += "\ncost model measured here (units: the operators' weights add up to the operator table's; `evolve --cost-model bench.json`):\n ";
    for (name, w) in &r.cost_model.operators {
        t += &format!(" {name} {w:.1}");
    }
    t += &format!(
        "; tap {:.1}\n  rank correlation with the corpus's warm times: operator table {:.3}, measured {:.3}\n",
        r.cost_model.tap, c.table_rank_correlation, c.measured_rank_correlation
    );
    let h = &r.handwritten;
    t += &format!(
        "\nbilateral: hand-written {:.3} ms, generated {:.3} ms ({:.2}x), generated with tiles {:.3} ms ({:.2}x), generated unoptimised {:.3} ms ({:.2}x)\n",
        h.handwritten_ms.median,
        h.generated_ms.median,
        h.ratio,
        h.generated_tiled_ms.median,
        h.tiled_ratio,
        h.generated_plain_ms.median,
        h.plain_ratio
    );
    if !r.simplified.is_empty() {
        t += "\nsimplified against raw (warm dispatch, ms):\n";
        for s in &r.simplified {
            t += &format!(
                "  length {:>3} -> {:>3}: {:.3} -> {:.3} ({:.2}x)\n",
                s.raw_length, s.simplified_length, s.raw_ms.median, s.simplified_ms.median, s.ratio
            );
        }
    }
    if !r.stages.is_empty() {
        t += &format!(
            "\npipeline stages and forms, one {FRAME_SIDE}x{FRAME_SIDE} frame (@crossBilateral; warm median, ms):\n"
        );
        t += &format!(
            "  {:<32} {:>12} {:>12} {:>10} {:>10}\n",
            "stage", "lower+val ms", "compile ms", "warm ms", "ms/Mpx"
        );
        for s in &r.stages {
            t += &format!(
                "  {:<32} {:>12} {:>12.1} {:>10.2} {:>10.1}\n",
                s.stage,
                s.lower_validate_ms.map_or("-".into(), |v| format!("{v:.2}")),
                s.compile_ms,
                s.warm_ms.median,
                s.ms_per_mpx
            );
        }
    }
    if !r.frames.is_empty() {
        t += &format!(
            "\nwhole frames, {FRAME_SIDE}x{FRAME_SIDE} (shipped a-trous filters: wall time of pre-pass, temporal stage, guide and passes in one submission; OIDN: wall time of each execution on the device it chose; warm median [min, max], ms; pre / temporal / guide / passes: the medians of the pre-pass, the temporal stage, the guide and the passes, on the device's clock where it has one; on device: the frame's median on the device's own clock; light: mean luminance over the reference's on the bench scene, noisy {}):\n",
            r.noisy_light.map_or("-".into(), |l| format!("{l:.3}"))
        );
        t += &frames_table(&r.frames);
    }
    if !r.generations.is_empty() {
        t += "\none GP generation (this device) next to the thesis's Table 4.1 (GTX 980 Ti, population 200: another machine)\n";
        t += &format!(
            "{:>8} {:>6} {:>10} {:>10} {:>8} {:>9}   {:>12} {:>12}\n",
            "size", "pop", "compile s", "evaluate s", "gp s", "total s", "thesis GPU s", "thesis CPU s"
        );
        for g in &r.generations {
            let thesis = THESIS_TABLE_4_1.iter().find(|(s, ..)| *s == g.size);
            t += &format!(
                "{:>8} {:>6} {:>10.2} {:>10.2} {:>8.3} {:>9.2}   {:>12} {:>12}\n",
                format!("{0}x{0}", g.size),
                g.population,
                g.compile_s,
                g.evaluate_s,
                g.gp_s,
                g.total_s,
                thesis.map_or("-".into(), |t| format!("{:.3}", t.1)),
                thesis.map_or("-".into(), |t| format!("{:.1}", t.2))
            );
        }
    }
    t
}

/// `bench --frames`' table.
pub fn frames_report(r: &super::FramesReport) -> String {
    format!(
        "device  {}\nframes  {}; each method's frame in one submission (wall ms: recording to completion; pre / temporal / guide / passes on the device's clock where it has one), OIDN's its program's own time; {} rounds\n{}",
        r.device,
        r.source,
        r.repeats * 2,
        frames_table(&r.frames)
    ) + &profiles(&r.frames)
}

/// Where each profiled frame goes, kernel by kernel: its passes a frame,
/// their time on the device's clock and their share of the frame's.
fn profiles(frames: &[super::FrameResult]) -> String {
    let mut t = String::new();
    for f in frames {
        let Some(kernels) = &f.profile else { continue };
        let total: f64 = kernels.iter().map(|k| k.device_ms).sum();
        t += &format!(
            "\nprofile {} {}x{}: each kernel's passes and copies a frame, on the device's clock (median of {} frames): {:.3} ms{}\n",
            f.method,
            f.width,
            f.height,
            super::PROFILED_FRAMES,
            total,
            f.device_ms.map_or(String::new(), |d| format!(" of the frame's {d:.3} ms (the rest: wgpu's clears of new images, and gaps)"))
        );
        let width = kernels.iter().map(|k| k.kernel.chars().count()).max().unwrap_or(0).max("kernel".len());
        t += &format!("  {:<width$} {:>10} {:>10} {:>7}\n", "kernel", "dispatches", "ms", "share");
        for k in kernels {
            t += &format!(
                "  {:<width$} {:>10} {:>10.3} {:>6.1}%\n",
                k.kernel,
                k.dispatches,
                k.device_ms,
                100.0 * k.device_ms / total.max(f64::MIN_POSITIVE)
            );
        }
    }
    t
}

/// Whole frames as a table: one row a method and size.
pub fn frames_table(frames: &[super::FrameResult]) -> String {
    let mut t = String::new();
    let pipeline_width = frames.iter().map(|f| f.pipeline.len()).max().unwrap_or(0).max("pipeline".len());
    t += &format!(
        "  {:<34} {:>9} {:<pipeline_width$} {:>10} {:>22} {:>28} {:>9} {:>10} {:>8} {:>7}\n",
        "method",
        "size",
        "pipeline",
        "compile ms",
        "warm ms",
        "pre / temporal / guide / passes",
        "on device",
        "ms/Mpx",
        "/ OIDN",
        "light"
    );
    for f in frames {
        t += &format!(
            "  {:<34} {:>9} {:<pipeline_width$} {:>10} {:>22} {:>28} {:>9} {:>10.1} {:>8} {:>7}\n",
            f.method,
            format!("{}x{}", f.width, f.height),
            f.pipeline,
            f.compile_ms.map_or("-".into(), |v| format!("{v:.1}")),
            format!("{:.2} [{:.2}, {:.2}]", f.warm_ms.median, f.warm_ms.min, f.warm_ms.max),
            f.parts_ms.map_or("-".into(), |p| format!(
                "{:.1} / {:.1} / {:.1} / {:.1}",
                p.prepass, p.temporal, p.guide, p.passes
            )),
            f.device_ms.map_or("-".into(), |d| format!("{d:.3}")),
            f.ms_per_mpx,
            f.over_oidn.map_or("-".into(), |v| format!("{v:.2}x")),
            f.light.map_or("-".into(), |v| format!("{v:.3}")),
        );
    }
    t
}
