//! UVC / V4L2 cameras (`/dev/videoN`) through the `v4l` crate. Compile-checked in CI; capture
//! itself needs a device, which CI machines do not have.
//!
//! Contract:
//! - [`V4lCamera::open`] opens a device **by path**; an absent device is a [`CameraError::Open`]
//!   naming the path and saying it does not exist. Nothing is enumerated.
//! - Only raw mono formats are accepted (see [`encoding_of_fourcc`]): `GREY` (8 bit), `Y10 `,
//!   `Y12 `, `Y16 ` (little-endian `u16` containers). MIPI-packed (`Y10P`, `Y12P`) and colour
//!   or compressed formats are refused by name. The frame size must keep the 2×2 polariser mosaic
//!   whole (even width and height).
//! - Rows may be padded by the driver (`bytesperline` > width × bytes per sample):
//!   [`unpack_strided`] drops the padding.
//! - Exposure goes to `V4L2_CID_EXPOSURE_ABSOLUTE` (100 µs units) when the device has it. V4L2
//!   gain units are driver-defined, not dB: a non-zero `gain_db` is refused rather than guessed.
//!   UVC has no standard external trigger: `external_trigger = true` is refused.
//! - Frame ids come from the driver's 32-bit buffer sequence, unwrapped to 64 bits; a sequence
//!   gap means the driver had no free buffer and dropped frames: counted as **underruns**. A
//!   buffer the driver marks `ERROR` (incomplete transfer) is delivered
//!   [`FrameStatus::Flagged`] and counted under `missing_packets`.
//! - `t_camera_ns` is the driver's buffer timestamp (usually `CLOCK_MONOTONIC`), `t_host_us` the
//!   host clock at dequeue.

use std::path::{Path, PathBuf};
use std::time::Duration;

use v4l::buffer::{Flags as BufferFlags, Type as BufferType};
use v4l::io::traits::CaptureStream;
use v4l::video::Capture;
use v4l::{Device, FourCC};

use super::unpack::{RawEncoding, UnpackError, check_mosaic_region, unpack_into};
use super::{
    Camera, CameraCounters, CameraError, CameraInfo, CameraSettings, Frame, FrameMeta, FrameStatus,
};
use ellipso_session::time::HostClock;

/// `V4L2_CID_EXPOSURE_ABSOLUTE` (units of 100 µs).
const CID_EXPOSURE_ABSOLUTE: u32 = 0x009a_0902;
/// `V4L2_CID_EXPOSURE_AUTO` (1 = manual).
const CID_EXPOSURE_AUTO: u32 = 0x009a_0901;
/// Buffers in the mmap pool.
const POOL_BUFFERS: u32 = 8;

/// The encoding behind a V4L2 fourcc, if ellipso reads it raw.
pub fn encoding_of_fourcc(fourcc: &[u8; 4]) -> Option<RawEncoding> {
    match fourcc {
        b"GREY" => Some(RawEncoding::Mono8),
        b"Y10 " => Some(RawEncoding::Mono10),
        b"Y12 " => Some(RawEncoding::Mono12),
        b"Y16 " => Some(RawEncoding::Mono16),
        _ => None,
    }
}

/// Fourccs to try for a requested bit depth, best first.
pub fn preferred_fourccs(bit_depth: u8) -> &'static [&'static [u8; 4]] {
    match bit_depth {
        8 => &[b"GREY"],
        10 => &[b"Y10 "],
        12 => &[b"Y12 ", b"Y16 "],
        16 => &[b"Y16 "],
        _ => &[],
    }
}

/// Unpacks a frame whose rows are `stride_bytes` apart (`stride_bytes` ≥ the packed row size),
/// dropping the row padding. `out` is cleared first.
pub fn unpack_strided(
    encoding: RawEncoding,
    bytes: &[u8],
    width: u32,
    height: u32,
    stride_bytes: usize,
    out: &mut Vec<u16>,
) -> Result<(), UnpackError> {
    let row = encoding.bytes_for(width as usize);
    if stride_bytes <= row {
        return unpack_into(encoding, bytes, width, height, out);
    }
    let rows = height as usize;
    // the last row need not carry its padding
    let needed = stride_bytes * rows.saturating_sub(1) + row;
    if bytes.len() < needed {
        return Err(UnpackError::Truncated {
            encoding: encoding.name(),
            width,
            height,
            needed,
            got: bytes.len(),
        });
    }
    let mut packed = Vec::with_capacity(row * rows);
    for r in 0..rows {
        packed.extend_from_slice(&bytes[r * stride_bytes..r * stride_bytes + row]);
    }
    unpack_into(encoding, &packed, width, height, out)
}

