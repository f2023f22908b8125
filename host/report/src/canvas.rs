//! An RGB8 raster canvas: pixels, clipped lines, filled rectangles and 8×8 bitmap text.
//!
//! Contract: every drawing call accepts any coordinates (off-canvas parts are clipped, nothing
//! panics); text uses the `font8x8` basic-Latin glyphs (non-ASCII characters draw as `?`)
//! magnified by an integer scale. [`Canvas::save_png`] writes an 8-bit RGB PNG.

use std::path::Path;

use font8x8::legacy::BASIC_LEGACY;

use super::ReportError;

/// An sRGB colour.
pub type Rgb = [u8; 3];

/// Glyph cell size of the bitmap font, in pixels at scale 1.
pub const GLYPH_PX: u32 = 8;

/// How a line is drawn.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Stroke {
    /// Colour.
    pub color: Rgb,
    /// Width in pixels (≥ 1).
    pub thickness: u32,
    /// `Some((on, off))`: dashed, lengths in pixels along the line.
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

/// An inclusive clip rectangle in pixel coordinates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClipRect {
    /// Left.
    pub x_min: f64,
    /// Top.
    pub y_min: f64,
    /// Right (inclusive).
    pub x_max: f64,
    /// Bottom (inclusive).
    pub y_max: f64,
}

impl ClipRect {
    /// No clipping beyond the canvas itself.
    pub const NONE: Self = Self {
        x_min: f64::NEG_INFINITY,
        y_min: f64::NEG_INFINITY,
        x_max: f64::INFINITY,
        y_max: f64::INFINITY,
    };
}

/// A width × height RGB8 image, row-major, origin top-left.
#[derive(Clone, Debug, PartialEq)]
pub struct Canvas {
    width: u32,
    height: u32,
    pixels: Vec<u8>,
}

