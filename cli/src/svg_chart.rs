//! Inline SVG charts for HTML pages (`goby sim`'s report page): stacked
//! horizontal bars and x-y plots (points or lines), drawn as plain SVG
//! elements with no script, no font file and no network, so that the page
//! reads the same anywhere. [`crate::plot`] draws PNG files; these are
//! text, small, and scale with the page.

use std::fmt::Write;

/// Colours, one per series or part in turn.
pub const PALETTE: [&str; 8] = [
    "#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#17becf", "#8c564b", "#7f7f7f",
];

/// `text` safe inside XML text and attribute values.
pub fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// One bar: its label and its parts, `(value, colour)`, left to right.
#[derive(Debug, Clone, PartialEq)]
pub struct Bar {
    /// Label left of the bar.
    pub label: String,
    /// Its parts.
    pub parts: Vec<(f64, &'static str)>,
}

/// Horizontal bars, stacked, on a scale from 0 to `max` (at least the
/// longest bar); `legend` names the colours. Each bar's total is written
/// right of it with `format_total`.
pub fn bars(
    title: &str,
    bars: &[Bar],
    max: f64,
    legend: &[(&str, &str)],
    format_total: impl Fn(f64) -> String,
) -> String {
    const LEFT: f64 = 220.0;
    const WIDTH: f64 = 420.0;
    const ROW: f64 = 22.0;
    let total = |b: &Bar| b.parts.iter().map(|p| p.0).sum::<f64>();
    let max = bars
        .iter()
        .map(total)
        .fold(max, f64::max)
        .max(f64::MIN_POSITIVE);
    let legend_rows = if legend.is_empty() { 0.0 } else { 1.0 };
    let height = 30.0 + ROW * (bars.len() as f64 + legend_rows) + 10.0;
    let width = (LEFT + WIDTH + 80.0).max(LEFT + legend_width(legend));
    let mut svg = open(title, width, height);
    for (i, bar) in bars.iter().enumerate() {
        let y = 30.0 + ROW * i as f64;
        let _ = write!(
            svg,
            r#"<text x="{:.1}" y="{:.1}" text-anchor="end">{}</text>"#,
            LEFT - 6.0,
            y + 14.0,
            escape(&bar.label)
        );
        let mut x = LEFT;
        for &(value, colour) in &bar.parts {
            let w = value.max(0.0) / max * WIDTH;
            let _ = write!(
                svg,
                r#"<rect x="{x:.1}" y="{:.1}" width="{w:.1}" height="{:.1}" fill="{colour}"/>"#,
                y + 3.0,
                ROW - 6.0
            );
            x += w;
        }
        let _ = write!(
            svg,
            r#"<text x="{:.1}" y="{:.1}">{}</text>"#,
            x + 4.0,
            y + 14.0,
            escape(&format_total(total(bar)))
        );
    }
    let y = 30.0 + ROW * bars.len() as f64 + 14.0;
    legend_row(&mut svg, legend, LEFT, y);
    svg + "</svg>"
}

/// One named series of an x-y plot.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend entry.
    pub name: String,
    /// Colour.
    pub colour: &'static str,
    /// `(x, y)` points; non-finite ones are left out.
    pub points: Vec<(f64, f64)>,
}

/// An x-y plot: points, or with `lines` a line through each series's
/// points in their order; axes ticked at round steps (1, 2 or 5 times a
/// power of ten).
pub fn xy(title: &str, x_label: &str, y_label: &str, series: &[Series], lines: bool) -> String {
    const LEFT: f64 = 70.0;
    const TOP: f64 = 30.0;
    const W: f64 = 520.0;
    const H: f64 = 260.0;
    let finite = || {
        series
            .iter()
            .flat_map(|s| s.points.iter())
            .filter(|(x, y)| x.is_finite() && y.is_finite())
    };
    let span = |v: Vec<f64>| {
        let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        match (lo.is_finite(), hi - lo > 1e-12) {
            (false, _) => (0.0, 1.0),
            (true, true) => (lo, hi),
            (true, false) => (lo - 1.0, hi + 1.0),
        }
    };
    let (x0, x1) = span(finite().map(|p| p.0).collect());
    let (y0, y1) = span(finite().map(|p| p.1).collect());
    let px = |x: f64| LEFT + (x - x0) / (x1 - x0) * W;
    let py = |y: f64| TOP + H - (y - y0) / (y1 - y0) * H;
    let legend_y = TOP + H + 50.0;
    let legend: Vec<(&str, &str)> = series.iter().map(|s| (s.name.as_str(), s.colour)).collect();
    let width = (LEFT + W + 30.0).max(LEFT + legend_width(&legend));
    let mut svg = open(title, width, legend_y + 10.0);
    let _ = write!(
        svg,
        r##"<rect x="{LEFT}" y="{TOP}" width="{W}" height="{H}" fill="none" stroke="#999"/>"##
    );
    for (v, label) in ticks(x0, x1) {
        let _ = write!(
            svg,
            r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">{label}</text>"#,
            px(v),
            TOP + H + 16.0
        );
    }
    for (v, label) in ticks(y0, y1) {
        let _ = write!(
            svg,
            r#"<text x="{:.1}" y="{:.1}" text-anchor="end">{label}</text>"#,
            LEFT - 6.0,
            py(v) + 4.0
        );
    }
    let _ = write!(
        svg,
        r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">{}</text><text x="14" y="{:.1}" text-anchor="middle" transform="rotate(-90 14 {:.1})">{}</text>"#,
        LEFT + W / 2.0,
        TOP + H + 34.0,
        escape(x_label),
        TOP + H / 2.0,
        TOP + H / 2.0,
        escape(y_label)
    );
    for s in series {
        let points = s
            .points
            .iter()
            .filter(|(x, y)| x.is_finite() && y.is_finite());
        if lines {
            let path: Vec<String> = points
                .map(|&(x, y)| format!("{:.1},{:.1}", px(x), py(y)))
                .collect();
            let _ = write!(
                svg,
                r#"<polyline fill="none" stroke="{}" stroke-width="1.5" points="{}"/>"#,
                s.colour,
                path.join(" ")
            );
        } else {
            for &(x, y) in points {
                let _ = write!(
                    svg,
                    r#"<circle cx="{:.1}" cy="{:.1}" r="2.5" fill="{}"/>"#,
                    px(x),
                    py(y),
                    s.colour
                );
            }
        }
    }
    let legend: Vec<(&str, &str)> = series.iter().map(|s| (s.name.as_str(), s.colour)).collect();
    legend_row(&mut svg, &legend, LEFT, legend_y);
    svg + "</svg>"
}

