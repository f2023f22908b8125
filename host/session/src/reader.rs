//! Opens a recorded session for replay, tolerating what a crash or bad media leaves behind.
//!
//! - A missing or unparsable manifest is an error naming the file, line and column.
//! - A truncated last line of the log (a write cut by SIGKILL) is dropped and reported.
//! - A corrupt line elsewhere is skipped and reported with its line number (in
//!   [`ReadReport::summary`] too); the rest is kept.
//! - A frame id with two `frame` events, or a pulse logged twice, is reported (never "intact").
//! - The `frames/` directory is the truth for which frames exist: a frame whose event was never
//!   written (killed between rename and log) is still listed, without metadata; a `frame` event
//!   whose file is missing is reported. Temporary `.partial` files are ignored.
//! - Each frame carries the flash that lit it from its `pairing` event: bracket step, actual
//!   on-time and [`FrameEntry::flash_energy_rel`]. Sessions written before bracketing (and frames
//!   without a pairing) read as step 0 at full energy, 1.0.

use ellipso_model::file_io::{caps, read_bounded, read_bounded_text};
use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};

use super::events::{FrameStatus, SessionEvent};
use super::manifest::Manifest;
use super::{SCHEMA_VERSION, SessionError, frame_png, paths};

/// One frame of a session.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameEntry {
    /// Frame id.
    pub frame_id: u64,
    /// Path of its PNG.
    pub path: PathBuf,
    /// Its `frame` event, if it was written.
    pub event: Option<SessionEvent>,
    /// The pulse it was paired with, if any.
    pub pulse_seq: Option<u64>,
    /// False when the frame was flagged incomplete at capture.
    pub complete: bool,
    /// The flash-energy bracket step of its pulse (0 without a bracket or pairing).
    pub bracket_step: u8,
    /// Its pulse's actual flash on-time, µs (`None` in sessions before bracketing or unpaired).
    pub flash_on_us: Option<u32>,
    /// Flash energy that lit the frame relative to the capture's full pulse
    /// (`flash_on_us / flash_duration_us`); 1.0 when not recorded. Divide the frame's flash
    /// signal by it to compare frames of different bracket steps; 0 means the flash did not
    /// light (skipped) and the frame holds no flash signal.
    pub flash_energy_rel: f64,
}

impl FrameEntry {
    /// The exposure (µs) and analogue gain (dB) its `frame` event recorded; `None` without
    /// that event.
    pub fn recorded_exposure_gain(&self) -> Option<[f64; 2]> {
        match &self.event {
            Some(SessionEvent::Frame {
                exposure_us,
                gain_db,
                ..
            }) => Some([f64::from(*exposure_us), f64::from(*gain_db)]),
            _ => None,
        }
    }
}

/// What reading found wrong (nothing here prevents replay).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ReadReport {
    /// The last line of the log was cut short and dropped.
    pub truncated_last_line: bool,
    /// Corrupt lines skipped: (line number from 1, error).
    pub bad_lines: Vec<(usize, String)>,
    /// Frames on disk without a `frame` event.
    pub frames_without_event: Vec<u64>,
    /// `frame` events whose file is missing.
    pub events_without_frame: Vec<u64>,
    /// The manifest has an end record (the capture ended cleanly).
    pub ended_cleanly: bool,
    /// Frame ids with more than one `frame` event (the first is kept).
    pub duplicate_frame_events: Vec<u64>,
    /// Pulse sequence numbers with more than one `pulse` event.
    pub duplicate_pulses: Vec<u64>,
    /// Frame ids whose `pose` / `pose_rejected` events computed from the same inputs
    /// (`TrackedFrom`) disagree (the last one is what readers of poses take; identical repeats,
    /// and outcomes recomputed from other bytes or boards, are not listed).
    pub conflicting_poses: Vec<u64>,
}

