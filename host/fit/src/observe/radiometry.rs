//! The radiometry of a recorded session: how raw digital numbers become model units, i.e. the
//! normaliser N (docs/model.md §11 "Inputs and the normaliser N") per (vertex, view), and the
//! analyser model the observation channels are computed with. One place, [`radiometry_of`],
//! decides it from the session's rig record (`ellipso_session::rig::RigRecord`); the fit never
//! opens the scene or rig file a session was captured from.
//!
//! Contract:
//! - **Simulator sessions** (absolute): the manifest records the camera-equation parameters
//!   (f-number, QE, pitch, full well, bit depth, the vignetting exponent the renderer applied)
//!   and the analysers' extinction ratio, as the capture took them from the scene. N is then
//!   exactly the renderer's [`ellipso_model::radiometry::Radiometry::normaliser`] with the
//!   frame's recorded exposure and gain, so a noise-free render divided by N gives
//!   `ellipso_model::optics::measure::observe` of the true material. A simulator session
//!   recorded before these were written is refused with the command that upgrades it
//!   (`ellipso session upgrade`).
//! - **Hardware and replayed sessions** (relative): no absolute radiometric calibration exists,
//!   so N is a documented relative normaliser
//!   `N_rel = full_scale_dn · (t / 10 ms) · 10^(gain_dB/20) · profile(θ_flash) · (0.5 m / d)²`:
//!   model intensity 1 is full scale at a 10 ms, 0 dB exposure of a point on the flash axis
//!   0.5 m away. Albedos fitted with it are relative (one unknown global scale per session),
//!   consistent across views, exposures, gains and distances. Vignetting is not modelled.
//! - **Analyser extinction**: with a finite extinction ratio ER (e = 1/ER) an analyser at θ
//!   measures `½[(1+e)s0 + (1−e)(s1 cos2θ + s2 sin2θ)]` (the renderer's model). The observation
//!   channels undo it exactly: `I^s = (I0 − I90)/(1−e)`, `I^α = (I135 − I45)/(1−e)`,
//!   `I^d = (I0 + I90)/(1+e) − I^s`; with e = 0 these are docs/model.md §6's `I0 − I90`,
//!   `I135 − I45` and `2·I90`, bit for bit.
//! - Distances are clamped to ≥ 1 mm exactly as the renderer clamps them.
//! - **Flash energy.** A frame lit by a bracketed (shorter) pulse collects `E` times the flash
//!   light of a full pulse, `E` = the frame's recorded `FrameEntry::flash_energy_rel`. The
//!   normaliser of that frame is `E·N` ([`PointNormaliser::with_flash_energy`]): dividing its DN
//!   by `E·N` gives the same model units as a full-energy frame, and the fit's noise model,
//!   which reads sensor noise in DN and converts it with the sample's normaliser, then gives the
//!   short pulse's sample its larger relative noise (docs/fit-observe.md, "Flash-energy
//!   bracket"). Frames with `E = 0` hold no flash signal and are never sampled.

use std::path::PathBuf;

use ellipso_model::radiometry::{CameraRadiometry, Radiometry, full_scale_dn as full_scale};
use ellipso_model::rig::FlashSpec;

use super::ObserveError;
use crate::solve::SensorNoiseModel;
use ellipso_session::reader::Session;
use ellipso_session::rig::{FitInputs, RadiometryRecord};

/// Exposure at which the relative normaliser maps model intensity 1 to full scale, µs.
pub const RELATIVE_REFERENCE_EXPOSURE_US: f64 = 10_000.0;
/// Flash distance at which the relative normaliser maps model intensity 1 to full scale, m.
pub const RELATIVE_REFERENCE_DISTANCE_M: f64 = 0.5;
/// Closest flash distance the normaliser evaluates, m (the renderer's clamp: a point flash has
/// no meaning closer than its own size).
const MIN_FLASH_DISTANCE_M: f64 = 1e-3;

/// Where the normaliser's absolute scale comes from.
#[derive(Clone, Debug, PartialEq)]
pub enum NormaliserKind {
    /// The renderer's camera equation (simulator sessions) with these parameters (vignetting
    /// exponent included); exposure and gain come from each frame.
    Absolute(CameraRadiometry),
    /// The relative normaliser of the module doc (hardware sessions).
    Relative,
}

