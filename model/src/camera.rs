//! The pinhole + Brown–Conrady camera model shared by the simulator (which renders through it)
//! and the host (which estimates pose and calibrates through it): one model, never two copies.
//!
//! # Conventions
//! - **Camera frame**: OpenCV — x right, y down, z forward (along the optical axis). Metres.
//! - **Pixel coordinates**: OpenCV — the *centre* of pixel (col i, row j) is at (i, j); the image
//!   covers [-0.5, width-0.5] × [-0.5, height-0.5]. (AprilTag puts pixel centres at i + 0.5; the
//!   detector wrapper in `ellipso-vision` converts.)
//! - **Poses** are [`Pose`] = `Isometry3<f64>` named `b_from_a` (`camera_from_board` maps a
//!   board-frame point into the camera frame), so chains read right to left.
//! - **Lens model** (OpenCV `calib3d`, Brown 1966 / Conrady 1919): with normalised coordinates
//!   x = X/Z, y = Y/Z and r² = x² + y²,
//!   ```text
//!   x_d = x·(1 + k1 r² + k2 r⁴ + k3 r⁶) + 2 p1 x y + p2 (r² + 2 x²)
//!   y_d = y·(1 + k1 r² + k2 r⁴ + k3 r⁶) + p1 (r² + 2 y²) + 2 p2 x y
//!   u = fx·x_d + cx,   v = fy·y_d + cy            (no skew)
//!   ```
//! - **Parameter vector** order (Jacobians, covariances): `[fx, fy, cx, cy, k1, k2, p1, p2, k3]`,
//!   OpenCV's `cameraMatrix` + `distCoeffs` order.
//!
//! The TOML form of a [`CameraModel`] is one flat table (`width, height, fx, fy, cx, cy, k1, k2,
//! k3, p1, p2`, distortion keys optional and zero by default), checked on load: unknown keys,
//! non-finite numbers, non-positive focal lengths or image sizes are errors naming the field.

mod jacobian;
mod plausible;

pub use jacobian::ProjectionJacobians;
pub use plausible::{FOCAL_MAX_SIDES, FOCAL_MIN_SIDES, RADIAL_MAX, TANGENTIAL_MAX};

use nalgebra::{Isometry3, Matrix2, Point3, Unit, Vector2, Vector3};
use serde::{Deserialize, Serialize};

/// A rigid transform `b_from_a`: maps points from frame a into frame b (metres).
pub type Pose = Isometry3<f64>;

/// Number of camera parameters in the Jacobian order `[fx, fy, cx, cy, k1, k2, p1, p2, k3]`.
pub const CAMERA_PARAM_COUNT: usize = 9;

/// Names of the camera parameters in Jacobian order.
pub const CAMERA_PARAM_NAMES: [&str; CAMERA_PARAM_COUNT] =
    ["fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3"];

/// Points closer to the camera plane than this (z in metres) do not project.
pub const MIN_DEPTH_M: f64 = 1e-9;

/// Iteration cap of [`Distortion::undistort`].
pub const UNDISTORT_MAX_ITERATIONS: usize = 50;

/// Convergence tolerance of [`Distortion::undistort`] in normalised units (≈1e-9 px at f = 1e3 px).
pub const UNDISTORT_TOLERANCE: f64 = 1e-12;

/// Errors of the camera model.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CameraError {
    /// A parameter is NaN or infinite.
    #[error("camera parameter {name} is not finite ({value})")]
    NotFinite { name: &'static str, value: f64 },
    /// A focal length is zero or negative.
    #[error("camera focal length {name} must be > 0 px, got {value}")]
    NonPositiveFocal { name: &'static str, value: f64 },
    /// The image has zero width or height.
    #[error("camera image size must be positive, got {width}×{height}")]
    EmptyImage { width: u32, height: u32 },
    /// Newton iteration inverting the lens distortion did not converge.
    #[error(
        "undistortion of distorted normalised point ({x_d}, {y_d}) did not converge \
         (residual {residual:e} after {iterations} iterations); the point is outside the \
         region where the distortion polynomial is invertible"
    )]
    UndistortNoConvergence {
        x_d: f64,
        y_d: f64,
        residual: f64,
        iterations: usize,
    },
    /// A pixel coordinate is NaN or infinite.
    #[error("pixel coordinate ({u}, {v}) is not finite")]
    PixelNotFinite { u: f64, v: f64 },
}

