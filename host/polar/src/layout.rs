//! Which mosaic a raw frame is, from its pixels: monochrome (IMX250MZR) or colour (IMX250MYR),
//! for frames given without a layout.
//!
//! Contract: [`detect`] looks at the frame's 4×4 tiles. In each, the four 2×2 polariser blocks
//! are summed (the four analysers of a block sum to s0, so polarisation cancels) and compared:
//! `rg` = |B(0,0) − ½(B(0,1) + B(1,0))| + |B(1,1) − ½(B(0,1) + B(1,0))| (red and blue blocks
//! against the two green ones, in a colour mosaic) and `gg` = |B(0,1) − B(1,0)| (the two greens;
//! in a mono mosaic any two blocks), each relative to the tile's mean, medians over the tiles.
//! On a mono sensor all four blocks see the same smooth scene, so `rg` ≈ 2·`gg`; under a Bayer
//! filter red and blue differ from green wherever the scene or the channels' sensitivities do,
//! so `rg` ≫ `gg`. [`Detection::Colour`] when `rg` > 4·`gg` + 0.05, [`Detection::Mono`] when
//! `rg` < 3·`gg` + 0.02, [`Detection::Unsure`] between (the caller refuses and asks for a
//! layout). A colour frame of a grey scene with balanced channels reads as mono — and is then
//! also processed correctly as mono: each block holds the same four analysers in both layouts.

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
    /// Median relative red/blue-against-green block difference.
    pub rg: f64,
    /// Median relative green-against-green block difference.
    pub gg: f64,
    /// Tiles compared (bright enough: mean above 1 % of the largest sample).
    pub tiles: usize,
}

/// Detects the layout of a `width × height` raw frame (row-major samples; see the module doc).
/// Frames smaller than one tile, or without bright tiles, are `Unsure`.
pub fn detect(width: usize, height: usize, samples: &[u16]) -> LayoutEvidence {
    let at = |x: usize, y: usize| f64::from(samples[y * width + x]);
    let block = |tx: usize, ty: usize, bx: usize, by: usize| {
        let (x, y) = (tx * 4 + bx * 2, ty * 4 + by * 2);
        at(x, y) + at(x + 1, y) + at(x, y + 1) + at(x + 1, y + 1)
    };
    let max = samples.iter().copied().max().unwrap_or(0);
    let floor = 0.01 * 4.0 * f64::from(max);
    let (mut rg, mut gg) = (Vec::new(), Vec::new());
    if samples.len() >= width * height {
        for ty in 0..height / 4 {
            for tx in 0..width / 4 {
                let r = block(tx, ty, 0, 0);
                let g1 = block(tx, ty, 1, 0);
                let g2 = block(tx, ty, 0, 1);
                let b = block(tx, ty, 1, 1);
                let mean = (r + g1 + g2 + b) / 4.0;
                // a tile in the dark says nothing but noise
                if !(mean > floor && mean > 0.0) {
                    continue;
                }
                let g = 0.5 * (g1 + g2);
                rg.push(((r - g).abs() + (b - g).abs()) / mean);
                gg.push((g1 - g2).abs() / mean);
            }
        }
    }
    let tiles = rg.len();
    use ellipso_model::stats::median;
    let (rg, gg) = (median(&mut rg), median(&mut gg));
    let detection = if tiles < 4 || !(rg.is_finite() && gg.is_finite()) {
        Detection::Unsure
    } else if rg > 4.0 * gg + 0.05 {
        Detection::Colour
    } else if rg < 3.0 * gg + 0.02 {
        Detection::Mono
    } else {
        Detection::Unsure
    };
    LayoutEvidence {
        detection,
        rg,
        gg,
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
}
