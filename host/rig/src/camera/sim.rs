//! The `sim` backend: the virtual rig's simulated camera, behind the same [`Camera`] trait.
//!
//! Frames come from [`ellipso_sim::rig::SimCamera`], which exposes on the rising edges of the
//! trigger wire and renders through the simulator. This backend does what a real GigE backend
//! does with them: unwraps the 16-bit block ids into monotonic 64-bit ids (gaps are frames lost
//! in transfer, counted), drops duplicated block ids (counted), flags frames with missing packets,
//! and stamps the host arrival time in the capture's [`HostClock`] from the simulated arrival
//! instant (the camera's latency, not the simulator's render time). Its timestamp latch
//! ([`Camera::clock_sample`]) reads the simulated camera's own counter, as a GigE camera's
//! `GevTimestampControlLatch` does.

use std::time::Duration;

use crossbeam_channel::RecvTimeoutError;
use ellipso_sim::rig::{FrameStatus as SimStatus, SimCamera};

use super::frame_id::Unwrapped;
use super::{
    Camera, CameraCounters, CameraError, CameraInfo, CameraSettings, Frame, FrameIdUnwrapper,
    FrameMeta, FrameStatus,
};
use ellipso_session::time::HostClock;

/// The simulated camera as a [`Camera`].
pub struct SimCameraBackend {
    camera: SimCamera,
    clock: HostClock,
    info: CameraInfo,
    ids: FrameIdUnwrapper,
    counters: CameraCounters,
    settings: Option<CameraSettings>,
    started: bool,
}

impl SimCameraBackend {
    /// Wraps a running simulated camera; `info` describes its sensor.
    pub fn new(camera: SimCamera, clock: HostClock, info: CameraInfo) -> Self {
        Self {
            camera,
            clock,
            info,
            ids: FrameIdUnwrapper::new(),
            counters: CameraCounters::default(),
            settings: None,
            started: false,
        }
    }
}

impl Camera for SimCameraBackend {
    fn info(&self) -> CameraInfo {
        self.info.clone()
    }

    fn configure(&mut self, settings: &CameraSettings) -> Result<(), CameraError> {
        if settings.bit_depth != self.info.bit_depth {
            return Err(CameraError::Setting {
                device: "sim".into(),
                setting: "bit depth",
                reason: format!(
                    "the scene's sensor has {} bits; change `rig.camera.bit_depth` in the scene",
                    self.info.bit_depth
                ),
            });
        }
        self.settings = Some(*settings);
        Ok(())
    }

    fn start(&mut self) -> Result<(), CameraError> {
        self.started = true;
        Ok(())
    }

    fn next_frame(&mut self, timeout: Duration) -> Result<Option<Frame>, CameraError> {
        loop {
            let f = match self.camera.frames().recv_timeout(timeout) {
                Ok(f) => f,
                Err(RecvTimeoutError::Timeout) => {
                    self.counters.timeouts += 1;
                    return Ok(None);
                }
                Err(RecvTimeoutError::Disconnected) => return Err(CameraError::EndOfStream),
            };
            let frame_id = match self.ids.push(f.block_id) {
                Unwrapped::Next { frame_id, skipped } => {
                    self.counters.other_failures += skipped;
                    frame_id
                }
                Unwrapped::Duplicate { .. } => {
                    self.counters.duplicates += 1;
                    continue;
                }
                Unwrapped::Invalid => {
                    self.counters.other_failures += 1;
                    continue;
                }
            };
            let status = match f.status {
                SimStatus::Complete => {
                    self.counters.completed += 1;
                    FrameStatus::Complete
                }
                SimStatus::Flagged { missing_packets } => {
                    self.counters.missing_packets += 1;
                    FrameStatus::Flagged(format!("missing packets ({missing_packets})"))
                }
            };
            let (exposure_us, gain_db) = self
                .settings
                .map_or((0, 0.0), |s| (s.exposure_us, s.gain_db));
            return Ok(Some(Frame {
                meta: FrameMeta {
                    frame_id,
                    t_camera_ns: Some(f.t_camera_ns),
                    t_host_us: self.clock.at(f.arrival),
                    width: f.width,
                    height: f.height,
                    status,
                    exposure_us,
                    gain_db,
                },
                pixels: f.pixels,
            }));
        }
    }

    fn stop(&mut self) -> Result<(), CameraError> {
        self.started = false;
        Ok(())
    }

    fn counters(&self) -> CameraCounters {
        self.counters
    }

    fn clock_sample(&mut self) -> Option<super::CameraClockSample> {
        let t_host_before = self.clock.now();
        let t_camera_ns = self.camera.latch_timestamp_ns();
        let t_host_after = self.clock.now();
        Some(super::CameraClockSample {
            t_camera_ns,
            t_host_before,
            t_host_after,
        })
    }

    fn frames_in_flight(&self) -> u64 {
        let c = self.camera.counters();
        // exposures not yet handed over: neither delivered (duplicates count twice) nor dropped
        c.exposures
            .saturating_sub(c.dropped + c.delivered.saturating_sub(c.duplicated))
    }
}
