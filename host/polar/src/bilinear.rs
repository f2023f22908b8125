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

use ellipso_model::mosaic::{Analyser, Channel, SensorLayout};

use super::band::{AnalyserBand, Levels, RowBuf};
use super::frame::RawFrameView;
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
    frame: &RawFrameView<'_>,
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

/// A demosaiced band as full planes (the `demosaic()` API), built row by row.
pub(crate) fn bilinear_band(
    frame: &RawFrameView<'_>,
    levels: &Levels,
    colour: Option<Channel>,
) -> AnalyserBand {
    let (w, h) = (frame.width() as usize, frame.height() as usize);
    let mut intensity: [Plane<f32>; 4] = std::array::from_fn(|_| Plane::new(w, h));
    let mut mask: Plane<PixelMask> = Plane::new(w, h);
    let mut rows = BilinearRows::new(frame, levels, colour);
    let mut buf = RowBuf::default();
    for y in 0..h {
        rows.fill_row(y, &mut buf);
        let span = y * w..(y + 1) * w;
        for (plane, row) in intensity.iter_mut().zip(&buf.intensity) {
            plane.data_mut()[span.clone()].copy_from_slice(row);
        }
        mask.data_mut()[span].copy_from_slice(&buf.mask);
    }
    AnalyserBand {
        colour,
        intensity,
        mask,
    }
}

/// Streams bilinear output rows of one band, top to bottom, with O(width) memory.
pub(crate) struct BilinearRows<'f> {
    frame: &'f RawFrameView<'f>,
    levels: Levels,
    planes: [PlaneRows; 4],
}

impl<'f> BilinearRows<'f> {
    /// Prepares the four analyser planes of band `colour`.
    pub(crate) fn new(
        frame: &'f RawFrameView<'f>,
        levels: &Levels,
        colour: Option<Channel>,
    ) -> Self {
        let layout = frame.layout();
        let width = frame.width() as usize;
        BilinearRows {
            frame,
            levels: *levels,
            planes: Analyser::ALL.map(|a| {
                PlaneRows::new(
                    layout,
                    colour,
                    a,
                    width,
                    rectangular_lattice(layout, colour, a),
                )
            }),
        }
    }

    /// Fills `buf` with output row `y` (rows must be requested in increasing order for the
    /// row cache to be effective; any order is correct).
    pub(crate) fn fill_row(&mut self, y: usize, buf: &mut RowBuf) {
        let width = self.frame.width() as usize;
        buf.reshape(width);
        buf.mask.fill(PixelMask::VALID);
        for (plane, out) in self.planes.iter_mut().zip(buf.intensity.iter_mut()) {
            plane.row(self.frame, &self.levels, y, out, &mut buf.mask);
        }
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

/// One lattice row scattered along x with the 1-D tent: Σk·v, Σk (usable), Σk (saturated).
#[derive(Debug, Default)]
struct ScatteredRow {
    lattice_row: Option<usize>,
    sums: [Vec<f32>; 3],
}

/// How one analyser plane is interpolated.
#[derive(Debug)]
enum Method {
    /// Separable tent over a rectangular lattice, with two cached scattered lattice rows.
    Separable {
        lattice: Lattice,
        kernel: Vec<f32>,
        cache: [ScatteredRow; 2],
    },
    /// Per-pixel tap lists (the quincunx G lattice).
    Taps { table: Vec<Vec<Tap>> },
}

/// Row-streaming interpolation state of one (colour, analyser) plane.
#[derive(Debug)]
struct PlaneRows {
    colour: Option<Channel>,
    analyser: Analyser,
    method: Method,
    /// Accumulated Σk·v, Σk, Σk_saturated of the current output row.
    acc: [Vec<f32>; 3],
    /// Twice-the-reach taps, built on first need.
    fallback: Option<Vec<Vec<Tap>>>,
}

impl PlaneRows {
    fn new(
        layout: SensorLayout,
        colour: Option<Channel>,
        analyser: Analyser,
        width: usize,
        lattice: Option<Lattice>,
    ) -> PlaneRows {
        let method = match lattice {
            Some(lattice) => {
                let (period, reach) = (lattice.period as f32, lattice.period - 1);
                Method::Separable {
                    lattice,
                    kernel: (0..=2 * reach)
                        .map(|j| 1.0 - (j as f32 - reach as f32).abs() / period)
                        .collect(),
                    cache: Default::default(),
                }
            }
            None => Method::Taps {
                table: tap_table(layout, colour, analyser, 1),
            },
        };
        PlaneRows {
            colour,
            analyser,
            method,
            acc: std::array::from_fn(|_| vec![0.0; width]),
            fallback: None,
        }
    }

    /// Writes output row `y` of this plane into `out` and ORs its flags into `mask`.
    fn row(
        &mut self,
        frame: &RawFrameView<'_>,
        levels: &Levels,
        y: usize,
        out: &mut [f32],
        mask: &mut [PixelMask],
    ) {
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU supports AVX2 (checked just above), the only requirement of
                // `row_avx2`.
                unsafe { self.row_avx2(frame, levels, y, out, mask) };
                return;
            }
        }
        self.row_portable(frame, levels, y, out, mask);
    }

