//! The physical range of every value in a session's rig record (`manifest.rig`: flash,
//! radiometry, noise, analysers), checked where the fit reads it, so that an impossible value is
//! refused by its key instead of surfacing later as a misleading error ("no vertex has a single
//! sample") or — worse — as a changed result.
//!
//! Contract: [`check`] returns the first value outside its range as [`RangeError`], which names
//! the manifest key, the value, and the range. The camera model (`rig.camera`) is checked by the
//! fit's own input checks (`ellipso_fit::inputs`), not here.
//!
//! The ranges, and why (generous: each excludes only what no real rig or simulated scene has):
//! - flash offset: finite, at most [`MAX_FLASH_OFFSET_M`] from the lens — the flash is mounted
//!   on the camera (default 30 mm; ring lights and arms reach tens of centimetres);
//! - flash radiant intensity: finite, in (0, [`MAX_RADIANT_INTENSITY_W_PER_SR`]];
//! - polariser angle: finite; cos-power exponent: 0 ≤ n ≤ 1000 (the scene loader's bound: a
//!   larger n is a beam under 3° wide, a spot, not a flash); a table profile as the scene loader
//!   checks it (angles from 0 rising to ≤ 180°, relative values finite and ≥ 0);
//! - f-number in [0.5, 256] (0.5 is the limit of a lens in air, numerical aperture 1; 256 is
//!   beyond any photographic stop); quantum efficiency in (0, 1]; pixel pitch in
//!   [0.5, 100] µm (the smallest sensors' pixels are ≈0.6 µm, scientific ones ≤ 30 µm);
//!   full well in [100, 10⁷] e⁻ (sub-micron pixels hold ≈3000 e⁻, large CCD pixels < 10⁶);
//!   bit depth 1–16 (the frames' own bound); vignetting exponent 0 ≤ n ≤ 20 (cos⁴ is the
//!   natural fall-off; the scene loader's bound);
//! - read noise 0 ≤ σ ≤ 1000 e⁻ (the scene loader's bound); gain in [−20, 60] dB (the bound the
//!   fit puts on each frame's gain);
//! - analyser extinction ratio in [1, 10⁹] (1: no analyser at all; the scene loader's bound).

use ellipso_model::radiometry::{CameraRadiometry, SensorNoiseSpec};
use ellipso_model::rig::{FlashProfileKind, FlashSpec};

pub use crate::rig::RangeError;
use crate::rig::{RadiometryRecord, RigRecord};

/// The farthest a flash may sit from the lens, m (module doc).
pub const MAX_FLASH_OFFSET_M: f64 = 1.0;

/// The largest radiant intensity a flash may record, W/sr: a studio flash's peak electrical
/// power is ≈10⁵ W, under 10⁴ W/sr of light; 10⁶ leaves a factor 100.
pub const MAX_RADIANT_INTENSITY_W_PER_SR: f64 = 1e6;

fn within(key: &str, v: f64, lo: f64, hi: f64, range: &'static str) -> Result<(), RangeError> {
    if v.is_finite() && (lo..=hi).contains(&v) {
        Ok(())
    } else {
        Err(RangeError {
            key: key.to_owned(),
            value: v.to_string(),
            range,
        })
    }
}

fn above_zero(key: &str, v: f64, hi: f64, range: &'static str) -> Result<(), RangeError> {
    within(key, v, f64::MIN_POSITIVE, hi, range)
}

/// Checks every value of `rig` but its camera against its physical range (module doc).
pub fn check(rig: &RigRecord) -> Result<(), RangeError> {
    if let Some(flash) = &rig.flash {
        check_flash(flash)?;
    }
    if let Some(RadiometryRecord::Absolute(r)) = &rig.radiometry {
        check_radiometry(r)?;
    }
    if let Some(n) = &rig.noise {
        check_noise(n)?;
    }
    if let Some(er) = rig.analyser_extinction_ratio {
        within(
            "rig.analyser_extinction_ratio",
            er,
            1.0,
            1e9,
            "1 to 10⁹; 1 is no analyser",
        )?;
    }
    Ok(())
}

