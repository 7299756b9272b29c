//! PNG line charts for the simulation commands (`goby queue simulate`, ...).
//!
//! Text is drawn with a font embedded in the binary, so plots come out the
//! same on a machine without any fonts installed. Glyphs are placed by
//! their own metrics (`GlyphText`): plotters' `ab_glyph` renderer draws
//! each glyph's ink at the pen position, dropping its left side bearing,
//! which evens out letter gaps and spaces alike (a legend's "3 nodes" read
//! "3nodes").
//!
//! Each axis says what its values are ([`Axis`]): a share runs from 0 to
//! 1, whole numbers are labelled as such, at whole-number ticks.

use std::fmt;
use std::path::Path;
use std::sync::OnceLock;

use ab_glyph::{Font, FontRef, ScaleFont};
use plotters::coord::ranged1d::{DefaultFormatting, KeyPointHint};
use plotters::prelude::*;
use plotters::style::{register_font, FontStyle};
use plotters_backend::{
    text_anchor::{HPos, VPos},
    BackendColor, BackendCoord, BackendStyle, BackendTextStyle, DrawingErrorKind,
};

/// Font family name the charts draw their text with.
pub(crate) const FONT_FAMILY: &str = "sans-serif";

/// One named line of a chart.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend entry.
    pub name: String,
    /// `(x, y)` points, drawn in the given order; non-finite points are skipped.
    pub points: Vec<(f64, f64)>,
}

/// What the values along an axis are: it decides the axis's range, its
/// ticks and how they are labelled.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Axis {
    /// Any real values: the range covers them, ticks at round steps,
    /// labelled with the decimals the step needs.
    #[default]
    Real,
    /// Whole numbers (counts, sizes, a coolness): ticks at whole numbers
    /// only, labelled without decimals.
    Integer,
    /// A share, fraction or probability: the axis runs from 0 to 1 whatever
    /// the values (one outside is an error).
    Share,
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
    /// What the horizontal values are.
    pub x_axis: Axis,
    /// What the vertical values are.
    pub y_axis: Axis,
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

/// The embedded chart font, parsed once.
fn chart_font() -> Result<&'static FontRef<'static>, PlotError> {
    static FONT: OnceLock<Option<FontRef<'static>>> = OnceLock::new();
    FONT.get_or_init(|| FontRef::try_from_slice(epaint_default_fonts::UBUNTU_LIGHT).ok())
        .as_ref()
        .ok_or_else(|| PlotError("the embedded chart font could not be loaded".into()))
}

/// Calls `pixel(x, y, coverage)` for every pixel of `text` drawn at
/// `size` (plotters' size: the font's ascent to descent, in pixels), the
/// pen starting at x = 0 and the baseline at y = `size / 2` (where plotters
/// puts it, so its text layout still holds). Each glyph is placed by its
/// own bounds, left side bearing included, after the advance and kerning
/// of those before it: the widths are those plotters lays text out with.
fn glyph_pixels(font: &FontRef<'_>, size: f32, text: &str, mut pixel: impl FnMut(i32, i32, f32)) {
    let scaled = font.as_scaled(size);
    let baseline = size / 2.0;
    let mut pen = 0f32;
    let mut previous = None;
    for c in text.chars() {
        let id = scaled.glyph_id(c);
        if let Some(p) = previous {
            pen += scaled.kern(p, id);
        }
        let glyph = id.with_scale_and_position(size, ab_glyph::point(pen, baseline));
        if let Some(outline) = scaled.outline_glyph(glyph) {
            let bounds = outline.px_bounds();
            outline.draw(|x, y, coverage| {
                pixel(
                    bounds.min.x as i32 + x as i32,
                    bounds.min.y as i32 + y as i32,
                    coverage,
                )
            });
        }
        pen += scaled.h_advance(id);
        previous = Some(id);
    }
}

