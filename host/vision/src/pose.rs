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
//! Frames and conventions are those of [`ellipso_model::camera`]: OpenCV camera frame, pixel
//! centres at integer coordinates, poses named `camera_from_board`. See `docs/pose.md`.

pub mod board;
pub mod detect;
pub mod dlt;
pub mod estimate;
pub mod homography;
pub mod ippe;
pub mod raw_edges;
pub mod refine;

pub use board::{Assembly, BoardCorners, TagGridBoard, assemble_correspondences};
pub use detect::{DetectError, DetectorConfig, TagDetection, TagDetector, TagFamily};
pub use estimate::{BoardPose, Correspondence, PoseConfig, PoseRejection, estimate_board_pose};

/// The rotation nearest to a matrix whose columns are already close to orthonormal (IPPE and
/// eigenvector output): Gram–Schmidt on the first two columns, third = their cross product, then
/// the closed-form quaternion. Cheaper than nalgebra's iterative `from_matrix`, exact for a
/// rotation input. The columns must be non-zero and not parallel (true for the callers).
pub(crate) fn orthonormalise(m: &nalgebra::Matrix3<f64>) -> nalgebra::UnitQuaternion<f64> {
    let c1 = m.column(0).normalize();
    let c2 = m.column(1) - c1 * c1.dot(&m.column(1));
    let c2 = c2.normalize();
    let c3 = c1.cross(&c2);
    let r = nalgebra::Matrix3::from_columns(&[c1, c2, c3]);
    nalgebra::UnitQuaternion::from_rotation_matrix(&nalgebra::Rotation3::from_matrix_unchecked(r))
}

/// `value > limit`; false when either is NaN, so `if !exceeds(x, tol) { reject }` also rejects
/// NaN (the form every positivity guard in this module uses).
pub(crate) fn exceeds(value: f64, limit: f64) -> bool {
    value > limit
}

#[cfg(test)]
pub(crate) mod synthetic;
#[cfg(test)]
mod tests;
