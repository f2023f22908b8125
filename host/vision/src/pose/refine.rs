//! Levenberg–Marquardt refinement of one rigid pose on pixel reprojection error **with** lens
//! distortion, using the analytic projection Jacobian of [`CameraModel`].
//!
//! A small hand-written LM (not the `levenberg-marquardt` crate): the problem has only 6
//! parameters, so building JᵀJ (6×6) directly and solving it by Cholesky is cheaper than the
//! crate's QR on the full 2N×6 Jacobian, and the same loop structure is reused by the
//! calibration's Schur-complement solver.
//!
//! Parametrisation: the minimal 6-vector δ = (ω, υ) is a **left** perturbation in the camera
//! frame, `camera_from_board ← (exp([ω]×), υ) · camera_from_board`, i.e. X_c ↦ exp([ω]×)·X_c + υ,
//! so ∂X_c/∂δ = [−[X_c]× | I₃]. Damping is Marquardt's: (JᵀJ + λ·diag(JᵀJ)) δ = −Jᵀr, the
//! diagonal floored at 1e-12. The loop (λ schedule, acceptance, stops) is the crate's one
//! [`crate::lm::minimise`]; converged when an accepted step lowers the cost by ≤ 1e-10
//! relatively or ‖δ‖ < 1e-12 (rad, m).

use ellipso_model::camera::{CameraModel, Pose};

use crate::lm::{Schedule, Step, minimise};
use nalgebra::{
    Matrix2x3, Matrix3, Matrix6, Point3, SMatrix, Translation3, UnitQuaternion, Vector3, Vector6,
};

/// Relative cost decrease below which the iteration has converged (the cost is then within
/// ~1e-10 of its minimum: far below any noise-driven change).
const COST_TOLERANCE: f64 = 1e-10;
/// Step norm (rad, m) below which the iteration has converged.
const STEP_TOLERANCE: f64 = 1e-12;
/// Initial Marquardt damping.
const INITIAL_DAMPING: f64 = 1e-4;

/// Result of refining one pose.
#[derive(Debug, Clone)]
pub struct RefinedPose {
    /// The refined `camera_from_board`.
    pub camera_from_board: Pose,
    /// Sum of squared pixel residuals, px².
    pub cost_px2: f64,
    /// Per point: projected − observed, px.
    pub residuals_px: Vec<[f64; 2]>,
    /// Gauss–Newton normal matrix JᵀJ at the solution, in the (ω, υ) parametrisation.
    pub normal_matrix: Matrix6<f64>,
    /// LM iterations taken.
    pub iterations: usize,
}

/// Applies the left perturbation δ = (ω, υ) to a pose (see the module doc).
pub fn apply_left_update(pose: &Pose, delta: &Vector6<f64>) -> Pose {
    let omega = Vector3::new(delta[0], delta[1], delta[2]);
    let upsilon = Vector3::new(delta[3], delta[4], delta[5]);
    let r = UnitQuaternion::from_scaled_axis(omega);
    Pose::from_parts(
        Translation3::from(r * pose.translation.vector + upsilon),
        r * pose.rotation,
    )
}

/// ∂X_c/∂δ = [−[X_c]× | I₃] for the left perturbation.
pub fn d_point_d_left_update(point_camera: &Point3<f64>) -> SMatrix<f64, 3, 6> {
    let mut j = SMatrix::<f64, 3, 6>::zeros();
    let skew = Matrix3::new(
        0.0,
        -point_camera.z,
        point_camera.y,
        point_camera.z,
        0.0,
        -point_camera.x,
        -point_camera.y,
        point_camera.x,
        0.0,
    );
    j.fixed_view_mut::<3, 3>(0, 0).copy_from(&(-skew));
    j.fixed_view_mut::<3, 3>(0, 3)
        .copy_from(&Matrix3::identity());
    j
}

/// Sum of squared pixel residuals; `None` if any point is behind the camera.
pub fn reprojection_cost(
    camera: &CameraModel,
    camera_from_board: &Pose,
    points_board: &[Point3<f64>],
    pixels: &[[f64; 2]],
) -> Option<f64> {
    let mut cost = 0.0;
    for (p, obs) in points_board.iter().zip(pixels) {
        let q = camera.project(&(camera_from_board * p))?;
        cost += (q[0] - obs[0]).powi(2) + (q[1] - obs[1]).powi(2);
    }
    Some(cost)
}

