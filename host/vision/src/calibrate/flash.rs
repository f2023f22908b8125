//! Flash position from specular highlights on a mirror-like sphere of known radius at a known
//! place on the board.
//!
//! Per view we know `camera_from_board`, the sphere (centre in the board frame, radius) and the
//! pixel of the highlight. The ray through the pixel meets the sphere at P (near intersection)
//! with outward normal n. Mirror reflection — n bisects the directions to the camera and to the
//! flash — means the flash lies on the reflected ray P + τ·m, τ > 0, with
//! m = 2(n·v)n − v and v = −P/‖P‖ the unit direction back to the camera. The flash offset F
//! (camera frame, fixed on the rig) is the point closest to all reflected rays:
//! minimise Σ wᵢ‖(I − mᵢmᵢᵀ)(F − Pᵢ)‖², a 3×3 linear system. Because highlight-pixel noise
//! perturbs each ray's *direction*, the second pass weights by wᵢ = 1/τᵢ² (τᵢ = mᵢ·(F − Pᵢ) from
//! the first pass), turning the residuals into angles (rad).
//!
//! Geometry: the reflected rays must come from different directions, or the position along them
//! is not determined however small their residuals are. An orbit aimed at the sphere's centre at
//! a fixed distance sees the *same* ray in the camera frame in every view; the sphere has to move
//! around the image (and in depth). Rays whose directions all lie within
//! [`MIN_RAY_SPREAD_RAD`] of their mean are rejected as [`FlashError::Degenerate`] — the residual
//! covariance cannot reveal that degeneracy (identical rays have identical, tiny residuals).
//!
//! Uncertainty: σ² = Σ wᵢ‖eᵢ‖² / (2n − 3) (two residual components per ray, three unknowns),
//! covariance σ²·(Σ wᵢ(I − mᵢmᵢᵀ))⁻¹ — the Gauss–Markov estimate under isotropic angular noise.

use ellipso_model::camera::{CameraError, CameraModel, Pose};
use nalgebra::{Matrix3, Point3, Vector3};

/// Smallest accepted largest angle between a reflected ray and the mean ray direction, rad
/// (1°): below it the flash's position along the rays is not determined (see the module doc).
pub const MIN_RAY_SPREAD_RAD: f64 = 0.017_453_292_519_943_295;

/// One highlight observation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HighlightObservation {
    /// Board frame → camera frame for this view.
    pub camera_from_board: Pose,
    /// Sphere centre in the board frame, m.
    pub sphere_centre_board_m: Point3<f64>,
    /// Sphere radius, m.
    pub sphere_radius_m: f64,
    /// Highlight centre, px (integer-centre convention, raw distorted image).
    pub highlight_px: [f64; 2],
}

/// The estimated flash position.
#[derive(Debug, Clone, PartialEq)]
pub struct FlashEstimate {
    /// Flash position in the camera frame, m.
    pub flash_camera_m: Point3<f64>,
    /// Its 3×3 covariance, m².
    pub covariance_m2: Matrix3<f64>,
    /// 1σ along camera x, y, z, m.
    pub std_m: [f64; 3],
    /// Per view: angle between the reflected ray and the direction to the estimate, rad.
    pub ray_angle_residuals_rad: Vec<f64>,
    /// RMS of those angles, rad.
    pub rms_angle_rad: f64,
}

impl FlashEstimate {
    /// The rig file's `[flash]` table (`offset_m`, camera frame), each coordinate's 1σ in a
    /// comment; floats in Rust's shortest round-trip form, so reading it back is exact.
    pub fn to_toml_flash_section(&self) -> String {
        let p = self.flash_camera_m;
        let s = self.std_m;
        format!(
            "[flash]\n\
             # from specular highlights in {} views; ray-angle RMS {:.3} mrad\n\
             # 1σ: x {:.2} mm, y {:.2} mm, z {:.2} mm (camera frame: x right, y down, z forward)\n\
             offset_m = [{:?}, {:?}, {:?}]\n",
            self.ray_angle_residuals_rad.len(),
            self.rms_angle_rad * 1e3,
            s[0] * 1e3,
            s[1] * 1e3,
            s[2] * 1e3,
            p.x,
            p.y,
            p.z
        )
    }
}

/// Why the flash could not be estimated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FlashError {
    /// Fewer than two views.
    #[error("flash estimation needs at least 2 highlight views, got {0}")]
    TooFewViews(usize),
    /// Radius not positive/finite.
    #[error("view {view}: sphere radius {radius_m} m must be positive and finite")]
    BadRadius { view: usize, radius_m: f64 },
    /// The highlight pixel cannot be unprojected.
    #[error("view {view}: highlight pixel cannot be unprojected: {source}")]
    Unproject { view: usize, source: CameraError },
    /// The ray through the highlight misses the sphere: wrong pose, sphere or highlight.
    #[error("view {view}: the ray through the highlight misses the sphere by {miss_m:.2e} m")]
    RayMissesSphere { view: usize, miss_m: f64 },
    /// All reflected rays are (nearly) parallel: the position along them is not determined.
    #[error(
        "reflected rays are nearly parallel; move the sphere around the image and in depth (not an orbit aimed at its centre)"
    )]
    Degenerate,
}