/// The radiometric model of one session (see the module doc).
#[derive(Clone, Debug, PartialEq)]
pub struct SessionRadiometry {
    /// The flash as recorded (position, polariser, intensity, angular profile).
    pub flash: FlashSpec,
    /// Absolute or relative scale.
    pub kind: NormaliserKind,
    /// e = 1/ER of the on-chip analysers (0: ideal).
    pub analyser_extinction: f64,
    /// 2^bits − 1 of the recorded frames.
    pub full_scale_dn: f64,
}

/// The normaliser of one frame (its exposure and gain fixed).
#[derive(Clone, Debug)]
pub enum FrameRadiometry {
    /// The renderer's chain with the frame's exposure and gain.
    Absolute(Radiometry),
    /// The relative normaliser.
    Relative {
        /// The flash (angular profile).
        flash: FlashSpec,
        /// full_scale · (t / 10 ms) · 10^(gain/20).
        scale: f64,
    },
}

impl FrameRadiometry {
    /// N, DN per unit model intensity, at a point `flash_distance_m` from the flash,
    /// `angle_from_flash_axis_rad` off its axis and `field_angle_rad` off the optical axis.
    pub fn normaliser(
        &self,
        flash_distance_m: f64,
        angle_from_flash_axis_rad: f64,
        field_angle_rad: f64,
    ) -> f64 {
        match self {
            FrameRadiometry::Absolute(r) => {
                r.normaliser(flash_distance_m, angle_from_flash_axis_rad, field_angle_rad)
            }
            FrameRadiometry::Relative { flash, scale } => {
                let d = flash_distance_m.max(MIN_FLASH_DISTANCE_M);
                let r = RELATIVE_REFERENCE_DISTANCE_M / d;
                scale * flash.relative_intensity(angle_from_flash_axis_rad.to_degrees()) * r * r
            }
        }
    }
}

/// N at any world point of one frame: the frame's radiometry with the sampler's geometry — the
/// flash aimed along the optical axis, the angle off it of the beam to the point, the field
/// angle of the point's ray off the optical axis (what `sampler::FrameSampler` evaluates per
/// vertex, and what a picture of that frame needs per pixel).
#[derive(Clone, Debug)]
pub struct PointNormaliser {
    /// The frame's radiometry.
    pub radiometry: FrameRadiometry,
    /// Flash position, world.
    pub flash_world: nalgebra::Point3<f64>,
    /// Flash axis (= optical axis), world, unit.
    pub flash_axis_world: nalgebra::Vector3<f64>,
    /// World → camera of the frame.
    pub camera_from_world: nalgebra::Isometry3<f64>,
    /// Flash energy that lit the frame relative to a full pulse (`FrameEntry::flash_energy_rel`;
    /// 1 for an unbracketed frame). Multiplies N.
    pub flash_energy_rel: f64,
}

impl PointNormaliser {
    /// The normaliser of a frame taken at `world_from_camera` with `radiometry`.
    pub fn new(
        radiometry: FrameRadiometry,
        flash: &FlashSpec,
        world_from_camera: &nalgebra::Isometry3<f64>,
    ) -> Self {
        Self {
            radiometry,
            flash_world: flash.position_world(world_from_camera),
            flash_axis_world: world_from_camera.rotation * nalgebra::Vector3::z(),
            camera_from_world: world_from_camera.inverse(),
            flash_energy_rel: 1.0,
        }
    }

    /// The same normaliser for a frame lit by `flash_energy_rel` of a full flash pulse (the
    /// frame's recorded relative pulse energy, ≥ 0; 0 makes N = 0: the frame is unlit).
    pub fn with_flash_energy(self, flash_energy_rel: f64) -> Self {
        Self {
            flash_energy_rel,
            ..self
        }
    }

    /// N at `point` (DN per model unit), the flash energy included; 0 outside the flash's
    /// emission or for an unlit frame, not finite for a point on the flash or the camera centre.
    pub fn at(&self, point: &nalgebra::Point3<f64>) -> f64 {
        let beam = point - self.flash_world;
        let d = beam.norm();
        let cos_axis = (beam / d).dot(&self.flash_axis_world).clamp(-1.0, 1.0);
        let p_cam = self.camera_from_world * point;
        // |p_cam| > 0 for any point the camera can see.
        let cos_field = (p_cam.z / p_cam.coords.norm()).clamp(-1.0, 1.0);
        self.flash_energy_rel
            * self
                .radiometry
                .normaliser(d, cos_axis.acos(), cos_field.acos())
    }
}

