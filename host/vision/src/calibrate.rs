//! Camera calibration from views of a planar tag board, and the flash position from specular
//! highlights on a sphere.
//!
//! [`calibrate`] pipeline (see `docs/pose.md`):
//! 1. per view: validate (finite, on the board plane z = 0, enough points) and fit the
//!    board→pixel homography (normalised DLT) — failing views are set aside with a reason;
//! 2. Zhang's closed form for fx, fy, cx, cy (zero skew) — [`zhang`];
//! 3. per view `camera_from_board` by IPPE + LM with that pinhole camera;
//! 4. k1, k2 by Zhang's linear least squares, p1 = p2 = k3 = 0;
//! 5. joint LM over camera + all poses with a Schur-complement solver — [`bundle`];
//! 6. views whose RMS exceeds both `outlier_factor`×median and `outlier_floor_px` are rejected
//!    and step 5 repeats (at most `max_outlier_rounds` times);
//! 7. standard errors from σ²·S⁻¹, σ² = cost/(2N − p);
//! 8. the camera must be determined by the views ([`determined`]): a focal length or principal
//!    point known only roughly, or uncertainties the cost's shape contradicts (a near-degenerate
//!    view set, [`spread`]), are refused with how to take calibration photos.
//!
//! [`flash`] estimates the flash position in the camera frame, [`flash_polariser`] its polariser
//! angle, [`flash_session`] both from a session's sphere frames; [`session`] is `ellipso
//! calibrate` (and `ellipso calibrate flash`): on a recorded session, the rig file's sections
//! written.

pub mod bundle;
pub mod determined;
pub mod flash;
pub mod flash_polariser;
pub mod flash_session;
pub mod highlight;
pub mod report;
pub mod session;
pub mod spread;
pub mod views;
pub mod zhang;

use ellipso_model::camera::{CAMERA_PARAM_COUNT, CameraModel, Distortion, Pose};
use nalgebra::{Matrix3, Point2, Point3, SMatrix};

use crate::pose::estimate::{Correspondence, PoseConfig, PoseRejection, estimate_board_pose};
use crate::pose::homography::{HomographyError, homography_dlt};
use bundle::{BundleResult, ViewData, bundle_adjust, invert_scaled};
use zhang::{ZhangError, intrinsics_from_homographies, radial_initialisation};

/// Settings of [`calibrate`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CalibConfig {
    /// Fewer usable views than this is an error; values below 3 count as 3 (the closed form's
    /// minimum). Default 3 — but use ≥ 10 views with varied tilt for a good calibration.
    pub min_views: usize,
    /// Views with fewer points are set aside. Default 8.
    pub min_points_per_view: usize,
    /// Hold k3 at 0. Default true: k3 is poorly determined unless corners reach the image corners,
    /// and a free k3 trades off against k1/k2.
    pub fix_k3: bool,
    /// Hold p1 = p2 = 0. Default false.
    pub fix_tangential: bool,
    /// A view is an outlier when its RMS exceeds this multiple of the median view RMS and also
    /// `outlier_floor_px`. Default 3.
    pub outlier_factor: f64,
    /// Views at or below this RMS (px) are never outliers, however good the others are.
    /// Default 0.5 px.
    pub outlier_floor_px: f64,
    /// Outlier rejection rounds (each re-runs the joint LM). Default 3.
    pub max_outlier_rounds: usize,
    /// Joint LM iteration cap. Default 100.
    pub max_iterations: usize,
    /// Largest 1σ of a focal length, as a fraction of it, for the camera to count as
    /// determined ([`determined`]). Default 0.005.
    pub max_focal_rel_std: f64,
    /// Largest 1σ of a principal-point coordinate, as a fraction of the image side. Default
    /// 0.01.
    pub max_centre_std_frac: f64,
}

impl Default for CalibConfig {
    fn default() -> Self {
        CalibConfig {
            min_views: 3,
            min_points_per_view: 8,
            fix_k3: true,
            fix_tangential: false,
            outlier_factor: 3.0,
            outlier_floor_px: 0.5,
            max_outlier_rounds: 3,
            max_iterations: 100,
            max_focal_rel_std: 0.005,
            max_centre_std_frac: 0.01,
        }
    }
}

