//! Writes a session while capturing: manifest first, then frames and events as they happen.
//!
//! Ordering rules that make a SIGKILL harmless (see the module contract in `session`):
//! frame PNG → temporary name → rename into `frames/` → append its `frame` event (one `write`).
//! The manifest is replaced atomically (temporary file + rename) at start and at [`finish`].
//!
//! [`finish`]: SessionWriter::finish

use std::fs::{self, File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};

use super::events::{FrameStatus, SessionEvent};
use super::manifest::{EndRecord, Manifest};
use super::{SessionError, frame_png, paths};
use crate::time::HostTimeUs;

/// An open session being written.
#[derive(Debug)]
pub struct SessionWriter {
    dir: PathBuf,
    manifest: Manifest,
    events: File,
    frames_written: u64,
    paired: u64,
}

/// A frame encoded to its temporary file, waiting to be committed.
#[derive(Debug)]
pub struct PreparedFrame {
    tmp: PathBuf,
    dst: PathBuf,
    event: SessionEvent,
}

/// A frame to record.
#[derive(Debug, Clone, Copy)]
pub struct FrameRecord<'a> {
    /// Host arrival time.
    pub t_host_us: HostTimeUs,
    /// Monotonic 64-bit frame id.
    pub frame_id: u64,
    /// Camera timestamp, ns.
    pub t_camera_ns: Option<u64>,
    /// Exposure, µs.
    pub exposure_us: u32,
    /// Gain, dB.
    pub gain_db: f32,
    /// Width, px.
    pub width: u32,
    /// Height, px.
    pub height: u32,
    /// Raw mosaic samples, row-major.
    pub pixels: &'a [u16],
    /// Completion.
    pub flagged: Option<&'a str>,
}

impl SessionWriter {
    /// Creates `dir`, which must be new or an empty directory ([`check_fresh`]), and writes the
    /// manifest.
    pub fn create(dir: &Path, manifest: Manifest) -> Result<Self, SessionError> {
        check_fresh(dir)?;
        if let Some(parent) = dir.parent().filter(|p| !p.as_os_str().is_empty()) {
            fs::create_dir_all(parent).map_err(SessionError::io(parent))?;
        }
        match fs::create_dir(dir) {
            Ok(()) => {}
            // an empty directory (checked above) is fine
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists && dir.is_dir() => {}
            Err(e) => return Err(SessionError::io(dir)(e)),
        }
        // `create_dir`, `create_new`: if another process raced us into `dir`, fail rather than
        // share it
        let frames = dir.join(paths::FRAMES);
        fs::create_dir(&frames).map_err(SessionError::io(&frames))?;
        write_manifest(dir, &manifest)?;
        let log = dir.join(paths::EVENTS);
        let events = OpenOptions::new()
            .create_new(true)
            .append(true)
            .open(&log)
            .map_err(SessionError::io(&log))?;
        Ok(Self {
            dir: dir.to_path_buf(),
            manifest,
            events,
            frames_written: 0,
            paired: 0,
        })
    }

    /// The session directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Frames written so far.
    pub fn frames_written(&self) -> u64 {
        self.frames_written
    }

    /// Appends one event as one line, in one write.
    pub fn log(&mut self, event: &SessionEvent) -> Result<(), SessionError> {
        if matches!(event, SessionEvent::Pairing { .. }) {
            self.paired += 1;
        }
        append_line(&mut self.events, &self.dir.join(paths::EVENTS), event)
    }

    /// Writes a frame's PNG atomically, then its `frame` event.
    pub fn write_frame(&mut self, f: FrameRecord<'_>) -> Result<(), SessionError> {
        let prepared = Self::prepare_frame(&self.frames_dir(), f)?;
        self.commit_frame(prepared)
    }

    /// The directory frames go to (for [`prepare_frame`](Self::prepare_frame) on other threads).
    pub fn frames_dir(&self) -> PathBuf {
        self.dir.join(paths::FRAMES)
    }

    /// First half of [`write_frame`](Self::write_frame), safe to run on any thread in parallel:
    /// encodes the PNG to a temporary name in `frames_dir`.
    pub fn prepare_frame(
        frames_dir: &Path,
        f: FrameRecord<'_>,
    ) -> Result<PreparedFrame, SessionError> {
        let name = paths::frame_file(f.frame_id);
        let tmp = frames_dir.join(format!(".{name}.partial"));
        let crc64 = match frame_png::write(&tmp, f.width, f.height, f.pixels) {
            Ok(c) => c,
            Err(e) => {
                // a full disk must not be left fuller by the half-written frame
                let _ = fs::remove_file(&tmp);
                return Err(e);
            }
        };
        let event = SessionEvent::Frame {
            t_host_us: f.t_host_us,
            frame_id: f.frame_id,
            file: name.clone(),
            t_camera_ns: f.t_camera_ns,
            exposure_us: f.exposure_us,
            gain_db: f.gain_db,
            status: match f.flagged {
                None => FrameStatus::Complete,
                Some(r) => FrameStatus::Flagged {
                    reason: r.to_string(),
                },
            },
            crc64: Some(crc64),
        };
        Ok(PreparedFrame {
            tmp,
            dst: frames_dir.join(name),
            event,
        })
    }

