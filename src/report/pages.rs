//! The report's pages from its measurements: `results.json`, `.csv`, `.md`,
//! the SVG plots and `index.html`. Markdown and HTML come from tera templates
//! (`templates/report.*.tera`; the HTML one autoescaped) over one [`Page`],
//! in which every figure is already formatted.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::{Context, Result};
use serde::Serialize;

use super::{plot, Cell, Results, NOISY};
use crate::{io, metrics};

/// A scene's or method's name as a file name.
pub(super) fn file_name(name: &str) -> String {
    name.chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' || c == '_' { c } else { '_' }).collect()
}

fn fmt(value: Option<f64>, digits: usize) -> String {
    match value {
        Some(v) if v.abs() >= 1e4 || (v != 0.0 && v.abs() < 1e-3) => format!("{v:.digits$e}", digits = digits.min(3)),
        Some(v) => format!("{v:.digits$}"),
        None => "—".into(),
    }
}

/// What the Markdown and HTML templates show.
#[derive(Serialize)]
struct Page<'a> {
    generator: &'a str,
    device: &'a str,
    radius: u32,
    repeats: usize,
    baseline: Option<BaselineRow>,
    methods: Vec<MethodRow>,
    scenes: Vec<ScenePage>,
    feature_usage: bool,
    expressions: Vec<ExpressionItem>,
    /// Each method and scene whose light is off by more than [`metrics::LIGHT_TOLERANCE`].
    light_flags: Vec<String>,
    light_tolerance: String,
}

#[derive(Serialize)]
struct BaselineRow {
    scenes: String,
    evaluated: usize,
    sigmas: Vec<(String, String)>,
    fitness: String,
    hand_set_fitness: String,
}

#[derive(Serialize)]
struct MethodRow {
    name: String,
    normalised: String,
    relmse: String,
    vs_peer: String,
    flip: String,
    /// Mean light ratio over the scenes, and the scene furthest from 1.
    light: String,
    worst_light: String,
    ms_per_mpx: String,
    scenes_run: usize,
    length: String,
}

#[derive(Serialize)]
struct ScenePage {
    name: String,
    file: String,
    path: String,
    width: usize,
    height: usize,
    spp: String,
    crop_x: usize,
    crop_y: usize,
    crop_side: usize,
    /// The viewer's width in CSS pixels (small renders enlarged), and the
    /// crop's box in it, in percent of the frame: left, top, width, height.
    view_width: usize,
    crop_box: [String; 4],
    cells: Vec<CellRow>,
    /// The crops shown, in the strip's order: every method that ran, then the reference.
    crops: Vec<CropItem>,
}

#[derive(Serialize)]
struct CellRow {
    method: String,
    unavailable: Option<String>,
    relmse: String,
    relmse_half_spp: String,
    mse: String,
    flip: String,
    /// The light ratio, marked where it is off by more than [`metrics::LIGHT_TOLERANCE`].
    light: String,
    normalised: String,
    vs_peer: String,
    ms_per_mpx: String,
    /// ` (fastest–slowest)`, or empty.
    ms_range: String,
    flagged_pixels: usize,
}

/// The viewer shows a frame narrower than this at a whole multiple of its size.
const VIEW_WIDTH: usize = 768;

#[derive(Serialize)]
struct CropItem {
    name: String,
    file: String,
}

#[derive(Serialize)]
struct ExpressionItem {
    name: String,
    origin: String,
    length: usize,
    pipeline: String,
    expr: String,
}