/// Why a view was left out of the calibration.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ViewRejection {
    /// Too few points.
    #[error("too few points: {found}, need {required}")]
    TooFewPoints { found: usize, required: usize },
    /// A coordinate is NaN or infinite.
    #[error("point {point} is not finite")]
    NotFinite { point: usize },
    /// A board point is off the z = 0 plane.
    #[error("point {point} is off the board plane (z = {z_m} m); calibration needs z = 0")]
    OffBoardPlane { point: usize, z_m: f64 },
    /// The homography could not be fitted.
    #[error("homography: {0}")]
    Homography(#[from] HomographyError),
    /// No pose for the view with the closed-form camera.
    #[error("initial pose: {0}")]
    Pose(#[from] PoseRejection),
    /// Reprojection RMS far above the other views (wrong detection, motion blur, moved board).
    #[error("outlier: view RMS {rms_px:.3} px vs median {median_rms_px:.3} px")]
    Outlier { rms_px: f64, median_rms_px: f64 },
}

/// A view that was left out, by its index in the input.
#[derive(Debug, Clone, PartialEq)]
pub struct RejectedView {
    /// Index into the `views` argument.
    pub index: usize,
    /// Why.
    pub reason: ViewRejection,
}

/// Why calibration failed as a whole.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CalibError {
    /// Image size is zero.
    #[error("image size {width}×{height} is empty")]
    EmptyImage { width: u32, height: u32 },
    /// Too few views survived validation / outlier rejection.
    #[error("only {usable} usable views, need {required} ({} rejected: {})", rejected.len(),
        rejected.iter().map(|r| format!("view {}: {}", r.index, r.reason)).collect::<Vec<_>>().join("; "))]
    TooFewViews {
        usable: usize,
        required: usize,
        rejected: Vec<RejectedView>,
    },
    /// Zhang's closed form failed.
    #[error(transparent)]
    ClosedForm(#[from] ZhangError),
    /// The joint optimisation could not run (a board behind the camera or a singular system).
    #[error("joint optimisation failed: {0}")]
    Optimisation(&'static str),
    /// The views do not determine the camera (see [`determined`]).
    #[error("{0}")]
    Undetermined(Box<determined::Undetermined>),
}

/// One calibrated view.
#[derive(Debug, Clone, PartialEq)]
pub struct CalibratedView {
    /// Index into the `views` argument.
    pub index: usize,
    /// Board frame → camera frame.
    pub camera_from_board: Pose,
    /// Reprojection RMS of this view, px.
    pub rms_px: f64,
    /// Points in the view.
    pub points: usize,
}

/// A calibrated camera with its uncertainty.
#[derive(Debug, Clone, PartialEq)]
pub struct Calibration {
    /// The camera model.
    pub camera: CameraModel,
    /// 1σ standard errors in the order `[fx, fy, cx, cy, k1, k2, p1, p2, k3]` (0 for fixed).
    pub std_errors: [f64; CAMERA_PARAM_COUNT],
    /// Covariance of the camera parameters in the same order (rows of fixed ones are 0).
    pub covariance: SMatrix<f64, CAMERA_PARAM_COUNT, CAMERA_PARAM_COUNT>,
    /// Which parameters were estimated (false = held fixed).
    pub estimated: [bool; CAMERA_PARAM_COUNT],
    /// Reprojection RMS over all points of the kept views, √(Σ‖r‖²/N), px.
    pub rms_px: f64,
    /// Kept views with their poses.
    pub views: Vec<CalibratedView>,
    /// Views left out, with reasons.
    pub rejected: Vec<RejectedView>,
    /// Joint LM iterations of the final round.
    pub iterations: usize,
    /// How varied the kept views' board orientations are.
    pub spread: spread::ViewSpread,
}

/// Validated points of one view.
struct Prepared {
    index: usize,
    points: Vec<Point3<f64>>,
    pixels: Vec<[f64; 2]>,
}

fn prepare(
    index: usize,
    view: &[(Point3<f64>, Point2<f64>)],
    config: &CalibConfig,
) -> Result<Prepared, ViewRejection> {
    let required = config.min_points_per_view.max(4);
    if view.len() < required {
        return Err(ViewRejection::TooFewPoints {
            found: view.len(),
            required,
        });
    }
    for (point, (p, q)) in view.iter().enumerate() {
        if !(p
            .coords
            .iter()
            .chain(q.coords.iter())
            .all(|v| v.is_finite()))
        {
            return Err(ViewRejection::NotFinite { point });
        }
        // 1 µm: boards are printed flat; anything larger is a caller mix-up of frames.
        if p.z.abs() > 1e-6 {
            return Err(ViewRejection::OffBoardPlane { point, z_m: p.z });
        }
    }
    Ok(Prepared {
        index,
        points: view.iter().map(|(p, _)| *p).collect(),
        pixels: view.iter().map(|(_, q)| [q.x, q.y]).collect(),
    })
}

/// The error for `usable` views left when `config` needs more.
fn too_few(usable: usize, rejected: &[RejectedView], config: &CalibConfig) -> CalibError {
    CalibError::TooFewViews {
        usable,
        required: config.min_views.max(3),
        rejected: rejected.to_vec(),
    }
}

/// The kept views as the joint optimisation reads them.
fn view_data(kept: &[Prepared]) -> Vec<ViewData<'_>> {
    kept.iter()
        .map(|p| ViewData {
            points_board: &p.points,
            pixels: &p.pixels,
        })
        .collect()
}

