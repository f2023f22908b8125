//! Effects on demand: the [`EffectPlan`] of a scene, i.e. the stages a simulation runs and why.
//!
//! Contract:
//! - Every physical or sensor effect is a [`Stage`]. [`EffectPlan::from_scene`] derives the
//!   content stages (diffuse, diffuse polarisation, specular, single scattering, the Stokes
//!   path, shadows, flash falloff) from what the scene contains, and takes the sensor and fault
//!   stages from the effects the scene lists ([`crate::scene::EffectsSpec::listed`]). A stage
//!   that is not in the plan is never executed; every stage left out carries the reason.
//! - The renderer ([`crate::render`]) executes [`Executor::Renderer`] stages and reports how
//!   often it ran each one in a [`StageCounts`] per frame, so tests can prove that a scene pays
//!   only for the effects it needs. Frame-level and link stages ([`Executor::Rig`]) are in the
//!   plan for the virtual rig to execute; it reads their parameters from [`EffectPlan::rig_faults`].
//! - Derivation rules (also printed by `ellipso sim plan`):
//!   - diffuse: any object material with ρ_d > 0, or any board (boards are matte paper);
//!   - diffuse polarisation: the camera has analysers and an object material has ρ_d > 0
//!     (boards are depolarising paper and never need it);
//!   - specular / single scattering: any object material with ρ_s > 0 / any ρ_ss channel > 0;
//!   - Stokes path (`polarisation`): the camera has analysers. Without analysers only s0 is
//!     observed and no Mueller work is done at all ([`LightTransport`]);
//!   - shadows: at least two surfaces (objects + boards) or any mesh object; a single convex
//!     analytic surface cannot shadow itself (its back-facing points get no light anyway);
//!   - flash falloff: always (the flash is a point source: 1/d² and its angular profile);
//!   - motion blur: listed *and* a non-zero linear or angular speed (a static rig has none).
//!   - the sensor's fixed pattern (`analyser_errors`, `prnu`, `black_level`, `hot_pixels`) and
//!     the flash's true polariser angle and profile (`flash_polariser_error`,
//!     `flash_profile_error`): listed. Each fixed-pattern stage costs one evaluation of its
//!     per-pixel draw per raw pixel (a hash, no stored map: [`crate::render::FixedPattern`]);
//!     the flash stages cost nothing per pixel (the renderer lights the scene with the true
//!     flash, the session records the stated one).
//!
//! Only materials actually bound to an object count, so an unused material costs nothing.

mod counts;
mod derive;
#[cfg(test)]
mod tests;

pub use counts::{StageCounts, StageSet};

use crate::scene::EffectKind;
use crate::scene::effects::{
    AnalyserErrors, BlackLevel, FlashPolariserError, FlashProfileError, FrameDrops, HotPixels,
    LinkCorruption, LinkDisconnect, MotionBlur, PolariserExtinction, Prnu, ReadNoise,
    TriggerJitter, Vignetting,
};
use serde::Serialize;

/// One stage of the simulation.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Stage {
    /// Diffuse reflection intensity (objects: pBRDF diffuse lobe; boards: Lambertian paper).
    Diffuse,
    /// The polarised part of the object diffuse lobe (Fresnel transmission, Mueller form).
    DiffusePolarisation,
    /// Specular microfacet reflection (ρ_s lobe).
    Specular,
    /// Single scattering (ρ_ss lobe).
    SingleScattering,
    /// Full Stokes transport and the per-pixel analyser projection (the Mueller path).
    Polarisation,
    /// Shadow rays towards the flash.
    Shadows,
    /// 1/d² and the flash's angular profile.
    FlashFalloff,
    /// cos^n of the field angle.
    Vignetting,
    /// Brown–Conrady distortion of the primary rays.
    LensDistortion,
    /// Finite extinction ratio of the on-chip polarisers.
    PolariserExtinction,
    /// Per-pixel analyser angle and extinction errors (fixed pattern).
    AnalyserErrors,
    /// Photo-response non-uniformity (fixed pattern).
    Prnu,
    /// Poisson photon noise.
    ShotNoise,
    /// Gaussian read noise.
    ReadNoise,
    /// Black level and dark-signal non-uniformity (fixed pattern).
    BlackLevel,
    /// Hot pixels (fixed pattern).
    HotPixels,
    /// Rounding to whole digital numbers.
    Quantisation,
    /// Full-well and ADC clipping.
    Saturation,
    /// The flash polariser off its recorded angle.
    FlashPolariserError,
    /// The flash's true angular profile differs from the recorded one.
    FlashProfileError,
    /// Camera motion during the exposure.
    MotionBlur,
    /// Trigger timing jitter (virtual rig).
    TriggerJitter,
    /// Lost frames (virtual rig).
    FrameDrops,
    /// Bit errors on the trigger-board link (virtual rig).
    LinkCorruption,
    /// The trigger-board link drops out (virtual rig).
    LinkDisconnect,
}