impl ReadReport {
    /// One-line human summary.
    pub fn summary(&self) -> String {
        let mut parts = Vec::new();
        if !self.ended_cleanly {
            parts.push("capture did not end cleanly (no end record)".to_string());
        }
        if self.truncated_last_line {
            parts.push("last log line truncated".to_string());
        }
        if !self.bad_lines.is_empty() {
            let lines: Vec<String> = self
                .bad_lines
                .iter()
                .take(10)
                .map(|(n, _)| n.to_string())
                .collect();
            let more = if self.bad_lines.len() > 10 {
                ", …"
            } else {
                ""
            };
            parts.push(format!(
                "{} corrupt log lines skipped (line{} {}{more})",
                self.bad_lines.len(),
                if self.bad_lines.len() == 1 { "" } else { "s" },
                lines.join(", ")
            ));
        }
        if !self.duplicate_frame_events.is_empty() {
            parts.push(format!(
                "{} frame ids logged twice ({})",
                self.duplicate_frame_events.len(),
                list(&self.duplicate_frame_events)
            ));
        }
        if !self.duplicate_pulses.is_empty() {
            parts.push(format!(
                "{} pulses logged twice (seq {})",
                self.duplicate_pulses.len(),
                list(&self.duplicate_pulses)
            ));
        }
        if !self.conflicting_poses.is_empty() {
            parts.push(format!(
                "{} frames with pose events that disagree ({})",
                self.conflicting_poses.len(),
                list(&self.conflicting_poses)
            ));
        }
        if !self.frames_without_event.is_empty() {
            parts.push(format!(
                "{} frames without metadata",
                self.frames_without_event.len()
            ));
        }
        if !self.events_without_frame.is_empty() {
            parts.push(format!(
                "{} logged frames missing on disk",
                self.events_without_frame.len()
            ));
        }
        if parts.is_empty() {
            "intact".to_string()
        } else {
            parts.join("; ")
        }
    }
}

/// Up to 10 ids, comma-separated, then `…` and the count.
pub fn id_list(ids: &[u64]) -> String {
    let mut s = list(ids);
    if ids.len() > 10 {
        s.push_str(&format!(" ({} frames)", ids.len()));
    }
    s
}

/// Up to 10 ids, comma-separated.
fn list(ids: &[u64]) -> String {
    let mut s: Vec<String> = ids.iter().take(10).map(u64::to_string).collect();
    if ids.len() > 10 {
        s.push("…".into());
    }
    s.join(", ")
}

/// A frame's raw samples: `(width, height, pixels)`, row-major.
pub type FrameSamples = (u32, u32, Vec<u16>);

/// A session opened for reading.
#[derive(Debug, Clone)]
pub struct Session {
    /// Its directory.
    pub dir: PathBuf,
    /// The manifest.
    pub manifest: Manifest,
    /// Every readable event, in log order.
    pub events: Vec<SessionEvent>,
    /// Every frame on disk, by id.
    pub frames: Vec<FrameEntry>,
    /// What was wrong.
    pub report: ReadReport,
}

impl Session {
    /// Loads a frame's raw samples: `(width, height, pixels)`, checked against the manifest and
    /// against the checksum its `frame` event recorded (`crate::provenance`): a file that is not
    /// the one recorded is a bad frame, so every stage skips it rather than pairing another
    /// capture's pixels with this frame's pose.
    pub fn load_frame(&self, entry: &FrameEntry) -> Result<FrameSamples, SessionError> {
        self.load_frame_and_crc64(entry).1
    }

    /// [`Session::load_frame`], with the CRC-64/XZ of the bytes it read (`None`: the file could
    /// not be read): one read and one hash of the file ([`frame_png::read_hashed`]) serve both
    /// the check against the recorded checksum and the caller's record of what it loaded
    /// (tracking's `TrackedFrom`).
    pub fn load_frame_and_crc64(
        &self,
        entry: &FrameEntry,
    ) -> (Option<u64>, Result<FrameSamples, SessionError>) {
        match frame_png::read_hashed(&entry.path) {
            Err(e) => (None, Err(e)),
            Ok((bytes, crc64)) => (Some(crc64), self.decode_frame(entry, &bytes, crc64)),
        }
    }

