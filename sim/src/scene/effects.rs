//! The effects section: sensor and fault effects a scene asks for, each with its parameters.
//!
//! Contract: an effect is on exactly when its table is present (`shot_noise = {}` turns on shot
//! noise with no parameters). Only effects that are *choices* are listed here; effects that follow
//! from the scene content (diffuse and specular reflection, diffuse polarisation, single scattering,
//! shadows, flash falloff) are never listed — the renderer derives them. [`EffectsSpec::validate`]
//! checks ranges and consistency with the rig and names the key; [`EffectsSpec::listed`] gives the
//! renderer the enabled set to plan from.

mod validate;

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
}
