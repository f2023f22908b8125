//! Poses of short-pulse frames in a bracketed capture: tracked like every frame, and borrowed
//! from their tracked neighbours only where tracking refused them.
//!
//! # The decision
//!
//! A bracketed capture (`docs/protocol.md`, "Flash-energy bracket") lights some frames with a
//! fraction of the flash. Each frame is tracked **on its own** first, exactly like a full-energy
//! frame: the tracker's detection image is scaled by its own 99.5th percentile before the
//! AprilTag detector thresholds it locally, so a dimmer frame loses signal-to-noise, not tags. On
//! the simulated rig (`multi_material_bracket.toml`, half resolution) every 1/4 and 1/16 frame
//! tracked with 13–15 tags at 0.2–0.5 px RMS, like the full frames between them. A frame's own
//! pose is the better one: a hand-held rig moves between frames (≈ 8 mm at 0.05 m/s and 167 ms).
//!
//! Only when tracking refuses a **short-pulse frame** (relative flash energy below 1; a
//! full-energy frame that fails stays without a pose) does it borrow a pose:
//! - from the nearest tracked frames before and after it, each at most one bracket cycle away
//!   (frame ids), interpolated at its trigger time — translation linearly, rotation by slerp
//!   — which follows a smooth hand motion to second order in the frame spacing;
//! - from the one tracked neighbour within a cycle when only one side has one (the start or end
//!   of a capture, or a run of refusals), taken as is;
//! - nowhere when neither side has one within a cycle: the frame stays without a pose.
//!
//! Times are the pulses' trigger times (device µs, via the frames' `pairing` and `pulse` events);
//! frames without them fall back to frame ids as time (a free run spaces frames evenly).
//! Borrowed poses are logged as `pose_interpolated` events after the frame's `pose_rejected`,
//! naming the frames they came from, so a reader can always tell a measured pose from a
//! borrowed one; `Session::poses` (`ellipso_session::poses`) reads them back.

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use nalgebra::{Isometry3, Translation3};

use crate::tracked::{ProcessError, TrackedFrame};
use ellipso_session::events::SessionEvent;
use ellipso_session::reader::Session;
use ellipso_session::time::HostTimeUs;
use ellipso_session::writer::SessionAppender;

/// Frames lit by less than this share of a full pulse are short-pulse frames.
pub const FULL_ENERGY: f64 = 0.999;

/// A pose a short-pulse frame borrowed from its tracked neighbours.
#[derive(Debug, Clone, PartialEq)]
pub struct BorrowedPose {
    /// The frame.
    pub frame_id: u64,
    /// Camera frame → world frame.
    pub world_from_camera: Isometry3<f64>,
    /// The tracked frames it came from: `[before, after]` (the same id twice for one neighbour).
    pub from_frame_ids: [u64; 2],
    /// Interpolation weight of `after` (0: the pose of `before`).
    pub weight: f64,
}

/// What the interpolation needs of one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameTiming {
    /// Frame id.
    pub frame_id: u64,
    /// Its pulse's trigger time, device µs (`None` when unpaired or not logged).
    pub t_trigger_us: Option<u64>,
    /// Relative flash energy that lit it.
    pub flash_energy_rel: f64,
}

/// The borrowed poses of a tracked session (see the [module docs](self)).
pub fn borrow_short_pulse_poses(session: &Session, tracked: &[TrackedFrame]) -> Vec<BorrowedPose> {
    let poses: BTreeMap<u64, Option<Isometry3<f64>>> = tracked
        .iter()
        .map(|t| {
            (
                t.frame_id,
                t.result.as_ref().ok().map(|p| p.world_from_camera),
            )
        })
        .collect();
    borrow(&frame_timings(session), &poses, bracket_cycle(session))
}

/// Each frame's pulse trigger time and flash energy.
pub fn frame_timings(session: &Session) -> Vec<FrameTiming> {
    let triggers: HashMap<u64, u64> = session
        .events
        .iter()
        .filter_map(|e| match e {
            SessionEvent::Pulse {
                seq,
                t_trigger_device_us,
                ..
            } => Some((*seq, t_trigger_device_us.0)),
            _ => None,
        })
        .collect();
    session
        .frames
        .iter()
        .map(|f| FrameTiming {
            frame_id: f.frame_id,
            t_trigger_us: f.pulse_seq.and_then(|s| triggers.get(&s).copied()),
            flash_energy_rel: f.flash_energy_rel,
        })
        .collect()
}

/// Steps per bracket cycle: the `configured` bracket's length, else the largest recorded step
/// + 1, at least 1.
pub fn bracket_cycle(session: &Session) -> u64 {
    let configured = session.events.iter().rev().find_map(|e| match e {
        SessionEvent::Configured { config, .. } => {
            (!config.bracket.is_empty()).then_some(config.bracket.len() as u64)
        }
        _ => None,
    });
    let seen = session
        .frames
        .iter()
        .map(|f| u64::from(f.bracket_step) + 1)
        .max();
    configured.or(seen).unwrap_or(1).max(1)
}

