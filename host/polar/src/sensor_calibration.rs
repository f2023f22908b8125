//! A per-pixel sensor calibration: what `ellipso calibrate sensor` measures from dark frames,
//! flat fields and polariser-sheet flats ([`measure`]), the file it writes ([`file`]) and the
//! Stokes estimator `ellipso polar --calibration` builds from it ([`apply`]).
//!
//! The model (docs/sensor-calibration.md): raw pixel `p` delivers
//!
//! ```text
//! DN_p = dark_p + K · v(θ_p) · (a_p · s) · L        a_p = [a0, a1, a2]_p
//! ```
//!
//! with `dark_p` its dark level (black level + DSNU + hot-pixel signal), `K` the conversion gain,
//! `v(θ) = cos^n θ` the vignetting at the pixel's field angle, `L` the scene's radiance and `a_p`
//! the pixel's analysis vector (PRNU × its analyser's transmission: for ideal analysers at θ_k,
//! `½[1, cos2θ_k, sin2θ_k]`). The analysis vectors are normalised per colour band so that the
//! band's mean parallel transmission `a0 + |(a1, a2)|` is 1, the ideal analysers' value, so a
//! calibrated frame reads the Stokes vector an ideal sensor with the same lens would read
//! (vignetting stays in the image, as the fit's normaliser models it).
//!
//! Contract: a [`SensorCalibration`] holds one record per raw pixel (`dark_dn`, `a0`, `a1`, `a2`)
//! and a header of EMVA 1288 figures ([`SensorFigures`]); its identity ([`SensorCalibration::id`])
//! is the CRC-64 of its file, which a rig file names; reading refuses another format, version,
//! a corrupt or truncated file and an identity other than the one asked for, each by name.

pub mod apply;
pub mod file;
pub mod measure;
pub mod session;
#[cfg(test)]
mod tests;

use ellipso_model::mosaic::SensorLayout;
use ellipso_session::manifest::SensorInfo;
use serde::{Deserialize, Serialize};

pub use apply::{PixelEstimators, process_with_sensor};
pub use file::SensorCalibrationError;
pub use measure::{MeasureError, MeasureOptions, measure};
pub use session::{CalibratedDemosaic, for_session};

/// The format name in every header.
pub const FORMAT: &str = "ellipso-sensor-calibration";
/// The version this build reads and writes.
pub const VERSION: u32 = 1;

/// One point of the photon transfer curve.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PhotonTransferPoint {
    /// Relative light level of the flats.
    pub level_rel: f64,
    /// Mean signal above the dark level, DN.
    pub mean_dn: f64,
    /// Temporal variance (from frame differences), DN².
    pub variance_dn2: f64,
}

/// The sensor's figures, EMVA 1288 style.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorFigures {
    /// Conversion gain K, DN per electron.
    pub gain_dn_per_e: f64,
    /// Its inverse, electrons per DN.
    pub gain_e_per_dn: f64,
    /// Temporal dark noise without quantisation, DN.
    pub read_noise_dn: f64,
    /// The same in electrons.
    pub read_noise_e: f64,
    /// Mean dark level (black level), DN.
    pub black_level_dn: f64,
    /// Dark-signal non-uniformity (spatial sd of the dark level, hot pixels excluded), DN.
    pub dsnu_dn: f64,
    /// Photo-response non-uniformity (spatial sd of the flat response after vignetting and
    /// the analysers' transmissions are divided out, temporal noise removed), relative.
    pub prnu_rel: f64,
    /// Saturation: the largest mean signal above dark whose variance still rises, DN (the
    /// ADC's full scale minus the black level when the flats never saturate).
    pub saturation_dn: f64,
    /// The same in electrons.
    pub saturation_e: f64,
    /// Vignetting exponent n of `cos^n` of the field angle.
    pub vignetting_exponent: f64,
    /// Extinction ratio per colour band (R, G, B; one value on a mono sensor), from the band's
    /// mean diattenuation.
    pub extinction_ratio: Vec<f64>,
    /// Mean analyser angle error per nominal analyser (0°, 45°, 90°, 135°), degrees.
    pub analyser_angle_mean_error_deg: [f64; 4],
    /// Pixel-to-pixel sd of the analyser angle about its analyser's mean, degrees.
    pub analyser_angle_sd_deg: f64,
    /// Pixels whose dark level is more than 10 DSNU-widths (and 5 DN) above the median.
    pub hot_pixels: u64,
    /// The photon transfer curve.
    pub photon_transfer: Vec<PhotonTransferPoint>,
}

/// The header of a calibration file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorHeader {
    /// Always [`FORMAT`].
    pub format: String,
    /// Always [`VERSION`].
    pub version: u32,
    /// The sensor it was measured on.
    pub sensor: SensorInfo,
    /// Gain setting of the captures, dB (a calibration holds at this gain).
    pub gain_db: f64,
    /// The figures.
    pub figures: SensorFigures,
    /// What it was measured from, in words.
    pub source: String,
}

/// One raw pixel's calibration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PixelRecord {
    /// Dark level, DN.
    pub dark_dn: f32,
    /// Analysis vector `[a0, a1, a2]` (module doc).
    pub analysis: [f32; 3],
}

/// A sensor calibration (module doc).
#[derive(Debug, Clone, PartialEq)]
pub struct SensorCalibration {
    /// Header.
    pub header: SensorHeader,
    /// One record per raw pixel, row-major.
    pub pixels: Vec<PixelRecord>,
    /// CRC-64 of the file's bytes before the checksum (set when written or read).
    pub checksum: u64,
}

impl SensorCalibration {
    /// The identity a rig file and a session name: the checksum as 16 hex digits.
    pub fn id(&self) -> String {
        format!("{:016x}", self.checksum)
    }

    /// The sensor layout.
    pub fn layout(&self) -> SensorLayout {
        self.header.sensor.layout
    }

    /// The record of raw pixel `(x, y)`.
    pub fn pixel(&self, x: u32, y: u32) -> PixelRecord {
        self.pixels[y as usize * self.header.sensor.width as usize + x as usize]
    }

    /// Pixel `(x, y)`'s analyser angle (degrees, in [0, 180)) and extinction ratio.
    pub fn analyser(&self, x: u32, y: u32) -> (f64, f64) {
        let [a0, a1, a2] = self.pixel(x, y).analysis.map(f64::from);
        let amp = a1.hypot(a2);
        let angle = (0.5 * a2.atan2(a1)).to_degrees().rem_euclid(180.0);
        let er = if a0 > amp {
            (a0 + amp) / (a0 - amp)
        } else {
            f64::INFINITY
        };
        (angle, er)
    }
}