/// Step 1: each view validated and its board→pixel homography fitted; the views that fail go
/// to `rejected` with why. Returns the prepared views and their homographies, in input order.
fn fit_homographies(
    views: &[Vec<(Point3<f64>, Point2<f64>)>],
    config: &CalibConfig,
    rejected: &mut Vec<RejectedView>,
) -> (Vec<Prepared>, Vec<Matrix3<f64>>) {
    let mut prepared = Vec::new();
    let mut homographies = Vec::new();
    for (index, view) in views.iter().enumerate() {
        let result = prepare(index, view, config).and_then(|p| {
            let xy: Vec<[f64; 2]> = p.points.iter().map(|q| [q.x, q.y]).collect();
            Ok((homography_dlt(&xy, &p.pixels)?, p))
        });
        match result {
            Ok((h, p)) => {
                homographies.push(h);
                prepared.push(p);
            }
            Err(reason) => rejected.push(RejectedView { index, reason }),
        }
    }
    (prepared, homographies)
}

/// Step 2: the pinhole camera (zero distortion) of Zhang's closed form.
fn closed_form_camera(
    homographies: &[Matrix3<f64>],
    width: u32,
    height: u32,
) -> Result<CameraModel, CalibError> {
    let intrinsics = intrinsics_from_homographies(homographies, width, height)?;
    let pinhole = CameraModel::pinhole(width, height, intrinsics);
    pinhole
        .validate()
        .map_err(|_| CalibError::Optimisation("closed form gave an invalid camera"))?;
    Ok(pinhole)
}

/// Step 3: each view's initial `camera_from_board` with the pinhole camera; views it cannot
/// pose go to `rejected`. Returns the kept views and their poses.
fn initial_poses(
    pinhole: &CameraModel,
    prepared: Vec<Prepared>,
    rejected: &mut Vec<RejectedView>,
) -> (Vec<Prepared>, Vec<Pose>) {
    // Permissive: only geometry can reject here.
    let pose_config = PoseConfig {
        min_tags: 0,
        min_corners: 4,
        max_rms_px: f64::INFINITY,
        min_flip_ratio: 0.0,
        ..PoseConfig::default()
    };
    let mut kept = Vec::new();
    let mut poses = Vec::new();
    for p in prepared {
        let corr: Vec<Correspondence> = p
            .points
            .iter()
            .zip(&p.pixels)
            .enumerate()
            .map(|(k, (q, px))| Correspondence {
                tag_id: 0,
                corner: (k % 4) as u8,
                point_board_m: *q,
                pixel: *px,
            })
            .collect();
        match estimate_board_pose(pinhole, &corr, &pose_config) {
            Ok(bp) => {
                poses.push(bp.camera_from_board);
                kept.push(p);
            }
            Err(e) => rejected.push(RejectedView {
                index: p.index,
                reason: e.into(),
            }),
        }
    }
    (kept, poses)
}

