//! Plane-to-plane homography by the normalised Direct Linear Transform (Hartley & Zisserman,
//! *Multiple View Geometry*, 2nd ed., Alg. 4.2): both point sets are translated to their centroid
//! and scaled to mean distance √2, the 2N×9 system A·h = 0 is solved by SVD (right singular
//! vector of the smallest singular value), and the result is de-normalised.
//!
//! Contract: ≥ 4 finite correspondences, not all on one line in either plane; returns H with
//! `dst ~ H · [src, 1]` scaled so that ‖H‖_F = 1 and H₃₃ ≥ 0, or a [`HomographyError`].

use super::exceeds;
use nalgebra::{DMatrix, Matrix3, Vector3};

/// Singular-value ratio below which the DLT system is treated as rank deficient (collinear or
/// coincident points).
const RANK_TOLERANCE: f64 = 1e-10;

/// Why no homography could be estimated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum HomographyError {
    /// Fewer than the 4 correspondences a homography needs.
    #[error("a homography needs at least 4 point pairs, got {0}")]
    TooFewPoints(usize),
    /// The two point lists differ in length.
    #[error("homography source has {src} points but destination has {dst}")]
    LengthMismatch { src: usize, dst: usize },
    /// A coordinate is NaN or infinite.
    #[error("homography point {index} is not finite")]
    NotFinite { index: usize },
    /// The points are collinear or coincident, so the homography is not determined.
    #[error("homography is not determined: points are collinear or coincident")]
    Degenerate,
}

/// Similarity transform moving the centroid to the origin and the mean distance to √2
/// (Hartley normalisation). Errors if all points coincide.
pub(crate) fn normalising_transform(points: &[[f64; 2]]) -> Result<Matrix3<f64>, HomographyError> {
    let n = points.len() as f64;
    let (mut mx, mut my) = (0.0, 0.0);
    for p in points {
        mx += p[0];
        my += p[1];
    }
    let (mx, my) = (mx / n, my / n);
    let mean_dist = points
        .iter()
        .map(|p| (p[0] - mx).hypot(p[1] - my))
        .sum::<f64>()
        / n;
    // Coincident points: no scale can be defined (guards the division below).
    if !exceeds(mean_dist, f64::EPSILON * (1.0 + mx.abs() + my.abs())) {
        return Err(HomographyError::Degenerate);
    }
    let s = std::f64::consts::SQRT_2 / mean_dist;
    Ok(Matrix3::new(
        s,
        0.0,
        -s * mx,
        0.0,
        s,
        -s * my,
        0.0,
        0.0,
        1.0,
    ))
}

fn apply(t: &Matrix3<f64>, p: [f64; 2]) -> [f64; 2] {
    // Only used with affine `t` (last row 0 0 1), so no division.
    [
        t[(0, 0)] * p[0] + t[(0, 1)] * p[1] + t[(0, 2)],
        t[(1, 0)] * p[0] + t[(1, 1)] * p[1] + t[(1, 2)],
    ]
}

