//! Reference frames for Stokes vectors, and the rotations between them.
//!
//! Contract (docs/model.md §1 "Frames", documented once here):
//! - A [`Frame`] is a right-handed orthonormal basis (x, y, z) with z the **propagation**
//!   direction; Stokes vectors in it are seen looking back along z.
//! - **Light frame** ([`Frame::light`]): z = −ω_i (light → surface), y = the flash "up"
//!   orthogonalised against z, x = y × z.
//! - **Camera frame** ([`Frame::camera`]): z = ω_o (surface → camera), y = the camera "up"
//!   (image up) orthogonalised against z, x = y × z (image right).
//!   From an OpenCV world→camera rotation R, up = −(row 1 of R) ([`camera_up_from_opencv`]).
//! - When the supplied up vector is (nearly) parallel to z, the fallback up is the world axis
//!   least aligned with z (ties → the earlier of x, y, z); see [`Frame::from_z_up`].
//!
//! The rotation between two frames about a shared z is the rotator C(θ) with θ the angle from
//! the first frame's x to the second's ([`Frame::rotator_to`]), computed without angles.

use super::{OpticsError, Real, Rotator, Vec3};

/// Squared length below which a vector is treated as having no direction. Chosen far below any
/// geometry the rig can produce (angles of ~1e-10 rad) and above f64 rounding of unit vectors'
/// cross products of identical inputs (exact 0).
pub(crate) const DIRECTION_EPS_SQ: f64 = 1e-24;

/// A right-handed orthonormal frame; z is the propagation direction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame<T> {
    /// x axis (for the camera frame: image right).
    pub x: Vec3<T>,
    /// y axis (for the camera frame: image up).
    pub y: Vec3<T>,
    /// z axis: propagation direction.
    pub z: Vec3<T>,
}

impl<T: Real> Frame<T> {
    /// The frame with propagation direction `z` (any non-zero length) and y as close as
    /// possible to `up`. If `up` is zero, non-finite or within ~1e-6 rad of ±z, the world axis
    /// least aligned with z is used as up instead, so a frame always exists for a valid z.
    pub fn from_z_up(z: Vec3<T>, up: Vec3<T>) -> Result<Self, OpticsError> {
        let z = z
            .normalized_or_none(DIRECTION_EPS_SQ)
            .ok_or(OpticsError::ZeroDirection("frame z"))?;
        // Relative threshold: the up vector may have any length.
        let project = |u: Vec3<T>| {
            let scale: f64 = u.re().iter().map(|v| v * v).sum();
            (u - z.scale(u.dot(z))).normalized_or_none(1e-12 * scale)
        };
        let y = match project(up) {
            Some(y) => y,
            None => {
                let a = z.re().map(f64::abs);
                let axis = if a[0] <= a[1] && a[0] <= a[2] {
                    [1.0, 0.0, 0.0]
                } else if a[1] <= a[2] {
                    [0.0, 1.0, 0.0]
                } else {
                    [0.0, 0.0, 1.0]
                };
                project(Vec3::from_f64(axis)).ok_or(OpticsError::ZeroDirection("frame up"))?
            }
        };
        Ok(Self {
            x: y.cross(z),
            y,
            z,
        })
    }

    /// The light (incident) frame: z = −`to_light`, y from `light_up`.
    pub fn light(to_light: Vec3<T>, light_up: Vec3<T>) -> Result<Self, OpticsError> {
        Self::from_z_up(-to_light, light_up)
    }

    /// The camera (outgoing) frame: z = `to_camera`, y from `camera_up` (image up).
    pub fn camera(to_camera: Vec3<T>, camera_up: Vec3<T>) -> Result<Self, OpticsError> {
        Self::from_z_up(to_camera, camera_up)
    }

    /// Coordinates of a world vector in this frame.
    pub fn to_local(&self, v: Vec3<T>) -> Vec3<T> {
        Vec3::new(self.x.dot(v), self.y.dot(v), self.z.dot(v))
    }

    /// C(θ) taking Stokes vectors from this frame to `other`, where both share the propagation
    /// direction (only the components of `other.x` in this frame's x–y plane are used).
    /// Returns the identity if `other.x` has no component in this plane (z axes not shared).
    pub fn rotator_to(&self, other: &Self) -> Rotator<T> {
        self.rotator_to_axis(other.x)
            .unwrap_or_else(Rotator::identity)
    }

