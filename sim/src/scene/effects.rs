//! The effects section: sensor and fault effects a scene asks for, each with its parameters.
//!
//! Contract: an effect is on exactly when its table is present (`shot_noise = {}` turns on shot
//! noise with no parameters). Only effects that are *choices* are listed here; effects that follow
//! from the scene content (diffuse and specular reflection, diffuse polarisation, single scattering,
//! shadows, flash falloff) are never listed — the renderer derives them. [`EffectsSpec::validate`]
//! checks ranges and consistency with the rig and names the key; [`EffectsSpec::listed`] gives the
//! renderer the enabled set to plan from.

use super::error::{Located, SceneError};
use super::rig::RigSpec;
use serde::{Deserialize, Serialize};

/// An effect with no parameters.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Enabled {}

/// Read noise.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ReadNoise {
    /// Standard deviation, electrons RMS.
    pub sigma_e: f64,
}

/// Vignetting as `cos^n` of the field angle.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Vignetting {
    /// Exponent n (4 = natural cos⁴ falloff).
    pub exponent: f64,
}

/// Finite extinction ratio of the on-chip polarisers.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct PolariserExtinction {
    /// Transmission of parallel over crossed light (e.g. 300 for a wire-grid at 525 nm).
    pub ratio: f64,
}

/// Camera motion during the exposure.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct MotionBlur {
    /// Sub-exposure samples (≥ 2).
    pub samples: u32,
    /// Linear hand speed, m/s.
    pub linear_speed_m_per_s: f64,
    /// Angular hand speed, degrees/s.
    pub angular_speed_deg_per_s: f64,
}

/// Trigger timing jitter.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct TriggerJitter {
    /// Standard deviation, microseconds.
    pub sigma_us: f64,
}

/// Random frame loss.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct FrameDrops {
    /// Probability that a frame is lost, in [0, 1).
    pub probability: f64,
}

/// Bit errors on the trigger-board link.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct LinkCorruption {
    /// Bit error rate, in [0, 0.5].
    pub bit_error_rate: f64,
}

/// The trigger-board link drops out.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct LinkDisconnect {
    /// Frame index at which the link goes down.
    pub at_frame: u32,
    /// How long it stays down, milliseconds (absent = for good).
    #[serde(default)]
    pub duration_ms: Option<f64>,
}

/// The `[effects]` table.
#[derive(Clone, Debug, Default, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct EffectsSpec {
    /// Poisson photon noise.
    #[serde(default)]
    pub shot_noise: Option<Enabled>,
    /// Gaussian read noise.
    #[serde(default)]
    pub read_noise: Option<ReadNoise>,
    /// Rounding to `rig.camera.bit_depth` digital numbers.
    #[serde(default)]
    pub quantisation: Option<Enabled>,
    /// Clipping at `rig.camera.full_well_e` and at the ADC's maximum code.
    #[serde(default)]
    pub saturation: Option<Enabled>,
    /// Field-angle falloff.
    #[serde(default)]
    pub vignetting: Option<Vignetting>,
    /// Brown–Conrady distortion with `rig.camera` k1, k2, k3, p1, p2.
    #[serde(default)]
    pub lens_distortion: Option<Enabled>,
    /// Imperfect polarisers.
    #[serde(default)]
    pub polariser_extinction: Option<PolariserExtinction>,
    /// Exposure-time motion.
    #[serde(default)]
    pub motion_blur: Option<MotionBlur>,
    /// Trigger jitter.
    #[serde(default)]
    pub trigger_jitter: Option<TriggerJitter>,
    /// Frame drops.
    #[serde(default)]
    pub frame_drops: Option<FrameDrops>,
    /// Link byte corruption.
    #[serde(default)]
    pub link_corruption: Option<LinkCorruption>,
    /// Link disconnect.
    #[serde(default)]
    pub link_disconnect: Option<LinkDisconnect>,
}

/// Names of listable effects, for plans and reports.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum EffectKind {
    /// `shot_noise`
    ShotNoise,
    /// `read_noise`
    ReadNoise,
    /// `quantisation`
    Quantisation,
    /// `saturation`
    Saturation,
    /// `vignetting`
    Vignetting,
    /// `lens_distortion`
    LensDistortion,
    /// `polariser_extinction`
    PolariserExtinction,
    /// `motion_blur`
    MotionBlur,
    /// `trigger_jitter`
    TriggerJitter,
    /// `frame_drops`
    FrameDrops,
    /// `link_corruption`
    LinkCorruption,
    /// `link_disconnect`
    LinkDisconnect,
}

