//! A frame's analyser images as the sampler reads them: the [`AnalyserPixels`] interface, the
//! recorded mosaic's [`DnImage`] and its interpolation kernel ([`SampleKernel`]).
//!
//! Contract:
//! - [`DnImage`] holds the SUPERPIXEL planes of `ellipso_polar::demosaic` (no demosaic
//!   interpolation) converted back to dark-subtracted DN, plus per superpixel and colour band the
//!   largest raw DN of its samples (the saturation test). A raw position `x` maps to superpixel
//!   coordinate `(x − o)/t` with `t` the tile size and `o` the raw offset of the sample inside
//!   its tile: with [`SamplePoint::Lattice`] (default) `o` is where that colour-analyser sample
//!   really sits (a 0° mono sample at raw `2u + 1`; colour G averages its two blocks, so its
//!   offset is their mean), with [`SamplePoint::SuperpixelCentre`] it is the tile centre
//!   `(t − 1)/2` for every sample (track.rs step 3). Values are interpolated by the kernel in
//!   those coordinates, clamped to the edge superpixels at the frame's border.
//! - A sample is saturated when any superpixel in its kernel's footprint has a raw DN at or
//!   above the gate's saturation level, so a clipped neighbour never leaks into an interpolated
//!   value that looks unclipped.
//! - **Crops.** [`DnImage::crop`] keeps only the superpixels that samples inside a raw-pixel
//!   rectangle can reach (a fit's frame cache holds the object's part of each frame). A crop
//!   samples every point whose taps it holds ([`DnImage::covers`]) bit-identically to the whole
//!   frame — the taps and their clamping at the frame's border are computed in the whole
//!   frame's coordinates; a point whose taps it does not hold samples as NaN (the non-finite
//!   gate), never as a neighbour's value.

use ellipso_model::mosaic::{Analyser, SensorLayout};
use ellipso_polar::demosaic::{AnalyserImage, Levels};
use ellipso_polar::frame::RawFrame;

use super::SamplePoint;
use super::footprint::{Footprint, Octagon};
pub use super::rect::PixelRect;

/// The demosaiced frame in dark-subtracted DN (see the module contract).
#[derive(Clone, Debug)]
pub struct DnImage {
    tile_px: f64,
    kernel: SampleKernel,
    /// Half-side of the square of raw pixels a sampled value draws on, px.
    footprint_radius_px: f64,
    /// The whole frame's size in superpixels (the taps are clamped to it).
    frame_size: [usize; 2],
    /// Superpixel of the held planes' first element (0, 0 for a whole frame).
    origin: [usize; 2],
    /// Size of the held planes in superpixels.
    width: usize,
    height: usize,
    bands: Vec<DnBand>,
}

#[derive(Clone, Debug)]
struct DnBand {
    /// `[I0, I45, I90, I135]` planes, DN.
    dn: [Vec<f32>; 4],
    /// Raw offsets (x, y) of each analyser's sample inside the tile, px.
    offset_px: [[f64; 2]; 4],
    /// Largest dark-subtracted raw DN of the band's samples per superpixel.
    max_dn: Vec<f32>,
    /// How far (x, y) the band's blocks sit from their mean position (`offset_px`), raw px:
    /// a colour band's sample averages blocks up to this far apart.
    spread_px: [f64; 2],
}