    /// Second half: renames the frame into place, then appends its `frame` event.
    pub fn commit_frame(&mut self, prepared: PreparedFrame) -> Result<(), SessionError> {
        fs::rename(&prepared.tmp, &prepared.dst).map_err(SessionError::io(&prepared.dst))?;
        self.frames_written += 1;
        self.log(&prepared.event)
    }

    /// Records the end, rewrites the manifest with it and syncs everything to disk.
    pub fn finish(mut self, t_host_us: HostTimeUs, reason: &str) -> Result<PathBuf, SessionError> {
        self.log(&SessionEvent::End {
            t_host_us,
            reason: reason.to_string(),
        })?;
        self.events
            .sync_all()
            .map_err(SessionError::io(self.dir.join(paths::EVENTS)))?;
        let now = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_micros() as u64)
            .unwrap_or(0);
        self.manifest.end = Some(EndRecord {
            ended_unix_us: now,
            reason: reason.to_string(),
            frames: self.frames_written,
            paired: self.paired,
        });
        write_manifest(&self.dir, &self.manifest)?;
        Ok(self.dir)
    }
}

/// Refuses a `dir` that is not new or an empty directory: it must never be another session
/// (even one whose manifest is gone), nor a file, nor lie inside a recorded session.
pub fn check_fresh(dir: &Path) -> Result<(), SessionError> {
    if dir.join(paths::MANIFEST).exists() {
        return Err(SessionError::AlreadyExists {
            path: dir.to_path_buf(),
        });
    }
    let not_fresh = |what: String| SessionError::NotFresh {
        path: dir.to_path_buf(),
        what,
    };
    if let Some(session) = session_above(dir) {
        return Err(not_fresh(format!(
            "lies inside the recorded session {}: a session is never written into another \
             (choose an --out outside it)",
            session.display()
        )));
    }
    match fs::symlink_metadata(dir) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(SessionError::io(dir)(e)),
        Ok(m) if !m.is_dir() => Err(not_fresh("exists and is not a directory".into())),
        Ok(_) => {
            let mut names: Vec<String> = fs::read_dir(dir)
                .map_err(SessionError::io(dir))?
                .filter_map(Result::ok)
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .collect();
            if names.is_empty() {
                return Ok(());
            }
            names.sort();
            let n = names.len();
            names.truncate(3);
            let more = if n > 3 { ", …" } else { "" };
            Err(not_fresh(format!(
                "is not empty ({n} entries: {}{more})",
                names.join(", ")
            )))
        }
    }
}

/// The recorded session strictly above `dir`, if any, its path resolved (symbolic links, `..`)
/// as far as it exists.
fn session_above(dir: &Path) -> Option<PathBuf> {
    let abs = std::path::absolute(dir).ok()?;
    // the nearest existing ancestor, canonical, then the rest as given
    let mut existing = abs.as_path();
    let mut rest = Vec::new();
    while !existing.exists() {
        rest.push(existing.file_name()?.to_owned());
        existing = existing.parent()?;
    }
    let mut resolved = existing.canonicalize().ok()?;
    resolved.extend(rest.iter().rev());
    paths::enclosing_session(resolved.parent()?)
}

/// Replaces the manifest of the recorded session in `dir` with `manifest` (`ellipso session
/// upgrade`: an older session given the sections this build records), keeping the old file as
/// [`paths::MANIFEST_BACKUP`]. Refuses when a backup is already there (an earlier upgrade's:
/// it is never overwritten). Nothing else in the session is touched. Returns the backup's path.
pub fn replace_manifest(dir: &Path, manifest: &Manifest) -> Result<PathBuf, SessionError> {
    let path = dir.join(paths::MANIFEST);
    let backup = dir.join(paths::MANIFEST_BACKUP);
    let old = fs::read(&path).map_err(SessionError::io(&path))?;
    let mut file = fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&backup)
        .map_err(SessionError::io(&backup))?;
    file.write_all(&old)
        .and_then(|()| file.sync_all())
        .map_err(SessionError::io(&backup))?;
    write_manifest(dir, manifest)?;
    Ok(backup)
}

