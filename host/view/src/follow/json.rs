//! The live state as the page reads it: counters, per-frame status, tracking and coverage, as
//! one JSON value (the event stream's payload; `docs/view.md` describes what the page shows).

use std::collections::BTreeMap;

use nalgebra::Point3;
use serde_json::json;

use super::{FollowState, PoseStatus};
use crate::coverage::{self, Category};

impl FollowState {
    pub(super) fn json(&self, version: u64) -> serde_json::Value {
        let c = &self.counters;
        let coverage = self.coverage.as_ref();
        let frames: Vec<serde_json::Value> = self
            .frames
            .iter()
            .map(|(id, f)| {
                let (status, reason, angles) = match (&f.flagged, &f.pose) {
                    (Some(r), _) => ("flagged", Some(r.clone()), None),
                    (None, PoseStatus::Pending) => ("pending", None, None),
                    (None, PoseStatus::Rejected(r)) => ("rejected", Some(r.clone()), None),
                    (
                        None,
                        PoseStatus::Posed {
                            world_from_camera, ..
                        },
                    ) => (
                        "posed",
                        None,
                        coverage.map(|cv| {
                            cv.dome_angles(&Point3::from(world_from_camera.translation.vector))
                        }),
                    ),
                };
                json!({"id": id, "status": status, "reason": reason,
                       "az": angles.map(|a| a.0), "el": angles.map(|a| a.1)})
            })
            .collect();
        let mut rejections: BTreeMap<String, usize> = BTreeMap::new();
        for f in self.frames.values() {
            if let PoseStatus::Rejected(r) = &f.pose {
                *rejections.entry(r.clone()).or_insert(0) += 1;
            }
        }
        let posed = self.posed().count();
        let live_tracked = self
            .frames
            .values()
            .filter(|f| matches!(f.pose, PoseStatus::Posed { live: true, .. }))
            .count();
        let pending = self
            .frames
            .values()
            .filter(|f| matches!(f.pose, PoseStatus::Pending) && f.flagged.is_none())
            .count();
        let flagged = self.frames.values().filter(|f| f.flagged.is_some()).count();
        let recent: Vec<u64> = self
            .frames
            .values()
            .map(|f| f.t_host_us)
            .filter(|&t| t > 0)
            .collect();
        let fps = match (recent.iter().max(), recent.len()) {
            (Some(&last), n) if n >= 2 => {
                let window: Vec<u64> = recent
                    .iter()
                    .copied()
                    .filter(|&t| t + 2_000_000 >= last)
                    .collect();
                let first = window.iter().min().copied().unwrap_or(last);
                if last > first {
                    (window.len() - 1) as f64 / ((last - first) as f64 * 1e-6)
                } else {
                    0.0
                }
            }
            _ => 0.0,
        };
        let state = if self.manifest.is_none() {
            "waiting"
        } else if c.ended.is_some() {
            "ended"
        } else {
            "capturing"
        };
        let without_frame = c
            .pairing_errors
            .get("pulse_without_frame")
            .copied()
            .unwrap_or(0);
        json!({
            "version": version,
            "session": self.config.session.display().to_string(),
            "state": state,
            "end_reason": c.ended,
            "counters": {
                "frames": self.frames.values().filter(|f| f.t_host_us > 0).count(),
                "pulses": c.pulses,
                "paired": c.paired,
                "dropped": without_frame + flagged as u64,
                "flagged": flagged,
                "pairing_errors": c.pairing_errors,
                "link_frames_ok": c.link_ok,
                "link_errors": c.link_bad,
                "clock_rms_us": c.clock_rms_us,
                "clock_drift_ppm": c.clock_drift_ppm,
                "faults": c.faults,
                "disconnected": c.disconnected,
                "fps": fps,
                "bad_log_lines": self.bad_lines,
            },
            "latest": self.latest_view.as_ref().map(|v| v.stats.clone()),
            "latest_error": self.latest_error,
            "frames": frames,
            "tracking": {
                "enabled": self.config.track,
                "error": match &self.tracker { Some(Err(e)) => Some(e.clone()), _ => None },
                "posed": posed,
                "posed_by_view": live_tracked,
                "pending": pending,
                // while the capture runs only its newest frame is tracked; the rest after the end
                "deferred": self.capturing() && self.config.track,
                "rejections": rejections,
            },
            "coverage": coverage.map(|cv| json!({
                "proxy": cv.is_proxy(),
                "elements": cv.normals().len(),
                "views": cv.view_count(),
                "counts": cv.counts(),
                "labels": Category::ALL.map(Category::label),
                "hints": cv.hints(),
                "centre": [cv.centre().x, cv.centre().y, cv.centre().z],
                "dome": if cv.is_proxy() {
                    cv.normals().iter().map(|n| {
                        let (az, el) = coverage::dome_angles(&n.into_inner());
                        [az, el]
                    }).collect::<Vec<_>>()
                } else { Vec::new() },
            })),
        })
    }
}