/// Pinhole intrinsics in pixels, OpenCV convention (pixel centres at integer coordinates).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Intrinsics {
    /// Focal length along x, px.
    pub fx: f64,
    /// Focal length along y, px.
    pub fy: f64,
    /// Principal point x, px (integer-centre convention).
    pub cx: f64,
    /// Principal point y, px (integer-centre convention).
    pub cy: f64,
}

/// Brown–Conrady lens distortion, OpenCV's formula and coefficients (dimensionless, acting on
/// normalised coordinates).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Distortion {
    /// Radial r² coefficient.
    #[serde(default)]
    pub k1: f64,
    /// Radial r⁴ coefficient.
    #[serde(default)]
    pub k2: f64,
    /// Radial r⁶ coefficient.
    #[serde(default)]
    pub k3: f64,
    /// First tangential coefficient.
    #[serde(default)]
    pub p1: f64,
    /// Second tangential coefficient.
    #[serde(default)]
    pub p2: f64,
}

/// A calibrated camera: image size, intrinsics and lens distortion.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "CameraModelToml", into = "CameraModelToml")]
pub struct CameraModel {
    /// Image width, px.
    pub width: u32,
    /// Image height, px.
    pub height: u32,
    /// Pinhole intrinsics.
    pub intrinsics: Intrinsics,
    /// Lens distortion.
    pub distortion: Distortion,
}

/// The flat TOML/serde form of [`CameraModel`] (the rig file's `[camera]` table).
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct CameraModelToml {
    width: u32,
    height: u32,
    fx: f64,
    fy: f64,
    cx: f64,
    cy: f64,
    #[serde(default)]
    k1: f64,
    #[serde(default)]
    k2: f64,
    #[serde(default)]
    k3: f64,
    #[serde(default)]
    p1: f64,
    #[serde(default)]
    p2: f64,
}

impl TryFrom<CameraModelToml> for CameraModel {
    type Error = CameraError;
    fn try_from(t: CameraModelToml) -> Result<Self, CameraError> {
        let model = CameraModel {
            width: t.width,
            height: t.height,
            intrinsics: Intrinsics {
                fx: t.fx,
                fy: t.fy,
                cx: t.cx,
                cy: t.cy,
            },
            distortion: Distortion {
                k1: t.k1,
                k2: t.k2,
                k3: t.k3,
                p1: t.p1,
                p2: t.p2,
            },
        };
        model.validate()?;
        Ok(model)
    }
}

impl From<CameraModel> for CameraModelToml {
    fn from(m: CameraModel) -> Self {
        let (i, d) = (m.intrinsics, m.distortion);
        CameraModelToml {
            width: m.width,
            height: m.height,
            fx: i.fx,
            fy: i.fy,
            cx: i.cx,
            cy: i.cy,
            k1: d.k1,
            k2: d.k2,
            k3: d.k3,
            p1: d.p1,
            p2: d.p2,
        }
    }
}

impl Distortion {
    /// No distortion.
    pub const ZERO: Distortion = Distortion {
        k1: 0.0,
        k2: 0.0,
        k3: 0.0,
        p1: 0.0,
        p2: 0.0,
    };

    /// Applies the lens distortion to an ideal normalised point (x, y) = (X/Z, Y/Z).
    pub fn distort(&self, normalised: [f64; 2]) -> [f64; 2] {
        let [x, y] = normalised;
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
        [
            x * radial + 2.0 * self.p1 * x * y + self.p2 * (r2 + 2.0 * x * x),
            y * radial + self.p1 * (r2 + 2.0 * y * y) + 2.0 * self.p2 * x * y,
        ]
    }

