//! Joint board pose: one PnP over every corner of every visible tag of a board (never per tag),
//! with frame rejection for a typed reason.
//!
//! Pipeline: validate input → undistort observed corners → initialise (coplanar points: both
//! IPPE solutions; non-coplanar: linear DLT) → LM-refine every candidate on pixel reprojection
//! error with distortion ([`super::refine`]) → keep the lower-cost one → per-tag robust step →
//! flip margin, RMS, residuals, covariance → accept or reject per [`PoseConfig`].
//!
//! Per-tag robust step: one bad tag costs a tag, not the frame. A tag whose corners reproject
//! with an RMS above both [`PoseConfig::tag_outlier_factor`] × the median tag's and
//! [`PoseConfig::max_rms_px`] (a tag cut by the object's silhouette, decoded with a corner in
//! the wrong place) is dropped and the joint pose solved again without it — the worst tag first,
//! one at a time, at most a third of the tags (one when fewer than six), and never below
//! [`PoseConfig::min_tags`] and [`PoseConfig::min_corners`]. A frame whose tags are all equally
//! bad (a wrong camera model, a moved board) keeps them all and is rejected as before. Dropped
//! tags are listed in [`BoardPose::dropped_tags`].

use std::collections::BTreeSet;

use ellipso_model::camera::{CameraModel, Pose};
use nalgebra::{Matrix3, Matrix6, Point3, SMatrix, Vector3};

use super::dlt::dlt_pose;
use super::ippe::{IppeError, ippe_planar};
use super::refine::{RefinedPose, refine_pose};

/// One 2-D/3-D correspondence: a tag corner on the board and where it was seen.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Correspondence {
    /// Tag the corner belongs to (used for the tag-count check and in diagnostics).
    pub tag_id: u32,
    /// Corner index 0..4 in the detector's order (see [`super::detect`]).
    pub corner: u8,
    /// The corner in the board frame, metres.
    pub point_board_m: Point3<f64>,
    /// The observed corner, px, integer-centre (OpenCV) convention, distorted (raw image).
    pub pixel: [f64; 2],
}

/// Acceptance thresholds and solver limits of [`estimate_board_pose`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseConfig {
    /// Fewer distinct tags than this rejects the frame. Default 2: a single tag's pose flips
    /// (AprilTag issues #71, #114) and its ≈1 % of the image cannot pin the rotation.
    pub min_tags: usize,
    /// Fewer corners than this rejects the frame. Default 8 (two whole tags).
    pub min_corners: usize,
    /// Reprojection RMS (px, over points, √(Σ‖r‖²/N)) above this rejects the frame: a wrong
    /// detection, a moved board or a wrong camera model. Default 1.0 px.
    pub max_rms_px: f64,
    /// When the two planar candidates refine to different minima, the flip ratio (see
    /// [`BoardPose::flip_ratio`]) must reach this or the frame is rejected as an ambiguous flip.
    /// Default 4.0.
    pub min_flip_ratio: f64,
    /// Expected per-coordinate corner noise of the detector, px (1σ). Floors the denominator of
    /// the flip ratio at its expected value (2N − 6)·σ², so that a best fit that is luckily
    /// *too* good (few points: χ² with 2 degrees of freedom for one tag) cannot make a flip look
    /// unambiguous. Default 0.2 px (AprilTag on a sharp 5 MP image: 0.1–0.2 px).
    pub expected_corner_noise_px: f64,
    /// LM iteration cap per candidate. Default 50.
    pub max_iterations: usize,
    /// Points whose distance from their best-fit plane is below this fraction of the point
    /// spread are treated as coplanar (IPPE); otherwise DLT initialises. Default 1e-6.
    pub coplanarity_tolerance: f64,
    /// A tag whose RMS exceeds this multiple of the median tag's (and `max_rms_px`) is dropped
    /// by the per-tag robust step (module doc). Default 3.
    pub tag_outlier_factor: f64,
}