    /// Decodes a frame file's `bytes` (whose CRC-64/XZ is `crc64`), refusing bytes that are not
    /// the ones its `frame` event recorded or a size that is not the manifest's.
    fn decode_frame(
        &self,
        entry: &FrameEntry,
        bytes: &[u8],
        crc64: u64,
    ) -> Result<FrameSamples, SessionError> {
        if let Some(SessionEvent::Frame {
            crc64: Some(want), ..
        }) = &entry.event
            && crc64 != *want
        {
            return Err(SessionError::BadFrame {
                path: entry.path.clone(),
                reason: "its bytes are not the ones this session recorded (their checksum \
                         differs from the `frame` event's): damaged, or another capture's frame"
                    .into(),
            });
        }
        let (w, h, px) = frame_png::decode(&entry.path, bytes)?;
        let s = &self.manifest.sensor;
        if (w, h) != (s.width, s.height) {
            return Err(SessionError::BadFrame {
                path: entry.path.clone(),
                reason: format!("{w}×{h} but the manifest says {}×{}", s.width, s.height),
            });
        }
        Ok((w, h, px))
    }
}

/// What a `pairing` event says about a frame.
struct Paired {
    seq: u64,
    bracket_step: u8,
    flash_on_us: Option<u32>,
    flash_energy_rel: f64,
}

/// Opens the session in `dir`.
pub fn open(dir: &Path) -> Result<Session, SessionError> {
    let manifest = read_manifest(dir)?;
    let mut report = ReadReport {
        ended_cleanly: manifest.end.is_some(),
        ..ReadReport::default()
    };
    let events = read_events(dir, &mut report)?;
    let indexed = index_events(&events, &mut report);
    let on_disk = frames_on_disk(dir)?;
    let frames = frame_entries(on_disk, &indexed, &mut report);
    Ok(Session {
        dir: dir.to_path_buf(),
        manifest,
        events,
        frames,
        report,
    })
}

/// Reads `dir`'s manifest: a schema version other than this build's is refused before the
/// shape is checked (so a newer schema gets the right message), then the JSON and the sensor.
fn read_manifest(dir: &Path) -> Result<Manifest, SessionError> {
    let manifest_path = dir.join(paths::MANIFEST);
    let text = read_bounded_text(&manifest_path, caps::MANIFEST)
        .map_err(SessionError::io(&manifest_path))?;
    // check the version before the shape, so a newer schema gets the right message
    if let Ok(v) = serde_json::from_str::<serde_json::Value>(&text)
        && let Some(found) = v.get("schema_version").and_then(|x| x.as_u64())
        && found as u32 != SCHEMA_VERSION
    {
        return Err(SessionError::UnsupportedVersion {
            path: manifest_path,
            found: found as u32,
            supported: SCHEMA_VERSION,
        });
    }
    let manifest: Manifest =
        serde_json::from_str(&text).map_err(|e| SessionError::BadManifest {
            path: manifest_path.clone(),
            line: e.line(),
            column: e.column(),
            message: e.to_string(),
        })?;
    manifest
        .sensor
        .check()
        .map_err(|(field, what)| SessionError::InvalidManifest {
            path: manifest_path.clone(),
            field,
            what,
        })?;
    Ok(manifest)
}