/// Unwraps the driver's 32-bit sequence numbers: `(frame_id, frames skipped before it)`, or
/// `None` for a repeated sequence number.
#[derive(Debug, Clone, Default)]
pub struct SequenceUnwrapper {
    last: Option<(u32, u64)>,
}

impl SequenceUnwrapper {
    /// Feeds the next sequence number.
    pub fn push(&mut self, sequence: u32) -> Option<(u64, u64)> {
        let Some((last_seq, last_id)) = self.last else {
            self.last = Some((sequence, 0));
            return Some((0, 0));
        };
        let advance = u64::from(sequence.wrapping_sub(last_seq));
        if advance == 0 {
            return None;
        }
        let id = last_id + advance;
        self.last = Some((sequence, id));
        Some((id, advance - 1))
    }
}

/// A V4L2 capture device.
pub struct V4lCamera {
    path: PathBuf,
    device: Device,
    stream: Option<v4l::io::mmap::Stream<'static>>,
    clock: HostClock,
    width: u32,
    height: u32,
    stride_bytes: usize,
    encoding: Option<RawEncoding>,
    exposure_us: u32,
    gain_db: f32,
    sequence: SequenceUnwrapper,
    counters: CameraCounters,
    scratch: Vec<u16>,
}

impl V4lCamera {
    /// Opens the device at `path` (e.g. `/dev/video0`). Frame arrival times use `clock`.
    pub fn open(path: impl AsRef<Path>, clock: HostClock) -> Result<Self, CameraError> {
        let path = path.as_ref().to_path_buf();
        let device = Device::with_path(&path).map_err(|e| CameraError::Open {
            device: path.display().to_string(),
            reason: if e.kind() == std::io::ErrorKind::NotFound {
                "no such device (is the camera plugged in and its driver loaded?)".to_owned()
            } else {
                e.to_string()
            },
        })?;
        let mut cam = Self {
            path,
            device,
            stream: None,
            clock,
            width: 0,
            height: 0,
            stride_bytes: 0,
            encoding: None,
            exposure_us: 0,
            gain_db: 0.0,
            sequence: SequenceUnwrapper::default(),
            counters: CameraCounters::default(),
            scratch: Vec::new(),
        };
        if let Ok(f) = cam.device.format() {
            cam.adopt(&f);
        }
        Ok(cam)
    }

    fn name(&self) -> String {
        self.path.display().to_string()
    }

    fn setting_err(&self, setting: &'static str, reason: impl std::fmt::Display) -> CameraError {
        CameraError::Setting {
            device: self.name(),
            setting,
            reason: reason.to_string(),
        }
    }

    fn stream_err(&self, reason: impl std::fmt::Display) -> CameraError {
        CameraError::Stream {
            device: self.name(),
            reason: reason.to_string(),
        }
    }

    fn adopt(&mut self, f: &v4l::Format) {
        self.width = f.width;
        self.height = f.height;
        self.stride_bytes = f.stride as usize;
        self.encoding = encoding_of_fourcc(&f.fourcc.repr);
    }
}

impl Camera for V4lCamera {
    fn info(&self) -> CameraInfo {
        let model = self
            .device
            .query_caps()
            .map(|c| c.card)
            .unwrap_or_else(|_| "unknown".to_owned());
        CameraInfo {
            backend: "v4l",
            model,
            width: self.width,
            height: self.height,
            layout: "mono_polar".to_owned(),
            bit_depth: self.encoding.map_or(0, RawEncoding::bit_depth),
        }
    }