impl Canvas {
    /// A canvas filled with `background`.
    pub fn new(width: u32, height: u32, background: Rgb) -> Self {
        let n = width as usize * height as usize;
        let mut pixels = Vec::with_capacity(n * 3);
        for _ in 0..n {
            pixels.extend_from_slice(&background);
        }
        Self {
            width,
            height,
            pixels,
        }
    }
    /// Width in pixels.
    pub fn width(&self) -> u32 {
        self.width
    }
    /// Height in pixels.
    pub fn height(&self) -> u32 {
        self.height
    }
    /// The pixel at (x, y), or `None` outside the canvas.
    pub fn get(&self, x: i64, y: i64) -> Option<Rgb> {
        self.index(x, y)
            .map(|i| [self.pixels[i], self.pixels[i + 1], self.pixels[i + 2]])
    }
    /// Sets one pixel; outside the canvas nothing happens.
    pub fn set(&mut self, x: i64, y: i64, color: Rgb) {
        if let Some(i) = self.index(x, y) {
            self.pixels[i..i + 3].copy_from_slice(&color);
        }
    }
    fn index(&self, x: i64, y: i64) -> Option<usize> {
        if x < 0 || y < 0 || x >= i64::from(self.width) || y >= i64::from(self.height) {
            return None;
        }
        Some((y as usize * self.width as usize + x as usize) * 3)
    }
    /// Fills the rectangle [x, x + w) × [y, y + h), clipped.
    pub fn fill_rect(&mut self, x: i64, y: i64, w: i64, h: i64, color: Rgb) {
        let x0 = x.max(0);
        let y0 = y.max(0);
        let x1 = (x + w).min(i64::from(self.width));
        let y1 = (y + h).min(i64::from(self.height));
        for yy in y0..y1 {
            for xx in x0..x1 {
                self.set(xx, yy, color);
            }
        }
    }
    /// Outline of a rectangle, 1 px.
    pub fn stroke_rect(&mut self, x: i64, y: i64, w: i64, h: i64, color: Rgb) {
        self.fill_rect(x, y, w, 1, color);
        self.fill_rect(x, y + h - 1, w, 1, color);
        self.fill_rect(x, y, 1, h, color);
        self.fill_rect(x + w - 1, y, 1, h, color);
    }
    /// A straight segment from `a` to `b` (pixel-centre coordinates), clipped to `clip` and to
    /// the canvas (Liang–Barsky).
    pub fn line(&mut self, a: (f64, f64), b: (f64, f64), stroke: &Stroke, clip: ClipRect) {
        self.segment(a, b, stroke, clip, 0.0);
    }
    /// A connected polyline; dashes continue across its vertices. Points with a non-finite
    /// coordinate break the line.
    pub fn polyline(&mut self, points: &[(f64, f64)], stroke: &Stroke, clip: ClipRect) {
        let mut phase = 0.0;
        for w in points.windows(2) {
            phase += self.segment(w[0], w[1], stroke, clip, phase);
        }
    }
    /// Draws one segment starting `phase` pixels into the dash pattern; returns its length.
    fn segment(
        &mut self,
        (x0, y0): (f64, f64),
        (x1, y1): (f64, f64),
        stroke: &Stroke,
        clip: ClipRect,
        phase: f64,
    ) -> f64 {
        let full_len = (x1 - x0).hypot(y1 - y0);
        let clip = ClipRect {
            x_min: clip.x_min.max(0.0),
            y_min: clip.y_min.max(0.0),
            x_max: clip.x_max.min(f64::from(self.width) - 1.0),
            y_max: clip.y_max.min(f64::from(self.height) - 1.0),
        };
        let Some(((ax, ay), (bx, by), t0)) = clip_segment((x0, y0), (x1, y1), clip) else {
            return if full_len.is_finite() { full_len } else { 0.0 };
        };
        let (dx, dy) = (bx - ax, by - ay);
        let steps = dx.abs().max(dy.abs()).ceil().max(1.0) as usize;
        let r = f64::from(stroke.thickness.max(1)) / 2.0 - 0.5;
        let (lo, hi) = ((-r).floor() as i64, r.ceil() as i64);
        for k in 0..=steps {
            let t = k as f64 / steps as f64;
            let (x, y) = (ax + dx * t, ay + dy * t);
            if let Some((on, off)) = stroke.dash {
                let along = phase + full_len * t0 + (dx * t).hypot(dy * t);
                if on + off > 0.0 && along.rem_euclid(on + off) >= on {
                    continue;
                }
            }
            for oy in lo..=hi {
                for ox in lo..=hi {
                    self.set(x.round() as i64 + ox, y.round() as i64 + oy, stroke.color);
                }
            }
        }
        full_len
    }
    /// Width in pixels of `text` at `scale`.
    pub fn text_width(text: &str, scale: u32) -> u32 {
        text.chars().count() as u32 * GLYPH_PX * scale
    }
    /// Draws `text` with its top-left corner at (x, y), each glyph pixel a `scale`² block.
    pub fn text(&mut self, x: i64, y: i64, text: &str, color: Rgb, scale: u32) {
        self.glyphs(x, y, text, color, scale, false);
    }
    /// Draws `text` rotated 90° counter-clockwise (reading bottom to top) with the bottom-left
    /// of its first glyph at (x, y + width): it occupies [x, x + 8·scale) × [y, y + width).
    pub fn text_vertical(&mut self, x: i64, y: i64, text: &str, color: Rgb, scale: u32) {
        self.glyphs(x, y, text, color, scale, true);
    }
    fn glyphs(&mut self, x: i64, y: i64, text: &str, color: Rgb, scale: u32, vertical: bool) {
        let s = i64::from(scale.max(1));
        let g = i64::from(GLYPH_PX);
        let total = text.chars().count() as i64 * g * s;
        for (k, ch) in text.chars().enumerate() {
            let code = if ch.is_ascii() {
                ch as usize
            } else {
                '?' as usize
            };
            let glyph = BASIC_LEGACY[code];
            for (row, bits) in glyph.iter().enumerate() {
                for col in 0..8 {
                    if bits >> col & 1 == 0 {
                        continue;
                    }
                    // Glyph-space pixel (u along the text, v down the glyph).
                    let u = k as i64 * g + col;
                    let v = row as i64;
                    let (px, py) = if vertical {
                        (x + v * s, y + total - (u + 1) * s)
                    } else {
                        (x + u * s, y + v * s)
                    };
                    self.fill_rect(px, py, s, s, color);
                }
            }
        }
    }
    /// Writes the canvas as an 8-bit RGB PNG.
    pub fn save_png(&self, path: &Path) -> Result<(), ReportError> {
        let img = image::RgbImage::from_raw(self.width, self.height, self.pixels.clone())
            .ok_or(ReportError::EmptyCanvas)?;
        // whole or not at all: a full disk leaves no empty picture behind
        crate::atomic_file::write_png(path, &img).map_err(|e| ReportError::Write {
            path: path.display().to_string(),
            source: image::ImageError::IoError(e),
        })
    }
    /// The raw RGB8 bytes, row-major.
    pub fn as_bytes(&self) -> &[u8] {
        &self.pixels
    }
}

