//! The board drawing as an 8-bit gray raster at a chosen resolution (dots per inch): shapes
//! anti-aliased by 4 × 4 supersampling of each pixel they touch, text through plotters with the
//! bundled font. The pixel pitch is exactly 25.4 / dpi mm; the image is the paper rounded to
//! whole pixels.

use plotters::backend::{BitMapBackend, DrawingBackend};
use plotters::style::{FontDesc, FontFamily, FontStyle, RGBColor, TextStyle};

use super::Drawing;

/// Supersamples per pixel side: coverage in steps of 1/16, edges placed to 1/8 px on average.
const SUPERSAMPLE: usize = 4;

/// Most pixels a raster may have (a 600 dpi A3 page is 70 M): larger asks are refused, not
/// allocated.
pub const MAX_PIXELS: usize = 100_000_000;

/// A gray image, row-major, 0 = black.
#[derive(Debug, Clone, PartialEq)]
pub struct GrayImage {
    /// Width, px.
    pub width: usize,
    /// Height, px.
    pub height: usize,
    /// Pixels.
    pub gray: Vec<u8>,
}

/// Why a raster cannot be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RasterError {
    /// Resolution not positive or too large for the page.
    #[error("{dpi} dpi gives a {width} × {height} px page (at most {MAX_PIXELS} px, dpi > 0)")]
    Resolution {
        /// Asked resolution.
        dpi: f64,
        /// Resulting width.
        width: usize,
        /// Resulting height.
        height: usize,
    },
}

/// Whether `p` lies inside the convex quad (either winding).
fn inside(q: &[[f64; 2]; 4], p: [f64; 2]) -> bool {
    let mut sign = 0.0f64;
    for k in 0..4 {
        let (a, b) = (q[k], q[(k + 1) % 4]);
        let cross = (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]);
        if cross != 0.0 {
            if sign != 0.0 && cross.signum() != sign {
                return false;
            }
            sign = cross.signum();
        }
    }
    true
}

/// Rasterises `drawing` at `dpi`.
pub fn rasterise(drawing: &Drawing, dpi: f64) -> Result<GrayImage, RasterError> {
    let px_per_mm = dpi / 25.4;
    let width = (drawing.paper_mm[0] * px_per_mm).round().max(0.0) as usize;
    let height = (drawing.paper_mm[1] * px_per_mm).round().max(0.0) as usize;
    if !(dpi.is_finite() && dpi > 0.0) || width == 0 || height == 0 || width * height > MAX_PIXELS {
        return Err(RasterError::Resolution { dpi, width, height });
    }
    let mut black = vec![0u16; width * height];
    let n = SUPERSAMPLE;
    for quad in &drawing.quads {
        let q = quad.0.map(|p| [p[0] * px_per_mm, p[1] * px_per_mm]);
        let (mut x0, mut y0, mut x1, mut y1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
        for p in &q {
            (x0, y0, x1, y1) = (x0.min(p[0]), y0.min(p[1]), x1.max(p[0]), y1.max(p[1]));
        }
        let clamp_x = |v: f64| (v.max(0.0) as usize).min(width - 1);
        let clamp_y = |v: f64| (v.max(0.0) as usize).min(height - 1);
        for py in clamp_y(y0.floor())..=clamp_y(y1.ceil()) {
            for px in clamp_x(x0.floor())..=clamp_x(x1.ceil()) {
                let mut hits = 0u16;
                for sy in 0..n {
                    for sx in 0..n {
                        let p = [
                            px as f64 + (sx as f64 + 0.5) / n as f64,
                            py as f64 + (sy as f64 + 0.5) / n as f64,
                        ];
                        hits += u16::from(inside(&q, p));
                    }
                }
                let cell = &mut black[py * width + px];
                *cell = (*cell + hits).min((n * n) as u16);
            }
        }
    }
    let full = (n * n) as f64;
    let gray: Vec<u8> = black
        .iter()
        .map(|&b| (255.0 * (1.0 - f64::from(b) / full)).round() as u8)
        .collect();
    let mut rgb: Vec<u8> = gray.iter().flat_map(|&g| [g, g, g]).collect();
    crate::font::ensure_registered();
    {
        let mut backend = BitMapBackend::with_buffer(&mut rgb, (width as u32, height as u32));
        for t in &drawing.texts {
            let font = FontDesc::new(
                FontFamily::Name(crate::font::FAMILY),
                t.size_mm * px_per_mm,
                FontStyle::Normal,
            );
            let style = TextStyle::from(font).color(&RGBColor(0, 0, 0)).pos(
                plotters::style::text_anchor::Pos::new(
                    plotters::style::text_anchor::HPos::Left,
                    plotters::style::text_anchor::VPos::Bottom,
                ),
            );
            // text is a label for people: a failure to draw it leaves the tags intact
            let _ = backend.draw_text(
                &t.text,
                &style,
                (
                    (t.x_mm * px_per_mm).round() as i32,
                    (t.baseline_mm * px_per_mm).round() as i32,
                ),
            );
        }
        let _ = backend.present();
    }
    let gray = rgb.chunks_exact(3).map(|p| p[1]).collect();
    Ok(GrayImage {
        width,
        height,
        gray,
    })
}
