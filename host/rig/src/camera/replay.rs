//! The `replay` backend: a recorded session's frames, delivered as a live camera would.
//!
//! Frames come in frame-id order with the metadata recorded at capture (host arrival time, camera
//! timestamp, exposure, gain, completion status). Frames whose metadata was lost in a crash are
//! delivered with what the file tells (size) and flagged `metadata missing`, so nothing recorded is
//! dropped and nothing unverified is fitted. Deterministic: replaying twice gives identical frames.

use std::time::Duration;

use super::{
    Camera, CameraCounters, CameraError, CameraInfo, CameraSettings, Frame, FrameMeta, FrameStatus,
};
use ellipso_session::events::{FrameStatus as LoggedStatus, SessionEvent};
use ellipso_session::reader::{self, Session};
use ellipso_session::time::HostTimeUs;

/// A session replayed as a camera.
#[derive(Debug)]
pub struct ReplayCamera {
    session: Session,
    next: usize,
    started: bool,
    counters: CameraCounters,
}

impl ReplayCamera {
    /// Opens the session in `dir`.
    pub fn open(dir: &std::path::Path) -> Result<Self, CameraError> {
        let session = reader::open(dir).map_err(|e| CameraError::Open {
            device: format!("replay:{}", dir.display()),
            reason: e.to_string(),
        })?;
        Ok(Self {
            session,
            next: 0,
            started: false,
            counters: CameraCounters::default(),
        })
    }

    /// The session being replayed.
    pub fn session(&self) -> &Session {
        &self.session
    }

    fn device(&self) -> String {
        format!("replay:{}", self.session.dir.display())
    }
}

impl Camera for ReplayCamera {
    fn info(&self) -> CameraInfo {
        let s = &self.session.manifest.sensor;
        CameraInfo {
            backend: "replay",
            model: self.session.manifest.software.clone(),
            width: s.width,
            height: s.height,
            layout: s.layout.clone(),
            bit_depth: s.bit_depth,
        }
    }

    /// A replay plays what was recorded; settings are accepted and ignored.
    fn configure(&mut self, _settings: &CameraSettings) -> Result<(), CameraError> {
        Ok(())
    }

    fn start(&mut self) -> Result<(), CameraError> {
        self.started = true;
        Ok(())
    }

    fn next_frame(&mut self, _timeout: Duration) -> Result<Option<Frame>, CameraError> {
        if !self.started {
            return Err(CameraError::Stream {
                device: self.device(),
                reason: "not started".into(),
            });
        }
        let Some(entry) = self.session.frames.get(self.next).cloned() else {
            return Err(CameraError::EndOfStream);
        };
        self.next += 1;
        let (width, height, pixels) =
            self.session
                .load_frame(&entry)
                .map_err(|e| CameraError::Stream {
                    device: self.device(),
                    reason: e.to_string(),
                })?;
        let meta = match entry.event {
            Some(SessionEvent::Frame {
                t_host_us,
                t_camera_ns,
                exposure_us,
                gain_db,
                status,
                ..
            }) => FrameMeta {
                frame_id: entry.frame_id,
                t_camera_ns,
                t_host_us,
                width,
                height,
                status: match status {
                    LoggedStatus::Complete => FrameStatus::Complete,
                    LoggedStatus::Flagged { reason } => FrameStatus::Flagged(reason),
                },
                exposure_us,
                gain_db,
            },
            _ => FrameMeta {
                frame_id: entry.frame_id,
                t_camera_ns: None,
                t_host_us: HostTimeUs(0),
                width,
                height,
                status: FrameStatus::Flagged("metadata missing (capture interrupted)".into()),
                exposure_us: 0,
                gain_db: 0.0,
            },
        };
        match meta.status {
            FrameStatus::Complete => self.counters.completed += 1,
            FrameStatus::Flagged(_) => self.counters.other_failures += 1,
        }
        Ok(Some(Frame { meta, pixels }))
    }

    fn stop(&mut self) -> Result<(), CameraError> {
        self.started = false;
        Ok(())
    }

    fn counters(&self) -> CameraCounters {
        self.counters
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ellipso_session::manifest::{Manifest, SensorInfo, SessionSource};
    use ellipso_session::writer::{FrameRecord, SessionWriter};

    fn record(dir: &std::path::Path) {
        let manifest = Manifest::new(
            SessionSource::Simulator {
                scene: "x.toml".into(),
                seed: 1,
            },
            SensorInfo {
                layout: "mono_polar".into(),
                width: 4,
                height: 2,
                bit_depth: 12,
            },
            0,
        );
        let mut w = SessionWriter::create(dir, manifest).unwrap();
        for id in [3u64, 1, 2] {
            let px: Vec<u16> = (0..8).map(|i| (i * 100 + id) as u16).collect();
            w.write_frame(FrameRecord {
                t_host_us: HostTimeUs(id * 10),
                frame_id: id,
                t_camera_ns: None,
                exposure_us: 500,
                gain_db: 1.5,
                width: 4,
                height: 2,
                pixels: &px,
                flagged: (id == 2).then_some("missing packets"),
            })
            .unwrap();
        }
        w.finish(HostTimeUs(99), "completed").unwrap();
    }

    fn replay_all(dir: &std::path::Path) -> Vec<Frame> {
        let mut cam = ReplayCamera::open(dir).unwrap();
        cam.start().unwrap();
        let mut frames = Vec::new();
        loop {
            match cam.next_frame(Duration::ZERO) {
                Ok(Some(f)) => frames.push(f),
                Err(CameraError::EndOfStream) => break,
                other => panic!("{other:?}"),
            }
        }
        frames
    }

    #[test]
    fn replays_in_id_order_with_recorded_metadata_identically_twice() {
        let tmp = tempfile::tempdir().unwrap();
        record(tmp.path());
        let a = replay_all(tmp.path());
        assert_eq!(
            a.iter().map(|f| f.meta.frame_id).collect::<Vec<_>>(),
            vec![1, 2, 3]
        );
        assert_eq!(
            a[1].meta.status,
            FrameStatus::Flagged("missing packets".into())
        );
        assert_eq!(
            (a[0].meta.exposure_us, a[0].meta.t_host_us),
            (500, HostTimeUs(10))
        );
        assert_eq!(a[2].pixels[1], 103);
        assert_eq!(
            a,
            replay_all(tmp.path()),
            "replaying twice gives identical frames"
        );
    }

    #[test]
    fn frames_without_metadata_come_flagged_not_dropped() {
        let tmp = tempfile::tempdir().unwrap();
        record(tmp.path());
        std::fs::write(tmp.path().join("events.jsonl"), b"").unwrap();
        let frames = replay_all(tmp.path());
        assert_eq!(frames.len(), 3);
        assert!(
            frames.iter().all(
                |f| matches!(&f.meta.status, FrameStatus::Flagged(r) if r.contains("metadata"))
            )
        );
    }
}
