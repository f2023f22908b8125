//! Demosaicing: from a raw mosaic frame to four analyser-intensity planes per colour band.
//!
//! Two methods, named in every output ([`DemosaicMethod::name`]):
//!
//! - **Superpixel** (default): each 2×2 polariser block becomes one output pixel, no
//!   interpolation. Mono gives (W/2)×(H/2); colour gives (W/4)×(H/4) per R, G, B band (the two G
//!   blocks of a 4×4 tile are averaged). The four analysers of an output pixel see four
//!   neighbouring points (instantaneous-field-of-view error at edges), but no value is ever mixed
//!   from different superpixels: the conservative choice for fitting.
//! - **Bilinear**: full resolution W×H. Each (colour, analyser) sample lattice is interpolated
//!   with a tent kernel normalised by the weights of the samples used: rectangular lattices (all
//!   mono planes; R and B) with a separable tent of one lattice period, the quincunx G lattice
//!   with a tent in its own 45°-rotated lattice axes. In the interior this is exact bilinear
//!   interpolation (reproduces affine fields); at the frame border missing neighbours are
//!   dropped and the weights renormalised. Edges in the scene give colour/polarisation fringes
//!   (IFoV artefacts); use it for viewing, superpixel for measuring.
//!
//! Normalisation: `I = (DN − dark_dn) / (full_scale_dn − dark_dn)`, not clamped (noise below
//! the dark level stays negative and unbiased; dark masking happens on s0 later).
//!
//! Masking: a raw sample at or above the saturation level is never used. A superpixel with any
//! saturated sample is [`MaskReason::Saturated`] (for G, a tile is only saturated when both G
//! blocks are; otherwise the unsaturated block alone is used). A bilinear output is
//! [`MaskReason::Saturated`] when any sample in its kernel footprint was saturated (the value is
//! still interpolated from the unsaturated ones, for display), and [`MaskReason::NoSamples`] when
//! some analyser had no sample in reach.

use ellipso_model::mosaic::{Analyser, Channel, SensorLayout};
use serde::Serialize;

pub(crate) use super::band::RowBuf;
pub use super::band::{AnalyserBand, Levels};
use super::bilinear;
use super::frame::{RawFrame, RawFrameView};
use super::mask::{MaskReason, PixelMask};
use super::plane::Plane;

/// How the mosaic is turned into per-analyser planes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum DemosaicMethod {
    /// One output pixel per 2×2 polariser block; no interpolation.
    #[default]
    Superpixel,
    /// Full resolution; tent-kernel (bilinear) interpolation per colour-analyser lattice.
    Bilinear,
}

impl DemosaicMethod {
    /// Lowercase name as written in outputs (`superpixel`, `bilinear`).
    pub fn name(self) -> &'static str {
        match self {
            DemosaicMethod::Superpixel => "superpixel",
            DemosaicMethod::Bilinear => "bilinear",
        }
    }

    /// One-line description for reports.
    pub fn description(self) -> &'static str {
        match self {
            DemosaicMethod::Superpixel => {
                "2x2 superpixel, no interpolation (colour: G blocks averaged), half (mono) or quarter (colour) resolution"
            }
            DemosaicMethod::Bilinear => {
                "bilinear (tent kernel per colour-analyser lattice, renormalised at borders and around saturated samples), full resolution"
            }
        }
    }

    /// Output size for a `width × height` raw frame of `layout`.
    pub fn output_size(self, layout: SensorLayout, width: u32, height: u32) -> (usize, usize) {
        let (w, h) = (width as usize, height as usize);
        match (self, layout) {
            (DemosaicMethod::Bilinear, _) => (w, h),
            (DemosaicMethod::Superpixel, SensorLayout::MonoPolar) => (w / 2, h / 2),
            (DemosaicMethod::Superpixel, SensorLayout::ColourPolar) => (w / 4, h / 4),
        }
    }
}

/// The demosaiced frame: one [`AnalyserBand`] (mono) or three (R, G, B).
#[derive(Debug, Clone, PartialEq)]
pub struct AnalyserImage {
    /// Method used.
    pub method: DemosaicMethod,
    /// Layout of the source frame.
    pub layout: SensorLayout,
    /// Bands: `[mono]` or `[R, G, B]`.
    pub bands: Vec<AnalyserBand>,
}

/// Band colours of a layout: `[None]` for mono, `[R, G, B]` for colour.
pub(crate) fn band_colours(layout: SensorLayout) -> Vec<Option<Channel>> {
    match layout {
        SensorLayout::MonoPolar => vec![None],
        SensorLayout::ColourPolar => Channel::ALL.iter().copied().map(Some).collect(),
    }
}

