//! The report's pictures as SVG text: a log-log scatter of time against
//! error with the Pareto front, and a horizontal bar chart. Hand-written SVG
//! is a few lines of text per mark and opens in every browser.

use std::fmt::Write;

/// One method in a scatter plot.
#[derive(Clone, Debug)]
pub struct Point {
    pub label: String,
    /// Milliseconds per megapixel.
    pub time: f64,
    pub error: f64,
}

/// For each point, whether no other point is at least as fast and at least
/// as accurate, and strictly better in one of the two.
pub fn pareto_front(points: &[Point]) -> Vec<bool> {
    points
        .iter()
        .map(|p| {
            !points.iter().any(|q| q.time <= p.time && q.error <= p.error && (q.time < p.time || q.error < p.error))
        })
        .collect()
}

const WIDTH: f64 = 700.0;
const HEIGHT: f64 = 420.0;
const LEFT: f64 = 70.0;
const RIGHT: f64 = 190.0;
const TOP: f64 = 36.0;
const BOTTOM: f64 = 50.0;

fn escape(text: &str) -> String {
    text.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;")
}

/// An empty plot of the common size: white, its title at the top left.
fn canvas(title: &str) -> String {
    let mut svg = String::new();
    let _ = writeln!(
        svg,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{WIDTH}" height="{HEIGHT}" viewBox="0 0 {WIDTH} {HEIGHT}" font-family="sans-serif" font-size="12">"#
    );
    let _ = writeln!(svg, r#"<rect width="100%" height="100%" fill="white"/>"#);
    let _ = writeln!(svg, r#"<text x="{}" y="20" font-size="14" font-weight="bold">{}</text>"#, LEFT, escape(title));
    svg
}

/// The y axis's decades (`range`, log10) as grid lines with labels; `y` maps a value to its row.
fn log_y_ticks(svg: &mut String, range: (f64, f64), y: &dyn Fn(f64) -> f64) {
    for v in ticks(range) {
        let py = y(v);
        let _ = writeln!(
            svg,
            r##"<line x1="{LEFT}" y1="{py:.1}" x2="{:.1}" y2="{py:.1}" stroke="#ddd"/><text x="{:.1}" y="{:.1}" text-anchor="end">{}</text>"##,
            WIDTH - RIGHT,
            LEFT - 6.0,
            py + 4.0,
            tick_label(v)
        );
    }
}

/// The plot area's frame and the two axes' names (the y axis logarithmic).
fn axes(svg: &mut String, x_label: &str, y_label: &str) {
    let (plot_w, plot_h) = (WIDTH - LEFT - RIGHT, HEIGHT - TOP - BOTTOM);
    let _ =
        writeln!(svg, r##"<rect x="{LEFT}" y="{TOP}" width="{plot_w}" height="{plot_h}" fill="none" stroke="#444"/>"##);
    let _ = writeln!(
        svg,
        r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">{}</text>"#,
        LEFT + plot_w / 2.0,
        HEIGHT - 10.0,
        escape(x_label)
    );
    let _ = writeln!(
        svg,
        r#"<text transform="translate(16 {:.1}) rotate(-90)" text-anchor="middle">{} (log)</text>"#,
        TOP + plot_h / 2.0,
        escape(y_label)
    );
}

/// A log axis covering `values` (log10 of its ends), padded by a tenth of
/// the span on each side, at least a factor of 2 wide.
fn log_range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite() && *v > 0.0)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)));
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    let (lo, hi) = (lo.log10(), hi.log10());
    let span = (hi - lo).max(2f64.log10());
    let mid = (lo + hi) / 2.0;
    (mid - span * 0.6, mid + span * 0.6)
}

/// Tick values inside a log range: 1, 2, 5 times powers of ten, or only
/// the powers when the range spans many decades.
fn ticks((lo, hi): (f64, f64)) -> Vec<f64> {
    let steps: &[f64] = if hi - lo > 3.0 { &[1.0] } else { &[1.0, 2.0, 5.0] };
    let mut out = Vec::new();
    for d in (lo.floor() as i32)..=(hi.ceil() as i32) {
        for s in steps {
            let v = s * 10f64.powi(d);
            if (lo..=hi).contains(&v.log10()) {
                out.push(v);
            }
        }
    }
    out
}

fn tick_label(v: f64) -> String {
    if (1e-3..1e5).contains(&v) {
        let text = format!("{v:.3}");
        text.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        format!("{v:.0e}")
    }
}

