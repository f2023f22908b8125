//! The poses every later stage takes (`ellipso mesh`, `fit`, `export`, the COLMAP import, the
//! bench and the demo): the session's recorded `pose` events, tracking first the complete
//! frames that have neither a pose nor a rejection.
//!
//! Contract: [`poses_of`] appends the new poses to the session's event log (whole lines, under
//! the log's lock, so one run tracks a session at a time and a second waits and takes the
//! first one's poses), reopens the session to read them back, and checks what every stage
//! that takes poses needs (a possible camera, possible poses). Its lines (the wait, the count
//! of frames to track) go through the caller's [`Say`]; it prints nothing itself.

use ellipso_run_error::{Context, RunError, Say};
use ellipso_session::reader::Session;
use nalgebra::Isometry3;

/// The session's recorded poses (`pose` events), tracking first every complete frame that has
/// neither a pose nor a rejection (none tracked yet, or a tracking run cut short).
pub fn poses_of(session: &Session, say: &dyn Say) -> Result<Vec<(u64, Isometry3<f64>)>, RunError> {
    let mut untracked = ellipso_vision::process::untracked_frames(session);
    let mut poses = session.poses().tracked();
    // one run tracks a session at a time; a second waits and takes the first one's poses
    let _lock = if untracked.is_empty() {
        None
    } else {
        let lock = ellipso_session::writer::LogLock::acquire(&session.dir, || {
            say.err(format_args!(
                "{}: another run is tracking this session's poses; waiting for it…",
                session.dir.display()
            ))
        })?;
        let now = ellipso_session::reader::open(&session.dir)?;
        untracked = ellipso_vision::process::untracked_frames(&now);
        poses = now.poses().tracked();
        lock
    };
    if !untracked.is_empty() {
        say.err(format_args!(
            "{} of {} complete frames have no pose yet: tracking their AprilTags first…",
            untracked.len(),
            session.frames.iter().filter(|f| f.complete).count()
        ));
        let tracked = ellipso_vision::process::track_frames(
            session,
            &ellipso_vision::track::TrackConfig::default(),
            |id| untracked.contains(&id),
        )?;
        ellipso_vision::process::append_poses(
            &session.dir,
            &tracked,
            ellipso_session::time::HostClock::new().now(),
        )
        .context(
            "recording the new poses failed part-way (every line written is whole; the next \
             fit tracks the frames still without one)",
        )?;
        poses = ellipso_session::reader::open(&session.dir)?
            .poses()
            .tracked();
    }
    ellipso_run_error::ensure!(
        !poses.is_empty(),
        "{}: no frame could be posed from the AprilTags",
        session.dir.display()
    );
    // what every stage that takes poses needs: a possible camera, possible poses
    ellipso_fit::inputs::check_camera(&ellipso_fit::observe::camera_of(session)?)?;
    ellipso_fit::inputs::check_poses(&poses)?;
    Ok(poses)
}
