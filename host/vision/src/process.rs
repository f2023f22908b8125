//! The stages after capture, run on a recorded session (live capture and replay alike).
//!
//! Contract: the same session gives the same results, frame by frame, on any thread count —
//! frames are processed independently (one [`Tracker`] per worker) and results are ordered by
//! frame id. Nothing here changes recorded frames; results are appended to the session log as
//! `pose` / `pose_rejected` events (by [`append_poses`]) or returned for a report.

use std::collections::BTreeMap;
use std::path::Path;

use ellipso_model::camera::CameraModel;
use ellipso_run_error::{RunError, Say};
use rayon::prelude::*;

use crate::track::{TrackConfig, TrackRejection, TrackedBoard, Tracker};
use ellipso_polar::frame::RawFrame;
use ellipso_session::events::{SessionEvent, TrackedFrom};
use ellipso_session::reader::Session;
use ellipso_session::time::HostTimeUs;
use ellipso_session::writer::SessionAppender;

pub use crate::tracked::{ProcessError, TrackedFrame};
pub use ellipso_session::rig::RigRecord;

fn manifest_error(session: &Session, what: String) -> ProcessError {
    let path = session
        .dir
        .join(ellipso_session::paths::MANIFEST)
        .display()
        .to_string();
    ProcessError::Manifest { path, what }
}

/// The AprilTag boards recorded in a session's manifest (at least one).
pub fn boards_of(session: &Session) -> Result<Vec<TrackedBoard>, ProcessError> {
    let boards = session.manifest.boards.clone();
    if boards.is_empty() {
        return Err(manifest_error(
            session,
            "no AprilTag boards recorded: poses cannot be tracked".into(),
        ));
    }
    Ok(boards)
}

/// The camera model and boards recorded in a session's manifest.
pub fn rig_of(session: &Session) -> Result<(CameraModel, Vec<TrackedBoard>), ProcessError> {
    let rig =
        session.manifest.rig.as_ref().ok_or_else(|| {
            manifest_error(session, "`rig` is not recorded: no camera model".into())
        })?;
    Ok((rig.camera, boards_of(session)?))
}

/// Tracks every complete frame of `session`, in parallel, ordered by frame id.
pub fn track_session(
    session: &Session,
    config: &TrackConfig,
) -> Result<Vec<TrackedFrame>, ProcessError> {
    track_frames(session, config, |_| true)
}

/// Complete frames of `session` with neither a `pose` nor a `pose_rejected` event: frames a
/// tracking run never reached (it was stopped, or its appends failed on a full disk).
pub fn untracked_frames(session: &Session) -> std::collections::BTreeSet<u64> {
    let poses = session.poses();
    session
        .frames
        .iter()
        .filter(|f| f.complete && !poses.has_outcome(f.frame_id))
        .map(|f| f.frame_id)
        .collect()
}

/// Tracks the complete frames of `session` for which `select(frame_id)` holds, in parallel,
/// ordered by frame id.
pub fn track_frames(
    session: &Session,
    config: &TrackConfig,
    select: impl Fn(u64) -> bool,
) -> Result<Vec<TrackedFrame>, ProcessError> {
    let (camera, boards) = rig_of(session)?;
    let boards_crc64 = Some(ellipso_session::provenance::boards_crc64(&boards));
    let layout = session.manifest.sensor.layout;
    let bit_depth = session.manifest.sensor.bit_depth;
    let frames: Vec<_> = session
        .frames
        .iter()
        .filter(|f| f.complete && select(f.frame_id))
        .collect();
    let results = frames
        .par_iter()
        .map_init(
            || Tracker::new(camera, boards.clone(), config.clone()),
            |tracker, entry| {
                // one read and one hash of the file: the checksum of the bytes tracked
                let (frame_crc64, result) = match tracker {
                    Err(e) => (
                        ellipso_session::provenance::file_crc64(&entry.path).ok(),
                        Err(TrackRejection::Frame(e.to_string())),
                    ),
                    Ok(tracker) => {
                        let (crc64, loaded) = session.load_frame_and_crc64(entry);
                        let result = loaded
                            .map_err(|e| TrackRejection::Frame(e.to_string()))
                            .and_then(|(w, h, px)| {
                                RawFrame::new(w, h, bit_depth, layout, px)
                                    .map_err(|e| TrackRejection::Frame(e.to_string()))
                            })
                            .and_then(|raw| tracker.track(&raw));
                        (crc64, result)
                    }
                };
                TrackedFrame {
                    frame_id: entry.frame_id,
                    result,
                    from: TrackedFrom {
                        frame_crc64,
                        boards_crc64,
                    },
                }
            },
        )
        .collect();
    Ok(results)
}