impl<'a> Page<'a> {
    fn of(results: &'a Results) -> Page<'a> {
        let dash = || "—".to_string();
        Page {
            generator: &results.generator,
            device: &results.device,
            radius: results.radius,
            repeats: results.repeats,
            baseline: results.baseline.as_ref().map(|b| BaselineRow {
                scenes: b.scenes.join(", "),
                evaluated: b.evaluated,
                sigmas: b.sigmas.0.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect(),
                fitness: format!("{:.4}", b.fitness),
                hand_set_fitness: format!("{:.4}", b.hand_set_fitness),
            }),
            methods: results
                .methods
                .iter()
                .map(|m| MethodRow {
                    name: match &m.ran_instead {
                        Some(v) => format!("{} (as {} on {} of its scenes: sparse light)", m.name, v.name, v.scenes),
                        None => m.name.clone(),
                    },
                    normalised: fmt(m.mean_normalised, 4),
                    relmse: fmt(m.mean_relmse, 4),
                    vs_peer: fmt(m.mean_vs_peer, 2),
                    flip: fmt(m.mean_flip, 4),
                    light: fmt(m.mean_light, 3),
                    worst_light: m.worst_light.as_ref().map_or_else(dash, |(scene, light)| {
                        format!("{}{} ({scene})", fmt(Some(*light), 3), off(*light))
                    }),
                    ms_per_mpx: fmt(m.mean_ms_per_mpx, 1),
                    scenes_run: m.scenes_run,
                    length: m.length.map_or_else(dash, |l| l.to_string()),
                })
                .collect(),
            scenes: results
                .scenes
                .iter()
                .map(|s| {
                    let cells: Vec<&Cell> = results.cells.iter().filter(|c| c.scene == s.name).collect();
                    ScenePage {
                        name: s.name.clone(),
                        file: file_name(&s.name),
                        path: s.path.clone(),
                        width: s.width,
                        height: s.height,
                        spp: s.spp.map_or_else(|| "?".into(), |m| m.to_string()),
                        crop_x: s.crop[0],
                        crop_y: s.crop[1],
                        crop_side: s.crop[2],
                        view_width: s.width * (VIEW_WIDTH / s.width).max(1),
                        crop_box: [
                            (s.crop[0], s.width),
                            (s.crop[1], s.height),
                            (s.crop[2], s.width),
                            (s.crop[2], s.height),
                        ]
                        .map(|(v, of)| format!("{:.3}", 100.0 * v as f64 / of as f64)),
                        crops: cells
                            .iter()
                            .filter(|c| c.unavailable.is_none())
                            .map(|c| c.method.as_str())
                            .chain(["reference"])
                            .map(|name| CropItem { name: name.to_string(), file: file_name(name) })
                            .collect(),
                        cells: cells
                            .iter()
                            .map(|c| CellRow {
                                method: match &c.ran_instead {
                                    Some(variant) => format!("{} (as {variant}: sparse light)", c.method),
                                    None => c.method.clone(),
                                },
                                unavailable: c.unavailable.clone(),
                                relmse: fmt(c.relmse, 5),
                                relmse_half_spp: fmt(c.relmse_half_spp, 5),
                                mse: fmt(c.mse, 5),
                                flip: fmt(c.flip, 4),
                                light: format!("{}{}", fmt(c.light, 3), c.light.map(off).unwrap_or_default()),
                                normalised: fmt(c.normalised, 4),
                                vs_peer: fmt(c.vs_peer, 2),
                                ms_per_mpx: fmt(c.ms_per_mpx, 1),
                                ms_range: c
                                    .ms_per_mpx_range
                                    .map(|(a, b)| format!(" ({a:.1}–{b:.1})"))
                                    .unwrap_or_default(),
                                flagged_pixels: c.flagged_pixels,
                            })
                            .collect(),
                    }
                })
                .collect(),
            feature_usage: results.feature_usage.is_some(),
            light_flags: results
                .cells
                .iter()
                .filter_map(|c| Some((c, c.light?)))
                .filter(|(_, light)| !off(*light).is_empty())
                .map(|(c, light)| {
                    let change = (light - 1.0) * 100.0;
                    let method = match &c.ran_instead {
                        Some(variant) => format!("{} (as {variant})", c.method),
                        None => c.method.clone(),
                    };
                    format!("{method} on {}: {light:.3} of the reference's mean luminance ({change:+.1} %)", c.scene)
                })
                .collect(),
            light_tolerance: format!("{:.0} %", metrics::LIGHT_TOLERANCE * 100.0),
            expressions: results
                .methods
                .iter()
                .flat_map(|m| {
                    let own = m.expr.clone().map(|expr| ExpressionItem {
                        name: m.name.clone(),
                        origin: format!("{:?}", m.origin),
                        length: m.length.unwrap_or(0),
                        pipeline: m.pipeline.clone().unwrap_or_else(|| "window".into()),
                        expr,
                    });
                    // What ran in its place where the light was sparse: listed under it.
                    let variant = m.ran_instead.as_ref().map(|v| ExpressionItem {
                        name: format!("{} (in {}'s place where the light is sparse)", v.name, m.name),
                        origin: format!("{:?}", m.origin),
                        length: v.length,
                        pipeline: v.pipeline.clone(),
                        expr: v.expr.clone(),
                    });
                    own.into_iter().chain(variant)
                })
                .collect(),
        }
    }
}

/// The two page templates; the `.html` one is autoescaped (tera's default for that extension).
fn templates() -> &'static tera::Tera {
    static TERA: std::sync::OnceLock<tera::Tera> = std::sync::OnceLock::new();
    TERA.get_or_init(|| {
        let mut tera = tera::Tera::default();
        tera.add_raw_templates([
            ("report.html", include_str!("../../templates/report.html.tera")),
            ("report.md", include_str!("../../templates/report.md.tera")),
        ])
        .expect("the report templates parse");
        tera
    })
}

