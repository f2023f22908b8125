//! What tracking a session gives, shared by the processing stages ([`crate::process`]) and the
//! short-pulse pose borrowing that follows them ([`crate::short_pulse_poses`]): one frame's
//! result ([`TrackedFrame`]) and the stages' error ([`ProcessError`]).

use ellipso_session::SessionError;
use ellipso_session::events::TrackedFrom;

use crate::track::{FramePose, TrackRejection};

/// Errors of the processing stages.
#[derive(Debug, thiserror::Error)]
pub enum ProcessError {
    /// The session's manifest lacks what a stage needs.
    #[error("{path}: {what}")]
    Manifest {
        /// The manifest.
        path: String,
        /// What is missing or wrong.
        what: String,
    },
    /// Reading or appending to the session failed.
    #[error(transparent)]
    Session(#[from] SessionError),
}

/// One frame's tracking result.
#[derive(Debug, Clone)]
pub struct TrackedFrame {
    /// Frame id.
    pub frame_id: u64,
    /// Pose or rejection.
    pub result: Result<FramePose, TrackRejection>,
    /// What it was computed from: the checksum of the frame file's bytes read, and of the
    /// boards (`ellipso_session::provenance`).
    pub from: TrackedFrom,
}