    /// [`Self::row_portable`] compiled for AVX2 (same operations, bit-identical results).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn row_avx2(
        &mut self,
        frame: &RawFrameView<'_>,
        levels: &Levels,
        y: usize,
        out: &mut [f32],
        mask: &mut [PixelMask],
    ) {
        self.row_portable(frame, levels, y, out, mask);
    }

    #[inline(always)]
    fn row_portable(
        &mut self,
        frame: &RawFrameView<'_>,
        levels: &Levels,
        y: usize,
        out: &mut [f32],
        mask: &mut [PixelMask],
    ) {
        match &mut self.method {
            Method::Separable {
                lattice,
                kernel,
                cache,
            } => {
                let [acc_v, acc_w, acc_s] = &mut self.acc;
                for a in [&mut *acc_v, &mut *acc_w, &mut *acc_s] {
                    a.fill(0.0);
                }
                let reach = lattice.period - 1;
                for (j, k) in kernel.iter().enumerate() {
                    let Some(yy) = (y + j).checked_sub(reach) else {
                        continue;
                    };
                    if yy >= frame.height() as usize
                        || yy < lattice.y0
                        || (yy - lattice.y0) % lattice.period != 0
                    {
                        continue;
                    }
                    let r = (yy - lattice.y0) / lattice.period;
                    let slot = cached_row(cache, frame, levels, *lattice, kernel, r);
                    for (acc, src) in [&mut *acc_v, &mut *acc_w, &mut *acc_s]
                        .into_iter()
                        .zip(&slot.sums)
                    {
                        for (a, b) in acc.iter_mut().zip(src) {
                            *a += k * b;
                        }
                    }
                }
                // separate simple loops so each vectorises
                for ((o, v), wt) in out.iter_mut().zip(&*acc_v).zip(&*acc_w) {
                    let value = v / wt.max(f32::MIN_POSITIVE);
                    *o = if *wt > 0.0 { value } else { 0.0 };
                }
                for (m, st) in mask.iter_mut().zip(&*acc_s) {
                    *m = PixelMask(m.0 | (u8::from(*st > 0.0) * MaskReason::Saturated.bit()));
                }
                let needs_fallback = acc_w
                    .iter()
                    .zip(&*acc_s)
                    .any(|(wt, st)| *wt <= 0.0 && *st <= 0.0);
                if needs_fallback {
                    for x in 0..out.len() {
                        if acc_w[x] <= 0.0 && acc_s[x] <= 0.0 {
                            let (o, m) = fallback_pixel(
                                &mut self.fallback,
                                frame,
                                levels,
                                self.colour,
                                self.analyser,
                                x,
                                y,
                            );
                            out[x] = o;
                            mask[x] = PixelMask(mask[x].0 | m.0);
                        }
                    }
                }
            }
            Method::Taps { table } => {
                let tile = frame.layout().tile_px() as usize;
                for (x, (o, m)) in out.iter_mut().zip(mask.iter_mut()).enumerate() {
                    let taps = &table[(y % tile) * tile + x % tile];
                    let (value, weight, saturated) =
                        interpolate(frame, levels, taps, x as i32, y as i32);
                    if saturated {
                        *o = value;
                        *m = m.with(MaskReason::Saturated);
                    } else if weight > 0.0 {
                        *o = value;
                    } else {
                        let (v, extra) = fallback_pixel(
                            &mut self.fallback,
                            frame,
                            levels,
                            self.colour,
                            self.analyser,
                            x,
                            y,
                        );
                        *o = v;
                        *m = PixelMask(m.0 | extra.0);
                    }
                }
            }
        }
    }
}