impl DnImage {
    /// From a superpixel demosaic of `raw` with `levels`.
    pub fn new(
        raw: &RawFrame,
        image: &AnalyserImage,
        levels: &Levels,
        point: SamplePoint,
        kernel: SampleKernel,
    ) -> DnImage {
        let layout = raw.layout();
        let t = layout.tile_px() as usize;
        let (w, h) = (raw.width() as usize / t, raw.height() as usize / t);
        // DN per normalised unit, from the levels themselves (one definition of the scale).
        let dn_per_unit = 1.0 / (levels.normalise(1) - levels.normalise(0));
        let dark = levels.dark_dn();
        let data = raw.data_dn();
        let raw_w = raw.width() as usize;
        let bands = image
            .bands
            .iter()
            .map(|band| {
                let blocks: &[(usize, usize)] = match (layout, band.colour) {
                    (SensorLayout::ColourPolar, Some(c)) => c.blocks_in_tile(),
                    _ => &[(0, 0)],
                };
                let offset_px = Analyser::ALL.map(|a| match point {
                    SamplePoint::SuperpixelCentre => [(t as f64 - 1.0) / 2.0; 2],
                    SamplePoint::Lattice => {
                        let (ax, ay) = a.offset_in_block();
                        let n = blocks.len() as f64;
                        let mean = |f: &dyn Fn(&(usize, usize)) -> usize| {
                            blocks.iter().map(|b| f(b) as f64).sum::<f64>() / n
                        };
                        [mean(&|b| 2 * b.0 + ax), mean(&|b| 2 * b.1 + ay)]
                    }
                });
                let dn = std::array::from_fn(|k| {
                    band.intensity[k]
                        .data()
                        .iter()
                        .map(|&v| v * dn_per_unit)
                        .collect()
                });
                // Row by row: for each block of the tile, the two raw rows it covers, and the
                // largest of its 2×2 samples per tile column (the tiles lie inside the frame:
                // w·t ≤ raw width, h·t ≤ raw height).
                let mut max_dn = vec![0f32; w * h];
                let mut top = vec![0u16; w];
                for (j, row) in max_dn.chunks_exact_mut(w).enumerate() {
                    top.fill(0);
                    for &(bx, by) in blocks {
                        for dy in 0..2 {
                            let y = t * j + 2 * by + dy;
                            let Some(raw_row) = data.get(y * raw_w..(y + 1) * raw_w) else {
                                continue;
                            };
                            for (i, m) in top.iter_mut().enumerate() {
                                let x = t * i + 2 * bx;
                                if let Some(pair) = raw_row.get(x..x + 2) {
                                    *m = (*m).max(pair[0]).max(pair[1]);
                                }
                            }
                        }
                    }
                    for (m, &v) in row.iter_mut().zip(&top) {
                        *m = f32::from(v) - dark;
                    }
                }
                let spread_px = std::array::from_fn(|axis| {
                    let n = blocks.len() as f64;
                    let pos = |b: &(usize, usize)| 2.0 * if axis == 0 { b.0 } else { b.1 } as f64;
                    let mean = blocks.iter().map(pos).sum::<f64>() / n;
                    blocks
                        .iter()
                        .map(|b| (pos(b) - mean).abs())
                        .fold(0.0, f64::max)
                });
                DnBand {
                    dn,
                    offset_px,
                    max_dn,
                    spread_px,
                }
            })
            .collect();
        // A value interpolates lattice samples within one tile of the point (two for the
        // cubic kernel); a colour band's sample averages its blocks, which sit up to `spread`
        // raw pixels from their mean; every raw pixel covers ±½ px.
        let spread = match layout {
            SensorLayout::ColourPolar => ellipso_model::mosaic::Channel::ALL
                .iter()
                .map(|c| {
                    let b = c.blocks_in_tile();
                    let n = b.len() as f64;
                    let (mx, my) = (
                        b.iter().map(|b| 2.0 * b.0 as f64).sum::<f64>() / n,
                        b.iter().map(|b| 2.0 * b.1 as f64).sum::<f64>() / n,
                    );
                    b.iter()
                        .map(|b| {
                            (2.0 * b.0 as f64 - mx)
                                .abs()
                                .max((2.0 * b.1 as f64 - my).abs())
                        })
                        .fold(0.0, f64::max)
                })
                .fold(0.0, f64::max),
            SensorLayout::MonoPolar => 0.0,
        };
        DnImage {
            tile_px: t as f64,
            kernel,
            footprint_radius_px: kernel.reach_tiles() * t as f64 + spread + 0.5,
            frame_size: [w, h],
            origin: [0, 0],
            width: w,
            height: h,
            bands,
        }
    }

    /// Number of colour bands (1 mono, 3 colour).
    pub fn band_count(&self) -> usize {
        self.bands.len()
    }

    /// Bytes held by the planes.
    pub fn bytes(&self) -> usize {
        self.bands.len() * 5 * self.width * self.height * std::mem::size_of::<f32>()
    }

    /// Analyser DN `[I0, I45, I90, I135]` per band at raw pixel `(x, y)`, and per band and
    /// analyser the largest raw DN in the kernel's footprint (NaN where a crop does not hold
    /// the taps, see the module contract).
    pub fn sample(&self, pixel: [f64; 2]) -> ([[f32; 4]; 3], [[f32; 4]; 3]) {
        self.sample_with(self.kernel, pixel)
    }

