//! Line plots through `plotters`: title, axes with numeric ticks and labels (any Unicode the
//! bundled font has: η, σ, °), a legend, several coloured solid or dashed series, an optional
//! logarithmic x axis; rendered to an RGB image and saved as PNG.
//!
//! Contract: `LinePlot::new(title).x_label(..).y_label(..).series(name, points)….save_png(path)`.
//! Non-finite points (and x ≤ 0 on a log axis) break a series' line instead of failing; a
//! series of one point is drawn as a dot; a plot with no drawable point at all is an error
//! ([`ReportError::NoData`]). Ranges default to the data (y padded by 5 %).

use std::ops::Range;
use std::path::Path;

use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::prelude::*;

use super::ReportError;
use super::colour::Rgb;
use super::font::{FAMILY, ensure_registered};

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

/// How a series' line is drawn.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Stroke {
    /// Colour.
    pub color: Rgb,
    /// Width in pixels (≥ 1).
    pub thickness: u32,
    /// `Some((on, off))`: dashed, lengths in pixels.
    pub dash: Option<(f64, f64)>,
}

impl Stroke {
    /// A solid line.
    pub fn solid(color: Rgb, thickness: u32) -> Self {
        Self {
            color,
            thickness,
            dash: None,
        }
    }
}

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
    /// Dots at the points and no line between them.
    pub dots: bool,
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
    legend: LegendPosition,
    y_names: Vec<String>,
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
            legend: LegendPosition::TopRight,
            y_names: Vec::new(),
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
    /// Image size in pixels (at least 320 × 240).
    pub fn size(mut self, width: u32, height: u32) -> Self {
        self.width = width.max(320);
        self.height = height.max(240);
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
            dots: false,
        });
        self
    }

    /// Adds a series drawn as dots at its points, no line between them, in the next palette
    /// colour.
    pub fn dots(
        mut self,
        name: impl Into<String>,
        points: impl IntoIterator<Item = (f64, f64)>,
    ) -> Self {
        let color = PALETTE[self.series.len() % PALETTE.len()];
        self.series.push(Series {
            name: name.into(),
            points: points.into_iter().collect(),
            stroke: Stroke::solid(color, 3),
            dots: true,
        });
        self
    }

    /// Names the rows of a categorical y axis: y = k is row `names[k]`, drawn top to bottom,
    /// each tick labelled by its name (the y range becomes −½ … n − ½, reversed).
    pub fn y_names(mut self, names: Vec<String>) -> Self {
        let n = names.len() as f64;
        self.y_names = names;
        self.y_range = Some((-0.5, n - 0.5));
        self
    }

    fn drawable(&self, (x, y): (f64, f64)) -> bool {
        x.is_finite() && y.is_finite() && (!self.log_x || x > 0.0)
    }

    /// Data ranges (x in data units; a log axis spans whole data, not log units).
    fn ranges(&self) -> Result<[(f64, f64); 2], ReportError> {
        let pts: Vec<(f64, f64)> = self
            .series
            .iter()
            .flat_map(|s| s.points.iter().copied())
            .filter(|&p| self.drawable(p))
            .collect();
        if pts.is_empty() && (self.x_range.is_none() || self.y_range.is_none()) {
            return Err(ReportError::NoData);
        }
        let span = |f: fn(&(f64, f64)) -> f64| {
            pts.iter()
                .map(f)
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                    (a.min(v), b.max(v))
                })
        };
        let log = self.log_x;
        let widen = |(lo, hi): (f64, f64), pad: f64, log: bool| {
            if hi > lo {
                let p = (hi - lo) * pad;
                (lo - p, hi + p)
            } else if log {
                (lo / 2.0, hi * 2.0)
            } else {
                let d = if lo == 0.0 { 1.0 } else { lo.abs() * 0.1 };
                (lo - d, hi + d)
            }
        };
        let valid = |(a, b): (f64, f64)| a.is_finite() && b.is_finite() && b > a;
        let x = match self.x_range {
            Some(r) if valid(r) && (!log || r.0 > 0.0) => r,
            Some(_) => return Err(ReportError::BadRange("x")),
            None => widen(span(|p| p.0), 0.0, log),
        };
        let y = match self.y_range {
            Some(r) if valid(r) => r,
            Some(_) => return Err(ReportError::BadRange("y")),
            None => widen(span(|p| p.1), 0.05, false),
        };
        Ok([x, y])
    }

    /// Renders the plot.
    pub fn render(&self) -> Result<image::RgbImage, ReportError> {
        let [(x0, x1), (y0, y1)] = self.ranges()?;
        ensure_registered();
        let mut buf = vec![255u8; self.width as usize * self.height as usize * 3];
        {
            let root =
                BitMapBackend::with_buffer(&mut buf, (self.width, self.height)).into_drawing_area();
            if self.log_x {
                self.draw_on(&root, (x0..x1).log_scale(), y0..y1)?;
            } else {
                self.draw_on(&root, x0..x1, y0..y1)?;
            }
            root.present().map_err(ReportError::draw)?;
        }
        image::RgbImage::from_raw(self.width, self.height, buf).ok_or(ReportError::EmptyCanvas)
    }

    fn draw_on<X>(
        &self,
        root: &DrawingArea<BitMapBackend<'_>, plotters::coord::Shift>,
        x: X,
        y: Range<f64>,
    ) -> Result<(), ReportError>
    where
        X: AsRangedCoord<Value = f64>,
        X::CoordDescType: ValueFormatter<f64>,
    {
        let text = |size: f64| (FAMILY, size).into_font().color(&INK);
        let mut chart = ChartBuilder::on(root)
            .caption(&self.title, text(24.0))
            .margin(16)
            .x_label_area_size(56)
            .y_label_area_size(if !self.y_names.is_empty() {
                // room for the longest row name at the label font's ~9 px per character
                (self
                    .y_names
                    .iter()
                    .map(|n| n.chars().count())
                    .max()
                    .unwrap_or(0) as u32
                    * 9
                    + 24)
                    .clamp(56, 420)
            } else if self.y_label.is_empty() {
                56
            } else {
                80
            })
            .build_cartesian_2d(x, y)
            .map_err(ReportError::draw)?;
        let log_x = self.log_x;
        let x_tick = move |v: &f64| tick_label(*v, log_x);
        let names = &self.y_names;
        let y_tick = |v: &f64| {
            if names.is_empty() {
                return tick_label(*v, false);
            }
            // Rows are drawn top to bottom: row k sits at y = n − 1 − k.
            let k = names.len() as f64 - 1.0 - v.round();
            if (v - v.round()).abs() < 1e-6 && k >= 0.0 && (k as usize) < names.len() {
                names[k as usize].clone()
            } else {
                String::new()
            }
        };
        let mut mesh = chart.configure_mesh();
        if !self.y_names.is_empty() {
            mesh.y_labels(self.y_names.len() * 2 + 1);
        }
        mesh.x_label_formatter(&x_tick)
            .y_label_formatter(&y_tick)
            .x_desc(self.x_label.as_str())
            .y_desc(self.y_label.as_str())
            .axis_desc_style(text(20.0))
            .label_style(text(17.0))
            .bold_line_style(RGBColor(222, 222, 222))
            .light_line_style(RGBColor(244, 244, 244))
            .axis_style(INK)
            .draw()
            .map_err(ReportError::draw)?;
        let mut labelled = false;
        for series in &self.series {
            let Stroke {
                color: [r, g, b],
                thickness,
                dash,
            } = series.stroke;
            let style = RGBColor(r, g, b).stroke_width(thickness.max(1));
            let mut first = true;
            // Categorical rows count from the top.
            let flip = |(x, y): (f64, f64)| {
                if self.y_names.is_empty() {
                    (x, y)
                } else {
                    (x, self.y_names.len() as f64 - 1.0 - y)
                }
            };
            let points: Vec<(f64, f64)> = series.points.iter().copied().map(flip).collect();
            for run in points.split(|&p| !self.drawable(p)) {
                let anno = match (run, dash) {
                    ([], _) => continue,
                    (_, _) if series.dots => chart.draw_series(
                        run.iter()
                            .map(|p| Circle::new(*p, thickness + 2, style.filled())),
                    ),
                    ([p], _) => chart.draw_series(std::iter::once(Circle::new(
                        *p,
                        thickness + 2,
                        style.filled(),
                    ))),
                    (_, None) => chart.draw_series(LineSeries::new(run.iter().copied(), style)),
                    (_, Some((on, off))) => chart.draw_series(DashedLineSeries::new(
                        run.iter().copied(),
                        on.max(1.0) as u32,
                        off.max(1.0) as u32,
                        style,
                    )),
                }
                .map_err(ReportError::draw)?;
                if std::mem::take(&mut first) && !series.name.is_empty() {
                    labelled = true;
                    let anno = anno.label(series.name.as_str());
                    match dash {
                        _ if series.dots => anno.legend(move |(x, y)| {
                            Circle::new((x + 14, y), thickness + 2, style.filled())
                        }),
                        None => anno
                            .legend(move |(x, y)| PathElement::new([(x, y), (x + 28, y)], style)),
                        // short dashes, so a dashed series reads as dashed in the legend
                        Some(_) => anno.legend(move |(x, y)| {
                            plotters::element::DashedPathElement::new(
                                [(x, y), (x + 28, y)],
                                7,
                                4,
                                style,
                            )
                        }),
                    };
                }
            }
        }
        if labelled {
            chart
                .configure_series_labels()
                .position(match self.legend {
                    LegendPosition::TopLeft => SeriesLabelPosition::UpperLeft,
                    LegendPosition::TopRight => SeriesLabelPosition::UpperRight,
                    LegendPosition::BottomLeft => SeriesLabelPosition::LowerLeft,
                    LegendPosition::BottomRight => SeriesLabelPosition::LowerRight,
                })
                .margin(12)
                .legend_area_size(36)
                .label_font(text(17.0))
                .background_style(WHITE.mix(0.9))
                .border_style(INK)
                .draw()
                .map_err(ReportError::draw)?;
        }
        Ok(())
    }

    /// Renders and writes the plot as PNG (whole or not at all).
    pub fn save_png(&self, path: impl AsRef<Path>) -> Result<(), ReportError> {
        super::save_rgb(&self.render()?, path.as_ref())
    }
}

