//! Cameras: one trait for every frame source, and the backends behind it.
//!
//! Contract of [`Camera`]:
//! - Frames carry a monotonic 64-bit [`FrameMeta::frame_id`] (backends with 16-bit GigE block ids
//!   unwrap them with [`FrameIdUnwrapper`]), the camera's own timestamp where it has one, and the
//!   host arrival time in the capture's [`HostClock`](ellipso_session::time::HostClock).
//! - A frame that arrived damaged is delivered **flagged** ([`FrameStatus::Flagged`]) so it can be
//!   recorded and counted, and is never fitted.
//! - [`CameraCounters`] keeps completed frames, missing packets, underruns (the application was too
//!   slow) and timeouts apart, as aravis does: they have different causes and different cures.
//! - `next_frame` returns `Ok(None)` on timeout (counted), never blocks forever.
//!
//! Backends: `sim` (in-process simulator, default), `aravis`
//! (GigE/USB3 Vision, cargo feature), `v4l` (UVC, cargo feature).

#[cfg(feature = "aravis")]
pub mod aravis;
pub mod frame_id;
pub mod sim;
pub mod unpack;
#[cfg(feature = "v4l")]
pub mod v4l;

use std::time::Duration;

pub use frame_id::FrameIdUnwrapper;

use ellipso_session::time::HostTimeUs;

/// Completion of a delivered frame.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FrameStatus {
    /// Every pixel arrived.
    Complete,
    /// Damaged: kept and counted, never fitted.
    Flagged(String),
}

/// Metadata of one frame.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameMeta {
    /// Monotonic 64-bit frame id.
    pub frame_id: u64,
    /// The camera's timestamp, ns of its own clock, if it provides one.
    pub t_camera_ns: Option<u64>,
    /// When the frame was complete on the host.
    pub t_host_us: HostTimeUs,
    /// Width, px.
    pub width: u32,
    /// Height, px.
    pub height: u32,
    /// Completion.
    pub status: FrameStatus,
    /// Exposure it was taken with, µs.
    pub exposure_us: u32,
    /// Gain, dB.
    pub gain_db: f32,
}

/// A raw mosaic frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    /// Metadata.
    pub meta: FrameMeta,
    /// Raw samples, row-major, unshifted (12-bit data in 0..=4095).
    pub pixels: Vec<u16>,
}

/// Static description of a camera.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraInfo {
    /// Backend name: `sim`, `aravis`, `v4l`.
    pub backend: &'static str,
    /// Model / identifier.
    pub model: String,
    /// Sensor width, px.
    pub width: u32,
    /// Sensor height, px.
    pub height: u32,
    /// Mosaic layout name (`mono_polar`, `colour_polar`).
    pub layout: String,
    /// Significant bits per sample.
    pub bit_depth: u8,
}

/// Settings applied before streaming.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraSettings {
    /// Exposure, µs.
    pub exposure_us: u32,
    /// Analogue gain, dB.
    pub gain_db: f32,
    /// Bits per sample requested (8, 10, 12, 16).
    pub bit_depth: u8,
    /// Expose on the external trigger input (the flash rig) rather than free-running.
    pub external_trigger: bool,
}

/// One reading of the camera's timestamp counter, bracketed by host times: the camera-side
/// half of a camera→host clock model (GigE Vision's `GevTimestampControlLatch` /
/// `GevTimestampValue`, SFNC's `TimestampLatch` / `TimestampLatchValue`). The counter was read
/// somewhere between `t_host_before` and `t_host_after`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct CameraClockSample {
    /// The camera's timestamp counter, ns (the clock of [`FrameMeta::t_camera_ns`]).
    pub t_camera_ns: u64,
    /// Host time just before the latch was requested.
    pub t_host_before: HostTimeUs,
    /// Host time just after its value was read back.
    pub t_host_after: HostTimeUs,
}

impl CameraClockSample {
    /// Half the bracket, µs: how far the latch may lie from the bracket's midpoint.
    pub fn half_width_us(&self) -> f64 {
        self.t_host_after.0.saturating_sub(self.t_host_before.0) as f64 / 2.0
    }
}

/// Counters of a stream, each failure mode apart.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub struct CameraCounters {
    /// Frames delivered complete.
    pub completed: u64,
    /// Frames delivered flagged because packets were missing.
    pub missing_packets: u64,
    /// Frames lost because no buffer was free (the consumer was too slow).
    pub underruns: u64,
    /// `next_frame` calls that timed out.
    pub timeouts: u64,
    /// Frames failed for another reason (size mismatch, aborted, lost whole in transfer…).
    pub other_failures: u64,
    /// Frames delivered twice with the same id (the copy is dropped).
    pub duplicates: u64,
}

/// Camera errors, naming the device and what is wrong.
#[derive(Debug, thiserror::Error)]
pub enum CameraError {
    /// The camera could not be opened.
    #[error("cannot open camera {device}: {reason}")]
    Open {
        /// Device identifier.
        device: String,
        /// Why.
        reason: String,
    },
    /// A setting was refused.
    #[error("camera {device} refused {setting}: {reason}")]
    Setting {
        /// Device identifier.
        device: String,
        /// Which setting.
        setting: &'static str,
        /// Why.
        reason: String,
    },
    /// The stream failed.
    #[error("camera {device} stream failed: {reason}")]
    Stream {
        /// Device identifier.
        device: String,
        /// Why.
        reason: String,
    },
    /// No more frames (a replay reached its end).
    #[error("end of stream")]
    EndOfStream,
}

/// A frame source.
pub trait Camera: Send {
    /// What it is.
    fn info(&self) -> CameraInfo;
    /// Applies settings (before `start`).
    fn configure(&mut self, settings: &CameraSettings) -> Result<(), CameraError>;
    /// Starts streaming.
    fn start(&mut self) -> Result<(), CameraError>;
    /// Waits up to `timeout` for the next frame; `Ok(None)` on timeout.
    fn next_frame(&mut self, timeout: Duration) -> Result<Option<Frame>, CameraError>;
    /// Stops streaming.
    fn stop(&mut self) -> Result<(), CameraError>;
    /// Counters so far.
    fn counters(&self) -> CameraCounters;
    /// Frames exposed but not yet delivered, where the backend can tell (a simulator rendering
    /// behind real time); the capture waits for them before it ends. Default: 0.
    fn frames_in_flight(&self) -> u64 {
        0
    }
    /// Latches and reads the camera's timestamp counter, where the backend can (before `start`
    /// or while streaming); `None` where it cannot. Frames are then paired on their exposure
    /// timestamps rather than their arrival (`acquire::pairing`). Default: `None`.
    fn clock_sample(&mut self) -> Option<CameraClockSample> {
        None
    }
}