    /// 2×2 Jacobian of [`Distortion::distort`] w.r.t. the ideal normalised point.
    pub fn distort_jacobian(&self, normalised: [f64; 2]) -> Matrix2<f64> {
        let [x, y] = normalised;
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
        // d(radial)/d(r²)
        let d_radial = self.k1 + r2 * (2.0 * self.k2 + 3.0 * self.k3 * r2);
        let (dr_dx, dr_dy) = (2.0 * x * d_radial, 2.0 * y * d_radial);
        Matrix2::new(
            radial + x * dr_dx + 2.0 * self.p1 * y + 6.0 * self.p2 * x,
            x * dr_dy + 2.0 * self.p1 * x + 2.0 * self.p2 * y,
            y * dr_dx + 2.0 * self.p1 * x + 2.0 * self.p2 * y,
            radial + y * dr_dy + 6.0 * self.p1 * y + 2.0 * self.p2 * x,
        )
    }

    /// Inverts [`Distortion::distort`]: the ideal normalised point whose distorted image is
    /// `distorted`. Damped Newton iteration from x = x_d (OpenCV uses a fixed-point iteration,
    /// which diverges for strong barrel distortion; Newton converges quadratically wherever the
    /// Jacobian is regular). Converged when the distortion residual is below
    /// [`UNDISTORT_TOLERANCE`]; otherwise [`CameraError::UndistortNoConvergence`].
    pub fn undistort(&self, distorted: [f64; 2]) -> Result<[f64; 2], CameraError> {
        let [x_d, y_d] = distorted;
        if !(x_d.is_finite() && y_d.is_finite()) {
            return Err(CameraError::PixelNotFinite { u: x_d, v: y_d });
        }
        let target = Vector2::new(x_d, y_d);
        let mut p = target;
        let residual_at = |p: &Vector2<f64>| Vector2::from(self.distort([p.x, p.y])) - target;
        let mut r = residual_at(&p);
        for _ in 0..UNDISTORT_MAX_ITERATIONS {
            if r.norm() < UNDISTORT_TOLERANCE {
                return Ok([p.x, p.y]);
            }
            let jac = self.distort_jacobian([p.x, p.y]);
            let Some(step) = jac.lu().solve(&r) else {
                break;
            };
            // Backtracking: halve the step until the residual decreases (at most 30 halvings).
            let mut scale = 1.0;
            let mut accepted = false;
            for _ in 0..30 {
                let trial = p - step * scale;
                let r_trial = residual_at(&trial);
                if r_trial.norm() < r.norm() {
                    p = trial;
                    r = r_trial;
                    accepted = true;
                    break;
                }
                scale *= 0.5;
            }
            if !accepted {
                break;
            }
        }
        if r.norm() < UNDISTORT_TOLERANCE {
            return Ok([p.x, p.y]);
        }
        Err(CameraError::UndistortNoConvergence {
            x_d,
            y_d,
            residual: r.norm(),
            iterations: UNDISTORT_MAX_ITERATIONS,
        })
    }
}

impl CameraModel {
    /// A distortion-free camera.
    pub fn pinhole(width: u32, height: u32, intrinsics: Intrinsics) -> Self {
        CameraModel {
            width,
            height,
            intrinsics,
            distortion: Distortion::ZERO,
        }
    }

    /// Checks that every parameter is finite, focal lengths are positive and the image is not
    /// empty.
    pub fn validate(&self) -> Result<(), CameraError> {
        if self.width == 0 || self.height == 0 {
            return Err(CameraError::EmptyImage {
                width: self.width,
                height: self.height,
            });
        }
        for (name, value) in CAMERA_PARAM_NAMES.iter().zip(self.params()) {
            if !value.is_finite() {
                return Err(CameraError::NotFinite { name, value });
            }
        }
        for (name, value) in [("fx", self.intrinsics.fx), ("fy", self.intrinsics.fy)] {
            if value <= 0.0 {
                return Err(CameraError::NonPositiveFocal { name, value });
            }
        }
        Ok(())
    }