    fn configure(&mut self, settings: &CameraSettings) -> Result<(), CameraError> {
        if self.stream.is_some() {
            return Err(self.setting_err("settings", "cannot configure while streaming"));
        }
        if settings.external_trigger {
            return Err(self.setting_err(
                "external trigger",
                "V4L2/UVC has no standard external trigger control",
            ));
        }
        if settings.gain_db != 0.0 {
            return Err(self.setting_err(
                "gain",
                "V4L2 gain units are driver-defined, not dB; leave gain_db at 0",
            ));
        }
        let offered: Vec<[u8; 4]> = self
            .device
            .enum_formats()
            .map_err(|e| self.setting_err("pixel format", e))?
            .into_iter()
            .map(|d| d.fourcc.repr)
            .collect();
        let Some(fourcc) = preferred_fourccs(settings.bit_depth)
            .iter()
            .find(|f| offered.contains(f))
        else {
            let names: Vec<String> = offered
                .iter()
                .map(|f| String::from_utf8_lossy(f).into_owned())
                .collect();
            return Err(self.setting_err(
                "pixel format",
                format!(
                    "no raw {}-bit mono format among {names:?} (ellipso reads GREY, Y10, Y12, Y16)",
                    settings.bit_depth
                ),
            ));
        };
        let mut format = self
            .device
            .format()
            .map_err(|e| self.setting_err("pixel format", e))?;
        format.fourcc = FourCC::new(fourcc);
        let granted = self
            .device
            .set_format(&format)
            .map_err(|e| self.setting_err("pixel format", e))?;
        check_mosaic_region(0, 0, granted.width, granted.height)
            .map_err(|r| self.setting_err("frame size", r))?;
        self.adopt(&granted);
        if self.encoding.is_none() {
            return Err(self.setting_err(
                "pixel format",
                format!("driver granted {} instead", granted.fourcc),
            ));
        }
        // exposure: manual mode, then the absolute time in 100 µs units, where the device has it
        let has = |id: u32| {
            self.device
                .query_controls()
                .map(|c| c.iter().any(|d| d.id == id))
                .unwrap_or(false)
        };
        if has(CID_EXPOSURE_ABSOLUTE) {
            if has(CID_EXPOSURE_AUTO) {
                let manual = v4l::control::Control {
                    id: CID_EXPOSURE_AUTO,
                    value: v4l::control::Value::Integer(1),
                };
                self.device
                    .set_control(manual)
                    .map_err(|e| self.setting_err("exposure", e))?;
            }
            let units = i64::from(settings.exposure_us.div_ceil(100).max(1));
            let ctrl = v4l::control::Control {
                id: CID_EXPOSURE_ABSOLUTE,
                value: v4l::control::Value::Integer(units),
            };
            self.device
                .set_control(ctrl)
                .map_err(|e| self.setting_err("exposure", e))?;
            self.exposure_us = u32::try_from(units * 100).unwrap_or(u32::MAX);
        } else {
            tracing::warn!(device = %self.name(), "no absolute exposure control: exposure unchanged");
            self.exposure_us = settings.exposure_us;
        }
        self.gain_db = 0.0;
        Ok(())
    }

    fn start(&mut self) -> Result<(), CameraError> {
        if self.stream.is_some() {
            return Ok(());
        }
        if self.encoding.is_none() {
            return Err(self.stream_err("start before a raw mono format was configured"));
        }
        let stream = v4l::io::mmap::Stream::with_buffers(
            &self.device,
            BufferType::VideoCapture,
            POOL_BUFFERS,
        )
        .map_err(|e| self.stream_err(e))?;
        self.stream = Some(stream);
        Ok(())
    }

    fn next_frame(&mut self, timeout: Duration) -> Result<Option<Frame>, CameraError> {
        let name = self.name();
        let Some(encoding) = self.encoding else {
            return Err(self.stream_err("no raw format configured"));
        };
        let Some(stream) = self.stream.as_mut() else {
            return Err(self.stream_err("next_frame before start"));
        };
        stream.set_timeout(timeout);
        let (bytes, meta) = match stream.next() {
            Ok(x) => x,
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {
                self.counters.timeouts += 1;
                return Ok(None);
            }
            Err(e) => {
                return Err(CameraError::Stream {
                    device: name,
                    reason: e.to_string(),
                });
            }
        };
        let t_host_us = self.clock.now();
        let used = (meta.bytesused as usize).min(bytes.len());
        let unpacked = unpack_strided(
            encoding,
            &bytes[..used],
            self.width,
            self.height,
            self.stride_bytes,
            &mut self.scratch,
        );
        let corrupted = meta.flags.contains(BufferFlags::ERROR);
        let sequence = meta.sequence;
        let t_camera_ns = u64::try_from(meta.timestamp.sec)
            .ok()
            .zip(u64::try_from(meta.timestamp.usec).ok())
            .map(|(s, us)| s * 1_000_000_000 + us * 1_000)
            .filter(|&t| t != 0);
        if let Err(e) = unpacked {
            self.counters.other_failures += 1;
            tracing::warn!(device = %name, error = %e, "frame could not be unpacked");
            return Ok(None);
        }
        let Some((frame_id, skipped)) = self.sequence.push(sequence) else {
            self.counters.other_failures += 1;
            tracing::warn!(device = %name, sequence, "repeated buffer sequence dropped");
            return Ok(None);
        };
        self.counters.underruns += skipped;
        let status = if corrupted {
            self.counters.missing_packets += 1;
            FrameStatus::Flagged("driver marked the buffer corrupted".to_owned())
        } else {
            self.counters.completed += 1;
            FrameStatus::Complete
        };
        Ok(Some(Frame {
            meta: FrameMeta {
                frame_id,
                t_camera_ns,
                t_host_us,
                width: self.width,
                height: self.height,
                status,
                exposure_us: self.exposure_us,
                gain_db: self.gain_db,
            },
            pixels: self.scratch.clone(),
        }))
    }