/// Every readable event of `dir`'s log, in log order (none without a log); a cut last line and
/// corrupt lines go to `report`.
fn read_events(dir: &Path, report: &mut ReadReport) -> Result<Vec<SessionEvent>, SessionError> {
    let log_path = dir.join(paths::EVENTS);
    let log = match read_bounded(&log_path, caps::EVENT_LOG) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Vec::new(),
        Err(e) => {
            return Err(SessionError::Io {
                path: log_path,
                error: e,
            });
        }
    };
    let ends_with_newline = log.last() == Some(&b'\n');
    let lines: Vec<&[u8]> = log.split(|&b| b == b'\n').collect();
    let mut events = Vec::new();
    for (i, line) in lines.iter().enumerate() {
        if line.iter().all(u8::is_ascii_whitespace) {
            continue;
        }
        let is_last = i + 1 == lines.len();
        match serde_json::from_slice::<SessionEvent>(line) {
            Ok(e) => events.push(e),
            Err(_) if is_last && !ends_with_newline => report.truncated_last_line = true,
            Err(e) => report.bad_lines.push((i + 1, e.to_string())),
        }
    }
    Ok(events)
}

/// What the log says about the frames.
struct IndexedEvents {
    /// Each frame id's first `frame` event.
    logged: BTreeMap<u64, SessionEvent>,
    /// Each frame id's last `pairing` event.
    pairs: BTreeMap<u64, Paired>,
}

/// Indexes `events` by frame; duplicate `frame` and `pulse` events and pose events that
/// disagree go to `report`.
fn index_events(events: &[SessionEvent], report: &mut ReadReport) -> IndexedEvents {
    let mut logged: BTreeMap<u64, SessionEvent> = BTreeMap::new();
    let mut pairs: BTreeMap<u64, Paired> = BTreeMap::new();
    let mut pulses = std::collections::BTreeSet::new();
    // per frame and what it was computed from: its first pose value (rotation and translation;
    // empty for a rejection); a later outcome computed from other inputs is no conflict
    let mut poses: BTreeMap<(u64, crate::events::TrackedFrom), Vec<f64>> = BTreeMap::new();
    for e in events {
        let pose = match e.pose_event() {
            Some((_, crate::poses::PoseEvent::Interpolated { .. })) | None => None,
            Some((id, p)) => Some((
                (id, e.tracked_from().unwrap_or_default()),
                p.logged_values(),
            )),
        };
        if let Some((id, value)) = pose {
            match poses.get(&id) {
                Some(first) if *first != value => {
                    if !report.conflicting_poses.contains(&id.0) {
                        report.conflicting_poses.push(id.0);
                    }
                }
                Some(_) => {}
                None => {
                    poses.insert(id, value);
                }
            }
        }
        match e {
            SessionEvent::Frame { frame_id, .. } => {
                if logged.contains_key(frame_id) {
                    report.duplicate_frame_events.push(*frame_id);
                } else {
                    logged.insert(*frame_id, e.clone());
                }
            }
            SessionEvent::Pulse { seq, .. } if !pulses.insert(*seq) => {
                report.duplicate_pulses.push(*seq);
            }
            SessionEvent::Pairing {
                frame_id,
                seq,
                bracket_step,
                flash_on_us,
                flash_energy_rel,
                ..
            } => {
                pairs.insert(
                    *frame_id,
                    Paired {
                        seq: *seq,
                        bracket_step: bracket_step.unwrap_or(0),
                        flash_on_us: *flash_on_us,
                        // A non-finite or negative value (hand edits) reads as not recorded.
                        flash_energy_rel: flash_energy_rel
                            .filter(|e| e.is_finite() && *e >= 0.0)
                            .unwrap_or(1.0),
                    },
                );
            }
            _ => {}
        }
    }
    IndexedEvents { logged, pairs }
}

/// The frame files in `dir`'s `frames/` (none without it), by id; other names (`.partial`
/// files included) are ignored.
fn frames_on_disk(dir: &Path) -> Result<BTreeMap<u64, PathBuf>, SessionError> {
    let frames_dir = dir.join(paths::FRAMES);
    let mut on_disk: BTreeMap<u64, PathBuf> = BTreeMap::new();
    if frames_dir.is_dir() {
        for entry in fs::read_dir(&frames_dir).map_err(SessionError::io(&frames_dir))? {
            let path = entry.map_err(SessionError::io(&frames_dir))?.path();
            let name = path
                .file_name()
                .and_then(|n| n.to_str())
                .unwrap_or_default();
            if let Some(id) = name
                .strip_suffix(".png")
                .and_then(|s| s.parse::<u64>().ok())
            {
                on_disk.insert(id, path);
            }
        }
    }
    Ok(on_disk)
}

