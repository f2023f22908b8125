//! Whether a camera model is one a lens and sensor can have: the bounds a rig file's camera,
//! a session's recorded camera and the fit's input all share, so one impossible value is refused
//! the same way wherever it is read.
//!
//! Contract: [`CameraModel::check_plausible`] returns the first implausible parameter in words
//! naming it (`fx = 1e308 px is outside …`); the caller says where it came from.

use super::CameraModel;

/// Smallest focal length, in longer image sides (a 180° fisheye is ≈ 0.3).
pub const FOCAL_MIN_SIDES: f64 = 0.1;
/// Largest focal length, in longer image sides (a 600 mm lens on a 2/3" sensor is ≈ 70).
pub const FOCAL_MAX_SIDES: f64 = 100.0;
/// Largest |k1|, |k2|, |k3|.
pub const RADIAL_MAX: f64 = 100.0;
/// Largest |p1|, |p2|.
pub const TANGENTIAL_MAX: f64 = 1.0;

impl CameraModel {
    /// Checks that every parameter is finite and within what a lens can have: focal lengths
    /// within [`FOCAL_MIN_SIDES`, `FOCAL_MAX_SIDES`] longer image sides, the principal point
    /// at most half an image outside it, |k| ≤ [`RADIAL_MAX`], |p| ≤ [`TANGENTIAL_MAX`].
    pub fn check_plausible(&self) -> Result<(), String> {
        self.validate().map_err(|e| e.to_string())?;
        let side = f64::from(self.width.max(self.height));
        let i = self.intrinsics;
        for (name, f) in [("fx", i.fx), ("fy", i.fy)] {
            if !(FOCAL_MIN_SIDES * side..=FOCAL_MAX_SIDES * side).contains(&f) {
                return Err(format!(
                    "{name} = {f:e} px is outside [{}, {}] px ({FOCAL_MIN_SIDES}–{FOCAL_MAX_SIDES} \
                     image widths): no lens has it — recalibrate (`ellipso calibrate`)",
                    FOCAL_MIN_SIDES * side,
                    FOCAL_MAX_SIDES * side
                ));
            }
        }
        for (name, c, len) in [
            ("cx", i.cx, f64::from(self.width)),
            ("cy", i.cy, f64::from(self.height)),
        ] {
            if !(-0.5 * len..=1.5 * len).contains(&c) {
                return Err(format!(
                    "{name} = {c:e} px is more than half an image outside the {len}-px image"
                ));
            }
        }
        let d = self.distortion;
        for (name, k, max) in [
            ("k1", d.k1, RADIAL_MAX),
            ("k2", d.k2, RADIAL_MAX),
            ("k3", d.k3, RADIAL_MAX),
            ("p1", d.p1, TANGENTIAL_MAX),
            ("p2", d.p2, TANGENTIAL_MAX),
        ] {
            if k.abs() > max {
                return Err(format!(
                    "{name} = {k:e} is beyond ±{max}: no lens distorts so"
                ));
            }
        }
        Ok(())
    }
}
