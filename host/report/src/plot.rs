//! Line plots: axes with numeric ticks, title, axis labels, legend, several coloured series,
//! optional logarithmic x axis; rendered on a [`Canvas`] and saved as PNG.
//!
//! Contract: `LinePlot::new(title).x_label(..).y_label(..).series(name, points)….save_png(path)`.
//! Non-finite points (and x ≤ 0 on a log axis) break a series' line instead of failing; a plot
//! with no drawable point at all is an error ([`ReportError::NoData`]). Ranges default to the
//! data (y padded by 5 %), ticks are "nice" 1–2–5 steps, or decades on a log axis.

use std::path::Path;

use super::ReportError;
use super::canvas::{Canvas, ClipRect, GLYPH_PX, Rgb, Stroke};

/// Default series colours (colour-blind-friendly Okabe–Ito order, then greys).
pub const PALETTE: [Rgb; 8] = [
    [0, 114, 178],
    [213, 94, 0],
    [0, 158, 115],
    [204, 121, 167],
    [230, 159, 0],
    [86, 180, 233],
    [0, 0, 0],
    [120, 120, 120],
];

const WHITE: Rgb = [255, 255, 255];
const INK: Rgb = [20, 20, 20];
const GRID: Rgb = [225, 225, 225];
const GRID_MINOR: Rgb = [242, 242, 242];

/// Where the legend box sits inside the plot area.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum LegendPosition {
    /// Upper left corner.
    TopLeft,
    /// Upper right corner (default).
    #[default]
    TopRight,
    /// Lower left corner.
    BottomLeft,
    /// Lower right corner.
    BottomRight,
}

/// One named series of (x, y) points.
#[derive(Clone, Debug, PartialEq)]
pub struct Series {
    /// Legend entry.
    pub name: String,
    /// Points in data coordinates, drawn in order.
    pub points: Vec<(f64, f64)>,
    /// How its line is drawn.
    pub stroke: Stroke,
}

/// A line-plot builder.
#[derive(Clone, Debug, PartialEq)]
pub struct LinePlot {
    title: String,
    x_label: String,
    y_label: String,
    series: Vec<Series>,
    log_x: bool,
    x_range: Option<(f64, f64)>,
    y_range: Option<(f64, f64)>,
    width: u32,
    height: u32,
    text_scale: u32,
    legend: LegendPosition,
}

impl LinePlot {
    /// An empty 960 × 640 plot with a title.
    pub fn new(title: impl Into<String>) -> Self {
        Self {
            title: title.into(),
            x_label: String::new(),
            y_label: String::new(),
            series: Vec::new(),
            log_x: false,
            x_range: None,
            y_range: None,
            width: 960,
            height: 640,
            text_scale: 2,
            legend: LegendPosition::TopRight,
        }
    }
    /// Where to put the legend.
    pub fn legend(mut self, position: LegendPosition) -> Self {
        self.legend = position;
        self
    }
    /// Label under the x axis.
    pub fn x_label(mut self, label: impl Into<String>) -> Self {
        self.x_label = label.into();
        self
    }
    /// Label beside the y axis (drawn vertically).
    pub fn y_label(mut self, label: impl Into<String>) -> Self {
        self.y_label = label.into();
        self
    }
    /// Logarithmic x axis (base 10).
    pub fn log_x(mut self, on: bool) -> Self {
        self.log_x = on;
        self
    }
    /// Fixed x range (data units).
    pub fn x_range(mut self, lo: f64, hi: f64) -> Self {
        self.x_range = Some((lo, hi));
        self
    }
    /// Fixed y range (data units).
    pub fn y_range(mut self, lo: f64, hi: f64) -> Self {
        self.y_range = Some((lo, hi));
        self
    }
    /// Image size in pixels (at least 200 × 150).
    pub fn size(mut self, width: u32, height: u32) -> Self {
        self.width = width.max(200);
        self.height = height.max(150);
        self
    }
    /// Glyph magnification of all text (1 = 8 px font).
    pub fn text_scale(mut self, scale: u32) -> Self {
        self.text_scale = scale.clamp(1, 8);
        self
    }
    /// Adds a solid series in the next palette colour.
    pub fn series(
        self,
        name: impl Into<String>,
        points: impl IntoIterator<Item = (f64, f64)>,
    ) -> Self {
        let color = PALETTE[self.series.len() % PALETTE.len()];
        self.series_styled(name, points, Stroke::solid(color, 2))
    }
    /// Adds a series with an explicit stroke.
    pub fn series_styled(
        mut self,
        name: impl Into<String>,
        points: impl IntoIterator<Item = (f64, f64)>,
        stroke: Stroke,
    ) -> Self {
        self.series.push(Series {
            name: name.into(),
            points: points.into_iter().collect(),
            stroke,
        });
        self
    }