/// The bitmap backend with text drawn by [`glyph_pixels`] (everything else
/// as the bitmap backend draws it).
pub(crate) struct GlyphText<'a> {
    inner: BitMapBackend<'a>,
    font: &'static FontRef<'static>,
}

/// `inner` with its text drawn by the chart font's own glyph metrics (see
/// [`GlyphText`]), the font registered under [`FONT_FAMILY`].
///
/// # Errors
/// When the embedded font cannot be loaded.
pub(crate) fn glyph_backend(inner: BitMapBackend<'_>) -> Result<GlyphText<'_>, PlotError> {
    ensure_font()?;
    Ok(GlyphText {
        inner,
        font: chart_font()?,
    })
}

type BackendResult =
    Result<(), DrawingErrorKind<<BitMapBackend<'static> as DrawingBackend>::ErrorType>>;

impl DrawingBackend for GlyphText<'_> {
    type ErrorType = <BitMapBackend<'static> as DrawingBackend>::ErrorType;

    fn get_size(&self) -> (u32, u32) {
        self.inner.get_size()
    }

    fn ensure_prepared(&mut self) -> BackendResult {
        self.inner.ensure_prepared()
    }

    fn present(&mut self) -> BackendResult {
        self.inner.present()
    }

    fn draw_pixel(&mut self, point: BackendCoord, color: BackendColor) -> BackendResult {
        self.inner.draw_pixel(point, color)
    }

    fn draw_line<S: BackendStyle>(
        &mut self,
        from: BackendCoord,
        to: BackendCoord,
        style: &S,
    ) -> BackendResult {
        self.inner.draw_line(from, to, style)
    }

    fn draw_rect<S: BackendStyle>(
        &mut self,
        upper_left: BackendCoord,
        bottom_right: BackendCoord,
        style: &S,
        fill: bool,
    ) -> BackendResult {
        self.inner.draw_rect(upper_left, bottom_right, style, fill)
    }

    fn draw_path<S: BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        path: I,
        style: &S,
    ) -> BackendResult {
        self.inner.draw_path(path, style)
    }

    fn draw_circle<S: BackendStyle>(
        &mut self,
        center: BackendCoord,
        radius: u32,
        style: &S,
        fill: bool,
    ) -> BackendResult {
        self.inner.draw_circle(center, radius, style, fill)
    }

    fn fill_polygon<S: BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        vert: I,
        style: &S,
    ) -> BackendResult {
        self.inner.fill_polygon(vert, style)
    }

    fn blit_bitmap(&mut self, pos: BackendCoord, size: (u32, u32), src: &[u8]) -> BackendResult {
        self.inner.blit_bitmap(pos, size, src)
    }

    /// As plotters' own `draw_text` (anchor, rotation, the layout box from
    /// the registered font), the glyphs placed by [`glyph_pixels`].
    fn draw_text<TStyle: BackendTextStyle>(
        &mut self,
        text: &str,
        style: &TStyle,
        pos: BackendCoord,
    ) -> BackendResult {
        let color = style.color();
        if color.alpha == 0.0 {
            return Ok(());
        }
        let ((min_x, min_y), (max_x, max_y)) = style
            .layout_box(text)
            .map_err(|e| DrawingErrorKind::FontError(Box::new(e)))?;
        let (width, height) = (max_x - min_x, max_y - min_y);
        let dx = match style.anchor().h_pos {
            HPos::Left => 0,
            HPos::Right => -width,
            HPos::Center => -width / 2,
        };
        let dy = match style.anchor().v_pos {
            VPos::Top => 0,
            VPos::Center => -height / 2,
            VPos::Bottom => -height,
        };
        let transform = style.transform();
        let mut result = Ok(());
        let inner = &mut self.inner;
        glyph_pixels(self.font, style.size() as f32, text, |x, y, coverage| {
            if result.is_err() {
                return;
            }
            let (x, y) = transform.transform(x + dx - min_x, y + dy - min_y);
            let color = BackendColor {
                alpha: color.alpha * f64::from(coverage.clamp(0.0, 1.0)),
                rgb: color.rgb,
            };
            result = inner.draw_pixel((pos.0 + x, pos.1 + y), color);
        });
        result
    }
}