fn write_manifest(dir: &Path, manifest: &Manifest) -> Result<(), SessionError> {
    let path = dir.join(paths::MANIFEST);
    let tmp = dir.join(".manifest.json.partial");
    let json = serde_json::to_vec_pretty(manifest).map_err(|e| SessionError::Io {
        path: path.clone(),
        error: std::io::Error::other(e),
    })?;
    if let Err(e) = fs::write(&tmp, json) {
        let _ = fs::remove_file(&tmp);
        return Err(SessionError::io(&tmp)(e));
    }
    fs::rename(&tmp, &path).map_err(SessionError::io(&path))
}

/// An exclusive advisory lock (`flock(2)`) on a session's event log, held by a stage that reads
/// the log, works, then appends to it (pose tracking): two such runs at once would both track
/// the same frames and both append their poses. The lock changes no byte of the session and is
/// released by the kernel however its holder ends.
#[derive(Debug)]
pub struct LogLock {
    _file: File,
}

impl LogLock {
    /// Takes the lock on the log of the session in `dir`, calling `waiting` once when another
    /// process holds it (then waits for it). A session without a log needs no lock (`None`).
    pub fn acquire(dir: &Path, waiting: impl FnOnce()) -> Result<Option<Self>, SessionError> {
        let path = dir.join(paths::EVENTS);
        let file = match File::open(&path) {
            Ok(f) => f,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(e) => return Err(SessionError::io(&path)(e)),
        };
        #[cfg(unix)]
        {
            use std::os::fd::AsRawFd;
            let fd = file.as_raw_fd();
            // SAFETY: flock on a descriptor we own; no memory is passed.
            if unsafe { libc::flock(fd, libc::LOCK_EX | libc::LOCK_NB) } != 0 {
                waiting();
                // SAFETY: as above, now waiting.
                if unsafe { libc::flock(fd, libc::LOCK_EX) } != 0 {
                    return Err(SessionError::io(&path)(std::io::Error::last_os_error()));
                }
            }
        }
        Ok(Some(Self { _file: file }))
    }
}

/// Appends events to an existing session's log (stages that run after capture, e.g. poses).
#[derive(Debug)]
pub struct SessionAppender {
    path: PathBuf,
    events: File,
}

impl SessionAppender {
    /// Opens the log of the session in `dir` for appending; the session must exist. A log whose
    /// last line was cut short (a killed writer) is first ended with a newline, so appended
    /// events start on a line of their own and the cut line stays a (reported) corrupt line.
    pub fn open(dir: &Path) -> Result<Self, SessionError> {
        let manifest = dir.join(paths::MANIFEST);
        if !manifest.is_file() {
            return Err(SessionError::Io {
                path: manifest,
                error: std::io::Error::new(std::io::ErrorKind::NotFound, "not a session"),
            });
        }
        let path = dir.join(paths::EVENTS);
        let mut events = OpenOptions::new()
            .read(true)
            .append(true)
            .create(true)
            .open(&path)
            .map_err(SessionError::io(&path))?;
        if !ends_with_newline(&mut events).map_err(SessionError::io(&path))? {
            write_all_or_nothing(&mut events, b"\n").map_err(SessionError::io(&path))?;
        }
        Ok(Self { path, events })
    }

    /// Appends one event as one line, in one write.
    pub fn log(&mut self, event: &SessionEvent) -> Result<(), SessionError> {
        append_line(&mut self.events, &self.path, event)
    }
}

/// Appends `event` to the log `file` (at `path`, for errors) as one line, in one write: the
/// crash-safety contract of the event log. All or nothing: a write cut short (a full disk) is
/// truncated away again, so no partial line is ever left behind by an error.
fn append_line(file: &mut File, path: &Path, event: &SessionEvent) -> Result<(), SessionError> {
    let mut line = serde_json::to_vec(event).map_err(|e| SessionError::Io {
        path: path.to_path_buf(),
        error: std::io::Error::other(e),
    })?;
    line.push(b'\n');
    write_all_or_nothing(file, &line).map_err(SessionError::io(path))
}

/// Writes `bytes` at the end of `file` (opened for appending) completely, or restores the
/// file's previous length and returns the error.
fn write_all_or_nothing(file: &mut File, bytes: &[u8]) -> std::io::Result<()> {
    let before = file.metadata()?.len();
    match file.write_all(bytes) {
        Ok(()) => Ok(()),
        Err(e) => {
            if let Err(undo) = file.set_len(before) {
                tracing::error!("could not remove a partly written log line: {undo}");
            }
            Err(e)
        }
    }
}

/// Whether `file` is empty or its last byte is a newline.
fn ends_with_newline(file: &mut File) -> std::io::Result<bool> {
    use std::io::{Read, Seek, SeekFrom};
    let len = file.metadata()?.len();
    if len == 0 {
        return Ok(true);
    }
    file.seek(SeekFrom::Start(len - 1))?;
    let mut last = [0u8; 1];
    file.read_exact(&mut last)?;
    Ok(last[0] == b'\n')
}
