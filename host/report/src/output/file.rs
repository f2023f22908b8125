//! A result file a command owns: claimed before the work starts (so a bad `--out` is refused
//! before minutes of computing), written whole through [`crate::atomic_file`].
//!
//! Contract of [`OutputFile::claim`]: the name is not a directory's (`out/`), its place passes
//! [`super::place::check`], its extension is the format's, and an existing file there is
//! replaced only when it is a regular file whose first bytes are the format's (a user's
//! document saved under the same name is refused, never overwritten); it is claimed
//! ([`super::claim`]): a second live run writing the same file is refused. The temporary files
//! a killed run left beside it are removed.

use std::io::Read;
use std::path::{Path, PathBuf};

use super::{OutputError, place};

/// A file format a command writes: its name, the extensions it is saved under and the bytes it
/// starts with (empty: text formats, any start).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FileFormat {
    /// Name in messages.
    pub name: &'static str,
    /// Accepted extensions, lower case, without the dot.
    pub extensions: &'static [&'static str],
    /// The first bytes of every file of this format.
    pub magic: &'static [u8],
}

impl FileFormat {
    /// PNG pictures.
    pub const PNG: Self = Self {
        name: "PNG",
        extensions: &["png"],
        magic: b"\x89PNG\r\n\x1a\n",
    };
    /// PLY meshes.
    pub const PLY: Self = Self {
        name: "PLY",
        extensions: &["ply"],
        magic: b"ply",
    };
    /// Wavefront OBJ meshes.
    pub const OBJ: Self = Self {
        name: "OBJ",
        extensions: &["obj"],
        magic: b"",
    };
    /// JSON reports (objects or arrays: text, any start).
    pub const JSON: Self = Self {
        name: "JSON",
        extensions: &["json"],
        magic: b"",
    };
    /// TOML sections (rig files).
    pub const TOML: Self = Self {
        name: "TOML",
        extensions: &["toml"],
        magic: b"",
    };
    /// Markdown reports.
    pub const MARKDOWN: Self = Self {
        name: "Markdown",
        extensions: &["md"],
        magic: b"",
    };
}

/// Removes the temporary files of `path` that runs killed mid-write left beside it
/// (`.NAME.PID.partial` of [`crate::atomic_file`], PID no longer running).
fn remove_dead_partials(parent: &Path, path: &Path) {
    let Some(name) = path.file_name().map(|n| n.to_string_lossy().into_owned()) else {
        return;
    };
    let prefix = format!(".{}.", crate::atomic_file::short_name(&name));
    for e in std::fs::read_dir(parent).into_iter().flatten().flatten() {
        let file = e.file_name().to_string_lossy().into_owned();
        let Some(pid) = file
            .strip_prefix(&prefix)
            .and_then(|rest| rest.strip_suffix(".partial"))
            .and_then(|pid| pid.parse::<i32>().ok())
        else {
            continue;
        };
        // SAFETY: signal 0 sends nothing; it only asks whether the process exists.
        let alive = unsafe { libc::kill(pid, 0) } == 0
            || std::io::Error::last_os_error().raw_os_error() == Some(libc::EPERM);
        if !alive {
            let _ = std::fs::remove_file(e.path());
        }
    }
}

/// A result file claimed by a command; the claim ([`super::claim`]) is held while any clone
/// lives.
#[derive(Debug, Clone)]
pub struct OutputFile {
    path: PathBuf,
    shown: PathBuf,
    format: FileFormat,
    _claim: std::sync::Arc<super::claim::FileClaim>,
}

