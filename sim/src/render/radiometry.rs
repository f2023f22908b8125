//! Radiometry: how a model intensity becomes electrons and digital numbers. Shared by the
//! renderer (forward) and the host's fit (which divides raw DN by the same [`Radiometry::normaliser`],
//! the normaliser N of docs/model.md §11 "Inputs and the normaliser N"), so the two can never
//! disagree about units.
//!
//! # Units
//! - **Model intensity** `m` (dimensionless): the analysed intensity of `P·s_light` for a unit
//!   flash Stokes vector (s0 = 1), with P the pBRDF of [`ellipso_model::optics::pbrdf`] (foreshortening
//!   included, no 1/d²). A pixel with an analyser at θ measures `m = ½(s0 + s1 cos2θ + s2 sin2θ)`
//!   of `s = P·s_light`; a camera without analysers measures `m = s0`. Boards (matte paper) give
//!   `m = albedo · cosθ_i · (½ or 1)`.
//! - The albedos ρ_d of scene files are Lambertian albedos in [0, 1], so the radiance leaving the
//!   surface is `L = E · m / π` with `E = I_e · profile(θ_flash) / d²` the flash irradiance
//!   normal to the beam (`I_e` = `radiant_intensity_w_per_sr`, W/sr; d in metres).
//! - Camera equation (on-axis, thin lens): the sensor irradiance is `π L / (4 N²)` (N the f-number),
//!   times `cos^n(field angle)` when vignetting is planned. The pixel collects it over its area
//!   `A = pitch²` for the exposure `t`:
//!   ```text
//!   electrons = K_cal · QE · t · A / (4 N² · E_photon) · I_e · profile(θ) / d² · vignetting · m
//!   DN        = electrons · (2^bits − 1) / full_well_e · 10^(gain_dB / 20)
//!   ```
//!   with `E_photon = h c / 550 nm` (a monochromatic-equivalent green photon) and
//!   [`SYSTEM_CALIBRATION`] `K_cal`.
//! - At 0 dB the full well maps to the ADC's full scale, so electron and DN saturation coincide;
//!   with gain the ADC clips first.
//!
//! Contract: `DN_expected = normaliser(d, θ_flash, field angle) × m` before noise, saturation
//! and quantisation, exactly as the renderer computes it (tested against a render).

use crate::scene::{CameraSpec, FlashProfileKind, FlashSpec};

/// Planck constant × speed of light / 550 nm: the energy of one green photon, joules.
pub const PHOTON_ENERGY_J: f64 = 6.626_070_15e-34 * 2.997_924_58e8 / 550e-9;

/// System calibration factor `K_cal` of the camera equation. It stands for everything the
/// thin-lens, single-wavelength equation leaves out (lens transmission, the sensor's spectral
/// response to a white LED, microlens gain), and is chosen so that the shipped sphere scene's
/// white board (albedo 0.85) sits near 40 % of full scale at its default exposure (8 ms at
/// 0.5 m, 0.5 W/sr, f/5.6): diffuse surfaces never saturate, glossy highlights do.
pub const SYSTEM_CALIBRATION: f64 = 4.0;

/// The radiometric chain of one rig (camera + flash) with or without vignetting.
#[derive(Clone, Debug, PartialEq)]
pub struct Radiometry {
    /// Electrons per unit model intensity at unit irradiance factor (W/sr/m²·s⁻¹ folded in).
    electrons_per_unit_irradiance: f64,
    /// DN per electron (ADC scale × analogue gain).
    dn_per_electron: f64,
    /// Full-well capacity, electrons.
    full_well_e: f64,
    /// 2^bits − 1.
    full_scale_dn: f64,
    /// Vignetting exponent n of cos^n (field angle), when planned.
    vignetting_exponent: Option<f64>,
    /// The flash (intensity and angular profile).
    flash: FlashSpec,
}

impl Radiometry {
    /// The chain for `camera` and `flash`; `vignetting_exponent` only when the plan holds the
    /// vignetting stage.
    pub fn new(camera: &CameraSpec, flash: &FlashSpec, vignetting_exponent: Option<f64>) -> Self {
        let pitch_m = camera.pixel_pitch_um * 1e-6;
        let exposure_s = camera.exposure_us * 1e-6;
        let electrons_per_unit_irradiance =
            SYSTEM_CALIBRATION * camera.quantum_efficiency * exposure_s * pitch_m * pitch_m
                / (4.0 * camera.f_number * camera.f_number * PHOTON_ENERGY_J);
        let full_scale_dn = f64::from((1u32 << camera.bit_depth) - 1);
        // full_well_e > 0 is validated by the scene loader.
        let dn_per_electron =
            full_scale_dn / camera.full_well_e * 10f64.powf(camera.gain_db / 20.0);
        Self {
            electrons_per_unit_irradiance,
            dn_per_electron,
            full_well_e: camera.full_well_e,
            full_scale_dn,
            vignetting_exponent,
            flash: flash.clone(),
        }
    }