impl Default for PoseConfig {
    fn default() -> Self {
        PoseConfig {
            min_tags: 2,
            min_corners: 8,
            max_rms_px: 1.0,
            min_flip_ratio: 4.0,
            expected_corner_noise_px: 0.2,
            max_iterations: 50,
            coplanarity_tolerance: 1e-6,
            tag_outlier_factor: 3.0,
        }
    }
}

/// Why a frame produced no board pose.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PoseRejection {
    /// Too few distinct tags of the board were seen.
    #[error("too few tags: {found} seen, {required} required")]
    TooFewTags { found: usize, required: usize },
    /// Too few corners.
    #[error("too few corners: {found} seen, {required} required")]
    TooFewCorners { found: usize, required: usize },
    /// An input coordinate is NaN or infinite.
    #[error("correspondence {index} (tag {tag_id}, corner {corner}) is not finite")]
    NotFinite {
        index: usize,
        tag_id: u32,
        corner: u8,
    },
    /// An observed corner lies where the lens model cannot be inverted.
    #[error("corner of tag {tag_id} at pixel ({u:.1}, {v:.1}) cannot be undistorted: {reason}")]
    Undistort {
        tag_id: u32,
        u: f64,
        v: f64,
        reason: String,
    },
    /// The points do not determine a pose (collinear, coincident, plane edge-on, behind camera).
    #[error("degenerate geometry: {0}")]
    Degenerate(String),
    /// The best pose still reprojects badly.
    #[error("reprojection RMS {rms_px:.3} px exceeds the limit {max_px:.3} px")]
    ReprojectionTooHigh { rms_px: f64, max_px: f64 },
    /// The two planar solutions fit almost equally well: the rotation could be flipped.
    #[error("ambiguous planar flip: alternative/best cost ratio {ratio:.2} below {min:.2}")]
    AmbiguousFlip { ratio: f64, min: f64 },
}

/// An accepted board pose with its quality measures.
#[derive(Debug, Clone)]
pub struct BoardPose {
    /// Board frame → camera frame.
    pub camera_from_board: Pose,
    /// Reprojection RMS over points, √(Σ‖r‖²/N), px.
    pub rms_px: f64,
    /// Per correspondence (input order, dropped tags included): projected − observed, px.
    pub residuals_px: Vec<[f64; 2]>,
    /// Flip margin: cost of the other planar minimum divided by max(cost of this one,
    /// (2N − 6)·σ²) with σ = [`PoseConfig::expected_corner_noise_px`]; `None` when there is no
    /// second minimum (both IPPE candidates refined to the same pose, or non-planar points).
    pub flip_ratio: Option<f64>,
    /// The other planar minimum, when there is one.
    pub alternative: Option<Pose>,
    /// 6×6 covariance σ²(JᵀJ)⁻¹ of the left perturbation (ω rad, υ m) in the camera frame
    /// (see [`super::refine`]), σ² = cost/(2N − 6).
    pub covariance: Matrix6<f64>,
    /// 1σ rotation uncertainty about the camera x, y, z axes, rad.
    pub rotation_std_rad: [f64; 3],
    /// 1σ uncertainty of the board origin in the camera frame (x, y, z), m.
    pub translation_std_m: [f64; 3],
    /// Distinct tags used.
    pub tag_count: usize,
    /// Tags the per-tag robust step left out, worst first, with their RMS (px) at the pose
    /// that dropped them.
    pub dropped_tags: Vec<(u32, f64)>,
    /// LM iterations of the kept candidate.
    pub iterations: usize,
}

