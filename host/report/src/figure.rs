//! Framed pictures: one or more images (pixel for pixel, never resampled) in a grid, each with
//! an optional caption, under an optional title, with the keys a reader needs below them —
//! colour bars with numeric ticks and a label, the 2-D AoLP × DoLP key of the HSV composite,
//! or labelled swatches for categorical images. Text, axes and ticks are drawn by `plotters`
//! with the bundled font; the images are copied in unchanged.
//!
//! Contract: with no title and no captions ([`Figure::bare`]) the first image's pixel (x, y)
//! is the figure's pixel (x, y) — pictures whose rows must stay aligned with an input frame
//! carry their keys underneath. Every figure is at least [`Figure::min_width`] wide (240 px by
//! default) so its keys stay legible under small images. Images of different sizes are an
//! error; a figure with no image is [`ReportError::EmptyCanvas`].

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use super::ReportError;
pub use super::colour::NO_DATA;
use super::colour::{ColourMap, Rgb, aolp_dolp};
use super::font::{FAMILY, ensure_registered};

/// Background of framed pictures (dark, so images read as they would on a screen).
pub const PAPER: Rgb = [24, 24, 24];
/// Text and axes on [`PAPER`].
pub const INK: Rgb = [235, 235, 235];

/// An RGB image, row-major, origin top-left.
#[derive(Clone, Debug, PartialEq)]
pub struct Picture {
    /// Width, px.
    pub width: u32,
    /// Height, px.
    pub height: u32,
    /// `width × height` pixels.
    pub pixels: Vec<Rgb>,
}

impl Picture {
    /// A scalar field through `map` over `[lo, hi]`; `None` and non-finite values are
    /// [`NO_DATA`].
    pub fn scalar(
        width: u32,
        height: u32,
        values: &[Option<f64>],
        map: ColourMap,
        lo: f64,
        hi: f64,
    ) -> Self {
        let span = if (hi - lo).abs() > 1e-300 {
            hi - lo
        } else {
            1.0
        };
        Self {
            width,
            height,
            pixels: values
                .iter()
                .map(|v| match v {
                    Some(v) if v.is_finite() => map.at((v - lo) / span),
                    _ => NO_DATA,
                })
                .collect(),
        }
    }
}

/// A key drawn under the images.
#[derive(Clone, Debug, PartialEq)]
pub enum Key {
    /// A colour bar: `map` over [`lo`, `hi`] with numeric ticks and `label` (units included).
    Bar {
        /// The map the images use.
        map: ColourMap,
        /// Value at the map's 0.
        lo: f64,
        /// Value at the map's 1.
        hi: f64,
        /// What the value is, with its unit, e.g. "η" or "AoLP (°)".
        label: String,
    },
    /// The key of [`crate::colour::aolp_dolp`]: AoLP 0–180° across (hue), DoLP 0–1 up, as the
    /// colour's saturation (value 1) or, with `dolp_as_value`, as its value (saturation 1).
    AolpDolp {
        /// DoLP scales the value (unpolarised is black) instead of the saturation (white).
        dolp_as_value: bool,
    },
    /// Labelled colour squares (categorical images).
    Swatches(Vec<(Rgb, String)>),
}

impl Key {
    /// Height of the key's band, px, at `width`.
    fn height(&self, width: u32) -> u32 {
        match self {
            Key::Bar { .. } => 56,
            Key::AolpDolp { .. } => 130,
            Key::Swatches(items) => {
                let mut rows = 1;
                let mut x = 0;
                for (_, label) in items {
                    let w = swatch_width(label);
                    if x + w > width.saturating_sub(2 * MARGIN) && x > 0 {
                        rows += 1;
                        x = 0;
                    }
                    x += w;
                }
                rows * SWATCH_ROW + 8
            }
        }
    }
}

/// A figure builder.
#[derive(Clone, Debug, PartialEq)]
pub struct Figure {
    title: String,
    images: Vec<(String, Picture)>,
    columns: usize,
    keys: Vec<Key>,
    min_width: u32,
}

const MARGIN: u32 = 8;
const GAP: u32 = 8;
const TITLE_PX: u32 = 26;
const CAPTION_PX: u32 = 20;
const SWATCH_ROW: u32 = 20;
const TITLE_FONT: f64 = 17.0;
const TEXT_FONT: f64 = 14.0;

fn swatch_width(label: &str) -> u32 {
    // a 14 px square, a space, the label, a gap
    20 + text_width(label, TEXT_FONT) + 16
}

/// Width of `text` in the bundled font at `size` px; 0 for no text.
fn text_width(text: &str, size: f64) -> u32 {
    if text.is_empty() {
        return 0;
    }
    ensure_registered();
    let font = FontDesc::new(FontFamily::Name(FAMILY), size, FontStyle::Normal);
    font.box_size(text).map_or_else(
        |_| (text.chars().count() as f64 * size * 0.6) as u32,
        |(w, _)| w,
    )
}

