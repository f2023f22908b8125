//! Measuring a sensor calibration from a captures folder (`ellipso calibrate sensor`).
//!
//! Method (docs/sensor-calibration.md; EMVA 1288 Release 4 for the radiometry, the
//! analysis-matrix calibration of division-of-focal-plane polarimeters for the analysers):
//! 1. **Dark frames** (≥ 2): each pixel's mean is its dark level; the median and robust sd of
//!    those give the hot pixels (above median + max(10 σ, 5 DN)); the black level is the mean
//!    of the others, the DSNU their spatial sd with the temporal part `σ²_d / n` removed; the
//!    temporal dark variance σ²_d is the mean per-pixel variance.
//! 2. **Flats** (≥ 2 levels, ≥ 2 frames each): per level the mean signal above dark μ and the
//!    temporal variance σ² from differences of frame pairs (`½(x₁ − x₂)²`, which cancels every
//!    fixed pattern); the conversion gain K is the least-squares slope through the origin of
//!    `σ² − σ²_d` against μ over the levels below 70 % of the range with no clipped pixel
//!    (EMVA's linear range). Read noise = `√(σ²_d − 1/12)` DN (quantisation removed), ÷ K in e⁻.
//!    Each pixel's response r_p is the slope through the origin of its mean signal against the
//!    level; `ln r_p = c_(band, analyser) + n · ln cos θ_p + ln PRNU_p` fitted within the
//!    (band, analyser) groups gives the vignetting exponent n (θ_p the field angle of the
//!    pixel's centre through the lens model of the captures), the residual's sd, less the
//!    temporal noise of r_p, the PRNU.
//! 3. **Polariser-sheet flats** (≥ 4 distinct angles): per pixel, least squares of its signal
//!    above dark against `[1, cos2φ, sin2φ]` gives `L · v_p · a_p`; dividing by the vignetting
//!    `cos^n θ_p` and normalising each band's mean parallel transmission `a0 + |(a1, a2)|` to 1
//!    gives the analysis vectors (the sheet is taken as ideal: its own extinction ratio, if
//!    finite, lowers every pixel's measured diattenuation alike).
//!
//! Contract: every frame is read once, in manifest order, with accumulators of a few f64 per
//! pixel (no frame kept but the previous flat of a pair). Missing captures are an error that
//! names the photos to take; a pixel clipped in any flat or sheet frame keeps the ideal
//! analysis vector of its nominal analyser and is counted.
//!
//! Here the captures are sorted and checked and the figures assembled; the stages live in the
//! children `radiometry` (darks, flats, vignetting and PRNU) and `analysers` (polariser sheets).

use std::collections::BTreeMap;
use std::path::Path;

use ellipso_model::mosaic::SensorLayout;
use ellipso_session::calibration_captures::{CaptureKind, CaptureSet};

use super::{FORMAT, SensorCalibration, SensorFigures, SensorHeader, VERSION};

mod analysers;
mod radiometry;

use analysers::Analysers;
use radiometry::{Darks, PhotonTransfer, Vignetting};

/// Settings of a measurement.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeasureOptions {
    /// Upper end of the photon transfer fit, fraction of the range above the black level
    /// (EMVA 1288 fits the linear part, below about 70 % of saturation).
    pub photon_transfer_max_fraction: f64,
}

impl Default for MeasureOptions {
    fn default() -> Self {
        MeasureOptions {
            photon_transfer_max_fraction: 0.7,
        }
    }
}

/// Why a measurement cannot be made.
#[derive(Debug, thiserror::Error)]
pub enum MeasureError {
    /// A frame cannot be read or does not match the manifest's sensor.
    #[error("{file}: {what}")]
    Frame {
        /// The frame file.
        file: String,
        /// What is wrong.
        what: String,
    },
    /// Captures are missing; says which photos to take.
    #[error("{what}; take: {photos}")]
    Missing {
        /// What cannot be measured.
        what: String,
        /// The photos to take.
        photos: String,
    },
    /// The data does not determine a figure.
    #[error("{0}")]
    Degenerate(String),
}

struct Frames<'a> {
    dir: &'a Path,
    set: &'a CaptureSet,
}

impl Frames<'_> {
    fn read(&self, file: &str) -> Result<Vec<u16>, MeasureError> {
        let s = &self.set.sensor;
        let (w, h, px) = ellipso_session::frame_png::read(&self.dir.join(file)).map_err(|e| {
            MeasureError::Frame {
                file: file.into(),
                what: e.to_string(),
            }
        })?;
        if (w, h) != (s.width, s.height) {
            return Err(MeasureError::Frame {
                file: file.into(),
                what: format!(
                    "{w}×{h} px, the manifest's sensor is {}×{}",
                    s.width, s.height
                ),
            });
        }
        Ok(px)
    }
}

fn band_of(layout: SensorLayout, x: u32, y: u32) -> usize {
    layout.colour_at(x, y).map_or(0, |c| c.index())
}

