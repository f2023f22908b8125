//! Similarity transforms (scale, rotation, translation) between two reconstructions of the same
//! cameras, estimated robustly from the cameras' poses: how a COLMAP or other photogrammetry
//! model, whose frame and scale are its own, is brought into the board frame (docs/mesh.md,
//! "The way in").
//!
//! Contract:
//! - [`umeyama`] is the closed-form least-squares similarity between two point sets (S. Umeyama,
//!   "Least-squares estimation of transformation parameters between two point patterns", IEEE
//!   PAMI 13(4), 1991, eqs. 38–42, with its reflection guard); `None` when the source points do
//!   not span a plane (fewer than 3, coincident or collinear).
//! - [`align_poses`] estimates `target_from_source` from frames posed in both frames. Each frame
//!   contributes its camera centre and its rotation: the estimate minimises
//!   Σ |c_t − (s·R·c_s + t)|² + λ·Σ ‖R·R_s − R_t‖²_F with λ = w·D²/2, D² the mean squared
//!   distance of the target centres from their centroid and w = [`AlignConfig::rotation_weight`],
//!   so a rotation error θ weighs as much as a centre error of D·θ (‖ΔR‖²_F ≈ 2θ² for small θ).
//!   It starts from Umeyama on the centres and alternates the rotation (SVD of s·H + λ·K, the
//!   same reflection guard) and the scale (closed form) until neither moves.
//! - Robustness: hypotheses from every triple of frames (seeded random triples when there are
//!   more than [`AlignConfig::max_hypotheses`]), scored by a truncated quadratic (MSAC) of each
//!   frame's residual against the inlier thresholds; the best is refitted on its inliers until
//!   the inlier set no longer changes. A frame is an inlier when its centre residual is at most
//!   `inlier_mm` *and* its rotation residual at most `inlier_deg`.
//! - Refused, with the numbers: fewer than `min_frames` frames; centres that coincide or lie on
//!   a line (second singular value of the centred centres below `collinear_ratio` of the first,
//!   in either frame); fewer inliers than `min_inlier_fraction` of the frames (or 3); an inlier
//!   RMS above `max_rms_mm` or `max_rms_deg`.
//! - The target frame is in metres (the board frame): residuals are reported in millimetres
//!   and degrees, per frame and as RMS and maximum over the inliers.
//! - Deterministic: the same input gives the same result (seeded, no thread dependence).

use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Similarity3, Translation3, UnitQuaternion};
use rand::{Rng, SeedableRng};

/// One frame posed in both frames: its camera in the source frame (e.g. a COLMAP model) and in
/// the target frame (the board frame, metres).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PosePair {
    /// The camera's pose in the source frame.
    pub source_from_camera: Isometry3<f64>,
    /// The camera's pose in the target frame.
    pub target_from_camera: Isometry3<f64>,
}

/// Settings of [`align_poses`] (defaults documented in docs/mesh.md, "The way in").
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AlignConfig {
    /// Fewest frames posed in both frames.
    pub min_frames: usize,
    /// A frame whose centre is further than this from its aligned source centre is an outlier, mm.
    pub inlier_mm: f64,
    /// A frame whose rotation differs by more than this from its aligned source rotation is an
    /// outlier, degrees.
    pub inlier_deg: f64,
    /// Fewest inliers, as a fraction of the frames posed in both.
    pub min_inlier_fraction: f64,
    /// Largest accepted RMS centre residual over the inliers, mm.
    pub max_rms_mm: f64,
    /// Largest accepted RMS rotation residual over the inliers, degrees.
    pub max_rms_deg: f64,
    /// Centres whose second singular value (centred) is below this fraction of the first lie on
    /// a line: the rotation about it would rest on the rotations alone. Refused.
    pub collinear_ratio: f64,
    /// Weight of the rotations against the centres (0: centres only; module contract).
    pub rotation_weight: f64,
    /// Most triples tried (all of them when there are no more).
    pub max_hypotheses: usize,
    /// Seed of the random triples.
    pub seed: u64,
}

