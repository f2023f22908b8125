//! Outputs a command owns: the one mechanism every `ellipso` command that writes a result
//! directory or file goes through, so that no run ever loses a user's files, writes over what it
//! reads, or leaves a mix of two runs behind.
//!
//! Contract of a result **directory** ([`OutputDir`]):
//! - *Owned.* `--out DIR` is written only when it is absent, empty, or holds the marker
//!   [`MARKER`] of the same command listing every file in it. A directory holding anything else
//!   — a user's files, another command's output, an older output a user added a file to — is
//!   refused, naming what is in the way; nothing is deleted to make room.
//! - *Apart from the inputs.* An output equal to, inside or containing one of the command's
//!   inputs, containing the current directory, or inside a recorded session (except the
//!   session's own derived directory of that command) is refused ([`place`]).
//! - *Whole or nothing.* A run writes into a fresh hidden sibling (`.DIR.ellipso-new-PID`),
//!   locked while it lives; [`OutputDir::commit`] syncs it, writes the marker and swaps it in
//!   for the previous output in one rename. An interrupted run leaves the previous complete
//!   output (or none); its staging directory is removed when the run is dropped, by
//!   [`abandon_active`] on a signal, or — after SIGKILL or a power cut — by the next run, which
//!   recognises it by its name and by nobody holding its lock.
//!
//! A result **file** ([`OutputFile`]) is claimed the same way (never inside an input or a
//! session, a name whose extension is the format written, an existing file replaced only when
//! it is a regular file of that format) and written whole through [`crate::atomic_file`].

mod claim;
mod file;
mod fsops;
pub mod place;

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

pub use file::{FileFormat, OutputFile};

/// The marker file of an output directory: which command wrote it and every file it wrote.
pub const MARKER: &str = ".ellipso-output.json";

/// Why an output cannot be written where asked.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// The directory holds files no run of this command wrote.
    #[error(
        "{}: refusing to write into a directory that holds files `ellipso {command}` did not write ({}); choose a new --out (nothing was deleted)",
        out.display(), found.join(", ")
    )]
    NotOurs {
        /// The directory.
        out: PathBuf,
        /// The command.
        command: String,
        /// A few of the foreign entries.
        found: Vec<String>,
    },
    /// The directory is another command's output.
    #[error(
        "{}: this is the output of `ellipso {found}`, not of `ellipso {command}`; choose another --out",
        out.display()
    )]
    OtherCommand {
        /// The directory.
        out: PathBuf,
        /// The command asking.
        command: String,
        /// The command whose marker it holds.
        found: String,
    },
    /// The output overlaps an input.
    #[error(
        "--out {}: the output {relation} {}, which this run reads; a command never writes over its inputs — choose a place outside them",
        out.display(), input.display()
    )]
    OverlapsInput {
        /// The output.
        out: PathBuf,
        /// "is", "is inside", "contains".
        relation: &'static str,
        /// The input.
        input: PathBuf,
    },
    /// The output is inside a recorded session.
    #[error(
        "--out {}: {} the recorded session {}; a session is never written after its capture (only the poses appended to its log) — choose a place outside it",
        out.display(), if out == session { "this is" } else { "inside" }, session.display()
    )]
    InsideSession {
        /// The output.
        out: PathBuf,
        /// The session.
        session: PathBuf,
    },
    /// A directory was asked for, a file is there (or the reverse).
    #[error("--out {}: {what}", out.display())]
    WrongKind {
        /// The output.
        out: PathBuf,
        /// What is wrong, in words.
        what: String,
    },
    /// Another live run is writing the same output.
    #[error(
        "{}: another ellipso run is writing this output now ({}); wait for it or choose another --out",
        out.display(), staging.display()
    )]
    Busy {
        /// The output.
        out: PathBuf,
        /// The other run's staging directory.
        staging: PathBuf,
    },
    /// The output's file system has less room than the results certainly take.
    #[error(
        "--out {}: the file system holding it has {free} bytes free, less than the {needed} bytes \
         the results take at the least; free some space or choose another --out (checked before \
         the work; nothing was written)",
        out.display()
    )]
    NoRoom {
        /// The output.
        out: PathBuf,
        /// Bytes free to this user there.
        free: u64,
        /// The least the results take.
        needed: u64,
    },
    /// The file system said no.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
}

impl OutputError {
    fn io(path: &Path, source: std::io::Error) -> Self {
        OutputError::Io {
            path: path.to_path_buf(),
            source,
        }
    }
}

