//! How far one rigid pose is from another, and one direction from another: the one error every
//! pose accuracy (pose estimation tests and benches, the demo and bench tables, the
//! reconstruction alignment's residuals) and every normal accuracy (bench scores, the fit's
//! surface update) reports.
//!
//! Contract: for two transforms of the same kind (both `world_from_camera`, or both
//! `camera_from_board`, …), [`pose_error`] gives
//! - `rotation_deg`: the angle of the relative rotation `R_truth⁻¹·R_estimate` (nalgebra's
//!   `UnitQuaternion::angle_to`, `2·atan2(|v|, |w|)` of the relative quaternion), in [0°, 180°];
//! - `translation_mm`: `‖t_estimate − t_truth‖` × 1000 (metres → millimetres), which equals the
//!   norm of the relative transform's translation `truth⁻¹·estimate` (a rotation keeps lengths).
//!
//! For `world_from_camera` poses the translation error is the distance of the camera centres.
//!
//! [`angle_between_deg`] is `acos(a·b / max(‖a‖‖b‖, 1e-300))` in degrees, the cosine clamped
//! into [−1, 1] (rounding can put it a hair outside); a zero vector gives 90°.

use nalgebra::{Isometry3, Vector3};

/// The rotation and translation between an estimated pose and the truth.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseError {
    /// Angle of the relative rotation, degrees in [0, 180].
    pub rotation_deg: f64,
    /// Distance of the translations, millimetres.
    pub translation_mm: f64,
}

/// The error of `estimate` against `truth` (module contract).
pub fn pose_error(estimate: &Isometry3<f64>, truth: &Isometry3<f64>) -> PoseError {
    PoseError {
        rotation_deg: truth.rotation.angle_to(&estimate.rotation).to_degrees(),
        translation_mm: (estimate.translation.vector - truth.translation.vector).norm() * 1e3,
    }
}

/// The angle between two directions, degrees in [0, 180] (module contract; any lengths).
pub fn angle_between_deg(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    (a.dot(b) / (a.norm() * b.norm()).max(1e-300))
        .clamp(-1.0, 1.0)
        .acos()
        .to_degrees()
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion, Vector3};

    #[test]
    fn the_error_is_the_relative_transform() {
        let truth = Isometry3::from_parts(
            Translation3::new(0.1, -0.2, 0.5),
            UnitQuaternion::from_euler_angles(0.3, -0.1, 1.2),
        );
        let nudge = Isometry3::from_parts(
            Translation3::new(0.003, 0.0, -0.004),
            UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 2f64.to_radians()),
        );
        let estimate = truth * nudge;
        let e = pose_error(&estimate, &truth);
        assert!((e.rotation_deg - 2.0).abs() < 1e-9, "{e:?}");
        assert!((e.translation_mm - 5.0).abs() < 1e-9, "{e:?}");
        let delta = truth.inverse() * estimate;
        assert!((e.rotation_deg - delta.rotation.angle().to_degrees()).abs() < 1e-9);
        assert!((e.translation_mm - delta.translation.vector.norm() * 1e3).abs() < 1e-9);
        let same = pose_error(&truth, &truth);
        assert_eq!((same.rotation_deg, same.translation_mm), (0.0, 0.0));
        // a half turn is 180°, not 0° or 360°
        let flipped = truth * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 3.0);
        assert!((pose_error(&flipped, &truth).rotation_deg - 3f64.to_degrees()).abs() < 1e-9);
    }

    #[test]
    fn directions_are_compared_whatever_their_length() {
        let (x, y) = (Vector3::x(), Vector3::y());
        assert_eq!(angle_between_deg(&x, &(3.0 * x)), 0.0);
        assert!((angle_between_deg(&x, &(x + y)) - 45.0).abs() < 1e-12);
        assert_eq!(angle_between_deg(&x, &-x), 180.0);
        assert_eq!(angle_between_deg(&x, &Vector3::zeros()), 90.0);
    }
}