impl Default for AlignConfig {
    fn default() -> Self {
        Self {
            min_frames: 4,
            inlier_mm: 5.0,
            inlier_deg: 1.0,
            min_inlier_fraction: 0.5,
            max_rms_mm: 2.0,
            max_rms_deg: 0.5,
            collinear_ratio: 0.01,
            rotation_weight: 1.0,
            max_hypotheses: 2000,
            seed: 29,
        }
    }
}

/// How well one frame agrees with the alignment.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PoseResidual {
    /// Distance between the target centre and the aligned source centre, mm.
    pub position_mm: f64,
    /// Angle between the target rotation and the aligned source rotation, degrees.
    pub rotation_deg: f64,
    /// Whether the frame is an inlier.
    pub inlier: bool,
}

/// The result of [`align_poses`].
#[derive(Clone, Debug, PartialEq)]
pub struct PoseAlignment {
    /// Maps source coordinates into the target frame.
    pub target_from_source: Similarity3<f64>,
    /// One residual per input pair, in the input order.
    pub residuals: Vec<PoseResidual>,
    /// Number of inliers.
    pub inliers: usize,
    /// RMS centre residual over the inliers, mm.
    pub rms_position_mm: f64,
    /// RMS rotation residual over the inliers, degrees.
    pub rms_rotation_deg: f64,
    /// Largest centre residual of an inlier, mm.
    pub max_position_mm: f64,
    /// Largest rotation residual of an inlier, degrees.
    pub max_rotation_deg: f64,
}

/// Why [`align_poses`] refused.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum AlignError {
    /// Not enough frames posed in both frames.
    #[error("{frames} frames are posed in both frames; the alignment needs at least {needed}")]
    TooFewFrames {
        /// Frames given.
        frames: usize,
        /// Fewest accepted.
        needed: usize,
    },
    /// The camera centres do not fix a similarity.
    #[error("degenerate camera centres in the {frame} frame: {what}")]
    Degenerate {
        /// `source` or `target`.
        frame: &'static str,
        /// What is degenerate, with the numbers.
        what: String,
    },
    /// Too many frames disagree.
    #[error(
        "only {inliers} of {frames} frames agree within {inlier_mm} mm and {inlier_deg}° \
         (at least {needed} must): the two sets of poses do not describe the same cameras"
    )]
    TooFewInliers {
        /// Inliers of the best hypothesis.
        inliers: usize,
        /// Frames given.
        frames: usize,
        /// Fewest accepted.
        needed: usize,
        /// The inlier threshold, mm.
        inlier_mm: f64,
        /// The inlier threshold, degrees.
        inlier_deg: f64,
    },
    /// The inliers agree, but not closely enough.
    #[error(
        "alignment residual RMS {rms_mm:.3} mm, {rms_deg:.3}° over {inliers} frames is above \
         the limit of {max_rms_mm} mm, {max_rms_deg}°"
    )]
    ResidualTooLarge {
        /// RMS centre residual, mm.
        rms_mm: f64,
        /// RMS rotation residual, degrees.
        rms_deg: f64,
        /// Inliers.
        inliers: usize,
        /// The limit, mm.
        max_rms_mm: f64,
        /// The limit, degrees.
        max_rms_deg: f64,
    },
}

/// The proper rotation R maximising tr(Rᵀ·M) (Umeyama 1991, eq. 39–40: the SVD M = U·Σ·Vᵀ and
/// R = U·diag(1, 1, det(U·Vᵀ))·Vᵀ, so a reflection is never returned).
fn nearest_rotation(m: &Matrix3<f64>) -> Option<Matrix3<f64>> {
    let svd = m.svd(true, true);
    let (u, v_t) = (svd.u?, svd.v_t?);
    let d = if (u * v_t).determinant() < 0.0 {
        -1.0
    } else {
        1.0
    };
    Some(u * Matrix3::from_diagonal(&nalgebra::Vector3::new(1.0, 1.0, d)) * v_t)
}

