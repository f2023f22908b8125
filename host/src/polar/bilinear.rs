//! Bilinear demosaicing: each (colour, analyser) sample lattice interpolated to full resolution.
//!
//! The interpolant is a normalised convolution: `value = Σ w·v / Σ w` over the lattice samples
//! in reach that are inside the frame and not saturated, with a tent kernel `w` one lattice
//! period wide (separable for rectangular lattices: all mono planes, colour R and B; along the
//! 45°-rotated lattice axes for the quincunx colour G lattice). In the interior this is exactly
//! bilinear interpolation; at borders and around saturated samples the weights renormalise.
//! Where no kernel sample is usable and none was saturated (corners of the G lattice), a kernel
//! of twice the reach is used. Flags: `Saturated` when any saturated sample lay in the kernel,
//! `NoSamples` when nothing at all was in reach.
//!
//! Rectangular lattices run as two separable passes (scatter along rows, gather along columns);
//! the G lattice and the fallback use per-pixel tap lists. Both compute the same sums (tested).

use ellipso_sim::mosaic::{Analyser, Channel, SensorLayout};

use super::demosaic::{AnalyserBand, Levels};
use super::frame::RawFrame;
use super::mask::{MaskReason, PixelMask};
use super::plane::Plane;

/// One interpolation tap: raw-pixel offset and weight.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Tap {
    dx: i32,
    dy: i32,
    weight: f32,
}

/// Taps of the (colour, analyser) lattice for every pixel phase in the tile, row-major by phase.
/// `spread` 1 is the bilinear kernel (one lattice period); 2 doubles its reach and is only the
/// fallback for border pixels whose bilinear neighbours all lie outside the frame (the corners
/// of the quincunx G lattice).
fn tap_table(
    layout: SensorLayout,
    colour: Option<Channel>,
    analyser: Analyser,
    spread: i32,
) -> Vec<Vec<Tap>> {
    let tile = layout.tile_px() as i32;
    let reach = spread * tile - 1;
    let on_lattice = |x: i32, y: i32| {
        // shift by whole tiles so the lookup never sees negative coordinates
        let (xs, ys) = ((x + 4 * tile) as u32, (y + 4 * tile) as u32);
        layout.analyser_at(xs, ys) == analyser && layout.colour_at(xs, ys) == colour
    };
    let weight = |dx: i32, dy: i32| -> f32 {
        let (dx, dy) = (dx as f32, dy as f32);
        let period = (spread * tile) as f32;
        if colour == Some(Channel::Green) {
            // quincunx G lattice: integer lattice in u = (dx+dy)/4, v = (dx−dy)/4
            let (u, v) = ((dx + dy) / period, (dx - dy) / period);
            (1.0 - u.abs()).max(0.0) * (1.0 - v.abs()).max(0.0)
        } else {
            (1.0 - dx.abs() / period).max(0.0) * (1.0 - dy.abs() / period).max(0.0)
        }
    };
    let mut table = Vec::with_capacity((tile * tile) as usize);
    for py in 0..tile {
        for px in 0..tile {
            let mut taps = Vec::new();
            for dy in -reach..=reach {
                for dx in -reach..=reach {
                    let w = weight(dx, dy);
                    if w > 0.0 && on_lattice(px + dx, py + dy) {
                        taps.push(Tap { dx, dy, weight: w });
                    }
                }
            }
            table.push(taps);
        }
    }
    table
}

/// Interpolates at `(x, y)` from `taps`: `(value, weight used, saw a saturated sample)`.
fn interpolate(
    frame: &RawFrame,
    levels: &Levels,
    taps: &[Tap],
    x: i32,
    y: i32,
) -> (f32, f32, bool) {
    let (w, h) = (frame.width() as i32, frame.height() as i32);
    let data = frame.data_dn();
    let (mut acc, mut weight_sum, mut saturated) = (0.0f32, 0.0f32, false);
    for t in taps {
        let (xx, yy) = (x + t.dx, y + t.dy);
        if xx < 0 || yy < 0 || xx >= w || yy >= h {
            continue;
        }
        let dn = data[(yy * w + xx) as usize];
        if levels.is_saturated(dn) {
            saturated = true;
        } else {
            acc += t.weight * levels.normalise(dn);
            weight_sum += t.weight;
        }
    }
    let value = if weight_sum > 0.0 {
        acc / weight_sum
    } else {
        0.0
    };
    (value, weight_sum, saturated)
}