/// Demosaics `frame` (owned or borrowed samples) with `method` into normalised analyser planes.
pub fn demosaic<D: AsRef<[u16]>>(
    frame: &RawFrame<D>,
    levels: &Levels,
    method: DemosaicMethod,
) -> AnalyserImage {
    let frame = &frame.view();
    let bands = match method {
        DemosaicMethod::Superpixel => band_colours(frame.layout())
            .into_iter()
            .map(|colour| superpixel_band(frame, levels, colour))
            .collect(),
        DemosaicMethod::Bilinear => band_colours(frame.layout())
            .into_iter()
            .map(|colour| bilinear::bilinear_band(frame, levels, colour))
            .collect(),
    };
    AnalyserImage {
        method,
        layout: frame.layout(),
        bands,
    }
}

fn superpixel_band(
    frame: &RawFrameView<'_>,
    levels: &Levels,
    colour: Option<Channel>,
) -> AnalyserBand {
    let (w, h) =
        DemosaicMethod::Superpixel.output_size(frame.layout(), frame.width(), frame.height());
    let mut band = AnalyserBand {
        colour,
        intensity: std::array::from_fn(|_| Plane::new(w, h)),
        mask: Plane::new(w, h),
    };
    let mut buf = RowBuf::default();
    for y in 0..h {
        superpixel_row(frame, levels, colour, y, &mut buf);
        let r = y * w..(y + 1) * w;
        for (plane, row) in band.intensity.iter_mut().zip(&buf.intensity) {
            plane.data_mut()[r.clone()].copy_from_slice(row);
        }
        band.mask.data_mut()[r].copy_from_slice(&buf.mask);
    }
    band
}

// Positions inside the 2×2 block, taken at compile time from the single mosaic definition.
const POS_0: (usize, usize) = Analyser::Deg0.offset_in_block();
const POS_45: (usize, usize) = Analyser::Deg45.offset_in_block();
const POS_90: (usize, usize) = Analyser::Deg90.offset_in_block();
const POS_135: (usize, usize) = Analyser::Deg135.offset_in_block();

/// Fills `buf` with superpixel output row `y_out` of band `colour`.
pub(crate) fn superpixel_row(
    frame: &RawFrameView<'_>,
    levels: &Levels,
    colour: Option<Channel>,
    y_out: usize,
    buf: &mut RowBuf,
) {
    let (w_out, _) =
        DemosaicMethod::Superpixel.output_size(frame.layout(), frame.width(), frame.height());
    buf.reshape(w_out);
    match colour {
        None => superpixel_mono_row(frame, levels, y_out, buf),
        Some(c) => superpixel_colour_row(frame, levels, c, y_out, buf),
    }
}

/// The hot path: one row of 2×2 superpixels; AVX2 where the CPU has it (same operations, so
/// bit-identical results).
fn superpixel_mono_row(frame: &RawFrameView<'_>, levels: &Levels, y_out: usize, buf: &mut RowBuf) {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2 (checked just above), the only requirement of
            // `superpixel_mono_row_avx2`.
            unsafe { superpixel_mono_row_avx2(frame, levels, y_out, buf) };
            return;
        }
    }
    superpixel_mono_row_portable(frame, levels, y_out, buf);
}

/// [`superpixel_mono_row_portable`] compiled for AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn superpixel_mono_row_avx2(
    frame: &RawFrameView<'_>,
    levels: &Levels,
    y_out: usize,
    buf: &mut RowBuf,
) {
    superpixel_mono_row_portable(frame, levels, y_out, buf);
}

/// One row of 2×2 superpixels, iterator-driven (no bounds checks, no allocation).
#[inline(always)]
fn superpixel_mono_row_portable(
    frame: &RawFrameView<'_>,
    levels: &Levels,
    y_out: usize,
    buf: &mut RowBuf,
) {
    let w = frame.width() as usize;
    let data = frame.data_dn();
    let start = 2 * y_out * w;
    let (Some(r0), Some(r1)) = (
        data.get(start..start + w),
        data.get(start + w..start + 2 * w),
    ) else {
        return; // unreachable for y_out < height/2: the frame size is validated
    };
    let rows = [r0, r1];
    let sat = levels.saturation_dn();
    let [o0, o45, o90, o135] = &mut buf.intensity;
    let blocks = rows[0].chunks_exact(2).zip(rows[1].chunks_exact(2));
    let outs = o0
        .iter_mut()
        .zip(o45.iter_mut())
        .zip(o90.iter_mut())
        .zip(o135.iter_mut())
        .zip(buf.mask.iter_mut());
    for ((top, bottom), ((((v0, v45), v90), v135), m)) in blocks.zip(outs) {
        let pick = |pos: (usize, usize)| {
            if pos.1 == 0 {
                top[pos.0]
            } else {
                bottom[pos.0]
            }
        };
        let (d0, d45, d90, d135) = (pick(POS_0), pick(POS_45), pick(POS_90), pick(POS_135));
        *v0 = levels.normalise(d0);
        *v45 = levels.normalise(d45);
        *v90 = levels.normalise(d90);
        *v135 = levels.normalise(d135);
        let saturated = (d0 >= sat) | (d45 >= sat) | (d90 >= sat) | (d135 >= sat);
        *m = PixelMask(u8::from(saturated) * MaskReason::Saturated.bit());
    }
}

