//! The fit's inputs checked against physical bounds before any work: a mesh, poses, a camera
//! and frame metadata that no real capture can produce are refused with the cause named,
//! instead of being fitted into a confident answer.
//!
//! Contract (`docs/reliability.md`, "Inputs refused"; each bound is a constant here):
//! - **camera** (`rig.camera`): finite; focal lengths in [[`FOCAL_MIN_SIDES`],
//!   [`FOCAL_MAX_SIDES`]] × the longer image side; principal point within half an image of the
//!   image; |k1|, |k2|, |k3| ≤ [`RADIAL_MAX`], |p1|, |p2| ≤ [`TANGENTIAL_MAX`];
//! - **poses**: finite, each camera within [`POSE_MAX_M`] of the board origin; more than one
//!   posed frame must not all share one pose (a log edited or written by something that is not
//!   tracking);
//! - **frames** of the poses: exposure in (0, [`EXPOSURE_MAX_US`]] µs, gain in
//!   [[`GAIN_MIN_DB`], [`GAIN_MAX_DB`]] dB, flash energy in [0, [`ENERGY_MAX`]] of a full pulse;
//!   no frame with two pose events that disagree;
//! - **mesh**: its extent at least [`MESH_MIN_PX`] px in the median view and at most
//!   [`MESH_MAX_M`]; triangles with area (at most half of them degenerate); its triangles wound
//!   counter-clockwise seen from outside — for a closed mesh a positive signed volume, and for
//!   any mesh the nearest camera in front of most vertices.
//!
//! Frames without a pose are not looked at (the fit never reads them).

use std::collections::BTreeMap;

use ellipso_model::camera::CameraModel;
use ellipso_model::geometry::TriangleMesh;
use ellipso_session::reader::Session;
use nalgebra::{Isometry3, Point3, Vector3};

pub use ellipso_model::camera::{FOCAL_MAX_SIDES, FOCAL_MIN_SIDES, RADIAL_MAX, TANGENTIAL_MAX};
/// Farthest camera from the board origin, m.
pub const POSE_MAX_M: f64 = 100.0;
/// Longest exposure, µs (one minute).
pub const EXPOSURE_MAX_US: f64 = 60e6;
/// Lowest gain, dB.
pub const GAIN_MIN_DB: f64 = -20.0;
/// Highest gain, dB (the IMX250's analogue and digital gain together reach 48 dB).
pub const GAIN_MAX_DB: f64 = 60.0;
/// Largest flash energy relative to a full pulse.
pub const ENERGY_MAX: f64 = 2.0;
/// Smallest extent of the mesh in the median view, px.
pub const MESH_MIN_PX: f64 = 8.0;
/// Largest extent of the mesh, m.
pub const MESH_MAX_M: f64 = 100.0;

/// An input no capture can produce.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum InputError {
    /// The camera model.
    #[error("the session's camera (`rig.camera` in manifest.json): {0}")]
    Camera(String),
    /// The poses.
    #[error("the poses (`pose` events in events.jsonl): {0}")]
    Poses(String),
    /// A frame's recorded metadata.
    #[error("frame {frame_id} (events.jsonl): {what}")]
    Frame {
        /// The frame.
        frame_id: u64,
        /// What is impossible about it.
        what: String,
    },
    /// The mesh.
    #[error("the mesh: {0}")]
    Mesh(String),
}

/// Checks the camera model (module doc).
pub fn check_camera(camera: &CameraModel) -> Result<(), InputError> {
    camera.check_plausible().map_err(InputError::Camera)
}

/// Checks the poses (`world_from_camera` per frame; module doc).
pub fn check_poses(poses: &[(u64, Isometry3<f64>)]) -> Result<(), InputError> {
    let bad = |what: String| Err(InputError::Poses(what));
    for (id, p) in poses {
        let t = p.translation.vector;
        let q = p.rotation.coords;
        if !(t.iter().chain(q.iter()).all(|v| v.is_finite())) {
            return bad(format!("frame {id}: the pose is not finite"));
        }
        if t.norm() > POSE_MAX_M {
            return bad(format!(
                "frame {id}: the camera is {:e} m from the board origin (at most {POSE_MAX_M} m)",
                t.norm()
            ));
        }
    }
    if let Some((_, first)) = poses.first()
        && poses.len() > 1
        && poses.iter().all(|(_, p)| {
            (p.translation.vector - first.translation.vector).norm() < 1e-6
                && p.rotation.angle_to(&first.rotation) < 1e-6
        })
    {
        return bad(format!(
            "all {} posed frames have one and the same pose: no hand-held capture does; the \
             poses were not tracked from these frames — remove the `pose` events and let the \
             fit track them",
            poses.len()
        ));
    }
    Ok(())
}

/// Checks the recorded metadata of the posed frames and that no frame has two pose events that
/// disagree (module doc).
pub fn check_frames(session: &Session, poses: &[(u64, Isometry3<f64>)]) -> Result<(), InputError> {
    let posed: std::collections::BTreeSet<u64> = poses.iter().map(|p| p.0).collect();
    for f in session
        .frames
        .iter()
        .filter(|f| posed.contains(&f.frame_id))
    {
        let bad = |what: String| {
            Err(InputError::Frame {
                frame_id: f.frame_id,
                what,
            })
        };
        if let Some([e, g]) = f.recorded_exposure_gain() {
            if !(e > 0.0 && e <= EXPOSURE_MAX_US) {
                return bad(format!(
                    "exposure_us = {e} is outside (0, {EXPOSURE_MAX_US}] µs: a frame exposed \
                     for no time holds no light"
                ));
            }
            if !(GAIN_MIN_DB..=GAIN_MAX_DB).contains(&g) {
                return bad(format!(
                    "gain_db = {g} is outside [{GAIN_MIN_DB}, {GAIN_MAX_DB}] dB"
                ));
            }
        }
        if !(0.0..=ENERGY_MAX).contains(&f.flash_energy_rel) {
            return bad(format!(
                "flash_energy_rel = {} is outside [0, {ENERGY_MAX}] of a full pulse",
                f.flash_energy_rel
            ));
        }
    }
    // the reader lists frames whose pose events disagree (the last one would silently win)
    if let Some(&frame_id) = session
        .report
        .conflicting_poses
        .iter()
        .find(|id| posed.contains(id))
    {
        return Err(InputError::Frame {
            frame_id,
            what: "its pose events disagree (an edited log, or two runs tracked it): keep one"
                .into(),
        });
    }
    Ok(())
}