    /// The parameter vector `[fx, fy, cx, cy, k1, k2, p1, p2, k3]`.
    pub fn params(&self) -> [f64; CAMERA_PARAM_COUNT] {
        let (i, d) = (self.intrinsics, self.distortion);
        [i.fx, i.fy, i.cx, i.cy, d.k1, d.k2, d.p1, d.p2, d.k3]
    }

    /// A copy with the parameter vector `[fx, fy, cx, cy, k1, k2, p1, p2, k3]` replaced.
    pub fn with_params(&self, p: &[f64; CAMERA_PARAM_COUNT]) -> Self {
        CameraModel {
            width: self.width,
            height: self.height,
            intrinsics: Intrinsics {
                fx: p[0],
                fy: p[1],
                cx: p[2],
                cy: p[3],
            },
            distortion: Distortion {
                k1: p[4],
                k2: p[5],
                p1: p[6],
                p2: p[7],
                k3: p[8],
            },
        }
    }

    /// Projects a camera-frame point (metres) to pixels; `None` when it is not in front of the
    /// camera (z ≤ [`MIN_DEPTH_M`]) or not finite. Points outside the image still project.
    pub fn project(&self, point_camera: &Point3<f64>) -> Option<[f64; 2]> {
        if !(point_camera.z > MIN_DEPTH_M && point_camera.coords.iter().all(|c| c.is_finite())) {
            return None;
        }
        let normalised = [
            point_camera.x / point_camera.z,
            point_camera.y / point_camera.z,
        ];
        Some(self.normalised_to_pixel(self.distortion.distort(normalised)))
    }

    /// Maps a distorted normalised point to pixels: (fx·x_d + cx, fy·y_d + cy).
    pub fn normalised_to_pixel(&self, distorted: [f64; 2]) -> [f64; 2] {
        let i = self.intrinsics;
        [i.fx * distorted[0] + i.cx, i.fy * distorted[1] + i.cy]
    }

    /// Maps a pixel to its distorted normalised point ((u − cx)/fx, (v − cy)/fy). The division is
    /// safe for any model that passed [`CameraModel::validate`] (fx, fy > 0).
    pub fn pixel_to_distorted(&self, pixel: [f64; 2]) -> [f64; 2] {
        let i = self.intrinsics;
        [(pixel[0] - i.cx) / i.fx, (pixel[1] - i.cy) / i.fy]
    }

    /// Removes lens distortion from a pixel: the ideal normalised point (X/Z, Y/Z) of the
    /// camera-frame ray through it.
    pub fn undistort_pixel(&self, pixel: [f64; 2]) -> Result<[f64; 2], CameraError> {
        if !(pixel[0].is_finite() && pixel[1].is_finite()) {
            return Err(CameraError::PixelNotFinite {
                u: pixel[0],
                v: pixel[1],
            });
        }
        self.distortion.undistort(self.pixel_to_distorted(pixel))
    }

    /// Where an ideal (undistorted) pinhole camera with the same intrinsics would see the pixel.
    pub fn undistort_to_pixel(&self, pixel: [f64; 2]) -> Result<[f64; 2], CameraError> {
        Ok(self.normalised_to_pixel(self.undistort_pixel(pixel)?))
    }

    /// Unit direction (camera frame) of the ray through a pixel, pointing forward (z > 0).
    pub fn unproject_to_ray(&self, pixel: [f64; 2]) -> Result<Unit<Vector3<f64>>, CameraError> {
        let [x, y] = self.undistort_pixel(pixel)?;
        Ok(Unit::new_normalize(Vector3::new(x, y, 1.0)))
    }

    /// Whether a pixel lies inside the image area [-0.5, w − 0.5] × [-0.5, h − 0.5].
    pub fn contains_pixel(&self, pixel: [f64; 2]) -> bool {
        pixel[0] >= -0.5
            && pixel[1] >= -0.5
            && pixel[0] <= f64::from(self.width) - 0.5
            && pixel[1] <= f64::from(self.height) - 0.5
    }
}

#[cfg(test)]
mod tests;
