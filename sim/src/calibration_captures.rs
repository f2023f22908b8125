//! Simulated sensor-calibration captures: the dark frames, flat fields and polariser-sheet
//! flats a user takes with the rig (`docs/sensor-calibration.md`), rendered for a scene's
//! camera with the scene's sensor effects, written as a captures folder
//! ([`ellipso_session::calibration_captures`]) that `ellipso calibrate sensor` reads.
//!
//! Contract: [`render`] draws every frame with [`crate::render::Renderer::render_uniform`]
//! from the scene's seed and the frame's index (a pure function of scene and plan); [`write`]
//! writes the PNGs and `captures.json` into a folder that must be empty or absent (it never
//! writes over anything).

use std::path::Path;

use ellipso_session::calibration_captures::{
    CaptureFrame, CaptureKind, CaptureSet, FORMAT, VERSION,
};
use ellipso_session::manifest::SensorInfo;

use crate::render::{RenderError, RenderOptions, Renderer, UniformTarget, frame_seed};
use crate::scene::Scene;

/// How many frames of each kind, and how bright.
#[derive(Clone, Debug, PartialEq)]
pub struct CapturePlan {
    /// Dark frames.
    pub dark_frames: u32,
    /// Relative flat-field levels (photon transfer), each in (0, 1]; 1 is `full_level_rel` of
    /// the full well at the image centre.
    pub flat_levels_rel: Vec<f64>,
    /// Frames per flat level.
    pub flat_frames: u32,
    /// Polariser-sheet angles, degrees (≥ 4 distinct).
    pub polariser_deg: Vec<f64>,
    /// Frames per polariser angle.
    pub polariser_frames: u32,
    /// Signal of the brightest flat at the image centre, as a fraction of the full well.
    pub full_level_rel: f64,
    /// Signal behind the sheet (parallel analyser, image centre), fraction of the full well.
    pub polariser_level_rel: f64,
}

impl Default for CapturePlan {
    /// 16 dark frames; 8 flat levels × 4 frames from 5 % to 70 % of the full well (EMVA 1288
    /// fits the photon transfer below 70 %); 8 sheet angles every 22.5° × 16 frames at 60 %.
    fn default() -> Self {
        CapturePlan {
            dark_frames: 16,
            flat_levels_rel: (1..=8).map(|i| f64::from(i) / 8.0).collect(),
            flat_frames: 4,
            polariser_deg: (0..8).map(|i| 22.5 * f64::from(i)).collect(),
            polariser_frames: 16,
            full_level_rel: 0.7,
            polariser_level_rel: 0.6,
        }
    }
}

/// One rendered capture frame.
#[derive(Clone, Debug)]
pub struct RenderedCapture {
    /// Its manifest entry.
    pub frame: CaptureFrame,
    /// The raw frame.
    pub raw: Vec<u16>,
}

/// The rendered set: the manifest and the frames it names.
#[derive(Clone, Debug)]
pub struct RenderedCaptures {
    /// `captures.json`.
    pub set: CaptureSet,
    /// The frames, in manifest order.
    pub frames: Vec<RenderedCapture>,
}

/// Renders the captures of `plan` with the sensor of `scene` at `options` (resolution override
/// honoured; supersampling is irrelevant to uniform targets).
pub fn render(
    scene: &Scene,
    plan: &CapturePlan,
    options: RenderOptions,
) -> Result<RenderedCaptures, RenderError> {
    let renderer = Renderer::new(scene, options)?;
    let camera = renderer.camera();
    let full_well_e = renderer.radiometry().full_well_e();
    let seed = options.seed.unwrap_or(scene.seed) ^ 0x00ca_11b7;
    let mut jobs: Vec<(String, CaptureKind, UniformTarget)> = Vec::new();
    for i in 0..plan.dark_frames {
        jobs.push((
            format!("dark_{i:03}.png"),
            CaptureKind::Dark,
            UniformTarget {
                electrons: 0.0,
                stokes: [1.0, 0.0, 0.0],
            },
        ));
    }
    for (l, level) in plan.flat_levels_rel.iter().enumerate() {
        for i in 0..plan.flat_frames {
            // a parallel analyser passes ½(1 + 1) of unpolarised light's s0: ask for twice the
            // level so the pixels sit at `level × full_level_rel` of the well
            jobs.push((
                format!("flat_{l:02}_{i:03}.png"),
                CaptureKind::Flat { level_rel: *level },
                UniformTarget {
                    electrons: 2.0 * level * plan.full_level_rel * full_well_e,
                    stokes: [1.0, 0.0, 0.0],
                },
            ));
        }
    }
    for (a, deg) in plan.polariser_deg.iter().enumerate() {
        let (s, c) = (2.0 * deg.to_radians()).sin_cos();
        for i in 0..plan.polariser_frames {
            jobs.push((
                format!("polariser_{a:02}_{i:03}.png"),
                CaptureKind::Polariser {
                    polariser_deg: *deg,
                },
                UniformTarget {
                    electrons: plan.polariser_level_rel * full_well_e,
                    stokes: [1.0, c, s],
                },
            ));
        }
    }
    let frames: Vec<RenderedCapture> = jobs
        .into_iter()
        .enumerate()
        .map(|(k, (file, kind, target))| RenderedCapture {
            frame: CaptureFrame { file, kind },
            raw: renderer
                .render_uniform(&target, frame_seed(seed, k))
                .iter()
                .map(|v| v.round().clamp(0.0, 65535.0) as u16)
                .collect(),
        })
        .collect();
    let set = CaptureSet {
        format: FORMAT.into(),
        version: VERSION,
        sensor: SensorInfo {
            layout: renderer.layout(),
            width: camera.width,
            height: camera.height,
            bit_depth: scene.rig.camera.bit_depth,
        },
        gain_db: scene.rig.camera.gain_db,
        camera: *camera,
        source: format!(
            "simulated: scene '{}', sensor seed {}",
            scene.name.clone().unwrap_or_default(),
            scene.effects.sensor_seed
        ),
        frames: Vec::new(),
    };
    let set = CaptureSet {
        frames: frames
            .iter()
            .map(|f: &RenderedCapture| f.frame.clone())
            .collect(),
        ..set
    };
    Ok(RenderedCaptures { set, frames })
}

/// Why a captures folder cannot be written.
#[derive(Debug, thiserror::Error)]
pub enum WriteError {
    /// The folder exists and is not empty.
    #[error("{0}: exists and is not empty (captures are written into a new folder)")]
    NotEmpty(String),
    /// A file cannot be written.
    #[error("{path}: {reason}")]
    Io {
        /// The file.
        path: String,
        /// What went wrong.
        reason: String,
    },
}

/// Writes `captures` into `dir` (created; must be empty or absent).
pub fn write(captures: &RenderedCaptures, dir: &Path) -> Result<(), WriteError> {
    let io = |path: &Path, e: &dyn std::fmt::Display| WriteError::Io {
        path: path.display().to_string(),
        reason: e.to_string(),
    };
    if dir.exists()
        && std::fs::read_dir(dir)
            .map_err(|e| io(dir, &e))?
            .next()
            .is_some()
    {
        return Err(WriteError::NotEmpty(dir.display().to_string()));
    }
    std::fs::create_dir_all(dir).map_err(|e| io(dir, &e))?;
    let s = &captures.set.sensor;
    for f in &captures.frames {
        let path = dir.join(&f.frame.file);
        ellipso_session::frame_png::write(&path, s.width, s.height, &f.raw)
            .map_err(|e| io(&path, &e))?;
    }
    captures
        .set
        .write(dir)
        .map_err(|e| io(&dir.join("captures.json"), &e))
}
