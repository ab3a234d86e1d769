//! insta snapshots of the generated WGSL: one per corpus expression.
//! CI never updates them (INSTA_UPDATE=no); review changes with `cargo insta review`.

use filterjit::{corpus, jit, parse_expr};

const CORPUS: &str = include_str!("data/corpus.txt");

fn settings() -> insta::Settings {
    let mut settings = insta::Settings::clone_current();
    settings.set_snapshot_path(concat!(env!("CARGO_MANIFEST_DIR"), "/snapshots"));
    settings.set_prepend_module_to_snapshot(false);
    settings.set_omit_expression(true);
    settings
}

#[test]
fn generated_wgsl_matches_snapshots() {
    let mut cases = corpus::named();
    cases.extend(crate::common::named_entries(CORPUS));
    assert!(cases.len() >= 15);
    settings().bind(|| {
        for (name, text) in cases {
            let expr = parse_expr(text).unwrap_or_else(|e| panic!("{name}:\n{e}"));
            let kernel = jit::compile(&expr, jit::KernelSpec::default()).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert!(kernel.wgsl().contains(&format!("// expression: {expr}")), "the header names the expression");
            insta::assert_snapshot!(format!("wgsl__{name}"), kernel.wgsl());
        }
    });
}

/// The pipeline's kernels: the pre-pass and spread modules (filterjit's and
/// exported), and `@crossBilateralAtrous`
/// as an à-trous pass (carrying the variance of an expression that reads it)
/// in filter and fitness kernels, and as a pass of the 3x3 stencil.
#[test]
fn pipeline_kernels_match_snapshots() {
    use filterjit::jit::{KernelKind, LowerOptions};
    let pipeline = corpus::resolve_with_pipeline("@crossBilateralAtrous").unwrap();
    let shape = jit::Shape::of(&pipeline.pipeline.expect("shipped with its pipeline"));
    assert!(shape.atrous && shape.remodulate);
    let carrying = parse_expr("exp(-(distance2(color) / (0.02 + colorVariance) + level * distance2(normal)))").unwrap();
    // Reads the guide image in the first pass only, the pass's colour after.
    let guided = parse_expr("exp(-(distance2(guide) + distance2(normal)))").unwrap();
    settings().bind(|| {
        insta::assert_snapshot!("pipeline__prepass", jit::prepass_wgsl(None));
        insta::assert_snapshot!("export__prepass", jit::prepass_wgsl(Some(jit::OutputFormat::Rgba32float)));
        insta::assert_snapshot!("pipeline__spread", jit::spread_wgsl(None));
        insta::assert_snapshot!("export__spread", jit::spread_wgsl(Some(jit::OutputFormat::Rgba32float)));
        insta::assert_snapshot!("pipeline__spread_surface", jit::spread_surface_wgsl(None));
        insta::assert_snapshot!(
            "export__spread_surface",
            jit::spread_surface_wgsl(Some(jit::OutputFormat::Rgba32float))
        );
        insta::assert_snapshot!("pipeline__planefit", jit::planefit_wgsl(None));
        insta::assert_snapshot!("pipeline__planefit_terms", jit::planefit_terms_wgsl());
        insta::assert_snapshot!("export__planefit", jit::planefit_wgsl(Some(jit::OutputFormat::Rgba32float)));
        insta::assert_snapshot!("pipeline__pixelfilter", jit::pixel_filter_wgsl(None));
        insta::assert_snapshot!("export__pixelfilter", jit::pixel_filter_wgsl(Some(jit::OutputFormat::Rgba16float)));
        insta::assert_snapshot!("pipeline__anchor", jit::anchor_wgsl(None));
        insta::assert_snapshot!("export__anchor", jit::anchor_wgsl(Some(jit::OutputFormat::Rgba16float)));
        insta::assert_snapshot!("pipeline__temporal", jit::temporal_wgsl(None));
        insta::assert_snapshot!("export__temporal", jit::temporal_wgsl(Some(jit::OutputFormat::Rgba32float)));
        // An à-trous pass carrying the temporal stage's variance from pass to pass (SVGF's rule).
        let svgf = corpus::resolve_with_pipeline("@svgf").unwrap();
        let temporal_shape = jit::Shape::of(&svgf.pipeline.expect("shipped with its pipeline"));
        let kernel =
            jit::compile(&svgf.expr, jit::KernelSpec { shape: temporal_shape, ..jit::KernelSpec::default() }).unwrap();
        assert!(kernel.wgsl().contains("buf_variance_out"), "the temporal variance is carried");
        insta::assert_snapshot!("pipeline__svgf.atrous.filter", kernel.wgsl());
        for (name, expr) in [("crossBilateralAtrous", &pipeline.expr), ("carrying", &carrying), ("guided", &guided)] {
            for (kind, label) in [(KernelKind::Filter, "filter"), (KernelKind::Fitness, "fitness")] {
                let kernel = jit::compile(expr, jit::KernelSpec { kind, options: LowerOptions::ALL, shape }).unwrap();
                insta::assert_snapshot!(format!("pipeline__{name}.atrous.{label}"), kernel.wgsl());
            }
        }
        // The 3x3 stencil's pass: the same kernel but for its taps and their weights.
        let linear: filterjit::pipeline::FilterPipeline = "outliers=2,demodulate,atrous3x3=4".parse().unwrap();
        let kernel = jit::compile(
            &pipeline.expr,
            jit::KernelSpec { shape: jit::Shape::of(&linear), ..jit::KernelSpec::default() },
        )
        .unwrap();
        insta::assert_snapshot!("pipeline__crossBilateralAtrous.atrous3x3.filter", kernel.wgsl());
    });
}

