//! `ellipso-polar`: polarisation-mosaic processing for Sony IMX250MZR (mono) / IMX250MYR (colour) sensors.
//!
//! A raw mosaic frame ([`RawFrame`], pattern from [`ellipso_model::mosaic`]) becomes, per colour
//! band, f32 planes of s0, s1, s2, DoLP, AoLP, the consistency residual and the rig's
//! observation channels I^d, I^s, I^α, plus a validity mask with reasons ([`PixelMask`]).
//!
//! ```text
//! RawFrame ──demosaic (superpixel | bilinear)──▶ AnalyserImage ──stokes──▶ PolarImage
//!          └────── process(): either method fused row by row, no full-size intermediate ──┘
//! ```
//!
//! [`convert`] is `ellipso polar`: one raw frame file (PNG, TIFF, `.npy`) read, processed and
//! written as pictures, `stokes.exr` and `summary.json` into an owned folder.
//!
//! ```
//! use ellipso_polar::{PolarConfig, process, synthetic::mosaic_from_stokes};
//! use ellipso_model::mosaic::SensorLayout;
//!
//! // A 12-bit IMX250MZR frame of light polarised at 30° (DoLP 0.5); s in DN.
//! let phi = 30f64.to_radians();
//! let frame = mosaic_from_stokes(SensorLayout::MonoPolar, 64, 48, 12, |_, _, _| {
//!     [2000.0, 1000.0 * (2.0 * phi).cos(), 1000.0 * (2.0 * phi).sin()]
//! })?;
//! let image = process(&frame, &PolarConfig::default())?; // superpixel: 32×24
//! let band = &image.bands[0];
//! assert_eq!((image.width(), image.height()), (32, 24));
//! assert!(band.mask.data()[0].is_valid());
//! assert!((band.dolp.data()[0] - 0.5).abs() < 1e-3);
//! assert!((band.aolp_rad.data()[0].to_degrees() - 30.0).abs() < 0.1);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! # Conventions (stated once; docs/polar.md repeats them with the check procedure)
//!
//! - Image coordinates: `x` to image-right, rows `y` grow **downward**; origin at the first pixel
//!   delivered, sensor not flipped.
//! - Analyser angle θ: from image-right toward image-**up**, seen in the unflipped displayed
//!   image, i.e. looking back along the direction of propagation. I45 is the analyser at +45°.
//! - AoLP: counter-clockwise from image-right in that view, in radians, in [0, π).
//! - Stokes (Hagen et al., Opt. Eng. 58(8) 080501, 2019; `elerac/polanalyser: polanalyser/stokes.py`):
//!   `s0 = ½(I0+I45+I90+I135)`, `s1 = I0 − I90`, `s2 = I45 − I135`,
//!   `DoLP = √(s1²+s2²)/s0`, `AoLP = ½·atan2(s2, s1) mod π`.
//! - Observation channels (docs/model.md §6): `I^d = 2·I90`, `I^s = I0 − I90`, `I^α = I135 − I45`;
//!   `s1 = I^s` and `s2 = −I^α` bit for bit; `s0 − s1 = I^d` when the residual is 0.
//! - Non-ideal analysers: an optional [`AnalyserCalibration`] (angles, extinction ratios, gains)
//!   replaces the formulas by the least-squares estimator ([`calibration`]); a per-pixel
//!   [`SensorCalibration`] (dark level and analysis vector of every raw pixel, measured by
//!   `ellipso calibrate sensor`) gives every superpixel its own ([`sensor_calibration`]).
//! - Units: normalised, `I = (DN − dark) / (full scale − dark)`; s0 ∈ [0, 2] for unclipped data.
//! - Handedness check: a linear polariser in front of the lens at +30° counter-clockwise from
//!   image-right must read AoLP = 30°, not 150°. If it reads 150°, the camera's 45°/135° labels
//!   are mirrored; the fix is one place, [`ellipso_model::mosaic`], with a test.
//!
//! # Masking (never averaged in)
//!
//! Saturated raw samples, dark pixels (s0/2 below `dark_intensity`), DoLP > 1 (unphysical) and,
//! optionally, large consistency residuals are flagged per output pixel ([`MaskReason`]).
//! Every output is finite for every valid frame (guards documented in [`stokes`]).

mod band;
mod bilinear;
pub mod calibration;
pub mod channels;
pub mod convert;
pub mod demosaic;
pub mod frame;
pub mod intensity;
pub mod layout;
pub mod mask;
pub mod plane;
pub mod sensor_calibration;
pub mod stokes;
pub mod synthetic;
#[cfg(any(test, feature = "test-support"))]
pub mod test_support;

use ellipso_model::mosaic::SensorLayout;

pub use calibration::{AnalyserCalibration, CalibrationError, StokesMatrix};
pub use channels::ObservationChannels;
pub use demosaic::{AnalyserBand, AnalyserImage, DemosaicMethod, Levels, demosaic};
pub use frame::{FrameError, RawFrame, RawFrameView};
pub use mask::{MaskReason, MaskSummary, PixelMask};
pub use plane::Plane;
pub use sensor_calibration::{SensorCalibration, process_with_sensor};
pub use stokes::{StokesBand, aolp_rad, dolp, intensity_behind_analyser, stokes_from_intensities};