    fn to_axis_x(&self, x: f64) -> f64 {
        if self.log_x {
            if x > 0.0 { x.log10() } else { f64::NAN }
        } else {
            x
        }
    }

    /// Data ranges in axis coordinates (log10 for a log x axis).
    fn ranges(&self) -> Result<[(f64, f64); 2], ReportError> {
        let pts: Vec<(f64, f64)> = self
            .series
            .iter()
            .flat_map(|s| s.points.iter())
            .map(|&(x, y)| (self.to_axis_x(x), y))
            .filter(|(x, y)| x.is_finite() && y.is_finite())
            .collect();
        let explicit_x = self
            .x_range
            .map(|(a, b)| (self.to_axis_x(a), self.to_axis_x(b)));
        if pts.is_empty() && (explicit_x.is_none() || self.y_range.is_none()) {
            return Err(ReportError::NoData);
        }
        let span = |f: fn(&(f64, f64)) -> f64| {
            pts.iter()
                .map(f)
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                    (a.min(v), b.max(v))
                })
        };
        let widen = |(lo, hi): (f64, f64), pad: f64| {
            if hi > lo {
                let p = (hi - lo) * pad;
                (lo - p, hi + p)
            } else {
                let d = if lo == 0.0 { 1.0 } else { lo.abs() * 0.1 };
                (lo - d, hi + d)
            }
        };
        let x = match explicit_x {
            Some((a, b)) if a.is_finite() && b.is_finite() && b > a => (a, b),
            Some(_) => return Err(ReportError::BadRange("x")),
            None => widen(span(|p| p.0), 0.0),
        };
        let y = match self.y_range {
            Some((a, b)) if a.is_finite() && b.is_finite() && b > a => (a, b),
            Some(_) => return Err(ReportError::BadRange("y")),
            None => widen(span(|p| p.1), 0.05),
        };
        Ok([x, y])
    }

    /// Renders the plot.
    pub fn render(&self) -> Result<Canvas, ReportError> {
        let [(x0, x1), (y0, y1)] = self.ranges()?;
        let s = self.text_scale;
        let g = i64::from(GLYPH_PX * s);
        let mut c = Canvas::new(self.width, self.height, WHITE);
        let x_ticks = if self.log_x {
            log_ticks(x0, x1)
        } else {
            linear_ticks(x0, x1)
        };
        let y_ticks = linear_ticks(y0, y1);
        let y_label_w = y_ticks
            .iter()
            .map(|t| Canvas::text_width(&t.label, s))
            .max()
            .unwrap_or(0);
        // Layout (pixels).
        let left = g / 2
            + if self.y_label.is_empty() {
                0
            } else {
                g + g / 2
            }
            + i64::from(y_label_w)
            + g / 2
            + 6;
        let right = i64::from(self.width) - g * 2;
        let top = if self.title.is_empty() { g } else { g * 3 };
        let bottom = i64::from(self.height) - g * if self.x_label.is_empty() { 2 } else { 4 };
        if right - left < 20 || bottom - top < 20 {
            return Err(ReportError::TooSmall);
        }
        let px = |x: f64| left as f64 + (x - x0) / (x1 - x0) * (right - left) as f64;
        let py = |y: f64| bottom as f64 - (y - y0) / (y1 - y0) * (bottom - top) as f64;
        // Grid and ticks.
        for t in &x_ticks {
            let x = px(t.value).round() as i64;
            c.fill_rect(
                x,
                top,
                1,
                bottom - top,
                if t.major { GRID } else { GRID_MINOR },
            );
            if t.major {
                c.fill_rect(x, bottom, 1, 6, INK);
                let w = i64::from(Canvas::text_width(&t.label, s));
                c.text(x - w / 2, bottom + 10, &t.label, INK, s);
            }
        }
        for t in &y_ticks {
            let y = py(t.value).round() as i64;
            c.fill_rect(left, y, right - left, 1, GRID);
            c.fill_rect(left - 6, y, 6, 1, INK);
            let w = i64::from(Canvas::text_width(&t.label, s));
            c.text(left - 10 - w, y - g / 2, &t.label, INK, s);
        }
        c.stroke_rect(left, top, right - left + 1, bottom - top + 1, INK);
        // Title and labels: centred on the plot area, or on the image and at a smaller scale
        // when they would not fit.
        let width = i64::from(self.width);
        let place = |text: &str, lo: i64, hi: i64| {
            let mut scale = s;
            while scale > 1 && i64::from(Canvas::text_width(text, scale)) > width - 8 {
                scale -= 1;
            }
            let w = i64::from(Canvas::text_width(text, scale));
            let (lo, hi) = if w > hi - lo { (0, width) } else { (lo, hi) };
            (((lo + hi) / 2 - w / 2).max(0), scale)
        };
        let (tx, ts) = place(&self.title, left, right);
        c.text(tx, g, &self.title, INK, ts);
        let (lx, ls) = place(&self.x_label, left, right);
        c.text(lx, bottom + 10 + g + g / 2, &self.x_label, INK, ls);
        if !self.y_label.is_empty() {
            let h = i64::from(Canvas::text_width(&self.y_label, s));
            c.text_vertical(g / 2, (top + bottom) / 2 - h / 2, &self.y_label, INK, s);
        }
        // Series.
        let clip = ClipRect {
            x_min: left as f64 + 1.0,
            y_min: top as f64 + 1.0,
            x_max: right as f64 - 1.0,
            y_max: bottom as f64 - 1.0,
        };
        for series in &self.series {
            let mut run: Vec<(f64, f64)> = Vec::new();
            for &(x, y) in &series.points {
                let ax = self.to_axis_x(x);
                if ax.is_finite() && y.is_finite() {
                    run.push((px(ax), py(y)));
                } else {
                    c.polyline(&run, &series.stroke, clip);
                    run.clear();
                }
            }
            c.polyline(&run, &series.stroke, clip);
            if let [only] = run.as_slice() {
                c.fill_rect(
                    only.0.round() as i64 - 2,
                    only.1.round() as i64 - 2,
                    5,
                    5,
                    series.stroke.color,
                );
            }
        }
        self.draw_legend(&mut c, (left, top, right, bottom));
        Ok(c)
    }

    fn draw_legend(&self, c: &mut Canvas, (left, top, right, bottom): (i64, i64, i64, i64)) {
        if self.series.is_empty() {
            return;
        }
        let s = self.text_scale;
        let g = i64::from(GLYPH_PX * s);
        let sample = g * 3;
        let name_w = self
            .series
            .iter()
            .map(|x| Canvas::text_width(&x.name, s))
            .max()
            .unwrap_or(0);
        let w = sample + g + i64::from(name_w) + g;
        let h = self.series.len() as i64 * (g + g / 2) + g / 2;
        let x = match self.legend {
            LegendPosition::TopLeft | LegendPosition::BottomLeft => left + g / 2,
            LegendPosition::TopRight | LegendPosition::BottomRight => right - w - g / 2,
        };
        let y = match self.legend {
            LegendPosition::TopLeft | LegendPosition::TopRight => top + g / 2,
            LegendPosition::BottomLeft | LegendPosition::BottomRight => bottom - h - g / 2,
        };
        c.fill_rect(x, y, w, h, WHITE);
        c.stroke_rect(x, y, w, h, INK);
        for (k, series) in self.series.iter().enumerate() {
            let row = y + g / 2 + k as i64 * (g + g / 2);
            let mid = (row + g / 2) as f64;
            let stroke = Stroke {
                dash: series.stroke.dash.map(|(a, b)| (a.min(8.0), b.min(6.0))),
                ..series.stroke
            };
            c.line(
                ((x + g / 2) as f64, mid),
                ((x + g / 2 + sample) as f64, mid),
                &stroke,
                ClipRect::NONE,
            );
            c.text(x + g + sample, row, &series.name, INK, s);
        }
    }

    /// Renders and writes the plot as PNG.
    pub fn save_png(&self, path: impl AsRef<Path>) -> Result<(), ReportError> {
        self.render()?.save_png(path.as_ref())
    }
}