/// Step 4: the pinhole camera with k1, k2 from the radial initialisation (Zhang §3.3).
fn with_radial_start(pinhole: CameraModel, kept: &[Prepared], poses: &[Pose]) -> CameraModel {
    let mut samples = Vec::new();
    for (p, pose) in kept.iter().zip(poses) {
        for (q, px) in p.points.iter().zip(&p.pixels) {
            let c = pose * q;
            let norm = [c.x / c.z, c.y / c.z];
            samples.push((norm, pinhole.normalised_to_pixel(norm), *px));
        }
    }
    let [k1, k2] = radial_initialisation(&pinhole.intrinsics, &samples);
    CameraModel {
        distortion: Distortion {
            k1,
            k2,
            ..Distortion::ZERO
        },
        ..pinhole
    }
}

/// Which camera parameters are estimated under `config`.
fn free_parameters(config: &CalibConfig) -> [bool; CAMERA_PARAM_COUNT] {
    let mut free = [true; CAMERA_PARAM_COUNT];
    if config.fix_tangential {
        free[6] = false;
        free[7] = false;
    }
    if config.fix_k3 {
        free[8] = false;
    }
    free
}

/// Steps 5 and 6: the joint LM, repeated without the outlier views (removed from `kept` and
/// added to `rejected`) until none is left or the rounds run out. Returns the last round.
fn adjust_rejecting_outliers(
    mut camera: CameraModel,
    mut poses: Vec<Pose>,
    kept: &mut Vec<Prepared>,
    free: &[bool; CAMERA_PARAM_COUNT],
    config: &CalibConfig,
    rejected: &mut Vec<RejectedView>,
) -> Result<BundleResult, CalibError> {
    let mut round = 0;
    loop {
        let data = view_data(kept);
        let result = bundle_adjust(&camera, &poses, &data, free, config.max_iterations).ok_or(
            CalibError::Optimisation("a board is behind the camera at the start"),
        )?;
        let mut rms: Vec<f64> = kept
            .iter()
            .zip(&result.view_cost_px2)
            .map(|(p, c)| (c / p.points.len() as f64).sqrt())
            .collect();
        let view_rms = rms.clone();
        let median = ellipso_model::stats::median(&mut rms);
        let threshold = (config.outlier_factor * median).max(config.outlier_floor_px);
        let outliers: Vec<usize> = (0..kept.len())
            .filter(|&i| view_rms[i] > threshold)
            .collect();
        if outliers.is_empty() || round >= config.max_outlier_rounds {
            return Ok(result);
        }
        round += 1;
        for &i in outliers.iter().rev() {
            let p = kept.remove(i);
            rejected.push(RejectedView {
                index: p.index,
                reason: ViewRejection::Outlier {
                    rms_px: view_rms[i],
                    median_rms_px: median,
                },
            });
        }
        if kept.len() < config.min_views.max(3) {
            return Err(too_few(kept.len(), rejected, config));
        }
        camera = result.camera;
        poses = result
            .poses
            .into_iter()
            .enumerate()
            .filter(|(i, _)| !outliers.contains(i))
            .map(|(_, p)| p)
            .collect();
    }
}

/// Step 7's result: the camera parameters' uncertainty.
struct Uncertainty {
    /// σ² = cost/(2N − p), px².
    sigma2_px2: f64,
    /// σ²·S⁻¹, rows and columns of fixed parameters 0.
    covariance: SMatrix<f64, CAMERA_PARAM_COUNT, CAMERA_PARAM_COUNT>,
    /// √ of the covariance diagonal.
    std_errors: [f64; CAMERA_PARAM_COUNT],
}

