//! Raw mosaic frames as 16-bit grayscale PNG: lossless, viewable in any image viewer.
//!
//! Samples are stored unshifted (a 12-bit frame holds 0..=4095 in the 16-bit container), exactly as
//! the camera delivered them; the bit depth is in the manifest. Reading rejects anything that is
//! not a single-channel 16-bit PNG of the expected size.

use std::path::Path;

use image::{ImageBuffer, Luma};

use super::SessionError;

/// Writes `pixels` (row-major, `width × height`) to `path` as a 16-bit grayscale PNG. Returns
/// the CRC-64/XZ of the bytes written (`crate::provenance`).
pub fn write(path: &Path, width: u32, height: u32, pixels: &[u16]) -> Result<u64, SessionError> {
    let bad = |reason: String| SessionError::BadFrame {
        path: path.to_path_buf(),
        reason,
    };
    if pixels.len() != width as usize * height as usize {
        return Err(bad(format!(
            "{} samples for a {width}×{height} frame",
            pixels.len()
        )));
    }
    let img: ImageBuffer<Luma<u16>, &[u16]> =
        ImageBuffer::from_raw(width, height, pixels).ok_or_else(|| bad("buffer size".into()))?;
    let mut png = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .map_err(|e| bad(e.to_string()))?;
    std::fs::write(path, &png).map_err(SessionError::io(path))?;
    Ok(crate::checksum::crc64(&png))
}

/// Reads a 16-bit grayscale PNG: `(width, height, pixels)`.
pub fn read(path: &Path) -> Result<(u32, u32, Vec<u16>), SessionError> {
    decode(path, &read_bytes(path)?)
}

/// A frame file's bytes: a regular file of a frame's size at most (a FIFO or device never
/// opened).
pub fn read_bytes(path: &Path) -> Result<Vec<u8>, SessionError> {
    ellipso_model::file_io::check_regular(path, ellipso_model::file_io::caps::FRAME)
        .map_err(SessionError::io(path))?;
    ellipso_model::file_io::read_bounded(path, ellipso_model::file_io::caps::FRAME)
        .map_err(SessionError::io(path))
}

/// A frame file's bytes ([`read_bytes`]) and their CRC-64/XZ: the one place a session hashes
/// a frame file it reads (`Session::check_frames`, `Session::load_frame`).
pub fn read_hashed(path: &Path) -> Result<(Vec<u8>, u64), SessionError> {
    let bytes = read_bytes(path)?;
    let crc64 = crate::checksum::crc64(&bytes);
    Ok((bytes, crc64))
}

/// Decodes the bytes of the 16-bit grayscale PNG at `path` (named in errors), within the
/// largest sensor the manifest allows: `(width, height, pixels)`.
pub fn decode(path: &Path, bytes: &[u8]) -> Result<(u32, u32, Vec<u16>), SessionError> {
    let bad = |reason: String| SessionError::BadFrame {
        path: path.to_path_buf(),
        reason,
    };
    let mut reader = image::ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .map_err(SessionError::io(path))?;
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(crate::manifest::MAX_SIDE_PX);
    limits.max_image_height = Some(crate::manifest::MAX_SIDE_PX);
    reader.limits(limits);
    let img = reader
        .decode()
        .map_err(|e| bad(format!("not a readable PNG: {e}")))?;
    match img {
        image::DynamicImage::ImageLuma16(buf) => {
            let (w, h) = buf.dimensions();
            Ok((w, h, buf.into_raw()))
        }
        other => Err(bad(format!(
            "expected a single-channel 16-bit raw mosaic, found {:?}",
            other.color()
        ))),
    }
}
