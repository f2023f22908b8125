//! The raw mosaic as a full-resolution intensity image of the board: each mosaic phase (its
//! place in the analyser tile, and on a colour sensor its colour filter) divided by its gain.
//!
//! Why. Tags were detected on the superpixel image, one value per tile (2×2 raw pixels on a
//! mono sensor, 4×4 on a colour one); at 612×512 on a colour sensor that image is 153×128 and
//! its tags are too small to be found (the generalisation bench posed 2–4 of 50 frames there).
//! The board is printed in achromatic ink on matte paper, so every phase sees the same pattern
//! through its own gain (colour filter × analyser transmission of the paper's mostly
//! unpolarised light); with the gains divided out, every raw pixel is a sample of that pattern
//! and the detector gets the full resolution.
//!
//! Contract of [`flat_raw`]:
//! - A phase's gain is the median, over the bright tiles, of the ratio of its pixel to its
//!   tile's mean: bright tiles (mean at or above the 90th percentile of the tile means, and no
//!   pixel at the frame's largest value, which may be clipped) are the white paper wherever the
//!   board fills a tenth of the frame; the median keeps a minority of coloured or polarising
//!   tiles among them (the object, a highlight) from moving it. A gain that is not finite and
//!   positive (a dark frame) is 1.
//! - The result is `raw / gain` per pixel (f32, row-major, the frame's size). A black level
//!   is not subtracted: it leaves a faint phase pattern on the ink, well inside the detector's
//!   local threshold.

use ellipso_polar::frame::RawFrame;

/// Tiles at or above this quantile of the tile means are taken as the white paper.
const BRIGHT_QUANTILE: f64 = 0.9;

/// The frame with each phase's gain divided out (module doc): `(values, width, height)`.
pub fn flat_raw(frame: &RawFrame) -> (Vec<f32>, usize, usize) {
    let (w, h) = (frame.width() as usize, frame.height() as usize);
    let t = frame.layout().tile_px() as usize;
    let data = frame.data_dn();
    let (tw, th) = (w / t, h / t);
    let max_dn = data.iter().copied().max().unwrap_or(0);
    // Tile means (tiles with a pixel at the frame's maximum left out: possibly clipped).
    let mut means: Vec<(usize, usize, f64)> = Vec::with_capacity(tw * th);
    for ty in 0..th {
        for tx in 0..tw {
            let mut sum = 0.0;
            let mut clipped = false;
            for y in ty * t..ty * t + t {
                for x in tx * t..tx * t + t {
                    let v = data[y * w + x];
                    clipped |= v == max_dn;
                    sum += f64::from(v);
                }
            }
            if !clipped {
                means.push((tx, ty, sum / (t * t) as f64));
            }
        }
    }
    let mut sorted: Vec<f64> = means.iter().map(|m| m.2).collect();
    sorted.sort_by(f64::total_cmp);
    let threshold = sorted
        .get(((sorted.len() as f64 - 1.0) * BRIGHT_QUANTILE).max(0.0) as usize)
        .copied()
        .unwrap_or(f64::INFINITY);
    let mut ratios: Vec<Vec<f64>> = vec![Vec::new(); t * t];
    for &(tx, ty, mean) in &means {
        if !(mean >= threshold && mean > 0.0) {
            continue;
        }
        for py in 0..t {
            for px in 0..t {
                let v = data[(ty * t + py) * w + tx * t + px];
                ratios[py * t + px].push(f64::from(v) / mean);
            }
        }
    }
    let gains: Vec<f32> = ratios
        .into_iter()
        .map(|mut r| {
            let g = if r.is_empty() {
                f64::NAN
            } else {
                ellipso_model::stats::median(&mut r)
            };
            if g.is_finite() && g > 0.0 {
                g as f32
            } else {
                1.0
            }
        })
        .collect();
    let mut out = vec![0f32; w * h];
    for y in 0..h {
        for x in 0..w {
            out[y * w + x] = f32::from(data[y * w + x]) / gains[(y % t) * t + x % t];
        }
    }
    (out, w, h)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ellipso_model::mosaic::SensorLayout;

    #[test]
    fn the_phase_gains_of_a_colour_mosaic_are_divided_out() {
        // A white sheet (4000 DN) with a black square (200 DN), seen through 16 phase gains.
        let (w, h, t) = (64usize, 48usize, 4usize);
        let gains: Vec<f64> = (0..16).map(|k| 0.3 + 0.04 * k as f64).collect();
        let mut data = vec![0u16; w * h];
        for y in 0..h {
            for x in 0..w {
                let level = if (20..40).contains(&x) && (12..30).contains(&y) {
                    200.0
                } else {
                    4000.0
                };
                data[y * w + x] = (level * gains[(y % t) * t + x % t]).round() as u16;
            }
        }
        let frame = RawFrame::new(w as u32, h as u32, 12, SensorLayout::ColourPolar, data).unwrap();
        let (flat, fw, fh) = flat_raw(&frame);
        assert_eq!((fw, fh), (w, h));
        // Every paper pixel reads the same value, every ink pixel too, to the DN rounding.
        let paper: Vec<f32> = (0..w * h)
            .filter(|&i| !((20..40).contains(&(i % w)) && (12..30).contains(&(i / w))))
            .map(|i| flat[i])
            .collect();
        let (lo, hi) = paper
            .iter()
            .fold((f32::MAX, f32::MIN), |(a, b), &v| (a.min(v), b.max(v)));
        assert!(hi / lo < 1.002, "paper spread {lo}..{hi}");
        let ink = flat[20 * w + 25];
        assert!((ink / lo - 0.05).abs() < 0.005, "ink {ink} paper {lo}");
    }
}