/// Where a view's highlight ray meets its sphere: the near intersection and the outward unit
/// normal there, camera frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpherePoint {
    /// The highlight's point on the sphere, m.
    pub point_camera_m: Point3<f64>,
    /// The outward unit normal there.
    pub normal_camera: Vector3<f64>,
}

/// The highlight's point on the sphere of observation `o` (number `view` in errors).
pub fn sphere_point(
    camera: &CameraModel,
    view: usize,
    o: &HighlightObservation,
) -> Result<SpherePoint, FlashError> {
    let r = o.sphere_radius_m;
    if !(r.is_finite() && r > 0.0) {
        return Err(FlashError::BadRadius { view, radius_m: r });
    }
    let d = camera
        .unproject_to_ray(o.highlight_px)
        .map_err(|source| FlashError::Unproject { view, source })?
        .into_inner();
    let c = (o.camera_from_board * o.sphere_centre_board_m).coords;
    let dc = d.dot(&c);
    let disc = dc * dc - c.norm_squared() + r * r;
    if disc < 0.0 {
        let miss_m = (c - d * dc).norm() - r;
        return Err(FlashError::RayMissesSphere { view, miss_m });
    }
    let p = d * (dc - disc.sqrt());
    Ok(SpherePoint {
        point_camera_m: Point3::from(p),
        normal_camera: (p - c) / r,
    })
}

/// Estimates the flash position in the camera frame (see the module doc).
pub fn estimate_flash_position(
    camera: &CameraModel,
    observations: &[HighlightObservation],
) -> Result<FlashEstimate, FlashError> {
    if observations.len() < 2 {
        return Err(FlashError::TooFewViews(observations.len()));
    }
    let mut rays = Vec::with_capacity(observations.len());
    for (view, o) in observations.iter().enumerate() {
        let sp = sphere_point(camera, view, o)?;
        let p = sp.point_camera_m.coords;
        let n = sp.normal_camera;
        let v = -p.normalize();
        let m = (2.0 * n.dot(&v) * n - v).normalize();
        rays.push((p, m));
    }
    // Direction spread: the mean of unit vectors is non-zero here (all m point back toward the
    // camera side), normalised with a guard.
    let mean = rays
        .iter()
        .fold(Vector3::zeros(), |a, (_, m)| a + m)
        .try_normalize(1e-12)
        .ok_or(FlashError::Degenerate)?;
    let spread = rays
        .iter()
        .map(|(_, m)| m.dot(&mean).clamp(-1.0, 1.0).acos())
        .fold(0.0, f64::max);
    // NaN spread fails too.
    if spread.is_nan() || spread < MIN_RAY_SPREAD_RAD {
        return Err(FlashError::Degenerate);
    }
    let solve = |weights: &[f64]| -> Result<(Vector3<f64>, Matrix3<f64>), FlashError> {
        let mut a = Matrix3::zeros();
        let mut b = Vector3::zeros();
        for ((p, m), w) in rays.iter().zip(weights) {
            let proj = Matrix3::identity() - m * m.transpose();
            a += proj * *w;
            b += proj * p * *w;
        }
        let eig = a.symmetric_eigen();
        let (lmin, lmax) = (eig.eigenvalues.min(), eig.eigenvalues.max());
        // Nearly parallel rays leave a ~zero eigenvalue along them.
        if lmin.is_nan() || lmin <= 1e-9 * lmax {
            return Err(FlashError::Degenerate);
        }
        let a_inv = a.try_inverse().ok_or(FlashError::Degenerate)?;
        Ok((a_inv * b, a_inv))
    };
    let (first, _) = solve(&vec![1.0; rays.len()])?;
    // Angular weights; τ floored at 1 mm so a ray passing through the estimate cannot dominate.
    let weights: Vec<f64> = rays
        .iter()
        .map(|(p, m)| 1.0 / m.dot(&(first - p)).max(1e-3).powi(2))
        .collect();
    let (flash, a_inv) = solve(&weights)?;
    let angles: Vec<f64> = rays
        .iter()
        .map(|(p, m)| {
            let to_flash = flash - p;
            // Clamp the cosine into [-1, 1] before acos (round-off).
            let cos = (m.dot(&to_flash) / to_flash.norm().max(1e-12)).clamp(-1.0, 1.0);
            cos.acos()
        })
        .collect();
    let weighted_sq: f64 = rays
        .iter()
        .zip(&weights)
        .map(|((p, m), w)| {
            w * ((Matrix3::identity() - m * m.transpose()) * (flash - p)).norm_squared()
        })
        .sum();
    let dof = (2 * rays.len()).saturating_sub(3).max(1) as f64;
    let covariance_m2 = a_inv * (weighted_sq / dof);
    let std_m = [0, 1, 2].map(|k| covariance_m2[(k, k)].max(0.0).sqrt());
    let rms_angle_rad = (angles.iter().map(|a| a * a).sum::<f64>() / angles.len() as f64).sqrt();
    Ok(FlashEstimate {
        flash_camera_m: Point3::from(flash),
        covariance_m2,
        std_m,
        ray_angle_residuals_rad: angles,
        rms_angle_rad,
    })
}
