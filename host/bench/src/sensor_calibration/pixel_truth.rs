//! The simulator's fixed pattern of the bench's sensor read pixel by pixel: the true figures the
//! calibration measures (gain, black level, extinction ratios) and the errors of its per-pixel
//! estimates (analyser angles, vignetting) against the pattern.
//!
//! Contract: the black level, analyser angles and extinction ratios are over the non-hot pixels,
//! the vignetting over every pixel; the renderer is the bench's, at the resolution given.

use ellipso_polar::sensor_calibration::SensorCalibration;
use ellipso_run_error::RunError;
use ellipso_sim::render::Renderer;
use ellipso_sim::scene::Scene;

use super::options;

/// The pattern's truth and the per-pixel errors of a calibration against it.
pub(super) struct PixelTruth {
    /// The true conversion gain, DN per electron.
    pub k_true: f64,
    /// The true black level: the mean offset of the non-hot pixels, DN.
    pub black_true: f64,
    /// The true extinction ratio of each colour band present.
    pub er_true: Vec<f64>,
    /// RMS over the non-hot pixels of the calibration's analyser angle error, degrees.
    pub analyser_angle_rms_deg: f64,
    /// Largest relative error of the calibration's vignetting factor over the frame.
    pub vignetting_err: f64,
    /// Pixels in the frame.
    pub pixels: u32,
}

/// Reads `scene`'s fixed pattern at `resolution` against the calibration `cal`.
pub(super) fn read(
    scene: &Scene,
    cal: &SensorCalibration,
    resolution: [u32; 2],
) -> Result<PixelTruth, RunError> {
    let f = &cal.header.figures;
    let renderer =
        Renderer::new(scene, options(resolution)).map_err(|e| RunError::msg(e.to_string()))?;
    let pattern = renderer.fixed_pattern();
    let layout = renderer.layout();
    let camera = *renderer.camera();
    let (w, h) = (camera.width, camera.height);
    let k_true = renderer.radiometry().dn_per_electron();
    // truth figures from the pattern, over the non-hot pixels
    let (mut off, mut cnt, mut ang2, mut na) = (0.0, 0.0, 0.0, 0.0);
    let mut d_band = [(0.0f64, 0.0f64); 3];
    let mut vig_err = 0.0f64;
    for y in 0..h {
        for x in 0..w {
            let p = pattern.pixel(x, y);
            let d = camera
                .unproject_to_ray([f64::from(x), f64::from(y)])
                .map_or(1.0, |r| r.z);
            let v_true = renderer.radiometry().vignetting(d.clamp(-1.0, 1.0).acos());
            vig_err = vig_err.max((d.powf(f.vignetting_exponent) / v_true - 1.0).abs());
            if p.hot {
                continue;
            }
            off += p.offset_dn;
            cnt += 1.0;
            let (est_deg, _) = cal.analyser(x, y);
            let nominal = layout.analyser_at(x, y).angle_rad().to_degrees();
            let true_deg = nominal + p.angle_error_rad.to_degrees();
            let e = (est_deg - true_deg + 90.0).rem_euclid(180.0) - 90.0;
            ang2 += e * e;
            na += 1.0;
            let e_inv = p.inverse_extinction.unwrap_or(0.0);
            let band = layout.colour_at(x, y).map_or(0, |c| c.index());
            d_band[band].0 += (1.0 - e_inv) / (1.0 + e_inv);
            d_band[band].1 += 1.0;
        }
    }
    let black_true = off / cnt;
    let er_true: Vec<f64> = d_band
        .iter()
        .filter(|(_, c)| *c > 0.0)
        .map(|(s, c)| {
            let d = s / c;
            (1.0 + d) / (1.0 - d)
        })
        .collect();
    Ok(PixelTruth {
        k_true,
        black_true,
        er_true,
        analyser_angle_rms_deg: (ang2 / na).sqrt(),
        vignetting_err: vig_err,
        pixels: w * h,
    })
}
