//! PNG line charts for the simulation commands (`goby queue simulate`, ...).
//!
//! Text is drawn with a font embedded in the binary, so plots come out the
//! same on a machine without any fonts installed.

use std::fmt;
use std::path::Path;
use std::sync::OnceLock;

use plotters::prelude::*;
use plotters::style::{register_font, FontStyle};

/// Font family name the charts draw their text with.
const FONT_FAMILY: &str = "sans-serif";

/// One named line of a chart.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend entry.
    pub name: String,
    /// `(x, y)` points, drawn in the given order; non-finite points are skipped.
    pub points: Vec<(f64, f64)>,
}

/// A chart of one or more lines sharing both axes.
#[derive(Debug, Clone, PartialEq)]
pub struct LineChart {
    /// Caption above the plot area.
    pub title: String,
    /// Label of the horizontal axis.
    pub x_label: String,
    /// Label of the vertical axis.
    pub y_label: String,
    /// The lines.
    pub series: Vec<Series>,
}

/// A chart that could not be drawn or written.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PlotError(String);

impl fmt::Display for PlotError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for PlotError {}

/// Line colours, one per series in turn.
const PALETTE: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(148, 103, 189),
    RGBColor(255, 127, 14),
    RGBColor(23, 190, 207),
];

fn ensure_font() -> Result<(), PlotError> {
    static REGISTERED: OnceLock<Result<(), String>> = OnceLock::new();
    REGISTERED
        .get_or_init(|| {
            register_font(
                FONT_FAMILY,
                FontStyle::Normal,
                epaint_default_fonts::UBUNTU_LIGHT,
            )
            .map_err(|_| "the embedded chart font could not be loaded".to_string())
        })
        .clone()
        .map_err(PlotError)
}

/// Smallest and largest of the values, widened when they are equal so that
/// the axis has a length. `None` when there is no finite value.
fn span(values: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
    if lo > hi {
        return None;
    }
    if hi - lo < f64::EPSILON * hi.abs().max(1.0) {
        let pad = (hi.abs() * 0.1).max(1.0);
        return Some((lo - pad, hi + pad));
    }
    Some((lo, hi))
}

impl LineChart {
    /// Axis ranges covering every finite point, the vertical one with a 5 %
    /// margin. `None` when the chart has no finite point.
    fn ranges(&self) -> Option<((f64, f64), (f64, f64))> {
        let finite = || {
            self.series
                .iter()
                .flat_map(|s| s.points.iter())
                .filter(|(x, y)| x.is_finite() && y.is_finite())
        };
        let x = span(finite().map(|p| p.0))?;
        let (y_lo, y_hi) = span(finite().map(|p| p.1))?;
        let margin = (y_hi - y_lo) * 0.05;
        Some((x, (y_lo - margin, y_hi + margin)))
    }

    /// The corner of the plot area with the fewest points near it, where the
    /// legend hides the least.
    fn emptiest_corner(&self, x: (f64, f64), y: (f64, f64)) -> (SeriesLabelPosition, usize) {
        let corners = [
            (SeriesLabelPosition::UpperRight, true, true),
            (SeriesLabelPosition::UpperLeft, false, true),
            (SeriesLabelPosition::LowerRight, true, false),
            (SeriesLabelPosition::LowerLeft, false, false),
        ];
        let near = |right: bool, upper: bool| {
            self.series
                .iter()
                .flat_map(|s| s.points.iter())
                .filter(|(px, py)| {
                    let fx = (px - x.0) / (x.1 - x.0);
                    let fy = (py - y.0) / (y.1 - y.0);
                    let in_x = if right { fx > 0.55 } else { fx < 0.45 };
                    let in_y = if upper { fy > 0.6 } else { fy < 0.4 };
                    in_x && in_y
                })
                .count()
        };
        corners
            .into_iter()
            .map(|(position, right, upper)| (position, near(right, upper)))
            .min_by_key(|&(_, count)| count)
            .unwrap_or((SeriesLabelPosition::UpperRight, 0))
    }