    /// C(θ) from this frame to the frame about the same z whose x axis is the projection of
    /// `axis` onto this frame's x–y plane. `None` when that projection vanishes
    /// (squared length ≤ 1e-24·|axis|²).
    pub fn rotator_to_axis(&self, axis: Vec3<T>) -> Option<Rotator<T>> {
        let scale: f64 = axis.re().iter().map(|v| v * v).sum();
        Rotator::from_direction(self.x.dot(axis), self.y.dot(axis), DIRECTION_EPS_SQ * scale)
    }
}

impl Frame<f64> {
    /// The same frame as constants of another scalar type.
    pub fn cast<T: Real>(&self) -> Frame<T> {
        Frame {
            x: self.x.cast(),
            y: self.y.cast(),
            z: self.z.cast(),
        }
    }
}

/// The camera up vector (image up, world coordinates) from an OpenCV world→camera rotation
/// `r` (row-major): −(second row), because OpenCV's camera +Y points down the image.
pub fn camera_up_from_opencv(r_camera_from_world: [[f64; 3]; 3]) -> [f64; 3] {
    r_camera_from_world[1].map(|v| -v)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::Stokes;

    fn v(a: [f64; 3]) -> Vec3<f64> {
        Vec3::from_f64(a)
    }

    fn assert_orthonormal(f: &Frame<f64>) {
        for (a, b) in [(f.x, f.y), (f.y, f.z), (f.x, f.z)] {
            assert!(a.dot(b).abs() < 1e-14);
        }
        for a in [f.x, f.y, f.z] {
            assert!((a.norm_squared() - 1.0).abs() < 1e-14);
        }
        let c = f.x.cross(f.y);
        assert!((c - f.z).norm_squared() < 1e-28, "right-handed");
    }

    #[test]
    fn camera_frame_axes_follow_the_convention() {
        let f = Frame::camera(v([0.0, 0.0, 2.0]), v([0.0, 1.0, 0.0])).unwrap();
        assert_eq!(f.x, v([1.0, 0.0, 0.0]));
        assert_eq!(f.y, v([0.0, 1.0, 0.0]));
        let l = Frame::light(v([0.0, 0.0, 1.0]), v([0.0, 1.0, 0.0])).unwrap();
        // Coaxial: x_i = −x_o (docs/model.md §1 "Frames").
        assert_eq!(l.x, v([-1.0, 0.0, 0.0]));
        assert_orthonormal(&l);
    }

    #[test]
    fn parallel_or_zero_up_falls_back_and_zero_z_is_an_error() {
        for up in [
            [0.0, 0.0, 1.0],
            [0.0, 0.0, -3.0],
            [0.0; 3],
            [f64::NAN, 0.0, 0.0],
        ] {
            let f = Frame::camera(v([0.0, 0.0, 1.0]), v(up)).unwrap();
            assert_orthonormal(&f);
        }
        assert!(Frame::camera(v([0.0; 3]), v([0.0, 1.0, 0.0])).is_err());
    }

    #[test]
    fn opencv_up_is_minus_second_row() {
        let r = [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]];
        assert_eq!(camera_up_from_opencv(r), [0.0, 1.0, 0.0]);
    }

    #[test]
    fn rotating_between_frames_preserves_the_physical_polarisation() {
        // A beam along z, linearly polarised along world direction e. Expressed in two frames
        // about z, the AoLP in each frame must point along e.
        let z = v([0.3, -0.2, 0.9]);
        let a = Frame::from_z_up(z, v([0.0, 1.0, 0.0])).unwrap();
        let b = Frame::from_z_up(z, v([1.0, 0.4, 0.0])).unwrap();
        let e = a.x.scale(0.6_f64.cos()) + a.y.scale(0.6_f64.sin());
        let s_a = Stokes::linear(1.0, 0.6);
        let s_b = a.rotator_to(&b).apply(s_a);
        let ang = s_b.aolp_rad();
        let e_b = b.x.scale(ang.cos()) + b.y.scale(ang.sin());
        assert!(e_b.cross(e).norm_squared() < 1e-24, "{e_b:?} vs {e:?}");
        // Round trip.
        let back = b.rotator_to(&a).apply(s_b);
        assert!((back.s1 - s_a.s1).abs() < 1e-14 && (back.s2 - s_a.s2).abs() < 1e-14);
    }
}
