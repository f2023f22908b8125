//! Reading an input file with a bound: every file ellipso reads whole (meshes, scenes,
//! manifests, event logs, frames, part files) goes through [`read_bounded`], so an endless
//! source cannot grow the process until the kernel kills it, and a special file cannot hang it.
//!
//! Contract: the path must name a regular file (after symbolic links) — a FIFO, a character or
//! block device (`/dev/zero`), a socket or a directory is refused before it is opened, so opening
//! never blocks; a file larger than the caller's cap is refused by its size, and the read itself
//! stops one byte past the cap (a file that grows while it is read, or reports no size, is
//! refused as well). Errors are `std::io::Error`s whose message says which bound was crossed, so
//! each reader's own error names the file as before.

use std::io::{self, Read};
use std::path::Path;

/// Caps of the files ellipso reads, bytes (documented in `docs/reliability.md`, "Bounds").
pub mod caps {
    /// A mesh file (PLY or OBJ): 4 GiB, ~100 M triangles in binary PLY.
    pub const MESH: u64 = 4 << 30;
    /// A scene or board TOML file.
    pub const SCENE: u64 = 16 << 20;
    /// A session manifest.
    pub const MANIFEST: u64 = 64 << 20;
    /// A session's event log: 4 GiB (a million frames with their pulses, pairings and poses
    /// is well under 1 GiB).
    pub const EVENT_LOG: u64 = 4 << 30;
    /// A raw frame (PNG): 1 GiB, twice a 16384² 16-bit frame stored uncompressed.
    pub const FRAME: u64 = 1 << 30;
}

/// What a path that is not a regular file is, in words.
fn kind_of(meta: &std::fs::Metadata) -> &'static str {
    let t = meta.file_type();
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_fifo() {
            return "a named pipe (FIFO)";
        }
        if t.is_char_device() {
            return "a character device";
        }
        if t.is_block_device() {
            return "a block device";
        }
        if t.is_socket() {
            return "a socket";
        }
    }
    if t.is_dir() {
        "a directory"
    } else {
        "not a regular file"
    }
}

/// Checks that `path` is a regular file of at most `cap` bytes; returns its size.
pub fn check_regular(path: &Path, cap: u64) -> io::Result<u64> {
    let meta = std::fs::metadata(path)?;
    if !meta.is_file() {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("is {}, not a regular file", kind_of(&meta)),
        ));
    }
    if meta.len() > cap {
        return Err(too_large(meta.len(), cap));
    }
    Ok(meta.len())
}

fn too_large(len: u64, cap: u64) -> io::Error {
    io::Error::new(
        io::ErrorKind::InvalidData,
        format!("is {len} bytes, more than the {cap}-byte limit for this kind of file"),
    )
}

/// Reads the regular file `path` whole, refusing it when it holds more than `cap` bytes (see the
/// module doc).
pub fn read_bounded(path: &Path, cap: u64) -> io::Result<Vec<u8>> {
    let len = check_regular(path, cap)?;
    let file = std::fs::File::open(path)?;
    let mut bytes = Vec::with_capacity(usize::try_from(len).unwrap_or(0));
    file.take(cap.saturating_add(1)).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > cap {
        return Err(too_large(bytes.len() as u64, cap));
    }
    Ok(bytes)
}

/// [`read_bounded`] as UTF-8 text.
pub fn read_bounded_text(path: &Path, cap: u64) -> io::Result<String> {
    String::from_utf8(read_bounded(path, cap)?).map_err(|e| {
        io::Error::new(
            io::ErrorKind::InvalidData,
            format!("is not UTF-8 text: {e}"),
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn special_files_and_oversized_ones_are_refused_without_reading() {
        let e = read_bounded(Path::new("/dev/zero"), 1 << 20).unwrap_err();
        assert!(e.to_string().contains("character device"), "{e}");
        let dir = tempfile::tempdir().unwrap();
        let e = read_bounded(dir.path(), 10).unwrap_err();
        assert!(e.to_string().contains("directory"), "{e}");
        let fifo = dir.path().join("p");
        let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
        // SAFETY: a NUL-terminated path.
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
        // returns at once: a FIFO is never opened
        let e = read_bounded(&fifo, 10).unwrap_err();
        assert!(e.to_string().contains("FIFO"), "{e}");
        let f = dir.path().join("f");
        std::fs::write(&f, [7u8; 11]).unwrap();
        let e = read_bounded(&f, 10).unwrap_err();
        assert!(e.to_string().contains("10-byte limit"), "{e}");
        assert_eq!(read_bounded(&f, 11).unwrap(), [7u8; 11]);
    }

    #[test]
    fn a_file_without_a_size_is_still_bounded() {
        // procfs reports 0 bytes and then yields more
        if let Ok(b) = read_bounded(Path::new("/proc/self/status"), 1 << 20) {
            assert!(!b.is_empty());
        }
        let e = read_bounded(Path::new("/proc/self/status"), 8).unwrap_err();
        assert!(e.to_string().contains("limit"), "{e}");
    }
}
