//! GigE Vision (and, compile-checked, USB3 Vision) cameras through libaravis 0.8.
//!
//! Contract:
//! - **No discovery.** [`AravisCamera::open`] takes an explicit address or device id and refuses
//!   anything else; a numeric IP address (`"127.0.0.1"`, `"192.168.10.2"`) is opened by unicast
//!   and never falls back to a broadcast. Discovery lives only in [`discover_gige_cameras`], which
//!   broadcasts on every interface and must be called only behind an explicit opt-in CLI flag on a
//!   real rig — never from tests.
//! - `configure` sets exposure (µs), gain (dB), a raw-mosaic pixel format for the requested bit
//!   depth (polarisation names first), 1×1 binning/decimation and the trigger. Anything that
//!   would destroy the 2×2 polariser mosaic (binning, decimation, odd region offsets or sizes,
//!   camera-processed polarisation formats) is refused with an error naming it.
//! - External trigger: `TriggerSelector = FrameStart`, then `TriggerMode = On`, then
//!   `TriggerSource = Line0`, where the camera has those features; a camera without them (or
//!   without a `Line0` entry) gets a clear `Setting` error. aravis' fake camera has all three and
//!   then sends nothing (nothing drives its Line0); the tests check that and run free-running.
//! - Streaming uses a buffer pool sized for the camera's **datasheet** frame rate
//!   ([`AravisOptions::datasheet_fps`] × [`AravisOptions::pool_span_s`]), not the capture
//!   rate, so a burst never starves the pool. Buffers are read zero-copy and unpacked to `u16`.
//! - Status mapping: `Success` → [`FrameStatus::Complete`]; `MissingPackets` → delivered as
//!   [`FrameStatus::Flagged`]`("missing packets")` (kept, never fitted); any other status is
//!   counted in `other_failures` (with the status name in the log) and not delivered.
//! - Block ids are unwrapped with [`FrameIdUnwrapper`]; a repeated block id is dropped and
//!   counted as another failure. Frames are lost when the ids jump: a gap of `n` counts `n`
//!   `underruns` when libaravis reported underruns meanwhile (no free buffer: the consumer was
//!   too slow), else `n` frames "lost whole on the wire" in `other_failures` (logged). libaravis'
//!   own underrun statistic counts *packets*, not frames ([`AravisCamera::underrun_packets`]),
//!   so it is used as evidence only.
//! - `t_camera_ns` is the buffer's device timestamp (`None` when the camera gives 0), `t_host_us`
//!   the host clock at the moment the buffer was popped.
//! - The packet size granted and the socket-buffer mode (with `net.core.rmem_max`) are logged.

mod discover;
pub mod fake;
pub mod format;
mod settings;

pub use discover::{DiscoveredCamera, discover_gige_cameras};

use std::time::Duration;

use aravis::glib::prelude::Cast;
use aravis::prelude::*;
use aravis::{Buffer, BufferPayloadType, BufferStatus, GvStream, GvStreamSocketBuffer, Stream};

use super::frame_id::Unwrapped;
use super::unpack::{RawEncoding, unpack_into};
use super::{
    Camera, CameraCounters, CameraError, CameraInfo, CameraSettings, Frame, FrameIdUnwrapper,
    FrameMeta, FrameStatus,
};
use ellipso_session::time::HostClock;

/// Options of an aravis camera beyond the per-capture [`CameraSettings`].
#[derive(Debug, Clone, PartialEq)]
pub struct AravisOptions {
    /// Sensor region `(offset_x, offset_y, width, height)`, px; `None` keeps the camera's.
    pub region: Option<(u32, u32, u32, u32)>,
    /// GVSP packet size, bytes; `None` keeps the camera's (use ≤ 1500 without jumbo frames).
    pub packet_size_bytes: Option<u32>,
    /// Free-running frame rate, Hz; `None` keeps the camera's. Ignored with an external trigger.
    pub frame_rate_hz: Option<f64>,
    /// The camera's maximum frame rate from its datasheet at this region, Hz: sizes the pool.
    pub datasheet_fps: f64,
    /// Seconds of frames at `datasheet_fps` the buffer pool holds.
    pub pool_span_s: f64,
    /// Mosaic layout name reported in [`CameraInfo::layout`] (`mono_polar` for the IMX250MZR,
    /// `colour_polar` for the IMX250MYR): GenICam has no standard feature that says it.
    pub layout: String,
}

