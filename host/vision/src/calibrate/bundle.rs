//! Joint Levenberg–Marquardt over the camera parameters `[fx, fy, cx, cy, k1, k2, p1, p2, k3]`
//! and one 6-dof pose per view, on pixel reprojection error, with the analytic Jacobians of
//! [`ellipso_model::camera`] and the left pose update of [`crate::pose::refine`].
//!
//! The normal equations have the arrow structure [[U, W], [Wᵀ, V]] with U 9×9 (camera), V
//! block-diagonal 6×6 (one block per view) and W 9×6n. They are never formed densely: each LM
//! step eliminates the pose blocks by the Schur complement S = U − Σ Wᵢ Vᵢ⁻¹ Wᵢᵀ (9×9), solves
//! for the camera step, then back-substitutes each pose step — O(n) per iteration, so 300 views
//! cost the same per view as 3. S is Jacobi-scaled before its Cholesky solve because its diagonal
//! spans ~14 orders of magnitude (fx² vs k3). Fixed parameters have their columns zeroed and
//! unit diagonals, so their steps are exactly 0. At the solution, σ²·S⁻¹ (undamped) is the
//! marginal covariance of the camera parameters. The loop (λ schedule from 1e-3, acceptance,
//! stops) is the crate's one [`crate::lm::minimise`]; it stops once an accepted step lowers the
//! cost by ≤ 1e-14 relatively. The damping is Marquardt's on U and on each Vᵢ, without the pose
//! refinement's diagonal floor (a camera parameter without information is fixed instead).

use ellipso_model::camera::{CAMERA_PARAM_COUNT, CameraModel, Pose};
use nalgebra::{Matrix6, Point3, SMatrix, SVector, Vector2, Vector6};

use crate::lm::{Schedule, Step, minimise};
use crate::pose::refine::{apply_left_update, d_point_d_left_update};

type CamMat = SMatrix<f64, CAMERA_PARAM_COUNT, CAMERA_PARAM_COUNT>;
type CamVec = SVector<f64, CAMERA_PARAM_COUNT>;
type CrossMat = SMatrix<f64, CAMERA_PARAM_COUNT, 6>;

/// One view's observations: board points (z = 0) and observed pixels.
pub struct ViewData<'a> {
    /// Board-frame points, m.
    pub points_board: &'a [Point3<f64>],
    /// Observed pixels, px.
    pub pixels: &'a [[f64; 2]],
}

/// Output of [`bundle_adjust`].
pub struct BundleResult {
    /// Refined camera.
    pub camera: CameraModel,
    /// Refined `camera_from_board` per view.
    pub poses: Vec<Pose>,
    /// Total squared reprojection error, px².
    pub cost_px2: f64,
    /// Squared reprojection error per view, px².
    pub view_cost_px2: Vec<f64>,
    /// Undamped Schur complement S at the solution (fixed parameters: unit rows).
    pub schur: CamMat,
    /// LM iterations taken.
    pub iterations: usize,
}

struct Normal {
    u: CamMat,
    g_c: CamVec,
    v: Vec<Matrix6<f64>>,
    w: Vec<CrossMat>,
    g_p: Vec<Vector6<f64>>,
    cost: f64,
    view_cost: Vec<f64>,
}

