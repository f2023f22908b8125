//! Does a calibration know what it says? The checks between the joint optimisation and the
//! answer: a camera the views do not determine is refused, with what to photograph instead,
//! rather than returned with uncertainties that do not cover the truth.
//!
//! Two checks (`docs/pose.md`, "When calibration refuses"):
//! 1. **Precision.** The stated 1σ of each focal length must be at most
//!    [`CalibConfig::max_focal_rel_std`] of it, and of each principal-point coordinate at most
//!    [`CalibConfig::max_centre_std_frac`] of the image side: a camera known to ±5 % is no
//!    calibration.
//! 2. **Honest uncertainty.** Near a degenerate view set (every board tilted about one camera
//!    axis, [`super::spread`]) the cost is a long curved valley: the optimum found can be far from
//!    the truth while the local curvature — the covariance — says it is sharp. The hypothesis
//!    "principal point at the image centre" is tested two ways: the Wald distance of the
//!    estimate from it under the stated covariance, and the likelihood ratio (the rise of the
//!    cost, in σ², when the principal point is held there and everything else re-optimised). For
//!    a problem the covariance describes, the two agree; when the Wald distance is significant
//!    (> χ²₂ at 0.999) and the likelihood ratio is less than a quarter of it, the stated
//!    uncertainty understates the real one at least twofold, and the calibration is refused. The
//!    same is asked without the hypothesis: the principal point held 3 stated σ away along its
//!    least certain direction (both ways) must raise χ² by at least a quarter of the 9 the
//!    covariance predicts.

use ellipso_model::camera::{CAMERA_PARAM_COUNT, CameraModel, Pose};
use nalgebra::{Matrix2, SMatrix, Vector2};

use super::CalibConfig;
use super::bundle::{ViewData, bundle_adjust};
use super::spread::ViewSpread;

/// How far, in stated σ, the profile probe moves the principal point.
const PROBE_SIGMAS: f64 = 3.0;

/// χ² with 2 degrees of freedom at 0.999.
const CHI2_2_999: f64 = 13.815_510_557_964_274;

/// How to take photos a camera can be calibrated from.
pub const HOW_TO: &str = "take 15–30 calibration photos of the board alone (no object on it), \
     filling much of the frame, tilted 20–45° in turn left, right, up and down and rotated in \
     its plane, with the board reaching every part of the image, corners included; an orbit \
     around an object at one camera roll tilts the board about one axis only and cannot \
     calibrate a camera";

/// Why the views do not determine the camera.
#[derive(Debug, Clone, PartialEq)]
pub struct Undetermined {
    /// What was found, in words (parameter, estimate, its σ, the test's figures).
    pub why: String,
    /// The spread of the views' board orientations.
    pub spread: ViewSpread,
}

impl std::fmt::Display for Undetermined {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "the views do not determine the camera: {}; the board's tilt spans {:.1}° RMS but \
             only {:.1}° out of one plane",
            self.why, self.spread.tilt_spread_deg, self.spread.out_of_plane_deg
        )?;
        if self.spread.out_of_plane_deg < 2.0 {
            let d = self.spread.common_direction_camera;
            let axis = if d.x.abs() >= d.y.abs() {
                "horizontal"
            } else {
                "vertical"
            };
            write!(
                f,
                " (every view tilts the board about the camera's {axis} axis, the degenerate case \
                 of plane-based calibration)"
            )?;
        }
        write!(f, ". To calibrate, {HOW_TO}")
    }
}

