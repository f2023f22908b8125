//! Zhang's closed-form intrinsics from ≥ 3 homographies of a planar target (Z. Zhang, "A Flexible
//! New Technique for Camera Calibration", IEEE TPAMI 22(11):1330–1334, 2000, §3.1 and App. B),
//! with zero skew imposed, plus the linear radial initialisation of §3.3.
//!
//! Each homography H = λ K [r₁ r₂ t] (board z = 0 plane → pixels) gives two linear constraints
//! on the symmetric B = K⁻ᵀK⁻¹: h₁ᵀBh₂ = 0 and h₁ᵀBh₁ = h₂ᵀBh₂. With zero skew B₁₂ = 0, leaving
//! five unknowns (B₁₁, B₂₂, B₁₃, B₂₃, B₃₃) found as the smallest right singular vector of the
//! stacked 2n×5 system. For conditioning the pixels are first mapped by
//! T: u ↦ (u − (w−1)/2)/s, s = (w + h)/2, and K = T⁻¹K'.

use ellipso_model::camera::Intrinsics;
use nalgebra::{DMatrix, Matrix3};

/// Why the closed form failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ZhangError {
    /// Fewer homographies than the closed form needs.
    #[error("Zhang's closed form needs at least 3 views, got {0}")]
    TooFewViews(usize),
    /// The views do not constrain K (e.g. all boards parallel to each other or fronto-parallel).
    #[error("Zhang's closed form is degenerate: {0} (vary the board tilt between views)")]
    Degenerate(&'static str),
}

/// vᵢⱼ of Zhang's eq. (8), reduced to the unknowns (B₁₁, B₂₂, B₁₃, B₂₃, B₃₃) (B₁₂ = 0).
fn v_ij(h: &Matrix3<f64>, i: usize, j: usize) -> [f64; 5] {
    let (hi, hj) = (h.column(i), h.column(j));
    [
        hi[0] * hj[0],
        hi[1] * hj[1],
        hi[2] * hj[0] + hi[0] * hj[2],
        hi[2] * hj[1] + hi[1] * hj[2],
        hi[2] * hj[2],
    ]
}

/// Closed-form intrinsics (zero skew) from board-to-pixel homographies.
pub fn intrinsics_from_homographies(
    homographies: &[Matrix3<f64>],
    width: u32,
    height: u32,
) -> Result<Intrinsics, ZhangError> {
    if homographies.len() < 3 {
        return Err(ZhangError::TooFewViews(homographies.len()));
    }
    let s = (f64::from(width) + f64::from(height)) / 2.0;
    let (cx0, cy0) = (
        (f64::from(width) - 1.0) / 2.0,
        (f64::from(height) - 1.0) / 2.0,
    );
    let t = Matrix3::new(
        1.0 / s,
        0.0,
        -cx0 / s,
        0.0,
        1.0 / s,
        -cy0 / s,
        0.0,
        0.0,
        1.0,
    );
    let mut v = DMatrix::<f64>::zeros(2 * homographies.len(), 5);
    for (k, h) in homographies.iter().enumerate() {
        let hn = t * h;
        let hn = hn / hn.norm().max(f64::MIN_POSITIVE);
        let v12 = v_ij(&hn, 0, 1);
        let v11 = v_ij(&hn, 0, 0);
        let v22 = v_ij(&hn, 1, 1);
        for c in 0..5 {
            v[(2 * k, c)] = v12[c];
            v[(2 * k + 1, c)] = v11[c] - v22[c];
        }
    }
    let svd = v.svd(false, true);
    let v_t = svd.v_t.ok_or(ZhangError::Degenerate("SVD failed"))?;
    let sv = &svd.singular_values;
    let mut order: Vec<usize> = (0..sv.len()).collect();
    order.sort_by(|&a, &b| sv[a].total_cmp(&sv[b]));
    if sv[order[1]] <= 1e-12 * sv[order[sv.len() - 1]] {
        return Err(ZhangError::Degenerate("the views leave K undetermined"));
    }
    let b = v_t.row(order[0]);
    let (mut b11, mut b22, mut b13, mut b23, mut b33) = (b[0], b[1], b[2], b[3], b[4]);
    // B is positive definite up to scale: fix the sign so that B₁₁ > 0.
    if b11 < 0.0 {
        (b11, b22, b13, b23, b33) = (-b11, -b22, -b13, -b23, -b33);
    }
    if b11 <= 0.0 || b22 <= 0.0 {
        return Err(ZhangError::Degenerate("B is not positive definite"));
    }
    // Zhang App. B with B₁₂ = 0 (γ = 0).
    let v0 = -b23 / b22;
    let lambda = b33 - (b13 * b13 + v0 * (-b11 * b23)) / b11;
    let (a2, b2) = (lambda / b11, lambda / b22);
    if a2 <= 0.0 || b2 <= 0.0 {
        return Err(ZhangError::Degenerate("negative focal length squared"));
    }
    let (alpha, beta) = (a2.sqrt(), b2.sqrt());
    let u0 = -b13 * a2 / lambda;
    // Undo the conditioning: K = T⁻¹ K'.
    Ok(Intrinsics {
        fx: alpha * s,
        fy: beta * s,
        cx: u0 * s + cx0,
        cy: v0 * s + cy0,
    })
}

/// Linear least squares for (k1, k2) given ideal normalised points, their ideal (undistorted)
/// pixels and the observed pixels (Zhang §3.3, eq. 13). Returns zeros when the system is
/// singular (all points near the principal point) or the result is implausible (|k| > 1).
pub fn radial_initialisation(
    intrinsics: &Intrinsics,
    samples: &[([f64; 2], [f64; 2], [f64; 2])],
) -> [f64; 2] {
    let mut ata = nalgebra::Matrix2::<f64>::zeros();
    let mut atb = nalgebra::Vector2::<f64>::zeros();
    for (norm, ideal, observed) in samples {
        let r2 = norm[0] * norm[0] + norm[1] * norm[1];
        for axis in 0..2 {
            let centre = if axis == 0 {
                intrinsics.cx
            } else {
                intrinsics.cy
            };
            let d = ideal[axis] - centre;
            let row = nalgebra::Vector2::new(d * r2, d * r2 * r2);
            ata += row * row.transpose();
            atb += row * (observed[axis] - ideal[axis]);
        }
    }
    match ata.cholesky() {
        Some(c) => {
            let k = c.solve(&atb);
            if k.iter().all(|v| v.is_finite() && v.abs() <= 1.0) {
                [k[0], k[1]]
            } else {
                [0.0; 2]
            }
        }
        None => [0.0; 2],
    }
}