use demosaic::{RowBuf, band_colours, superpixel_row};
use stokes::{AnalyserRow, Thresholds, stokes_row};

/// Mean intensity below which a pixel is dark by default (docs/model.md §12: threshold 0.001).
pub const DEFAULT_DARK_INTENSITY: f32 = 0.001;

/// How to turn a raw frame into Stokes images.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PolarConfig {
    /// Demosaic method.
    pub demosaic: DemosaicMethod,
    /// Black level subtracted from every raw sample, in DN (0 = none).
    pub dark_level_dn: f32,
    /// Raw samples at or above this DN are saturated; `None` = the bit depth's full scale.
    pub saturation_dn: Option<u16>,
    /// Pixels whose mean analyser intensity s0/2 (normalised) is below this are dark.
    pub dark_intensity: f32,
    /// Pixels with |I0 + I90 − I45 − I135| (normalised) above this are inconsistent; `None` = off.
    /// With a calibration the residual is `nᵀI` (see [`calibration`]).
    pub max_residual: Option<f32>,
    /// Measured analyser angles, extinction ratios and gains; `None` = ideal analysers (exact
    /// textbook formulas, the fast path).
    pub calibration: Option<AnalyserCalibration>,
}

impl Default for PolarConfig {
    fn default() -> Self {
        PolarConfig {
            demosaic: DemosaicMethod::Superpixel,
            dark_level_dn: 0.0,
            saturation_dn: None,
            dark_intensity: DEFAULT_DARK_INTENSITY,
            max_residual: None,
            calibration: None,
        }
    }
}

/// Why a frame cannot be processed with a configuration.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PolarError {
    /// The dark level is not finite, negative, or not below the saturation level.
    #[error(
        "dark level {dark_level_dn} DN must be finite, ≥ 0 and below the saturation level {saturation_dn} DN"
    )]
    DarkLevel {
        /// Configured dark level.
        dark_level_dn: f32,
        /// Effective saturation level.
        saturation_dn: u16,
    },
    /// The saturation level is above what the bit depth can deliver or zero.
    #[error(
        "saturation level {saturation_dn} DN is outside 1..={full_scale_dn} (the {bit_depth}-bit full scale)"
    )]
    SaturationLevel {
        /// Configured saturation level.
        saturation_dn: u16,
        /// Full scale of the frame's bit depth.
        full_scale_dn: u16,
        /// The frame's bit depth.
        bit_depth: u8,
    },
    /// The analyser calibration cannot be used.
    #[error("analyser calibration: {0}")]
    Calibration(#[from] CalibrationError),
    /// A per-pixel sensor calibration cannot be applied.
    #[error("sensor calibration: {0}")]
    SensorCalibration(String),
    /// A threshold is not a finite non-negative number.
    #[error("{name} = {value} must be finite and ≥ 0")]
    Threshold {
        /// Which setting.
        name: &'static str,
        /// Its value.
        value: f32,
    },
}

impl PolarConfig {
    /// Validates the configuration against `frame` and returns its normalisation levels.
    pub fn levels<D: AsRef<[u16]>>(&self, frame: &RawFrame<D>) -> Result<Levels, PolarError> {
        let full_scale_dn = frame.full_scale_dn();
        let saturation_dn = self.saturation_dn.unwrap_or(full_scale_dn);
        if saturation_dn == 0 || saturation_dn > full_scale_dn {
            return Err(PolarError::SaturationLevel {
                saturation_dn,
                full_scale_dn,
                bit_depth: frame.bit_depth(),
            });
        }
        let dark = self.dark_level_dn;
        if !dark.is_finite() || dark < 0.0 || dark >= f32::from(saturation_dn) {
            return Err(PolarError::DarkLevel {
                dark_level_dn: dark,
                saturation_dn,
            });
        }
        Ok(Levels::new(full_scale_dn, dark, saturation_dn))
    }

    pub(crate) fn thresholds(&self) -> Result<Thresholds, PolarError> {
        let check = |name: &'static str, value: f32| {
            if value.is_finite() && value >= 0.0 {
                Ok(value)
            } else {
                Err(PolarError::Threshold { name, value })
            }
        };
        Ok(Thresholds {
            dark_s0: 2.0 * check("dark_intensity", self.dark_intensity)?,
            max_residual: match self.max_residual {
                Some(v) => check("max_residual", v)?,
                None => f32::INFINITY,
            },
            matrix: self.calibration.map(|c| c.stokes_matrix()).transpose()?,
        })
    }
}