/// The two checks of the module doc on a finished joint optimisation.
#[expect(
    clippy::too_many_arguments,
    reason = "the state of one finished optimisation"
)]
pub fn check(
    camera: &CameraModel,
    std_errors: &[f64; CAMERA_PARAM_COUNT],
    covariance: &SMatrix<f64, CAMERA_PARAM_COUNT, CAMERA_PARAM_COUNT>,
    poses: &[Pose],
    views: &[ViewData<'_>],
    free: &[bool; CAMERA_PARAM_COUNT],
    cost_px2: f64,
    sigma2_px2: f64,
    spread: ViewSpread,
    config: &CalibConfig,
) -> Result<(), Undetermined> {
    let undetermined = |why: String| Undetermined { why, spread };
    let p = camera.params();
    let sides = [f64::from(camera.width), f64::from(camera.height)];
    for (k, name) in ["fx", "fy"].iter().enumerate() {
        // a focal length is positive (validated camera): the ratio is defined
        let rel = std_errors[k] / p[k].abs().max(f64::MIN_POSITIVE);
        if rel > config.max_focal_rel_std {
            return Err(undetermined(format!(
                "{name} = {:.1} ± {:.1} px (± {:.1} %, more than {:.1} %)",
                p[k],
                std_errors[k],
                100.0 * rel,
                100.0 * config.max_focal_rel_std
            )));
        }
    }
    for (k, name) in ["cx", "cy"].iter().enumerate() {
        let frac = std_errors[2 + k] / sides[k];
        if frac > config.max_centre_std_frac {
            return Err(undetermined(format!(
                "{name} = {:.1} ± {:.1} px (± {:.1} % of the image side, more than {:.1} %)",
                p[2 + k],
                std_errors[2 + k],
                100.0 * frac,
                100.0 * config.max_centre_std_frac
            )));
        }
    }
    // the hypothesis: the principal point at the image centre (integer-centre convention)
    let centre = Vector2::new((sides[0] - 1.0) / 2.0, (sides[1] - 1.0) / 2.0);
    let delta = Vector2::new(p[2], p[3]) - centre;
    let block = Matrix2::new(
        covariance[(2, 2)],
        covariance[(2, 3)],
        covariance[(3, 2)],
        covariance[(3, 3)],
    );
    let Some(inverse) = block.try_inverse() else {
        return Err(undetermined(
            "the principal point's covariance is singular".into(),
        ));
    };
    // the rise of χ² when the principal point is held at `at` and the rest re-optimised
    let likelihood_ratio = |at: Vector2<f64>| -> f64 {
        let mut held = *camera;
        held.intrinsics.cx = at.x;
        held.intrinsics.cy = at.y;
        let mut free_held = *free;
        free_held[2] = false;
        free_held[3] = false;
        match bundle_adjust(&held, poses, views, &free_held, config.max_iterations) {
            // σ² > 0 unless every point fits exactly; then any rise is significant
            Some(refit) => (refit.cost_px2 - cost_px2).max(0.0) / sigma2_px2.max(1e-300),
            // the held camera puts a board behind it: the data reject it outright
            None => f64::INFINITY,
        }
    };
    // a probe PROBE_SIGMAS stated σ along the principal point's least certain direction, both
    // ways: a problem its covariance describes rises by PROBE_SIGMAS² there
    let eig = block.symmetric_eigen();
    let k = usize::from(eig.eigenvalues[1] > eig.eigenvalues[0]);
    let step = eig.eigenvectors.column(k) * (PROBE_SIGMAS * eig.eigenvalues[k].max(0.0).sqrt());
    for sign in [1.0, -1.0] {
        let at = Vector2::new(p[2], p[3]) + sign * step;
        let rise = likelihood_ratio(at);
        if rise < PROBE_SIGMAS * PROBE_SIGMAS / 4.0 {
            return Err(undetermined(format!(
                "moving the principal point {PROBE_SIGMAS}σ of its stated uncertainty, to \
                 ({:.1}, {:.1}) px, raises the fit's χ² by only {rise:.2} where {:.0} is expected: \
                 the views leave the camera free along a valley its uncertainty does not show \
                 (estimate fx {:.1}, fy {:.1}, cx {:.1}, cy {:.1} px)",
                at.x,
                at.y,
                PROBE_SIGMAS * PROBE_SIGMAS,
                p[0],
                p[1],
                p[2],
                p[3]
            )));
        }
    }
    let wald = delta.dot(&(inverse * delta));
    if wald <= CHI2_2_999 {
        return Ok(());
    }
    let likelihood_ratio = likelihood_ratio(centre);
    if likelihood_ratio < wald / 4.0 {
        return Err(undetermined(format!(
            "the estimate (fx {:.1}, fy {:.1}, cx {:.1}, cy {:.1} px) puts the principal point \
             {:.0}σ from the image centre by its stated uncertainty, yet holding it at the \
             centre raises the fit's χ² by only {:.1} (the stated uncertainty predicts {:.0}): \
             the views leave the camera free along a valley its uncertainty does not show",
            p[0],
            p[1],
            p[2],
            p[3],
            wald.sqrt(),
            likelihood_ratio,
            wald
        )));
    }
    Ok(())
}
