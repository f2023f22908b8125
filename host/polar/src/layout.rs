//! Which mosaic a raw frame is, from its pixels: monochrome (IMX250MZR) or colour (IMX250MYR),
//! for frames given without a layout.
//!
//! Contract: [`detect`] looks at the frame's 4×4 tiles. In each, the four 2×2 polariser blocks
//! are summed (the four analysers of a block sum to s0, so polarisation cancels) and compared:
//! `rg` = |B(0,0) − ½(B(0,1) + B(1,0))| + |B(1,1) − ½(B(0,1) + B(1,0))| (red and blue blocks
//! against the two green ones, in a colour mosaic) and `gg` = |B(0,1) − B(1,0)| (the two greens;
//! in a mono mosaic any two blocks), each relative to the tile's mean. Only *flat* tiles count:
//! bright (mean above 1 % of the largest sample) and within ±[`FLAT_TOLERANCE`] of the means of
//! their four neighbouring tiles. An edge inside a tile makes its neighbours' means differ, and
//! an edge across a mono tile's anti-diagonal gives `rg` ≫ `gg` like a colour filter would; in a
//! flat tile a mono sensor's four blocks see the same smooth scene (`rg` ≈ 2·`gg`, both noise and
//! gradient), while under a Bayer filter red and blue differ from green wherever the scene or the
//! channels' sensitivities do (`rg` ≫ `gg`).
//!
//! The verdict compares `rg` with `gg` at two levels over the flat tiles: the median (a frame
//! whose colour is everywhere) and the [`UPPER_QUANTILE`] (a coloured object on a grey board,
//! where most flat tiles are the board's). At each level the frame is colour-like when `rg` >
//! 4·`gg` + 0.05 and mono-like when `rg` < 3·`gg` + 0.02 (a mono frame sits near `rg` = 2·`gg`;
//! the offsets keep noise-only tiles, where both are a few DN, on the mono side).
//! [`Detection::Colour`] when either level is colour-like, [`Detection::Mono`] when both are
//! mono-like, [`Detection::Unsure`] otherwise (the caller refuses and asks for a layout), so a
//! coloured object filling a tenth of the flat tiles is seen. A colour frame of a grey scene
//! with balanced channels still reads as mono — and is then processed correctly as mono: each
//! block holds the same four analysers in both layouts; only colour that is in the pixels can
//! be found in them.

/// Largest relative difference between a tile's mean and each of its four neighbours' for the
/// tile to count as flat: 10 %, far above the shot noise of a 16-pixel sum at 1 % of full scale
/// (σ/mean ≈ 1/√(16·40 DN) ≈ 4 %, a pessimistic 12-bit floor) for neighbours on smooth shading,
/// far below the contrast of an edge worth the name (a tag's black/white is 5–10×).
pub const FLAT_TOLERANCE: f64 = 0.10;

/// The upper level of the comparison: the 90th percentile, so that a colour region covering
/// more than a tenth of the flat tiles decides the verdict.
pub const UPPER_QUANTILE: f64 = 0.9;

/// The verdict on a frame's layout.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Detection {
    /// No colour filter pattern: a monochrome polarisation mosaic.
    Mono,
    /// A Bayer pattern of 2×2 blocks: a colour polarisation mosaic.
    Colour,
    /// Neither clearly.
    Unsure,
}

/// What [`detect`] measured.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LayoutEvidence {
    /// The verdict.
    pub detection: Detection,
    /// Median relative red/blue-against-green block difference over the flat tiles.
    pub rg: f64,
    /// Median relative green-against-green block difference over the flat tiles.
    pub gg: f64,
    /// `rg` at the [`UPPER_QUANTILE`].
    pub rg_upper: f64,
    /// `gg` at the [`UPPER_QUANTILE`].
    pub gg_upper: f64,
    /// Tiles compared (bright and flat).
    pub tiles: usize,
}

/// Which side of the thresholds one level's pair falls on (module doc): `Some(true)` colour,
/// `Some(false)` mono, `None` between.
fn verdict(rg: f64, gg: f64) -> Option<bool> {
    if rg > 4.0 * gg + 0.05 {
        Some(true)
    } else if rg < 3.0 * gg + 0.02 {
        Some(false)
    } else {
        None
    }
}

