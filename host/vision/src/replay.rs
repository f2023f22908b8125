//! `ellipso replay DIR`: a recorded session through the same stages as a live capture.
//!
//! Prints what reading the session found (a crash leaves a truncated log, frames without
//! metadata…), the capture's own figures (frames, flagged, pairings and pairing errors, link
//! losses), then runs the stages after capture (pose tracking) and writes `replay.json` in
//! `--out` (default: `DIR/replay`). Deterministic: replaying twice writes identical files.

use std::collections::BTreeMap;
use std::path::PathBuf;

use anyhow::Context;

use ellipso_session::events::SessionEvent;
use ellipso_session::reader;
use ellipso_vision::process::{self, TrackedFrame};
use ellipso_vision::track::TrackConfig;

/// Arguments of `ellipso replay`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Session directory.
    pub session: PathBuf,
    /// Where to write the replay report (default: SESSION/replay).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

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
) -> anyhow::Result<ReplayReport> {
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
    rms.sort_by(f64::total_cmp);
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
        median_pose_rms_px: rms.get(rms.len() / 2).copied(),
        per_frame,
    })
}

/// Prints the human summary of a report.
pub fn print_summary(r: &ReplayReport) {
    crate::outln!("session      {}", r.session);
    crate::outln!("read         {}", r.read);
    crate::outln!("frames       {} ({} complete)", r.frames, r.complete);
    crate::outln!("pulses       {}   paired {}", r.pulses, r.paired);
    for (k, n) in &r.pairing_errors {
        crate::outln!("  {k:<22} {n}");
    }
    match r.median_pose_rms_px {
        Some(rms) => crate::outln!(
            "poses        {} of {} frames (median reprojection {rms:.3} px)",
            r.posed,
            r.complete
        ),
        None => crate::outln!("poses        {} of {} frames", r.posed, r.complete),
    }
    for (k, n) in &r.pose_rejected {
        crate::outln!("  rejected: {k} ({n})");
    }
}

/// Runs `ellipso replay`.
pub fn run(args: Args) -> anyhow::Result<()> {
    // a path that is no session is said as such first (opening reads only its manifest and log)
    ellipso_session::reader::open(&args.session)?;
    // the session's own `replay/` by default (docs/session-format.md, "Derived outputs")
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| args.session.join("replay"));
    let claimed = ellipso_report::output::OutputDir::claim_in_session(
        &out,
        "replay",
        &[&args.session],
        Some("replay"),
    )?;
    let r = report(&args.session, None)?;
    print_summary(&r);
    let path = claimed.path().join("replay.json");
    ellipso_report::atomic_file::write(&path, serde_json::to_vec_pretty(&r)?)
        .with_context(|| format!("writing {}", claimed.published(&path).display()))?;
    let published = claimed.commit()?;
    crate::outln!("report       {}", published.join("replay.json").display());
    Ok(())
}
