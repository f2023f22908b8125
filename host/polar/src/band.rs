//! Types shared by both demosaic methods ([`crate::demosaic`] and its bilinear path): one
//! frame's raw-to-normalised [`Levels`], a band's four analyser planes ([`AnalyserBand`]) and the
//! reusable output-row buffer ([`RowBuf`]) the row-by-row consumers fill.

use ellipso_model::mosaic::Channel;

use super::mask::PixelMask;
use super::plane::Plane;

/// Raw-to-normalised conversion and saturation level, fixed for one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Levels {
    dark_dn: f32,
    scale: f32,
    saturation_dn: u16,
}

impl Levels {
    /// Levels for data with `full_scale_dn`, a dark level below it and a saturation level above
    /// the dark level. Callers validate (see `PolarConfig::levels`); out-of-order inputs are
    /// clamped so the scale stays finite and positive.
    pub(crate) fn new(full_scale_dn: u16, dark_dn: f32, saturation_dn: u16) -> Levels {
        let span = (f32::from(full_scale_dn) - dark_dn).max(1.0);
        Levels {
            dark_dn,
            scale: 1.0 / span,
            saturation_dn,
        }
    }

    /// Dark level subtracted from every sample, in DN.
    pub fn dark_dn(&self) -> f32 {
        self.dark_dn
    }

    /// Normalised intensity per DN (`1 / (full scale − dark)`).
    pub fn scale_per_dn(&self) -> f32 {
        self.scale
    }

    /// Samples at or above this DN are saturated.
    pub fn saturation_dn(&self) -> u16 {
        self.saturation_dn
    }

    /// Normalised intensity of a raw sample.
    #[inline(always)]
    pub fn normalise(&self, dn: u16) -> f32 {
        (f32::from(dn) - self.dark_dn) * self.scale
    }

    /// True when a raw sample is saturated.
    #[inline(always)]
    pub fn is_saturated(&self, dn: u16) -> bool {
        dn >= self.saturation_dn
    }
}

/// Four analyser planes (indexed by
/// [`Analyser::index`](ellipso_model::mosaic::Analyser::index): 0°, 45°, 90°, 135°) of one band.
#[derive(Debug, Clone, PartialEq)]
pub struct AnalyserBand {
    /// Colour filter (`None` for mono).
    pub colour: Option<Channel>,
    /// Normalised intensities `[I0, I45, I90, I135]`.
    pub intensity: [Plane<f32>; 4],
    /// Saturated / no-sample flags from demosaicing.
    pub mask: Plane<PixelMask>,
}

/// Reusable buffers for one superpixel output row.
#[derive(Debug, Default)]
pub(crate) struct RowBuf {
    pub intensity: [Vec<f32>; 4],
    pub mask: Vec<PixelMask>,
    /// Second colour block (G) of the row and per-block saturation flags.
    pub(crate) block: [Vec<f32>; 4],
    pub(crate) saturated: [Vec<bool>; 2],
}

impl RowBuf {
    pub(crate) fn reshape(&mut self, width: usize) {
        for v in self.intensity.iter_mut().chain(&mut self.block) {
            v.resize(width, 0.0);
        }
        for v in &mut self.saturated {
            v.resize(width, false);
        }
        self.mask.resize(width, PixelMask::VALID);
    }
}