/// Tracks every complete frame of the recorded session in `dir` and appends the poses to its
/// log (`ellipso capture` after recording, the demo, `bench mesh`); short-pulse frames of a
/// bracketed capture that tracking refused borrow a pose from their tracked neighbours
/// ([`crate::short_pulse_poses`]), logged as `pose_interpolated`, and their count is said on
/// `say`'s output. Returns what tracking found, frame by frame.
pub fn track_and_append(dir: &Path, say: &dyn Say) -> Result<Vec<TrackedFrame>, RunError> {
    let session = ellipso_session::reader::open(dir)?;
    let tracked = track_session(&session, &TrackConfig::default())?;
    let now = ellipso_session::time::HostClock::new().now();
    append_poses(dir, &tracked, now)?;
    let borrowed = crate::short_pulse_poses::borrow_short_pulse_poses(&session, &tracked);
    crate::short_pulse_poses::append_borrowed_poses(dir, &borrowed, now)?;
    if !borrowed.is_empty() {
        say.out(format_args!(
            "poses        {} short-pulse frames posed from their tracked neighbours",
            borrowed.len()
        ));
    }
    Ok(tracked)
}

/// Appends `pose` / `pose_rejected` events for `tracked` to the session's log, one whole line
/// per frame (a failed append leaves no partial line; frames not reached are found again by
/// [`untracked_frames`]).
pub fn append_poses(
    dir: &Path,
    tracked: &[TrackedFrame],
    t_host_us: HostTimeUs,
) -> Result<(), ProcessError> {
    let mut log = SessionAppender::open(dir)?;
    for t in tracked {
        let event = match &t.result {
            Ok(p) => {
                let camera_from_world = p.world_from_camera.inverse();
                let r = camera_from_world.rotation.scaled_axis();
                let tr = camera_from_world.translation.vector;
                SessionEvent::Pose {
                    t_host_us,
                    frame_id: t.frame_id,
                    rotation_camera_from_world: [r.x, r.y, r.z],
                    translation_camera_from_world_m: [tr.x, tr.y, tr.z],
                    rms_px: p.board_pose.rms_px,
                    tags: p.board_pose.tag_count as u32,
                    from: t.from,
                }
            }
            Err(reason) => SessionEvent::PoseRejected {
                t_host_us,
                frame_id: t.frame_id,
                reason: reason.to_string(),
                from: t.from,
            },
        };
        log.log(&event)?;
    }
    Ok(())
}

/// Counts of tracking outcomes: posed, and rejections by reason.
pub fn tally(tracked: &[TrackedFrame]) -> (usize, BTreeMap<String, usize>) {
    let mut rejected = BTreeMap::new();
    let mut posed = 0;
    for t in tracked {
        match &t.result {
            Ok(_) => posed += 1,
            Err(r) => *rejected.entry(r.to_string()).or_insert(0) += 1,
        }
    }
    (posed, rejected)
}

/// How many complete frames [`layout_contradiction`] examines: the first, the middle and the
/// last, so a colour object seen in part of an orbit is still found (each costs one decode).
const LAYOUT_FRAMES: usize = 3;

/// The error for a manifest whose `sensor.layout` is monochrome while its frames' pixels carry
/// a colour filter pattern (`ellipso_polar::layout::detect`, the detection `ellipso polar`
/// uses), naming the frame; `None` when no examined frame contradicts it. A colour layout on
/// frames that read as mono is no contradiction (a grey scene under balanced colour filters
/// reads as mono and is processed correctly either way, `ellipso_polar::layout`).
pub fn layout_contradiction(session: &Session) -> Option<String> {
    use ellipso_model::mosaic::SensorLayout;
    use ellipso_polar::layout::{Detection, detect};
    if session.manifest.sensor.layout != SensorLayout::MonoPolar {
        return None;
    }
    let complete: Vec<_> = session.frames.iter().filter(|f| f.complete).collect();
    let n = complete.len();
    let m = LAYOUT_FRAMES.min(n);
    let picks: std::collections::BTreeSet<usize> = (0..m)
        .map(|k| k * n.saturating_sub(1) / (m - 1).max(1))
        .collect();
    for entry in picks.into_iter().map(|k| complete[k]) {
        let Ok((w, h, px)) = session.load_frame(entry) else {
            continue;
        };
        let e = detect(w as usize, h as usize, &px);
        if e.detection == Detection::Colour {
            return Some(format!(
                "{}: `sensor.layout` is mono_polar, but frame {}'s pixels carry a colour filter \
                 pattern (red/blue blocks differ from green by {:.2} of the mean, the two greens \
                 by {:.3}, over {} flat tiles): set `sensor.layout` to colour_polar",
                session.dir.join(ellipso_session::paths::MANIFEST).display(),
                entry.frame_id,
                e.rg.max(e.rg_upper),
                e.gg,
                e.tiles
            ));
        }
    }
    None
}