/// The pure rule: for every short-pulse frame without a pose, a pose from its tracked neighbours
/// at most `cycle` frame ids away.
pub fn borrow(
    frames: &[FrameTiming],
    poses: &BTreeMap<u64, Option<Isometry3<f64>>>,
    cycle: u64,
) -> Vec<BorrowedPose> {
    let timing: HashMap<u64, &FrameTiming> = frames.iter().map(|f| (f.frame_id, f)).collect();
    let tracked: BTreeMap<u64, Isometry3<f64>> = poses
        .iter()
        .filter_map(|(&id, p)| p.map(|p| (id, p)))
        .collect();
    let mut out = Vec::new();
    for f in frames {
        let refused = matches!(poses.get(&f.frame_id), Some(None));
        if !refused || f.flash_energy_rel >= FULL_ENERGY {
            continue;
        }
        let id = f.frame_id;
        let before = tracked
            .range(..id)
            .next_back()
            .filter(|(b, _)| id - **b <= cycle);
        let after = tracked
            .range(id + 1..)
            .next()
            .filter(|(a, _)| **a - id <= cycle);
        let (world_from_camera, from, weight) = match (before, after) {
            (Some((&b, pb)), Some((&a, pa))) => {
                let t = |i: u64| timing.get(&i).and_then(|f| f.t_trigger_us);
                // Trigger times when all three have them, frame ids otherwise; clamped so a
                // clock glitch cannot extrapolate.
                let w = match (t(b), t(id), t(a)) {
                    (Some(tb), Some(tf), Some(ta)) if ta > tb => {
                        (tf as f64 - tb as f64) / (ta as f64 - tb as f64)
                    }
                    _ => (id - b) as f64 / (a - b) as f64,
                }
                .clamp(0.0, 1.0);
                (interpolate(pb, pa, w), [b, a], w)
            }
            (Some((&b, pb)), None) => (*pb, [b, b], 0.0),
            (None, Some((&a, pa))) => (*pa, [a, a], 0.0),
            (None, None) => continue,
        };
        out.push(BorrowedPose {
            frame_id: id,
            world_from_camera,
            from_frame_ids: from,
            weight,
        });
    }
    out
}

/// `a` at `w = 0`, `b` at `w = 1`: translation linear, rotation slerp (shortest arc; for
/// opposite rotations, where slerp is undefined, the nearer end).
fn interpolate(a: &Isometry3<f64>, b: &Isometry3<f64>, w: f64) -> Isometry3<f64> {
    let t = a.translation.vector.lerp(&b.translation.vector, w);
    let r = a
        .rotation
        .try_slerp(&b.rotation, w, 1e-12)
        .unwrap_or(if w < 0.5 { a.rotation } else { b.rotation });
    Isometry3::from_parts(Translation3::from(t), r)
}

