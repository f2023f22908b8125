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

/// The sensor's black level (a constant offset in DN) and its dark-signal non-uniformity.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct BlackLevel {
    /// Mean offset added to every pixel, DN.
    pub dn: f64,
    /// Pixel-to-pixel standard deviation of the offset (DSNU), DN.
    #[serde(default)]
    pub dsnu_dn: f64,
}

/// Photo-response non-uniformity: each pixel's response scaled by `1 + N(0, sigma_rel²)`.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Prnu {
    /// Relative standard deviation of the pixel gains.
    pub sigma_rel: f64,
}

/// Per-pixel analyser errors: the wire grid's angle off nominal and a finite extinction ratio
/// that differs per colour and per pixel (see `docs/sensor-calibration.md` for the sources of
/// the magnitudes).
#[derive(Clone, Copy, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct AnalyserErrors {
    /// Standard deviation of each pixel's analyser angle about its nominal angle, degrees.
    pub angle_sigma_deg: f64,
    /// Mean extinction ratio under the R, G, B filters (a mono sensor takes the G value).
    pub extinction_ratio_rgb: [f64; 3],
    /// Relative pixel-to-pixel standard deviation of the extinction ratio.
    #[serde(default)]
    pub extinction_sigma_rel: f64,
}

/// Hot pixels: a fraction of the pixels with a large extra dark signal.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct HotPixels {
    /// Fraction of the pixels that are hot, in [0, 0.01].
    pub fraction: f64,
    /// Extra dark signal of a hot pixel, DN.
    pub dn: f64,
}

/// The flash's polariser turned off the angle the rig record states.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct FlashPolariserError {
    /// Rotation of the polariser's transmission axis about the flash axis, degrees.
    pub angle_deg: f64,
}

/// The flash's angular profile is not the one the rig record states: the renderer lights the
/// scene with `cos^exponent` of the angle from the flash axis instead.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct FlashProfileError {
    /// The true profile's cosine exponent.
    pub exponent: f64,
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
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
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
    /// Per-pixel analyser angle and extinction errors.
    #[serde(default)]
    pub analyser_errors: Option<AnalyserErrors>,
    /// Photo-response non-uniformity.
    #[serde(default)]
    pub prnu: Option<Prnu>,
    /// Black level and DSNU.
    #[serde(default)]
    pub black_level: Option<BlackLevel>,
    /// Hot pixels.
    #[serde(default)]
    pub hot_pixels: Option<HotPixels>,
    /// The flash polariser's angle error.
    #[serde(default)]
    pub flash_polariser_error: Option<FlashPolariserError>,
    /// The flash's true angular profile.
    #[serde(default)]
    pub flash_profile_error: Option<FlashProfileError>,
    /// Seed of the sensor's fixed pattern (DSNU, PRNU, analyser errors, hot pixels): one
    /// physical sensor, the same in every scene that names the same seed (default 1).
    #[serde(default = "default_sensor_seed")]
    pub sensor_seed: u64,
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

fn default_sensor_seed() -> u64 {
    1
}

impl Default for EffectsSpec {
    fn default() -> Self {
        EffectsSpec {
            shot_noise: None,
            read_noise: None,
            quantisation: None,
            saturation: None,
            vignetting: None,
            lens_distortion: None,
            polariser_extinction: None,
            analyser_errors: None,
            prnu: None,
            black_level: None,
            hot_pixels: None,
            flash_polariser_error: None,
            flash_profile_error: None,
            sensor_seed: default_sensor_seed(),
            motion_blur: None,
            trigger_jitter: None,
            frame_drops: None,
            link_corruption: None,
            link_disconnect: None,
        }
    }
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
    /// `analyser_errors`
    AnalyserErrors,
    /// `prnu`
    Prnu,
    /// `black_level`
    BlackLevel,
    /// `hot_pixels`
    HotPixels,
    /// `flash_polariser_error`
    FlashPolariserError,
    /// `flash_profile_error`
    FlashProfileError,
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
            (self.analyser_errors.is_some(), K::AnalyserErrors),
            (self.prnu.is_some(), K::Prnu),
            (self.black_level.is_some(), K::BlackLevel),
            (self.hot_pixels.is_some(), K::HotPixels),
            (self.flash_polariser_error.is_some(), K::FlashPolariserError),
            (self.flash_profile_error.is_some(), K::FlashProfileError),
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
        if let Some(a) = self.analyser_errors {
            if !rig.camera.analysers {
                return Err(loc.invalid(
                    k("analyser_errors"),
                    "rig.camera.analysers is false: no analysers",
                ));
            }
            in_range(
                k("analyser_errors.angle_sigma_deg"),
                a.angle_sigma_deg,
                0.0,
                10.0,
                "need 0..=10°",
            )?;
            for (c, er) in ["R", "G", "B"].iter().zip(a.extinction_ratio_rgb) {
                in_range(
                    k(&format!("analyser_errors.extinction_ratio_rgb ({c})")),
                    er,
                    2.0,
                    1e6,
                    "need a ratio ≥ 2",
                )?;
            }
            in_range(
                k("analyser_errors.extinction_sigma_rel"),
                a.extinction_sigma_rel,
                0.0,
                0.3,
                "need 0..=0.3",
            )?;
        }
        if let Some(p) = self.prnu {
            in_range(k("prnu.sigma_rel"), p.sigma_rel, 0.0, 0.2, "need 0..=0.2")?;
        }
        if let Some(b) = self.black_level {
            in_range(k("black_level.dn"), b.dn, 0.0, 4096.0, "need 0..=4096 DN")?;
            in_range(
                k("black_level.dsnu_dn"),
                b.dsnu_dn,
                0.0,
                100.0,
                "need 0..=100 DN",
            )?;
        }
        if let Some(h) = self.hot_pixels {
            in_range(
                k("hot_pixels.fraction"),
                h.fraction,
                0.0,
                0.01,
                "need 0..=0.01",
            )?;
            in_range(k("hot_pixels.dn"), h.dn, 0.0, 65535.0, "need 0..=65535 DN")?;
        }
        if let Some(f) = self.flash_polariser_error {
            if !rig.flash.polarised {
                return Err(loc.invalid(
                    k("flash_polariser_error"),
                    "rig.flash.polarised is false: no flash polariser",
                ));
            }
            in_range(
                k("flash_polariser_error.angle_deg"),
                f.angle_deg,
                -45.0,
                45.0,
                "need -45..=45°",
            )?;
        }
        if let Some(f) = self.flash_profile_error {
            in_range(
                k("flash_profile_error.exponent"),
                f.exponent,
                0.0,
                50.0,
                "need 0..=50",
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
