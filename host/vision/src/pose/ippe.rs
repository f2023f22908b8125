//! Planar pose initialisation by IPPE — Infinitesimal Plane-Based Pose Estimation (T. Collins and
//! A. Bartoli, IJCV 109(3):252–286, 2014) — returning **both** solutions of the planar ambiguity.
//!
//! Input: model points (x, y) on the plane z = 0 of the model frame and their *undistorted*
//! normalised image points (X/Z, Y/Z). Derivation (the paper's §4, in our notation):
//! 1. centre the model at its centroid and fit the homography H (normalised DLT) with H₃₃ = 1;
//! 2. the image of the centroid is v = (H₁₃, H₂₃) and the Jacobian of the homography there is
//!    J = [[H₁₁ − H₃₁H₁₃, H₁₂ − H₃₂H₁₃], [H₂₁ − H₃₁H₂₃, H₂₂ − H₃₂H₂₃]];
//! 3. with R_v the rotation taking e₃ to p̂ = [v; 1]/‖[v; 1]‖ and B = [I₂ | −v]·R_v[:, 0..2],
//!    A = B⁻¹J = γ·R'₂₂ where R = R_v·R' and γ = 1/t_z: γ is the largest singular value of A
//!    (the top-left 2×2 block of a rotation has largest singular value 1);
//! 4. the first two columns of R' are [R'₂₂; bᵀ] with b·bᵀ = I − R'₂₂ᵀR'₂₂ (rank one), so b is
//!    known up to sign — the two signs are the two planar solutions;
//! 5. given each R, the translation is the linear least-squares solution over all points of
//!    (R q + t)ₓ − x·(R q + t)_z = 0 (and likewise for y) — the paper's final step.
//!
//! Both returned poses are `camera_from_model` (model frame → OpenCV camera frame).

use super::exceeds;
use nalgebra::{Matrix2, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector2, Vector3};

use super::homography::{HomographyError, homography_dlt};
use ellipso_model::camera::Pose;