pub(crate) fn bilinear_band(
    frame: &RawFrame,
    levels: &Levels,
    colour: Option<Channel>,
) -> AnalyserBand {
    let (w, h) = (frame.width() as usize, frame.height() as usize);
    let mut intensity: [Plane<f32>; 4] = std::array::from_fn(|_| Plane::new(w, h));
    let mut mask: Plane<PixelMask> = Plane::new(w, h);
    let layout = frame.layout();
    for a in Analyser::ALL {
        let plane = intensity[a.index()].data_mut();
        match rectangular_lattice(layout, colour, a) {
            Some(lattice) => separable(frame, levels, colour, a, lattice, plane, mask.data_mut()),
            None => per_pixel(frame, levels, colour, a, plane, mask.data_mut()),
        }
    }
    AnalyserBand {
        colour,
        intensity,
        mask,
    }
}

/// A rectangular sample lattice: first sample `(x0, y0)`, period in both axes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Lattice {
    x0: usize,
    y0: usize,
    period: usize,
}

/// The lattice of `(colour, analyser)` if it is rectangular (everything but colour G).
fn rectangular_lattice(
    layout: SensorLayout,
    colour: Option<Channel>,
    analyser: Analyser,
) -> Option<Lattice> {
    let block = match colour {
        Some(Channel::Green) => return None,
        None => (0, 0),
        Some(c) => *c.blocks_in_tile().first()?,
    };
    let (x0, y0) = layout.pixel_in_tile(analyser, block);
    Some(Lattice {
        x0,
        y0,
        period: layout.tile_px() as usize,
    })
}

/// Marks pixel `i` from its accumulated weights: value, `Saturated`, or the fallback kernel.
#[expect(
    clippy::too_many_arguments,
    reason = "one call site; a struct would only rename them"
)]
fn finish_pixel(
    frame: &RawFrame,
    levels: &Levels,
    fallback: &mut Option<Vec<Vec<Tap>>>,
    colour: Option<Channel>,
    analyser: Analyser,
    (x, y): (usize, usize),
    (acc, weight, saturated_weight): (f32, f32, f32),
    out: (&mut f32, &mut PixelMask),
) {
    let (mut value, mut weight, mut saturated) = (
        acc / weight.max(f32::MIN_POSITIVE),
        weight,
        saturated_weight > 0.0,
    );
    if weight <= 0.0 && !saturated {
        let layout = frame.layout();
        let tile = layout.tile_px() as usize;
        let table = fallback.get_or_insert_with(|| tap_table(layout, colour, analyser, 2));
        let taps = &table[(y % tile) * tile + x % tile];
        (value, weight, saturated) = interpolate(frame, levels, taps, x as i32, y as i32);
    }
    *out.0 = if weight > 0.0 { value } else { 0.0 };
    if saturated {
        *out.1 = out.1.with(MaskReason::Saturated);
    } else if weight <= 0.0 {
        *out.1 = out.1.with(MaskReason::NoSamples);
    }
}

/// Separable normalised convolution for a rectangular lattice: scatter each sample along its row
/// with the 1-D tent, then gather the (at most two) lattice rows in reach of each output row.
fn separable(
    frame: &RawFrame,
    levels: &Levels,
    colour: Option<Channel>,
    analyser: Analyser,
    lattice: Lattice,
    plane: &mut [f32],
    masks: &mut [PixelMask],
) {
    let (w, h) = (frame.width() as usize, frame.height() as usize);
    let period = lattice.period;
    let reach = period - 1;
    let kernel: Vec<f32> = (0..2 * period - 1)
        .map(|j| 1.0 - (j as f32 - reach as f32).abs() / period as f32)
        .collect();
    let rows = (h - lattice.y0).div_ceil(period);
    // per lattice row: Σ k·v, Σ k (unsaturated), Σ k (saturated), at every x
    let mut sum_v = vec![0.0f32; rows * w];
    let mut sum_w = vec![0.0f32; rows * w];
    let mut sum_s = vec![0.0f32; rows * w];
    for r in 0..rows {
        let Some(raw) = frame.row((lattice.y0 + r * period) as u32) else {
            continue;
        };
        let span = r * w..(r + 1) * w;
        let (sv, sw, ss) = (
            &mut sum_v[span.clone()],
            &mut sum_w[span.clone()],
            &mut sum_s[span],
        );
        for x in (lattice.x0..w).step_by(period) {
            let dn = raw[x];
            let first = x.saturating_sub(reach);
            let taps = &kernel[first + reach - x..];
            let end = (x + period).min(w);
            if levels.is_saturated(dn) {
                for (s, k) in ss[first..end].iter_mut().zip(taps) {
                    *s += k;
                }
            } else {
                let v = levels.normalise(dn);
                for ((a, b), k) in sv[first..end].iter_mut().zip(&mut sw[first..end]).zip(taps) {
                    *a += k * v;
                    *b += k;
                }
            }
        }
    }
    let mut fallback = None;
    let (mut acc_v, mut acc_w, mut acc_s) = (vec![0.0f32; w], vec![0.0f32; w], vec![0.0f32; w]);
    for y in 0..h {
        acc_v.fill(0.0);
        acc_w.fill(0.0);
        acc_s.fill(0.0);
        for (j, k) in kernel.iter().enumerate() {
            let Some(yy) = (y + j).checked_sub(reach) else {
                continue;
            };
            if yy >= h || yy < lattice.y0 || (yy - lattice.y0) % period != 0 {
                continue;
            }
            let span = (yy - lattice.y0) / period * w..((yy - lattice.y0) / period + 1) * w;
            for (acc, src) in [
                (&mut acc_v, &sum_v),
                (&mut acc_w, &sum_w),
                (&mut acc_s, &sum_s),
            ] {
                for (a, b) in acc.iter_mut().zip(&src[span.clone()]) {
                    *a += k * b;
                }
            }
        }
        let out_rows = plane[y * w..(y + 1) * w]
            .iter_mut()
            .zip(&mut masks[y * w..(y + 1) * w]);
        for (x, (out, m)) in out_rows.enumerate() {
            let sums = (acc_v[x], acc_w[x], acc_s[x]);
            finish_pixel(
                frame,
                levels,
                &mut fallback,
                colour,
                analyser,
                (x, y),
                sums,
                (out, m),
            );
        }
    }
}