/// Ticks from `lo` to `hi` at a round step (1, 2 or 5 times a power of
/// ten, about five of them), each with its label in the decimals the
/// step needs.
fn ticks(lo: f64, hi: f64) -> Vec<(f64, String)> {
    let rough = (hi - lo) / 5.0;
    let power = 10f64.powf(rough.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * power)
        .find(|&s| s >= rough)
        .unwrap_or(10.0 * power);
    let decimals = (-step.log10().floor()).clamp(0.0, 6.0) as usize;
    let first = (lo / step).ceil() as i64;
    let last = (hi / step).floor() as i64;
    (first..=last)
        .map(|k| {
            let v = k as f64 * step;
            (v, format!("{v:.decimals$}"))
        })
        .collect()
}

/// The opening of a chart: its size, its font, its title.
fn open(title: &str, width: f64, height: f64) -> String {
    format!(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{width:.0}" height="{height:.0}" viewBox="0 0 {width:.0} {height:.0}" font-family="sans-serif" font-size="12" role="img"><title>{t}</title><text x="8" y="18" font-size="14" font-weight="bold">{t}</text>"#,
        t = escape(title)
    )
}

/// The width of one legend entry called `name`, pixels.
fn entry_width(name: &str) -> f64 {
    24.0 + 7.0 * name.chars().count() as f64
}

/// The width of a row of `legend`, pixels.
fn legend_width(legend: &[(&str, &str)]) -> f64 {
    legend.iter().map(|(name, _)| entry_width(name)).sum()
}

/// The colour swatches and names of `legend`, in a row from `x` at `y`.
fn legend_row(svg: &mut String, legend: &[(&str, &str)], mut x: f64, y: f64) {
    for (name, colour) in legend {
        let _ = write!(
            svg,
            r#"<rect x="{x:.1}" y="{:.1}" width="10" height="10" fill="{colour}"/><text x="{:.1}" y="{y:.1}">{}</text>"#,
            y - 9.0,
            x + 14.0,
            escape(name)
        );
        x += entry_width(name);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn charts_escape_their_text_and_scale_their_values() {
        let svg = bars(
            "a <b>",
            &[Bar {
                label: "x&y".into(),
                parts: vec![(1.0, PALETTE[0]), (1.0, PALETTE[1])],
            }],
            0.0,
            &[("one", PALETTE[0])],
            |t| format!("{t}"),
        );
        assert!(svg.contains("a &lt;b&gt;") && svg.contains("x&amp;y"));
        // Two halves of the 420-pixel scale.
        assert_eq!(svg.matches(r#"width="210.0""#).count(), 2, "{svg}");
        let svg = xy(
            "t",
            "x",
            "y",
            &[Series {
                name: "s".into(),
                colour: PALETTE[2],
                points: vec![(0.0, 0.0), (10.0, 5.0), (f64::NAN, 1.0)],
            }],
            false,
        );
        assert_eq!(svg.matches("<circle").count(), 2);
        let labels: Vec<String> = ticks(0.011, 1.0).into_iter().map(|t| t.1).collect();
        assert_eq!(labels, ["0.2", "0.4", "0.6", "0.8", "1.0"]);
        let labels: Vec<String> = ticks(20.0, 7150.0).into_iter().map(|t| t.1).collect();
        assert_eq!(labels, ["2000", "4000", "6000"]);
        assert!(svg.contains(r#"cx="70.0" cy="290.0""#) && svg.contains(r#"cx="590.0" cy="30.0""#));
    }
}
