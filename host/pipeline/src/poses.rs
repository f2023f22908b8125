//! The poses every later stage takes (`ellipso mesh`, `fit`, `export`, the COLMAP import, the
//! bench and the demo): the session's recorded `pose` events, tracking first the complete
//! frames that have neither a pose nor a rejection, and those whose recorded outcome is stale.
//!
//! Contract: [`poses_of`] first checks that the frames are the session's own
//! ([`checked_frames`]: every file's checksum against its `frame` event, and a `sensor.layout`
//! of mono refused on frames that carry a colour pattern), then tracks what has no outcome or a
//! stale one (computed from other bytes or other board definitions,
//! `ellipso_session::provenance`), saying which and why. It appends the new poses to the
//! session's event log (whole lines, under the log's lock, so one run tracks a session at a time
//! and a second waits and takes the first one's poses), reopens the session to read them back,
//! and checks what every stage that takes poses needs (a possible camera, possible poses). Its
//! lines (the wait, the frames to track) go through the caller's [`Say`]; it prints nothing
//! itself.

use std::collections::BTreeSet;

use ellipso_run_error::{Context, RunError, Say};
use ellipso_session::provenance::{FrameCheck, Stale, stale_outcomes};
use ellipso_session::reader::Session;
use nalgebra::Isometry3;

/// Checks that `session`'s frames are its own (module contract): refuses a session whose files
/// were renamed or are not the ones recorded, naming them, and a mono `sensor.layout` on colour
/// frames; warns of single damaged or foreign files (every stage skips them); says on
/// `say` when the frames carry no checksum (an older session) and are not checked.
pub fn checked_frames(session: &Session, say: &dyn Say) -> Result<FrameCheck, RunError> {
    let check = session.check_frames();
    if let Some(refusal) = check.refusal(&session.dir) {
        ellipso_run_error::bail!("{refusal}");
    }
    if let Some(warning) = check.warning() {
        say.err(format_args!(
            "warning: {}: {warning}",
            session.dir.display()
        ));
    }
    if let Some(note) = check.note() {
        say.err(format_args!("note: {}: {note}", session.dir.display()));
    }
    if let Some(contradiction) = ellipso_vision::process::layout_contradiction(session) {
        ellipso_run_error::bail!("{contradiction}");
    }
    Ok(check)
}

/// The complete frames with no tracking outcome, and those whose outcome is stale.
fn to_track(session: &Session, check: &FrameCheck) -> (BTreeSet<u64>, Vec<(u64, Stale)>) {
    let untracked = ellipso_vision::process::untracked_frames(session);
    let stale = stale_outcomes(&session.poses(), check, &session.manifest.boards);
    (untracked, stale)
}

/// The stale frames grouped by why: `frames 0, 1, … (16 frames) (why); frame 4 (why)`.
pub fn stale_list(stale: &[(u64, Stale)]) -> String {
    let mut by_why: std::collections::BTreeMap<String, Vec<u64>> = Default::default();
    for (id, why) in stale {
        by_why.entry(why.to_string()).or_default().push(*id);
    }
    by_why
        .into_iter()
        .map(|(why, ids)| {
            let ids_s = ellipso_session::reader::id_list(&ids);
            if ids.len() == 1 {
                format!("frame {ids_s} ({why})")
            } else {
                format!("frames {ids_s} ({why})")
            }
        })
        .collect::<Vec<_>>()
        .join("; ")
}

/// The session's recorded poses (`pose` events), tracking first every complete frame that has
/// neither a pose nor a rejection (none tracked yet, or a tracking run cut short) or whose
/// outcome is stale (module contract).
pub fn poses_of(session: &Session, say: &dyn Say) -> Result<Vec<(u64, Isometry3<f64>)>, RunError> {
    let check = checked_frames(session, say)?;
    let (mut untracked, mut stale) = to_track(session, &check);
    let mut poses = session.poses().tracked();
    // one run tracks a session at a time; a second waits and takes the first one's poses
    let _lock = if untracked.is_empty() && stale.is_empty() {
        None
    } else {
        let lock = ellipso_session::writer::LogLock::acquire(&session.dir, || {
            say.err(format_args!(
                "{}: another run is tracking this session's poses; waiting for it…",
                session.dir.display()
            ))
        })?;
        let now = ellipso_session::reader::open(&session.dir)?;
        (untracked, stale) = to_track(&now, &check);
        poses = now.poses().tracked();
        lock
    };
    if !stale.is_empty() {
        say.err(format_args!(
            "{}: {} frames' recorded tracking is stale, tracking them again: {}",
            session.dir.display(),
            stale.len(),
            stale_list(&stale)
        ));
    }
    if !untracked.is_empty() {
        say.err(format_args!(
            "{} of {} complete frames have no pose yet: tracking their AprilTags first…",
            untracked.len(),
            session.frames.iter().filter(|f| f.complete).count()
        ));
    }
    let todo: BTreeSet<u64> = untracked
        .iter()
        .copied()
        .chain(stale.iter().map(|(id, _)| *id))
        .collect();
    if !todo.is_empty() {
        let tracked = ellipso_vision::process::track_frames(
            session,
            &ellipso_vision::track::TrackConfig::default(),
            |id| todo.contains(&id),
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
        // a frame that could not be read (a copy still in progress) is said, not only logged:
        // its rejection records the bytes it saw, so the next run tracks it again once they
        // change (`ellipso_session::provenance`)
        let unreadable: Vec<String> = tracked
            .iter()
            .filter_map(|t| match &t.result {
                Err(ellipso_vision::track::TrackRejection::Frame(why)) => {
                    Some(format!("frame {} ({why})", t.frame_id))
                }
                _ => None,
            })
            .collect();
        if !unreadable.is_empty() {
            say.err(format_args!(
                "warning: {} frames could not be read and are left out: {}; once their files \
                 are whole the next run tracks them again",
                unreadable.len(),
                unreadable.join(", ")
            ));
        }
        poses = ellipso_session::reader::open(&session.dir)?
            .poses()
            .tracked();
    }
    if poses.is_empty() {
        // the most frequent reason, so a wrong board in the manifest is named as such
        let now = ellipso_session::reader::open(&session.dir)?.poses();
        let mut reasons: std::collections::BTreeMap<&str, usize> = Default::default();
        for (_, why) in now.rejected() {
            *reasons.entry(why).or_default() += 1;
        }
        let top = reasons
            .iter()
            .max_by_key(|(_, n)| **n)
            .map(|(why, n)| format!(" ({n} frames: {why}; check the manifest's `boards`)"))
            .unwrap_or_default();
        ellipso_run_error::bail!(
            "{}: no frame could be posed from the AprilTags{top}",
            session.dir.display()
        );
    }
    // what every stage that takes poses needs: a possible camera, possible poses
    ellipso_fit::inputs::check_camera(&ellipso_fit::observe::camera_of(session)?)?;
    ellipso_fit::inputs::check_poses(&poses)?;
    Ok(poses)
}