impl OutputFile {
    /// Claims the file `out` of `format` for `command`, which reads `inputs` (see the module doc);
    /// `derived` as for [`super::OutputDir::claim_in_session`]. Creates missing parent
    /// directories.
    pub fn claim(
        out: &Path,
        command: &str,
        format: FileFormat,
        inputs: &[&Path],
        derived: Option<&str>,
    ) -> Result<Self, OutputError> {
        let wrong = |what: String| OutputError::WrongKind {
            out: out.to_path_buf(),
            what,
        };
        let text = out.as_os_str().to_string_lossy();
        if text.ends_with('/') || out.file_name().is_none() {
            return Err(wrong(format!(
                "names a directory; this command writes one {} file (e.g. {}/result.{})",
                format.name,
                text.trim_end_matches('/'),
                format.extensions[0]
            )));
        }
        if out.file_name().is_some_and(|n| n.len() > 255) {
            return Err(wrong(
                "its name is longer than 255 bytes, more than a file system stores; choose a \
                 shorter name"
                    .into(),
            ));
        }
        let path = place::resolve(out)?;
        place::check(&path, command, inputs, derived)?;
        let ext = out
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase());
        if !ext
            .as_deref()
            .is_some_and(|e| format.extensions.contains(&e))
        {
            return Err(wrong(format!(
                "this command writes {}; name the file .{}",
                format.name,
                format.extensions.join(" or .")
            )));
        }
        match std::fs::metadata(&path) {
            Ok(m) if m.is_dir() => {
                return Err(wrong("is a directory; name a file inside it".into()));
            }
            Ok(m) if !m.is_file() => {
                return Err(wrong(
                    "is not a regular file (a pipe, device or socket); name a file".into(),
                ));
            }
            Ok(_) => {
                let mut head = vec![0u8; format.magic.len()];
                let read = std::fs::File::open(&path)
                    .and_then(|f| f.take(head.len() as u64).read(&mut head))
                    .map_err(|e| OutputError::io(&path, e))?;
                if read < head.len() || head != format.magic {
                    return Err(wrong(format!(
                        "exists and is not a {} file; refusing to replace it (nothing was changed)",
                        format.name
                    )));
                }
            }
            Err(_) => {}
        }
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).map_err(|e| OutputError::io(parent, e))?;
        }
        let claim = super::claim::FileClaim::take(&path, out)?;
        if let Some(parent) = path.parent() {
            remove_dead_partials(parent, &path);
        }
        Ok(OutputFile {
            path,
            shown: out.to_path_buf(),
            format,
            _claim: std::sync::Arc::new(claim),
        })
    }

    /// The file's path (resolved).
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The file as the user named it.
    pub fn shown(&self) -> &Path {
        &self.shown
    }

    /// Refuses, before the work, a file system that cannot hold `needed` bytes (the least the
    /// caller will write there, its own lower bound): a full disk is then said at the claim,
    /// not after minutes of computing. Bytes free are those available to this user
    /// (`statvfs(3)`'s `f_bavail`); where they cannot be read nothing is refused (the write
    /// still fails cleanly, [`crate::atomic_file`]).
    pub fn ensure_room(&self, needed: u64) -> Result<(), OutputError> {
        let dir = self.path.parent().unwrap_or(Path::new("."));
        match free_bytes(dir) {
            Some(free) if free < needed => Err(OutputError::NoRoom {
                out: self.shown.clone(),
                free,
                needed,
            }),
            _ => Ok(()),
        }
    }

    /// The format claimed.
    pub fn format(&self) -> FileFormat {
        self.format
    }

    /// Writes `bytes` whole (or not at all).
    pub fn write(&self, bytes: impl AsRef<[u8]>) -> Result<(), OutputError> {
        crate::atomic_file::write(&self.path, bytes).map_err(|e| OutputError::io(&self.shown, e))
    }
}

/// Bytes available to this user on the file system holding `dir` (`None`: not readable).
pub fn free_bytes(dir: &Path) -> Option<u64> {
    use std::os::unix::ffi::OsStrExt;
    let c = std::ffi::CString::new(dir.as_os_str().as_bytes()).ok()?;
    // SAFETY: `c` is a valid NUL-terminated path; `st` is written by statvfs before it is read.
    let mut st: libc::statvfs = unsafe { std::mem::zeroed() };
    if unsafe { libc::statvfs(c.as_ptr(), &mut st) } != 0 {
        return None;
    }
    Some((st.f_bavail as u64).saturating_mul(st.f_frsize as u64))
}