/// Who executes a stage.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Executor {
    /// The renderer, per ray sample or per pixel.
    Renderer,
    /// The virtual rig, per frame or on the link.
    Rig,
}

impl Stage {
    /// Number of stages.
    pub const COUNT: usize = 25;
    /// Every stage, in pipeline order.
    pub const ALL: [Stage; Stage::COUNT] = [
        Stage::Diffuse,
        Stage::DiffusePolarisation,
        Stage::Specular,
        Stage::SingleScattering,
        Stage::Polarisation,
        Stage::Shadows,
        Stage::FlashFalloff,
        Stage::Vignetting,
        Stage::LensDistortion,
        Stage::PolariserExtinction,
        Stage::AnalyserErrors,
        Stage::Prnu,
        Stage::ShotNoise,
        Stage::ReadNoise,
        Stage::BlackLevel,
        Stage::HotPixels,
        Stage::Quantisation,
        Stage::Saturation,
        Stage::FlashPolariserError,
        Stage::FlashProfileError,
        Stage::MotionBlur,
        Stage::TriggerJitter,
        Stage::FrameDrops,
        Stage::LinkCorruption,
        Stage::LinkDisconnect,
    ];

    /// Position in [`Stage::ALL`].
    pub fn index(self) -> usize {
        self as usize
    }

    /// The snake_case name used in plans, JSON and scene files.
    pub fn name(self) -> &'static str {
        match self {
            Stage::Diffuse => "diffuse",
            Stage::DiffusePolarisation => "diffuse_polarisation",
            Stage::Specular => "specular",
            Stage::SingleScattering => "single_scattering",
            Stage::Polarisation => "polarisation",
            Stage::Shadows => "shadows",
            Stage::FlashFalloff => "flash_falloff",
            Stage::Vignetting => "vignetting",
            Stage::LensDistortion => "lens_distortion",
            Stage::PolariserExtinction => "polariser_extinction",
            Stage::AnalyserErrors => "analyser_errors",
            Stage::Prnu => "prnu",
            Stage::BlackLevel => "black_level",
            Stage::HotPixels => "hot_pixels",
            Stage::FlashPolariserError => "flash_polariser_error",
            Stage::FlashProfileError => "flash_profile_error",
            Stage::ShotNoise => "shot_noise",
            Stage::ReadNoise => "read_noise",
            Stage::Quantisation => "quantisation",
            Stage::Saturation => "saturation",
            Stage::MotionBlur => "motion_blur",
            Stage::TriggerJitter => "trigger_jitter",
            Stage::FrameDrops => "frame_drops",
            Stage::LinkCorruption => "link_corruption",
            Stage::LinkDisconnect => "link_disconnect",
        }
    }

    /// Who executes the stage.
    pub fn executor(self) -> Executor {
        match self {
            Stage::TriggerJitter
            | Stage::FrameDrops
            | Stage::LinkCorruption
            | Stage::LinkDisconnect => Executor::Rig,
            _ => Executor::Renderer,
        }
    }

    /// The stage a listed effect turns on.
    pub fn from_effect(kind: EffectKind) -> Stage {
        match kind {
            EffectKind::ShotNoise => Stage::ShotNoise,
            EffectKind::ReadNoise => Stage::ReadNoise,
            EffectKind::Quantisation => Stage::Quantisation,
            EffectKind::Saturation => Stage::Saturation,
            EffectKind::Vignetting => Stage::Vignetting,
            EffectKind::LensDistortion => Stage::LensDistortion,
            EffectKind::PolariserExtinction => Stage::PolariserExtinction,
            EffectKind::AnalyserErrors => Stage::AnalyserErrors,
            EffectKind::Prnu => Stage::Prnu,
            EffectKind::BlackLevel => Stage::BlackLevel,
            EffectKind::HotPixels => Stage::HotPixels,
            EffectKind::FlashPolariserError => Stage::FlashPolariserError,
            EffectKind::FlashProfileError => Stage::FlashProfileError,
            EffectKind::MotionBlur => Stage::MotionBlur,
            EffectKind::TriggerJitter => Stage::TriggerJitter,
            EffectKind::FrameDrops => Stage::FrameDrops,
            EffectKind::LinkCorruption => Stage::LinkCorruption,
            EffectKind::LinkDisconnect => Stage::LinkDisconnect,
        }
    }
}

