//! `ellipso-session`: the on-disk session — the typed contract between capture and every later
//! stage, as `ellipso-protocol` is the wire contract between board and host. A session is the record
//! of one capture, written while capturing and replayed later.
//! Format v1 (`docs/session-format.md` is the specification):
//! ```text
//! SESSION/
//!   manifest.json      what was captured with what (rig, sensor, boards, software, schema version)
//!   events.jsonl       append-only log, one JSON object per line (pulses, frames, pairings, faults, poses)
//!   frames/00000042.png  raw mosaic frames, 16-bit grayscale PNG, named by 64-bit frame id
//! ```
//!
//! Contract:
//! - Crash safety: a frame's PNG is written to a temporary name and renamed into place before its
//!   `frame` event is appended; every event is one `write` of a whole line. A capture killed with
//!   SIGKILL therefore leaves every frame written before the kill readable, and at worst one
//!   truncated last line, which [`reader::open`] tolerates and reports.
//! - Nothing already recorded is lost to bad input: a corrupt line in the middle of the log is
//!   skipped and reported with its line number; the rest of the session stays usable.
//! - Versioning: [`SCHEMA_VERSION`] changes only on incompatible change; additive fields are
//!   `#[serde(default)]` and unknown event types are kept as [`events::SessionEvent::Unknown`].

pub mod calibration_captures;
mod checksum;
pub mod events;
pub mod frame_png;
pub mod link_counters;
pub mod manifest;
pub mod poses;
pub mod provenance;
pub mod reader;
pub mod rig;
pub mod rig_ranges;
pub mod time;
pub mod writer;

#[cfg(test)]
mod test_fixture;

pub use events::SessionEvent;
pub use manifest::Manifest;
pub use poses::SessionPoses;
pub use reader::{FrameEntry, ReadReport, Session};
pub use writer::SessionWriter;

/// Schema version of sessions this build writes and reads.
pub const SCHEMA_VERSION: u32 = 1;

/// File names inside a session directory.
pub mod paths {
    /// The manifest.
    pub const MANIFEST: &str = "manifest.json";
    /// The manifest as it was before `ellipso session upgrade` rewrote it.
    pub const MANIFEST_BACKUP: &str = "manifest.json.pre-upgrade";
    /// The event log.
    pub const EVENTS: &str = "events.jsonl";
    /// The frames directory.
    pub const FRAMES: &str = "frames";

    /// File name of a frame inside [`FRAMES`].
    pub fn frame_file(frame_id: u64) -> String {
        format!("{frame_id:08}.png")
    }

    /// Subdirectories of a session that later stages may write into, each owned by one command
    /// (`docs/session-format.md`, "Derived outputs"): nothing else inside a session is ever
    /// written after its capture, except the poses appended to the log.
    pub const DERIVED: [(&str, &str); 2] = [("replay", "replay"), ("calibration", "calibrate")];

    /// The recorded session `path` lies in (or is), if any: the nearest directory at or above
    /// `path` that holds a [`MANIFEST`] file beside an [`EVENTS`] log or a [`FRAMES`] directory.
    /// `path` should be absolute (a relative one is looked at only as far as it goes).
    pub fn enclosing_session(path: &std::path::Path) -> Option<std::path::PathBuf> {
        path.ancestors()
            .find(|dir| {
                dir.join(MANIFEST).is_file()
                    && (dir.join(EVENTS).exists() || dir.join(FRAMES).is_dir())
            })
            .map(std::path::Path::to_path_buf)
    }
}

/// Errors reading or writing a session; each names the file and what is wrong.
#[derive(Debug, thiserror::Error)]
pub enum SessionError {
    /// A filesystem operation failed.
    #[error("{path}: {error}")]
    Io {
        /// The file or directory.
        path: std::path::PathBuf,
        /// The OS error.
        error: std::io::Error,
    },
    /// The manifest does not parse.
    #[error("{path}:{line}:{column}: bad manifest: {message}")]
    BadManifest {
        /// The manifest file.
        path: std::path::PathBuf,
        /// Line, from 1.
        line: usize,
        /// Column, from 1.
        column: usize,
        /// What serde said.
        message: String,
    },
    /// A manifest field holds an impossible value.
    #[error("{path}: `{field}`: {what}")]
    InvalidManifest {
        /// The manifest file.
        path: std::path::PathBuf,
        /// The field, e.g. `sensor.bit_depth`.
        field: &'static str,
        /// What is wrong.
        what: String,
    },
    /// The session was written by a newer, incompatible schema.
    #[error(
        "{path}: session schema v{found} is not supported by this ellipso (reads v{supported})"
    )]
    UnsupportedVersion {
        /// The manifest file.
        path: std::path::PathBuf,
        /// Version found.
        found: u32,
        /// Version supported.
        supported: u32,
    },
    /// A frame file is not a valid raw mosaic PNG.
    #[error("{path}: {reason}")]
    BadFrame {
        /// The frame file.
        path: std::path::PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// The directory already holds a session.
    #[error("{path}: already holds a session; choose a new directory")]
    AlreadyExists {
        /// The directory.
        path: std::path::PathBuf,
    },
    /// The directory is not a fresh one: a new session is never written among other files
    /// (an older recording's `frames/` or `events.jsonl` above all).
    #[error(
        "{path}: {what}; a capture writes only into a new or empty directory, never over \
         another recording — choose a new --out"
    )]
    NotFresh {
        /// The directory.
        path: std::path::PathBuf,
        /// What is there.
        what: String,
    },
}

impl SessionError {
    pub(crate) fn io(path: impl Into<std::path::PathBuf>) -> impl FnOnce(std::io::Error) -> Self {
        let path = path.into();
        move |error| Self::Io { path, error }
    }
}