/// Singular values (descending) of the centred points.
fn spread(points: &[Point3<f64>]) -> [f64; 3] {
    let n = points.len().max(1) as f64;
    let mean = points
        .iter()
        .fold(nalgebra::Vector3::zeros(), |a, p| a + p.coords)
        / n;
    let c = points.iter().fold(Matrix3::zeros(), |a, p| {
        let d = p.coords - mean;
        a + d * d.transpose()
    });
    let mut s: Vec<f64> = c
        .symmetric_eigenvalues()
        .iter()
        .map(|e| e.max(0.0).sqrt())
        .collect();
    s.sort_by(|a, b| b.total_cmp(a));
    [s[0], s[1], s[2]]
}

/// Whether the points are one point: their spread is below 1e-9 of their distance from the
/// origin (rounding leaves a spread of ~1e-16 of it where they coincide).
fn coincide(points: &[Point3<f64>], spread: &[f64; 3]) -> bool {
    let extent = points.iter().map(|p| p.coords.norm()).fold(0.0, f64::max);
    // NaN spreads (non-finite centres) count as coincident
    spread[0].is_nan() || spread[0] <= 1e-9 * extent
}

/// Whether the points span a plane: σ₂ ≥ ratio·σ₁ and they do not coincide.
fn spans_plane(points: &[Point3<f64>], ratio: f64) -> bool {
    let s = spread(points);
    !coincide(points, &s) && s[1] >= ratio * s[0]
}

/// The least-squares similarity mapping `source` onto `target` (module contract).
pub fn umeyama(source: &[Point3<f64>], target: &[Point3<f64>]) -> Option<Similarity3<f64>> {
    if source.len() < 3 || source.len() != target.len() || !spans_plane(source, 1e-9) {
        return None;
    }
    estimate(source, target, None, 0.0)
}

/// The joint estimate of the module contract on `source`/`target` centres with the pairs'
/// rotations `(R_source, R_target)` weighted by `rotation_weight`.
fn estimate(
    source: &[Point3<f64>],
    target: &[Point3<f64>],
    rotations: Option<&[(Matrix3<f64>, Matrix3<f64>)]>,
    rotation_weight: f64,
) -> Option<Similarity3<f64>> {
    let n = source.len() as f64;
    let mean = |p: &[Point3<f64>]| {
        p.iter()
            .fold(nalgebra::Vector3::zeros(), |a, x| a + x.coords)
            / n
    };
    let (mx, my) = (mean(source), mean(target));
    let mut h = Matrix3::zeros();
    let (mut var_x, mut var_y) = (0.0, 0.0);
    for (x, y) in source.iter().zip(target) {
        let (dx, dy) = (x.coords - mx, y.coords - my);
        h += dy * dx.transpose();
        var_x += dx.norm_squared();
        var_y += dy.norm_squared();
    }
    // guard: coincident source centres leave the scale undefined
    if var_x.is_nan() || var_y.is_nan() || var_x <= 0.0 || var_y <= 0.0 {
        return None;
    }
    let mut r = nearest_rotation(&h)?;
    let mut s = (r.transpose() * h).trace() / var_x;
    if let Some(rot) = rotations.filter(|_| rotation_weight > 0.0) {
        let lambda = rotation_weight * (var_y / n) / 2.0;
        let k = rot
            .iter()
            .fold(Matrix3::zeros(), |a, (rs, rt)| a + rt * rs.transpose());
        for _ in 0..100 {
            let r_next = nearest_rotation(&(h * s.max(0.0) + k * lambda))?;
            let s_next = (r_next.transpose() * h).trace() / var_x;
            let moved = (r_next - r).norm() + (s_next - s).abs() / s.abs().max(1e-300);
            r = r_next;
            s = s_next;
            if moved < 1e-13 {
                break;
            }
        }
    }
    // a non-positive scale is no similarity between the two sets (mirror or no relation)
    if !s.is_finite() || s <= 0.0 {
        return None;
    }
    let rotation = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
    let t = my - rotation * mx * s;
    Some(Similarity3::from_parts(Translation3::from(t), rotation, s))
}

/// The camera pose in the target frame that `target_from_source` gives a source pose: the
/// rotation is turned, the centre mapped; the camera frame stays metric.
pub fn apply_to_pose(
    target_from_source: &Similarity3<f64>,
    source_from_camera: &Isometry3<f64>,
) -> Isometry3<f64> {
    let centre =
        target_from_source.transform_point(&Point3::from(source_from_camera.translation.vector));
    Isometry3::from_parts(
        Translation3::from(centre.coords),
        target_from_source.isometry.rotation * source_from_camera.rotation,
    )
}