/// Builds JᵀJ and Jᵀr at a pose; `None` if a point is behind the camera.
fn normal_equations(
    camera: &CameraModel,
    pose: &Pose,
    points_board: &[Point3<f64>],
    pixels: &[[f64; 2]],
) -> Option<(Matrix6<f64>, Vector6<f64>, f64)> {
    let mut jtj = Matrix6::zeros();
    let mut jtr = Vector6::zeros();
    let mut cost = 0.0;
    for (p, obs) in points_board.iter().zip(pixels) {
        let pc = pose * p;
        let pj = camera.project_with_jacobians(&pc)?;
        let d_pix: Matrix2x3<f64> = pj.d_pixel_d_point;
        let j = d_pix * d_point_d_left_update(&pc);
        let r = nalgebra::Vector2::new(pj.pixel[0] - obs[0], pj.pixel[1] - obs[1]);
        jtj += j.transpose() * j;
        jtr += j.transpose() * r;
        cost += r.norm_squared();
    }
    Some((jtj, jtr, cost))
}

/// Refines `initial` by LM (see the module doc); `None` if the initial pose puts a point behind
/// the camera. `points_board` and `pixels` have equal length (checked by the caller).
pub fn refine_pose(
    camera: &CameraModel,
    initial: &Pose,
    points_board: &[Point3<f64>],
    pixels: &[[f64; 2]],
    max_iterations: usize,
) -> Option<RefinedPose> {
    /// The loop's state: the pose with its normal equations and cost.
    struct State {
        pose: Pose,
        jtj: Matrix6<f64>,
        jtr: Vector6<f64>,
        cost: f64,
    }
    let at = |pose: Pose| {
        normal_equations(camera, &pose, points_board, pixels).map(|(jtj, jtr, cost)| State {
            pose,
            jtj,
            jtr,
            cost,
        })
    };
    let schedule = Schedule {
        initial_damping: INITIAL_DAMPING,
        relative_cost_tolerance: COST_TOLERANCE,
        step_tolerance: STEP_TOLERANCE,
    };
    let (state, iterations) = minimise(
        at(*initial)?,
        |s: &State| s.cost,
        &schedule,
        max_iterations,
        |s, lambda| {
            let mut damped = s.jtj;
            for k in 0..6 {
                // Marquardt scaling; the floor keeps a zero diagonal (no information) from
                // making the damped system singular.
                damped[(k, k)] += lambda * s.jtj[(k, k)].max(1e-12);
            }
            let Some(chol) = damped.cholesky() else {
                return Step::Singular;
            };
            let delta = -chol.solve(&s.jtr);
            Step::Tried {
                trial: at(apply_left_update(&s.pose, &delta)),
                step_norm: delta.norm(),
            }
        },
    );
    let State {
        pose, jtj, cost, ..
    } = state;
    let residuals_px = points_board
        .iter()
        .zip(pixels)
        .map(|(p, obs)| {
            // The accepted pose keeps every point in front (normal_equations succeeded).
            let q = camera.project(&(pose * p)).unwrap_or([f64::NAN; 2]);
            [q[0] - obs[0], q[1] - obs[1]]
        })
        .collect();
    Some(RefinedPose {
        camera_from_board: pose,
        cost_px2: cost,
        residuals_px,
        normal_matrix: jtj,
        iterations,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use ellipso_model::camera::{Distortion, Intrinsics};

    #[test]
    fn pose_jacobian_matches_central_differences() {
        let cam = CameraModel {
            width: 2448,
            height: 2048,
            intrinsics: Intrinsics {
                fx: 3500.0,
                fy: 3500.0,
                cx: 1224.0,
                cy: 1024.0,
            },
            distortion: Distortion {
                k1: -0.1,
                k2: 0.05,
                k3: 0.0,
                p1: 1e-4,
                p2: -2e-4,
            },
        };
        let pose = Pose::from_parts(
            Translation3::new(0.02, -0.01, 0.5),
            UnitQuaternion::from_euler_angles(2.9, 0.2, 0.4),
        );
        let p = Point3::new(0.03, 0.04, 0.0);
        let pc = pose * p;
        let analytic =
            cam.project_with_jacobians(&pc).unwrap().d_pixel_d_point * d_point_d_left_update(&pc);
        for k in 0..6 {
            let h = 1e-7;
            let mut d = Vector6::zeros();
            d[k] = h;
            let a = cam.project(&(apply_left_update(&pose, &d) * p)).unwrap();
            let b = cam.project(&(apply_left_update(&pose, &-d) * p)).unwrap();
            for row in 0..2 {
                let numeric = (a[row] - b[row]) / (2.0 * h);
                assert!((numeric - analytic[(row, k)]).abs() < 1e-4 * numeric.abs().max(1.0));
            }
        }
    }
}