/// Stokes images of one frame: one band (mono) or three (R, G, B), all the same size.
#[derive(Debug, Clone, PartialEq)]
pub struct PolarImage {
    /// Demosaic method used (name it in every output).
    pub method: DemosaicMethod,
    /// Layout of the source frame.
    pub layout: SensorLayout,
    /// Levels the raw data was normalised with.
    pub levels: Levels,
    /// Bands: `[mono]` or `[R, G, B]`.
    pub bands: Vec<StokesBand>,
}

impl PolarImage {
    /// An empty image to pass to [`process_into`] (which sizes it).
    pub fn empty() -> PolarImage {
        PolarImage {
            method: DemosaicMethod::Superpixel,
            layout: SensorLayout::MonoPolar,
            levels: Levels::new(1, 0.0, 1),
            bands: Vec::new(),
        }
    }

    /// Output width in pixels (0 when empty).
    pub fn width(&self) -> usize {
        self.bands.first().map_or(0, StokesBand::width)
    }

    /// Output height in pixels (0 when empty).
    pub fn height(&self) -> usize {
        self.bands.first().map_or(0, StokesBand::height)
    }
}

/// Processes one frame (owned samples, or a [`RawFrameView`] of a buffer the caller lends):
/// demosaic, Stokes, DoLP, AoLP, residual, channels, mask.
pub fn process<D: AsRef<[u16]>>(
    frame: &RawFrame<D>,
    config: &PolarConfig,
) -> Result<PolarImage, PolarError> {
    let mut out = PolarImage::empty();
    process_into(frame, config, &mut out)?;
    Ok(out)
}

/// [`process`] into existing buffers (no allocation once `out` has the right size): the path
/// for streaming. Both methods run fused row by row (demosaic row → Stokes row), with no
/// full-resolution intermediate.
pub fn process_into<D: AsRef<[u16]>>(
    frame: &RawFrame<D>,
    config: &PolarConfig,
    out: &mut PolarImage,
) -> Result<(), PolarError> {
    // one compiled body for owned and borrowed samples: the same code, the same bits
    let frame = &frame.view();
    let levels = config.levels(frame)?;
    let thresholds = config.thresholds()?;
    let layout = frame.layout();
    let (w, h) = config
        .demosaic
        .output_size(layout, frame.width(), frame.height());
    let colours = band_colours(layout);
    out.method = config.demosaic;
    out.layout = layout;
    out.levels = levels;
    out.bands.resize_with(colours.len(), StokesBand::default);
    for (band, colour) in out.bands.iter_mut().zip(&colours) {
        band.reshape(*colour, w, h);
    }
    match config.demosaic {
        DemosaicMethod::Superpixel => {
            let mut buf = RowBuf::default();
            for band in &mut out.bands {
                for y in 0..h {
                    superpixel_row(frame, &levels, band.colour, y, &mut buf);
                    let [i0, i45, i90, i135] = &buf.intensity;
                    let input = AnalyserRow {
                        intensity: [i0, i45, i90, i135],
                        mask: &buf.mask,
                    };
                    stokes_row(input, band.row_mut(y), thresholds);
                }
            }
        }
        DemosaicMethod::Bilinear => {
            let mut buf = RowBuf::default();
            for band in &mut out.bands {
                let mut rows = bilinear::BilinearRows::new(frame, &levels, band.colour);
                for y in 0..h {
                    rows.fill_row(y, &mut buf);
                    let [i0, i45, i90, i135] = &buf.intensity;
                    let input = AnalyserRow {
                        intensity: [i0, i45, i90, i135],
                        mask: &buf.mask,
                    };
                    stokes_row(input, band.row_mut(y), thresholds);
                }
            }
        }
    }
    Ok(())
}

/// Stokes images from already demosaiced analyser planes (any source: our demosaicers, another
/// library's, a simulator's ideal planes). Uses the thresholds of `config`; its levels and
/// demosaic method are not applied (the planes are taken as normalised already).
pub fn stokes_from_analysers(
    analysers: &AnalyserImage,
    levels: Levels,
    config: &PolarConfig,
) -> Result<PolarImage, PolarError> {
    let thresholds = config.thresholds()?;
    let bands = analysers
        .bands
        .iter()
        .map(|a_band| {
            let mut band = StokesBand::default();
            band.reshape(a_band.colour, a_band.mask.width(), a_band.mask.height());
            fill_band(a_band, &mut band, thresholds);
            band
        })
        .collect();
    Ok(PolarImage {
        method: analysers.method,
        layout: analysers.layout,
        levels,
        bands,
    })
}

fn fill_band(a_band: &AnalyserBand, band: &mut StokesBand, thresholds: Thresholds) {
    let [p0, p45, p90, p135] = &a_band.intensity;
    let rows = p0
        .rows()
        .zip(p45.rows())
        .zip(p90.rows())
        .zip(p135.rows())
        .zip(a_band.mask.rows());
    for (y, ((((r0, r45), r90), r135), m)) in rows.enumerate() {
        let input = AnalyserRow {
            intensity: [r0, r45, r90, r135],
            mask: m,
        };
        stokes_row(input, band.row_mut(y), thresholds);
    }
}

#[cfg(test)]
mod tests;