fn check_flash(f: &FlashSpec) -> Result<(), RangeError> {
    let offset = nalgebra::Vector3::from(f.offset_m).norm();
    if !(offset.is_finite() && offset <= MAX_FLASH_OFFSET_M) {
        return Err(RangeError {
            key: "rig.flash.offset_m".into(),
            value: format!("{:?}", f.offset_m),
            range: "finite, at most 1 m from the lens: the flash is mounted on the camera",
        });
    }
    within(
        "rig.flash.polariser_deg",
        f.polariser_deg,
        -360.0,
        360.0,
        "−360° to 360°",
    )?;
    above_zero(
        "rig.flash.radiant_intensity_w_per_sr",
        f.radiant_intensity_w_per_sr,
        MAX_RADIANT_INTENSITY_W_PER_SR,
        "above 0, at most 10⁶ W/sr",
    )?;
    let p = &f.profile;
    match p.kind {
        FlashProfileKind::CosPower => {
            if let Some(n) = p.exponent {
                within(
                    "rig.flash.profile.exponent",
                    n,
                    0.0,
                    1000.0,
                    "0 to 1000 (cos-power exponent)",
                )?;
            }
        }
        FlashProfileKind::Table => {
            let angles = p.angle_deg.as_deref().unwrap_or_default();
            let relative = p.relative.as_deref().unwrap_or_default();
            let rising = angles.first() == Some(&0.0)
                && angles.windows(2).all(|w| w[1] > w[0])
                && angles.last().is_some_and(|a| *a <= 180.0);
            if angles.len() < 2 || angles.len() != relative.len() || !rising {
                return Err(RangeError {
                    key: "rig.flash.profile.angle_deg".into(),
                    value: format!("{angles:?}"),
                    range: "≥ 2 angles from 0 rising to ≤ 180°, one relative value each",
                });
            }
            for (i, v) in relative.iter().enumerate() {
                within(
                    &format!("rig.flash.profile.relative[{i}]"),
                    *v,
                    0.0,
                    f64::MAX,
                    "finite, ≥ 0",
                )?;
            }
        }
    }
    Ok(())
}

fn check_radiometry(r: &CameraRadiometry) -> Result<(), RangeError> {
    let k = |f: &str| format!("rig.radiometry.{f}");
    within(&k("f_number"), r.f_number, 0.5, 256.0, "f/0.5 to f/256")?;
    above_zero(
        &k("quantum_efficiency"),
        r.quantum_efficiency,
        1.0,
        "above 0, at most 1 electron per photon",
    )?;
    within(
        &k("pixel_pitch_um"),
        r.pixel_pitch_um,
        0.5,
        100.0,
        "0.5 to 100 µm",
    )?;
    within(
        &k("full_well_e"),
        r.full_well_e,
        100.0,
        1e7,
        "100 to 10⁷ e⁻",
    )?;
    bit_depth(&k("bit_depth"), r.bit_depth)?;
    if let Some(n) = r.vignetting_exponent {
        within(
            &k("vignetting_exponent"),
            n,
            0.0,
            20.0,
            "0 to 20 (cos⁴ is the natural fall-off)",
        )?;
    }
    Ok(())
}

fn check_noise(n: &SensorNoiseSpec) -> Result<(), RangeError> {
    let k = |f: &str| format!("rig.noise.{f}");
    within(
        &k("read_noise_e"),
        n.read_noise_e,
        0.0,
        1000.0,
        "0 to 1000 e⁻ RMS",
    )?;
    within(&k("gain_db"), n.gain_db, -20.0, 60.0, "−20 to 60 dB")?;
    within(
        &k("full_well_e"),
        n.full_well_e,
        100.0,
        1e7,
        "100 to 10⁷ e⁻",
    )?;
    bit_depth(&k("bit_depth"), n.bit_depth)
}

fn bit_depth(key: &str, bits: u8) -> Result<(), RangeError> {
    within(key, f64::from(bits), 1.0, 16.0, "1 to 16 bits")
}

#[cfg(test)]
mod tests;
