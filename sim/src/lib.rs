//! `ellipso-sim`: the forward model of the ellipso rig.
//!
//! The physics it renders with (optics, camera, geometry, mosaic) lives in `ellipso-model`,
//! which the fit shares.
//!
//! AprilTag boards (families, code tables, albedo, corners, ray hits) are in
//! `ellipso_model::tags`, shared with the tracker.
//! - [`scene`]: scene files (TOML): objects, materials, AprilTag boards, rig, capture path.
//!
//! - [`effects`]: effects on demand — the plan of stages a scene needs, with reasons, and the
//!   per-frame stage execution counts that prove it.
//! - [`render`]: the polarimetric renderer (raw mosaic frames + ground truth) and the
//!   radiometry shared with the fit.
//!
//! - [`record`]: what a session records of a scene (rig record, boards), so its fit and tracking
//!   need no scene file.
//!
//! - [`rig`]: the virtual rig — trigger board, camera, wire, clocks, faults.
//!
//! - [`generate`]: scenes drawn from a seed (shape, measured materials, patches, capture path)
//!   for the generalisation bench.
#![cfg_attr(not(test), forbid(unsafe_code))] // the tests compare with the C apriltag library

pub mod calibration_captures;
pub mod effects;
pub mod generate;
pub mod record;
pub mod render;
pub mod rig;
pub mod scene;
#[cfg(any(test, feature = "test-support"))]
pub mod test_support;

#[cfg(test)]
mod tag_checks;