    /// Flash irradiance normal to the beam per unit model intensity, W/m²:
    /// `I_e · profile(θ) / d²`. `distance_m` is clamped to ≥ 1 mm (a point flash has no
    /// meaning closer than its own size, and the clamp keeps 1/d² finite).
    pub fn flash_irradiance_w_per_m2(
        &self,
        distance_m: f64,
        angle_from_flash_axis_rad: f64,
    ) -> f64 {
        let d = distance_m.max(1e-3);
        self.flash.radiant_intensity_w_per_sr
            * self
                .flash
                .relative_intensity(angle_from_flash_axis_rad.to_degrees())
            / (d * d)
    }

    /// The same irradiance from the cosine of the angle off the flash axis (the renderer's hot
    /// path: no acos/cos round trip for the `cos_power` profile; tables go through the angle).
    pub fn flash_irradiance_from_cos(&self, distance_m: f64, cos_from_flash_axis: f64) -> f64 {
        let c = cos_from_flash_axis.clamp(-1.0, 1.0);
        let profile = match (self.flash.profile.kind, self.flash.profile.exponent) {
            // Same clamp as `FlashSpec::relative_intensity`: no light behind the emitter.
            (FlashProfileKind::CosPower, None | Some(1.0)) => c.max(0.0),
            (FlashProfileKind::CosPower, Some(n)) => c.max(0.0).powf(n),
            (FlashProfileKind::Table, _) => self.flash.relative_intensity(c.acos().to_degrees()),
        };
        let d = distance_m.max(1e-3);
        self.flash.radiant_intensity_w_per_sr * profile / (d * d)
    }

    /// `cos^n` of the field angle (1 when vignetting is not planned). The cosine is clamped
    /// to [0, 1].
    pub fn vignetting(&self, field_angle_rad: f64) -> f64 {
        self.vignetting_from_cos(field_angle_rad.cos())
    }

    /// `cos^n` from the cosine of the field angle (clamped to [0, 1]).
    pub fn vignetting_from_cos(&self, cos_field: f64) -> f64 {
        match self.vignetting_exponent {
            Some(n) => cos_field.clamp(0.0, 1.0).powf(n),
            None => 1.0,
        }
    }

    /// Electrons per unit model intensity at a point `distance_m` from the flash,
    /// `angle_from_flash_axis_rad` off its axis, seen at `field_angle_rad` off the optical axis.
    pub fn electrons_per_model_unit(
        &self,
        distance_m: f64,
        angle_from_flash_axis_rad: f64,
        field_angle_rad: f64,
    ) -> f64 {
        self.electrons_per_unit_irradiance
            * self.flash_irradiance_w_per_m2(distance_m, angle_from_flash_axis_rad)
            * self.vignetting(field_angle_rad)
    }

    /// Electrons per unit model intensity per unit flash irradiance (W/m²).
    pub fn electrons_per_irradiance(&self) -> f64 {
        self.electrons_per_unit_irradiance
    }

    /// The normaliser N: expected DN per unit analysed model intensity (before noise,
    /// saturation and quantisation). The fit divides observed DN by it to get model units.
    pub fn normaliser(
        &self,
        distance_m: f64,
        angle_from_flash_axis_rad: f64,
        field_angle_rad: f64,
    ) -> f64 {
        self.electrons_per_model_unit(distance_m, angle_from_flash_axis_rad, field_angle_rad)
            * self.dn_per_electron
    }

    /// DN per electron (ADC scale × analogue gain).
    pub fn dn_per_electron(&self) -> f64 {
        self.dn_per_electron
    }

    /// Full-well capacity, electrons.
    pub fn full_well_e(&self) -> f64 {
        self.full_well_e
    }

    /// The ADC's largest code, 2^bits − 1.
    pub fn full_scale_dn(&self) -> f64 {
        self.full_scale_dn
    }
}

