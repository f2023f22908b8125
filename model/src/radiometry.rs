//! Radiometry: how a model intensity becomes electrons and digital numbers. Shared by the
//! simulator's renderer (forward) and the host's fit (which divides raw DN by the same
//! [`Radiometry::normaliser`],
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

use serde::{Deserialize, Serialize};

use crate::rig::{CameraSpec, FlashProfileKind, FlashSpec};

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
        Self::of_exposure(
            &camera.radiometry(vignetting_exponent),
            camera.exposure_us,
            camera.gain_db,
            flash,
        )
    }

    /// The chain of a camera described by its camera-equation parameters (what a session
    /// records), exposed for `exposure_us` at `gain_db`, lit by `flash`.
    pub fn of_exposure(
        camera: &CameraRadiometry,
        exposure_us: f64,
        gain_db: f64,
        flash: &FlashSpec,
    ) -> Self {
        let pitch_m = camera.pixel_pitch_um * 1e-6;
        let exposure_s = exposure_us * 1e-6;
        let electrons_per_unit_irradiance =
            SYSTEM_CALIBRATION * camera.quantum_efficiency * exposure_s * pitch_m * pitch_m
                / (4.0 * camera.f_number * camera.f_number * PHOTON_ENERGY_J);
        Self {
            electrons_per_unit_irradiance,
            dn_per_electron: dn_per_electron(camera.bit_depth, camera.full_well_e, gain_db),
            full_well_e: camera.full_well_e,
            full_scale_dn: full_scale_dn(camera.bit_depth),
            vignetting_exponent: camera.vignetting_exponent,
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

/// The ADC's largest code for `bit_depth` significant bits, `2^bits − 1` (bits clamped to
/// 1..=16, the range a frame can have, so the shift is always defined).
pub fn full_scale_dn(bit_depth: u8) -> f64 {
    f64::from((1u32 << u32::from(bit_depth).clamp(1, 16)) - 1)
}

/// DN per photo-electron of a sensor with `bit_depth` bits and `full_well_e` electrons at
/// `gain_db`: the full well maps to full scale at 0 dB.
pub fn dn_per_electron(bit_depth: u8, full_well_e: f64, gain_db: f64) -> f64 {
    // full_well_e > 0 is validated by the scene loader and the session reader.
    full_scale_dn(bit_depth) / full_well_e * 10f64.powf(gain_db / 20.0)
}

/// The absolute camera-equation parameters of a camera, without its exposure and gain (which
/// each frame records): what a simulator session records so its fit computes the renderer's
/// normaliser without the scene file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraRadiometry {
    /// Lens f-number.
    pub f_number: f64,
    /// Quantum efficiency, electrons per photon.
    pub quantum_efficiency: f64,
    /// Pixel pitch, micrometres.
    pub pixel_pitch_um: f64,
    /// Full-well capacity, electrons.
    pub full_well_e: f64,
    /// ADC output bit depth.
    pub bit_depth: u8,
    /// Vignetting exponent n of cos^n(field angle), when the renderer applies vignetting.
    #[serde(default)]
    pub vignetting_exponent: Option<f64>,
}

/// The sensor noise a capture had, in the terms the fit's noise model reads: read noise,
/// shot noise through the conversion gain (full well, bit depth, analogue gain), quantisation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorNoiseSpec {
    /// Read noise, electrons RMS (0: none simulated).
    pub read_noise_e: f64,
    /// Whether photon shot noise is present.
    pub shot_noise: bool,
    /// Whether the frames are quantised to whole DN (adds 1/12 DN² of variance).
    pub quantised: bool,
    /// Analogue gain the noise was characterised at, dB.
    pub gain_db: f64,
    /// Full-well capacity, electrons.
    pub full_well_e: f64,
    /// ADC output bit depth.
    pub bit_depth: u8,
}

impl SensorNoiseSpec {
    /// DN per photo-electron at this spec's gain ([`dn_per_electron`]).
    pub fn dn_per_electron(&self) -> f64 {
        dn_per_electron(self.bit_depth, self.full_well_e, self.gain_db)
    }
}

impl CameraSpec {
    /// This camera's camera-equation parameters, with `vignetting_exponent` as the renderer
    /// applies it.
    pub fn radiometry(&self, vignetting_exponent: Option<f64>) -> CameraRadiometry {
        CameraRadiometry {
            f_number: self.f_number,
            quantum_efficiency: self.quantum_efficiency,
            pixel_pitch_um: self.pixel_pitch_um,
            full_well_e: self.full_well_e,
            bit_depth: self.bit_depth,
            vignetting_exponent,
        }
    }
}