/// Estimates `camera_from_board` from all corners of all tags of one board seen in one frame.
pub fn estimate_board_pose(
    camera: &CameraModel,
    correspondences: &[Correspondence],
    config: &PoseConfig,
) -> Result<BoardPose, PoseRejection> {
    let all_tags = correspondences
        .iter()
        .map(|c| c.tag_id)
        .collect::<BTreeSet<u32>>()
        .len();
    // a third of the tags, at least one: the good ones stay the majority the median stands on
    let max_dropped = (all_tags / 3).max(1);
    let mut kept: Vec<Correspondence> = correspondences.to_vec();
    let mut dropped: Vec<(u32, f64)> = Vec::new();
    loop {
        let solved = solve(camera, &kept, config)?;
        let tags = kept.iter().map(|c| c.tag_id).collect::<BTreeSet<u32>>();
        let worst = (dropped.len() < max_dropped && tags.len() > config.min_tags)
            .then(|| outlier_tag(&kept, &solved.best.residuals_px, config))
            .flatten();
        match worst {
            Some((tag, rms))
                if kept.iter().filter(|c| c.tag_id != tag).count() >= config.min_corners.max(4) =>
            {
                dropped.push((tag, rms));
                kept.retain(|c| c.tag_id != tag);
            }
            _ => {
                let mut pose = accept(&kept, solved, tags.len(), config)?;
                if !dropped.is_empty() {
                    // residuals of every input corner, the dropped ones included
                    pose.residuals_px = residuals(camera, &pose.camera_from_board, correspondences);
                }
                pose.dropped_tags = dropped;
                return Ok(pose);
            }
        }
    }
}

/// The tag to drop (module doc), with its RMS, px.
fn outlier_tag(
    kept: &[Correspondence],
    residuals_px: &[[f64; 2]],
    config: &PoseConfig,
) -> Option<(u32, f64)> {
    let mut sums: std::collections::BTreeMap<u32, (f64, usize)> = Default::default();
    for (c, r) in kept.iter().zip(residuals_px) {
        let e = sums.entry(c.tag_id).or_insert((0.0, 0));
        e.0 += r[0] * r[0] + r[1] * r[1];
        e.1 += 1;
    }
    // every tag has ≥ 1 corner: the division is by a positive count
    let mut rms: Vec<(u32, f64)> = sums
        .into_iter()
        .map(|(t, (s, n))| (t, (s / n as f64).sqrt()))
        .collect();
    let mut sorted: Vec<f64> = rms.iter().map(|r| r.1).collect();
    let median = ellipso_model::stats::median(&mut sorted);
    rms.sort_by(|a, b| b.1.total_cmp(&a.1));
    let (tag, worst) = rms[0];
    (worst > config.max_rms_px && worst > config.tag_outlier_factor * median)
        .then_some((tag, worst))
}

/// Projected − observed for every correspondence at `camera_from_board` (NaN where a point is
/// behind the camera).
fn residuals(
    camera: &CameraModel,
    camera_from_board: &Pose,
    correspondences: &[Correspondence],
) -> Vec<[f64; 2]> {
    correspondences
        .iter()
        .map(
            |c| match camera.project(&(camera_from_board * c.point_board_m)) {
                Some(p) => [p[0] - c.pixel[0], p[1] - c.pixel[1]],
                None => [f64::NAN; 2],
            },
        )
        .collect()
}

/// The refined candidates of one joint solve: the best and a distinct alternative minimum.
struct Solved {
    best: RefinedPose,
    alternative: Option<RefinedPose>,
}

