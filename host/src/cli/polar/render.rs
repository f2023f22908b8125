//! Minimal private raster helpers for `ellipso polar`: colour maps, an 8×8-font text blitter and
//! legend strips appended under an image. Not a general plotting module (on purpose).
//!
//! Contract: drawing outside the canvas is clipped, never a panic; every colour map takes any
//! f32 (NaN included) and returns a valid colour.

use font8x8::legacy::{BASIC_LEGACY, LATIN_LEGACY};

/// An 8-bit RGB colour.
pub(super) type Rgb = [u8; 3];

/// Colour of masked pixels in false-colour images (mid-grey: no hue, not black, not white).
pub(super) const MASKED: Rgb = [128, 128, 128];
const BACKGROUND: Rgb = [0, 0, 0];
const INK: Rgb = [255, 255, 255];
/// Height of the legend strip under each image, in pixels.
const LEGEND_PX: usize = 44;
/// Legends are at least this wide (narrow frames get a black margin on the right).
const MIN_LEGEND_WIDTH_PX: usize = 240;

/// An RGB raster, row-major, rows growing downward.
#[derive(Debug, Clone)]
pub(super) struct Canvas {
    pub width: usize,
    pub height: usize,
    pub pixels: Vec<Rgb>,
}

impl Canvas {
    /// A `width × height` canvas filled with `fill`.
    pub fn new(width: usize, height: usize, fill: Rgb) -> Canvas {
        Canvas {
            width,
            height,
            pixels: vec![fill; width * height],
        }
    }

    /// Sets one pixel; ignored outside the canvas.
    pub fn set(&mut self, x: usize, y: usize, colour: Rgb) {
        if x < self.width && y < self.height {
            self.pixels[y * self.width + x] = colour;
        }
    }

    /// Draws `text` with its top-left corner at `(x, y)` (8×8 glyphs; `?` for unknown chars).
    pub fn text(&mut self, x: usize, y: usize, text: &str, colour: Rgb) {
        for (k, ch) in text.chars().enumerate() {
            let code = ch as usize;
            let glyph = match code {
                0..=127 => BASIC_LEGACY[code],
                0xA0..=0xFF => LATIN_LEGACY[code - 0xA0],
                _ => BASIC_LEGACY[usize::from(b'?')],
            };
            for (row, bits) in glyph.iter().enumerate() {
                for col in 0..8 {
                    if bits & (1 << col) != 0 {
                        self.set(x + 8 * k + col, y + row, colour);
                    }
                }
            }
        }
    }

    /// This canvas with a legend strip appended underneath (and widened if very narrow).
    pub fn with_legend(self, legend: &Legend) -> Canvas {
        let width = self.width.max(MIN_LEGEND_WIDTH_PX);
        let mut out = Canvas::new(width, self.height + LEGEND_PX, BACKGROUND);
        for (y, row) in self.pixels.chunks_exact(self.width.max(1)).enumerate() {
            out.pixels[y * width..y * width + self.width].copy_from_slice(row);
        }
        let y0 = self.height;
        match legend {
            Legend::Bar { title, map, ticks } => {
                let (left, right) = (8usize, width.saturating_sub(8).max(9));
                let span = (right - left) as f32;
                for x in left..right {
                    let colour = map((x - left) as f32 / span);
                    for y in y0 + 4..y0 + 16 {
                        out.set(x, y, colour);
                    }
                }
                for (pos, label) in ticks {
                    let x = left + (pos.clamp(0.0, 1.0) * span).round() as usize;
                    for y in y0 + 16..y0 + 20 {
                        out.set(x.min(right - 1), y, INK);
                    }
                    let label_px = 8 * label.chars().count();
                    let lx = x
                        .saturating_sub(label_px / 2)
                        .min(width.saturating_sub(label_px));
                    out.text(lx, y0 + 21, label, INK);
                }
                out.text(left, y0 + 33, title, INK);
            }
            Legend::Swatches(items) => {
                let mut x = 8usize;
                let mut y = y0 + 6;
                for (colour, label) in items {
                    let item_px = 14 + 8 * label.chars().count() + 12;
                    if x + item_px > width && x > 8 {
                        x = 8;
                        y += 14;
                    }
                    for dy in 0..8 {
                        for dx in 0..10 {
                            out.set(x + dx, y + dy, *colour);
                        }
                    }
                    out.text(x + 14, y, label, INK);
                    x += item_px;
                }
            }
        }
        out
    }

    /// Channel 0 of every pixel (for canvases drawn in greys only).
    pub fn to_gray(&self) -> Vec<u8> {
        self.pixels.iter().map(|p| p[0]).collect()
    }

    /// Interleaved RGB bytes.
    pub fn to_rgb_bytes(&self) -> Vec<u8> {
        self.pixels.iter().flatten().copied().collect()
    }
}