impl EffectsSpec {
    /// The enabled effects, in a fixed order.
    pub fn listed(&self) -> Vec<EffectKind> {
        use EffectKind as K;
        [
            (self.shot_noise.is_some(), K::ShotNoise),
            (self.read_noise.is_some(), K::ReadNoise),
            (self.quantisation.is_some(), K::Quantisation),
            (self.saturation.is_some(), K::Saturation),
            (self.vignetting.is_some(), K::Vignetting),
            (self.lens_distortion.is_some(), K::LensDistortion),
            (self.polariser_extinction.is_some(), K::PolariserExtinction),
            (self.motion_blur.is_some(), K::MotionBlur),
            (self.trigger_jitter.is_some(), K::TriggerJitter),
            (self.frame_drops.is_some(), K::FrameDrops),
            (self.link_corruption.is_some(), K::LinkCorruption),
            (self.link_disconnect.is_some(), K::LinkDisconnect),
        ]
        .into_iter()
        .filter_map(|(on, k)| on.then_some(k))
        .collect()
    }

    /// Range checks and consistency with the rig and photo count; keys under `effects`.
    pub fn validate(
        &self,
        rig: &RigSpec,
        photo_count: u32,
        loc: &Located<'_>,
    ) -> Result<(), SceneError> {
        let k = |f: &str| format!("effects.{f}");
        let in_range = |key: String, v: f64, lo: f64, hi: f64, what: &str| {
            if v.is_finite() && v >= lo && v <= hi {
                Ok(())
            } else {
                Err(loc.invalid(key, format!("{v}: {what}")))
            }
        };
        if let Some(r) = self.read_noise {
            in_range(
                k("read_noise.sigma_e"),
                r.sigma_e,
                0.0,
                1000.0,
                "need 0 ≤ σ ≤ 1000 e⁻",
            )?;
        }
        if let Some(v) = self.vignetting {
            in_range(
                k("vignetting.exponent"),
                v.exponent,
                0.0,
                20.0,
                "need 0 ≤ n ≤ 20",
            )?;
        }
        match (self.lens_distortion.is_some(), rig.camera.has_distortion()) {
            (true, false) => {
                return Err(loc.invalid(
                    k("lens_distortion"),
                    "listed, but rig.camera has all-zero distortion coefficients",
                ));
            }
            (false, true) => {
                return Err(loc.invalid(
                    "rig.camera",
                    "distortion coefficients given but effects.lens_distortion is not listed \
                     (list it, or set k1..p2 to 0)",
                ));
            }
            _ => {}
        }
        if let Some(e) = self.polariser_extinction {
            if !rig.camera.analysers {
                return Err(loc.invalid(
                    k("polariser_extinction"),
                    "rig.camera.analysers is false: no polarisers",
                ));
            }
            in_range(
                k("polariser_extinction.ratio"),
                e.ratio,
                1.0,
                1e9,
                "need a ratio ≥ 1",
            )?;
        }
        if let Some(m) = self.motion_blur {
            if !(2..=256).contains(&m.samples) {
                return Err(loc.invalid(
                    k("motion_blur.samples"),
                    format!("{}: need 2..=256", m.samples),
                ));
            }
            in_range(
                k("motion_blur.linear_speed_m_per_s"),
                m.linear_speed_m_per_s,
                0.0,
                10.0,
                "need 0..=10 m/s",
            )?;
            in_range(
                k("motion_blur.angular_speed_deg_per_s"),
                m.angular_speed_deg_per_s,
                0.0,
                3600.0,
                "need 0..=3600 °/s",
            )?;
        }
        if let Some(t) = self.trigger_jitter {
            in_range(
                k("trigger_jitter.sigma_us"),
                t.sigma_us,
                0.0,
                1e6,
                "need 0 ≤ σ ≤ 1 s",
            )?;
        }
        if let Some(f) = self.frame_drops {
            in_range(
                k("frame_drops.probability"),
                f.probability,
                0.0,
                0.999_999,
                "need 0 ≤ p < 1",
            )?;
        }
        if let Some(c) = self.link_corruption {
            in_range(
                k("link_corruption.bit_error_rate"),
                c.bit_error_rate,
                0.0,
                0.5,
                "need 0 ≤ BER ≤ 0.5",
            )?;
        }
        if let Some(d) = self.link_disconnect {
            if d.at_frame >= photo_count {
                return Err(loc.invalid(
                    k("link_disconnect.at_frame"),
                    format!(
                        "frame {} is past the last photo ({})",
                        d.at_frame,
                        photo_count.saturating_sub(1)
                    ),
                ));
            }
            if let Some(ms) = d.duration_ms {
                in_range(
                    k("link_disconnect.duration_ms"),
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
