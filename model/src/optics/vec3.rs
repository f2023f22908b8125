//! A minimal 3-vector generic over [`Real`], for directions in the optics model.
//!
//! Contract: plain component-wise arithmetic, dot and cross products; `normalized` refuses
//! vectors whose squared length is not a positive finite number instead of producing NaN.

use core::ops::{Add, Mul, Neg, Sub};

use super::Real;

/// A 3-vector (world or frame coordinates; the owner of the value names the frame).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Vec3<T> {
    /// x component.
    pub x: T,
    /// y component.
    pub y: T,
    /// z component.
    pub z: T,
}

impl<T: Real> Vec3<T> {
    /// From components.
    #[inline]
    pub const fn new(x: T, y: T, z: T) -> Self {
        Self { x, y, z }
    }
    /// From an `f64` array (constants).
    #[inline]
    pub fn from_f64(v: [f64; 3]) -> Self {
        Self::new(T::from_f64(v[0]), T::from_f64(v[1]), T::from_f64(v[2]))
    }
    /// From an array of scalars.
    #[inline]
    pub fn from_array(v: [T; 3]) -> Self {
        Self::new(v[0], v[1], v[2])
    }
    /// As an array of scalars.
    #[inline]
    pub fn to_array(self) -> [T; 3] {
        [self.x, self.y, self.z]
    }
    /// Real parts as `f64`.
    #[inline]
    pub fn re(self) -> [f64; 3] {
        [self.x.re(), self.y.re(), self.z.re()]
    }
    /// Dot product.
    #[inline]
    pub fn dot(self, o: Self) -> T {
        self.x * o.x + self.y * o.y + self.z * o.z
    }
    /// Cross product `self × o`.
    #[inline]
    pub fn cross(self, o: Self) -> Self {
        Self::new(
            self.y * o.z - self.z * o.y,
            self.z * o.x - self.x * o.z,
            self.x * o.y - self.y * o.x,
        )
    }
    /// Squared length.
    #[inline]
    pub fn norm_squared(self) -> T {
        self.dot(self)
    }
    /// Scales by a scalar.
    #[inline]
    pub fn scale(self, k: T) -> Self {
        Self::new(self.x * k, self.y * k, self.z * k)
    }
    /// The unit vector along `self`, or `None` when the squared length is below `min_norm_sq`
    /// (or not finite): a direction cannot be recovered from it.
    #[inline]
    pub fn normalized_or_none(self, min_norm_sq: f64) -> Option<Self> {
        let n2 = self.norm_squared();
        let r = n2.re();
        if r.is_finite() && r > min_norm_sq {
            Some(self.scale(n2.sqrt().recip()))
        } else {
            None
        }
    }
    /// True when every component (and derivative) is finite.
    #[inline]
    pub fn is_finite(self) -> bool {
        self.x.is_finite() && self.y.is_finite() && self.z.is_finite()
    }
}

impl Vec3<f64> {
    /// The same vector as constants of another scalar type.
    #[inline]
    pub fn cast<T: Real>(self) -> Vec3<T> {
        Vec3::from_f64([self.x, self.y, self.z])
    }
}

impl<T: Real> Add for Vec3<T> {
    type Output = Self;
    #[inline]
    fn add(self, o: Self) -> Self {
        Self::new(self.x + o.x, self.y + o.y, self.z + o.z)
    }
}

impl<T: Real> Sub for Vec3<T> {
    type Output = Self;
    #[inline]
    fn sub(self, o: Self) -> Self {
        Self::new(self.x - o.x, self.y - o.y, self.z - o.z)
    }
}

impl<T: Real> Neg for Vec3<T> {
    type Output = Self;
    #[inline]
    fn neg(self) -> Self {
        Self::new(-self.x, -self.y, -self.z)
    }
}

impl<T: Real> Mul<T> for Vec3<T> {
    type Output = Self;
    #[inline]
    fn mul(self, k: T) -> Self {
        self.scale(k)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cross_is_right_handed_and_normalisation_refuses_zero() {
        let x = Vec3::<f64>::from_f64([1.0, 0.0, 0.0]);
        let y = Vec3::<f64>::from_f64([0.0, 1.0, 0.0]);
        assert_eq!(x.cross(y), Vec3::from_f64([0.0, 0.0, 1.0]));
        assert!(
            Vec3::<f64>::from_f64([0.0; 3])
                .normalized_or_none(0.0)
                .is_none()
        );
        assert!(
            Vec3::<f64>::from_f64([f64::NAN, 0.0, 1.0])
                .normalized_or_none(0.0)
                .is_none()
        );
        let n = Vec3::<f64>::from_f64([3.0, 0.0, 4.0])
            .normalized_or_none(0.0)
            .unwrap();
        assert!((n.x - 0.6).abs() < 1e-15 && (n.z - 0.8).abs() < 1e-15);
    }
}
