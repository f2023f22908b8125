//! Analytic Jacobians of [`CameraModel::project`](super::CameraModel::project): w.r.t. the
//! camera-frame point (for pose estimation) and w.r.t. the camera parameters
//! `[fx, fy, cx, cy, k1, k2, p1, p2, k3]` (for calibration). The tests check both against
//! central differences.

use nalgebra::{Matrix2x3, Point3, SMatrix};

use super::{CAMERA_PARAM_COUNT, CameraModel, MIN_DEPTH_M};

/// A projected pixel with its Jacobians.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProjectionJacobians {
    /// The projected pixel (u, v).
    pub pixel: [f64; 2],
    /// ∂(u, v)/∂(X, Y, Z) of the camera-frame point, px per metre.
    pub d_pixel_d_point: Matrix2x3<f64>,
    /// ∂(u, v)/∂[fx, fy, cx, cy, k1, k2, p1, p2, k3].
    pub d_pixel_d_params: SMatrix<f64, 2, CAMERA_PARAM_COUNT>,
}

impl CameraModel {
    /// Projects a camera-frame point and returns the Jacobians; `None` exactly when
    /// [`CameraModel::project`] is `None`.
    pub fn project_with_jacobians(
        &self,
        point_camera: &Point3<f64>,
    ) -> Option<ProjectionJacobians> {
        if !(point_camera.z > MIN_DEPTH_M && point_camera.coords.iter().all(|c| c.is_finite())) {
            return None;
        }
        let inv_z = 1.0 / point_camera.z; // z > MIN_DEPTH_M checked above
        // Same arithmetic as `project`, so the pixels agree bit for bit.
        let (x, y) = (
            point_camera.x / point_camera.z,
            point_camera.y / point_camera.z,
        );
        let d = self.distortion;
        let i = self.intrinsics;
        let [x_d, y_d] = d.distort([x, y]);
        let pixel = self.normalised_to_pixel([x_d, y_d]);

        // ∂(x, y)/∂(X, Y, Z)
        let d_norm_d_point = Matrix2x3::new(inv_z, 0.0, -x * inv_z, 0.0, inv_z, -y * inv_z);
        let d_dist_d_norm = d.distort_jacobian([x, y]);
        let mut d_pixel_d_dist = d_dist_d_norm;
        d_pixel_d_dist.row_mut(0).scale_mut(i.fx);
        d_pixel_d_dist.row_mut(1).scale_mut(i.fy);
        let d_pixel_d_point = d_pixel_d_dist * d_norm_d_point;

        let r2 = x * x + y * y;
        let (r4, r6) = (r2 * r2, r2 * r2 * r2);
        let mut j = SMatrix::<f64, 2, CAMERA_PARAM_COUNT>::zeros();
        // fx, fy, cx, cy
        j[(0, 0)] = x_d;
        j[(1, 1)] = y_d;
        j[(0, 2)] = 1.0;
        j[(1, 3)] = 1.0;
        // k1, k2
        j[(0, 4)] = i.fx * x * r2;
        j[(1, 4)] = i.fy * y * r2;
        j[(0, 5)] = i.fx * x * r4;
        j[(1, 5)] = i.fy * y * r4;
        // p1, p2
        j[(0, 6)] = i.fx * 2.0 * x * y;
        j[(1, 6)] = i.fy * (r2 + 2.0 * y * y);
        j[(0, 7)] = i.fx * (r2 + 2.0 * x * x);
        j[(1, 7)] = i.fy * 2.0 * x * y;
        // k3
        j[(0, 8)] = i.fx * x * r6;
        j[(1, 8)] = i.fy * y * r6;

        Some(ProjectionJacobians {
            pixel,
            d_pixel_d_point,
            d_pixel_d_params: j,
        })
    }
}
