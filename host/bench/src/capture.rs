//! Captures with known truth for the benches: a scene's capture rendered straight into a
//! session, and the true pose of every frame of a session recorded from a scene.
//!
//! Contract:
//! - [`render_session`] writes the session `ellipso capture --sim` writes — the same manifest
//!   (simulator source naming the scene file, sensor layout, the rig record with camera model,
//!   flash, radiometry and noise, boards) and
//!   the same raw frames (the simulated camera renders frame k with the same renderer, options
//!   and noise seed, so its PNGs are byte-identical: `capture_frames_equal_direct_renders` in
//!   `tests/`) — without the trigger board, the pty and the real-time pacing, which cannot
//!   change a pixel. Frame k has frame id k, the scene's exposure and gain, and no pulse
//!   (relative flash energy 1: the full pulse).
//! - [`pose_index`] maps every frame of a session recorded from a scene to the index of its
//!   pose on the scene's capture path: through its pulse (pulse k fires pose k; the first pulse
//!   recorded is pose 0) when frames are paired, else frame id k ↔ pose k.
//! - [`true_poses`] are those poses (`world_from_camera`) by frame id: the tracker's truth.

use std::collections::BTreeMap;
use std::path::Path;

use ellipso_session::manifest::{Manifest, SensorInfo, SessionSource};
use ellipso_session::reader::Session;
use ellipso_session::time::HostTimeUs;
use ellipso_session::writer::{FrameRecord, SessionWriter};
use ellipso_sim::render::{RenderOptions, Renderer};
use ellipso_sim::scene::Scene;
use ellipso_vision::process::{boards_of_scene, rig_record_of_scene};
use nalgebra::Isometry3;

use crate::BenchError;

/// Renders `scene` (loaded from `scene_path`) with `options` into a new session at `dir`
/// (module doc); `progress(done, total)` after each frame.
pub fn render_session(
    scene_path: &Path,
    scene: &Scene,
    options: RenderOptions,
    dir: &Path,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(), BenchError> {
    let renderer = Renderer::new(scene, options).map_err(|e| BenchError::Render(e.to_string()))?;
    let camera = *renderer.camera();
    let scene_file =
        std::fs::canonicalize(scene_path).map_err(|e| BenchError::io(scene_path, e))?;
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
    let session = |e: ellipso_session::SessionError| BenchError::Session(e.to_string());
    let mut writer = SessionWriter::create(dir, manifest).map_err(session)?;
    let total = renderer.frame_count();
    for k in 0..total {
        let frame = renderer
            .render_frame(k)
            .map_err(|e| BenchError::Render(e.to_string()))?;
        writer
            .write_frame(FrameRecord {
                t_host_us: HostTimeUs(k as u64 * 1000),
                frame_id: k as u64,
                t_camera_ns: None,
                exposure_us: scene.rig.camera.exposure_us.round() as u32,
                gain_db: scene.rig.camera.gain_db as f32,
                width: frame.width,
                height: frame.height,
                pixels: &frame.raw(),
                flagged: None,
            })
            .map_err(session)?;
        progress(k + 1, total);
    }
    writer
        .finish(HostTimeUs(total as u64 * 1000), "completed")
        .map_err(session)?;
    Ok(())
}

/// Frame id → index of its pose on the scene's capture path (module doc).
pub fn pose_index(session: &Session) -> BTreeMap<u64, usize> {
    let first_seq = session.frames.iter().filter_map(|f| f.pulse_seq).min();
    session
        .frames
        .iter()
        .filter_map(|f| {
            let k = match (f.pulse_seq, first_seq) {
                (Some(s), Some(first)) => s - first,
                _ => f.frame_id,
            };
            usize::try_from(k).ok().map(|k| (f.frame_id, k))
        })
        .collect()
}

/// The scene's pose of every frame of `session` that has one, by frame id.
pub fn true_poses(session: &Session, scene: &Scene) -> Vec<(u64, Isometry3<f64>)> {
    pose_index(session)
        .into_iter()
        .filter_map(|(id, k)| scene.camera_poses.get(k).map(|p| (id, p.world_from_camera)))
        .collect()
}