    /// The vertical range and legend corner: when every corner has points,
    /// the range grows upwards to leave the legend room of its own.
    fn layout(&self, x: (f64, f64), y: (f64, f64)) -> ((f64, f64), SeriesLabelPosition) {
        match self.emptiest_corner(x, y) {
            (position, 0) => (y, position),
            _ => {
                let rows = self.series.len() as f64;
                let grown = (y.0, y.1 + (y.1 - y.0) * (0.1 + 0.07 * rows));
                (grown, self.emptiest_corner(x, grown).0)
            }
        }
    }

    /// Draws the chart into a `width` × `height` PNG file at `path`.
    pub fn write_png(&self, path: &Path, width: u32, height: u32) -> Result<(), PlotError> {
        ensure_font()?;
        let ((x_lo, x_hi), y) = self
            .ranges()
            .ok_or_else(|| PlotError(format!("chart \"{}\" has no finite point", self.title)))?;
        let ((y_lo, y_hi), legend) = self.layout((x_lo, x_hi), y);
        let draw_error =
            |e: &dyn fmt::Display| PlotError(format!("cannot draw chart {}: {e}", path.display()));
        let root = BitMapBackend::new(path, (width, height)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| draw_error(&e))?;
        let mut chart = ChartBuilder::on(&root)
            .caption(&self.title, (FONT_FAMILY, 22))
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(70)
            .build_cartesian_2d(x_lo..x_hi, y_lo..y_hi)
            .map_err(|e| draw_error(&e))?;
        chart
            .configure_mesh()
            .x_desc(&self.x_label)
            .y_desc(&self.y_label)
            .label_style((FONT_FAMILY, 14))
            .axis_desc_style((FONT_FAMILY, 16))
            .draw()
            .map_err(|e| draw_error(&e))?;
        for (i, series) in self.series.iter().enumerate() {
            let color = PALETTE[i % PALETTE.len()];
            let points: Vec<(f64, f64)> = series
                .points
                .iter()
                .copied()
                .filter(|(x, y)| x.is_finite() && y.is_finite())
                .collect();
            chart
                .draw_series(LineSeries::new(points.clone(), color.stroke_width(2)))
                .map_err(|e| draw_error(&e))?
                .label(&series.name)
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
                });
            chart
                .draw_series(
                    points
                        .into_iter()
                        .map(|p| Circle::new(p, 3, color.filled())),
                )
                .map_err(|e| draw_error(&e))?;
        }
        chart
            .configure_series_labels()
            .label_font((FONT_FAMILY, 14))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .position(legend)
            .draw()
            .map_err(|e| draw_error(&e))?;
        root.present().map_err(|e| draw_error(&e))?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chart(points: Vec<(f64, f64)>) -> LineChart {
        LineChart {
            title: "τ test".into(),
            x_label: "x".into(),
            y_label: "y".into(),
            series: vec![Series {
                name: "a".into(),
                points,
            }],
        }
    }

    #[test]
    fn writes_a_png_of_the_requested_size() {
        let dir = std::env::temp_dir().join(format!("goby-plot-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("chart.png");
        chart(vec![(0.0, 1.0), (0.5, f64::NAN), (1.0, 3.0)])
            .write_png(&path, 320, 200)
            .unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
        // IHDR: width and height, big-endian, at bytes 16..24.
        assert_eq!(u32::from_be_bytes(bytes[16..20].try_into().unwrap()), 320);
        assert_eq!(u32::from_be_bytes(bytes[20..24].try_into().unwrap()), 200);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_chart_without_finite_points_is_an_error() {
        let err = chart(vec![(f64::NAN, 1.0)])
            .write_png(Path::new("unused.png"), 100, 100)
            .unwrap_err();
        assert!(err.to_string().contains("no finite point"), "{err}");
    }

    #[test]
    fn a_flat_series_still_has_an_axis_length() {
        let ((_, _), (lo, hi)) = chart(vec![(0.0, 5.0), (1.0, 5.0)]).ranges().unwrap();
        assert!(lo < 5.0 && hi > 5.0);
    }
}