/// What a legend strip shows.
pub(super) enum Legend {
    /// A colour bar over [0, 1] with ticks `(position in 0..=1, label)` and a title.
    Bar {
        title: String,
        map: Box<dyn Fn(f32) -> Rgb>,
        ticks: Vec<(f32, String)>,
    },
    /// Coloured squares with labels (categorical images).
    Swatches(Vec<(Rgb, String)>),
}

/// Grey level for `t` in [0, 1] (clamped; NaN is black).
pub(super) fn grey(t: f32) -> Rgb {
    let v = unit_to_u8(t);
    [v, v, v]
}

/// Fully saturated hue wheel: `hue_turns` in [0, 1) maps round the wheel (red at 0 and 1),
/// scaled by `value` in [0, 1].
pub(super) fn hue(hue_turns: f32, value: f32) -> Rgb {
    let h = if hue_turns.is_finite() {
        hue_turns.rem_euclid(1.0) * 6.0
    } else {
        0.0
    };
    let v = if value.is_finite() {
        value.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let sector = (h.floor() as u8).min(5);
    let f = h - h.floor();
    let (r, g, b) = match sector {
        0 => (1.0, f, 0.0),
        1 => (1.0 - f, 1.0, 0.0),
        2 => (0.0, 1.0, f),
        3 => (0.0, 1.0 - f, 1.0),
        4 => (f, 0.0, 1.0),
        _ => (1.0, 0.0, 1.0 - f),
    };
    [unit_to_u8(r * v), unit_to_u8(g * v), unit_to_u8(b * v)]
}

/// Diverging blue–white–red map for `t` in [−1, 1] (clamped; NaN is white).
pub(super) fn diverging(t: f32) -> Rgb {
    let t = if t.is_finite() {
        t.clamp(-1.0, 1.0)
    } else {
        0.0
    };
    // endpoints: blue (33, 102, 172), red (178, 24, 43) — ColorBrewer RdBu ends
    let (end, a) = if t < 0.0 {
        ([33.0, 102.0, 172.0], -t)
    } else {
        ([178.0, 24.0, 43.0], t)
    };
    let mix = |e: f32| (255.0 + (e - 255.0) * a).round().clamp(0.0, 255.0) as u8;
    [mix(end[0]), mix(end[1]), mix(end[2])]
}

/// `round(255·t)` for `t` clamped to [0, 1]; NaN gives 0.
pub(super) fn unit_to_u8(t: f32) -> u8 {
    if t.is_finite() {
        (t.clamp(0.0, 1.0) * 255.0).round() as u8
    } else {
        0
    }
}

/// `round(65535·t)` for `t` clamped to [0, 1]; NaN gives 0.
pub(super) fn unit_to_u16(t: f32) -> u16 {
    if t.is_finite() {
        (t.clamp(0.0, 1.0) * 65535.0).round() as u16
    } else {
        0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hue_wheel_closes_and_hits_primaries() {
        assert_eq!(hue(0.0, 1.0), [255, 0, 0]);
        assert_eq!(hue(1.0, 1.0), hue(0.0, 1.0), "0 and π meet");
        assert_eq!(hue(1.0 / 3.0, 1.0), [0, 255, 0]);
        assert_eq!(hue(2.0 / 3.0, 1.0), [0, 0, 255]);
        assert_eq!(hue(0.25, 0.0), [0, 0, 0]);
        assert_eq!(hue(f32::NAN, f32::NAN), [0, 0, 0]);
    }

    #[test]
    fn diverging_is_white_at_zero_and_symmetric_in_lightness() {
        assert_eq!(diverging(0.0), [255, 255, 255]);
        assert_eq!(diverging(-1.0), [33, 102, 172]);
        assert_eq!(diverging(5.0), [178, 24, 43]);
        assert_eq!(diverging(f32::NAN), [255, 255, 255]);
    }

    #[test]
    fn text_draws_inside_and_clips_outside() {
        let mut c = Canvas::new(10, 10, [0, 0, 0]);
        c.text(0, 0, "A", [255, 255, 255]);
        assert!(c.pixels.contains(&[255, 255, 255]));
        c.text(8, 8, "°WW", [1, 2, 3]); // mostly off-canvas: no panic
        let legend = Legend::Bar {
            title: "DoLP".into(),
            map: Box::new(grey),
            ticks: vec![(0.0, "0".into()), (1.0, "1".into())],
        };
        let out = c.with_legend(&legend);
        assert_eq!(
            (out.width, out.height),
            (MIN_LEGEND_WIDTH_PX, 10 + LEGEND_PX)
        );
        let sw = Canvas::new(300, 2, [0, 0, 0])
            .with_legend(&Legend::Swatches(vec![([255, 0, 0], "saturated".into())]));
        assert!(sw.pixels.contains(&[255, 0, 0]));
    }

    #[test]
    fn scaling_clamps() {
        assert_eq!(unit_to_u16(2.0), 65535);
        assert_eq!(unit_to_u16(-1.0), 0);
        assert_eq!(unit_to_u8(0.5), 128);
        assert_eq!(grey(f32::INFINITY), [0, 0, 0]);
    }
}
