//! The sensor calibration file (docs/sensor-calibration.md, "File format"):
//!
//! ```text
//! 16 bytes  magic  "ELLIPSO-SENSCAL\n"
//!  4 bytes  header length H, u32 little-endian
//!  H bytes  header, UTF-8 JSON (SensorHeader: format, version, sensor, gain_db, figures, source)
//!  W·H·16   one record per raw pixel, row-major: dark_dn, a0, a1, a2 as f32 little-endian
//!  8 bytes  CRC-64/XZ of every byte before it, u64 little-endian
//! ```
//!
//! Contract: [`write`] writes whole or not at all (through `ellipso_report`'s atomic file);
//! [`read`] checks, in this order, the size cap, the magic, the header, the version, the record
//! count against the header's sensor and the checksum, and when asked for an identity, that it
//! matches — each failure a [`SensorCalibrationError`] naming the file and what is wrong.
//! [`SensorCalibration::check_frame`] refuses a frame of another size or layout.

use std::path::{Path, PathBuf};

use super::{FORMAT, PixelRecord, SensorCalibration, SensorHeader, VERSION};
use crate::RawFrame;

/// The first 16 bytes of every calibration file.
pub const MAGIC: &[u8; 16] = b"ELLIPSO-SENSCAL\n";
/// Largest file read: a 16 384² sensor's records and a generous header.
const MAX_FILE_BYTES: u64 = 16_384 * 16_384 * 16 + (16 << 20);
const CRC: crc::Crc<u64> = crc::Crc::<u64>::new(&crc::CRC_64_XZ);

/// Why a calibration file cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum SensorCalibrationError {
    /// The file cannot be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// Not a sensor calibration file at all.
    #[error("{path}: not an ellipso sensor calibration (no 'ELLIPSO-SENSCAL' magic)")]
    NotACalibration {
        /// The file.
        path: PathBuf,
    },
    /// A version this build does not read.
    #[error("{path}: sensor calibration version {found}; this build reads version {VERSION}")]
    Version {
        /// The file.
        path: PathBuf,
        /// The version found.
        found: u32,
    },
    /// Truncated, a bad header, or a checksum that does not match.
    #[error("{path}: corrupt sensor calibration: {what}")]
    Corrupt {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        what: String,
    },
    /// The file is not the one the rig file names.
    #[error(
        "{path}: sensor calibration {found} is not the one the rig file or session names \
         ({expected}); recalibrate or update the rig file"
    )]
    Stale {
        /// The file.
        path: PathBuf,
        /// The identity asked for.
        expected: String,
        /// The file's identity.
        found: String,
    },
    /// The frame is of another size than the calibrated sensor.
    #[error(
        "sensor calibration {id} is for a {cal_width}×{cal_height} sensor, the frame is \
         {frame_width}×{frame_height}"
    )]
    SensorSize {
        /// Calibration identity.
        id: String,
        /// Calibrated width.
        cal_width: u32,
        /// Calibrated height.
        cal_height: u32,
        /// Frame width.
        frame_width: u32,
        /// Frame height.
        frame_height: u32,
    },
    /// The frame has another mosaic layout.
    #[error("sensor calibration {id} is for a {cal} sensor, the frame is {frame}")]
    Layout {
        /// Calibration identity.
        id: String,
        /// Calibrated layout.
        cal: String,
        /// Frame layout.
        frame: String,
    },
}

fn corrupt(path: &Path, what: impl Into<String>) -> SensorCalibrationError {
    SensorCalibrationError::Corrupt {
        path: path.to_path_buf(),
        what: what.into(),
    }
}