/// The residual of one pair under `sim` (flags left false).
fn residual(sim: &Similarity3<f64>, pair: &PosePair) -> PoseResidual {
    let aligned = apply_to_pose(sim, &pair.source_from_camera);
    let e = super::pose_error(&aligned, &pair.target_from_camera);
    PoseResidual {
        position_mm: e.translation_mm,
        rotation_deg: e.rotation_deg,
        inlier: false,
    }
}

/// The estimate on the members `idx` of `pairs`.
fn estimate_on(
    pairs: &[PosePair],
    idx: &[usize],
    config: &AlignConfig,
) -> Option<Similarity3<f64>> {
    let source: Vec<Point3<f64>> = idx
        .iter()
        .map(|&i| Point3::from(pairs[i].source_from_camera.translation.vector))
        .collect();
    let target: Vec<Point3<f64>> = idx
        .iter()
        .map(|&i| Point3::from(pairs[i].target_from_camera.translation.vector))
        .collect();
    let rotations: Vec<(Matrix3<f64>, Matrix3<f64>)> = idx
        .iter()
        .map(|&i| {
            (
                *pairs[i]
                    .source_from_camera
                    .rotation
                    .to_rotation_matrix()
                    .matrix(),
                *pairs[i]
                    .target_from_camera
                    .rotation
                    .to_rotation_matrix()
                    .matrix(),
            )
        })
        .collect();
    estimate(&source, &target, Some(&rotations), config.rotation_weight)
}

/// Residuals of every pair under `sim`, with inlier flags and the MSAC cost.
fn score(
    sim: &Similarity3<f64>,
    pairs: &[PosePair],
    config: &AlignConfig,
) -> (Vec<PoseResidual>, f64) {
    let mut cost = 0.0;
    let residuals = pairs
        .iter()
        .map(|p| {
            let mut r = residual(sim, p);
            let e = (r.position_mm / config.inlier_mm).max(r.rotation_deg / config.inlier_deg);
            r.inlier = e <= 1.0;
            // non-finite residuals (a NaN pose) count as outliers
            cost += if e.is_finite() { (e * e).min(1.0) } else { 1.0 };
            r
        })
        .collect();
    (residuals, cost)
}

/// The triples tried: all of them when there are at most `max` (in lexicographic order), else
/// `max` seeded random ones.
fn triples(n: usize, max: usize, seed: u64) -> Vec<[usize; 3]> {
    let all = n * n.saturating_sub(1) * n.saturating_sub(2) / 6;
    if all <= max {
        let mut out = Vec::with_capacity(all);
        for a in 0..n {
            for b in a + 1..n {
                for c in b + 1..n {
                    out.push([a, b, c]);
                }
            }
        }
        return out;
    }
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    (0..max)
        .map(|_| {
            let a = rng.random_range(0..n);
            let mut b = rng.random_range(0..n - 1);
            if b >= a {
                b += 1;
            }
            let mut c = rng.random_range(0..n - 2);
            for lo in [a.min(b), a.max(b)] {
                if c >= lo {
                    c += 1;
                }
            }
            [a, b, c]
        })
        .collect()
}

/// Checks that `points` span a plane (module contract), naming the frame they are in.
fn check_spread(points: &[Point3<f64>], frame: &'static str, ratio: f64) -> Result<(), AlignError> {
    let s = spread(points);
    if coincide(points, &s) {
        return Err(AlignError::Degenerate {
            frame,
            what: format!("all {} camera centres coincide", points.len()),
        });
    }
    if s[1] < ratio * s[0] {
        return Err(AlignError::Degenerate {
            frame,
            what: format!(
                "the {} camera centres lie on a line (second singular value {:.2e} of the first, \
                 at least {ratio} needed): the rotation about it is not fixed",
                points.len(),
                s[1] / s[0]
            ),
        });
    }
    Ok(())
}