/// Staging directories of the runs alive in this process.
static ACTIVE: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// Removes the staging directory of every output this process has claimed and not committed:
/// what a signal handler calls before the process exits, so an interrupted run leaves the
/// previous output and nothing else.
pub fn abandon_active() {
    let active = ACTIVE
        .lock()
        .map(|mut a| std::mem::take(&mut *a))
        .unwrap_or_default();
    for dir in active {
        let _ = std::fs::remove_dir_all(dir);
    }
}

fn forget(staging: &Path) {
    if let Ok(mut a) = ACTIVE.lock() {
        a.retain(|p| p != staging);
    }
}

/// The marker's content.
#[derive(Debug, serde::Serialize, serde::Deserialize)]
struct Marker {
    command: String,
    software: String,
    files: BTreeSet<String>,
}

/// Every entry under `dir` that is not a directory, as `/`-joined paths relative to `dir`.
fn files_under(dir: &Path) -> std::io::Result<BTreeSet<String>> {
    let mut out = BTreeSet::new();
    let mut stack = vec![PathBuf::new()];
    while let Some(rel) = stack.pop() {
        for e in std::fs::read_dir(dir.join(&rel))? {
            let e = e?;
            let r = rel.join(e.file_name());
            if e.file_type()?.is_dir() {
                stack.push(r);
            } else {
                out.insert(r.to_string_lossy().replace('\\', "/"));
            }
        }
    }
    Ok(out)
}

/// Checks that an existing `out` may be replaced by `command` (see the module doc).
fn check_owned(out: &Path, command: &str) -> Result<(), OutputError> {
    let files = files_under(out).map_err(|e| OutputError::io(out, e))?;
    if files.is_empty() {
        return Ok(());
    }
    let marker: Option<Marker> = std::fs::read(out.join(MARKER))
        .ok()
        .and_then(|b| serde_json::from_slice(&b).ok());
    let Some(marker) = marker else {
        return Err(OutputError::NotOurs {
            out: out.to_path_buf(),
            command: command.to_string(),
            found: files.into_iter().take(3).collect(),
        });
    };
    if marker.command != command {
        return Err(OutputError::OtherCommand {
            out: out.to_path_buf(),
            command: command.to_string(),
            found: marker.command,
        });
    }
    let foreign: Vec<String> = files
        .into_iter()
        .filter(|f| f != MARKER && !marker.files.contains(f))
        .take(3)
        .collect();
    if !foreign.is_empty() {
        return Err(OutputError::NotOurs {
            out: out.to_path_buf(),
            command: command.to_string(),
            found: foreign,
        });
    }
    Ok(())
}

/// A result directory being written (see the module doc).
#[derive(Debug)]
pub struct OutputDir {
    command: &'static str,
    /// Where the result goes, resolved.
    target: PathBuf,
    /// As the user named it (for messages).
    shown: PathBuf,
    staging: PathBuf,
    lock: Option<fsops::DirLock>,
}

impl OutputDir {
    /// Claims `out` for `command`, which reads `inputs`: checks where it is and who owns it,
    /// removes dead runs' leftovers beside it and creates the empty staging directory the run
    /// writes into ([`Self::path`]).
    pub fn claim(out: &Path, command: &'static str, inputs: &[&Path]) -> Result<Self, OutputError> {
        Self::claim_in_session(out, command, inputs, None)
    }

    /// [`Self::claim`] for a command that owns a derived directory of its input session
    /// (`derived`, one of `ellipso_session::paths::DERIVED`).
    pub fn claim_in_session(
        out: &Path,
        command: &'static str,
        inputs: &[&Path],
        derived: Option<&str>,
    ) -> Result<Self, OutputError> {
        let target = place::resolve(out)?;
        place::check(&target, command, inputs, derived)?;
        match std::fs::metadata(&target) {
            Ok(m) if m.is_dir() => check_owned(&target, command)?,
            Ok(_) => {
                return Err(OutputError::WrongKind {
                    out: out.to_path_buf(),
                    what: "is a file; this command writes a directory of results".into(),
                });
            }
            Err(_) => {}
        }
        let (parent, name) = match (target.parent(), target.file_name()) {
            (Some(p), Some(n)) => (p.to_path_buf(), n.to_string_lossy().into_owned()),
            _ => {
                return Err(OutputError::WrongKind {
                    out: out.to_path_buf(),
                    what: "is the root of the file system".into(),
                });
            }
        };
        std::fs::create_dir_all(&parent).map_err(|e| OutputError::io(&parent, e))?;
        let short = crate::atomic_file::short_name(&name);
        let staging = parent.join(format!(".{short}.ellipso-new-{}", std::process::id()));
        // a stale staging directory of this very pid (a recycled pid) is a dead run's
        let _ = std::fs::remove_dir_all(&staging);
        std::fs::create_dir(&staging).map_err(|e| OutputError::io(&staging, e))?;
        let lock = fsops::try_lock(&staging).map_err(|e| OutputError::io(&staging, e))?;
        if let Ok(mut a) = ACTIVE.lock() {
            a.push(staging.clone());
        }
        let claimed = OutputDir {
            command,
            target,
            shown: out.to_path_buf(),
            staging,
            lock,
        };
        claimed.clear_leftovers(&parent, &name)?;
        Ok(claimed)
    }