impl Default for AravisOptions {
    fn default() -> Self {
        Self {
            region: None,
            packet_size_bytes: None,
            frame_rate_hz: None,
            // IMX250MZR 5 MP polarisation camera over GigE: ~24 fps (8-bit), fewer at 12 bit
            datasheet_fps: 24.0,
            pool_span_s: 1.0,
            layout: "mono_polar".to_owned(),
        }
    }
}

/// Fewest and most buffers in the pool.
const POOL_MIN: usize = 8;
const POOL_MAX: usize = 512;

/// Buffers for `datasheet_fps × span_s`, clamped to `[POOL_MIN, POOL_MAX]` (a non-finite or
/// negative product gives the minimum).
pub fn pool_size(datasheet_fps: f64, span_s: f64) -> usize {
    let n = (datasheet_fps * span_s).ceil();
    if n.is_finite() && n > 0.0 {
        (n as usize).clamp(POOL_MIN, POOL_MAX)
    } else {
        POOL_MIN
    }
}

/// Whether `address` is something [`AravisCamera::open`] may open without any chance of a DNS
/// query or a discovery broadcast: a numeric IPv4/IPv6 address.
pub fn is_explicit_address(address: &str) -> bool {
    address.parse::<std::net::IpAddr>().is_ok()
}

/// A camera opened through libaravis.
pub struct AravisCamera {
    address: String,
    camera: aravis::Camera,
    options: AravisOptions,
    clock: HostClock,
    stream: Option<Stream>,
    encoding: RawEncoding,
    exposure_us: u32,
    gain_db: f32,
    unwrapper: FrameIdUnwrapper,
    counters: CameraCounters,
    skipped_by_id: u64,
    duplicates: u64,
    underrun_packets_at_last_gap: u64,
    underrun_packets_stopped: u64,
    failures_by_reason: std::collections::BTreeMap<String, u64>,
    geometry: (u32, u32, RawEncoding),
    payload_bytes: usize,
    scratch: Vec<u16>,
}

fn open_err(device: &str, reason: impl std::fmt::Display) -> CameraError {
    CameraError::Open {
        device: device.to_owned(),
        reason: reason.to_string(),
    }
}

impl AravisCamera {
    /// Opens the camera at `address`, a numeric IP address (no DNS, no discovery broadcast), and
    /// applies the region and packet size of `options`. Frame arrival times use `clock`.
    pub fn open(
        address: &str,
        options: AravisOptions,
        clock: HostClock,
    ) -> Result<Self, CameraError> {
        if !is_explicit_address(address) {
            return Err(open_err(
                address,
                "not a numeric IP address: names can reach DNS and then a discovery broadcast; \
                 give the camera's IP address",
            ));
        }
        let camera = aravis::Camera::new(Some(address)).map_err(|e| open_err(address, e))?;
        let mut cam = Self {
            address: address.to_owned(),
            camera,
            options,
            clock,
            stream: None,
            encoding: RawEncoding::Mono8,
            exposure_us: 0,
            gain_db: 0.0,
            unwrapper: FrameIdUnwrapper::new(),
            counters: CameraCounters::default(),
            skipped_by_id: 0,
            duplicates: 0,
            underrun_packets_at_last_gap: 0,
            underrun_packets_stopped: 0,
            failures_by_reason: std::collections::BTreeMap::new(),
            geometry: (0, 0, RawEncoding::Mono8),
            payload_bytes: 0,
            scratch: Vec::new(),
        };
        cam.apply_geometry()?;
        cam.encoding = cam.current_encoding()?;
        Ok(cam)
    }

    fn setting_err(&self, setting: &'static str, reason: impl std::fmt::Display) -> CameraError {
        CameraError::Setting {
            device: self.address.clone(),
            setting,
            reason: reason.to_string(),
        }
    }

    fn stream_err(&self, reason: impl std::fmt::Display) -> CameraError {
        CameraError::Stream {
            device: self.address.clone(),
            reason: reason.to_string(),
        }
    }

    fn has(&self, feature: &str) -> bool {
        self.camera.is_feature_available(feature).unwrap_or(false)
    }