/// The frames of a set sorted by kind, in manifest order, once every kind has enough.
struct Captures<'a> {
    /// Dark frames.
    darks: Vec<&'a str>,
    /// Flat levels with ≥ 2 frames, by ascending level: `(level_rel, files)`.
    levels: Vec<(f64, Vec<&'a str>)>,
    /// Polariser-sheet frames: `(polariser_deg, file)`.
    sheets: Vec<(f64, &'a str)>,
}

impl<'a> Captures<'a> {
    /// Sorts the frames of `set` by kind; too few darks, flat levels or sheet angles are a
    /// [`MeasureError::Missing`] naming the photos to take.
    fn sort(set: &'a CaptureSet) -> Result<Self, MeasureError> {
        let mut darks = Vec::new();
        let mut flats: BTreeMap<u64, (f64, Vec<&str>)> = BTreeMap::new();
        let mut sheets = Vec::new();
        for f in &set.frames {
            match f.kind {
                CaptureKind::Dark => darks.push(f.file.as_str()),
                CaptureKind::Flat { level_rel } => flats
                    .entry(level_rel.to_bits())
                    .or_insert((level_rel, Vec::new()))
                    .1
                    .push(f.file.as_str()),
                CaptureKind::Polariser { polariser_deg } => {
                    sheets.push((polariser_deg, f.file.as_str()))
                }
            }
        }
        if darks.len() < 2 {
            return Err(MeasureError::Missing {
                what: format!("{} dark frame(s): black level, DSNU and read noise need ≥ 2", darks.len()),
                photos: "16 frames with the lens capped and the flash off, at the object capture's exposure and gain".into(),
            });
        }
        let levels: Vec<(f64, Vec<&str>)> =
            flats.into_values().filter(|(_, f)| f.len() >= 2).collect();
        if levels.len() < 2 {
            return Err(MeasureError::Missing {
                what: format!("{} flat level(s) with ≥ 2 frames: the photon transfer needs ≥ 2", levels.len()),
                photos: "a light panel filling the view, 4 frames at each of 8 exposures from dim to about 70 % of saturation".into(),
            });
        }
        let mut angles: Vec<f64> = sheets.iter().map(|(a, _)| a.rem_euclid(180.0)).collect();
        angles.sort_by(f64::total_cmp);
        angles.dedup_by(|a, b| (*a - *b).abs() < 1e-6);
        if angles.len() < 4 {
            return Err(MeasureError::Missing {
                what: format!("{} polariser-sheet angle(s): the analysis vectors need ≥ 4", angles.len()),
                photos: "the light panel through a linear polariser sheet in front of the lens, 16 frames at each of 8 angles 22.5° apart".into(),
            });
        }
        Ok(Captures {
            darks,
            levels,
            sheets,
        })
    }
}

/// The sensor's pixel grid as the stages index it: pixel `i` at `(i % width, i / width)`.
#[derive(Debug, Clone, Copy)]
struct Grid {
    /// Frame width, px.
    width: usize,
    /// Pixel count.
    n: usize,
    /// The ADC's full scale, DN (a sample at or above it is clipped).
    full_scale: f64,
    /// The mosaic.
    layout: SensorLayout,
}

/// Measures the calibration of the captures in `dir` described by `set` (module doc).
pub fn measure(
    dir: &Path,
    set: &CaptureSet,
    options: MeasureOptions,
) -> Result<SensorCalibration, MeasureError> {
    let frames = Frames { dir, set };
    let s = &set.sensor;
    let (w, h) = (s.width as usize, s.height as usize);
    let grid = Grid {
        width: w,
        n: w * h,
        full_scale: f64::from((1u32 << u32::from(s.bit_depth)) - 1),
        layout: s.layout,
    };
    let captures = Captures::sort(set)?;
    let darks = Darks::measure(&frames, &captures.darks, grid)?;
    let mut flats = PhotonTransfer::measure(&frames, &captures.levels, &darks, grid, options)?;
    let vignetting = Vignetting::fit(&set.camera, grid, &darks, &flats);
    let analysers = Analysers::measure(
        &frames,
        &captures.sheets,
        grid,
        &darks,
        &mut flats.clipped,
        &vignetting,
    )?;
    let gain = flats.gain;
    let figures = SensorFigures {
        gain_dn_per_e: gain,
        gain_e_per_dn: 1.0 / gain,
        read_noise_dn: flats.read_noise_dn,
        read_noise_e: flats.read_noise_dn / gain,
        black_level_dn: darks.black,
        dsnu_dn: darks.dsnu,
        prnu_rel: vignetting.prnu,
        saturation_dn: flats.saturation_dn,
        saturation_e: flats.saturation_dn / gain,
        vignetting_exponent: vignetting.exponent,
        extinction_ratio: analysers.extinction_ratio,
        analyser_angle_mean_error_deg: analysers.angle_mean_rad.map(f64::to_degrees),
        analyser_angle_sd_deg: analysers.angle_sd_rad.to_degrees(),
        hot_pixels: darks.hot.iter().filter(|h| **h).count() as u64,
        photon_transfer: flats.points,
    };
    Ok(SensorCalibration {
        header: SensorHeader {
            format: FORMAT.into(),
            version: VERSION,
            sensor: set.sensor.clone(),
            gain_db: set.gain_db,
            figures,
            source: format!(
                "{} dark, {} flat, {} polariser-sheet frames from {}; {} clipped \
                 pixel(s) keep their nominal analyser",
                captures.darks.len(),
                captures.levels.iter().map(|(_, f)| f.len()).sum::<usize>(),
                captures.sheets.len(),
                set.source,
                analysers.ideal_kept
            ),
        },
        pixels: analysers.pixels,
        checksum: 0,
    })
}