/// How light is transported, chosen from the rig (the cheapest path that is exact for it).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum LightTransport {
    /// Camera without analysers, unpolarised flash: the scalar BRDF M00 per lobe, no rotations.
    Scalar,
    /// Camera without analysers, polarised flash: row 0 of P applied to the polarised light
    /// (the intensity depends on the input polarisation), no outgoing rotations.
    IntensityOfPolarised,
    /// Camera with analysers: full Stokes vector at the sensor, analysed per pixel.
    Stokes,
}

/// Parameters a stage carries (those of the scene's `[effects]` entry).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum StageParams {
    /// No parameters.
    None,
    /// Read noise.
    ReadNoise(ReadNoise),
    /// Vignetting.
    Vignetting(Vignetting),
    /// Polariser extinction.
    PolariserExtinction(PolariserExtinction),
    /// Per-pixel analyser errors.
    AnalyserErrors(AnalyserErrors),
    /// PRNU.
    Prnu(Prnu),
    /// Black level and DSNU.
    BlackLevel(BlackLevel),
    /// Hot pixels.
    HotPixels(HotPixels),
    /// Flash polariser angle error.
    FlashPolariserError(FlashPolariserError),
    /// Flash profile error.
    FlashProfileError(FlashProfileError),
    /// Motion blur.
    MotionBlur(MotionBlur),
    /// Trigger jitter.
    TriggerJitter(TriggerJitter),
    /// Frame drops.
    FrameDrops(FrameDrops),
    /// Link corruption.
    LinkCorruption(LinkCorruption),
    /// Link disconnect.
    LinkDisconnect(LinkDisconnect),
}

/// Whether a stage follows from the scene content or was listed in `[effects]`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Origin {
    /// Derived from materials, boards, geometry or the rig.
    Content,
    /// Listed in the scene's `[effects]`.
    Listed,
}

/// A stage in the plan.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PlannedStage {
    /// The stage.
    pub stage: Stage,
    /// Who runs it.
    pub executor: Executor,
    /// Derived or listed.
    pub origin: Origin,
    /// Why it is in, in words.
    pub reason: String,
    /// Its parameters.
    pub params: StageParams,
}

/// A stage left out, and why.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct OmittedStage {
    /// The stage.
    pub stage: Stage,
    /// Why it is out, in words.
    pub reason: String,
}

/// The frame-level and link faults the virtual rig executes (each `None` when not planned).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct RigFaults {
    /// Trigger timing jitter.
    pub trigger_jitter: Option<TriggerJitter>,
    /// Random frame loss.
    pub frame_drops: Option<FrameDrops>,
    /// Link bit errors.
    pub link_corruption: Option<LinkCorruption>,
    /// Link drop-out.
    pub link_disconnect: Option<LinkDisconnect>,
}

/// The stages a scene's simulation runs, each with its reason, and those it leaves out.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct EffectPlan {
    /// Scene name (or file stem).
    pub scene: String,
    /// The light-transport path the renderer uses.
    pub transport: LightTransport,
    /// Stages in, in pipeline order.
    pub stages: Vec<PlannedStage>,
    /// Stages out, in pipeline order.
    pub omitted: Vec<OmittedStage>,
}

impl EffectPlan {
    /// Whether `stage` is in the plan.
    pub fn contains(&self, stage: Stage) -> bool {
        self.stages.iter().any(|s| s.stage == stage)
    }

    /// The planned stages as a bit set (what the renderer branches on).
    pub fn stage_set(&self) -> StageSet {
        self.stages
            .iter()
            .fold(StageSet::EMPTY, |set, s| set.with(s.stage))
    }