    /// Frames whose block ids never arrived (gaps in the id sequence) so far.
    pub fn frames_skipped_by_id(&self) -> u64 {
        self.skipped_by_id
    }

    /// Repeated block ids dropped so far (also in `other_failures`).
    pub fn duplicate_block_ids(&self) -> u64 {
        self.duplicates
    }

    /// Frames not delivered, by reason (buffer status name, duplicate id, unpacking error…).
    pub fn failures_by_reason(&self) -> &std::collections::BTreeMap<String, u64> {
        &self.failures_by_reason
    }

    fn count_failure(&mut self, reason: String) {
        self.counters.other_failures += 1;
        *self.failures_by_reason.entry(reason).or_default() += 1;
    }

    /// The encoding frames are being decoded from.
    pub fn encoding(&self) -> RawEncoding {
        self.encoding
    }

    /// libaravis' own underrun count. In libaravis 0.8.26 it counts **packets** that found no
    /// free buffer (a lost 9-packet frame adds about 9), so it is evidence, not a frame count.
    pub fn underrun_packets(&self) -> u64 {
        self.underrun_packets_stopped + self.stream.as_ref().map_or(0, |s| s.statistics().2)
    }

    /// Unwraps a block id; `None` for a duplicate (counted) or an invalid id 0. A gap of `n`
    /// frames counts `n` underruns when libaravis saw underruns since the previous gap, else `n`
    /// frames lost whole on the wire (in `other_failures`).
    fn unwrap_id(&mut self, block_id: u64) -> Option<u64> {
        let block = u16::try_from(block_id).unwrap_or((block_id % 65_535) as u16);
        match self.unwrapper.push(block) {
            Unwrapped::Next { frame_id, skipped } => {
                self.skipped_by_id += skipped;
                if skipped > 0 {
                    let packets = self.underrun_packets();
                    if packets > self.underrun_packets_at_last_gap {
                        self.counters.underruns += skipped;
                    } else {
                        tracing::warn!(
                            camera = %self.address, frame_id, skipped,
                            "frames lost whole on the wire (id gap without underrun)"
                        );
                        self.counters.other_failures += skipped;
                        *self
                            .failures_by_reason
                            .entry("frame lost whole (id gap without underrun)".to_owned())
                            .or_default() += skipped;
                    }
                    self.underrun_packets_at_last_gap = packets;
                }
                Some(frame_id)
            }
            Unwrapped::Duplicate { frame_id } => {
                self.duplicates += 1;
                self.count_failure("duplicate block id".to_owned());
                tracing::warn!(camera = %self.address, block_id, frame_id, "duplicate block id dropped");
                None
            }
            Unwrapped::Invalid => None,
        }
    }

    /// Turns one popped buffer into a frame, or counts why not.
    fn take(&mut self, buffer: &Buffer) -> Option<Frame> {
        let t_host_us = self.clock.now();
        let status = buffer.status();
        let flag = match status {
            BufferStatus::Success => None,
            BufferStatus::MissingPackets => Some("missing packets"),
            other => {
                self.count_failure(format!("{other:?}"));
                // keep the id sequence in step so the failed frame is not also a gap
                let _ = self.unwrap_id(buffer.frame_id());
                tracing::warn!(camera = %self.address, status = ?other, "frame failed");
                return None;
            }
        };
        let frame_id = self.unwrap_id(buffer.frame_id())?;
        let (width, height, encoding) = if flag.is_some() {
            // a damaged frame: libaravis has not filled in its image part (asking for it logs
            // glib assertions), so the geometry the stream started with — the region and format
            // cannot change while streaming — describes the bytes
            self.geometry
        } else if matches!(
            buffer.payload_type(),
            BufferPayloadType::Image | BufferPayloadType::ExtendedChunkData
        ) {
            let width = u32::try_from(buffer.image_width()).unwrap_or(0);
            let height = u32::try_from(buffer.image_height()).unwrap_or(0);
            let code = buffer.image_pixel_format().raw();
            let Some(encoding) = format::encoding_of_pfnc(code) else {
                self.count_failure(format!("unsupported pixel format {code:#010x}"));
                return None;
            };
            (width, height, encoding)
        } else {
            self.count_failure(format!("payload type {:?}", buffer.payload_type()));
            return None;
        };
        let (ptr, received) = buffer.data();
        // libaravis reports 0 received bytes for a frame that missed packets; its memory is still
        // the whole buffer this camera allocated, holding what did arrive (and stale bytes where
        // packets are missing — which is why such frames are flagged and never fitted)
        let len = if flag.is_some() {
            self.payload_bytes
        } else {
            received.min(self.payload_bytes)
        };
        let bytes: &[u8] = if ptr.is_null() || len == 0 {
            &[]
        } else {
            // SAFETY: every buffer of this stream was allocated by `start` with exactly
            // `payload_bytes` bytes and `len` ≤ that; the memory stays valid and is not written
            // by libaravis until the buffer is pushed back; `buffer` is borrowed for this scope.
            unsafe { std::slice::from_raw_parts(ptr, len) }
        };
        if let Err(e) = unpack_into(encoding, bytes, width, height, &mut self.scratch) {
            tracing::warn!(camera = %self.address, error = %e, "frame could not be unpacked");
            self.count_failure(format!("unpack: {e}"));
            return None;
        }
        let status = match flag {
            None => {
                self.counters.completed += 1;
                FrameStatus::Complete
            }
            Some(reason) => {
                self.counters.missing_packets += 1;
                FrameStatus::Flagged(reason.to_owned())
            }
        };
        let t_camera_ns = Some(buffer.timestamp()).filter(|&t| t != 0);
        Some(Frame {
            meta: FrameMeta {
                frame_id,
                t_camera_ns,
                t_host_us,
                width,
                height,
                status,
                exposure_us: self.exposure_us,
                gain_db: self.gain_db,
            },
            pixels: self.scratch.clone(),
        })
    }