fn page(template: &str, results: &Results) -> Result<String> {
    let context = tera::Context::from_serialize(Page::of(results))?;
    templates().render(template, &context).with_context(|| format!("rendering {template}"))
}

/// Every page of the report into `output`.
pub(super) fn write(results: &Results, output: &Path) -> Result<()> {
    let put = |name: &str, bytes: &[u8]| -> Result<()> {
        let path = output.join(name);
        if let Some(dir) = path.parent() {
            std::fs::create_dir_all(dir)?;
        }
        io::write_bytes_atomically(&path, bytes)
            .map_err(anyhow::Error::from)
            .with_context(|| format!("writing {}", path.display()))
    };
    put("results.json", (serde_json::to_string_pretty(results)? + "\n").as_bytes())?;
    put("results.csv", csv(results).as_bytes())?;
    put("results.md", page("report.md", results)?.as_bytes())?;
    for (file, svg) in plots(results) {
        put(&file, svg.as_bytes())?;
    }
    if let Some(usage) = &results.feature_usage {
        let items: Vec<(String, usize)> = usage.iter().map(|(k, v)| (k.clone(), *v)).collect();
        put("features.svg", plot::bars("Feature usage in the hall of fame", &items).as_bytes())?;
    }
    put("index.html", page("report.html", results)?.as_bytes())?;
    Ok(())
}

/// The mark after a light ratio that changes the image's light by more than
/// [`metrics::LIGHT_TOLERANCE`]; empty otherwise.
fn off(light: f64) -> &'static str {
    if (light - 1.0).abs() > metrics::LIGHT_TOLERANCE {
        " ⚠"
    } else {
        ""
    }
}

fn csv(results: &Results) -> String {
    let mut out = String::from("scene,method,relmse,relmse_half_spp,mse,hdr_flip,light,normalised,relmse_vs_oidn,ms_per_mpx,ms_per_mpx_min,ms_per_mpx_max,flagged_pixels,unavailable,ran_instead\n");
    let opt = |v: Option<f64>| v.map(|v| format!("{v:e}")).unwrap_or_default();
    for c in &results.cells {
        let _ = writeln!(
            out,
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
            c.scene,
            c.method,
            opt(c.relmse),
            opt(c.relmse_half_spp),
            opt(c.mse),
            opt(c.flip),
            opt(c.light),
            opt(c.normalised),
            opt(c.vs_peer),
            opt(c.ms_per_mpx),
            opt(c.ms_per_mpx_range.map(|r| r.0)),
            opt(c.ms_per_mpx_range.map(|r| r.1)),
            c.flagged_pixels,
            c.unavailable.as_deref().unwrap_or("").replace(',', ";"),
            c.ran_instead.as_deref().unwrap_or("")
        );
    }
    out
}

