//! Board pose estimation: where the camera was relative to the AprilTag board in each frame.
//!
//! - [`detect`]: AprilTag detection; corners shifted to the integer-centre pixel convention.
//! - [`board`]: board corner geometry ([`BoardCorners`]) and correspondence assembly.
//! - [`homography`]: normalised DLT homography (Hartley & Zisserman).
//! - [`ippe`]: both planar pose solutions by IPPE (Collins & Bartoli 2014).
//! - [`dlt`]: linear pose for non-coplanar points.
//! - [`refine`]: LM refinement of a pose on reprojection error with lens distortion.
//! - [`estimate`]: the joint PnP over all corners of all tags of a board, with flip margin,
//!   covariance and typed frame rejection ([`PoseRejection`]).
//!
//! Frames and conventions are those of [`ellipso_sim::camera`]: OpenCV camera frame, pixel
//! centres at integer coordinates, poses named `camera_from_board`. See `docs/pose.md`.

pub mod board;
pub mod detect;
pub mod dlt;
pub mod estimate;
pub mod homography;
pub mod ippe;
pub mod refine;

pub use board::{Assembly, BoardCorners, TagGridBoard, assemble_correspondences};
pub use detect::{DetectError, DetectorConfig, TagDetection, TagDetector, TagFamily};
pub use estimate::{BoardPose, Correspondence, PoseConfig, PoseRejection, estimate_board_pose};

/// `value > limit`; false when either is NaN, so `if !exceeds(x, tol) { reject }` also rejects
/// NaN (the form every positivity guard in this module uses).
pub(crate) fn exceeds(value: f64, limit: f64) -> bool {
    value > limit
}

#[cfg(test)]
mod pipeline_tests;
#[cfg(test)]
pub(crate) mod synthetic;
#[cfg(test)]
mod tests;