/// One row of colour superpixels (4×4 tiles) for channel `colour`: R and B straight from their
/// block; G from both G blocks, averaged where both are unsaturated, else the unsaturated one.
fn superpixel_colour_row(
    frame: &RawFrameView<'_>,
    levels: &Levels,
    colour: Channel,
    y_out: usize,
    buf: &mut RowBuf,
) {
    let blocks = colour.blocks_in_tile();
    let [sat_a, sat_b] = &mut buf.saturated;
    let Some(&first) = blocks.first() else {
        return;
    };
    block_row(frame, levels, y_out, first, &mut buf.intensity, sat_a);
    let Some(&second) = blocks.get(1) else {
        for (m, s) in buf.mask.iter_mut().zip(sat_a.iter()) {
            *m = PixelMask(u8::from(*s) * MaskReason::Saturated.bit());
        }
        return;
    };
    block_row(frame, levels, y_out, second, &mut buf.block, sat_b);
    for (k, (out, other)) in buf.intensity.iter_mut().zip(&buf.block).enumerate() {
        for (((o, b), sa), sb) in out
            .iter_mut()
            .zip(other)
            .zip(sat_a.iter())
            .zip(sat_b.iter())
        {
            *o = match (*sa, *sb) {
                (false, true) => *o,
                (true, false) => *b,
                _ => 0.5 * (*o + *b), // both usable, or both saturated (display value only)
            };
        }
        if k == 0 {
            for ((m, sa), sb) in buf.mask.iter_mut().zip(sat_a.iter()).zip(sat_b.iter()) {
                *m = PixelMask(u8::from(*sa && *sb) * MaskReason::Saturated.bit());
            }
        }
    }
}

/// Normalised analyser values of 2×2 block `block` (block offsets in the 4×4 tile) for every
/// tile of colour-superpixel row `y_out`, and whether any of its four samples is saturated.
fn block_row(
    frame: &RawFrameView<'_>,
    levels: &Levels,
    y_out: usize,
    block: (usize, usize),
    out: &mut [Vec<f32>; 4],
    saturated: &mut [bool],
) {
    let w = frame.width() as usize;
    let y0 = 4 * y_out + 2 * block.1;
    let data = frame.data_dn();
    let (Some(r0), Some(r1)) = (
        data.get(y0 * w..(y0 + 1) * w),
        data.get((y0 + 1) * w..(y0 + 2) * w),
    ) else {
        return; // unreachable for y_out < height/4: the frame size is validated
    };
    let x_off = 2 * block.0;
    let [o0, o45, o90, o135] = out;
    let tiles = r0.chunks_exact(4).zip(r1.chunks_exact(4));
    let outs = o0
        .iter_mut()
        .zip(o45.iter_mut())
        .zip(o90.iter_mut())
        .zip(o135.iter_mut())
        .zip(saturated.iter_mut());
    for ((top, bottom), ((((v0, v45), v90), v135), sat)) in tiles.zip(outs) {
        let pick = |pos: (usize, usize)| {
            let row = if pos.1 == 0 { top } else { bottom };
            row.get(x_off + pos.0).copied().unwrap_or(0)
        };
        let (d0, d45, d90, d135) = (pick(POS_0), pick(POS_45), pick(POS_90), pick(POS_135));
        *v0 = levels.normalise(d0);
        *v45 = levels.normalise(d45);
        *v90 = levels.normalise(d90);
        *v135 = levels.normalise(d135);
        *sat = levels.is_saturated(d0)
            | levels.is_saturated(d45)
            | levels.is_saturated(d90)
            | levels.is_saturated(d135);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn output_sizes() {
        let m = SensorLayout::MonoPolar;
        let c = SensorLayout::ColourPolar;
        assert_eq!(
            DemosaicMethod::Superpixel.output_size(m, 2448, 2048),
            (1224, 1024)
        );
        assert_eq!(
            DemosaicMethod::Superpixel.output_size(c, 2448, 2048),
            (612, 512)
        );
        assert_eq!(
            DemosaicMethod::Bilinear.output_size(c, 2448, 2048),
            (2448, 2048)
        );
    }

    #[test]
    fn levels_normalise_and_saturate() {
        let l = Levels::new(4095, 95.0, 4000);
        assert_eq!(l.normalise(95), 0.0);
        assert!((l.normalise(4095) - 1.0).abs() < 1e-7);
        assert!(l.normalise(0) < 0.0, "below dark stays negative (unbiased)");
        assert!(l.is_saturated(4000) && !l.is_saturated(3999));
    }
}