/// The scattered lattice row `r`, computed into the older cache slot if not cached.
fn cached_row<'c>(
    cache: &'c mut [ScatteredRow; 2],
    frame: &RawFrameView<'_>,
    levels: &Levels,
    lattice: Lattice,
    kernel: &[f32],
    r: usize,
) -> &'c ScatteredRow {
    let slot = match cache.iter().position(|c| c.lattice_row == Some(r)) {
        Some(i) => i,
        None => {
            // evict the empty or lower (older) row: rows are requested in increasing order
            let i = match (cache[0].lattice_row, cache[1].lattice_row) {
                (None, _) => 0,
                (_, None) => 1,
                (Some(a), Some(b)) => usize::from(b < a),
            };
            scatter(frame, levels, lattice, kernel, r, &mut cache[i]);
            i
        }
    };
    &cache[slot]
}

/// Scatters lattice row `r` along x into `row.sums`.
fn scatter(
    frame: &RawFrameView<'_>,
    levels: &Levels,
    lattice: Lattice,
    kernel: &[f32],
    r: usize,
    row: &mut ScatteredRow,
) {
    let w = frame.width() as usize;
    let reach = lattice.period - 1;
    row.lattice_row = Some(r);
    for s in &mut row.sums {
        s.clear();
        s.resize(w, 0.0);
    }
    let Some(raw) = frame.row((lattice.y0 + r * lattice.period) as u32) else {
        return;
    };
    let [sv, sw, ss] = &mut row.sums;
    for x in (lattice.x0..w).step_by(lattice.period) {
        let dn = raw[x];
        let first = x.saturating_sub(reach);
        let end = (x + lattice.period).min(w);
        let taps = &kernel[first + reach - x..];
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

/// Value and flags of a pixel none of whose bilinear taps is usable (and none saturated): the
/// twice-the-reach kernel, or `NoSamples`.
fn fallback_pixel(
    fallback: &mut Option<Vec<Vec<Tap>>>,
    frame: &RawFrameView<'_>,
    levels: &Levels,
    colour: Option<Channel>,
    analyser: Analyser,
    x: usize,
    y: usize,
) -> (f32, PixelMask) {
    let layout = frame.layout();
    let tile = layout.tile_px() as usize;
    let table = fallback.get_or_insert_with(|| tap_table(layout, colour, analyser, 2));
    let (value, weight, saturated) = interpolate(
        frame,
        levels,
        &table[(y % tile) * tile + x % tile],
        x as i32,
        y as i32,
    );
    let mask = if saturated {
        PixelMask::only(MaskReason::Saturated)
    } else if weight <= 0.0 {
        PixelMask::only(MaskReason::NoSamples)
    } else {
        PixelMask::VALID
    };
    (value, mask)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::demosaic::band_colours;

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
            let owned = crate::RawFrame::new(w, h, 12, layout, data).expect("frame");
            let frame = owned.view();
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
                    let mut fast = PlaneRows::new(layout, colour, a, w as usize, Some(lattice));
                    let mut reference = PlaneRows::new(layout, colour, a, w as usize, None);
                    for y in 0..h as usize {
                        let (mut p1, mut m1) =
                            (vec![0.0; w as usize], vec![PixelMask::VALID; w as usize]);
                        let (mut p2, mut m2) =
                            (vec![0.0; w as usize], vec![PixelMask::VALID; w as usize]);
                        fast.row(&frame, &levels, y, &mut p1, &mut m1);
                        reference.row(&frame, &levels, y, &mut p2, &mut m2);
                        assert_eq!(m1, m2, "{layout:?} {colour:?} {a:?} row {y}");
                        for (x, z) in p1.iter().zip(&p2) {
                            assert!(
                                (x - z).abs() < 1e-6,
                                "{layout:?} {colour:?} {a:?}: {x} vs {z}"
                            );
                        }
                    }
                }
            }
        }
    }
}