/// Appends one `pose_interpolated` event per borrowed pose to the session's log.
pub fn append_borrowed_poses(
    dir: &Path,
    borrowed: &[BorrowedPose],
    t_host_us: HostTimeUs,
) -> Result<(), ProcessError> {
    if borrowed.is_empty() {
        return Ok(());
    }
    let mut log = SessionAppender::open(dir)?;
    for b in borrowed {
        let camera_from_world = b.world_from_camera.inverse();
        let r = camera_from_world.rotation.scaled_axis();
        let t = camera_from_world.translation.vector;
        log.log(&SessionEvent::PoseInterpolated {
            t_host_us,
            frame_id: b.frame_id,
            rotation_camera_from_world: [r.x, r.y, r.z],
            translation_camera_from_world_m: [t.x, t.y, t.z],
            from_frame_ids: b.from_frame_ids,
            weight: b.weight,
        })?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{UnitQuaternion, Vector3};

    fn pose(x: f64, yaw_deg: f64) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(x, 0.0, 0.5),
            UnitQuaternion::from_scaled_axis(Vector3::z() * yaw_deg.to_radians()),
        )
    }

    /// Frames 0..n, 10 ms apart, bracket 1, 1/4, 1/16.
    fn frames(n: u64) -> Vec<FrameTiming> {
        (0..n)
            .map(|i| FrameTiming {
                frame_id: i,
                t_trigger_us: Some(1_000_000 + 10_000 * i),
                flash_energy_rel: [1.0, 0.25, 0.0626][(i % 3) as usize],
            })
            .collect()
    }

    #[test]
    fn a_refused_short_frame_is_interpolated_at_its_trigger_time() {
        let mut poses: BTreeMap<u64, Option<Isometry3<f64>>> = (0..6)
            .map(|i| (i, Some(pose(i as f64 * 0.01, 3.0 * i as f64))))
            .collect();
        poses.insert(2, None); // 1/16 frame refused
        poses.insert(3, None); // full frame refused: never borrows
        let got = borrow(&frames(6), &poses, 3);
        assert_eq!(got.len(), 1);
        let b = &got[0];
        assert_eq!((b.frame_id, b.from_frame_ids), (2, [1, 4]));
        assert!((b.weight - 1.0 / 3.0).abs() < 1e-12);
        // Linear motion and a steady turn are reproduced exactly.
        let want = pose(0.02, 6.0);
        assert!((b.world_from_camera.translation.vector - want.translation.vector).norm() < 1e-12);
        assert!(b.world_from_camera.rotation.angle_to(&want.rotation) < 1e-12);
    }

    #[test]
    fn trigger_times_weigh_the_neighbours_and_ids_stand_in_without_them() {
        let mut f = frames(3);
        // Frame 1's pulse fired late: 3/4 of the way to frame 2.
        f[1].t_trigger_us = Some(1_015_000);
        f[2].flash_energy_rel = 1.0;
        let poses: BTreeMap<u64, Option<Isometry3<f64>>> = [
            (0, Some(pose(0.0, 0.0))),
            (1, None),
            (2, Some(pose(0.04, 0.0))),
        ]
        .into();
        let b = &borrow(&f, &poses, 3)[0];
        assert!((b.weight - 0.75).abs() < 1e-12);
        f[1].t_trigger_us = None;
        assert!((borrow(&f, &poses, 3)[0].weight - 0.5).abs() < 1e-12);
    }

    #[test]
    fn one_neighbour_within_a_cycle_is_taken_as_is_and_none_leaves_the_frame_unposed() {
        let poses: BTreeMap<u64, Option<Isometry3<f64>>> = [
            (0, Some(pose(0.1, 5.0))),
            (1, None),
            (2, None),
            (3, None),
            (4, None),
            (5, None),
            (6, None),
            (7, None),
            (8, None),
        ]
        .into();
        let got = borrow(&frames(9), &poses, 3);
        // Frames 1 and 2 are within 3 ids of frame 0; 4, 5, 7, 8 have no tracked frame near.
        let ids: Vec<(u64, [u64; 2])> =
            got.iter().map(|b| (b.frame_id, b.from_frame_ids)).collect();
        assert_eq!(ids, [(1, [0, 0]), (2, [0, 0])]);
        assert_eq!(got[0].world_from_camera, pose(0.1, 5.0));
        assert_eq!(got[0].weight, 0.0);
    }

    /// The session side: trigger times through `pairing` → `pulse`, energies from the pairing,
    /// the cycle from the `configured` bracket.
    #[test]
    fn a_session_gives_trigger_times_energies_and_the_cycle() {
        use ellipso_session::manifest::{Manifest, SensorInfo, SessionSource};
        use ellipso_session::time::DeviceTimeUs;
        use ellipso_session::writer::{FrameRecord, SessionWriter};
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("s");
        let manifest = Manifest::new(
            SessionSource::Simulator {
                scene: "x.toml".into(),
                seed: 1,
            },
            SensorInfo {
                layout: ellipso_model::mosaic::SensorLayout::MonoPolar,
                width: 4,
                height: 2,
                bit_depth: 12,
            },
            0,
        );
        let mut w = SessionWriter::create(&dir, manifest).unwrap();
        w.log(&SessionEvent::Configured {
            t_host_us: HostTimeUs(0),
            config: ellipso_session::events::BoardConfig {
                bracket: vec![32768, 8192, 2048],
                exposure_us: 6000,
                flash_delay_us: 100,
                flash_duration_us: 5000,
                frame_period_us: 500_000,
                pulses: ellipso_session::events::BoardPulses::Count(4),
                report_edges: false,
                trigger: ellipso_session::events::BoardTrigger::FreeRun,
            },
        })
        .unwrap();
        for id in 0..4u64 {
            let seq = id + 10;
            w.log(&SessionEvent::Pulse {
                t_host_us: HostTimeUs(id),
                seq,
                t_trigger_device_us: DeviceTimeUs(5_000 + 100 * id),
                t_flash_on_device_us: DeviceTimeUs(5_000 + 100 * id + 10),
                t_flash_off_device_us: DeviceTimeUs(5_000 + 100 * id + 20),
                flags: 0,
                bracket_step: (id % 3) as u8,
                flash_on_us: Some(10),
            })
            .unwrap();
            w.write_frame(FrameRecord {
                t_host_us: HostTimeUs(id),
                frame_id: id,
                t_camera_ns: None,
                exposure_us: 100,
                gain_db: 0.0,
                width: 4,
                height: 2,
                pixels: &[0; 8],
                flagged: None,
            })
            .unwrap();
            if id < 3 {
                w.log(&SessionEvent::Pairing {
                    t_host_us: HostTimeUs(id),
                    frame_id: id,
                    seq,
                    latency_us: None,
                    basis: None,
                    bracket_step: Some((id % 3) as u8),
                    flash_on_us: Some(10),
                    flash_energy_rel: Some([1.0, 0.25, 0.0625][id as usize]),
                })
                .unwrap();
            }
        }
        let session = ellipso_session::reader::open(&dir).unwrap();
        assert_eq!(bracket_cycle(&session), 3);
        let t: Vec<(Option<u64>, f64)> = frame_timings(&session)
            .iter()
            .map(|f| (f.t_trigger_us, f.flash_energy_rel))
            .collect();
        assert_eq!(
            t,
            [
                (Some(5_000), 1.0),
                (Some(5_100), 0.25),
                (Some(5_200), 0.0625),
                (None, 1.0)
            ]
        );
    }
}