/// A round step (1, 2 or 5 times a power of ten) giving at most
/// `max_ticks` intervals over `length`.
fn nice_step(length: f64, max_ticks: usize) -> f64 {
    let raw = length / max_ticks.max(1) as f64;
    let power = 10f64.powf(raw.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * power)
        .find(|&step| step >= raw * (1.0 - 1e-9))
        .unwrap_or(10.0 * power)
}

/// The range an axis of `kind` covers for values spanning `span`
/// (`margin`: the share of the span added at each end, for the vertical
/// axis). A share axis is 0 to 1; an integer axis ends on whole numbers.
fn axis_range(kind: Axis, span: (f64, f64), margin: f64) -> (f64, f64) {
    let pad = (span.1 - span.0) * margin;
    match kind {
        Axis::Share => (0.0, 1.0),
        Axis::Real => (span.0 - pad, span.1 + pad),
        Axis::Integer => ((span.0 - pad).floor(), (span.1 + pad).ceil()),
    }
}

/// Bold ticks, light ticks (the finer mesh) and the bold step of an axis
/// of `kind` over `range`: round steps, whole ones on an integer axis.
fn ticks(kind: Axis, range: (f64, f64)) -> (Vec<f64>, Vec<f64>, f64) {
    let (lo, hi) = range;
    let step = match kind {
        Axis::Integer => nice_step(hi - lo, 10).max(1.0),
        Axis::Real | Axis::Share => nice_step(hi - lo, 10),
    };
    let light_step = match kind {
        Axis::Integer => (step / 5.0).round().max(1.0),
        Axis::Real | Axis::Share => step / 5.0,
    };
    let multiples = |step: f64| -> Vec<f64> {
        let first = (lo / step - 1e-9).ceil() as i64;
        let last = (hi / step + 1e-9).floor() as i64;
        (first..=last)
            .map(|k| {
                let v = k as f64 * step;
                // 0.30000000000000004 → 0.3, and no "-0".
                let v = (v / step).round() * step;
                if v == 0.0 {
                    0.0
                } else {
                    v
                }
            })
            .collect()
    };
    let bold = multiples(step);
    let light = if light_step < step {
        multiples(light_step)
    } else {
        Vec::new()
    };
    (bold, light, step)
}

/// A linear axis over `range` with the ticks [`ticks`] chose.
#[derive(Debug, Clone)]
struct TickedAxis {
    range: (f64, f64),
    bold: Vec<f64>,
    light: Vec<f64>,
}

impl Ranged for TickedAxis {
    type FormatOption = DefaultFormatting;
    type ValueType = f64;

    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        let (lo, hi) = self.range;
        let share = (value - lo) / (hi - lo);
        let length = f64::from(limit.1 - limit.0);
        limit.0 + (length * share).round() as i32
    }

    fn key_points<Hint: KeyPointHint>(&self, hint: Hint) -> Vec<f64> {
        if hint.weight().allow_light_points() {
            self.light.clone()
        } else {
            self.bold.clone()
        }
    }

    fn range(&self) -> std::ops::Range<f64> {
        self.range.0..self.range.1
    }
}

/// The label of tick `value` on an axis of `kind` whose ticks are `step`
/// apart: whole numbers on an integer axis, otherwise the decimals the
/// step needs (0.2 → one, 0.05 → two, 5 → none).
fn tick_label(kind: Axis, value: f64, step: f64) -> String {
    let value = if value == 0.0 { 0.0 } else { value };
    match kind {
        Axis::Integer => format!("{}", value.round() as i64),
        Axis::Real | Axis::Share => {
            let decimals = if step >= 1.0 {
                0
            } else {
                (-step.log10() - 1e-9).ceil().max(0.0) as usize
            };
            format!("{value:.decimals$}")
        }
    }
}

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