/// One axis tick.
#[derive(Clone, Debug, PartialEq)]
struct Tick {
    value: f64,
    label: String,
    major: bool,
}

/// 1–2–5 ticks covering [lo, hi], about 5–10 of them.
fn linear_ticks(lo: f64, hi: f64) -> Vec<Tick> {
    let raw = (hi - lo) / 6.0;
    let mag = 10f64.powf(raw.log10().floor());
    let norm = raw / mag;
    let step = mag
        * if norm < 1.5 {
            1.0
        } else if norm < 3.0 {
            2.0
        } else if norm < 7.0 {
            5.0
        } else {
            10.0
        };
    let decimals = (-step.log10().floor()).max(0.0) as usize;
    let first = (lo / step).ceil() as i64;
    let last = (hi / step + 1e-9).floor() as i64;
    (first..=last)
        .map(|k| {
            let value = k as f64 * step;
            let mut label = format!("{value:.decimals$}");
            if label
                .trim_start_matches('-')
                .chars()
                .all(|ch| ch == '0' || ch == '.')
            {
                label = format!("{:.decimals$}", 0.0);
            }
            Tick {
                value,
                label,
                major: true,
            }
        })
        .collect()
}

/// Decade ticks (major) and 2…9 sub-ticks (minor) for a log10 axis spanning [lo, hi] in log
/// units.
fn log_ticks(lo: f64, hi: f64) -> Vec<Tick> {
    let mut ticks = Vec::new();
    for k in (lo.floor() as i64)..=(hi.ceil() as i64) {
        for m in 1..10 {
            let value = k as f64 + f64::from(m).log10();
            if value < lo - 1e-9 || value > hi + 1e-9 {
                continue;
            }
            let label = if m != 1 {
                String::new()
            } else if (-3..=3).contains(&k) {
                let decimals = (-k).max(0) as usize;
                format!("{:.decimals$}", 10f64.powi(k as i32))
            } else {
                format!("1e{k}")
            };
            ticks.push(Tick {
                value,
                label,
                major: m == 1,
            });
        }
    }
    ticks
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_are_nice_and_cover_the_range() {
        let t = linear_ticks(0.0, 1.0);
        let labels: Vec<&str> = t.iter().map(|t| t.label.as_str()).collect();
        assert_eq!(labels, ["0.0", "0.2", "0.4", "0.6", "0.8", "1.0"]);
        let t = linear_ticks(-0.05, 90.0);
        assert_eq!(t.first().map(|t| t.label.as_str()), Some("0"));
        assert_eq!(t.last().map(|t| t.value), Some(80.0));
        let l = log_ticks(-3.0, 1.0);
        let majors: Vec<&str> = l
            .iter()
            .filter(|t| t.major)
            .map(|t| t.label.as_str())
            .collect();
        assert_eq!(majors, ["0.001", "0.01", "0.1", "1", "10"]);
        assert_eq!(l.iter().filter(|t| !t.major).count(), 32);
    }

    #[test]
    fn renders_series_in_their_colours_and_rejects_empty_plots() {
        let plot = LinePlot::new("test")
            .x_label("x")
            .y_label("y")
            .series("a", (0..50).map(|i| (f64::from(i), f64::from(i).sin())))
            .series("b", [(0.0, 0.0), (f64::NAN, 1.0), (49.0, 1.0)]);
        let c = plot.render().unwrap();
        let has = |color: Rgb| c.as_bytes().chunks(3).any(|p| p == color);
        assert!(has(PALETTE[0]) && has(PALETTE[1]));
        assert_eq!(
            LinePlot::new("empty").render().unwrap_err(),
            ReportError::NoData
        );
        let nan_only = LinePlot::new("nan").series("n", [(f64::NAN, 1.0)]);
        assert_eq!(nan_only.render().unwrap_err(), ReportError::NoData);
        let log = LinePlot::new("log")
            .log_x(true)
            .series("l", [(0.0, 1.0), (1e-3, 1.0), (10.0, 2.0)]);
        assert!(log.render().is_ok());
        assert_eq!(
            LinePlot::new("r")
                .y_range(1.0, 0.0)
                .series("a", [(0.0, 0.0)])
                .render()
                .unwrap_err(),
            ReportError::BadRange("y")
        );
    }

    #[test]
    fn writes_a_png_that_decodes() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("p.png");
        LinePlot::new("png")
            .size(320, 240)
            .text_scale(1)
            .series("a", [(0.0, 0.0), (1.0, 1.0)])
            .save_png(&path)
            .unwrap();
        let img = image::open(&path).unwrap().to_rgb8();
        assert_eq!(img.dimensions(), (320, 240));
    }
}
