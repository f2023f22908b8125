//! A capture recorded into a session and tracked: the simulated rig ([`sim`]) or the physical
//! rig of a rig file ([`hardware`]), recorded by the caller's [`Recorder`] (the binary's progress
//! bar and signal handlers, or a quiet one), then its poses tracked and appended to the session
//! ([`record_and_track`]).
//!
//! Also here: [`rig_file`], the rig file's format (trigger port, sensor backend, camera model,
//! capture, boards), and [`session_upgrade`], the rig record an older session lacks, from its
//! scene file (`ellipso session upgrade`).
//!
//! Why a crate of its own: `ellipso-rig` drives the link and the cameras and must not link the
//! AprilTag C library; `ellipso-vision` tracks poses and must not drive hardware, nor depend on
//! the simulator or the wire protocol (a fit tracks recorded frames through it). A capture needs both; this crate is where they meet, so
//! `ellipso capture`, the demo and `ellipso bench mesh` all capture through the same code.
//!
//! Contract: nothing here prints except through the caller's [`Say`] (the tracker's lines); a
//! capture stopped by a signal is complete up to the stop and is not tracked (the user wants the
//! process to end; `ellipso replay` tracks it later).

#![forbid(unsafe_code)]

use std::path::PathBuf;

use ellipso_rig::acquire::capture::CaptureReport;
use ellipso_rig::acquire::ready::{ReadyCapture, Recorded, Recorder};
use ellipso_run_error::{RunError, Say};
use ellipso_vision::process::{self, TrackedFrame};

pub mod bracket;
pub mod hardware;
pub mod rig_file;
pub mod session_upgrade;
pub mod sim;

/// A finished capture.
#[derive(Debug)]
pub struct Captured {
    /// What happened.
    pub report: CaptureReport,
    /// The session directory.
    pub dir: PathBuf,
    /// Poses tracked after recording (none when not asked for or stopped by a signal).
    pub tracked: Option<Vec<TrackedFrame>>,
    /// The signal (SIGINT, SIGTERM) that stopped the capture, if one did.
    pub signal: Option<i32>,
}

/// Records `ready` with `recorder`, then tracks the session's poses and appends them
/// ([`process::track_and_append`]) when `track` holds and no signal stopped the capture.
pub fn record_and_track(
    ready: ReadyCapture,
    track: bool,
    recorder: &mut dyn Recorder,
    say: &dyn Say,
) -> Result<Captured, RunError> {
    let Recorded {
        report,
        dir,
        signal,
    } = recorder.record(ready)?;
    let tracked = if track && signal.is_none() {
        Some(process::track_and_append(&dir, say)?)
    } else {
        None
    };
    Ok(Captured {
        report,
        dir,
        tracked,
        signal,
    })
}