/// The fitness kernels evolve compiles: one individual's, three fused into
/// one kernel (the default on software adapters), and the reduction kernel
/// both feed.
#[test]
fn fitness_kernels_match_snapshots() {
    use filterjit::jit::{KernelKind, LowerOptions, Shape};
    let domains =
        crate::common::named_entries(CORPUS).into_iter().find(|(n, _)| *n == "domains").expect("in the corpus").1;
    let members: Vec<_> = [corpus::lookup("thesis1").unwrap(), corpus::lookup("bilateral").unwrap(), domains]
        .iter()
        .map(|text| parse_expr(text).unwrap())
        .collect();
    settings().bind(|| {
        let single = jit::compile(
            &members[0],
            jit::KernelSpec { kind: KernelKind::Fitness, options: LowerOptions::ALL, shape: Shape::WINDOW },
        )
        .unwrap();
        insta::assert_snapshot!("fitness__thesis1", single.wgsl());
        let fused = jit::compile_fused(
            &members,
            jit::KernelSpec { kind: jit::KernelKind::Fitness, options: LowerOptions::ALL, shape: Shape::WINDOW },
        )
        .unwrap();
        insta::assert_snapshot!("fitness__fused3", fused.wgsl());
        insta::assert_snapshot!("fitness__reduce", jit::reduce_wgsl());
    });
}

