//! The sensor-calibration loop end to end on simulated captures: `ellipso polar` with the
//! measured calibration on a frame rendered with per-pixel analyser errors reads the ideal
//! sensor's Stokes vector to the calibration's own noise; without it the error is the size the
//! effect implies.

use ellipso_bench::sensor_calibration::{calibrate, demo_with, stokes_check};

/// Colour tiles are 4×4: both sides multiples of 4, the demo's aspect.
const RESOLUTION: [u32; 2] = [244, 204];

#[test]
fn calibrated_polar_reads_the_ideal_sensor_and_uncalibrated_does_not() {
    let effects = "analyser_errors = { angle_sigma_deg = 1.0, extinction_ratio_rgb = [150.0, 250.0, 80.0], extinction_sigma_rel = 0.1 }\n\
                   black_level = { dn = 64.0, dsnu_dn = 1.5 }\nprnu = { sigma_rel = 0.008 }\n";
    let noisy = demo_with(effects, true).unwrap();
    let work = tempfile::tempdir().unwrap();
    let cal = calibrate(&noisy, RESOLUTION, &work.path().join("captures")).unwrap();
    let f = &cal.header.figures;
    assert!(
        (f.black_level_dn - 64.0).abs() < 0.5,
        "black level {}",
        f.black_level_dn
    );
    assert!(
        f.analyser_angle_sd_deg > 0.8 && f.analyser_angle_sd_deg < 1.2,
        "{}",
        f.analyser_angle_sd_deg
    );
    let clean = demo_with(effects, false).unwrap();
    let ideal = demo_with("", false).unwrap();
    let (max, rms, rms_uncalibrated) = stokes_check(&clean, &ideal, &cal, RESOLUTION).unwrap();
    eprintln!("calibrated: max {max:.2e} rms {rms:.2e}; uncalibrated rms {rms_uncalibrated:.2e}");
    // The calibration's own noise: 16 frames × 8 sheet angles leave ~0.1° per pixel on the
    // analyser angles (docs/sensor-calibration.md, measured), i.e. 2·0.1° ≈ 3.5e-3 rad of a
    // superpixel's |s12| (≤ 0.5 on the lit object) → ~1e-3 RMS; 2e-3 leaves room for the
    // smaller frame. The 1e-3 on every pixel needs more sheet frames (not met yet).
    assert!(
        rms < 2e-3,
        "calibrated Stokes off the ideal sensor's by {rms} RMS (max {max})"
    );
    // Without the calibration: a 1° RMS analyser angle error turns a polarised pixel's
    // (s1, s2) by ~2·1° = 0.035 rad of |s12|, PRNU of 0.8 % moves s0 by ~0.4 % (¼ of four
    // pixels' gains) and the extinction of 1/80…1/250 scales s0 up and s12 down by as much:
    // at the frame's lit pixels (s0 ~ 0.1–0.6) that is 1e-3 or more RMS, ten times the
    // calibrated error at least.
    assert!(
        rms_uncalibrated > 1e-3,
        "uncalibrated rms {rms_uncalibrated}"
    );
    assert!(rms_uncalibrated > 2.5 * rms, "{rms_uncalibrated} vs {rms}");
}