/// A colour-bar tick: `decimals` places, and never "-0.00".
fn bar_tick(v: f64, decimals: usize) -> String {
    let text = format!("{v:.decimals$}");
    match text.strip_prefix('-') {
        Some(rest) if rest.chars().all(|c| c == '0' || c == '.') => rest.to_string(),
        _ => text,
    }
}

impl Figure {
    /// A figure with a title line above its images.
    pub fn new(title: impl Into<String>) -> Self {
        Self {
            title: title.into(),
            images: Vec::new(),
            columns: 1,
            keys: Vec::new(),
            min_width: 240,
        }
    }
    /// A figure without title or margins: its first image starts at pixel (0, 0).
    pub fn bare() -> Self {
        Self::new("")
    }
    /// Adds an image with a caption above it (empty: none).
    pub fn image(mut self, caption: impl Into<String>, picture: Picture) -> Self {
        self.images.push((caption.into(), picture));
        self
    }
    /// Images per row (default 1).
    pub fn columns(mut self, columns: usize) -> Self {
        self.columns = columns.max(1);
        self
    }
    /// Adds a key under the images.
    pub fn key(mut self, key: Key) -> Self {
        self.keys.push(key);
        self
    }
    /// The least width of the figure, px.
    pub fn min_width(mut self, px: u32) -> Self {
        self.min_width = px;
        self
    }

    fn bare_layout(&self) -> bool {
        self.title.is_empty() && self.images.iter().all(|(c, _)| c.is_empty())
    }

    /// Renders the figure.
    pub fn render(&self) -> Result<image::RgbImage, ReportError> {
        let Some((_, first)) = self.images.first() else {
            return Err(ReportError::EmptyCanvas);
        };
        let (iw, ih) = (first.width, first.height);
        if self.images.iter().any(|(_, p)| {
            (p.width, p.height) != (iw, ih) || p.pixels.len() != iw as usize * ih as usize
        }) {
            return Err(ReportError::ImageSize);
        }
        let bare = self.bare_layout();
        let pad = if bare { 0 } else { MARGIN };
        let cols = self.columns.min(self.images.len()) as u32;
        let rows = self.images.len().div_ceil(self.columns) as u32;
        let caption = if self.images.iter().any(|(c, _)| !c.is_empty()) {
            CAPTION_PX
        } else {
            0
        };
        let title = if self.title.is_empty() { 0 } else { TITLE_PX };
        let grid_w = cols * iw + (cols - 1) * GAP;
        let width = (grid_w + 2 * pad)
            .max(self.min_width)
            .max(text_width(&self.title, TITLE_FONT) + 2 * MARGIN);
        let grid_h = rows * (ih + caption) + (rows - 1) * GAP;
        let top = pad + title;
        let keys_top = top + grid_h + if self.keys.is_empty() { pad } else { 4 };
        let key_heights: Vec<u32> = self.keys.iter().map(|k| k.height(width)).collect();
        let height = keys_top + key_heights.iter().sum::<u32>();
        if width == 0 || height == 0 {
            return Err(ReportError::EmptyCanvas);
        }
        ensure_registered();
        let mut buf = vec![0u8; width as usize * height as usize * 3];
        let left = (width - grid_w) / 2 * u32::from(!bare);
        let origin = |k: usize| {
            let (c, r) = (k as u32 % cols, k as u32 / cols);
            (
                left + c * (iw + GAP),
                top + r * (ih + caption + GAP) + caption,
            )
        };
        {
            let root = BitMapBackend::with_buffer(&mut buf, (width, height)).into_drawing_area();
            root.fill(&rgb(PAPER)).map_err(ReportError::draw)?;
            let ink = |size: f64| (FAMILY, size).into_font().color(&rgb(INK));
            if !self.title.is_empty() {
                root.draw_text(&self.title, &ink(TITLE_FONT), (MARGIN as i32, 6))
                    .map_err(ReportError::draw)?;
            }
            for (k, (text, _)) in self.images.iter().enumerate() {
                let (x, y) = origin(k);
                if !text.is_empty() {
                    root.draw_text(
                        text,
                        &ink(TEXT_FONT),
                        (x as i32 + 2, (y - caption + 3) as i32),
                    )
                    .map_err(ReportError::draw)?;
                }
            }
            let mut y = keys_top;
            for (key, h) in self.keys.iter().zip(&key_heights) {
                let area = root.clone().shrink((0, y), (width, *h));
                draw_key(&area, key, width)?;
                y += h;
            }
            root.present().map_err(ReportError::draw)?;
        }
        for (k, (_, picture)) in self.images.iter().enumerate() {
            let (x0, y0) = origin(k);
            for (row, src) in picture.pixels.chunks_exact(iw as usize).enumerate() {
                let start = ((y0 as usize + row) * width as usize + x0 as usize) * 3;
                for (dst, px) in buf[start..start + 3 * iw as usize]
                    .chunks_exact_mut(3)
                    .zip(src)
                {
                    dst.copy_from_slice(px);
                }
            }
        }
        image::RgbImage::from_raw(width, height, buf).ok_or(ReportError::EmptyCanvas)
    }

