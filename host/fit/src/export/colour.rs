//! Colour maps and framed figures for the fit's pictures.
//!
//! Contract: every map takes any f64 (NaN included) and returns a valid sRGB colour; values are
//! clamped to the map's range. [`figure`] frames an image with a title above and a colour bar
//! with its range below, on the report canvas; background and unreliable pixels are drawn in
//! [`NO_DATA`] grey.

use ellipso_report::{Canvas, Rgb};

/// Pixels without a value (background, unfitted).
pub const NO_DATA: Rgb = [96, 96, 96];
const INK: Rgb = [240, 240, 240];
const PAPER: Rgb = [24, 24, 24];

/// A colour map.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ColourMap {
    /// Perceptually uniform, dark blue → yellow (matplotlib's viridis, 9 control points).
    Viridis,
    /// Signed values: blue (−) → white (0) → red (+).
    Diverging,
    /// Angles: a cyclic hue wheel (the value is a fraction of the period).
    Cyclic,
}

const VIRIDIS: [[f64; 3]; 9] = [
    [68.0, 1.0, 84.0],
    [71.0, 44.0, 122.0],
    [59.0, 81.0, 139.0],
    [44.0, 113.0, 142.0],
    [33.0, 144.0, 141.0],
    [39.0, 173.0, 129.0],
    [92.0, 200.0, 99.0],
    [170.0, 220.0, 50.0],
    [253.0, 231.0, 37.0],
];

impl ColourMap {
    /// The colour of `t` ∈ [0, 1] (clamped; NaN → [`NO_DATA`]).
    pub fn at(self, t: f64) -> Rgb {
        if !t.is_finite() {
            return NO_DATA;
        }
        let t = t.clamp(0.0, 1.0);
        match self {
            ColourMap::Viridis => {
                let x = t * (VIRIDIS.len() - 1) as f64;
                let k = (x.floor() as usize).min(VIRIDIS.len() - 2);
                let f = x - k as f64;
                std::array::from_fn(|c| (VIRIDIS[k][c] * (1.0 - f) + VIRIDIS[k + 1][c] * f) as u8)
            }
            ColourMap::Diverging => {
                let s = 2.0 * t - 1.0;
                let blue = [33.0, 102.0, 172.0];
                let red = [178.0, 24.0, 43.0];
                let end = if s < 0.0 { blue } else { red };
                let a = s.abs();
                std::array::from_fn(|c| (250.0 * (1.0 - a) + end[c] * a) as u8)
            }
            ColourMap::Cyclic => {
                let h = t * 6.0;
                let x = 1.0 - (h % 2.0 - 1.0).abs();
                let (r, g, b) = match h as u32 {
                    0 => (1.0, x, 0.0),
                    1 => (x, 1.0, 0.0),
                    2 => (0.0, 1.0, x),
                    3 => (0.0, x, 1.0),
                    4 => (x, 0.0, 1.0),
                    _ => (1.0, 0.0, x),
                };
                [
                    (r * 230.0) as u8 + 20,
                    (g * 230.0) as u8 + 20,
                    (b * 230.0) as u8 + 20,
                ]
            }
        }
    }
}

/// An image to frame: RGB pixels row-major (`None` = no data).
pub struct Panel {
    /// Width, px.
    pub width: u32,
    /// Height, px.
    pub height: u32,
    /// Pixels.
    pub pixels: Vec<Option<Rgb>>,
}

impl Panel {
    /// A scalar field through a colour map over `[lo, hi]`.
    pub fn scalar(
        width: u32,
        height: u32,
        values: &[Option<f64>],
        map: ColourMap,
        lo: f64,
        hi: f64,
    ) -> Self {
        let span = (hi - lo).abs().max(1e-300);
        Self {
            width,
            height,
            pixels: values
                .iter()
                .map(|v| v.map(|v| map.at((v - lo) / span)))
                .collect(),
        }
    }
}

/// A colour bar under a figure.
pub struct Bar {
    /// Map.
    pub map: ColourMap,
    /// Low end label value.
    pub lo: f64,
    /// High end label value.
    pub hi: f64,
    /// Unit or meaning, e.g. "η" or "M/M00".
    pub label: String,
}

/// Title height and bar height, px (scale-1 font).
const TITLE_PX: u32 = 14;
const BAR_PX: u32 = 30;

