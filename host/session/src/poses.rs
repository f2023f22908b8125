//! The poses of a session: the one fold of its event log's `pose`, `pose_rejected` and
//! `pose_interpolated` events into each frame's pose ([`Session::poses`]). Every stage that
//! takes poses from a log reads them here: the fit, the mesh and the COLMAP export (through
//! [`SessionPoses::tracked`]), the tracker (which frames still need tracking,
//! [`SessionPoses::has_outcome`]), the short-pulse poses ([`SessionPoses::interpolated`]), the
//! live view (event by event, [`SessionPoses::apply`]) and the reader's consistency check (one
//! event's word, [`SessionEvent::pose_event`]).
//!
//! Contract:
//! - A frame's **tracked** pose is its last `pose` or `pose_rejected` event: a later tracking
//!   run supersedes an earlier one. A `pose` whose numbers are not all finite counts as an
//!   outcome without a pose.
//! - A frame's **borrowed** pose (a short-pulse frame posed from its neighbours) is its last
//!   `pose_interpolated` event with finite numbers; a later `pose` of the frame supersedes it
//!   (a `pose_rejected` does not: the borrowed pose follows the rejection it stands in for).
//! - Poses are `world_from_camera` (the log records `camera_from_world`), by frame id.
//! - What a frame's tracking outcome was computed from is its last outcome's [`TrackedFrom`]
//!   ([`SessionPoses::tracked_from`]; `crate::provenance` tells a stale one).

use std::collections::BTreeMap;

use nalgebra::Isometry3;

use crate::events::{SessionEvent, TrackedFrom, camera_from_world};

/// One event's word on a frame's pose, as logged.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PoseEvent<'a> {
    /// `pose`: tracked.
    Tracked {
        /// Rotation, axis-angle (rad), world → camera.
        rotation_camera_from_world: &'a [f64; 3],
        /// Translation, m, world origin in the camera frame.
        translation_camera_from_world_m: &'a [f64; 3],
    },
    /// `pose_rejected`: tracking refused the frame.
    Rejected {
        /// Why.
        reason: &'a str,
    },
    /// `pose_interpolated`: borrowed from the frame's tracked neighbours.
    Interpolated {
        /// Rotation, axis-angle (rad), world → camera.
        rotation_camera_from_world: &'a [f64; 3],
        /// Translation, m, world origin in the camera frame.
        translation_camera_from_world_m: &'a [f64; 3],
    },
}

impl PoseEvent<'_> {
    /// The logged numbers (rotation, then translation; none for a rejection).
    pub fn logged_values(&self) -> Vec<f64> {
        match self {
            Self::Tracked {
                rotation_camera_from_world: r,
                translation_camera_from_world_m: t,
            }
            | Self::Interpolated {
                rotation_camera_from_world: r,
                translation_camera_from_world_m: t,
            } => r.iter().chain(t.iter()).copied().collect(),
            Self::Rejected { .. } => Vec::new(),
        }
    }

    /// The pose, camera frame → world frame, when the event carries one whose numbers are all
    /// finite.
    pub fn world_from_camera(&self) -> Option<Isometry3<f64>> {
        match self {
            Self::Tracked {
                rotation_camera_from_world: r,
                translation_camera_from_world_m: t,
            }
            | Self::Interpolated {
                rotation_camera_from_world: r,
                translation_camera_from_world_m: t,
            } if r.iter().chain(t.iter()).all(|v| v.is_finite()) => {
                Some(camera_from_world(r, t).inverse())
            }
            _ => None,
        }
    }
}

impl SessionEvent {
    /// What a `pose` or `pose_rejected` event was computed from (`None` for other events).
    pub fn tracked_from(&self) -> Option<TrackedFrom> {
        match self {
            SessionEvent::Pose { from, .. } | SessionEvent::PoseRejected { from, .. } => {
                Some(*from)
            }
            _ => None,
        }
    }

    /// What this event says of a frame's pose: the frame and its [`PoseEvent`], if it is a
    /// `pose`, `pose_rejected` or `pose_interpolated` event.
    pub fn pose_event(&self) -> Option<(u64, PoseEvent<'_>)> {
        match self {
            SessionEvent::Pose {
                frame_id,
                rotation_camera_from_world,
                translation_camera_from_world_m,
                ..
            } => Some((
                *frame_id,
                PoseEvent::Tracked {
                    rotation_camera_from_world,
                    translation_camera_from_world_m,
                },
            )),
            SessionEvent::PoseRejected {
                frame_id, reason, ..
            } => Some((*frame_id, PoseEvent::Rejected { reason })),
            SessionEvent::PoseInterpolated {
                frame_id,
                rotation_camera_from_world,
                translation_camera_from_world_m,
                ..
            } => Some((
                *frame_id,
                PoseEvent::Interpolated {
                    rotation_camera_from_world,
                    translation_camera_from_world_m,
                },
            )),
            _ => None,
        }
    }
}

/// A frame's tracking outcome: its last `pose` or `pose_rejected` event.
#[derive(Debug, Clone, PartialEq)]
pub enum TrackedPose {
    /// Posed: camera frame → world frame (`None`: the logged numbers are not all finite).
    Posed(Option<Isometry3<f64>>),
    /// Refused by tracking, with the logged reason.
    Rejected(String),
}

/// The poses a session's log holds (module contract), by frame id.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SessionPoses {
    tracked: BTreeMap<u64, TrackedPose>,
    from: BTreeMap<u64, TrackedFrom>,
    interpolated: BTreeMap<u64, Isometry3<f64>>,
}