/// Per-pixel tap lists (the quincunx G lattice, and the reference for the separable path).
fn per_pixel(
    frame: &RawFrame,
    levels: &Levels,
    colour: Option<Channel>,
    analyser: Analyser,
    plane: &mut [f32],
    masks: &mut [PixelMask],
) {
    let layout = frame.layout();
    let (w, h) = (frame.width() as usize, frame.height() as usize);
    let tile = layout.tile_px() as usize;
    let table = tap_table(layout, colour, analyser, 1);
    let mut fallback = None;
    for y in 0..h {
        for x in 0..w {
            let taps = &table[(y % tile) * tile + x % tile];
            let (value, weight, saturated) = interpolate(frame, levels, taps, x as i32, y as i32);
            let sums = (value * weight, weight, if saturated { 1.0 } else { 0.0 });
            let i = y * w + x;
            finish_pixel(
                frame,
                levels,
                &mut fallback,
                colour,
                analyser,
                (x, y),
                sums,
                (&mut plane[i], &mut masks[i]),
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::polar::demosaic::band_colours;

    #[test]
    fn tent_weights_sum_to_one_in_the_interior() {
        for layout in SensorLayout::ALL {
            for colour in band_colours(layout) {
                for a in Analyser::ALL {
                    for (phase, taps) in tap_table(layout, colour, a, 1).iter().enumerate() {
                        let sum: f32 = taps.iter().map(|t| t.weight).sum();
                        assert!(
                            (sum - 1.0).abs() < 1e-6,
                            "{layout:?} {colour:?} {a:?} phase {phase}: {sum} {taps:?}"
                        );
                        // a pixel on its own lattice uses only itself (interpolation, not blur)
                        let own = taps.iter().any(|t| t.dx == 0 && t.dy == 0);
                        if own {
                            assert_eq!(taps.len(), 1, "{taps:?}");
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn separable_path_equals_per_pixel_taps_with_saturation_and_borders() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(21);
        for layout in SensorLayout::ALL {
            let (w, h) = (12u32, 8u32);
            let data: Vec<u16> = (0..w * h)
                .map(|_| {
                    if rng.random_bool(0.1) {
                        4095
                    } else {
                        rng.random_range(0..4000)
                    }
                })
                .collect();
            let frame = RawFrame::new(w, h, 12, layout, data).expect("frame");
            let levels = Levels::new(4095, 10.0, 4095);
            for colour in band_colours(layout) {
                for a in Analyser::ALL {
                    let Some(lattice) = rectangular_lattice(layout, colour, a) else {
                        continue;
                    };
                    // the lattice really is where the mosaic puts (colour, analyser)
                    assert_eq!(layout.analyser_at(lattice.x0 as u32, lattice.y0 as u32), a);
                    assert_eq!(
                        layout.colour_at(lattice.x0 as u32, lattice.y0 as u32),
                        colour
                    );
                    let n = (w * h) as usize;
                    let (mut p1, mut m1) = (vec![0.0; n], vec![PixelMask::VALID; n]);
                    let (mut p2, mut m2) = (vec![0.0; n], vec![PixelMask::VALID; n]);
                    separable(&frame, &levels, colour, a, lattice, &mut p1, &mut m1);
                    per_pixel(&frame, &levels, colour, a, &mut p2, &mut m2);
                    assert_eq!(m1, m2, "{layout:?} {colour:?} {a:?}");
                    for (x, y) in p1.iter().zip(&p2) {
                        assert!(
                            (x - y).abs() < 1e-6,
                            "{layout:?} {colour:?} {a:?}: {x} vs {y}"
                        );
                    }
                }
            }
        }
    }
}
