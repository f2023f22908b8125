//! The few file-system operations output directories need beyond `std`: an advisory lock held
//! on a directory for as long as a run writes it (so a later run can tell a live writer's
//! staging directory from a dead one's leftovers), the swap of two directories in one step, and
//! syncing a finished tree to disk before it is swapped in.
//!
//! Contract: on Linux the lock is `flock(2)` on the directory itself (released by the kernel
//! when the process dies, however it dies) and the swap is `renameat2(RENAME_EXCHANGE)`; where
//! either is unavailable the lock is reported as held by nobody and the swap falls back to two
//! renames (a crash between them leaves the old output beside a missing one, never a mix).

use std::fs::File;
use std::io;
use std::path::Path;

/// An exclusive advisory lock on a directory, held while the value lives.
#[derive(Debug)]
pub struct DirLock {
    _file: File,
}

impl DirLock {
    /// The metadata of the locked file itself (not of whatever its path names now).
    pub fn metadata(&self) -> io::Result<std::fs::Metadata> {
        self._file.metadata()
    }
}

/// Locks `dir` without waiting: `Ok(None)` when another process holds it.
pub fn try_lock(dir: &Path) -> io::Result<Option<DirLock>> {
    let file = File::open(dir)?;
    #[cfg(unix)]
    {
        use std::os::fd::AsRawFd;
        // SAFETY: flock on a descriptor we own; no memory is passed.
        let rc = unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) };
        if rc != 0 {
            let e = io::Error::last_os_error();
            return if e.kind() == io::ErrorKind::WouldBlock {
                Ok(None)
            } else {
                Err(e)
            };
        }
    }
    Ok(Some(DirLock { _file: file }))
}

/// Exchanges the directories `a` and `b` (both exist) in one step where the kernel can;
/// otherwise moves `b` to `aside`, then `a` to `b`, leaving the old `b` at `aside`. Returns where
/// the old `b` now is.
pub fn swap_in(a: &Path, b: &Path, aside: &Path) -> io::Result<std::path::PathBuf> {
    #[cfg(target_os = "linux")]
    {
        use std::ffi::CString;
        use std::os::unix::ffi::OsStrExt;
        let ca = CString::new(a.as_os_str().as_bytes())?;
        let cb = CString::new(b.as_os_str().as_bytes())?;
        // SAFETY: two NUL-terminated paths that live across the call.
        let rc = unsafe {
            libc::renameat2(
                libc::AT_FDCWD,
                ca.as_ptr(),
                libc::AT_FDCWD,
                cb.as_ptr(),
                libc::RENAME_EXCHANGE,
            )
        };
        if rc == 0 {
            return Ok(a.to_path_buf());
        }
        let e = io::Error::last_os_error();
        // file systems without the flag answer EINVAL (or ENOSYS on old kernels): fall back
        if !matches!(e.raw_os_error(), Some(libc::EINVAL | libc::ENOSYS)) {
            return Err(e);
        }
    }
    std::fs::rename(b, aside)?;
    std::fs::rename(a, b)?;
    Ok(aside.to_path_buf())
}

/// Syncs every regular file under `dir`, then the directories themselves, to disk.
pub fn sync_tree(dir: &Path) -> io::Result<()> {
    for entry in std::fs::read_dir(dir)? {
        let entry = entry?;
        let kind = entry.file_type()?;
        if kind.is_dir() {
            sync_tree(&entry.path())?;
        } else if kind.is_file() {
            File::open(entry.path())?.sync_all()?;
        }
    }
    File::open(dir)?.sync_all()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_held_lock_is_seen_and_released_with_its_holder() {
        let dir = tempfile::tempdir().unwrap();
        let held = try_lock(dir.path()).unwrap().expect("free");
        assert!(try_lock(dir.path()).unwrap().is_none());
        drop(held);
        assert!(try_lock(dir.path()).unwrap().is_some());
    }

    #[test]
    fn swapping_exchanges_contents() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("a"), dir.path().join("b"));
        std::fs::create_dir(&a).unwrap();
        std::fs::create_dir(&b).unwrap();
        std::fs::write(a.join("new"), b"n").unwrap();
        std::fs::write(b.join("old"), b"o").unwrap();
        let old = swap_in(&a, &b, &dir.path().join("aside")).unwrap();
        assert!(b.join("new").is_file());
        assert!(old.join("old").is_file());
        sync_tree(&b).unwrap();
    }
}
