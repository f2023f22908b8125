//! Result files written whole or not at all.
//!
//! Contract of [`write`]: the bytes go to a temporary file beside the destination
//! (`.NAME.PID.partial`), are synced, and the temporary file is renamed over the destination.
//! A reader never sees a half-written or empty result; on any error (a full disk above all) the
//! temporary file is removed and the destination is left as it was (absent, or the previous
//! version). [`write_png`] encodes in memory first, then does the same.

use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};

/// Longest file name, in bytes, kept whole inside a temporary sibling's name: a temporary name
/// adds at most 30 bytes (`.` + `.ellipso-claim` or `.ellipso-new-PID` or `.PID.partial`, a
/// PID ≤ 10 digits) and a name may have 255 bytes (`NAME_MAX`), so 200 leaves room.
const SHORT_NAME_MAX: usize = 200;

/// `name` as it appears inside the names of its temporary siblings: whole up to
/// [`SHORT_NAME_MAX`] bytes; longer, its first 100 bytes (at a character boundary), `~` and a
/// 64-bit FNV-1a hash of the whole name in hex — so a 250-byte output name gets temporary names
/// the file system accepts, and two long names still get different ones.
pub fn short_name(name: &str) -> std::borrow::Cow<'_, str> {
    if name.len() <= SHORT_NAME_MAX {
        return name.into();
    }
    let mut cut = 100;
    while !name.is_char_boundary(cut) {
        cut -= 1;
    }
    let hash = name.bytes().fold(0xcbf2_9ce4_8422_2325_u64, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    });
    format!("{}~{hash:016x}", &name[..cut]).into()
}

/// The temporary name `path` is written under before the rename.
fn temporary(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    path.with_file_name(format!(
        ".{}.{}.partial",
        short_name(&name),
        std::process::id()
    ))
}

/// Writes `bytes` to `path` atomically (see the module doc).
pub fn write(path: impl AsRef<Path>, bytes: impl AsRef<[u8]>) -> std::io::Result<()> {
    let path = path.as_ref();
    let tmp = temporary(path);
    let result = (|| {
        let mut f = fs::File::create(&tmp)?;
        f.write_all(bytes.as_ref())?;
        f.sync_all()?;
        fs::rename(&tmp, path)
    })();
    if result.is_err() {
        let _ = fs::remove_file(&tmp);
    }
    result
}

/// Encodes an image as PNG in memory and writes it atomically.
pub fn write_png<P, C>(
    path: impl AsRef<Path>,
    image: &image::ImageBuffer<P, C>,
) -> std::io::Result<()>
where
    P: image::PixelWithColorType,
    [P::Subpixel]: image::EncodableLayout,
    C: std::ops::Deref<Target = [P::Subpixel]>,
{
    let mut png = Vec::new();
    image
        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .map_err(std::io::Error::other)?;
    write(path, png)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_whole_files_and_leaves_no_temporary_behind() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("r.json");
        write(&p, b"{}").unwrap();
        write(&p, b"{\"a\":1}").unwrap();
        assert_eq!(fs::read(&p).unwrap(), b"{\"a\":1}");
        let names: Vec<_> = fs::read_dir(dir.path()).unwrap().collect();
        assert_eq!(names.len(), 1);
    }

    #[test]
    fn a_failed_write_leaves_the_previous_version() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("r.json");
        write(&p, b"old").unwrap();
        // the temporary name is taken by a directory: the write fails before the rename
        fs::create_dir(temporary(&p)).unwrap();
        assert!(write(&p, b"new").is_err());
        assert_eq!(fs::read(&p).unwrap(), b"old");
    }

    #[test]
    fn pngs_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("i.png");
        let img =
            image::ImageBuffer::<image::Luma<u16>, _>::from_raw(2, 2, vec![0u16, 1, 2, 3]).unwrap();
        write_png(&p, &img).unwrap();
        let back = image::open(&p).unwrap().into_luma16();
        assert_eq!(back.into_raw(), vec![0, 1, 2, 3]);
    }
}
