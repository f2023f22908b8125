//! What a session records of a scene: the rig record and the boards a simulated capture of it
//! writes into its manifest (`ellipso capture --sim`, the demo, the benches' rendered sessions,
//! and `ellipso session upgrade` for a session recorded before the record was complete), so the
//! session's tracking and fit never read the scene file; and a scene's capture rendered
//! straight into a session ([`render_session`]).
//!
//! Contract:
//! - The record holds the scene's flash, and the radiometry, sensor noise and analyser
//!   extinction its renderer simulates ([`crate::render::radiometry::recorded_sensor`]); the
//!   boards are the scene's placed boards as `ellipso_session::rig::TrackedBoard`.
//! - [`render_session`] writes the session `ellipso capture --sim` writes — the same manifest
//!   (simulator source naming the scene file, sensor layout, the rig record, boards) and the
//!   same raw frames (the simulated camera renders frame k with the same renderer, options and
//!   noise seed, so its PNGs are byte-identical: `capture_frames_equal_direct_renders` in
//!   `tests/`) — without the trigger board, the pty and the real-time pacing, which cannot
//!   change a pixel. Frame k has frame id `first_frame_id + k`, the scene's exposure and gain,
//!   host time k ms, and no pulse (relative flash energy 1: the full pulse).

use std::path::{Path, PathBuf};

use ellipso_model::camera::CameraModel;
use ellipso_session::manifest::{Manifest, SensorInfo, SessionSource};
use ellipso_session::rig::{RadiometryRecord, RigRecord, TrackedBoard};
use ellipso_session::time::HostTimeUs;
use ellipso_session::writer::{FrameRecord, SessionWriter};

use crate::render::{RenderOptions, Renderer};
use crate::scene::Scene;

/// Why [`render_session`] failed.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// The scene file's path could not be resolved.
    #[error("{}: {source}", path.display())]
    Io {
        /// The scene file.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// Rendering failed.
    #[error("{0}")]
    Render(String),
    /// Writing the session failed.
    #[error(transparent)]
    Session(#[from] ellipso_session::SessionError),
}

/// Renders `scene` (loaded from `scene_path`) with `options` into a new session at `dir`
/// (module contract), frame ids from `first_frame_id`; `progress(done, total)` after each
/// frame.
pub fn render_session(
    scene_path: &Path,
    scene: &Scene,
    options: RenderOptions,
    dir: &Path,
    first_frame_id: u64,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(), RecordError> {
    let renderer = Renderer::new(scene, options).map_err(|e| RecordError::Render(e.to_string()))?;
    let camera = *renderer.camera();
    let scene_file = std::fs::canonicalize(scene_path).map_err(|source| RecordError::Io {
        path: scene_path.to_owned(),
        source,
    })?;
    let mut manifest = Manifest::new(
        SessionSource::Simulator {
            scene: scene_file.display().to_string(),
            seed: scene.seed,
        },
        SensorInfo {
            layout: renderer.layout(),
            width: camera.width,
            height: camera.height,
            bit_depth: scene.rig.camera.bit_depth,
        },
        0,
    );
    manifest.rig = Some(rig_record_of_scene(scene, camera));
    manifest.boards = boards_of_scene(scene);
    let mut writer = SessionWriter::create(dir, manifest)?;
    let total = renderer.frame_count();
    for k in 0..total {
        let frame = renderer
            .render_frame(k)
            .map_err(|e| RecordError::Render(e.to_string()))?;
        writer.write_frame(FrameRecord {
            t_host_us: HostTimeUs(k as u64 * 1000),
            frame_id: first_frame_id + k as u64,
            t_camera_ns: None,
            exposure_us: scene.rig.camera.exposure_us.round() as u32,
            gain_db: scene.rig.camera.gain_db as f32,
            width: frame.width,
            height: frame.height,
            pixels: &frame.raw(),
            flagged: None,
        })?;
        progress(k + 1, total);
    }
    writer.finish(HostTimeUs(total as u64 * 1000), "completed")?;
    Ok(())
}

/// The rig record a simulated capture of `scene` writes, with `camera` the model of the frames
/// it renders (the scene's camera, or the resolution override's): the flash, and the
/// radiometry, sensor noise and analyser extinction the renderer simulates, so the session's
/// fit needs no scene file.
pub fn rig_record_of_scene(scene: &Scene, camera: CameraModel) -> RigRecord {
    let sensor = crate::render::radiometry::recorded_sensor(scene);
    RigRecord {
        camera,
        flash: Some(scene.rig.flash.clone()),
        radiometry: Some(RadiometryRecord::Absolute(sensor.radiometry)),
        noise: Some(sensor.noise),
        analyser_extinction_ratio: sensor.analyser_extinction_ratio,
        sensor_calibration: None,
    }
}

/// The boards a simulated capture of `scene` records, as tracking needs them.
pub fn boards_of_scene(scene: &Scene) -> Vec<TrackedBoard> {
    scene.boards.iter().map(TrackedBoard::from_placed).collect()
}
