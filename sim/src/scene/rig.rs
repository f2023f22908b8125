//! The rig section of a scene: camera and flash ([`RigSpec`]), with the range checks a scene
//! file's `[rig]` must pass. The types themselves live in `ellipso_model::rig` (a session records
//! the same flash and camera settings) and are re-exported here, so scene files parse as before.
//!
//! Contract: [`RigSpec::validate`] enforces ranges and names the key under `rig`.

use super::error::positive;
use super::error::{Located, SceneError};
pub use ellipso_model::rig::{
    CameraSpec, FlashProfileKind, FlashProfileSpec, FlashSpec, MAX_SIDE_PX, SensorKind,
};
use serde::{Deserialize, Serialize};

/// The analogue gain a simulated camera has, dB: the IMX250's 0–48 dB (scene files and the
/// stand-in camera of `rig check --fire` both hold a gain to it).
pub const GAIN_RANGE_DB: std::ops::RangeInclusive<f64> = 0.0..=48.0;

/// Camera and flash.
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct RigSpec {
    /// Camera model and settings.
    pub camera: CameraSpec,
    /// Flash (defaults: see [`FlashSpec`]).
    #[serde(default)]
    pub flash: FlashSpec,
}

impl RigSpec {
    /// Range checks; keys are under `rig`.
    pub fn validate(&self, loc: &Located<'_>) -> Result<(), SceneError> {
        let c = &self.camera;
        let k = |f: &str| format!("rig.camera.{f}");
        let [w, h] = c.resolution_px;
        if w < 2 || h < 2 || w % 2 != 0 || h % 2 != 0 || w > MAX_SIDE_PX || h > MAX_SIDE_PX {
            return Err(loc.invalid(
                k("resolution_px"),
                format!(
                    "{w}×{h}: need even sizes in 2..={MAX_SIDE_PX} for the 2×2 polariser mosaic"
                ),
            ));
        }
        let (i, d) = (c.intrinsics, c.distortion);
        for (f, v) in [("fx_px", i.fx), ("fy_px", i.fy)] {
            positive(loc, &k(f), v)?;
        }
        for (f, v, max) in [("cx_px", i.cx, w), ("cy_px", i.cy, h)] {
            if !(v.is_finite() && v >= 0.0 && v <= max as f64) {
                return Err(loc.invalid(
                    k(f),
                    format!("principal point {v} px lies outside the image (0..{max})"),
                ));
            }
        }
        for (f, v) in [
            ("k1", d.k1),
            ("k2", d.k2),
            ("k3", d.k3),
            ("p1", d.p1),
            ("p2", d.p2),
        ] {
            if !(v.is_finite() && v.abs() < 100.0) {
                return Err(
                    loc.invalid(k(f), format!("distortion coefficient {v} is not plausible"))
                );
            }
        }
        if ![8, 12, 16].contains(&c.bit_depth) {
            return Err(loc.invalid(
                k("bit_depth"),
                format!("{} bits: supported are 8, 12, 16", c.bit_depth),
            ));
        }
        positive(loc, &k("exposure_us"), c.exposure_us)?;
        if c.exposure_us > 10_000_000.0 {
            return Err(loc.invalid(k("exposure_us"), "longer than 10 s"));
        }
        if !(c.gain_db.is_finite() && GAIN_RANGE_DB.contains(&c.gain_db)) {
            return Err(loc.invalid(k("gain_db"), format!("{} dB outside 0..=48", c.gain_db)));
        }
        positive(loc, &k("full_well_e"), c.full_well_e)?;
        positive(loc, &k("pixel_pitch_um"), c.pixel_pitch_um)?;
        positive(loc, &k("f_number"), c.f_number)?;
        if !(c.quantum_efficiency > 0.0 && c.quantum_efficiency <= 1.0) {
            return Err(loc.invalid(k("quantum_efficiency"), "must be in (0, 1]"));
        }
        let f = &self.flash;
        let fk = |x: &str| format!("rig.flash.{x}");
        if !f.offset_m.iter().all(|v| v.is_finite()) {
            return Err(loc.invalid(fk("offset_m"), "must be finite"));
        }
        if !f.polariser_deg.is_finite() {
            return Err(loc.invalid(fk("polariser_deg"), "must be finite"));
        }
        if !f.polarised && f.polariser_deg != 0.0 {
            return Err(loc.invalid(fk("polariser_deg"), "given but the flash is not polarised"));
        }
        positive(
            loc,
            &fk("radiant_intensity_w_per_sr"),
            f.radiant_intensity_w_per_sr,
        )?;
        self.validate_profile(loc)
    }

    fn validate_profile(&self, loc: &Located<'_>) -> Result<(), SceneError> {
        let p = &self.flash.profile;
        let pk = |x: &str| format!("rig.flash.profile.{x}");
        match p.kind {
            FlashProfileKind::CosPower => {
                if p.angle_deg.is_some() || p.relative.is_some() {
                    let key = if p.angle_deg.is_some() {
                        "angle_deg"
                    } else {
                        "relative"
                    };
                    return Err(loc.invalid(pk(key), "only for kind = \"table\""));
                }
                if let Some(n) = p.exponent {
                    if !(n.is_finite() && (0.0..=1000.0).contains(&n)) {
                        return Err(loc.invalid(pk("exponent"), format!("{n} outside 0..=1000")));
                    }
                }
            }
            FlashProfileKind::Table => {
                if p.exponent.is_some() {
                    return Err(loc.invalid(pk("exponent"), "only for kind = \"cos_power\""));
                }
                let (Some(a), Some(r)) = (&p.angle_deg, &p.relative) else {
                    let key = if p.angle_deg.is_none() {
                        "angle_deg"
                    } else {
                        "relative"
                    };
                    return Err(
                        loc.invalid(pk(key), "a table profile needs angle_deg and relative")
                    );
                };
                if a.len() < 2 || a.len() != r.len() {
                    return Err(loc.invalid(
                        pk("relative"),
                        format!(
                            "{} values for {} angles (need equal counts, ≥ 2)",
                            r.len(),
                            a.len()
                        ),
                    ));
                }
                if a[0] != 0.0
                    || a.windows(2)
                        .any(|w| w[1].partial_cmp(&w[0]) != Some(std::cmp::Ordering::Greater))
                    || a[a.len() - 1] > 180.0
                {
                    return Err(loc.invalid(
                        pk("angle_deg"),
                        "must start at 0 and increase strictly up to ≤ 180",
                    ));
                }
                if r.iter().any(|v| !(v.is_finite() && *v >= 0.0)) {
                    return Err(loc.invalid(pk("relative"), "values must be finite and ≥ 0"));
                }
            }
        }
        Ok(())
    }
}