    fn stop(&mut self) -> Result<(), CameraError> {
        // dropping the stream issues STREAMOFF and unmaps the buffers
        self.stream = None;
        Ok(())
    }

    fn counters(&self) -> CameraCounters {
        self.counters
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fourccs_map_to_encodings() {
        assert_eq!(encoding_of_fourcc(b"GREY"), Some(RawEncoding::Mono8));
        assert_eq!(encoding_of_fourcc(b"Y10 "), Some(RawEncoding::Mono10));
        assert_eq!(encoding_of_fourcc(b"Y12 "), Some(RawEncoding::Mono12));
        assert_eq!(encoding_of_fourcc(b"Y16 "), Some(RawEncoding::Mono16));
        // MIPI packing, colour and compressed formats are not raw mono containers
        for f in [b"Y12P", b"Y10P", b"YUYV", b"MJPG", b"RGGB"] {
            assert_eq!(encoding_of_fourcc(f), None);
        }
        for depth in [8u8, 10, 12, 16] {
            for f in preferred_fourccs(depth) {
                assert!(encoding_of_fourcc(f).unwrap().bit_depth() >= depth);
            }
        }
    }

    #[test]
    fn grey_y12_y16_unpack() {
        let mut out = Vec::new();
        unpack_strided(RawEncoding::Mono8, &[7, 8, 9, 10], 2, 2, 2, &mut out).unwrap();
        assert_eq!(out, vec![7, 8, 9, 10]);
        unpack_strided(
            RawEncoding::Mono12,
            &[0xff, 0x0f, 0x01, 0x00],
            2,
            1,
            4,
            &mut out,
        )
        .unwrap();
        assert_eq!(out, vec![4095, 1]);
        unpack_strided(
            RawEncoding::Mono16,
            &[0xff, 0xff, 0x00, 0x80],
            1,
            2,
            2,
            &mut out,
        )
        .unwrap();
        assert_eq!(out, vec![0xffff, 0x8000]);
    }

    #[test]
    fn row_padding_is_dropped() {
        // 2×2 Y16 with 6-byte rows (2 bytes of padding), the last row unpadded
        let bytes = [1, 0, 2, 0, 0xee, 0xee, 3, 0, 4, 0];
        let mut out = Vec::new();
        unpack_strided(RawEncoding::Mono16, &bytes, 2, 2, 6, &mut out).unwrap();
        assert_eq!(out, vec![1, 2, 3, 4]);
        let e = unpack_strided(RawEncoding::Mono16, &bytes[..9], 2, 2, 6, &mut out).unwrap_err();
        assert!(e.to_string().contains("needs 10 bytes"), "{e}");
    }

    #[test]
    fn sequence_gaps_are_underruns_and_wrap() {
        let mut s = SequenceUnwrapper::default();
        assert_eq!(s.push(u32::MAX - 1), Some((0, 0)));
        assert_eq!(s.push(u32::MAX), Some((1, 0)));
        assert_eq!(s.push(0), Some((2, 0)));
        assert_eq!(s.push(3), Some((5, 2)));
        assert_eq!(s.push(3), None);
    }

    #[test]
    fn mosaic_size_is_checked() {
        assert!(check_mosaic_region(0, 0, 2448, 2048).is_ok());
        assert!(check_mosaic_region(0, 0, 2447, 2048).is_err());
    }

    #[test]
    fn absent_device_is_a_clear_error() {
        let path = "/dev/video-ellipso-does-not-exist";
        let Err(e) = V4lCamera::open(path, HostClock::new()) else {
            panic!("{path} must not open");
        };
        let msg = e.to_string();
        assert!(
            msg.contains(path) && msg.contains("no such device"),
            "{msg}"
        );
    }
}
