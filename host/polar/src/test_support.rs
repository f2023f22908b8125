//! Fixtures for the tests of the crates above this one (feature `test-support`, off in every
//! build that is not a test): one definition of the sensor calibration a test writes when it
//! needs a valid file of a given size and layout.

use ellipso_model::mosaic::SensorLayout;
use ellipso_session::manifest::SensorInfo;

use crate::sensor_calibration::{
    FORMAT, PixelRecord, SensorCalibration, SensorFigures, SensorHeader, VERSION,
};

/// A calibration of ideal analysers (unit transmission, black level `dark_dn`) for a `w`×`h`
/// 12-bit sensor; `dark_dn` (0 for an ideal one) tells two files apart.
pub fn ideal_calibration(layout: SensorLayout, w: u32, h: u32, dark_dn: f32) -> SensorCalibration {
    let pixels = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .map(|(x, y)| {
            let (s2, c2) = (2.0 * layout.analyser_at(x, y).angle_rad()).sin_cos();
            PixelRecord {
                dark_dn,
                analysis: [0.5, (0.5 * c2) as f32, (0.5 * s2) as f32],
            }
        })
        .collect();
    SensorCalibration {
        header: SensorHeader {
            format: FORMAT.into(),
            version: VERSION,
            sensor: SensorInfo {
                layout,
                width: w,
                height: h,
                bit_depth: 12,
            },
            gain_db: 0.0,
            figures: SensorFigures {
                gain_dn_per_e: 0.39,
                gain_e_per_dn: 1.0 / 0.39,
                read_noise_dn: 0.9,
                read_noise_e: 2.3,
                black_level_dn: f64::from(dark_dn),
                dsnu_dn: 0.0,
                prnu_rel: 0.0,
                saturation_dn: 4095.0,
                saturation_e: 10_500.0,
                vignetting_exponent: 0.0,
                // the file's JSON header holds finite numbers only
                extinction_ratio: vec![1e9],
                analyser_angle_mean_error_deg: [0.0; 4],
                analyser_angle_sd_deg: 0.0,
                hot_pixels: 0,
                photon_transfer: Vec::new(),
            },
            source: "test: ideal sensor".into(),
        },
        pixels,
        checksum: 0,
    }
}
