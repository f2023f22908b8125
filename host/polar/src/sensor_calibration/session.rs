//! A session's sensor calibration: which file applies to a session's frames ([`for_session`])
//! and the calibrated superpixel demosaic the fit, the mesh and the live view read those frames
//! with ([`CalibratedDemosaic`]).
//!
//! Contract:
//! - [`for_session`]: the file given on the command line, else the one the session recorded
//!   (`manifest.rig.sensor_calibration`, written by `capture` from the rig file), else none.
//!   A session that recorded an identity accepts only that identity, from either place (the
//!   stale-identity error otherwise); the file must be of the session's sensor (size and
//!   layout, each its own error). Nothing named: `Ok(None)`, and the frames are read exactly
//!   as without this module.
//! - [`CalibratedDemosaic::demosaic`] is the superpixel demosaic with the calibration's black
//!   level, each superpixel's Stokes vector estimated with its own analysis matrix
//!   ([`super::apply`]), then written back as the four intensities the fit's analyser model
//!   predicts for it: analysers at exactly 0/45/90/135° with the session's recorded extinction
//!   ratio `ER` (`e = 1/ER`, 0 for ideal analysers), `I_k = ½[(1+e)s0 + (1−e)(s1 cos2θ_k +
//!   s2 sin2θ_k)]`, plus the estimator's residual along that model's null direction
//!   `½[1, −1, 1, −1]` (so the four values keep the measurement's inconsistency, which the fit's
//!   gates read). For a calibration of ideal analysers and `e = 0` this returns the plain
//!   demosaic's values (`A A⁺ + u uᵀ = 1` for the ideal `A` and its unit null vector `u`).

use std::path::Path;
use std::sync::{Arc, Mutex};

use ellipso_session::manifest::{Manifest, SensorInfo, layout_name};

use super::SensorCalibration;
use super::apply::PixelEstimators;
use super::file::{SensorCalibrationError, read};
use crate::demosaic::{AnalyserImage, DemosaicMethod, Levels, demosaic};
use crate::frame::RawFrame;
use crate::{PolarConfig, PolarError};

/// The sensor calibration for a session's frames (module contract): `given` (a command line's
/// file) or the session's recorded one; `None` when neither names one.
pub fn for_session(
    manifest: &Manifest,
    given: Option<&Path>,
) -> Result<Option<SensorCalibration>, SensorCalibrationError> {
    let recorded = manifest
        .rig
        .as_ref()
        .and_then(|r| r.sensor_calibration.as_ref());
    let cal = match (given, recorded) {
        (Some(path), r) => read(path, r.map(|r| r.id.as_str()))?,
        (None, Some(r)) => read(&r.file, Some(&r.id))?,
        (None, None) => return Ok(None),
    };
    cal.check_sensor(&manifest.sensor)?;
    Ok(Some(cal))
}

impl SensorCalibration {
    /// Refuses a calibration of another sensor size or layout than `sensor`'s.
    pub fn check_sensor(&self, sensor: &SensorInfo) -> Result<(), SensorCalibrationError> {
        let s = &self.header.sensor;
        if (sensor.width, sensor.height) != (s.width, s.height) {
            return Err(SensorCalibrationError::SensorSize {
                id: self.id(),
                cal_width: s.width,
                cal_height: s.height,
                frame_width: sensor.width,
                frame_height: sensor.height,
            });
        }
        if sensor.layout != s.layout {
            return Err(SensorCalibrationError::Layout {
                id: self.id(),
                cal: layout_name(s.layout).into(),
                frame: layout_name(sensor.layout).into(),
            });
        }
        Ok(())
    }
}

/// The calibrated superpixel demosaic of one session (module contract). The per-superpixel
/// estimators are built at the first frame and reused while the levels stay the same.
#[derive(Debug)]
pub struct CalibratedDemosaic {
    calibration: Arc<SensorCalibration>,
    /// `e = 1/ER` of the analysers the intensities are written back for.
    extinction: f64,
    estimators: Mutex<Option<Arc<PixelEstimators>>>,
}

impl CalibratedDemosaic {
    /// The demosaic of `calibration` writing intensities back for analysers of extinction
    /// ratio `modelled_extinction_ratio` (`None`: ideal).
    pub fn new(
        calibration: Arc<SensorCalibration>,
        modelled_extinction_ratio: Option<f64>,
    ) -> CalibratedDemosaic {
        let extinction = match modelled_extinction_ratio {
            Some(er) if er >= 1.0 => 1.0 / er,
            _ => 0.0,
        };
        CalibratedDemosaic {
            calibration,
            extinction,
            estimators: Mutex::new(None),
        }
    }

    /// The calibration.
    pub fn calibration(&self) -> &SensorCalibration {
        &self.calibration
    }

    /// The configuration frames are read with: `config` with the calibration's black level
    /// (superpixel demosaic, no per-analyser calibration).
    pub fn config(&self, config: &PolarConfig) -> Result<PolarConfig, PolarError> {
        super::apply::calibrated_config(
            &PolarConfig {
                demosaic: DemosaicMethod::Superpixel,
                ..*config
            },
            &self.calibration,
        )
    }

    /// The calibrated analyser planes of `frame` read with `levels` (from [`Self::config`]).
    pub fn demosaic(&self, frame: &RawFrame, levels: &Levels) -> Result<AnalyserImage, PolarError> {
        self.calibration
            .check_frame(frame)
            .map_err(|e| PolarError::SensorCalibration(e.to_string()))?;
        let estimators = {
            let mut held = self.estimators.lock().unwrap_or_else(|p| p.into_inner());
            match held.as_ref() {
                Some(e) if e.levels() == levels => Arc::clone(e),
                _ => {
                    let e = Arc::new(PixelEstimators::new(&self.calibration, *levels)?);
                    *held = Some(Arc::clone(&e));
                    e
                }
            }
        };
        let mut image = demosaic(frame, levels, DemosaicMethod::Superpixel);
        estimators.reproject(&mut image, self.extinction)?;
        Ok(image)
    }
}