/// The bytes of `cal`'s file (checksum included) and the checksum.
pub fn to_bytes(cal: &SensorCalibration) -> (Vec<u8>, u64) {
    let header = serde_json::to_vec(&cal.header).unwrap_or_default();
    let mut bytes = Vec::with_capacity(24 + header.len() + cal.pixels.len() * 16);
    bytes.extend_from_slice(MAGIC);
    bytes.extend_from_slice(&(header.len() as u32).to_le_bytes());
    bytes.extend_from_slice(&header);
    for p in &cal.pixels {
        for v in [p.dark_dn, p.analysis[0], p.analysis[1], p.analysis[2]] {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
    }
    let sum = CRC.checksum(&bytes);
    bytes.extend_from_slice(&sum.to_le_bytes());
    (bytes, sum)
}

/// Writes `cal` to `path` whole or not at all; returns its identity (and sets `cal.checksum`).
pub fn write(cal: &mut SensorCalibration, path: &Path) -> Result<String, SensorCalibrationError> {
    let (bytes, sum) = to_bytes(cal);
    cal.checksum = sum;
    ellipso_report::atomic_file::write(path, &bytes).map_err(|source| {
        SensorCalibrationError::Io {
            path: path.to_path_buf(),
            source,
        }
    })?;
    Ok(cal.id())
}

/// Whether `path` starts with the calibration magic (how `ellipso polar --calibration` tells
/// a sensor calibration from a per-analyser JSON one).
pub fn is_sensor_calibration(path: &Path) -> bool {
    use std::io::Read;
    let mut head = [0u8; 16];
    std::fs::File::open(path)
        .and_then(|mut f| f.read_exact(&mut head))
        .is_ok()
        && &head == MAGIC
}

/// Reads and checks `path` (module doc); `expected_id`: the identity a rig file names.
pub fn read(
    path: &Path,
    expected_id: Option<&str>,
) -> Result<SensorCalibration, SensorCalibrationError> {
    let io = |source| SensorCalibrationError::Io {
        path: path.to_path_buf(),
        source,
    };
    ellipso_model::file_io::check_regular(path, MAX_FILE_BYTES).map_err(io)?;
    let bytes = std::fs::read(path).map_err(io)?;
    from_bytes(&bytes, path, expected_id)
}

/// [`read`] on bytes already in memory (`path` names them in errors).
pub fn from_bytes(
    bytes: &[u8],
    path: &Path,
    expected_id: Option<&str>,
) -> Result<SensorCalibration, SensorCalibrationError> {
    if bytes.len() < 16 || &bytes[..16] != MAGIC {
        return Err(SensorCalibrationError::NotACalibration {
            path: path.to_path_buf(),
        });
    }
    let Some(len) = bytes.get(16..20) else {
        return Err(corrupt(path, "truncated before the header"));
    };
    let header_len = u32::from_le_bytes([len[0], len[1], len[2], len[3]]) as usize;
    let Some(header_bytes) = bytes.get(20..20 + header_len) else {
        return Err(corrupt(path, "truncated inside the header"));
    };
    // the version first, so a newer file's other fields are not reported as corrupt
    let value: serde_json::Value =
        serde_json::from_slice(header_bytes).map_err(|e| corrupt(path, format!("header: {e}")))?;
    if value.get("format").and_then(|v| v.as_str()) != Some(FORMAT) {
        return Err(corrupt(path, format!("header: format is not '{FORMAT}'")));
    }
    let version = value.get("version").and_then(|v| v.as_u64()).unwrap_or(0);
    if version != u64::from(VERSION) {
        return Err(SensorCalibrationError::Version {
            path: path.to_path_buf(),
            found: version as u32,
        });
    }
    let header: SensorHeader =
        serde_json::from_value(value).map_err(|e| corrupt(path, format!("header: {e}")))?;
    header
        .sensor
        .check()
        .map_err(|(field, what)| corrupt(path, format!("header: {field}: {what}")))?;
    let count = header.sensor.width as usize * header.sensor.height as usize;
    let start = 20 + header_len;
    let expected_len = start + count * 16 + 8;
    if bytes.len() != expected_len {
        return Err(corrupt(
            path,
            format!(
                "{} bytes, a {}×{} calibration has {expected_len}",
                bytes.len(),
                header.sensor.width,
                header.sensor.height
            ),
        ));
    }
    let body = &bytes[..expected_len - 8];
    let tail = &bytes[expected_len - 8..];
    let stored = u64::from_le_bytes(tail.try_into().unwrap_or([0; 8]));
    let sum = CRC.checksum(body);
    if sum != stored {
        return Err(corrupt(
            path,
            format!("checksum {sum:016x} does not match the stored {stored:016x}"),
        ));
    }
    let id = format!("{sum:016x}");
    if let Some(expected) = expected_id
        && expected != id
    {
        return Err(SensorCalibrationError::Stale {
            path: path.to_path_buf(),
            expected: expected.to_string(),
            found: id,
        });
    }
    let f = |o: usize| f32::from_le_bytes([body[o], body[o + 1], body[o + 2], body[o + 3]]);
    let pixels = (0..count)
        .map(|i| {
            let o = start + 16 * i;
            PixelRecord {
                dark_dn: f(o),
                analysis: [f(o + 4), f(o + 8), f(o + 12)],
            }
        })
        .collect();
    Ok(SensorCalibration {
        header,
        pixels,
        checksum: sum,
    })
}

impl SensorCalibration {
    /// Refuses a frame of another size or layout than the calibrated sensor.
    pub fn check_frame<D: AsRef<[u16]>>(
        &self,
        frame: &RawFrame<D>,
    ) -> Result<(), SensorCalibrationError> {
        let s = &self.header.sensor;
        if (frame.width(), frame.height()) != (s.width, s.height) {
            return Err(SensorCalibrationError::SensorSize {
                id: self.id(),
                cal_width: s.width,
                cal_height: s.height,
                frame_width: frame.width(),
                frame_height: frame.height(),
            });
        }
        if frame.layout() != s.layout {
            return Err(SensorCalibrationError::Layout {
                id: self.id(),
                cal: ellipso_session::manifest::layout_name(s.layout).into(),
                frame: ellipso_session::manifest::layout_name(frame.layout()).into(),
            });
        }
        Ok(())
    }
}