/// The low and high ends of an axis.
type Span = (f64, f64);

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
    /// Axis ranges covering every finite point ([`axis_range`]: the
    /// vertical one with a 5 % margin, a share axis 0 to 1). An error when
    /// the chart has no finite point or a share axis has a value outside
    /// 0 to 1.
    fn ranges(&self) -> Result<(Span, Span), PlotError> {
        let finite = || {
            self.series
                .iter()
                .flat_map(|s| s.points.iter())
                .filter(|(x, y)| x.is_finite() && y.is_finite())
        };
        let no_point = || PlotError(format!("chart \"{}\" has no finite point", self.title));
        for (kind, label, values) in [
            (
                self.x_axis,
                &self.x_label,
                finite().map(|p| p.0).collect::<Vec<_>>(),
            ),
            (self.y_axis, &self.y_label, finite().map(|p| p.1).collect()),
        ] {
            if kind == Axis::Share {
                if let Some(v) = values.iter().find(|v| !(0.0..=1.0).contains(*v)) {
                    return Err(PlotError(format!(
                        "chart \"{}\": {v} is not a share (0 to 1) on axis \"{label}\"",
                        self.title
                    )));
                }
            }
        }
        let x = span(finite().map(|p| p.0)).ok_or_else(no_point)?;
        let y = span(finite().map(|p| p.1)).ok_or_else(no_point)?;
        Ok((
            axis_range(self.x_axis, x, 0.0),
            axis_range(self.y_axis, y, 0.05),
        ))
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
    /// the range grows upwards to leave the legend room of its own (not a
    /// share axis, which stays 0 to 1: its legend takes the emptiest
    /// corner).
    fn layout(&self, x: (f64, f64), y: (f64, f64)) -> ((f64, f64), SeriesLabelPosition) {
        match self.emptiest_corner(x, y) {
            (position, 0) => (y, position),
            (position, _) if self.y_axis == Axis::Share => (y, position),
            _ => {
                let rows = self.series.len() as f64;
                let grown = (y.0, y.1 + (y.1 - y.0) * (0.1 + 0.07 * rows));
                let grown = axis_range(self.y_axis, grown, 0.0);
                (grown, self.emptiest_corner(x, grown).0)
            }
        }
    }

    /// Draws the chart into a `width` × `height` PNG file at `path`.
    pub fn write_png(&self, path: &Path, width: u32, height: u32) -> Result<(), PlotError> {
        let backend = BitMapBackend::new(path, (width, height));
        self.draw(backend, &path.display().to_string())
    }

    /// Draws the chart into an RGB buffer of `width` × `height` pixels.
    pub fn draw_rgb(&self, buffer: &mut [u8], width: u32, height: u32) -> Result<(), PlotError> {
        if buffer.len() != (width as usize) * (height as usize) * 3 {
            return Err(PlotError(format!(
                "a {width} × {height} RGB buffer holds {} bytes, not {}",
                (width as usize) * (height as usize) * 3,
                buffer.len()
            )));
        }
        let backend = BitMapBackend::with_buffer(buffer, (width, height));
        self.draw(backend, "into a buffer")
    }

    fn draw(&self, backend: BitMapBackend<'_>, target: &str) -> Result<(), PlotError> {
        ensure_font()?;
        let ((x_lo, x_hi), y) = self.ranges()?;
        let ((y_lo, y_hi), legend) = self.layout((x_lo, x_hi), y);
        let (x_bold, x_light, x_step) = ticks(self.x_axis, (x_lo, x_hi));
        let (y_bold, y_light, y_step) = ticks(self.y_axis, (y_lo, y_hi));
        let draw_error =
            |e: &dyn fmt::Display| PlotError(format!("cannot draw chart {target}: {e}"));
        let backend = GlyphText {
            inner: backend,
            font: chart_font()?,
        };
        let root = backend.into_drawing_area();
        root.fill(&WHITE).map_err(|e| draw_error(&e))?;
        let mut chart = ChartBuilder::on(&root)
            .caption(&self.title, (FONT_FAMILY, 22))
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(70)
            .build_cartesian_2d(
                TickedAxis {
                    range: (x_lo, x_hi),
                    bold: x_bold,
                    light: x_light,
                },
                TickedAxis {
                    range: (y_lo, y_hi),
                    bold: y_bold,
                    light: y_light,
                },
            )
            .map_err(|e| draw_error(&e))?;
        let (x_axis, y_axis) = (self.x_axis, self.y_axis);
        let x_format = move |v: &f64| tick_label(x_axis, *v, x_step);
        let y_format = move |v: &f64| tick_label(y_axis, *v, y_step);
        chart
            .configure_mesh()
            .x_desc(&self.x_label)
            .y_desc(&self.y_label)
            .x_label_formatter(&x_format)
            .y_label_formatter(&y_format)
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
                .draw_series(LineSeries::new(
                    points.clone(),
                    Color::stroke_width(&color, 2),
                ))
                .map_err(|e| draw_error(&e))?
                .label(&series.name)
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], Color::stroke_width(&color, 2))
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
            .label_font((FONT_FAMILY, 15))
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
            x_axis: Axis::Real,
            y_axis: Axis::Real,
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

    /// The chart's own text path (the legend's, the labels'): `text` at
    /// `size` drawn at (`x`, 10) into a white RGB buffer `width` × 40.
    fn drawn_text(text: &str, size: f64, x: i32, width: u32) -> Vec<u8> {
        ensure_font().unwrap();
        let mut buffer = vec![255u8; width as usize * 40 * 3];
        {
            let backend = GlyphText {
                inner: BitMapBackend::with_buffer(&mut buffer, (width, 40)),
                font: chart_font().unwrap(),
            };
            let root = backend.into_drawing_area();
            root.draw(&Text::new(text, (x, 10), (FONT_FAMILY, size)))
                .unwrap();
            root.present().unwrap();
        }
        buffer
    }

    /// The columns of the space in "3 nodes" (from the advance of "3" to
    /// where the ink of "n" begins, by the font's metrics) are background
    /// in every row: plotters' own renderer, which drops the "n"'s left
    /// bearing, inks them (the legend read "3nodes").
    #[test]
    fn a_space_between_words_is_drawn_as_background() {
        let size = 15.0;
        let x0 = 5;
        let width = 120u32;
        let buffer = drawn_text("3 nodes", size, x0, width);
        let scaled = chart_font().unwrap().as_scaled(size as f32);
        let advance = |c| scaled.h_advance(scaled.glyph_id(c));
        let three = advance('3');
        let n_ink = three + advance(' ') + scaled.h_side_bearing(scaled.glyph_id('n'));
        let gap = (x0 + three.ceil() as i32)..(x0 + n_ink.floor() as i32);
        assert!(gap.len() >= 3, "a space of {gap:?} at {size} px");
        let column_is_background = |x: i32| {
            (0..40).all(|y| {
                let i = (y * width as usize + x as usize) * 3;
                buffer[i..i + 3].iter().all(|&v| v >= 250)
            })
        };
        for x in gap.clone() {
            assert!(
                column_is_background(x),
                "column {x} of the space {gap:?} is inked"
            );
        }
        // And the words around it are drawn.
        assert!(!column_is_background(gap.start - 2), "no ink of \"3\"");
        assert!(!column_is_background(gap.end + 1), "no ink of \"n\"");
    }

    /// A legend with spaces, over a share axis whose every corner holds
    /// points: the axis stays 0 to 1 (it used to grow to about 1.6 for the
    /// legend's room).
    #[test]
    fn a_share_axis_stays_between_0_and_1() {
        let crowded = LineChart {
            title: "share".into(),
            x_label: "coolness C".into(),
            y_label: "share of runs".into(),
            x_axis: Axis::Integer,
            y_axis: Axis::Share,
            series: (0..6)
                .map(|k| Series {
                    name: format!("{} nodes", 2 * k + 2),
                    points: vec![(1.0, 0.0), (1.0, 1.0), (32.0, 0.0), (32.0, 1.0)],
                })
                .collect(),
        };
        let (x, y) = crowded.ranges().unwrap();
        assert_eq!(y, (0.0, 1.0));
        let (y, _) = crowded.layout(x, y);
        assert_eq!(y, (0.0, 1.0));
        let (bold, _, step) = ticks(Axis::Share, y);
        let labels: Vec<String> = bold
            .iter()
            .map(|&v| tick_label(Axis::Share, v, step))
            .collect();
        assert_eq!(
            labels,
            ["0.0", "0.1", "0.2", "0.3", "0.4", "0.5", "0.6", "0.7", "0.8", "0.9", "1.0"]
        );
        // The same values on a real axis grow for the legend.
        let real = LineChart {
            y_axis: Axis::Real,
            ..crowded.clone()
        };
        let (x, y) = real.ranges().unwrap();
        assert!(real.layout(x, y).0 .1 > 1.2);
        // A share outside 0 to 1 is an error, not a taller axis.
        let mut bad = crowded.clone();
        bad.series[0].points.push((2.0, 1.25));
        let e = bad.ranges().unwrap_err().to_string();
        assert!(
            e.contains("1.25 is not a share (0 to 1) on axis \"share of runs\""),
            "{e}"
        );
        // It draws.
        let (w, h) = (400, 260);
        let mut buffer = vec![0u8; w as usize * h as usize * 3];
        crowded.draw_rgb(&mut buffer, w, h).unwrap();
    }

    #[test]
    fn an_integer_axis_has_whole_ticks_and_labels() {
        for (range, want) in [
            ((2.0, 6.0), vec!["2", "3", "4", "5", "6"]),
            ((0.0, 4.0), vec!["0", "1", "2", "3", "4"]),
            ((1.0, 32.0), vec!["5", "10", "15", "20", "25", "30"]),
            ((0.0, 1.0), vec!["0", "1"]),
        ] {
            let (bold, light, step) = ticks(Axis::Integer, range);
            let labels: Vec<String> = bold
                .iter()
                .map(|&v| tick_label(Axis::Integer, v, step))
                .collect();
            assert_eq!(labels, want, "{range:?}");
            assert!(
                bold.iter().chain(&light).all(|v| v.fract() == 0.0),
                "{range:?}: {bold:?} {light:?}"
            );
        }
        // The range of whole values ends on whole numbers, margin and all.
        assert_eq!(axis_range(Axis::Integer, (2.0, 6.0), 0.05), (1.0, 7.0));
        assert_eq!(axis_range(Axis::Integer, (2.0, 6.0), 0.0), (2.0, 6.0));
    }

    #[test]
    fn real_labels_carry_the_decimals_of_their_step() {
        assert_eq!(tick_label(Axis::Real, 0.30000000000000004, 0.1), "0.3");
        assert_eq!(tick_label(Axis::Real, 1500.0, 500.0), "1500");
        assert_eq!(tick_label(Axis::Real, 0.15, 0.05), "0.15");
        assert_eq!(tick_label(Axis::Real, -0.0, 0.5), "0.0");
        let (bold, _, step) = ticks(Axis::Real, (0.0, 0.7));
        assert_eq!(step, 0.1);
        assert_eq!(bold.len(), 8);
        assert_eq!(nice_step(30.0, 10), 5.0);
        assert_eq!(nice_step(0.4, 10), 0.05);
    }

    #[test]
    fn a_flat_series_still_has_an_axis_length() {
        let ((_, _), (lo, hi)) = chart(vec![(0.0, 5.0), (1.0, 5.0)]).ranges().unwrap();
        assert!(lo < 5.0 && hi > 5.0);
    }
}