/// Builds the blocks of the normal equations; `None` if a point is behind its camera.
fn build(
    camera: &CameraModel,
    poses: &[Pose],
    views: &[ViewData<'_>],
    free: &[bool; CAMERA_PARAM_COUNT],
) -> Option<Normal> {
    let n = views.len();
    let mut out = Normal {
        u: CamMat::zeros(),
        g_c: CamVec::zeros(),
        v: vec![Matrix6::zeros(); n],
        w: vec![CrossMat::zeros(); n],
        g_p: vec![Vector6::zeros(); n],
        cost: 0.0,
        view_cost: vec![0.0; n],
    };
    for (i, (view, pose)) in views.iter().zip(poses).enumerate() {
        for (p, obs) in view.points_board.iter().zip(view.pixels) {
            let pc = pose * p;
            let pj = camera.project_with_jacobians(&pc)?;
            let mut j_c = pj.d_pixel_d_params;
            for (k, is_free) in free.iter().enumerate() {
                if !is_free {
                    j_c.column_mut(k).fill(0.0);
                }
            }
            let j_p = pj.d_pixel_d_point * d_point_d_left_update(&pc);
            let r = Vector2::new(pj.pixel[0] - obs[0], pj.pixel[1] - obs[1]);
            out.u += j_c.transpose() * j_c;
            out.g_c += j_c.transpose() * r;
            out.v[i] += j_p.transpose() * j_p;
            out.w[i] += j_c.transpose() * j_p;
            out.g_p[i] += j_p.transpose() * r;
            out.view_cost[i] += r.norm_squared();
        }
        out.cost += out.view_cost[i];
    }
    Some(out)
}

/// Schur complement of the damped system and the reduced right-hand side −g_c + Σ WᵢVᵢ⁻¹gᵢ;
/// also returns the damped Vᵢ⁻¹. `None` if a pose block is singular.
fn schur(
    ne: &Normal,
    lambda: f64,
    free: &[bool; CAMERA_PARAM_COUNT],
) -> Option<(CamMat, CamVec, Vec<Matrix6<f64>>)> {
    let mut s = ne.u;
    for k in 0..CAMERA_PARAM_COUNT {
        s[(k, k)] = if free[k] {
            ne.u[(k, k)] * (1.0 + lambda)
        } else {
            1.0
        };
    }
    let mut rhs = -ne.g_c;
    let mut v_inv = Vec::with_capacity(ne.v.len());
    for ((v, w), g) in ne.v.iter().zip(&ne.w).zip(&ne.g_p) {
        let mut vd = *v;
        for k in 0..6 {
            vd[(k, k)] += lambda * v[(k, k)];
        }
        let inv = vd.cholesky()?.inverse();
        let y = w * inv;
        s -= y * w.transpose();
        rhs += y * g;
        v_inv.push(inv);
    }
    Some((s, rhs, v_inv))
}

/// Solves S x = b with Jacobi scaling (see the module doc).
pub(crate) fn solve_scaled(s: &CamMat, b: &CamVec) -> Option<CamVec> {
    let d = CamVec::from_iterator(
        (0..CAMERA_PARAM_COUNT).map(|k| 1.0 / s[(k, k)].max(f64::MIN_POSITIVE).sqrt()),
    );
    let scaled = CamMat::from_fn(|i, j| s[(i, j)] * d[i] * d[j]);
    let y = scaled.cholesky()?.solve(&b.component_mul(&d));
    Some(y.component_mul(&d))
}

/// Inverse of S with Jacobi scaling.
pub(crate) fn invert_scaled(s: &CamMat) -> Option<CamMat> {
    let d = CamVec::from_iterator(
        (0..CAMERA_PARAM_COUNT).map(|k| 1.0 / s[(k, k)].max(f64::MIN_POSITIVE).sqrt()),
    );
    let scaled = CamMat::from_fn(|i, j| s[(i, j)] * d[i] * d[j]);
    let inv = scaled.cholesky()?.inverse();
    Some(CamMat::from_fn(|i, j| inv[(i, j)] * d[i] * d[j]))
}

/// Runs LM from (camera, poses). `None` if the initial state puts a point behind its camera.
pub fn bundle_adjust(
    camera: &CameraModel,
    poses: &[Pose],
    views: &[ViewData<'_>],
    free: &[bool; CAMERA_PARAM_COUNT],
    max_iterations: usize,
) -> Option<BundleResult> {
    /// The loop's state: camera, poses and their normal equations (with the cost).
    struct State {
        cam: CameraModel,
        poses: Vec<Pose>,
        ne: Normal,
    }
    let schedule = Schedule {
        initial_damping: 1e-3,
        relative_cost_tolerance: 1e-14,
        step_tolerance: 0.0,
    };
    let start = State {
        cam: *camera,
        poses: poses.to_vec(),
        ne: build(camera, poses, views, free)?,
    };
    let (state, iterations) = minimise(
        start,
        |s: &State| s.ne.cost,
        &schedule,
        max_iterations,
        |s, lambda| {
            let ne = &s.ne;
            let step = schur(ne, lambda, free)
                .and_then(|(sc, rhs, v_inv)| Some((solve_scaled(&sc, &rhs)?, v_inv)));
            let Some((d_cam, v_inv)) = step else {
                return Step::Singular;
            };
            let mut trial_params = s.cam.params();
            for (p, d) in trial_params.iter_mut().zip(d_cam.iter()) {
                *p += d;
            }
            let trial_cam = s.cam.with_params(&trial_params);
            let trial_poses: Vec<Pose> = s
                .poses
                .iter()
                .enumerate()
                .map(|(i, pose)| {
                    let d_pose = v_inv[i] * (-ne.g_p[i] - ne.w[i].transpose() * d_cam);
                    apply_left_update(pose, &d_pose)
                })
                .collect();
            let trial = if trial_cam.validate().is_ok() {
                build(&trial_cam, &trial_poses, views, free).map(|ne| State {
                    cam: trial_cam,
                    poses: trial_poses,
                    ne,
                })
            } else {
                None
            };
            Step::Tried {
                trial,
                step_norm: 0.0,
            }
        },
    );
    let State { cam, poses, ne } = state;
    let (schur_undamped, _, _) = schur(&ne, 0.0, free)?;
    Some(BundleResult {
        camera: cam,
        poses,
        cost_px2: ne.cost,
        view_cost_px2: ne.view_cost,
        schur: schur_undamped,
        iterations,
    })
}