    /// [`DnImage::sample`] with `kernel` instead of the image's own (its taps lie within the
    /// image's own kernel's reach when `kernel` reaches no farther: a crop holds them).
    pub fn sample_with(
        &self,
        kernel: SampleKernel,
        pixel: [f64; 2],
    ) -> ([[f32; 4]; 3], [[f32; 4]; 3]) {
        let mut values = [[0f32; 4]; 3];
        let mut peaks = [[0f32; 4]; 3];
        let [fw, fh] = self.frame_size;
        let [ox, oy] = self.origin;
        let w = self.width;
        let held = |i: usize, o: usize, n: usize| i.checked_sub(o).filter(|&i| i < n);
        for (b, band) in self.bands.iter().enumerate().take(3) {
            for k in 0..4 {
                let [px, py] = band.offset_px[k];
                let sx = (pixel[0] - px) / self.tile_px;
                let sy = (pixel[1] - py) / self.tile_px;
                let taps_x = kernel.taps(sx, fw);
                let taps_y = kernel.taps(sy, fh);
                let plane = &band.dn[k];
                let mut v = 0.0;
                let mut peak = f32::NEG_INFINITY;
                'taps: for &(y, wy) in taps_y.iter().filter(|t| t.1 != 0.0) {
                    for &(x, wx) in taps_x.iter().filter(|t| t.1 != 0.0) {
                        let (Some(x), Some(y)) = (held(x, ox, w), held(y, oy, self.height)) else {
                            v = f64::NAN;
                            peak = f32::NAN;
                            break 'taps;
                        };
                        v += wx * wy * f64::from(plane[y * w + x]);
                        peak = peak.max(band.max_dn[y * w + x]);
                    }
                }
                values[b][k] = v as f32;
                peaks[b][k] = peak;
            }
        }
        (values, peaks)
    }

    /// The raw pixels the value at `pixel` draws on through taps whose weight |w_x·w_y| is at
    /// least `min_weight` (every band and analyser; a tap covers its band's blocks, each ±½ px),
    /// as the probe points of their bounding octagon ([`Footprint`]): the sample's real
    /// footprint, which the kernel's phase at that pixel decides — one tile where a lattice
    /// sample sits on the point, a cross of four tiles' reach for a Catmull–Rom value halfway
    /// between samples.
    pub fn footprint(&self, pixel: [f64; 2], min_weight: f64) -> Footprint {
        self.footprint_with(self.kernel, pixel, min_weight)
    }

    /// [`DnImage::footprint`] of a value interpolated with `kernel`.
    pub fn footprint_with(
        &self,
        kernel: SampleKernel,
        pixel: [f64; 2],
        min_weight: f64,
    ) -> Footprint {
        let mut octagon = Octagon::default();
        for band in self.bands.iter().take(3) {
            let half = band.spread_px.map(|s| s + 0.5);
            for offset in &band.offset_px {
                let lattice = |axis: usize| (pixel[axis] - offset[axis]) / self.tile_px;
                let taps_x = kernel.taps(lattice(0), self.frame_size[0]);
                let taps_y = kernel.taps(lattice(1), self.frame_size[1]);
                for &(iy, wy) in &taps_y {
                    for &(ix, wx) in &taps_x {
                        let w = wx * wy;
                        if w == 0.0 || w.abs() < min_weight {
                            continue;
                        }
                        let cx = ix as f64 * self.tile_px + offset[0];
                        let cy = iy as f64 * self.tile_px + offset[1];
                        octagon
                            .add_block([cx - half[0], cx + half[0]], [cy - half[1], cy + half[1]]);
                    }
                }
            }
        }
        if octagon.is_empty() {
            // No tap (cannot happen: the weights sum to 1): the kernel's whole reach.
            return Footprint::square(pixel, kernel.reach_tiles() * self.tile_px + 0.5);
        }
        octagon.footprint()
    }

    /// The superpixel range `[lo, hi)` per axis whose planes hold every tap of a sample inside
    /// `rect`, clamped to the frame.
    fn tap_range(&self, rect: &PixelRect) -> [[usize; 2]; 2] {
        let reach = self.kernel.reach_tiles();
        std::array::from_fn(|axis| {
            let offsets = self.bands.iter().flat_map(|b| b.offset_px.map(|o| o[axis]));
            let (o_min, o_max) = offsets.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), o| {
                (a.min(o), b.max(o))
            });
            let n = self.frame_size[axis];
            // The taps of coordinate s are floor(s) − (reach − 1) … floor(s) + reach; one
            // more on each side absorbs rounding.
            let lo = ((rect.min[axis] - o_max) / self.tile_px).floor() - reach;
            let hi = ((rect.max[axis] - o_min) / self.tile_px).floor() + reach + 2.0;
            let clamp = |v: f64| {
                if v.is_nan() {
                    0
                } else {
                    v.clamp(0.0, n as f64) as usize
                }
            };
            [clamp(lo), clamp(hi)]
        })
    }

    /// Whether every sample inside `rect` reads only superpixels this image holds (always true
    /// of a whole frame).
    pub fn covers(&self, rect: &PixelRect) -> bool {
        let need = self.tap_range(rect);
        let held = [
            [self.origin[0], self.origin[0] + self.width],
            [self.origin[1], self.origin[1] + self.height],
        ];
        (0..2).all(|a| need[a][0] >= held[a][0] && need[a][1] <= held[a][1])
            || (self.width, self.height) == (self.frame_size[0], self.frame_size[1])
    }

    /// The part of this image that samples inside `rect` read (see the module contract).
    pub fn crop(&self, rect: &PixelRect) -> DnImage {
        let [[x0, x1], [y0, y1]] = self.tap_range(rect);
        // held coordinates of the wanted range (a crop of a crop keeps what it holds)
        let x0 = x0.max(self.origin[0]);
        let y0 = y0.max(self.origin[1]);
        let x1 = x1.min(self.origin[0] + self.width).max(x0);
        let y1 = y1.min(self.origin[1] + self.height).max(y0);
        let (w, h) = (x1 - x0, y1 - y0);
        let copy = |plane: &[f32]| -> Vec<f32> {
            let mut out = Vec::with_capacity(w * h);
            for y in y0..y1 {
                let row = (y - self.origin[1]) * self.width;
                let from = row + x0 - self.origin[0];
                out.extend_from_slice(&plane[from..from + w]);
            }
            out
        };
        DnImage {
            tile_px: self.tile_px,
            kernel: self.kernel,
            footprint_radius_px: self.footprint_radius_px,
            frame_size: self.frame_size,
            origin: [x0, y0],
            width: w,
            height: h,
            bands: self
                .bands
                .iter()
                .map(|b| DnBand {
                    dn: std::array::from_fn(|k| copy(&b.dn[k])),
                    offset_px: b.offset_px,
                    max_dn: copy(&b.max_dn),
                    spread_px: b.spread_px,
                })
                .collect(),
        }
    }
}

