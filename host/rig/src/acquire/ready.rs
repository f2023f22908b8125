//! A capture ready to run: the trigger link, the camera and the new session, with the plan that
//! joins them ([`ReadyCapture`]) — what `ellipso capture` assembles from the simulated rig
//! ([`super::sim_rig`]) or the physical one ([`super::hardware`]) before it records.
//!
//! Contract: a board timing the connected board would refuse is refused by [`check_plan`]
//! before the session is created; [`ReadyCapture::run`] records through
//! [`super::capture::capture`] and then closes the link and stops an in-process virtual board,
//! in that order. The stop flag and the progress display are the caller's (the binary's signal
//! handlers and progress bar, a [`Recorder`] for the libraries that capture); nothing here
//! prints: [`report_lines`] are the summary's lines for the caller to print.

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

use ellipso_protocol::CaptureConfig;
use ellipso_run_error::RunError;
use ellipso_session::writer::SessionWriter;
use ellipso_sim::rig::VirtualBoard;

use super::capture::{CaptureError, CapturePlan, CaptureProgress, CaptureReport, capture};
use super::pairing::PairingConfig;
use crate::camera::{Camera, CameraSettings};
use crate::link::TriggerLink;

/// Everything a capture needs, connected and checked; the session is created.
pub struct ReadyCapture {
    /// The trigger board's link (closed first after the capture).
    pub(crate) link: TriggerLink,
    /// The camera.
    pub(crate) camera: Box<dyn Camera>,
    /// The new session.
    pub(crate) session: SessionWriter,
    /// Board timing, camera settings, pairing and queues.
    pub(crate) plan: CapturePlan,
    /// Photos the board will take.
    pub(crate) photos: u32,
    /// The in-process virtual board, stopped after the link is closed.
    pub(crate) board: Option<VirtualBoard>,
}

impl ReadyCapture {
    /// Photos the board will take (the progress display's total).
    pub fn photos(&self) -> u32 {
        self.photos
    }

    /// Records the capture until it ends or `stop` is set; `progress` sees live figures. Returns
    /// the report and the session directory.
    pub fn run(
        self,
        stop: &AtomicBool,
        progress: impl FnMut(&CaptureProgress),
    ) -> Result<(CaptureReport, PathBuf), CaptureError> {
        let Self {
            link,
            camera,
            session,
            plan,
            photos: _,
            board,
        } = self;
        let result = capture(&link, camera, session, &plan, stop, progress);
        drop(link);
        if let Some(board) = board {
            board.shutdown();
        }
        result
    }
}

/// Refuses a board timing the connected board would refuse, before anything is recorded (the
/// board checks it again when configured).
pub fn check_plan(link: &TriggerLink, config: CaptureConfig) -> Result<(), RunError> {
    ellipso_firmware::CapturePlan::new(config, &link.board().limits).map_err(|reason| {
        RunError::msg(format!(
            "the trigger board would refuse this capture (exposure {} µs, interval {} µs): {}",
            config.exposure_us,
            config.frame_period_us,
            crate::link::describe_reject(&reason)
        ))
    })?;
    Ok(())
}

/// The capture plan for a board timing: 20 clock pings, a 150 ms transfer budget for pairing,
/// 16 frames of queue, 2 PNG writers, and a time limit of the capture's length plus 10 minutes.
pub fn capture_plan(board: CaptureConfig, camera: CameraSettings, photos: u32) -> CapturePlan {
    CapturePlan {
        board,
        camera,
        clock_sync_pings: 20,
        pairing: PairingConfig::for_capture(board.exposure_us, board.frame_period_us, 150_000),
        frame_queue: 16,
        writer_threads: 2,
        max_duration: Duration::from_secs(
            u64::from(photos) * u64::from(board.frame_period_us) / 1_000_000 + 600,
        ),
    }
}

/// A capture run to its end, or to a stop by signal.
#[derive(Debug)]
pub struct Recorded {
    /// What happened.
    pub report: CaptureReport,
    /// The session directory.
    pub dir: PathBuf,
    /// The signal (SIGINT, SIGTERM) that stopped the capture, if one did.
    pub signal: Option<i32>,
}

/// How a caller records a [`ReadyCapture`]: its stop flag (the binary's signal handlers) and
/// its progress display, around [`ReadyCapture::run`]. The libraries that capture on the
/// simulated rig (the demo, `ellipso bench mesh`) take one.
pub trait Recorder {
    /// Runs `ready` to its end (or a stop) and says how it went.
    fn record(&mut self, ready: ReadyCapture) -> Result<Recorded, RunError>;
}

/// The capture summary's lines, as `ellipso capture` and the demo print them.
pub fn report_lines(r: &CaptureReport) -> Vec<String> {
    let mut lines = vec![
        format!("capture      {} in {:.1} s", r.end_reason, r.duration_s),
        format!(
            "frames       {} written ({} flagged), {} pulses",
            r.frames, r.flagged, r.pulses
        ),
    ];
    let p = &r.pairing;
    lines.push(format!(
        "pairing      {} paired · {} frames without pulse · {} pulses without frame · {} duplicates",
        p.paired,
        p.frame_without_pulse,
        p.pulse_without_frame,
        p.duplicate_frames + p.duplicate_pulses
    ));
    lines.push(format!(
        "link         {} frames ok · {} bad frames dropped",
        r.link.frames_ok,
        r.link.bad_frames()
    ));
    if let Some(c) = &r.clock {
        lines.push(format!(
            "clock        drift {:+.1} ppm · residual rms {:.0} µs",
            c.drift_ppm(),
            c.rms_us
        ));
    }
    if r.paired_per_step.len() > 1 {
        let steps: Vec<String> = r.paired_per_step.iter().map(u64::to_string).collect();
        lines.push(format!(
            "bracket      paired frames per step {}",
            steps.join(" / ")
        ));
    }
    lines
}