    /// Logs the socket buffer mode and the kernel's receive-buffer ceiling.
    fn log_socket_buffer(&self, gv: &GvStream, payload: usize) {
        let rmem_max = std::fs::read_to_string("/proc/sys/net/core/rmem_max")
            .ok()
            .and_then(|s| s.trim().parse::<usize>().ok());
        tracing::info!(
            camera = %self.address,
            mode = ?gv.socket_buffer(),
            requested_bytes = gv.socket_buffer_size(),
            rmem_max_bytes = ?rmem_max,
            payload_bytes = payload,
            "GVSP socket buffer"
        );
        if rmem_max.is_some_and(|m| m < payload) {
            tracing::warn!(
                camera = %self.address,
                "net.core.rmem_max is below one frame: the kernel will grant less than aravis asks \
                 (raise it with sysctl -w net.core.rmem_max=…) or run as root (packet socket)"
            );
        }
    }
}

impl Camera for AravisCamera {
    fn info(&self) -> CameraInfo {
        let model = self
            .camera
            .model_name()
            .map(|s| s.to_string())
            .unwrap_or_else(|_| "unknown".to_owned());
        let (_, _, w, h) = self.camera.region().unwrap_or((0, 0, 0, 0));
        CameraInfo {
            backend: "aravis",
            model,
            width: u32::try_from(w).unwrap_or(0),
            height: u32::try_from(h).unwrap_or(0),
            layout: self.options.layout.clone(),
            bit_depth: self.encoding.bit_depth(),
        }
    }

    fn configure(&mut self, settings: &CameraSettings) -> Result<(), CameraError> {
        if self.stream.is_some() {
            return Err(self.setting_err("settings", "cannot configure while streaming"));
        }
        self.select_pixel_format(settings.bit_depth)?;
        if self.camera.is_exposure_time_available().unwrap_or(false) {
            self.camera
                .set_exposure_time(f64::from(settings.exposure_us))
                .map_err(|e| self.setting_err("exposure", e))?;
        }
        if self.camera.is_gain_available().unwrap_or(false) {
            self.camera
                .set_gain(f64::from(settings.gain_db))
                .map_err(|e| self.setting_err("gain", e))?;
        }
        self.set_trigger(settings.external_trigger)?;
        // record what the camera actually took
        self.exposure_us = self
            .camera
            .exposure_time()
            .map(|e| e.round().clamp(0.0, f64::from(u32::MAX)) as u32)
            .unwrap_or(settings.exposure_us);
        self.gain_db = self
            .camera
            .gain()
            .map(|g| g as f32)
            .unwrap_or(settings.gain_db);
        Ok(())
    }