    /// The parameters of a planned stage (`None` when the stage is not planned).
    pub fn params(&self, stage: Stage) -> Option<StageParams> {
        self.stages
            .iter()
            .find(|s| s.stage == stage)
            .map(|s| s.params)
    }

    /// The faults the virtual rig executes, with their parameters.
    pub fn rig_faults(&self) -> RigFaults {
        let mut f = RigFaults::default();
        for s in &self.stages {
            match s.params {
                StageParams::TriggerJitter(p) => f.trigger_jitter = Some(p),
                StageParams::FrameDrops(p) => f.frame_drops = Some(p),
                StageParams::LinkCorruption(p) => f.link_corruption = Some(p),
                StageParams::LinkDisconnect(p) => f.link_disconnect = Some(p),
                _ => {}
            }
        }
        f
    }

    /// A human-readable table: stages in (who runs them, why) and stages out (why).
    pub fn to_table(&self) -> String {
        use std::fmt::Write;
        let mut out = String::new();
        let transport = match self.transport {
            LightTransport::Scalar => "scalar BRDF (S0 camera, unpolarised flash)",
            LightTransport::IntensityOfPolarised => {
                "intensity of polarised light (S0 camera, polarised flash)"
            }
            LightTransport::Stokes => "full Stokes (camera with analysers)",
        };
        let _ = writeln!(out, "effect plan for scene '{}'", self.scene);
        let _ = writeln!(out, "light transport: {transport}\n");
        let _ = writeln!(out, "stages in ({}):", self.stages.len());
        let _ = writeln!(out, "  {:<22} {:<9} {:<8} why", "stage", "run by", "origin");
        for s in &self.stages {
            let by = match s.executor {
                Executor::Renderer => "renderer",
                Executor::Rig => "rig",
            };
            let origin = match s.origin {
                Origin::Content => "content",
                Origin::Listed => "listed",
            };
            let params = params_text(&s.params);
            let _ = writeln!(
                out,
                "  {:<22} {:<9} {:<8} {}{}",
                s.stage.name(),
                by,
                origin,
                s.reason,
                params
            );
        }
        let _ = writeln!(out, "\nstages out ({}):", self.omitted.len());
        for s in &self.omitted {
            let _ = writeln!(out, "  {:<22} {}", s.stage.name(), s.reason);
        }
        out
    }
}

fn params_text(p: &StageParams) -> String {
    match p {
        StageParams::None => String::new(),
        StageParams::ReadNoise(r) => format!(" [sigma_e = {}]", r.sigma_e),
        StageParams::Vignetting(v) => format!(" [exponent = {}]", v.exponent),
        StageParams::PolariserExtinction(x) => format!(" [ratio = {}]", x.ratio),
        StageParams::AnalyserErrors(a) => format!(
            " [angle_sigma_deg = {}, extinction_ratio_rgb = {:?}, extinction_sigma_rel = {}]",
            a.angle_sigma_deg, a.extinction_ratio_rgb, a.extinction_sigma_rel
        ),
        StageParams::Prnu(p) => format!(" [sigma_rel = {}]", p.sigma_rel),
        StageParams::BlackLevel(b) => format!(" [dn = {}, dsnu_dn = {}]", b.dn, b.dsnu_dn),
        StageParams::HotPixels(h) => format!(" [fraction = {}, dn = {}]", h.fraction, h.dn),
        StageParams::FlashPolariserError(f) => format!(" [angle_deg = {}]", f.angle_deg),
        StageParams::FlashProfileError(f) => format!(" [exponent = {}]", f.exponent),
        StageParams::MotionBlur(m) => format!(
            " [samples = {}, {} m/s, {} deg/s]",
            m.samples, m.linear_speed_m_per_s, m.angular_speed_deg_per_s
        ),
        StageParams::TriggerJitter(t) => format!(" [sigma_us = {}]", t.sigma_us),
        StageParams::FrameDrops(f) => format!(" [probability = {}]", f.probability),
        StageParams::LinkCorruption(l) => format!(" [bit_error_rate = {}]", l.bit_error_rate),
        StageParams::LinkDisconnect(l) => match l.duration_ms {
            Some(d) => format!(" [at_frame = {}, duration_ms = {d}]", l.at_frame),
            None => format!(" [at_frame = {}, for good]", l.at_frame),
        },
    }
}