/// Why IPPE could not produce poses.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum IppeError {
    /// The homography could not be estimated.
    #[error("IPPE homography: {0}")]
    Homography(#[from] HomographyError),
    /// The geometry gives no finite solution (plane seen edge-on, centroid on the camera plane).
    #[error("IPPE: degenerate geometry ({0})")]
    Degenerate(&'static str),
}

/// Both IPPE solutions, the first being the one with the lower reprojection error in
/// normalised coordinates.
pub fn ippe_planar(
    model_xy: &[[f64; 2]],
    normalised_image: &[[f64; 2]],
) -> Result<[Pose; 2], IppeError> {
    let n = model_xy.len().max(1) as f64;
    let centroid = model_xy
        .iter()
        .fold([0.0, 0.0], |a, p| [a[0] + p[0] / n, a[1] + p[1] / n]);
    let centred: Vec<[f64; 2]> = model_xy
        .iter()
        .map(|p| [p[0] - centroid[0], p[1] - centroid[1]])
        .collect();
    let h = homography_dlt(&centred, normalised_image)?;
    // H₃₃ is the projective depth of the centroid: ~0 means the centroid lies on the camera plane.
    if !exceeds(h[(2, 2)].abs(), 1e-12 * h.norm()) {
        return Err(IppeError::Degenerate("plane centroid on the camera plane"));
    }
    let h = h / h[(2, 2)];
    let v = Vector2::new(h[(0, 2)], h[(1, 2)]);
    let jac = Matrix2::new(
        h[(0, 0)] - h[(2, 0)] * h[(0, 2)],
        h[(0, 1)] - h[(2, 1)] * h[(0, 2)],
        h[(1, 0)] - h[(2, 0)] * h[(1, 2)],
        h[(1, 1)] - h[(2, 1)] * h[(1, 2)],
    );
    let p_hat = Vector3::new(v.x, v.y, 1.0).normalize();
    // p̂_z > 0 always, so the rotation between e₃ and p̂ exists (never antipodal).
    let r_v = Rotation3::rotation_between(&Vector3::z(), &p_hat)
        .ok_or(IppeError::Degenerate("no rotation to the centroid ray"))?;
    let r_v = r_v.matrix();
    let proj = nalgebra::Matrix2x3::new(1.0, 0.0, -v.x, 0.0, 1.0, -v.y);
    let b_mat: Matrix2<f64> = proj * r_v.fixed_view::<3, 2>(0, 0);
    let b_inv = b_mat
        .try_inverse()
        .ok_or(IppeError::Degenerate("singular B"))?;
    let a = b_inv * jac;
    let sv = a.singular_values();
    let gamma = sv.max();
    if !(gamma > 0.0 && gamma.is_finite()) {
        return Err(IppeError::Degenerate("plane seen edge-on (zero Jacobian)"));
    }
    let r22 = a / gamma;
    // b bᵀ = I − R22ᵀ R22 (positive semi-definite, rank ≤ 1); take the better-conditioned column.
    let m = Matrix2::identity() - r22.transpose() * r22;
    let (i, mii) = if m[(0, 0)] >= m[(1, 1)] {
        (0, m[(0, 0)])
    } else {
        (1, m[(1, 1)])
    };
    // Clamp: round-off can make the diagonal slightly negative for a fronto-parallel plane.
    let b = if mii > 0.0 {
        m.column(i) / mii.sqrt()
    } else {
        Vector2::zeros()
    };
    let mut poses = Vec::with_capacity(2);
    for sign in [1.0, -1.0] {
        let c1 = Vector3::new(r22[(0, 0)], r22[(1, 0)], sign * b.x);
        let c2 = Vector3::new(r22[(0, 1)], r22[(1, 1)], sign * b.y);
        let c3 = c1.cross(&c2);
        let r_prime = Matrix3::from_columns(&[c1, c2, c3]);
        let r = r_v * r_prime;
        // Re-orthonormalise against round-off.
        let rot = super::orthonormalise(&r);
        let t_centred = translation_least_squares(&rot, &centred, normalised_image)?;
        // X_c = R (p − c) + t  ⇒  t_full = t − R c.
        let c3d = Vector3::new(centroid[0], centroid[1], 0.0);
        let t_full = t_centred - rot * c3d;
        poses.push(Pose::from_parts(Translation3::from(t_full), rot));
    }
    let mut errors: Vec<f64> = poses
        .iter()
        .map(|p| normalised_error(p, model_xy, normalised_image))
        .collect();
    if errors[1] < errors[0] {
        poses.swap(0, 1);
        errors.swap(0, 1);
    }
    Ok([poses[0], poses[1]])
}

/// Linear least squares for t given R: (R q + t)ₓ − x (R q + t)_z = 0 and the same for y.
fn translation_least_squares(
    rot: &UnitQuaternion<f64>,
    model_xy: &[[f64; 2]],
    image: &[[f64; 2]],
) -> Result<Vector3<f64>, IppeError> {
    let mut ata = Matrix3::<f64>::zeros();
    let mut atb = Vector3::<f64>::zeros();
    for (q, x) in model_xy.iter().zip(image) {
        let rq = rot * Vector3::new(q[0], q[1], 0.0);
        for (row, rhs) in [
            (Vector3::new(1.0, 0.0, -x[0]), x[0] * rq.z - rq.x),
            (Vector3::new(0.0, 1.0, -x[1]), x[1] * rq.z - rq.y),
        ] {
            ata += row * row.transpose();
            atb += row * rhs;
        }
    }
    let t = ata
        .cholesky()
        .ok_or(IppeError::Degenerate("translation not determined"))?
        .solve(&atb);
    if !exceeds(t.z, 0.0) {
        return Err(IppeError::Degenerate("plane behind the camera"));
    }
    Ok(t)
}

/// Sum of squared normalised-coordinate reprojection errors (∞ if a point is behind the camera).
fn normalised_error(pose: &Pose, model_xy: &[[f64; 2]], image: &[[f64; 2]]) -> f64 {
    model_xy
        .iter()
        .zip(image)
        .map(|(q, x)| {
            let p = pose * nalgebra::Point3::new(q[0], q[1], 0.0);
            if p.z <= 0.0 {
                return f64::INFINITY;
            }
            (p.x / p.z - x[0]).powi(2) + (p.y / p.z - x[1]).powi(2)
        })
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point3;
    use proptest::prelude::*;

    fn square(size: f64) -> Vec<[f64; 2]> {
        let h = size / 2.0;
        vec![[-h, -h], [h, -h], [h, h], [-h, h], [0.3 * h, 0.1 * h]]
    }

    proptest! {
        /// On noise-free data one of the two solutions is the true pose (to round-off).
        #[test]
        fn one_solution_is_exact(
            rx in -1.0f64..1.0, ry in -1.0f64..1.0, rz in -3.1f64..3.1,
            tx in -0.2f64..0.2, ty in -0.2f64..0.2, tz in 0.3f64..1.5,
        ) {
            let rot = UnitQuaternion::from_euler_angles(std::f64::consts::PI + rx, ry, rz);
            let truth = Pose::from_parts(Translation3::new(tx, ty, tz), rot);
            let model: Vec<[f64; 2]> = square(0.1).iter().map(|p| [p[0] + 0.05, p[1] - 0.02]).collect();
            let image: Vec<[f64; 2]> = model.iter().map(|q| {
                let p = truth * Point3::new(q[0], q[1], 0.0);
                [p.x / p.z, p.y / p.z]
            }).collect();
            prop_assume!(model.iter().all(|q| (truth * Point3::new(q[0], q[1], 0.0)).z > 0.05));
            let [best, _alt] = ippe_planar(&model, &image).unwrap();
            prop_assert!(best.rotation.angle_to(&truth.rotation) < 1e-6);
            prop_assert!((best.translation.vector - truth.translation.vector).norm() < 1e-7);
        }
    }

    /// The two solutions are mirror images about the line of sight to the centroid: they
    /// coincide when the plane faces that line exactly, and differ by twice the tilt otherwise.
    #[test]
    fn fronto_parallel_gives_two_coincident_solutions() {
        let truth = Pose::from_parts(
            Translation3::new(0.0, 0.0, 0.5),
            UnitQuaternion::from_euler_angles(std::f64::consts::PI, 0.0, 0.0),
        );
        let model = square(0.05)[..4].to_vec();
        let image: Vec<[f64; 2]> = model
            .iter()
            .map(|q| {
                let p = truth * Point3::new(q[0], q[1], 0.0);
                [p.x / p.z, p.y / p.z]
            })
            .collect();
        let [a, b] = ippe_planar(&model, &image).unwrap();
        assert!(a.rotation.angle_to(&truth.rotation) < 1e-6);
        assert!(
            b.rotation.angle_to(&truth.rotation) < 1e-6,
            "{}",
            b.rotation.angle_to(&truth.rotation)
        );
    }
}