/// A tick's text: the value with no trailing zeros; on a log axis only 1, 2 and 5 times a
/// power of ten are labelled (the other ticks stay, unlabelled), so labels never crowd.
fn tick_label(v: f64, log: bool) -> String {
    if log && v > 0.0 {
        let mantissa = v / 10f64.powf(v.log10().floor());
        if ![1.0, 2.0, 5.0, 10.0]
            .iter()
            .any(|m| (mantissa - m).abs() < 1e-6 * m)
        {
            return String::new();
        }
    }
    let text = format!("{v:.6}");
    let text = text.trim_end_matches('0').trim_end_matches('.');
    if text == "-0" {
        "0".into()
    } else {
        text.into()
    }
}

/// Text and axis colour.
const INK: RGBColor = RGBColor(20, 20, 20);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn renders_series_in_their_colours_and_rejects_empty_plots() {
        let plot = LinePlot::new("test η, σ in °")
            .x_label("x")
            .y_label("y")
            .series("a", (0..50).map(|i| (f64::from(i), f64::from(i).sin())))
            .series("b", [(0.0, 0.0), (f64::NAN, 1.0), (49.0, 1.0)]);
        let c = plot.render().unwrap();
        let has = |color: Rgb| c.pixels().any(|p| p.0 == color);
        assert!(has(PALETTE[0]) && has(PALETTE[1]));
        assert!(!has(PALETTE[2]), "only two series");
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
        let zero_only = LinePlot::new("log").log_x(true).series("l", [(0.0, 1.0)]);
        assert_eq!(zero_only.render().unwrap_err(), ReportError::NoData);
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
    fn dashed_series_leave_gaps_and_text_is_drawn() {
        let stroke = Stroke {
            color: [200, 0, 0],
            thickness: 2,
            dash: Some((10.0, 10.0)),
        };
        let count = |p: &LinePlot| {
            p.render()
                .unwrap()
                .pixels()
                .filter(|px| px.0 == [200, 0, 0])
                .count()
        };
        let line = |dash| {
            LinePlot::new("")
                .x_range(0.0, 1.0)
                .y_range(0.0, 1.0)
                .series_styled("", [(0.0, 0.5), (1.0, 0.5)], Stroke { dash, ..stroke })
        };
        let (solid, dashed) = (count(&line(None)), count(&line(stroke.dash)));
        assert!(dashed > 0 && dashed < solid * 3 / 4, "{dashed} vs {solid}");
        // the title is drawn: a plot with a title has more ink than one without
        let ink = |p: &LinePlot| {
            p.render()
                .unwrap()
                .pixels()
                .filter(|px| px.0[0] < 128)
                .count()
        };
        assert!(
            ink(&LinePlot::new("ηηη σσσ").x_range(0.0, 1.0).y_range(0.0, 1.0)) > ink(&line(None))
        );
    }

    #[test]
    fn tick_labels_are_short_and_sparse_on_log_axes() {
        assert_eq!(tick_label(10.0, false), "10");
        assert_eq!(tick_label(0.25, false), "0.25");
        assert_eq!(tick_label(-0.0, false), "0");
        assert_eq!(tick_label(3.0, true), "");
        assert_eq!(tick_label(20.0, true), "20");
        assert_eq!(tick_label(0.5, true), "0.5");
    }

    #[test]
    fn writes_a_png_that_decodes() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("p.png");
        LinePlot::new("png")
            .size(320, 240)
            .series("a", [(0.0, 0.0), (1.0, 1.0)])
            .save_png(&path)
            .unwrap();
        let img = image::open(&path).unwrap().to_rgb8();
        assert_eq!(img.dimensions(), (320, 240));
    }
}