/// How the analyser planes are interpolated at a sample's lattice coordinate.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SampleKernel {
    /// Bilinear (2 × 2 superpixels): smooths a shading profile's curvature and a highlight's
    /// peak by up to a tile on each side (measured: −0.2 … −0.7 % η per material on the demo
    /// through the true mesh, docs/error-budget.md).
    Bilinear,
    /// Catmull–Rom cubic convolution (Keys 1981, a = −½; 4 × 4 superpixels): exact for
    /// quadratics, so a shading profile's curvature does not bias the value.
    #[default]
    CatmullRom,
}

impl SampleKernel {
    /// How many lattice steps (tiles) on each side of the point the kernel's taps reach.
    pub fn reach_tiles(self) -> f64 {
        match self {
            SampleKernel::Bilinear => 1.0,
            SampleKernel::CatmullRom => 2.0,
        }
    }

    /// Up to four (index, weight) taps of lattice coordinate `s` in `0..n`; indices are clamped
    /// to the plane (the edge sample repeats), weights sum to 1.
    fn taps(self, s: f64, n: usize) -> [(usize, f64); 4] {
        let hi = n.saturating_sub(1);
        let s = s.clamp(0.0, hi as f64);
        let i = (s.floor() as usize).min(n.saturating_sub(2));
        let f = s - i as f64;
        let at = |d: isize| (i as isize + d).clamp(0, hi as isize) as usize;
        match self {
            SampleKernel::Bilinear => [(at(0), 1.0 - f), (at(1), f), (at(0), 0.0), (at(0), 0.0)],
            SampleKernel::CatmullRom => {
                let (f2, f3) = (f * f, f * f * f);
                [
                    (at(-1), 0.5 * (-f3 + 2.0 * f2 - f)),
                    (at(0), 0.5 * (3.0 * f3 - 5.0 * f2 + 2.0)),
                    (at(1), 0.5 * (-3.0 * f3 + 4.0 * f2 + f)),
                    (at(2), 0.5 * (f3 - f2)),
                ]
            }
        }
    }
}

