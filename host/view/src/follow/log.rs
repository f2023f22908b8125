//! Reading the session's log as it grows: complete lines of `events.jsonl` from where the last
//! poll stopped (a half-written last line waits for its end), each event folded into the
//! follower's frames and counters. Poses are taken through the session's one fold of its pose
//! events (`ellipso_session::poses`, step by step); a pose the log records replaces one the view
//! tracked.

use std::io::{Read, Seek, SeekFrom};
use std::time::Instant;

use super::{FollowState, FrameInfo, PoseStatus};
use ellipso_session::events::{FrameStatus, SessionEvent};
use ellipso_session::paths;
use ellipso_session::poses::TrackedPose;

impl FollowState {
    pub(super) fn read_log(&mut self) -> bool {
        let path = self.config.session.join(paths::EVENTS);
        let Ok(mut file) = std::fs::File::open(&path) else {
            return false;
        };
        if file.seek(SeekFrom::Start(self.log_offset)).is_err() {
            return false;
        }
        let mut bytes = Vec::new();
        if file.read_to_end(&mut bytes).is_err() || bytes.is_empty() {
            return false;
        }
        self.log_offset += bytes.len() as u64;
        self.log_grew = Some(Instant::now());
        self.partial.extend(bytes);
        let Some(last_newline) = self.partial.iter().rposition(|&b| b == b'\n') else {
            return false;
        };
        let complete: Vec<u8> = self.partial.drain(..=last_newline).collect();
        for line in complete.split(|&b| b == b'\n') {
            if line.iter().all(u8::is_ascii_whitespace) {
                continue;
            }
            match serde_json::from_slice::<SessionEvent>(line) {
                Ok(e) => self.on_event(e),
                Err(_) => self.bad_lines += 1,
            }
        }
        true
    }

    fn on_event(&mut self, e: SessionEvent) {
        if let Some(frame_id) = self.log_poses.apply(&e) {
            let status = match self.log_poses.outcome(frame_id) {
                Some(TrackedPose::Posed(Some(world_from_camera))) => PoseStatus::Posed {
                    world_from_camera: *world_from_camera,
                    live: false,
                },
                Some(TrackedPose::Posed(None)) => {
                    PoseStatus::Rejected("the logged pose is not finite".into())
                }
                Some(TrackedPose::Rejected(reason)) => PoseStatus::Rejected(reason.clone()),
                None => PoseStatus::Pending,
            };
            self.set_pose(frame_id, status);
        }
        let c = &mut self.counters;
        match e {
            SessionEvent::Pulse { .. } => c.pulses += 1,
            SessionEvent::Frame {
                frame_id,
                file,
                t_host_us,
                status,
                ..
            } => {
                let flagged = match status {
                    FrameStatus::Complete => None,
                    FrameStatus::Flagged { reason } => Some(reason),
                };
                let pose = self
                    .frames
                    .get(&frame_id)
                    .map_or(PoseStatus::Pending, |f| f.pose.clone());
                self.frames.insert(
                    frame_id,
                    FrameInfo {
                        file,
                        t_host_us: t_host_us.0,
                        flagged,
                        pose,
                    },
                );
            }
            SessionEvent::Pairing { .. } => c.paired += 1,
            SessionEvent::PairingError { kind, .. } => {
                *c.pairing_errors.entry(kind).or_insert(0) += 1;
            }
            SessionEvent::Link { counters, .. } => {
                c.link_ok = counters.frames_ok;
                c.link_bad = counters.bad_frames();
            }
            SessionEvent::ClockFit { gain, rms_us, .. } => {
                c.clock_rms_us = Some(rms_us);
                c.clock_drift_ppm = Some((gain - 1.0) * 1e6);
            }
            SessionEvent::Fault { what, .. } => c.faults.push(what),
            SessionEvent::Disconnected { reason, .. } => c.disconnected = Some(reason),
            SessionEvent::End { reason, .. } => c.ended = Some(reason),
            _ => {}
        }
    }

    fn set_pose(&mut self, frame_id: u64, pose: PoseStatus) {
        let entry = self.frames.entry(frame_id).or_insert_with(|| FrameInfo {
            file: paths::frame_file(frame_id),
            t_host_us: 0,
            flagged: None,
            pose: PoseStatus::Pending,
        });
        entry.pose = pose;
        // a recorded pose replaces one the view tracked: recount coverage from scratch
        if self.covered.contains(&frame_id) {
            self.coverage = None;
            self.covered.clear();
        }
    }
}

#[cfg(test)]
mod tests {
    use std::io::Write;
    use std::time::Duration;

    use super::*;
    use crate::follow::{CAPTURE_QUIET, FollowConfig};
    use ellipso_session::time::HostTimeUs;

    fn line(e: &SessionEvent) -> String {
        serde_json::to_string(e).unwrap() + "\n"
    }

    fn frame(id: u64) -> SessionEvent {
        SessionEvent::Frame {
            t_host_us: HostTimeUs(1000 + id),
            frame_id: id,
            file: paths::frame_file(id),
            t_camera_ns: None,
            exposure_us: 100,
            gain_db: 0.0,
            status: FrameStatus::Complete,
            crc64: None,
        }
    }

    fn append(dir: &std::path::Path, text: &str) {
        let mut f = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(dir.join(paths::EVENTS))
            .unwrap();
        f.write_all(text.as_bytes()).unwrap();
    }

    #[test]
    fn half_lines_wait_and_a_quiet_or_ended_log_is_not_capturing() {
        let dir = tempfile::tempdir().unwrap();
        let mut state = FollowState::new(FollowConfig::new(dir.path().to_path_buf()), None);
        assert!(!state.capturing(), "no log yet");
        let pulse = line(&SessionEvent::Pulse {
            t_host_us: HostTimeUs(5),
            seq: 0,
            t_trigger_device_us: ellipso_session::time::DeviceTimeUs(1),
            t_flash_on_device_us: ellipso_session::time::DeviceTimeUs(2),
            t_flash_off_device_us: ellipso_session::time::DeviceTimeUs(3),
            flags: 0,
            bracket_step: 0,
            flash_on_us: None,
        });
        let (head, tail) = pulse.split_at(pulse.len() / 2);
        append(dir.path(), &(line(&frame(0)) + head));
        state.read_log();
        assert_eq!(state.frames.len(), 1);
        assert_eq!(state.counters.pulses, 0, "a half-written line waits");
        assert!(state.capturing(), "the log just grew");
        assert_eq!(state.json(1)["tracking"]["deferred"], true);
        append(dir.path(), tail);
        state.read_log();
        assert_eq!((state.counters.pulses, state.bad_lines), (1, 0));
        // quiet for longer than CAPTURE_QUIET: paused (or crashed), the follower catches up
        state.log_grew = Some(Instant::now() - CAPTURE_QUIET - Duration::from_millis(10));
        assert!(!state.capturing());
        assert_eq!(state.json(1)["tracking"]["deferred"], false);
        append(dir.path(), &line(&frame(1)));
        state.read_log();
        assert!(state.capturing());
        append(
            dir.path(),
            &line(&SessionEvent::End {
                t_host_us: HostTimeUs(9),
                reason: "done".into(),
            }),
        );
        state.read_log();
        assert!(!state.capturing(), "the log says it ended");
        assert_eq!(state.counters.ended.as_deref(), Some("done"));
    }
}
