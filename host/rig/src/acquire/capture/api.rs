//! What a capture takes and gives: the [`CapturePlan`] (board timing, camera settings, clock
//! pings, pairing windows, queue and writer sizes, hard stop), the live [`CaptureProgress`], the
//! closing [`CaptureReport`], and the [`CaptureError`] for a capture that could not run.
//!
//! Contract: a [`CaptureError`] means the capture never ran (the board or camera failed before
//! the start, the session could not be written, the clock did not settle); problems during a
//! running capture end it cleanly instead and are told by the report's `end_reason`.

use std::time::Duration;

use ellipso_protocol::CaptureConfig;

use super::super::pairing::{PairingConfig, PairingCounts};
use crate::camera::{CameraCounters, CameraError, CameraSettings};
use crate::link::clock::ClockFit;
use crate::link::{LinkCounters, LinkError};
use ellipso_session::SessionError;

/// What to capture and how.
#[derive(Debug, Clone)]
pub struct CapturePlan {
    /// Timing sent to the trigger board.
    pub board: CaptureConfig,
    /// Camera settings.
    pub camera: CameraSettings,
    /// Pings for the clock model before starting.
    pub clock_sync_pings: usize,
    /// Pairing windows.
    pub pairing: PairingConfig,
    /// Frames that may wait between camera and disk.
    pub frame_queue: usize,
    /// PNG encoder threads.
    pub writer_threads: usize,
    /// Hard stop.
    pub max_duration: Duration,
}

/// Live figures for a progress display.
#[derive(Debug, Clone, Copy, Default)]
pub struct CaptureProgress {
    /// Pulses the board reported.
    pub pulses: u64,
    /// Frames written.
    pub frames: u64,
    /// Pulses expected (counted captures).
    pub expected: Option<u64>,
    /// Frames paired.
    pub paired: u64,
    /// Pairing errors of any kind.
    pub pairing_errors: u64,
    /// Frames the camera lost or flagged (underruns + missing packets + other).
    pub camera_drops: u64,
    /// Frames written per second since start.
    pub fps: f64,
}

/// What happened, for the summary and the closing figures.
#[derive(Debug, Clone, serde::Serialize)]
pub struct CaptureReport {
    /// Why it ended.
    pub end_reason: String,
    /// Wall time, s.
    pub duration_s: f64,
    /// Pulses reported by the board.
    pub pulses: u64,
    /// Frames written.
    pub frames: u64,
    /// Frames delivered flagged (kept, never fitted).
    pub flagged: u64,
    /// Pairing outcome counts.
    pub pairing: PairingCounts,
    /// Trigger-link counters.
    pub link: LinkCounters,
    /// Camera counters.
    pub camera: CameraCounters,
    /// Faults the board reported.
    pub board_faults: u64,
    /// Clock fit used for pairing.
    pub clock: Option<ClockFit>,
    /// Paired frames per bracket step (one entry without a bracket).
    pub paired_per_step: Vec<u64>,
}

/// Why a capture could not run (problems during a running capture end it cleanly instead).
#[derive(Debug, thiserror::Error)]
pub enum CaptureError {
    /// The trigger board refused or failed a command before the capture started.
    #[error(transparent)]
    Link(#[from] LinkError),
    /// The camera failed before the capture started.
    #[error(transparent)]
    Camera(#[from] CameraError),
    /// The session could not be written.
    #[error(transparent)]
    Session(#[from] SessionError),
    /// The clock model did not settle.
    #[error("the trigger board's clock did not settle after up to {pings} pings; check the link")]
    ClockNotSettled {
        /// Pings sent.
        pings: usize,
    },
}
