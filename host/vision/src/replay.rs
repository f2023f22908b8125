//! The replay report of a recorded session (`replay.json` of `ellipso replay DIR`; also said
//! after `capture` and in the demo): what reading the session found (a crash leaves a truncated
//! log, frames without metadata…), the capture's own figures (frames, flagged, pairings and
//! pairing errors), and the stages after capture (pose tracking) run again.
//! Deterministic: the same session gives the same report.

use std::collections::BTreeMap;

use ellipso_run_error::RunError;

use crate::process::{self, TrackedFrame};
use crate::track::TrackConfig;
use ellipso_session::events::SessionEvent;
use ellipso_session::reader;

/// The replay report (`replay.json`).
#[derive(Debug, serde::Serialize)]
pub struct ReplayReport {
    /// Session directory as given.
    pub session: String,
    /// What reading found.
    pub read: String,
    /// Frames on disk.
    pub frames: usize,
    /// Frames delivered complete.
    pub complete: usize,
    /// Pulse events in the log.
    pub pulses: usize,
    /// Pairings in the log.
    pub paired: usize,
    /// Pairing errors in the log, by kind.
    pub pairing_errors: BTreeMap<String, usize>,
    /// Frames with a pose.
    pub posed: usize,
    /// Frames without a pose, by reason.
    pub pose_rejected: BTreeMap<String, usize>,
    /// Median reprojection RMS of posed frames, px.
    pub median_pose_rms_px: Option<f64>,
    /// Per frame: id and pose (camera position in the world, m) or the rejection reason.
    pub per_frame: Vec<FrameLine>,
}

impl ReplayReport {
    /// The human summary, line by line (`ellipso replay` and `ellipso capture` print it).
    pub fn summary_lines(&self) -> Vec<String> {
        let mut lines = vec![
            format!("session      {}", self.session),
            format!("read         {}", self.read),
            format!("frames       {} ({} complete)", self.frames, self.complete),
            format!("pulses       {}   paired {}", self.pulses, self.paired),
        ];
        for (k, n) in &self.pairing_errors {
            lines.push(format!("  {k:<22} {n}"));
        }
        lines.push(match self.median_pose_rms_px {
            Some(rms) => format!(
                "poses        {} of {} frames (median reprojection {rms:.3} px)",
                self.posed, self.complete
            ),
            None => format!("poses        {} of {} frames", self.posed, self.complete),
        });
        for (k, n) in &self.pose_rejected {
            lines.push(format!("  rejected: {k} ({n})"));
        }
        lines
    }
}

/// One frame of the report.
#[derive(Debug, serde::Serialize)]
pub struct FrameLine {
    /// Frame id.
    pub frame_id: u64,
    /// Camera centre in the world, m (posed frames).
    pub camera_position_m: Option<[f64; 3]>,
    /// Reprojection RMS, px.
    pub rms_px: Option<f64>,
    /// Why there is no pose.
    pub rejected: Option<String>,
}

/// Builds the report of a session (shared with `capture` and `demo`).
pub fn report(
    dir: &std::path::Path,
    tracked: Option<&[TrackedFrame]>,
) -> Result<ReplayReport, RunError> {
    let session = reader::open(dir)?;
    let mut pairing_errors = BTreeMap::new();
    let (mut pulses, mut paired) = (0, 0);
    for e in &session.events {
        match e {
            SessionEvent::Pulse { .. } => pulses += 1,
            SessionEvent::Pairing { .. } => paired += 1,
            SessionEvent::PairingError { kind, .. } => {
                *pairing_errors.entry(kind.clone()).or_insert(0) += 1
            }
            _ => {}
        }
    }
    let owned;
    let tracked = match tracked {
        Some(t) => t,
        None => {
            owned = process::track_session(&session, &TrackConfig::default())?;
            &owned
        }
    };
    let (posed, pose_rejected) = process::tally(tracked);
    let mut rms: Vec<f64> = tracked
        .iter()
        .filter_map(|t| t.result.as_ref().ok().map(|p| p.board_pose.rms_px))
        .collect();
    let per_frame = tracked
        .iter()
        .map(|t| match &t.result {
            Ok(p) => {
                let c = p.world_from_camera.translation.vector;
                FrameLine {
                    frame_id: t.frame_id,
                    camera_position_m: Some([c.x, c.y, c.z]),
                    rms_px: Some(p.board_pose.rms_px),
                    rejected: None,
                }
            }
            Err(r) => FrameLine {
                frame_id: t.frame_id,
                camera_position_m: None,
                rms_px: None,
                rejected: Some(r.to_string()),
            },
        })
        .collect();
    Ok(ReplayReport {
        session: dir.display().to_string(),
        read: session.report.summary(),
        frames: session.frames.len(),
        complete: session.frames.iter().filter(|f| f.complete).count(),
        pulses,
        paired,
        pairing_errors,
        posed,
        pose_rejected,
        median_pose_rms_px: (!rms.is_empty()).then(|| ellipso_model::stats::median(&mut rms)),
        per_frame,
    })
}