    /// Removes the staging and set-aside directories of dead runs into the same output; a live
    /// run's is [`OutputError::Busy`].
    fn clear_leftovers(&self, parent: &Path, name: &str) -> Result<(), OutputError> {
        let prefix = format!(".{}.ellipso-", crate::atomic_file::short_name(name));
        let entries = std::fs::read_dir(parent).map_err(|e| OutputError::io(parent, e))?;
        for e in entries.filter_map(Result::ok) {
            let path = e.path();
            if path == self.staging || !e.file_name().to_string_lossy().starts_with(&prefix) {
                continue;
            }
            if !e.file_type().is_ok_and(|t| t.is_dir()) {
                let _ = std::fs::remove_file(&path);
                continue;
            }
            match fsops::try_lock(&path) {
                Ok(Some(_dead)) => {
                    std::fs::remove_dir_all(&path).map_err(|e| OutputError::io(&path, e))?;
                }
                Ok(None) => {
                    return Err(OutputError::Busy {
                        out: self.shown.clone(),
                        staging: path,
                    });
                }
                Err(e) => return Err(OutputError::io(&path, e)),
            }
        }
        Ok(())
    }

    /// The directory to write the results into (the staging directory until [`Self::commit`]).
    pub fn path(&self) -> &Path {
        &self.staging
    }

    /// The output as the user named it.
    pub fn shown(&self) -> &Path {
        &self.shown
    }

    /// Where `staged` (a path under [`Self::path`]) will be once committed, in the user's
    /// spelling; other paths are returned unchanged.
    pub fn published(&self, staged: &Path) -> PathBuf {
        staged
            .strip_prefix(&self.staging)
            .map(|rest| self.shown.join(rest))
            .unwrap_or_else(|_| staged.to_path_buf())
    }

    /// Syncs the results, writes the marker and swaps them in for the previous output in one
    /// step; returns the output's path as the user named it.
    pub fn commit(mut self) -> Result<PathBuf, OutputError> {
        let files = files_under(&self.staging).map_err(|e| OutputError::io(&self.staging, e))?;
        let marker = Marker {
            command: self.command.to_string(),
            software: format!("ellipso {}", env!("CARGO_PKG_VERSION")),
            files,
        };
        let bytes = serde_json::to_vec_pretty(&marker)
            .map_err(|e| OutputError::io(&self.staging, std::io::Error::other(e.to_string())))?;
        let marker_path = self.staging.join(MARKER);
        crate::atomic_file::write(&marker_path, bytes)
            .map_err(|e| OutputError::io(&marker_path, e))?;
        fsops::sync_tree(&self.staging).map_err(|e| OutputError::io(&self.staging, e))?;
        if self.target.exists() {
            // owned by this command (checked at the claim); checked again in case it changed
            check_owned(&self.target, self.command)?;
            let aside = self.staging.with_file_name(format!(
                "{}.ellipso-old-{}",
                self.target
                    .file_name()
                    .map(|n| format!(".{}", crate::atomic_file::short_name(&n.to_string_lossy())))
                    .unwrap_or_default(),
                std::process::id()
            ));
            let old = fsops::swap_in(&self.staging, &self.target, &aside)
                .map_err(|e| OutputError::io(&self.target, e))?;
            // the old output is out of sight; a failure to remove it is the next run's leftover
            let _ = std::fs::remove_dir_all(old);
        } else {
            std::fs::rename(&self.staging, &self.target)
                .map_err(|e| OutputError::io(&self.target, e))?;
        }
        if let Some(parent) = self.target.parent() {
            let _ = std::fs::File::open(parent).and_then(|d| d.sync_all());
        }
        forget(&self.staging);
        self.lock = None;
        // nothing left to remove on drop
        self.staging = PathBuf::new();
        Ok(self.shown.clone())
    }
}

impl Drop for OutputDir {
    fn drop(&mut self) {
        if !self.staging.as_os_str().is_empty() {
            let _ = std::fs::remove_dir_all(&self.staging);
            forget(&self.staging);
        }
    }
}

#[cfg(test)]
mod tests;
