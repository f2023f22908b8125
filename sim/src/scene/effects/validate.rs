//! Validation of the `[effects]` table: each listed effect's parameters against their ranges,
//! and the effects that need rig hardware (lens distortion, analysers, a flash polariser) or a
//! photo count against the rig and the capture. Checks run in the table's order and stop at the
//! first failure; its key names the field under `effects` (or `rig.camera`).

use super::EffectsSpec;
use crate::scene::error::{Located, SceneError};
use crate::scene::rig::RigSpec;

/// Builds the located errors of the effects checks, keys under `effects.`.
struct Checks<'l, 'a> {
    loc: &'l Located<'a>,
}

impl Checks<'_, '_> {
    /// An error at `effects.<field>`.
    fn invalid(&self, field: &str, message: impl Into<String>) -> SceneError {
        self.loc.invalid(format!("effects.{field}"), message)
    }

    /// `Ok` when `v` is finite and in `lo..=hi`; otherwise an error at `effects.<field>` saying
    /// the value and `what` is needed.
    fn in_range(
        &self,
        field: &str,
        v: f64,
        lo: f64,
        hi: f64,
        what: &str,
    ) -> Result<(), SceneError> {
        let key = format!("effects.{field}");
        if v.is_finite() && v >= lo && v <= hi {
            Ok(())
        } else {
            Err(self.loc.invalid(key, format!("{v}: {what}")))
        }
    }
}

impl EffectsSpec {
    /// Range checks and consistency with the rig and photo count; keys under `effects`.
    pub fn validate(
        &self,
        rig: &RigSpec,
        photo_count: u32,
        loc: &Located<'_>,
    ) -> Result<(), SceneError> {
        let checks = Checks { loc };
        self.validate_camera(rig, &checks)?;
        self.validate_analysers(rig, &checks)?;
        self.validate_fixed_pattern(&checks)?;
        self.validate_flash(rig, &checks)?;
        self.validate_capture_faults(photo_count, &checks)
    }

    /// Read noise, vignetting, and lens distortion listed exactly when the rig's camera has
    /// distortion coefficients.
    fn validate_camera(&self, rig: &RigSpec, c: &Checks<'_, '_>) -> Result<(), SceneError> {
        if let Some(r) = self.read_noise {
            c.in_range(
                "read_noise.sigma_e",
                r.sigma_e,
                0.0,
                1000.0,
                "need 0 ≤ σ ≤ 1000 e⁻",
            )?;
        }
        if let Some(v) = self.vignetting {
            c.in_range(
                "vignetting.exponent",
                v.exponent,
                0.0,
                20.0,
                "need 0 ≤ n ≤ 20",
            )?;
        }
        match (self.lens_distortion.is_some(), rig.camera.has_distortion()) {
            (true, false) => {
                return Err(c.invalid(
                    "lens_distortion",
                    "listed, but rig.camera has all-zero distortion coefficients",
                ));
            }
            (false, true) => {
                return Err(c.loc.invalid(
                    "rig.camera",
                    "distortion coefficients given but effects.lens_distortion is not listed \
                     (list it, or set k1..p2 to 0)",
                ));
            }
            _ => {}
        }
        Ok(())
    }

    /// Polariser extinction and analyser errors: only with analysers on the camera.
    fn validate_analysers(&self, rig: &RigSpec, c: &Checks<'_, '_>) -> Result<(), SceneError> {
        if let Some(e) = self.polariser_extinction {
            if !rig.camera.analysers {
                return Err(c.invalid(
                    "polariser_extinction",
                    "rig.camera.analysers is false: no polarisers",
                ));
            }
            c.in_range(
                "polariser_extinction.ratio",
                e.ratio,
                1.0,
                1e9,
                "need a ratio ≥ 1",
            )?;
        }
        if let Some(a) = self.analyser_errors {
            if !rig.camera.analysers {
                return Err(c.invalid(
                    "analyser_errors",
                    "rig.camera.analysers is false: no analysers",
                ));
            }
            c.in_range(
                "analyser_errors.angle_sigma_deg",
                a.angle_sigma_deg,
                0.0,
                10.0,
                "need 0..=10°",
            )?;
            for (colour, er) in ["R", "G", "B"].iter().zip(a.extinction_ratio_rgb) {
                c.in_range(
                    &format!("analyser_errors.extinction_ratio_rgb ({colour})"),
                    er,
                    2.0,
                    1e6,
                    "need a ratio ≥ 2",
                )?;
            }
            c.in_range(
                "analyser_errors.extinction_sigma_rel",
                a.extinction_sigma_rel,
                0.0,
                0.3,
                "need 0..=0.3",
            )?;
        }
        Ok(())
    }

