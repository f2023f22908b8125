//! Pose initialisation for **non-coplanar** 3-D points with known intrinsics: the linear DLT of
//! the 3×4 matrix P = [R | t] in undistorted normalised image coordinates (Hartley & Zisserman,
//! *Multiple View Geometry*, 2nd ed., §7.1, with the 3-D points normalised to centroid 0 and
//! mean distance √3), followed by projection of the left 3×3 block onto the nearest rotation
//! (SVD, U·Vᵀ) with the scale taken as the mean singular value.
//!
//! Contract: ≥ 6 finite points not all on one plane; returns `camera_from_model` or `None` for a
//! degenerate configuration. Only an initial guess: the caller refines it by LM.

use super::exceeds;
use ellipso_model::camera::Pose;
use nalgebra::{DMatrix, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};

/// Linear pose from ≥ 6 non-coplanar points; see the module doc.
pub fn dlt_pose(points: &[Point3<f64>], normalised_image: &[[f64; 2]]) -> Option<Pose> {
    let n = points.len();
    if n < 6 || normalised_image.len() != n {
        return None;
    }
    let centroid = points.iter().fold(Vector3::zeros(), |a, p| a + p.coords) / n as f64;
    let mean_dist = points
        .iter()
        .map(|p| (p.coords - centroid).norm())
        .sum::<f64>()
        / n as f64;
    // Coincident points: no scale (guards the division).
    if !exceeds(mean_dist, 1e-12) {
        return None;
    }
    let s = 3f64.sqrt() / mean_dist;
    let mut a = DMatrix::<f64>::zeros((2 * n).max(12), 12);
    for (i, (p, x)) in points.iter().zip(normalised_image).enumerate() {
        let q = (p.coords - centroid) * s;
        let hom = [q.x, q.y, q.z, 1.0];
        for c in 0..4 {
            a[(2 * i, c)] = hom[c];
            a[(2 * i, 8 + c)] = -x[0] * hom[c];
            a[(2 * i + 1, 4 + c)] = hom[c];
            a[(2 * i + 1, 8 + c)] = -x[1] * hom[c];
        }
    }
    let svd = a.svd(false, true);
    let v_t = svd.v_t.as_ref()?;
    let mut order: Vec<usize> = (0..svd.singular_values.len()).collect();
    order.sort_by(|&i, &j| svd.singular_values[i].total_cmp(&svd.singular_values[j]));
    // A one-dimensional null space is required (coplanar points leave a larger one).
    if !exceeds(
        svd.singular_values[order[1]],
        1e-9 * svd.singular_values[order[order.len() - 1]],
    ) {
        return None;
    }
    let p = v_t.row(order[0]);
    // P acting on normalised points; fold the normalisation back: X_n = s (X − c).
    let mut m = Matrix3::new(p[0], p[1], p[2], p[4], p[5], p[6], p[8], p[9], p[10]) * s;
    let mut p4 = Vector3::new(p[3], p[7], p[11]) - m * centroid;
    if m.determinant() < 0.0 {
        m = -m;
        p4 = -p4;
    }
    let svd_m = m.svd(true, true);
    let (u, v_t) = (svd_m.u?, svd_m.v_t?);
    let scale = svd_m.singular_values.mean();
    if !(scale > 0.0 && scale.is_finite()) {
        return None;
    }
    let mut r = u * v_t;
    if r.determinant() < 0.0 {
        return None;
    }
    r = Rotation3::from_matrix(&r).into_inner();
    let t = p4 / scale;
    let rot = UnitQuaternion::from_matrix(&r);
    let pose = Pose::from_parts(Translation3::from(t), rot);
    // The centroid must be in front of the camera.
    ((pose * Point3::from(centroid)).z > 0.0).then_some(pose)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_pose_of_a_3d_point_cloud() {
        let truth = Pose::from_parts(
            Translation3::new(0.05, -0.03, 0.6),
            UnitQuaternion::from_euler_angles(2.5, 0.3, -0.7),
        );
        let points: Vec<Point3<f64>> = (0..10)
            .map(|i| {
                let f = i as f64;
                Point3::new(
                    0.1 * (f * 1.3).sin(),
                    0.08 * (f * 0.7).cos(),
                    0.05 * (f * 2.1).sin(),
                )
            })
            .collect();
        let image: Vec<[f64; 2]> = points
            .iter()
            .map(|p| {
                let q = truth * p;
                [q.x / q.z, q.y / q.z]
            })
            .collect();
        let est = dlt_pose(&points, &image).unwrap();
        assert!(est.rotation.angle_to(&truth.rotation) < 1e-8);
        assert!((est.translation.vector - truth.translation.vector).norm() < 1e-9);
        // Coplanar points are not this solver's job.
        let flat: Vec<Point3<f64>> = points.iter().map(|p| Point3::new(p.x, p.y, 0.0)).collect();
        let flat_image: Vec<[f64; 2]> = flat
            .iter()
            .map(|p| {
                let q = truth * p;
                [q.x / q.z, q.y / q.z]
            })
            .collect();
        assert!(dlt_pose(&flat, &flat_image).is_none());
    }
}