/// Detects the layout of a `width × height` raw frame (row-major samples; see the module doc).
/// Frames smaller than 3×3 tiles, or with fewer than four flat bright tiles, are `Unsure`.
pub fn detect(width: usize, height: usize, samples: &[u16]) -> LayoutEvidence {
    let at = |x: usize, y: usize| f64::from(samples[y * width + x]);
    let block = |tx: usize, ty: usize, bx: usize, by: usize| {
        let (x, y) = (tx * 4 + bx * 2, ty * 4 + by * 2);
        at(x, y) + at(x + 1, y) + at(x, y + 1) + at(x + 1, y + 1)
    };
    let max = samples.iter().copied().max().unwrap_or(0);
    let floor = 0.01 * 4.0 * f64::from(max);
    let (tiles_x, tiles_y) = (width / 4, height / 4);
    let (mut rg, mut gg) = (Vec::new(), Vec::new());
    if samples.len() >= width * height && tiles_x >= 3 && tiles_y >= 3 {
        // each tile's four block sums and its mean
        let blocks: Vec<[f64; 4]> = (0..tiles_y)
            .flat_map(|ty| (0..tiles_x).map(move |tx| (tx, ty)))
            .map(|(tx, ty)| {
                [
                    block(tx, ty, 0, 0),
                    block(tx, ty, 1, 0),
                    block(tx, ty, 0, 1),
                    block(tx, ty, 1, 1),
                ]
            })
            .collect();
        let mean = |tx: usize, ty: usize| blocks[ty * tiles_x + tx].iter().sum::<f64>() / 4.0;
        for ty in 1..tiles_y - 1 {
            for tx in 1..tiles_x - 1 {
                let m = mean(tx, ty);
                // a tile in the dark says nothing but noise
                if !(m > floor && m > 0.0) {
                    continue;
                }
                let flat = [(tx - 1, ty), (tx + 1, ty), (tx, ty - 1), (tx, ty + 1)]
                    .iter()
                    .all(|&(x, y)| (mean(x, y) - m).abs() <= FLAT_TOLERANCE * m);
                if !flat {
                    continue;
                }
                let [r, g1, g2, b] = blocks[ty * tiles_x + tx];
                let g = 0.5 * (g1 + g2);
                rg.push(((r - g).abs() + (b - g).abs()) / m);
                gg.push((g1 - g2).abs() / m);
            }
        }
    }
    let tiles = rg.len();
    use ellipso_model::stats::{median, percentile};
    let (rg_upper, gg_upper) = (
        percentile(&mut rg, UPPER_QUANTILE),
        percentile(&mut gg, UPPER_QUANTILE),
    );
    let (rg, gg) = (median(&mut rg), median(&mut gg));
    let finite = [rg, gg, rg_upper, gg_upper].iter().all(|v| v.is_finite());
    let detection = if tiles < 4 || !finite {
        Detection::Unsure
    } else {
        match (verdict(rg, gg), verdict(rg_upper, gg_upper)) {
            (Some(true), _) | (_, Some(true)) => Detection::Colour,
            (Some(false), Some(false)) => Detection::Mono,
            _ => Detection::Unsure,
        }
    };
    LayoutEvidence {
        detection,
        rg,
        gg,
        rg_upper,
        gg_upper,
        tiles,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synthetic::mosaic_from_stokes;
    use ellipso_model::mosaic::{Channel, SensorLayout};

    fn frame(layout: SensorLayout, colour: [f64; 3]) -> Vec<u16> {
        mosaic_from_stokes(layout, 64, 48, 12, |x, y, c| {
            // a smooth, polarised scene with a gradient
            let k = match c {
                Some(Channel::Red) => colour[0],
                Some(Channel::Green) => colour[1],
                Some(Channel::Blue) => colour[2],
                None => 1.0,
            };
            let s0 = k * (1500.0 + 10.0 * x as f64 + 5.0 * y as f64);
            [s0, 0.3 * s0, -0.2 * s0]
        })
        .unwrap()
        .into_data()
    }

    #[test]
    fn mono_and_colour_mosaics_are_told_apart() {
        let mono = frame(SensorLayout::MonoPolar, [1.0; 3]);
        assert_eq!(detect(64, 48, &mono).detection, Detection::Mono);
        // a colour sensor under white light: green more sensitive than red and blue
        let colour = frame(SensorLayout::ColourPolar, [0.6, 1.0, 0.7]);
        let e = detect(64, 48, &colour);
        assert_eq!(e.detection, Detection::Colour, "{e:?}");
        // a black frame, or a frame smaller than a tile, says nothing
        assert_eq!(
            detect(64, 48, &vec![0; 64 * 48]).detection,
            Detection::Unsure
        );
        assert_eq!(detect(2, 2, &[1, 2, 3, 4]).detection, Detection::Unsure);
    }

    /// A balanced colour sensor (equal sensitivities) looking at a grey board with a red object
    /// covering a fifth of it: the board's tiles show no pattern, the object's do.
    #[test]
    fn a_coloured_object_on_a_grey_board_is_colour() {
        let (w, h) = (160, 120);
        let frame = mosaic_from_stokes(SensorLayout::ColourPolar, w, h, 12, |x, y, c| {
            let inside = (60..120).contains(&x) && (30..90).contains(&y);
            let k = match (inside, c) {
                (true, Some(Channel::Red)) => 0.9,
                (true, _) => 0.15,
                (false, _) => 0.6,
            };
            let s0 = k * (3000.0 + 2.0 * x as f64);
            [s0, 0.2 * s0, 0.1 * s0]
        })
        .unwrap()
        .into_data();
        let e = detect(w as usize, h as usize, &frame);
        assert_eq!(e.detection, Detection::Colour, "{e:?}");
        // the board alone is not told apart from a mono frame: only the colour in the pixels is
        assert!(verdict(e.rg, e.gg) == Some(false), "{e:?}");
    }

    /// A mono frame of a board with many edges at 45°, the direction that makes a mono tile's
    /// red and blue blocks differ from its greens: its edge tiles are not flat and do not count.
    #[test]
    fn diagonal_edges_do_not_make_a_mono_frame_colour() {
        let (w, h) = (160, 120);
        let frame = mosaic_from_stokes(SensorLayout::MonoPolar, w, h, 12, |x, y, _| {
            // stripes along the anti-diagonal, 24 px apart in x + y, black and white
            let s0 = if ((x + y) / 24) % 2 == 0 {
                3600.0
            } else {
                400.0
            };
            [s0, 0.1 * s0, 0.0]
        })
        .unwrap()
        .into_data();
        let e = detect(w as usize, h as usize, &frame);
        assert_eq!(e.detection, Detection::Mono, "{e:?}");
    }
}
