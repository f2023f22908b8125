//! A session proves its frames are its own, and its poses computed from them.
//!
//! - Each `frame` event records the CRC-64/XZ of its PNG's bytes as written (`crc64`).
//!   [`Session::check_frames`] reads every complete frame's file again and compares: a file whose
//!   bytes are not the ones its event recorded (frames from another capture, files renamed one id
//!   off, an `events.jsonl` from another capture, a copy still in progress) is a
//!   [`FrameMismatch`], named by frame, with the frame whose recorded checksum the file holds
//!   when there is one (a rename). A session whose files were renamed, or none of whose files
//!   is the one recorded, is inconsistent ([`FrameCheck::refusal`]); single damaged or foreign
//!   files are skipped by every stage (`Session::load_frame` refuses them) and said
//!   ([`FrameCheck::warning`]).
//! - Each `pose` / `pose_rejected` records what it was computed from ([`TrackedFrom`]): the
//!   checksum of the bytes tracking read and of the manifest's board definitions. An outcome
//!   whose frame checksum is not the frame's (the recorded one, else the file's now), or whose
//!   boards are not the manifest's now, is **stale** ([`stale_outcomes`]): the frame is tracked again (pose events shuffled
//!   between frames, a frame restored after a failed read, a board definition fixed).
//! - Sessions recorded before frames and outcomes carried checksums read as before: their frames
//!   are listed as unchecked ([`FrameCheck::unrecorded`]), never refused, and an outcome without
//!   a [`TrackedFrom`] is taken as it is.

use std::collections::BTreeMap;
use std::path::Path;

use crate::SessionError;
pub use crate::checksum::crc64;
use crate::events::{SessionEvent, TrackedFrom};
use crate::poses::SessionPoses;
use crate::reader::Session;
use crate::rig::TrackedBoard;

/// CRC-64/XZ of a frame file's bytes (a regular file of a frame's size at most), as
/// [`crate::frame_png::read_hashed`] computes it for every frame read.
pub fn file_crc64(path: &Path) -> Result<u64, SessionError> {
    crate::frame_png::read_hashed(path).map(|(_, crc64)| crc64)
}

/// The identity of a set of board definitions: CRC-64/XZ of their JSON as the manifest records
/// them (field order fixed, tags sorted by id), so any changed corner, placement or family
/// changes it.
pub fn boards_crc64(boards: &[TrackedBoard]) -> u64 {
    crc64(&serde_json::to_vec(boards).unwrap_or_default())
}

/// A complete frame whose file is not the one its `frame` event recorded.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FrameMismatch {
    /// The frame.
    pub frame_id: u64,
    /// The frame whose recorded checksum its file holds (a file renamed to another id).
    pub holds_frame: Option<u64>,
    /// The file cannot be read (why).
    pub unreadable: Option<String>,
}

/// What [`Session::check_frames`] found.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FrameCheck {
    /// Each complete frame's file checksum now (`None`: it cannot be read).
    pub current: BTreeMap<u64, Option<u64>>,
    /// Each complete frame's bytes as the session knows them: the checksum its `frame` event
    /// recorded, else its file's now. What a tracking outcome must have been computed from.
    pub expected: BTreeMap<u64, Option<u64>>,
    /// Complete frames whose `frame` event has no checksum (recorded before frames carried one,
    /// or a frame without an event): not checked.
    pub unrecorded: Vec<u64>,
    /// Complete frames whose file is not the one recorded.
    pub mismatched: Vec<FrameMismatch>,
}

impl FrameCheck {
    /// Whether the mismatches say the session's parts do not belong together: a file holds
    /// another frame's recorded bytes (files renamed), or no frame's file is the one recorded
    /// (frames, or the log, from another capture). Otherwise the mismatched frames are single
    /// damaged or foreign files, which every stage skips (`Session::load_frame` refuses them).
    pub fn inconsistent(&self) -> bool {
        !self.mismatched.is_empty()
            && (self.mismatched.iter().any(|m| m.holds_frame.is_some())
                || self.mismatched.len() == self.current.len())
    }

    /// The error naming every mismatched frame, when the session is [`Self::inconsistent`].
    pub fn refusal(&self, dir: &Path) -> Option<String> {
        if !self.inconsistent() {
            return None;
        }
        let named: Vec<String> = self
            .mismatched
            .iter()
            .take(10)
            .map(|m| match (m.holds_frame, &m.unreadable) {
                (_, Some(why)) => format!("frame {} (cannot be read: {why})", m.frame_id),
                (Some(other), None) => format!(
                    "frame {} (its file holds frame {other}'s pixels: renamed?)",
                    m.frame_id
                ),
                (None, None) => format!("frame {}", m.frame_id),
            })
            .collect();
        let more = if self.mismatched.len() > 10 {
            format!(" and {} more", self.mismatched.len() - 10)
        } else {
            String::new()
        };
        let whole = if self.mismatched.len() == self.current.len() {
            "; none matches: the frames and events.jsonl come from different captures"
        } else {
            ""
        };
        Some(format!(
            "{}: {} of {} frames are not the ones this session recorded (their files' checksums \
             differ from their `frame` events'): {}{more}{whole}. Restore this capture's frames \
             (a copy still in progress?), or remove the foreign files from frames/ to go on \
             without them",
            dir.display(),
            self.mismatched.len(),
            self.current.len(),
            named.join(", ")
        ))
    }