/// Estimates `target_from_source` from frames posed in both frames, robustly, and reports the
/// residuals (module contract).
pub fn align_poses(pairs: &[PosePair], config: &AlignConfig) -> Result<PoseAlignment, AlignError> {
    let n = pairs.len();
    let needed = config.min_frames.max(3);
    if n < needed {
        return Err(AlignError::TooFewFrames { frames: n, needed });
    }
    let centres = |f: &dyn Fn(&PosePair) -> Isometry3<f64>| -> Vec<Point3<f64>> {
        pairs
            .iter()
            .map(|p| Point3::from(f(p).translation.vector))
            .collect()
    };
    let source = centres(&|p| p.source_from_camera);
    let target = centres(&|p| p.target_from_camera);
    check_spread(&source, "source", config.collinear_ratio)?;
    check_spread(&target, "target", config.collinear_ratio)?;

    let mut best: Option<(f64, Vec<PoseResidual>)> = None;
    for [a, b, c] in triples(n, config.max_hypotheses, config.seed) {
        let tri = [source[a], source[b], source[c]];
        if !spans_plane(&tri, config.collinear_ratio) {
            continue;
        }
        let Some(sim) = estimate_on(pairs, &[a, b, c], config) else {
            continue;
        };
        let (residuals, cost) = score(&sim, pairs, config);
        if best.as_ref().is_none_or(|(c, _)| cost < *c) {
            best = Some((cost, residuals));
        }
    }
    let needed_inliers = ((config.min_inlier_fraction * n as f64).ceil() as usize).max(3);
    let too_few = |inliers| AlignError::TooFewInliers {
        inliers,
        frames: n,
        needed: needed_inliers,
        inlier_mm: config.inlier_mm,
        inlier_deg: config.inlier_deg,
    };
    let Some((_, mut residuals)) = best else {
        return Err(too_few(0));
    };
    // refit on the inliers until they no longer change
    let mut sim = None;
    for _ in 0..20 {
        let members: Vec<usize> = (0..n).filter(|&i| residuals[i].inlier).collect();
        let inlier_centres: Vec<Point3<f64>> = members.iter().map(|&i| source[i]).collect();
        if members.len() < needed_inliers || !spans_plane(&inlier_centres, config.collinear_ratio) {
            break;
        }
        let Some(next) = estimate_on(pairs, &members, config) else {
            break;
        };
        let (next_residuals, _) = score(&next, pairs, config);
        let stable = next_residuals
            .iter()
            .zip(&residuals)
            .all(|(a, b)| a.inlier == b.inlier);
        residuals = next_residuals;
        sim = Some(next);
        if stable {
            break;
        }
    }
    let inliers = residuals.iter().filter(|r| r.inlier).count();
    let Some(sim) = sim.filter(|_| inliers >= needed_inliers) else {
        return Err(too_few(inliers));
    };
    let inlier_centres: Vec<Point3<f64>> = (0..n)
        .filter(|&i| residuals[i].inlier)
        .map(|i| target[i])
        .collect();
    check_spread(&inlier_centres, "target", config.collinear_ratio)?;
    let of_inliers = |f: fn(&PoseResidual) -> f64| -> Vec<f64> {
        residuals.iter().filter(|r| r.inlier).map(f).collect()
    };
    let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt();
    let max = |v: &[f64]| v.iter().copied().fold(0.0, f64::max);
    let (pos, rot) = (
        of_inliers(|r| r.position_mm),
        of_inliers(|r| r.rotation_deg),
    );
    let alignment = PoseAlignment {
        target_from_source: sim,
        inliers,
        rms_position_mm: rms(&pos),
        rms_rotation_deg: rms(&rot),
        max_position_mm: max(&pos),
        max_rotation_deg: max(&rot),
        residuals,
    };
    if alignment.rms_position_mm > config.max_rms_mm
        || alignment.rms_rotation_deg > config.max_rms_deg
    {
        return Err(AlignError::ResidualTooLarge {
            rms_mm: alignment.rms_position_mm,
            rms_deg: alignment.rms_rotation_deg,
            inliers,
            max_rms_mm: config.max_rms_mm,
            max_rms_deg: config.max_rms_deg,
        });
    }
    Ok(alignment)
}

#[cfg(test)]
mod tests;