    /// The sensor's other fixed pattern: PRNU, black level and DSNU, hot pixels.
    fn validate_fixed_pattern(&self, c: &Checks<'_, '_>) -> Result<(), SceneError> {
        if let Some(p) = self.prnu {
            c.in_range("prnu.sigma_rel", p.sigma_rel, 0.0, 0.2, "need 0..=0.2")?;
        }
        if let Some(b) = self.black_level {
            c.in_range("black_level.dn", b.dn, 0.0, 4096.0, "need 0..=4096 DN")?;
            c.in_range(
                "black_level.dsnu_dn",
                b.dsnu_dn,
                0.0,
                100.0,
                "need 0..=100 DN",
            )?;
        }
        if let Some(h) = self.hot_pixels {
            c.in_range(
                "hot_pixels.fraction",
                h.fraction,
                0.0,
                0.01,
                "need 0..=0.01",
            )?;
            c.in_range("hot_pixels.dn", h.dn, 0.0, 65535.0, "need 0..=65535 DN")?;
        }
        Ok(())
    }

    /// The flash's polariser angle error (only with a polarised flash) and its true profile.
    fn validate_flash(&self, rig: &RigSpec, c: &Checks<'_, '_>) -> Result<(), SceneError> {
        if let Some(f) = self.flash_polariser_error {
            if !rig.flash.polarised {
                return Err(c.invalid(
                    "flash_polariser_error",
                    "rig.flash.polarised is false: no flash polariser",
                ));
            }
            c.in_range(
                "flash_polariser_error.angle_deg",
                f.angle_deg,
                -45.0,
                45.0,
                "need -45..=45°",
            )?;
        }
        if let Some(f) = self.flash_profile_error {
            c.in_range(
                "flash_profile_error.exponent",
                f.exponent,
                0.0,
                50.0,
                "need 0..=50",
            )?;
        }
        Ok(())
    }

    /// Motion blur, trigger jitter, frame drops and the link faults; a disconnect must start at
    /// one of the `photo_count` photos.
    fn validate_capture_faults(
        &self,
        photo_count: u32,
        c: &Checks<'_, '_>,
    ) -> Result<(), SceneError> {
        if let Some(m) = self.motion_blur {
            if !(2..=256).contains(&m.samples) {
                return Err(c.invalid(
                    "motion_blur.samples",
                    format!("{}: need 2..=256", m.samples),
                ));
            }
            c.in_range(
                "motion_blur.linear_speed_m_per_s",
                m.linear_speed_m_per_s,
                0.0,
                10.0,
                "need 0..=10 m/s",
            )?;
            c.in_range(
                "motion_blur.angular_speed_deg_per_s",
                m.angular_speed_deg_per_s,
                0.0,
                3600.0,
                "need 0..=3600 °/s",
            )?;
        }
        if let Some(t) = self.trigger_jitter {
            c.in_range(
                "trigger_jitter.sigma_us",
                t.sigma_us,
                0.0,
                1e6,
                "need 0 ≤ σ ≤ 1 s",
            )?;
        }
        if let Some(f) = self.frame_drops {
            c.in_range(
                "frame_drops.probability",
                f.probability,
                0.0,
                0.999_999,
                "need 0 ≤ p < 1",
            )?;
        }
        if let Some(lc) = self.link_corruption {
            c.in_range(
                "link_corruption.bit_error_rate",
                lc.bit_error_rate,
                0.0,
                0.5,
                "need 0 ≤ BER ≤ 0.5",
            )?;
        }
        if let Some(d) = self.link_disconnect {
            if d.at_frame >= photo_count {
                return Err(c.invalid(
                    "link_disconnect.at_frame",
                    format!(
                        "frame {} is past the last photo ({})",
                        d.at_frame,
                        photo_count.saturating_sub(1)
                    ),
                ));
            }
            if let Some(ms) = d.duration_ms {
                c.in_range(
                    "link_disconnect.duration_ms",
                    ms,
                    0.0,
                    3.6e6,
                    "need 0..=3 600 000 ms",
                )?;
            }
        }
        Ok(())
    }
}