/// Checks the mesh against the posed views (module doc); `camera` for its extent in pixels.
pub fn check_mesh(
    mesh: &TriangleMesh,
    poses: &[(u64, Isometry3<f64>)],
    camera: &CameraModel,
) -> Result<(), InputError> {
    let bad = |what: String| Err(InputError::Mesh(what));
    let p = mesh.positions();
    let tris = mesh.triangles();
    let (lo, hi) = p.iter().fold(
        (
            Vector3::repeat(f64::INFINITY),
            Vector3::repeat(f64::NEG_INFINITY),
        ),
        |(lo, hi), q| (lo.inf(&q.coords), hi.sup(&q.coords)),
    );
    let extent_m = (hi - lo).norm();
    // NaN (a non-finite position) fails too
    if extent_m.is_nan() || extent_m > MESH_MAX_M {
        return bad(format!(
            "it is {extent_m:e} m across (at most {MESH_MAX_M} m): wrong units?"
        ));
    }
    let centre = Point3::from((lo + hi) / 2.0);
    let mut distances: Vec<f64> = poses
        .iter()
        .map(|(_, w)| (w.translation.vector - centre.coords).norm())
        .collect();
    if !distances.is_empty() {
        let d = ellipso_model::stats::median(&mut distances).max(f64::MIN_POSITIVE);
        let px = camera.intrinsics.fx * extent_m / d;
        if px < MESH_MIN_PX {
            return bad(format!(
                "it is {extent_m:.3e} m across, {px:.2e} px in the median view at {d:.3} m \
                 (at least {MESH_MIN_PX} px): a mesh in other units, or of another object?"
            ));
        }
    }
    let area = |t: &[u32; 3]| {
        let [a, b, c] = t.map(|i| p[i as usize]);
        0.5 * (b - a).cross(&(c - a)).norm()
    };
    // a triangle smaller than a square nanometre, or than 1e-12 of the mesh's extent squared
    let tiny = (extent_m * extent_m * 1e-12).max(1e-18);
    let degenerate = tris.iter().filter(|t| area(t) <= tiny).count();
    if 2 * degenerate > tris.len() {
        return bad(format!(
            "{degenerate} of {} triangles have no area (total {:e} m²): not a surface",
            tris.len(),
            tris.iter().map(area).sum::<f64>()
        ));
    }
    check_winding(mesh, poses)
}

/// Triangles wound clockwise seen from outside turn every normal inward (module doc).
fn check_winding(mesh: &TriangleMesh, poses: &[(u64, Isometry3<f64>)]) -> Result<(), InputError> {
    let p = mesh.positions();
    let inward = || {
        Err(InputError::Mesh(
            "its triangles wind clockwise seen from outside, so every normal points inward: \
             reverse the winding of its faces (or export it with outward normals)"
                .into(),
        ))
    };
    if is_closed(mesh) {
        let volume: f64 = mesh
            .triangles()
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| p[i as usize].coords);
                a.dot(&b.cross(&c)) / 6.0
            })
            .sum();
        return if volume < 0.0 { inward() } else { Ok(()) };
    }
    if poses.is_empty() {
        return Ok(());
    }
    // open mesh: the nearest camera (up to 64 views) sees the front of most vertices
    let step = poses.len().div_ceil(64).max(1);
    let cameras: Vec<Vector3<f64>> = poses
        .iter()
        .step_by(step)
        .map(|(_, w)| w.translation.vector)
        .collect();
    let mut used = vec![false; p.len()];
    for t in mesh.triangles() {
        for &i in t {
            used[i as usize] = true;
        }
    }
    let (mut front, mut back) = (0usize, 0usize);
    for ((q, n), _) in p
        .iter()
        .zip(mesh.normals())
        .zip(&used)
        .filter(|(_, used)| **used)
    {
        let nearest = cameras
            .iter()
            .min_by(|a, b| (*a - q.coords).norm().total_cmp(&(*b - q.coords).norm()))
            .expect("at least one camera");
        if n.dot(&(nearest - q.coords)) >= 0.0 {
            front += 1;
        } else {
            back += 1;
        }
    }
    if back > 4 * front { inward() } else { Ok(()) }
}

/// Every edge shared by exactly two triangles.
fn is_closed(mesh: &TriangleMesh) -> bool {
    let mut edges: BTreeMap<(u32, u32), u32> = BTreeMap::new();
    for t in mesh.triangles() {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            *edges.entry((a.min(b), a.max(b))).or_insert(0) += 1;
        }
    }
    !edges.is_empty() && edges.values().all(|&n| n == 2)
}

/// All the checks of the module doc on a session fit's inputs.
pub fn check(
    session: &Session,
    mesh: &TriangleMesh,
    poses: &[(u64, Isometry3<f64>)],
    camera: &CameraModel,
) -> Result<(), InputError> {
    check_camera(camera)?;
    check_poses(poses)?;
    check_frames(session, poses)?;
    check_mesh(mesh, poses, camera)
}

#[cfg(test)]
mod tests;