impl SessionPoses {
    /// The fold of `events`, in log order.
    pub fn from_events<'a>(events: impl IntoIterator<Item = &'a SessionEvent>) -> Self {
        let mut poses = Self::default();
        for e in events {
            poses.apply(e);
        }
        poses
    }

    /// One step of the fold: takes `event`'s word on its frame's pose. Returns the frame whose
    /// tracking outcome ([`Self::outcome`]) it set, if it set one.
    pub fn apply(&mut self, event: &SessionEvent) -> Option<u64> {
        let (frame_id, e) = event.pose_event()?;
        if let Some(from) = event.tracked_from() {
            self.from.insert(frame_id, from);
        }
        match e {
            PoseEvent::Tracked { .. } => {
                self.interpolated.remove(&frame_id);
                self.tracked
                    .insert(frame_id, TrackedPose::Posed(e.world_from_camera()));
                Some(frame_id)
            }
            PoseEvent::Rejected { reason } => {
                self.tracked
                    .insert(frame_id, TrackedPose::Rejected(reason.to_string()));
                Some(frame_id)
            }
            PoseEvent::Interpolated { .. } => {
                if let Some(p) = e.world_from_camera() {
                    self.interpolated.insert(frame_id, p);
                }
                None
            }
        }
    }

    /// The tracked poses (finite ones), camera frame → world frame, sorted by frame id.
    pub fn tracked(&self) -> Vec<(u64, Isometry3<f64>)> {
        self.tracked
            .iter()
            .filter_map(|(&id, t)| match t {
                TrackedPose::Posed(Some(p)) => Some((id, *p)),
                _ => None,
            })
            .collect()
    }

    /// The borrowed poses of short-pulse frames, camera frame → world frame, sorted by frame id.
    pub fn interpolated(&self) -> Vec<(u64, Isometry3<f64>)> {
        self.interpolated.iter().map(|(&id, p)| (id, *p)).collect()
    }

    /// Frame `frame_id`'s tracking outcome, if the log has one.
    pub fn outcome(&self, frame_id: u64) -> Option<&TrackedPose> {
        self.tracked.get(&frame_id)
    }

    /// What frame `frame_id`'s tracking outcome was computed from, if the log has an outcome.
    pub fn tracked_from(&self, frame_id: u64) -> Option<TrackedFrom> {
        self.from.get(&frame_id).copied()
    }

    /// Whether the log has a tracking outcome (a `pose` or a `pose_rejected`) for `frame_id`.
    pub fn has_outcome(&self, frame_id: u64) -> bool {
        self.tracked.contains_key(&frame_id)
    }

    /// The frames tracking refused (last word a `pose_rejected`), with the reason, by frame id.
    pub fn rejected(&self) -> impl Iterator<Item = (u64, &str)> {
        self.tracked.iter().filter_map(|(&id, t)| match t {
            TrackedPose::Rejected(reason) => Some((id, reason.as_str())),
            TrackedPose::Posed(_) => None,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::time::HostTimeUs;

    fn pose(frame_id: u64, x: f64) -> SessionEvent {
        SessionEvent::Pose {
            t_host_us: HostTimeUs(0),
            frame_id,
            rotation_camera_from_world: [0.0; 3],
            translation_camera_from_world_m: [x, 0.0, 0.5],
            rms_px: 0.1,
            tags: 4,
            from: TrackedFrom::default(),
        }
    }

    fn rejected(frame_id: u64) -> SessionEvent {
        SessionEvent::PoseRejected {
            t_host_us: HostTimeUs(0),
            frame_id,
            reason: "no tag".into(),
            from: TrackedFrom::default(),
        }
    }

    fn interpolated(frame_id: u64, x: f64) -> SessionEvent {
        SessionEvent::PoseInterpolated {
            t_host_us: HostTimeUs(0),
            frame_id,
            rotation_camera_from_world: [0.0; 3],
            translation_camera_from_world_m: [x, 0.0, 0.5],
            from_frame_ids: [0, 2],
            weight: 0.5,
        }
    }

    #[test]
    fn the_last_word_counts_and_non_finite_poses_are_outcomes_without_a_pose() {
        let events = [
            pose(1, 0.1),
            rejected(2),
            pose(3, f64::NAN),
            pose(1, 0.2), // a later run supersedes
            rejected(4),
            pose(4, 0.4),
            pose(5, 0.5),
            rejected(5),
        ];
        let p = SessionPoses::from_events(&events);
        let tracked = p.tracked();
        assert_eq!(
            tracked.iter().map(|(id, _)| *id).collect::<Vec<_>>(),
            [1, 4]
        );
        // world_from_camera: the camera sits at −t in the world (no rotation)
        assert!((tracked[0].1.translation.vector.x + 0.2).abs() < 1e-15);
        assert!((1..=5).all(|id| p.has_outcome(id)));
        assert!(!p.has_outcome(6));
        assert_eq!(p.outcome(3), Some(&TrackedPose::Posed(None)));
        assert_eq!(
            p.rejected().collect::<Vec<_>>(),
            [(2, "no tag"), (5, "no tag")]
        );
    }

    #[test]
    fn a_borrowed_pose_follows_its_rejection_and_yields_to_a_later_pose() {
        let events = [
            rejected(2),
            interpolated(2, 0.2),
            rejected(3),
            interpolated(3, 0.3),
            pose(3, 0.33),
            rejected(4),
            interpolated(4, f64::INFINITY),
            rejected(2),
        ];
        let p = SessionPoses::from_events(&events);
        let ids: Vec<u64> = p.interpolated().iter().map(|(id, _)| *id).collect();
        assert_eq!(ids, [2]);
        // an interpolated pose is no tracking outcome
        let mut q = SessionPoses::default();
        assert_eq!(q.apply(&interpolated(7, 0.0)), None);
        assert!(!q.has_outcome(7));
        assert_eq!(q.apply(&rejected(7)), Some(7));
    }
}