    /// Renders and writes the figure as an 8-bit RGB PNG (whole or not at all).
    pub fn save_png(&self, path: impl AsRef<Path>) -> Result<(), ReportError> {
        super::save_rgb(&self.render()?, path.as_ref())
    }
}

fn rgb([r, g, b]: Rgb) -> RGBColor {
    RGBColor(r, g, b)
}

/// Draws one key into its band.
fn draw_key(
    area: &DrawingArea<BitMapBackend<'_>, Shift>,
    key: &Key,
    width: u32,
) -> Result<(), ReportError> {
    let ink = |size: f64| (FAMILY, size).into_font().color(&rgb(INK));
    match key {
        Key::Bar { map, lo, hi, label } => {
            let (lo, hi) = if hi > lo && lo.is_finite() && hi.is_finite() {
                (*lo, *hi)
            } else {
                (lo - 0.5, lo + 0.5)
            };
            let mut chart = ChartBuilder::on(area)
                .margin_left(MARGIN + 4)
                .margin_right(MARGIN + 14)
                .margin_top(2)
                .x_label_area_size(38)
                .build_cartesian_2d(lo..hi, 0.0..1.0)
                .map_err(ReportError::draw)?;
            let decimals = tick_decimals(lo, hi);
            chart
                .configure_mesh()
                .disable_mesh()
                .disable_y_axis()
                .x_labels(6)
                .set_all_tick_mark_size(6)
                .x_label_formatter(&|v| bar_tick(*v, decimals))
                .x_desc(label.as_str())
                .axis_desc_style(ink(TEXT_FONT))
                .label_style(ink(TEXT_FONT - 1.0))
                .axis_style(rgb(INK))
                .draw()
                .map_err(ReportError::draw)?;
            let columns = chart.plotting_area().get_pixel_range().0;
            let n = (columns.end - columns.start).max(2);
            let step = (hi - lo) / f64::from(n);
            chart
                .draw_series((0..n).map(|k| {
                    let a = lo + step * f64::from(k);
                    let c = map.at((f64::from(k) + 0.5) / f64::from(n));
                    Rectangle::new([(a, 0.0), (a + step, 1.0)], rgb(c).filled())
                }))
                .map_err(ReportError::draw)?;
        }
        Key::AolpDolp { dolp_as_value } => {
            let side = area.split_horizontally(width.min(360));
            let mut chart = ChartBuilder::on(&side.0)
                .margin_left(MARGIN)
                .margin_right(MARGIN + 14)
                .margin_top(4)
                .x_label_area_size(38)
                .y_label_area_size(52)
                .build_cartesian_2d(0.0..180.0, 0.0..1.0)
                .map_err(ReportError::draw)?;
            chart
                .configure_mesh()
                .disable_mesh()
                .x_labels(5)
                .y_labels(3)
                .set_all_tick_mark_size(6)
                .x_label_formatter(&|v| format!("{v:.0}°"))
                .y_label_formatter(&|v| format!("{v:.1}"))
                .x_desc(if *dolp_as_value {
                    "AoLP (hue) × DoLP (value)"
                } else {
                    "AoLP (hue) × DoLP (saturation)"
                })
                .y_desc("DoLP")
                .axis_desc_style(ink(TEXT_FONT - 1.0))
                .label_style(ink(TEXT_FONT - 1.0))
                .axis_style(rgb(INK))
                .draw()
                .map_err(ReportError::draw)?;
            let (xs, ys) = chart.plotting_area().get_pixel_range();
            let (nx, ny) = ((xs.end - xs.start).max(2), (ys.end - ys.start).max(2));
            let (dx, dy) = (180.0 / f64::from(nx), 1.0 / f64::from(ny));
            chart
                .draw_series((0..nx).flat_map(|i| {
                    let dolp_as_value = *dolp_as_value;
                    (0..ny).map(move |j| {
                        let (a, d) = (dx * f64::from(i), dy * f64::from(j));
                        let (a_rad, d) = ((a + dx / 2.0).to_radians(), d + dy / 2.0);
                        let c = if dolp_as_value {
                            aolp_dolp(a_rad, 1.0, d)
                        } else {
                            aolp_dolp(a_rad, d, 1.0)
                        };
                        Rectangle::new([(a, d), (a + dx, d + dy)], rgb(c).filled())
                    })
                }))
                .map_err(ReportError::draw)?;
        }
        Key::Swatches(items) => {
            let (mut x, mut y) = (MARGIN, 4);
            for (colour, label) in items {
                let w = swatch_width(label);
                if x + w > width.saturating_sub(MARGIN) && x > MARGIN {
                    x = MARGIN;
                    y += SWATCH_ROW;
                }
                let (xi, yi) = (x as i32, y as i32);
                area.draw(&Rectangle::new(
                    [(xi, yi + 2), (xi + 14, yi + 16)],
                    rgb(*colour).filled(),
                ))
                .map_err(ReportError::draw)?;
                area.draw(&Rectangle::new(
                    [(xi, yi + 2), (xi + 14, yi + 16)],
                    rgb(INK),
                ))
                .map_err(ReportError::draw)?;
                area.draw_text(label, &ink(TEXT_FONT), (xi + 20, yi + 2))
                    .map_err(ReportError::draw)?;
                x += w;
            }
        }
    }
    Ok(())
}

