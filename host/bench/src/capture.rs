//! Captures with known truth for the benches: a scene's capture rendered straight into a
//! session, and the true pose of every frame of a session recorded from a scene.
//!
//! Contract:
//! - [`render_session`] writes the session `ellipso capture --sim` writes
//!   (`ellipso_sim::record::render_session`, whose contract it is), frame k with frame id k.
//! - [`pose_index`] maps every frame of a session recorded from a scene to the index of its
//!   pose on the scene's capture path: through its pulse (pulse k fires pose k; the first pulse
//!   recorded is pose 0) when frames are paired, else frame id k ↔ pose k.
//! - [`true_poses`] are those poses (`world_from_camera`) by frame id: the tracker's truth.

use std::collections::BTreeMap;
use std::path::Path;

use ellipso_session::reader::Session;
use ellipso_sim::record::RecordError;
use ellipso_sim::render::RenderOptions;
use ellipso_sim::scene::Scene;
use nalgebra::Isometry3;

use crate::BenchError;

/// Renders `scene` (loaded from `scene_path`) with `options` into a new session at `dir`
/// (module doc; `ellipso_sim::record::render_session`, frame ids from 0); `progress(done,
/// total)` after each frame.
pub fn render_session(
    scene_path: &Path,
    scene: &Scene,
    options: RenderOptions,
    dir: &Path,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(), BenchError> {
    ellipso_sim::record::render_session(scene_path, scene, options, dir, 0, progress).map_err(|e| {
        match e {
            RecordError::Io { path, source } => BenchError::io(&path, source),
            RecordError::Render(what) => BenchError::Render(what),
            RecordError::Session(e) => BenchError::Session(e.to_string()),
        }
    })
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