/// Time per megapixel (x, log) against error (y, log); the front joined by a
/// step line and drawn filled; `baseline` a dashed horizontal line (the noisy input).
pub fn scatter(title: &str, y_label: &str, points: &[Point], baseline: Option<(&str, f64)>) -> String {
    let (x0, x1) = log_range(points.iter().map(|p| p.time));
    let (y0, y1) = log_range(points.iter().map(|p| p.error).chain(baseline.map(|b| b.1)));
    let plot_w = WIDTH - LEFT - RIGHT;
    let plot_h = HEIGHT - TOP - BOTTOM;
    let x = |v: f64| LEFT + (v.max(1e-300).log10() - x0) / (x1 - x0) * plot_w;
    let y = |v: f64| TOP + (1.0 - (v.max(1e-300).log10() - y0) / (y1 - y0)) * plot_h;
    let mut svg = canvas(title);
    for v in ticks((x0, x1)) {
        let px = x(v);
        let _ = writeln!(
            svg,
            r##"<line x1="{px:.1}" y1="{TOP}" x2="{px:.1}" y2="{:.1}" stroke="#ddd"/><text x="{px:.1}" y="{:.1}" text-anchor="middle">{}</text>"##,
            TOP + plot_h,
            TOP + plot_h + 16.0,
            tick_label(v)
        );
    }
    log_y_ticks(&mut svg, (y0, y1), &y);
    axes(&mut svg, "filter time, ms per megapixel (log)", y_label);
    if let Some((label, value)) = baseline {
        let py = y(value);
        let _ = writeln!(
            svg,
            r##"<line x1="{LEFT}" y1="{py:.1}" x2="{:.1}" y2="{py:.1}" stroke="#999" stroke-dasharray="5 4"/><text x="{:.1}" y="{:.1}" fill="#666">{}</text>"##,
            LEFT + plot_w,
            LEFT + 6.0,
            py - 4.0,
            escape(label)
        );
    }
    // The front as a staircase from the fastest to the most accurate.
    let front = pareto_front(points);
    let mut on_front: Vec<&Point> = points.iter().zip(&front).filter(|(_, f)| **f).map(|(p, _)| p).collect();
    on_front.sort_by(|a, b| a.time.total_cmp(&b.time));
    if !on_front.is_empty() {
        let mut path = format!("M {:.1} {:.1}", x(on_front[0].time), y(on_front[0].error));
        for pair in on_front.windows(2) {
            let _ = write!(path, " H {:.1} V {:.1}", x(pair[1].time), y(pair[1].error));
        }
        let _ = writeln!(svg, r##"<path d="{path}" fill="none" stroke="#c0392b" stroke-width="1.5"/>"##);
    }
    // Labels in the right margin, top to bottom in the order of the points'
    // heights, at least a line apart, each joined to its point by a thin line.
    let mut order: Vec<usize> = (0..points.len()).collect();
    order.sort_by(|a, b| y(points[*a].error).total_cmp(&y(points[*b].error)));
    let line = 14.0;
    let mut label_y = vec![0.0; points.len()];
    let mut next = TOP + 30.0;
    for &k in &order {
        label_y[k] = y(points[k].error).max(next);
        next = label_y[k] + line;
    }
    // Pull the stack back up if it ran past the bottom.
    let overflow = (next - line - (TOP + plot_h)).max(0.0);
    for k in &order {
        label_y[*k] -= overflow;
    }
    for (k, (p, is_front)) in points.iter().zip(&front).enumerate() {
        let (px, py) = (x(p.time), y(p.error));
        let (fill, stroke) = if *is_front { ("#c0392b", "#c0392b") } else { ("white", "#2c3e50") };
        let lx = LEFT + plot_w + 8.0;
        let _ = writeln!(
            svg,
            r##"<line x1="{:.1}" y1="{py:.1}" x2="{:.1}" y2="{:.1}" stroke="#bbb" stroke-width="0.7"/><circle cx="{px:.1}" cy="{py:.1}" r="5" fill="{fill}" stroke="{stroke}" stroke-width="1.5"><title>{}: {:.4} at {:.1} ms/Mpx</title></circle><text x="{:.1}" y="{:.1}" fill="{stroke}">{}</text>"##,
            px + 5.0,
            lx - 2.0,
            label_y[k] - 4.0,
            escape(&p.label),
            p.error,
            p.time,
            lx,
            label_y[k],
            escape(&p.label)
        );
    }
    let _ = writeln!(
        svg,
        r##"<text x="{:.1}" y="{:.1}" fill="#c0392b">● Pareto front</text>"##,
        LEFT + plot_w + 8.0,
        TOP + 8.0
    );
    svg.push_str("</svg>\n");
    svg
}

/// The colours of `lines`' series, in order (then again).
const SERIES_COLOURS: [&str; 6] = ["#7f8c8d", "#c0392b", "#2980b9", "#27ae60", "#8e44ad", "#d35400"];

/// A line per series over the same x labels (a sequence's frames), the y
/// axis logarithmic; a series' missing values break its line.
pub fn lines(title: &str, y_label: &str, x_labels: &[String], series: &[(String, Vec<Option<f64>>)]) -> String {
    let (y0, y1) = log_range(series.iter().flat_map(|(_, values)| values.iter().flatten().copied()));
    let plot_w = WIDTH - LEFT - RIGHT;
    let plot_h = HEIGHT - TOP - BOTTOM;
    let steps = x_labels.len().saturating_sub(1).max(1) as f64;
    let x = |k: usize| LEFT + k as f64 / steps * plot_w;
    let y = |v: f64| TOP + (1.0 - (v.max(1e-300).log10() - y0) / (y1 - y0)) * plot_h;
    let mut svg = canvas(title);
    log_y_ticks(&mut svg, (y0, y1), &y);
    for (k, label) in x_labels.iter().enumerate() {
        let _ = writeln!(
            svg,
            r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">{}</text>"#,
            x(k),
            TOP + plot_h + 16.0,
            escape(label)
        );
    }
    axes(&mut svg, "frame", y_label);
    for (n, (name, values)) in series.iter().enumerate() {
        let colour = SERIES_COLOURS[n % SERIES_COLOURS.len()];
        let mut path = String::new();
        let mut pen_down = false;
        for (k, value) in values.iter().enumerate() {
            match value.filter(|v| v.is_finite() && *v > 0.0) {
                Some(v) => {
                    let _ = write!(path, "{} {:.1} {:.1} ", if pen_down { "L" } else { "M" }, x(k), y(v));
                    pen_down = true;
                }
                None => pen_down = false,
            }
        }
        if !path.is_empty() {
            let _ = writeln!(
                svg,
                r#"<path d="{}" fill="none" stroke="{colour}" stroke-width="1.8"><title>{}</title></path>"#,
                path.trim_end(),
                escape(name)
            );
        }
        let ly = TOP + 14.0 + 16.0 * n as f64;
        let lx = LEFT + plot_w + 10.0;
        let _ = writeln!(
            svg,
            r#"<line x1="{lx:.1}" y1="{:.1}" x2="{:.1}" y2="{:.1}" stroke="{colour}" stroke-width="2.5"/><text x="{:.1}" y="{ly:.1}" fill="{colour}">{}</text>"#,
            ly - 4.0,
            lx + 16.0,
            ly - 4.0,
            lx + 20.0,
            escape(name)
        );
    }
    svg.push_str("</svg>\n");
    svg
}

/// A horizontal bar chart of counts, largest first.
pub fn bars(title: &str, items: &[(String, usize)]) -> String {
    let mut items = items.to_vec();
    items.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
    let row = 22.0;
    let label_w = 150.0;
    let bar_w = 360.0;
    let height = TOP + row * items.len().max(1) as f64 + 20.0;
    let max = items.iter().map(|i| i.1).max().unwrap_or(1).max(1) as f64;
    let mut svg = String::new();
    let _ = writeln!(
        svg,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{height}" viewBox="0 0 {w} {height}" font-family="sans-serif" font-size="12">"#,
        w = label_w + bar_w + 70.0
    );
    let _ = writeln!(svg, r#"<rect width="100%" height="100%" fill="white"/>"#);
    let _ = writeln!(svg, r#"<text x="10" y="20" font-size="14" font-weight="bold">{}</text>"#, escape(title));
    for (k, (label, count)) in items.iter().enumerate() {
        let top = TOP + row * k as f64;
        let w = *count as f64 / max * bar_w;
        let _ = writeln!(
            svg,
            r##"<text x="{:.1}" y="{:.1}" text-anchor="end">{}</text><rect x="{label_w}" y="{top:.1}" width="{w:.1}" height="{:.1}" fill="#2980b9"/><text x="{:.1}" y="{:.1}">{count}</text>"##,
            label_w - 8.0,
            top + 14.0,
            escape(label),
            row - 6.0,
            label_w + w + 6.0,
            top + 14.0
        );
    }
    svg.push_str("</svg>\n");
    svg
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(label: &str, time: f64, error: f64) -> Point {
        Point { label: label.into(), time, error }
    }

    #[test]
    fn the_front_keeps_only_undominated_points() {
        let points = [p("fast", 1.0, 0.5), p("slow-good", 10.0, 0.1), p("dominated", 5.0, 0.6), p("tie", 1.0, 0.5)];
        assert_eq!(pareto_front(&points), [true, true, false, true]);
    }

    #[test]
    fn lines_draw_a_path_per_series_and_break_at_missing_values() {
        let labels: Vec<String> = (1..=4).map(|k| k.to_string()).collect();
        let series = [
            ("a<b".to_string(), vec![Some(0.5), Some(0.2), None, Some(0.1)]),
            ("c".to_string(), vec![None, Some(0.05), Some(0.04), Some(0.03)]),
        ];
        let svg = lines("t", "relMSE", &labels, &series);
        assert_eq!(svg.matches("<path").count(), 2);
        // The first series breaks at its missing third frame: two moves.
        let first = svg.lines().find(|l| l.contains("<path") && l.contains("a&lt;b")).unwrap();
        assert_eq!(first.matches('M').count(), 2, "{first}");
        assert!(!svg.contains("a<b"));
    }

    #[test]
    fn scatter_marks_every_point_and_escapes_labels() {
        let svg = scatter("t", "relMSE", &[p("a<b", 3.0, 0.2), p("c", 30.0, 0.02)], Some(("noisy", 0.9)));
        assert_eq!(svg.matches("<circle").count(), 2);
        assert!(svg.contains("a&lt;b") && !svg.contains("a<b"));
        assert!(svg.contains("stroke-dasharray"), "the noisy line is drawn");
    }
}
