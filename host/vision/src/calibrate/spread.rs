//! How varied a calibration's views are: the board's normal in the camera frame, over the views.
//!
//! Plane-based calibration is degenerate when every board plane contains one common direction
//! — all normals lie on one great circle — (Sturm & Maybank, "On plane-based camera
//! calibration", CVPR 1999, §4): the focal length and principal point along that direction are
//! then not determined, and with lens distortion free the whole camera can drift far from the
//! truth at a reprojection error as low as the right one's. An orbit of a level camera around an
//! object on the board is exactly that case (every view is tilted about the camera's horizontal
//! axis). [`ViewSpread`] measures how far the views are from it.
//!
//! Contract: `out_of_plane_deg` is the RMS angle of the normals out of the plane through the
//! camera centre that fits them best (the smallest eigenvalue λ₃ of the normals' second moment
//! M = Σ n nᵀ / N, as asin √λ₃, λ₃ clamped to [0, 1]); `tilt_spread_deg` is the RMS angle of
//! the normals from their mean. Both are 0 for one view.

use ellipso_model::camera::Pose;
use nalgebra::{Matrix3, Vector3};

/// The spread of the board's orientation over a calibration's views (see the module doc).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViewSpread {
    /// RMS angle of the board normals out of their best-fit great circle, degrees.
    pub out_of_plane_deg: f64,
    /// RMS angle of the board normals from their mean direction, degrees.
    pub tilt_spread_deg: f64,
    /// The direction (camera frame, unit) every board plane most nearly contains.
    pub common_direction_camera: Vector3<f64>,
}

/// The spread of the views `camera_from_board`.
pub fn view_spread(poses: &[Pose]) -> ViewSpread {
    let normals: Vec<Vector3<f64>> = poses.iter().map(|p| p.rotation * Vector3::z()).collect();
    let n = normals.len().max(1) as f64;
    let moment: Matrix3<f64> = normals
        .iter()
        .map(|v| v * v.transpose())
        .sum::<Matrix3<f64>>()
        / n;
    let eig = moment.symmetric_eigen();
    let (k, &smallest) = eig
        .eigenvalues
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(b.1))
        .expect("3 eigenvalues");
    // λ₃ ∈ [0, 1] up to round-off: clamp before the square root and asin
    let out_of_plane_deg = smallest.clamp(0.0, 1.0).sqrt().asin().to_degrees();
    let sum: Vector3<f64> = normals.iter().sum();
    // the normals of boards a camera sees all face it: their sum is far from zero
    let mean = sum.try_normalize(1e-12).unwrap_or_else(Vector3::z);
    let tilt_spread_deg = (normals
        .iter()
        .map(|v| v.dot(&mean).clamp(-1.0, 1.0).acos().powi(2))
        .sum::<f64>()
        / n)
        .sqrt()
        .to_degrees();
    ViewSpread {
        out_of_plane_deg,
        tilt_spread_deg,
        common_direction_camera: eig.eigenvectors.column(k).into_owned(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};

    fn tilted(about: Vector3<f64>, deg: f64) -> Pose {
        Pose::from_parts(
            Translation3::new(0.0, 0.0, 0.5),
            UnitQuaternion::from_scaled_axis(about * deg.to_radians()),
        )
    }

    #[test]
    fn an_orbit_of_a_level_camera_is_degenerate_and_varied_tilts_are_not() {
        // every view tilted about the camera's x axis, by 25°…65°: one great circle
        let orbit: Vec<Pose> = (0..10)
            .map(|i| tilted(Vector3::x(), 25.0 + 4.0 * f64::from(i)))
            .collect();
        let s = view_spread(&orbit);
        assert!(s.out_of_plane_deg < 1e-6, "{s:?}");
        assert!(s.tilt_spread_deg > 10.0, "{s:?}");
        assert!(s.common_direction_camera.x.abs() > 0.999, "{s:?}");
        // tilts about both axes
        let mut varied = orbit.clone();
        varied.extend((0..10).map(|i| tilted(Vector3::y(), -30.0 + 6.0 * f64::from(i))));
        assert!(view_spread(&varied).out_of_plane_deg > 10.0);
    }
}