/// `(file, svg)`: the averaged scatter and one per scene.
fn plots(results: &Results) -> Vec<(String, String)> {
    let mut out = Vec::new();
    let mean_points: Vec<plot::Point> = results
        .methods
        .iter()
        .filter_map(|m| {
            Some(plot::Point { label: m.name.clone(), time: m.mean_ms_per_mpx?, error: m.mean_normalised? })
        })
        .collect();
    out.push((
        "plots/mean.svg".to_string(),
        plot::scatter(
            &format!("Mean over {} scenes: time against error", results.scenes.len()),
            "relMSE / noisy relMSE",
            &mean_points,
            Some(("noisy input", 1.0)),
        ),
    ));
    for s in &results.scenes {
        let cells: Vec<&Cell> = results.cells.iter().filter(|c| c.scene == s.name).collect();
        let points: Vec<plot::Point> = cells
            .iter()
            .filter_map(|c| Some(plot::Point { label: c.method.clone(), time: c.ms_per_mpx?, error: c.relmse? }))
            .collect();
        let noisy = cells.iter().find(|c| c.method == NOISY).and_then(|c| c.relmse);
        out.push((
            format!("plots/{}.svg", file_name(&s.name)),
            plot::scatter(
                &format!("{}: time against error", s.name),
                "relMSE",
                &points,
                noisy.map(|n| ("noisy input", n)),
            ),
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::report::{Origin, SceneInfo};

    #[test]
    fn the_html_page_escapes_what_it_shows_and_the_markdown_does_not() {
        let results = Results {
            generator: "filterjit".into(),
            device: "a <fast> & cheap device".into(),
            radius: 3,
            repeats: 1,
            scenes: vec![SceneInfo {
                name: "s".into(),
                path: "/data/<s>".into(),
                width: 8,
                height: 8,
                spp: Some(4),
                crop: [0, 0, 8],
            }],
            methods: vec![crate::report::MethodInfo {
                name: NOISY.into(),
                origin: Origin::Noisy,
                expr: None,
                length: None,
                pipeline: None,
                mean_relmse: Some(0.5),
                mean_flip: None,
                mean_light: None,
                worst_light: None,
                mean_normalised: Some(1.0),
                mean_vs_peer: None,
                mean_ms_per_mpx: None,
                scenes_run: 1,
                ran_instead: None,
            }],
            cells: vec![Cell {
                scene: "s".into(),
                method: NOISY.into(),
                relmse: Some(0.5),
                unavailable: None,
                ..Default::default()
            }],
            baseline: None,
            feature_usage: None,
        };
        let html = page("report.html", &results).unwrap();
        assert!(html.contains("a &lt;fast&gt; &amp; cheap device") && !html.contains("<fast>"), "{html}");
        assert!(html.contains("&lt;s&gt;") && html.contains("<td>noisy</td><td>0.50000</td>"), "{html}");
        let md = page("report.md", &results).unwrap();
        assert!(md.contains("a <fast> & cheap device") && md.contains("| noisy | 0.50000 |"), "{md}");
    }

    /// The light column and its flags, on a known answer: a method at 0.90
    /// of the reference's light is flagged, one at 0.99 is not.
    #[test]
    fn methods_that_change_the_light_are_flagged() {
        let cell = |method: &str, light: f64| Cell {
            scene: "room".into(),
            method: method.into(),
            relmse: Some(0.1),
            light: Some(light),
            ..Default::default()
        };
        let method = |name: &str, light: f64| crate::report::MethodInfo {
            name: name.into(),
            origin: Origin::Given,
            expr: None,
            length: None,
            pipeline: None,
            mean_relmse: Some(0.1),
            mean_flip: None,
            mean_light: Some(light),
            worst_light: Some(("room".into(), light)),
            mean_normalised: None,
            mean_vs_peer: None,
            mean_ms_per_mpx: None,
            scenes_run: 1,
            ran_instead: None,
        };
        let results = Results {
            generator: "filterjit".into(),
            device: "d".into(),
            radius: 3,
            repeats: 1,
            scenes: vec![SceneInfo {
                name: "room".into(),
                path: "room".into(),
                width: 8,
                height: 8,
                spp: Some(4),
                crop: [0, 0, 8],
            }],
            methods: vec![method("dark", 0.9), method("fine", 0.99)],
            cells: vec![cell("dark", 0.9), cell("fine", 0.99)],
            baseline: None,
            feature_usage: None,
        };
        let md = page("report.md", &results).unwrap();
        assert!(md.contains("* dark on room: 0.900 of the reference's mean luminance (-10.0 %)"), "{md}");
        assert!(!md.contains("fine on room"), "{md}");
        assert!(md.contains("| 0.900 ⚠ |") && md.contains("| 0.900 ⚠ (room) |"), "{md}");
        assert!(md.contains("| 0.990 |") && md.contains("| 0.990 (room) |"), "{md}");
        let html = page("report.html", &results).unwrap();
        assert!(html.contains("<li>dark on room: 0.900"), "{html}");
        assert!(csv(&results).lines().nth(1).unwrap().contains(",9e-1,"), "{}", csv(&results));
    }
}