/// The exported shader of the thesis's first expression in every text target,
/// and its manifest: what an engine developer copies out.
#[test]
fn exported_shaders_match_snapshots() {
    use filterjit::export::{export, Code, Target};
    let expr = parse_expr(corpus::lookup("thesis1").unwrap()).unwrap();
    settings().bind(|| {
        for target in [Target::Wgsl, Target::Glsl, Target::Hlsl, Target::Msl] {
            let exported = export(&expr, target, jit::OutputFormat::Rgba16float).unwrap();
            let Code::Text(text) = exported.code else { panic!("{target:?} is text") };
            insta::assert_snapshot!(format!("export__thesis1.{}", target.extension()), text);
        }
        let manifest = export(&expr, Target::Wgsl, jit::OutputFormat::Rgba16float).unwrap().manifest;
        insta::assert_snapshot!("export__thesis1.wgsl.json", serde_json::to_string_pretty(&manifest).unwrap());
        // A whole pipeline: an à-trous pass that carries the variance and remodulates, and its manifest.
        let carrying =
            parse_expr("exp(-(distance2(color) / (0.02 + colorVariance) + level * distance2(normal)))").unwrap();
        let pipeline = "outliers=2,demodulate,atrous=5".parse().unwrap();
        let exported =
            filterjit::export::export_pipeline(&carrying, &pipeline, Target::Wgsl, jit::OutputFormat::Rgba16float)
                .unwrap();
        let Code::Text(text) = exported.code else { panic!("WGSL is text") };
        insta::assert_snapshot!("export__carrying.atrous.wgsl", text);
        insta::assert_snapshot!(
            "export__carrying.atrous.wgsl.json",
            serde_json::to_string_pretty(&exported.manifest).unwrap()
        );
        // A weight that reads the guide: the guide stage's shader and where the manifest puts it.
        let guided = parse_expr("exp(-(distance2(guide) + distance2(normal)))").unwrap();
        let pipeline = "outliers=2,keep,demodulate,atrous3x3=3".parse().unwrap();
        let exported =
            filterjit::export::export_pipeline(&guided, &pipeline, Target::Wgsl, jit::OutputFormat::Rgba16float)
                .unwrap();
        let Code::Text(pass) = &exported.code else { panic!("WGSL is text") };
        insta::assert_snapshot!("export__guided.atrous.wgsl", pass);
        let Some(Code::Text(text)) = exported.stage(filterjit::export::StageName::Guide) else {
            panic!("a WGSL guide stage")
        };
        insta::assert_snapshot!("export__guide.wgsl", text);
        insta::assert_snapshot!(
            "export__guided.atrous.wgsl.json",
            serde_json::to_string_pretty(&exported.manifest).unwrap()
        );
        // The shipped temporal filter: the temporal stage's two shaders, what a sequence keeps.
        let temporal = corpus::resolve_with_pipeline("@temporal").unwrap();
        let pipeline = temporal.pipeline.expect("shipped with its pipeline");
        let exported = filterjit::export::export_filter(
            &temporal.expr,
            &pipeline,
            None,
            Target::Wgsl,
            jit::OutputFormat::Rgba16float,
        )
        .unwrap();
        let Code::Text(pass) = &exported.code else { panic!("WGSL is text") };
        insta::assert_snapshot!("export__temporal.atrous.wgsl", pass);
        insta::assert_snapshot!(
            "export__temporal.atrous.wgsl.json",
            serde_json::to_string_pretty(&exported.manifest).unwrap()
        );
    });
}

/// Every corpus expression and the bench's bloated ones next to their
/// simplified forms and the simplified kernels' WGSL.
#[test]
fn simplified_corpus_matches_snapshots() {
    let mut cases = corpus::named();
    cases.extend(crate::common::named_entries(CORPUS));
    let bloated: Vec<(String, &str)> =
        filterjit::bench::BLOATED.iter().enumerate().map(|(k, t)| (format!("bloated{}", k + 1), *t)).collect();
    let mut table = String::new();
    settings().bind(|| {
        for (name, text) in cases.iter().map(|(n, t)| (n.to_string(), *t)).chain(bloated.iter().cloned()) {
            let expr = parse_expr(text).unwrap();
            let simplified = filterjit::simplify::simplify(&expr);
            table += &format!("{name} ({} -> {} nodes)\n  {expr}\n  {simplified}\n", expr.len(), simplified.len());
            if name.starts_with("bloated") {
                insta::assert_snapshot!(
                    format!("simplified__{name}"),
                    jit::compile(&simplified, jit::KernelSpec::default()).unwrap().wgsl()
                );
            }
        }
        insta::assert_snapshot!("simplified__corpus", table);
    });
}