    fn start(&mut self) -> Result<(), CameraError> {
        if self.stream.is_some() {
            return Ok(());
        }
        let stream = self
            .camera
            .create_stream()
            .map_err(|e| self.stream_err(e))?;
        let payload = self.camera.payload().map_err(|e| self.stream_err(e))? as usize;
        if let Ok(gv) = stream.clone().downcast::<GvStream>() {
            gv.set_socket_buffer(GvStreamSocketBuffer::Auto);
            self.log_socket_buffer(&gv, payload);
        }
        let (_, _, w, h) = self.camera.region().map_err(|e| self.stream_err(e))?;
        self.geometry = (
            u32::try_from(w).unwrap_or(0),
            u32::try_from(h).unwrap_or(0),
            self.current_encoding()?,
        );
        let n = pool_size(self.options.datasheet_fps, self.options.pool_span_s);
        self.payload_bytes = payload;
        for _ in 0..n {
            stream.push_buffer(Buffer::new_allocate(payload));
        }
        tracing::info!(camera = %self.address, buffers = n, payload_bytes = payload, "stream pool");
        self.camera
            .set_acquisition_mode(aravis::AcquisitionMode::Continuous)
            .map_err(|e| self.stream_err(e))?;
        self.camera
            .start_acquisition()
            .map_err(|e| self.stream_err(e))?;
        self.stream = Some(stream);
        Ok(())
    }

    fn next_frame(&mut self, timeout: Duration) -> Result<Option<Frame>, CameraError> {
        let Some(stream) = self.stream.clone() else {
            return Err(self.stream_err("next_frame before start"));
        };
        let deadline = std::time::Instant::now() + timeout;
        loop {
            let left = deadline.saturating_duration_since(std::time::Instant::now());
            let left_us = u64::try_from(left.as_micros()).unwrap_or(u64::MAX);
            let Some(buffer) = stream.timeout_pop_buffer(left_us) else {
                self.counters.timeouts += 1;
                return Ok(None);
            };
            let frame = self.take(&buffer);
            stream.push_buffer(buffer);
            if frame.is_some() {
                return Ok(frame);
            }
            if left.is_zero() {
                self.counters.timeouts += 1;
                return Ok(None);
            }
        }
    }

    fn stop(&mut self) -> Result<(), CameraError> {
        if self.stream.is_none() {
            return Ok(());
        }
        let result = self
            .camera
            .stop_acquisition()
            .map_err(|e| self.stream_err(e));
        if let Some(stream) = self.stream.take() {
            let (completed, failures, underruns) = stream.statistics();
            self.underrun_packets_stopped += underruns;
            let gv = stream.downcast::<GvStream>().ok().map(|g| g.statistics());
            tracing::info!(
                camera = %self.address, completed, failures, underrun_packets = underruns,
                resent_and_missing_packets = ?gv, "stream statistics"
            );
        }
        result
    }

    fn counters(&self) -> CameraCounters {
        self.counters
    }
}

impl Drop for AravisCamera {
    fn drop(&mut self) {
        if self.stream.is_some() {
            let _ = self.stop();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pool_is_sized_from_the_datasheet_rate() {
        assert_eq!(pool_size(24.0, 1.0), 24);
        assert_eq!(pool_size(1000.0, 0.25), 250);
        assert_eq!(pool_size(2.0, 1.0), POOL_MIN);
        assert_eq!(pool_size(1e9, 1.0), POOL_MAX);
        assert_eq!(pool_size(f64::NAN, 1.0), POOL_MIN);
        assert_eq!(pool_size(-5.0, 1.0), POOL_MIN);
    }

    #[test]
    fn only_numeric_addresses_are_explicit() {
        assert!(is_explicit_address("127.0.0.1"));
        assert!(is_explicit_address("192.168.10.2"));
        assert!(is_explicit_address("::1"));
        assert!(!is_explicit_address("Fake_1"));
        assert!(!is_explicit_address("camera.local"));
        assert!(!is_explicit_address(""));
    }

    #[test]
    fn a_name_is_refused_before_reaching_aravis() {
        let Err(e) = AravisCamera::open("Fake_1", AravisOptions::default(), HostClock::new())
        else {
            panic!("a name must be refused");
        };
        assert!(e.to_string().contains("not a numeric IP address"), "{e}");
    }
}