/// Draws `panel` at (x, y) on `canvas`.
pub fn blit(canvas: &mut Canvas, panel: &Panel, x: i64, y: i64) {
    for py in 0..panel.height {
        for px in 0..panel.width {
            let c = panel.pixels[(py * panel.width + px) as usize].unwrap_or(NO_DATA);
            canvas.set(x + i64::from(px), y + i64::from(py), c);
        }
    }
}

/// Draws a colour bar of `width` at (x, y).
pub fn draw_bar(canvas: &mut Canvas, bar: &Bar, x: i64, y: i64, width: u32) {
    let w = i64::from(width.max(2));
    for k in 0..w {
        let c = bar.map.at(k as f64 / (w - 1) as f64);
        canvas.fill_rect(x + k, y, 1, 10, c);
    }
    let fmt = |v: f64| {
        if v.abs() >= 100.0 || (v != 0.0 && v.abs() < 0.01) {
            format!("{v:.2e}")
        } else {
            format!("{v:.3}")
        }
    };
    canvas.text(x, y + 13, &fmt(bar.lo), INK, 1);
    let hi = fmt(bar.hi);
    canvas.text(
        x + w - i64::from(Canvas::text_width(&hi, 1)),
        y + 13,
        &hi,
        INK,
        1,
    );
    let lw = i64::from(Canvas::text_width(&bar.label, 1));
    canvas.text(x + (w - lw) / 2, y + 13, &bar.label, INK, 1);
}

/// A framed figure: title, panel, optional colour bar.
pub fn figure(title: &str, panel: &Panel, bar: Option<&Bar>) -> Canvas {
    let width = panel.width.max(Canvas::text_width(title, 1) + 8).max(160);
    let height = TITLE_PX + panel.height + if bar.is_some() { BAR_PX } else { 4 };
    let mut c = Canvas::new(width, height, PAPER);
    c.text(4, 3, title, INK, 1);
    let x0 = i64::from((width - panel.width) / 2);
    blit(&mut c, panel, x0, i64::from(TITLE_PX));
    if let Some(bar) = bar {
        draw_bar(
            &mut c,
            bar,
            4,
            i64::from(TITLE_PX + panel.height + 4),
            width - 8,
        );
    }
    c
}

/// Robust display range of `values`: the 1st and 99th percentiles of the finite ones (a
/// degenerate range is widened to ±5 % or ±0.5).
pub fn robust_range(values: &[Option<f64>]) -> (f64, f64) {
    let mut v: Vec<f64> = values
        .iter()
        .flatten()
        .copied()
        .filter(|x| x.is_finite())
        .collect();
    if v.is_empty() {
        return (0.0, 1.0);
    }
    let lo = ellipso_report::percentile(&mut v, 0.01);
    let hi = ellipso_report::percentile(&mut v, 0.99);
    if hi - lo > 1e-9 * hi.abs().max(1.0) {
        (lo, hi)
    } else {
        let pad = (0.05 * lo.abs()).max(if lo == 0.0 { 0.5 } else { 0.0 });
        (lo - pad, hi + pad)
    }
}

/// sRGB encoding of a linear value in [0, 1] (IEC 61966-2-1).
pub fn srgb(linear: f64) -> u8 {
    let l = if linear.is_finite() {
        linear.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let s = if l <= 0.003_130_8 {
        12.92 * l
    } else {
        1.055 * l.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0).round() as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn maps_are_total_and_ordered() {
        for map in [ColourMap::Viridis, ColourMap::Diverging, ColourMap::Cyclic] {
            for t in [-1.0, 0.0, 0.3, 1.0, 2.0, f64::NAN, f64::INFINITY] {
                let _ = map.at(t);
            }
        }
        // Viridis brightens monotonically (sum of channels).
        let lum = |t: f64| {
            ColourMap::Viridis
                .at(t)
                .iter()
                .map(|&c| u32::from(c))
                .sum::<u32>()
        };
        assert!(lum(0.0) < lum(0.5) && lum(0.5) < lum(1.0));
        assert_eq!(ColourMap::Diverging.at(0.5), [250, 250, 250]);
        assert_eq!(ColourMap::Cyclic.at(0.0), ColourMap::Cyclic.at(0.0 + 1e-12));
        assert_eq!(srgb(0.0), 0);
        assert_eq!(srgb(1.0), 255);
        assert_eq!(srgb(f64::NAN), 0);
    }

    #[test]
    fn robust_range_survives_degenerate_input() {
        assert_eq!(robust_range(&[]), (0.0, 1.0));
        let (lo, hi) = robust_range(&[Some(1.5), Some(1.5), None]);
        assert!(lo < 1.5 && hi > 1.5);
    }
}