    /// The warning naming mismatched frames of a session that is not [`Self::inconsistent`]:
    /// they are skipped.
    pub fn warning(&self) -> Option<String> {
        if self.mismatched.is_empty() || self.inconsistent() {
            return None;
        }
        let ids: Vec<u64> = self.mismatched.iter().map(|m| m.frame_id).collect();
        Some(format!(
            "{} of {} frames are not the ones this session recorded (damaged, or another \
             capture's: their checksums differ from their `frame` events'): {}; they are skipped",
            ids.len(),
            self.current.len(),
            crate::reader::id_list(&ids)
        ))
    }

    /// A note for a session whose frames carry no checksum (an older session), if any.
    pub fn note(&self) -> Option<String> {
        (!self.unrecorded.is_empty()).then(|| {
            format!(
                "{} of {} frames carry no checksum (recorded before sessions did): that they \
                 are this capture's frames is not checked",
                self.unrecorded.len(),
                self.current.len()
            )
        })
    }
}

impl Session {
    /// Reads every complete frame's file and compares it with the checksum its `frame` event
    /// recorded (module contract).
    pub fn check_frames(&self) -> FrameCheck {
        // every frame event's, its file present or not (a file renamed to another id)
        let recorded: BTreeMap<u64, u64> = self
            .events
            .iter()
            .filter_map(|e| match e {
                SessionEvent::Frame {
                    crc64: Some(c),
                    frame_id,
                    ..
                } => Some((*frame_id, *c)),
                _ => None,
            })
            .rev()
            .collect();
        let by_checksum: BTreeMap<u64, u64> = recorded.iter().map(|(&id, &c)| (c, id)).collect();
        let mut check = FrameCheck::default();
        for f in self.frames.iter().filter(|f| f.complete) {
            let now = file_crc64(&f.path);
            check.current.insert(f.frame_id, now.as_ref().ok().copied());
            check.expected.insert(
                f.frame_id,
                recorded
                    .get(&f.frame_id)
                    .copied()
                    .or(now.as_ref().ok().copied()),
            );
            let Some(&want) = recorded.get(&f.frame_id) else {
                check.unrecorded.push(f.frame_id);
                continue;
            };
            match now {
                Ok(c) if c == want => {}
                Ok(c) => check.mismatched.push(FrameMismatch {
                    frame_id: f.frame_id,
                    holds_frame: by_checksum.get(&c).copied(),
                    unreadable: None,
                }),
                Err(e) => check.mismatched.push(FrameMismatch {
                    frame_id: f.frame_id,
                    holds_frame: None,
                    unreadable: Some(e.to_string()),
                }),
            }
        }
        check
    }
}

/// Why a tracking outcome is stale.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stale {
    /// It was computed with other board definitions than the manifest's now.
    BoardsChanged,
    /// It was computed from other bytes than the frame's file holds now: those of frame
    /// `from_frame` (shuffled pose events), or of no frame of the session (`None`: a file read
    /// while it was incomplete or unreadable).
    FrameChanged {
        /// The frame whose bytes it was computed from, when it is one of the session's.
        from_frame: Option<u64>,
    },
}

impl std::fmt::Display for Stale {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::BoardsChanged => write!(f, "tracked with other board definitions"),
            Self::FrameChanged {
                from_frame: Some(other),
            } => write!(f, "its pose event was computed from frame {other}'s pixels"),
            Self::FrameChanged { from_frame: None } => {
                write!(f, "tracked from other bytes than its file holds now")
            }
        }
    }
}

/// The complete frames whose tracking outcome is stale (module contract), by frame id, given
/// the frames' bytes as the session knows them (`check.expected`: recorded, else the file's now)
/// and the manifest's boards now.
pub fn stale_outcomes(
    poses: &SessionPoses,
    check: &FrameCheck,
    boards: &[TrackedBoard],
) -> Vec<(u64, Stale)> {
    let boards_now = boards_crc64(boards);
    let by_checksum: BTreeMap<u64, u64> = check
        .expected
        .iter()
        .filter_map(|(&id, c)| c.map(|c| (c, id)))
        .collect();
    let mut stale = Vec::new();
    // against the recorded bytes: a frame whose file is damaged since keeps the outcome of its
    // recorded bytes (its loader skips the file)
    for (&id, now) in &check.expected {
        let Some(TrackedFrom {
            frame_crc64,
            boards_crc64,
        }) = poses.tracked_from(id)
        else {
            continue;
        };
        if boards_crc64.is_some_and(|b| b != boards_now) {
            stale.push((id, Stale::BoardsChanged));
            continue;
        }
        // an outcome that records its boards but no frame checksum: the file could not be read
        let changed = match (frame_crc64, now) {
            (Some(then), Some(now)) => then != *now,
            (None, Some(_)) => boards_crc64.is_some(),
            (_, None) => false,
        };
        if changed {
            let from_frame = frame_crc64
                .and_then(|c| by_checksum.get(&c).copied())
                .filter(|&other| other != id);
            stale.push((id, Stale::FrameChanged { from_frame }));
        }
    }
    stale
}

#[cfg(test)]
mod tests;