/// Decimals that tell ticks over [lo, hi] apart (about six of them).
fn tick_decimals(lo: f64, hi: f64) -> usize {
    let step = (hi - lo).abs() / 6.0;
    if step.is_finite() && step > 0.0 {
        (-step.log10().floor()).clamp(0.0, 6.0) as usize
    } else {
        2
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp(w: u32, h: u32) -> Picture {
        let values: Vec<Option<f64>> = (0..w * h)
            .map(|i| (i % w != 0).then(|| f64::from(i % w) / f64::from(w)))
            .collect();
        Picture::scalar(w, h, &values, ColourMap::Viridis, 0.0, 1.0)
    }

    #[test]
    fn bare_figures_keep_image_pixels_in_place_and_add_keys_below() {
        let p = ramp(64, 20);
        let img = Figure::bare()
            .image("", p.clone())
            .key(Key::Bar {
                map: ColourMap::Grey,
                lo: 0.0,
                hi: 1.0,
                label: "DoLP".into(),
            })
            .render()
            .unwrap();
        assert_eq!(img.width(), 240, "narrow images get a key-wide figure");
        assert!(img.height() > 20 + 40);
        for (x, y) in [(0, 0), (1, 0), (63, 19), (30, 10)] {
            assert_eq!(img.get_pixel(x, y).0, p.pixels[(y * 64 + x) as usize]);
        }
        assert_eq!(img.get_pixel(0, 0).0, NO_DATA);
        // the key has ink (tick labels) and the bar's ends
        let below: Vec<Rgb> = (20..img.height())
            .flat_map(|y| (0..img.width()).map(move |x| (x, y)))
            .map(|(x, y)| img.get_pixel(x, y).0)
            .collect();
        assert!(below.contains(&INK));
        let grey_levels = below
            .iter()
            .filter(|c| c[0] == c[1] && c[1] == c[2])
            .map(|c| c[0]);
        let (darkest, brightest) = grey_levels.fold((255, 0), |(a, b), v| (v.min(a), v.max(b)));
        assert!(darkest < 4 && brightest > 250, "{darkest} {brightest}");
    }

    #[test]
    fn grids_captions_and_errors() {
        let fig = Figure::new("Mueller η σ")
            .columns(3)
            .image("M00", ramp(30, 30))
            .image("M01", ramp(30, 30))
            .image("M02", ramp(30, 30))
            .image("M10", ramp(30, 30))
            .key(Key::AolpDolp {
                dolp_as_value: false,
            })
            .key(Key::Swatches(vec![([255, 0, 0], "saturated".into())]));
        let img = fig.render().unwrap();
        assert!(img.width() >= 3 * 30 + 2 * GAP + 2 * MARGIN);
        assert!(img.pixels().any(|p| p.0 == [255, 0, 0]));
        let bad = Figure::new("x").image("", ramp(3, 3)).image("", ramp(4, 3));
        assert_eq!(bad.render().unwrap_err(), ReportError::ImageSize);
        assert_eq!(
            Figure::new("x").render().unwrap_err(),
            ReportError::EmptyCanvas
        );
        assert_eq!(tick_decimals(0.0, 1.0), 1);
        assert_eq!(tick_decimals(1.3, 1.75), 2);
        assert_eq!(tick_decimals(0.0, 180.0), 0);
        assert_eq!(bar_tick(-0.0001, 2), "0.00");
        assert_eq!(bar_tick(-0.1, 2), "-0.10");
        // a long title widens the figure instead of being cut
        let long = "a title much wider than the sixty-pixel image it stands above";
        let img = Figure::new(long).image("", ramp(60, 20)).render().unwrap();
        assert!(img.width() > 240 && img.width() >= text_width(long, TITLE_FONT));
    }
}