/// Validates, initialises and refines one joint pose over `correspondences`.
fn solve(
    camera: &CameraModel,
    correspondences: &[Correspondence],
    config: &PoseConfig,
) -> Result<Solved, PoseRejection> {
    let tags: BTreeSet<u32> = correspondences.iter().map(|c| c.tag_id).collect();
    if tags.len() < config.min_tags {
        return Err(PoseRejection::TooFewTags {
            found: tags.len(),
            required: config.min_tags,
        });
    }
    let required = config.min_corners.max(4);
    if correspondences.len() < required {
        return Err(PoseRejection::TooFewCorners {
            found: correspondences.len(),
            required,
        });
    }
    for (index, c) in correspondences.iter().enumerate() {
        let finite = c
            .point_board_m
            .coords
            .iter()
            .chain(c.pixel.iter())
            .all(|v| v.is_finite());
        if !finite {
            return Err(PoseRejection::NotFinite {
                index,
                tag_id: c.tag_id,
                corner: c.corner,
            });
        }
    }
    let points: Vec<Point3<f64>> = correspondences.iter().map(|c| c.point_board_m).collect();
    let pixels: Vec<[f64; 2]> = correspondences.iter().map(|c| c.pixel).collect();
    let normalised = correspondences
        .iter()
        .map(|c| {
            camera
                .undistort_pixel(c.pixel)
                .map_err(|e| PoseRejection::Undistort {
                    tag_id: c.tag_id,
                    u: c.pixel[0],
                    v: c.pixel[1],
                    reason: e.to_string(),
                })
        })
        .collect::<Result<Vec<_>, _>>()?;

    let candidates = initial_candidates(&points, &normalised, config)?;
    let mut refined: Vec<RefinedPose> = candidates
        .iter()
        .filter_map(|init| refine_pose(camera, init, &points, &pixels, config.max_iterations))
        .collect();
    if refined.is_empty() {
        return Err(PoseRejection::Degenerate(
            "no initial pose has the board in front".into(),
        ));
    }
    refined.sort_by(|a, b| a.cost_px2.total_cmp(&b.cost_px2));
    let best = refined.swap_remove(0);
    let alternative = refined
        .into_iter()
        .find(|alt| !same_pose(&alt.camera_from_board, &best.camera_from_board));
    Ok(Solved { best, alternative })
}

/// The acceptance checks of a joint solve over `kept` (RMS, flip margin) and its uncertainty.
fn accept(
    kept: &[Correspondence],
    solved: Solved,
    tag_count: usize,
    config: &PoseConfig,
) -> Result<BoardPose, PoseRejection> {
    let Solved { best, alternative } = solved;
    let points = kept;
    let n = points.len() as f64;
    let rms_px = (best.cost_px2 / n).sqrt();
    if rms_px.is_nan() || rms_px > config.max_rms_px {
        return Err(PoseRejection::ReprojectionTooHigh {
            rms_px,
            max_px: config.max_rms_px,
        });
    }
    // Denominator floored at the expected cost of a correct fit; if that is 0 too (σ = 0 and a
    // perfect fit) a distinct alternative is infinitely worse.
    let dof = (2 * points.len()).saturating_sub(6) as f64;
    let cost_floor = best
        .cost_px2
        .max(dof * config.expected_corner_noise_px.powi(2));
    let flip_ratio = alternative.as_ref().map(|alt| {
        if cost_floor > 0.0 {
            alt.cost_px2 / cost_floor
        } else {
            f64::INFINITY
        }
    });
    if let Some(ratio) = flip_ratio.filter(|r| *r < config.min_flip_ratio) {
        return Err(PoseRejection::AmbiguousFlip {
            ratio,
            min: config.min_flip_ratio,
        });
    }
    let (covariance, rotation_std_rad, translation_std_m) = uncertainty(
        &best.normal_matrix,
        best.cost_px2,
        points.len(),
        &best.camera_from_board,
    )?;
    Ok(BoardPose {
        camera_from_board: best.camera_from_board,
        rms_px,
        residuals_px: best.residuals_px,
        flip_ratio,
        alternative: alternative.map(|a| a.camera_from_board),
        covariance,
        rotation_std_rad,
        translation_std_m,
        tag_count,
        dropped_tags: Vec::new(),
        iterations: best.iterations,
    })
}

/// Two refined poses are the same minimum when they agree to 1e-6 rad and 1e-6 of the distance.
fn same_pose(a: &Pose, b: &Pose) -> bool {
    let scale = a.translation.vector.norm().max(1e-3);
    a.rotation.angle_to(&b.rotation) < 1e-6
        && (a.translation.vector - b.translation.vector).norm() < 1e-6 * scale
}