/// Step 7: standard errors from σ²·S⁻¹ over `n_points` points of the kept views.
fn uncertainty(
    result: &BundleResult,
    n_points: usize,
    n_views: usize,
    free: &[bool; CAMERA_PARAM_COUNT],
) -> Result<Uncertainty, CalibError> {
    let n_params = free.iter().filter(|f| **f).count() + 6 * n_views;
    // 2N > p whenever each view has ≥ 4 points and there are ≥ 3 views; max(1) guards anyway.
    let sigma2 = result.cost_px2 / (2 * n_points).saturating_sub(n_params).max(1) as f64;
    let inv = invert_scaled(&result.schur).ok_or(CalibError::Optimisation(
        "camera parameters are not determined",
    ))?;
    let mut covariance = inv * sigma2;
    for (k, is_free) in free.iter().enumerate() {
        if !is_free {
            covariance.row_mut(k).fill(0.0);
            covariance.column_mut(k).fill(0.0);
        }
    }
    // Covariance diagonal ≥ 0 up to round-off: clamp before sqrt.
    let std_errors = std::array::from_fn(|k| covariance[(k, k)].max(0.0).sqrt());
    Ok(Uncertainty {
        sigma2_px2: sigma2,
        covariance,
        std_errors,
    })
}

/// Calibrates a camera from views of a planar board (points on z = 0 of the board frame, with
/// their observed pixels in the integer-centre convention). See the module doc.
pub fn calibrate(
    views: &[Vec<(Point3<f64>, Point2<f64>)>],
    image_size: (u32, u32),
    config: &CalibConfig,
) -> Result<Calibration, CalibError> {
    let (width, height) = image_size;
    if width == 0 || height == 0 {
        return Err(CalibError::EmptyImage { width, height });
    }
    let mut rejected = Vec::new();
    let (prepared, homographies) = fit_homographies(views, config, &mut rejected);
    if prepared.len() < config.min_views.max(3) {
        return Err(too_few(prepared.len(), &rejected, config));
    }
    let pinhole = closed_form_camera(&homographies, width, height)?;
    let (mut kept, poses) = initial_poses(&pinhole, prepared, &mut rejected);
    if kept.len() < config.min_views.max(3) {
        return Err(too_few(kept.len(), &rejected, config));
    }
    let camera = with_radial_start(pinhole, &kept, &poses);
    let free = free_parameters(config);
    let result = adjust_rejecting_outliers(camera, poses, &mut kept, &free, config, &mut rejected)?;
    rejected.sort_by_key(|r| r.index);

    let n_points: usize = kept.iter().map(|p| p.points.len()).sum();
    let Uncertainty {
        sigma2_px2,
        covariance,
        std_errors,
    } = uncertainty(&result, n_points, kept.len(), &free)?;
    let spread = spread::view_spread(&result.poses);
    determined::check(
        &result.camera,
        &std_errors,
        &covariance,
        &result.poses,
        &view_data(&kept),
        &free,
        result.cost_px2,
        sigma2_px2,
        spread,
        config,
    )
    .map_err(|u| CalibError::Undetermined(Box::new(u)))?;
    let views_out = kept
        .iter()
        .zip(&result.poses)
        .zip(&result.view_cost_px2)
        .map(|((p, pose), c)| CalibratedView {
            index: p.index,
            camera_from_board: *pose,
            rms_px: (c / p.points.len() as f64).sqrt(),
            points: p.points.len(),
        })
        .collect();
    Ok(Calibration {
        camera: result.camera,
        std_errors,
        covariance,
        estimated: free,
        rms_px: (result.cost_px2 / n_points as f64).sqrt(),
        views: views_out,
        rejected,
        iterations: result.iterations,
        spread,
    })
}

#[cfg(test)]
mod tests;