/// A frame's analyser images as the sampler reads them (the recorded mosaic's [`DnImage`], or
/// an ideal sensor's in the error budget): per band, the four analysers' dark-subtracted DN at
/// a raw pixel position, and the largest raw DN of the pixels that value draws on (the
/// saturation test).
pub trait AnalyserPixels: Sync {
    /// Number of colour bands (1 mono, 3 colour).
    fn band_count(&self) -> usize;
    /// `[I0, I45, I90, I135]` per band at raw pixel `(x, y)`, and per band and analyser the
    /// largest raw DN in the footprint.
    fn sample(&self, pixel: [f64; 2]) -> ([[f32; 4]; 3], [[f32; 4]; 3]);
    /// Half-side of the square of raw pixels about the sampled point that a value draws on
    /// (its footprint), px; 0 for a point sample.
    fn footprint_radius_px(&self) -> f64;
    /// The raw pixels the value at `pixel` draws on through taps weighing at least
    /// `min_weight`, as probe points ([`Footprint`]); by default the square of
    /// [`Self::footprint_radius_px`].
    fn footprint(&self, pixel: [f64; 2], min_weight: f64) -> Footprint {
        let _ = min_weight;
        Footprint::square(pixel, self.footprint_radius_px())
    }
    /// The value at `pixel` from a kernel of smaller reach, with its footprint (taps of weight
    /// at least `min_weight`): what a sample whose own footprint leaves the vertex's surface
    /// can fall back on ([`super::sampler`]). `None` where the image has no narrower kernel.
    #[expect(
        clippy::type_complexity,
        reason = "the pair sample() returns, with its footprint"
    )]
    fn narrow(
        &self,
        pixel: [f64; 2],
        min_weight: f64,
    ) -> Option<(Footprint, ([[f32; 4]; 3], [[f32; 4]; 3]))> {
        let _ = (pixel, min_weight);
        None
    }
}

/// A shared image (a frame cache's crop) reads as the image itself.
impl<T: AnalyserPixels + Send> AnalyserPixels for std::sync::Arc<T> {
    fn band_count(&self) -> usize {
        (**self).band_count()
    }

    fn sample(&self, pixel: [f64; 2]) -> ([[f32; 4]; 3], [[f32; 4]; 3]) {
        (**self).sample(pixel)
    }

    fn footprint_radius_px(&self) -> f64 {
        (**self).footprint_radius_px()
    }

    fn footprint(&self, pixel: [f64; 2], min_weight: f64) -> Footprint {
        (**self).footprint(pixel, min_weight)
    }

    fn narrow(
        &self,
        pixel: [f64; 2],
        min_weight: f64,
    ) -> Option<(Footprint, ([[f32; 4]; 3], [[f32; 4]; 3]))> {
        (**self).narrow(pixel, min_weight)
    }
}

impl AnalyserPixels for DnImage {
    fn band_count(&self) -> usize {
        DnImage::band_count(self)
    }

    fn sample(&self, pixel: [f64; 2]) -> ([[f32; 4]; 3], [[f32; 4]; 3]) {
        DnImage::sample(self, pixel)
    }

    fn footprint_radius_px(&self) -> f64 {
        self.footprint_radius_px
    }

    fn footprint(&self, pixel: [f64; 2], min_weight: f64) -> Footprint {
        DnImage::footprint(self, pixel, min_weight)
    }

    /// The bilinear value (a tile's reach instead of two) where the image's own kernel is the
    /// cubic one.
    fn narrow(
        &self,
        pixel: [f64; 2],
        min_weight: f64,
    ) -> Option<(Footprint, ([[f32; 4]; 3], [[f32; 4]; 3]))> {
        (self.kernel.reach_tiles() > SampleKernel::Bilinear.reach_tiles()).then(|| {
            (
                self.footprint_with(SampleKernel::Bilinear, pixel, min_weight),
                self.sample_with(SampleKernel::Bilinear, pixel),
            )
        })
    }
}

#[cfg(test)]
mod tests;