/// Estimates H with `dst ~ H·[src; 1]` by the normalised DLT. See the module doc.
pub fn homography_dlt(src: &[[f64; 2]], dst: &[[f64; 2]]) -> Result<Matrix3<f64>, HomographyError> {
    if src.len() != dst.len() {
        return Err(HomographyError::LengthMismatch {
            src: src.len(),
            dst: dst.len(),
        });
    }
    if src.len() < 4 {
        return Err(HomographyError::TooFewPoints(src.len()));
    }
    if let Some(index) = src
        .iter()
        .zip(dst)
        .position(|(a, b)| !(a.iter().chain(b.iter()).all(|c| c.is_finite())))
    {
        return Err(HomographyError::NotFinite { index });
    }
    let t_src = normalising_transform(src)?;
    let t_dst = normalising_transform(dst)?;
    let n = src.len();
    // At least 9 rows so that the SVD exposes the full 9-dimensional right singular basis.
    let rows = (2 * n).max(9);
    let mut a = DMatrix::<f64>::zeros(rows, 9);
    for (i, (s, d)) in src.iter().zip(dst).enumerate() {
        let [x, y] = apply(&t_src, *s);
        let [u, v] = apply(&t_dst, *d);
        let r0 = [0.0, 0.0, 0.0, -x, -y, -1.0, v * x, v * y, v];
        let r1 = [x, y, 1.0, 0.0, 0.0, 0.0, -u * x, -u * y, -u];
        for c in 0..9 {
            a[(2 * i, c)] = r0[c];
            a[(2 * i + 1, c)] = r1[c];
        }
    }
    let svd = a.svd(false, true);
    let v_t = svd.v_t.as_ref().ok_or(HomographyError::Degenerate)?;
    let mut order: Vec<usize> = (0..svd.singular_values.len()).collect();
    order.sort_by(|&i, &j| svd.singular_values[i].total_cmp(&svd.singular_values[j]));
    let s_max = svd.singular_values[order[order.len() - 1]];
    // With 4+ points in general position the null space is one-dimensional: the second-smallest
    // singular value must be clearly non-zero.
    if !exceeds(svd.singular_values[order[1]], RANK_TOLERANCE * s_max) {
        return Err(HomographyError::Degenerate);
    }
    let h = v_t.row(order[0]);
    let h_norm = Matrix3::new(h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7], h[8]);
    let t_dst_inv = t_dst.try_inverse().ok_or(HomographyError::Degenerate)?;
    let mut out = t_dst_inv * h_norm * t_src;
    let norm = out.norm();
    if !(norm > 0.0 && norm.is_finite()) {
        return Err(HomographyError::Degenerate);
    }
    out /= norm;
    if out[(2, 2)] < 0.0 {
        out = -out;
    }
    Ok(out)
}

/// Maps a point through a homography; `None` when it maps to infinity (|w| ≤ 1e-300).
pub fn apply_homography(h: &Matrix3<f64>, p: [f64; 2]) -> Option<[f64; 2]> {
    let q = h * Vector3::new(p[0], p[1], 1.0);
    (q.z.abs() > 1e-300).then(|| [q.x / q.z, q.y / q.z])
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn grid() -> Vec<[f64; 2]> {
        (0..5)
            .flat_map(|i| (0..4).map(move |j| [i as f64 * 0.03, j as f64 * 0.04 - 0.05]))
            .collect()
    }

    proptest! {
        #[test]
        fn recovers_a_random_homography(
            h in proptest::array::uniform9(-1.0f64..1.0),
        ) {
            let truth = Matrix3::new(
                800.0 + 200.0 * h[0], 100.0 * h[1], 1200.0 + 50.0 * h[2],
                100.0 * h[3], 800.0 + 200.0 * h[4], 1000.0 + 50.0 * h[5],
                0.5 * h[6], 0.5 * h[7], 1.0 + 0.2 * h[8],
            );
            let src = grid();
            let dst: Vec<_> = src.iter().map(|p| apply_homography(&truth, *p).unwrap()).collect();
            let est = homography_dlt(&src, &dst).unwrap();
            for (s, d) in src.iter().zip(&dst) {
                let p = apply_homography(&est, *s).unwrap();
                prop_assert!((p[0] - d[0]).abs() < 1e-7 && (p[1] - d[1]).abs() < 1e-7);
            }
        }
    }

    #[test]
    fn exactly_four_points_suffice() {
        let src = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
        let dst = [[10.0, 10.0], [20.0, 11.0], [21.0, 22.0], [9.0, 19.0]];
        let h = homography_dlt(&src, &dst).unwrap();
        for (s, d) in src.iter().zip(&dst) {
            let p = apply_homography(&h, *s).unwrap();
            assert!((p[0] - d[0]).abs() < 1e-9 && (p[1] - d[1]).abs() < 1e-9);
        }
    }

    #[test]
    fn rejects_bad_input() {
        let line: Vec<[f64; 2]> = (0..6).map(|i| [i as f64, 2.0 * i as f64]).collect();
        let other: Vec<[f64; 2]> = (0..6).map(|i| [i as f64, (i * i) as f64]).collect();
        assert_eq!(
            homography_dlt(&line, &other),
            Err(HomographyError::Degenerate)
        );
        assert_eq!(
            homography_dlt(&line[..3], &other[..3]),
            Err(HomographyError::TooFewPoints(3))
        );
        assert!(matches!(
            homography_dlt(&line, &other[..5]),
            Err(HomographyError::LengthMismatch { .. })
        ));
        let mut nan = other.clone();
        nan[2][1] = f64::NAN;
        assert_eq!(
            homography_dlt(&line, &nan),
            Err(HomographyError::NotFinite { index: 2 })
        );
    }
}