impl SessionRadiometry {
    /// The radiometry a session's rig record describes, for frames of `bit_depth` bits.
    pub fn from_inputs(inputs: &FitInputs, bit_depth: u8) -> Self {
        let kind = match &inputs.radiometry {
            RadiometryRecord::Absolute(camera) => NormaliserKind::Absolute(camera.clone()),
            RadiometryRecord::Relative => NormaliserKind::Relative,
        };
        let analyser_extinction = match inputs.analyser_extinction_ratio {
            Some(ratio) if ratio >= 1.0 => 1.0 / ratio,
            _ => 0.0,
        };
        Self {
            flash: inputs.flash.clone(),
            kind,
            analyser_extinction,
            full_scale_dn: full_scale(bit_depth),
        }
    }

    /// The relative radiometry of a rig without absolute calibration.
    pub fn relative(flash: FlashSpec, bit_depth: u8) -> Self {
        Self {
            flash,
            kind: NormaliserKind::Relative,
            analyser_extinction: 0.0,
            full_scale_dn: full_scale(bit_depth),
        }
    }

    /// The normaliser of a frame exposed for `exposure_us` at `gain_db`.
    pub fn for_frame(&self, exposure_us: f64, gain_db: f64) -> FrameRadiometry {
        match &self.kind {
            NormaliserKind::Absolute(camera) => FrameRadiometry::Absolute(Radiometry::of_exposure(
                camera,
                exposure_us,
                gain_db,
                &self.flash,
            )),
            NormaliserKind::Relative => FrameRadiometry::Relative {
                flash: self.flash.clone(),
                scale: self.full_scale_dn * exposure_us / RELATIVE_REFERENCE_EXPOSURE_US
                    * 10f64.powf(gain_db / 20.0),
            },
        }
    }

    /// Observation channels `[I^d, I^s, I^α, I^t]` from analyser intensities `[I0, I45, I90, I135]`
    /// with this session's analyser extinction undone (module doc).
    pub fn channels(&self, analysers: [f64; 4]) -> [f64; 4] {
        let [i0, i45, i90, i135] = analysers;
        let e = self.analyser_extinction;
        if e == 0.0 {
            return [i90 + i90, i0 - i90, i135 - i45, i45 + i135];
        }
        // e = 1/ER ≤ 1 (ER ≥ 1 is enforced where e is set); 1 − e > 0 unless ER = 1 (no
        // polariser), which no camera with analysers has. The max keeps the division finite.
        let cross = (1.0 - e).max(1e-6);
        let specular = (i0 - i90) / cross;
        let alpha = (i135 - i45) / cross;
        let s0 = (i0 + i90) / (1.0 + e);
        [s0 - specular, specular, alpha, (i45 + i135) / (1.0 + e)]
    }
}

fn manifest_path(session: &Session) -> PathBuf {
    session.dir.join(ellipso_session::paths::MANIFEST)
}

/// The flash recorded in the session's manifest (`rig.flash`).
pub fn flash_of(session: &Session) -> Result<FlashSpec, ObserveError> {
    session
        .manifest
        .rig
        .as_ref()
        .and_then(|r| r.flash.clone())
        .ok_or_else(|| ObserveError::MissingFlash {
            path: manifest_path(session),
        })
}

/// The radiometry of `session` (see the module doc for the rules per source).
pub fn radiometry_of(session: &Session) -> Result<SessionRadiometry, ObserveError> {
    let inputs = session
        .manifest
        .fit_inputs(&session.dir)
        .map_err(|e| match e {
            ellipso_session::rig::RigError::MissingFlash => ObserveError::MissingFlash {
                path: manifest_path(session),
            },
            e => ObserveError::Manifest {
                path: manifest_path(session),
                what: e.to_string(),
            },
        })?;
    Ok(SessionRadiometry::from_inputs(
        &inputs,
        session.manifest.sensor.bit_depth,
    ))
}

/// The sensor noise the solver weights `session`'s samples by, where the session records it
/// (simulator sessions): shot noise through the recorded conversion gain, read noise in DN.
pub fn sensor_noise_of(session: &Session) -> Option<SensorNoiseModel> {
    let noise = session.manifest.rig.as_ref()?.noise.as_ref()?;
    let dn_per_electron = noise.dn_per_electron();
    Some(SensorNoiseModel {
        dn_per_electron,
        read_noise_dn: noise.read_noise_e * dn_per_electron,
    })
}