/// Initial poses: both IPPE solutions for coplanar points, the DLT pose otherwise.
fn initial_candidates(
    points: &[Point3<f64>],
    normalised: &[[f64; 2]],
    config: &PoseConfig,
) -> Result<Vec<Pose>, PoseRejection> {
    let n = points.len() as f64;
    let centroid = points.iter().fold(Vector3::zeros(), |a, p| a + p.coords) / n;
    let mut scatter = Matrix3::zeros();
    for p in points {
        let d = p.coords - centroid;
        scatter += d * d.transpose();
    }
    let eig = scatter.symmetric_eigen();
    let mut order = [0usize, 1, 2];
    order.sort_by(|&i, &j| eig.eigenvalues[i].total_cmp(&eig.eigenvalues[j]));
    let (lmin, lmid, lmax) = (
        eig.eigenvalues[order[0]],
        eig.eigenvalues[order[1]],
        eig.eigenvalues[order[2]],
    );
    // Second-largest spread ~0: points on a line (or coincident) cannot fix a pose.
    if !(lmax > 0.0 && lmid > 1e-12 * lmax) {
        return Err(PoseRejection::Degenerate(
            "board points are collinear or coincident".into(),
        ));
    }
    let tol = config.coplanarity_tolerance;
    if lmin.max(0.0).sqrt() > tol * lmax.sqrt() {
        return dlt_pose(points, normalised)
            .map(|p| vec![p])
            .ok_or_else(|| PoseRejection::Degenerate("linear PnP (DLT) failed".into()));
    }
    // Plane frame: origin at the centroid, z along the smallest-spread direction.
    let e0 = eig.eigenvectors.column(order[2]).into_owned();
    let e2 = eig.eigenvectors.column(order[0]).into_owned();
    let e1 = e2.cross(&e0);
    let board_from_plane_rot = Matrix3::from_columns(&[e0, e1, e2]);
    let plane_from_board = Pose::from_parts(
        nalgebra::Translation3::from(-(board_from_plane_rot.transpose() * centroid)),
        super::orthonormalise(&board_from_plane_rot.transpose()),
    );
    let plane_xy: Vec<[f64; 2]> = points
        .iter()
        .map(|p| {
            let q = plane_from_board * p;
            [q.x, q.y]
        })
        .collect();
    match ippe_planar(&plane_xy, normalised) {
        Ok(poses) => Ok(poses
            .iter()
            .map(|camera_from_plane| camera_from_plane * plane_from_board)
            .collect()),
        Err(IppeError::Homography(e)) => Err(PoseRejection::Degenerate(e.to_string())),
        Err(IppeError::Degenerate(why)) => Err(PoseRejection::Degenerate(why.into())),
    }
}

type Uncertainty = (Matrix6<f64>, [f64; 3], [f64; 3]);

/// σ²(JᵀJ)⁻¹ and the derived 1σ rotation and board-origin uncertainties.
fn uncertainty(
    normal_matrix: &Matrix6<f64>,
    cost_px2: f64,
    n_points: usize,
    camera_from_board: &Pose,
) -> Result<Uncertainty, PoseRejection> {
    let dof = (2 * n_points).saturating_sub(6);
    // dof ≥ 2 because at least 4 points are required; max(1) guards the division anyway.
    let sigma2 = cost_px2 / dof.max(1) as f64;
    let inv = normal_matrix
        .try_inverse()
        .ok_or_else(|| PoseRejection::Degenerate("pose Jacobian is rank deficient".into()))?;
    let cov = inv * sigma2;
    // The board origin t moves by dt = ω × t + υ = [−[t]× | I] δ.
    let t = camera_from_board.translation.vector;
    let mut a = SMatrix::<f64, 3, 6>::zeros();
    let skew = Matrix3::new(0.0, -t.z, t.y, t.z, 0.0, -t.x, -t.y, t.x, 0.0);
    a.fixed_view_mut::<3, 3>(0, 0).copy_from(&(-skew));
    a.fixed_view_mut::<3, 3>(0, 3)
        .copy_from(&Matrix3::identity());
    let cov_t = a * cov * a.transpose();
    // Diagonals of a PSD covariance are ≥ 0 up to round-off: clamp before sqrt.
    let rot = [0, 1, 2].map(|k| cov[(k, k)].max(0.0).sqrt());
    let trans = [0, 1, 2].map(|k| cov_t[(k, k)].max(0.0).sqrt());
    Ok((cov, rot, trans))
}