/// The normaliser N for a scene's rig (see [`Radiometry::normaliser`]); `vignetting_exponent`
/// as planned (`scene.effects.vignetting.map(|v| v.exponent)`).
pub fn normaliser(
    camera: &CameraSpec,
    flash: &FlashSpec,
    vignetting_exponent: Option<f64>,
    flash_to_point_distance_m: f64,
    angle_from_flash_axis_rad: f64,
    field_angle_rad: f64,
) -> f64 {
    Radiometry::new(camera, flash, vignetting_exponent).normaliser(
        flash_to_point_distance_m,
        angle_from_flash_axis_rad,
        field_angle_rad,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Scene;
    use std::path::Path;

    fn sphere_scene() -> Scene {
        Scene::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/sphere.toml")).unwrap()
    }

    #[test]
    fn white_board_on_axis_sits_mid_scale_in_the_sphere_scene() {
        let s = sphere_scene();
        let r = Radiometry::new(&s.rig.camera, &s.rig.flash, None);
        // White paper (0.85) seen head-on through an analyser: m = ½ · 0.85.
        let dn = r.normaliser(0.5, 0.0, 0.0) * 0.5 * 0.85;
        let fraction = dn / r.full_scale_dn();
        assert!((0.3..0.6).contains(&fraction), "white board at {fraction}");
    }

    #[test]
    fn normaliser_scales_as_inverse_square_exposure_and_gain() {
        let s = sphere_scene();
        let mut cam = s.rig.camera.clone();
        let f = s.rig.flash.clone();
        let n1 = normaliser(&cam, &f, None, 0.5, 0.0, 0.0);
        assert!((normaliser(&cam, &f, None, 1.0, 0.0, 0.0) * 4.0 / n1 - 1.0).abs() < 1e-12);
        cam.exposure_us *= 2.0;
        assert!((normaliser(&cam, &f, None, 0.5, 0.0, 0.0) / n1 - 2.0).abs() < 1e-12);
        cam.gain_db = 20.0;
        assert!((normaliser(&cam, &f, None, 0.5, 0.0, 0.0) / n1 - 20.0).abs() < 1e-9);
        // cos^4 at 30° off axis; cos^1 flash profile at 60°.
        let v = normaliser(&s.rig.camera, &f, Some(4.0), 0.5, 0.0, 30f64.to_radians());
        assert!((v / n1 - 30f64.to_radians().cos().powi(4)).abs() < 1e-12);
        let p = normaliser(&s.rig.camera, &f, None, 0.5, 60f64.to_radians(), 0.0);
        assert!((p / n1 - 0.5).abs() < 1e-12);
    }

    #[test]
    fn cosine_and_angle_forms_agree_for_both_profile_kinds() {
        let s = sphere_scene();
        let mut flash = s.rig.flash.clone();
        for exponent in [None, Some(1.0), Some(3.5)] {
            flash.profile.exponent = exponent;
            let r = Radiometry::new(&s.rig.camera, &flash, Some(4.0));
            for deg in [0.0f64, 10.0, 45.0, 89.0, 120.0] {
                let a = r.flash_irradiance_w_per_m2(0.4, deg.to_radians());
                let b = r.flash_irradiance_from_cos(0.4, deg.to_radians().cos());
                assert!(
                    (a - b).abs() <= 1e-12 * a.max(1.0),
                    "{exponent:?} {deg}: {a} {b}"
                );
                let v =
                    r.vignetting(deg.to_radians()) - r.vignetting_from_cos(deg.to_radians().cos());
                assert!(v.abs() < 1e-12);
            }
        }
        flash.profile.kind = FlashProfileKind::Table;
        flash.profile.angle_deg = Some(vec![0.0, 30.0, 60.0]);
        flash.profile.relative = Some(vec![1.0, 0.5, 0.1]);
        let r = Radiometry::new(&s.rig.camera, &flash, None);
        let a = r.flash_irradiance_w_per_m2(0.4, 45f64.to_radians());
        let b = r.flash_irradiance_from_cos(0.4, 45f64.to_radians().cos());
        assert!((a - b).abs() <= 1e-9 * a && (a / (0.5 / 0.16) - 0.3).abs() < 1e-9);
    }

    #[test]
    fn tiny_distances_stay_finite() {
        let s = sphere_scene();
        let n = normaliser(&s.rig.camera, &s.rig.flash, None, 0.0, 0.0, 0.0);
        assert!(n.is_finite() && n > 0.0);
    }
}