/// Clipped endpoints, and the parameter of the first along the original segment.
type ClippedSegment = ((f64, f64), (f64, f64), f64);

/// Liang–Barsky clipping of the segment a→b to the box; returns the clipped endpoints and the
/// parameter of the first one along the original segment.
fn clip_segment(a: (f64, f64), b: (f64, f64), clip: ClipRect) -> Option<ClippedSegment> {
    let ClipRect {
        x_min: xmin,
        y_min: ymin,
        x_max: xmax,
        y_max: ymax,
    } = clip;
    if ![a.0, a.1, b.0, b.1].iter().all(|v| v.is_finite()) || xmin > xmax || ymin > ymax {
        return None;
    }
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for (p, q) in [
        (-dx, a.0 - xmin),
        (dx, xmax - a.0),
        (-dy, a.1 - ymin),
        (dy, ymax - a.1),
    ] {
        if p == 0.0 {
            if q < 0.0 {
                return None;
            }
        } else {
            let r = q / p;
            if p < 0.0 {
                t0 = t0.max(r);
            } else {
                t1 = t1.min(r);
            }
        }
    }
    (t0 <= t1).then_some({
        (
            (a.0 + t0 * dx, a.1 + t0 * dy),
            (a.0 + t1 * dx, a.1 + t1 * dy),
            t0,
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const BLACK: Rgb = [0, 0, 0];
    const WHITE: Rgb = [255, 255, 255];

    fn count(c: &Canvas, color: Rgb) -> usize {
        c.as_bytes().chunks(3).filter(|p| *p == color).count()
    }

    #[test]
    fn lines_are_clipped_and_never_panic() {
        let mut c = Canvas::new(20, 10, WHITE);
        let all = ClipRect::NONE;
        let thin = Stroke::solid(BLACK, 1);
        c.line((-100.0, 5.0), (100.0, 5.0), &thin, all);
        assert_eq!(count(&c, BLACK), 20);
        c.line((f64::NAN, 0.0), (3.0, 3.0), &Stroke::solid(BLACK, 3), all);
        c.line((50.0, 50.0), (60.0, 60.0), &Stroke::solid(BLACK, 3), all);
        assert_eq!(count(&c, BLACK), 20);
        // Clip box restricts drawing.
        let mut d = Canvas::new(20, 10, WHITE);
        d.line(
            (0.0, 2.0),
            (19.0, 2.0),
            &thin,
            ClipRect {
                x_min: 5.0,
                y_min: 0.0,
                x_max: 9.0,
                y_max: 9.0,
            },
        );
        assert_eq!(count(&d, BLACK), 5);
        assert_eq!(d.get(4, 2), Some(WHITE));
        assert_eq!(d.get(5, 2), Some(BLACK));
        // Dashes leave gaps.
        let mut e = Canvas::new(40, 3, WHITE);
        let dashed = Stroke {
            dash: Some((4.0, 4.0)),
            ..thin
        };
        e.line((0.0, 1.0), (39.0, 1.0), &dashed, all);
        let n = count(&e, BLACK);
        assert!((16..=24).contains(&n), "{n}");
        // A polyline of short segments keeps the dash pattern going.
        let mut f = Canvas::new(40, 3, WHITE);
        let pts: Vec<(f64, f64)> = (0..40).map(|x| (f64::from(x), 1.0)).collect();
        f.polyline(&pts, &dashed, all);
        let m = count(&f, BLACK);
        assert!((16..=24).contains(&m) && m < 40, "{m}");
    }

    #[test]
    fn text_draws_glyph_pixels_and_rects_clip() {
        let mut c = Canvas::new(40, 20, WHITE);
        c.text(0, 0, "A", BLACK, 2);
        let a = count(&c, BLACK);
        assert!(a > 0 && a % 4 == 0);
        c.text(0, 0, " ", BLACK, 2);
        assert_eq!(count(&c, BLACK), a);
        let mut v = Canvas::new(20, 40, WHITE);
        v.text_vertical(0, 0, "A", BLACK, 2);
        assert_eq!(count(&v, BLACK), a);
        c.fill_rect(-5, -5, 1000, 1000, BLACK);
        assert_eq!(count(&c, BLACK), 800);
        assert_eq!(Canvas::text_width("abc", 2), 48);
    }
}