/// One entry per frame file, with its `frame` event and pairing where logged; frames without
/// an event and events without a file go to `report`.
fn frame_entries(
    on_disk: BTreeMap<u64, PathBuf>,
    indexed: &IndexedEvents,
    report: &mut ReadReport,
) -> Vec<FrameEntry> {
    let (logged, pairs) = (&indexed.logged, &indexed.pairs);
    report.events_without_frame = logged
        .keys()
        .filter(|id| !on_disk.contains_key(id))
        .copied()
        .collect();
    on_disk
        .into_iter()
        .map(|(frame_id, path)| {
            let event = logged.get(&frame_id).cloned();
            if event.is_none() {
                report.frames_without_event.push(frame_id);
            }
            let complete = !matches!(
                event,
                Some(SessionEvent::Frame {
                    status: FrameStatus::Flagged { .. },
                    ..
                })
            );
            let paired = pairs.get(&frame_id);
            FrameEntry {
                frame_id,
                path,
                event,
                pulse_seq: paired.map(|p| p.seq),
                complete,
                bracket_step: paired.map_or(0, |p| p.bracket_step),
                flash_on_us: paired.and_then(|p| p.flash_on_us),
                flash_energy_rel: paired.map_or(1.0, |p| p.flash_energy_rel),
            }
        })
        .collect()
}

impl Session {
    /// The poses this session's log holds (`crate::poses`' module contract).
    pub fn poses(&self) -> crate::poses::SessionPoses {
        crate::poses::SessionPoses::from_events(&self.events)
    }

    /// Frame `frame_id` as a stage that needs its radiometry may read it — its file is on disk,
    /// it was not flagged incomplete at capture, and its `frame` event recorded the exposure
    /// and gain — or why not. The carving and the fit both choose their frames with it, so
    /// they skip the same frames for the same reasons; whether the pixels decode is decided
    /// when they are loaded ([`Session::load_frame`]).
    pub fn readable_frame(&self, frame_id: u64) -> Result<ReadableFrame<'_>, FrameUnreadable> {
        let k = self
            .frames
            .binary_search_by_key(&frame_id, |f| f.frame_id)
            .map_err(|_| FrameUnreadable::NoFile)?;
        let entry = &self.frames[k];
        if !entry.complete {
            return Err(FrameUnreadable::Incomplete);
        }
        let [exposure_us, gain_db] = entry
            .recorded_exposure_gain()
            .ok_or(FrameUnreadable::NoFrameEvent)?;
        Ok(ReadableFrame {
            entry,
            exposure_us,
            gain_db,
        })
    }
}

/// A frame a stage may read ([`Session::readable_frame`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReadableFrame<'a> {
    /// Its file and metadata.
    pub entry: &'a FrameEntry,
    /// Exposure its `frame` event recorded, µs.
    pub exposure_us: f64,
    /// Analogue gain its `frame` event recorded, dB.
    pub gain_db: f64,
}

/// Why a frame may not be read ([`Session::readable_frame`]); the message is the reason the
/// stages list it under.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum FrameUnreadable {
    /// No file of that id in `frames/`.
    #[error("no frame file in the session")]
    NoFile,
    /// The capture flagged it incomplete.
    #[error("flagged incomplete at capture")]
    Incomplete,
    /// Its `frame` event is missing: exposure and gain unknown.
    #[error("no `frame` event: exposure and gain unknown")]
    NoFrameEvent,
}

#[cfg(test)]
mod tests;
