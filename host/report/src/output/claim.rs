//! The claim of a single result file: one lock file beside it (`.NAME.ellipso-claim`), held
//! with `flock(2)` from the claim until the run ends, so that a second run writing the same
//! file is refused at its claim ("another ellipso run is writing this output now") instead of
//! both finishing and the file holding the other run's result.
//!
//! Contract: [`FileClaim::take`] creates the lock file if needed and locks it without waiting;
//! held by another process it is [`OutputError::Busy`]. After locking, the path is checked to
//! still name the locked file (a run that ends unlinks it, and a run that opened the old file
//! just before must not believe it holds the new one); dropping the claim unlinks the file and
//! releases the lock, in that order. The kernel releases the lock of a killed run; its file is
//! then a free claim the next run takes.

use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};

use super::{OutputError, fsops};

/// A held claim on one result file.
#[derive(Debug)]
pub(crate) struct FileClaim {
    path: PathBuf,
    _lock: fsops::DirLock,
}

impl FileClaim {
    /// Claims `file` (resolved), shown to the user as `shown` (see the module doc).
    pub(crate) fn take(file: &Path, shown: &Path) -> Result<Self, OutputError> {
        let name = file
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let path = file.with_file_name(format!(
            ".{}.ellipso-claim",
            crate::atomic_file::short_name(&name)
        ));
        for _ in 0..16 {
            std::fs::OpenOptions::new()
                .create(true)
                .append(true)
                .open(&path)
                .map_err(|e| OutputError::io(&path, e))?;
            let Some(lock) = fsops::try_lock(&path).map_err(|e| OutputError::io(&path, e))? else {
                return Err(OutputError::Busy {
                    out: shown.to_path_buf(),
                    staging: path,
                });
            };
            // the lock is on the file opened; is it still the one at `path`?
            let same = match (std::fs::metadata(&path), lock.metadata()) {
                (Ok(now), Ok(held)) => now.ino() == held.ino() && now.dev() == held.dev(),
                _ => false,
            };
            if same {
                return Ok(FileClaim { path, _lock: lock });
            }
        }
        Err(OutputError::Busy {
            out: shown.to_path_buf(),
            staging: path,
        })
    }
}

impl Drop for FileClaim {
    fn drop(&mut self) {
        // unlinked while still locked: a waiting run then finds a fresh file (module doc)
        let _ = std::fs::remove_file(&self.path);
    }
}
