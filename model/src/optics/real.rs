//! The scalar abstraction every optics function is generic over.
//!
//! Contract: [`Real`] is implemented for `f32`, `f64` and the forward-mode dual number
//! [`Dual<N>`](super::Dual). Model code only ever uses the operations below, so one source
//! gives the renderer its fast `f32`/`f64` path and the fit exact derivatives.
//!
//! Branches and clamps in model code compare **real parts** ([`Real::re`]); a clamped value is
//! replaced by a constant ([`Real::from_f64`], zero derivative) and each such clamp is
//! documented where it is made. Transcendental functions follow the usual calculus rules on the
//! derivative part; the one deliberate exception is `sqrt` at exactly 0, whose derivative is
//! defined as 0 (see [`Dual`](super::Dual)).

use core::fmt::Debug;
use core::ops::{Add, AddAssign, Div, DivAssign, Mul, MulAssign, Neg, Sub, SubAssign};

/// A real scalar: `f32`, `f64`, or a dual number carrying derivatives.
pub trait Real:
    Copy
    + Debug
    + Send
    + Sync
    + 'static
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + SubAssign
    + MulAssign
    + DivAssign
{
    /// Machine epsilon of the underlying floating-point type.
    const EPSILON: f64;

    /// A constant (all derivatives zero).
    fn from_f64(value: f64) -> Self;
    /// The real part (the value itself for plain floats), used for every branch and clamp.
    fn re(self) -> f64;
    /// Square root. Callers guarantee a non-negative argument (clamp first).
    fn sqrt(self) -> Self;
    /// Absolute value (derivative sign taken from the real part, + at 0).
    fn abs(self) -> Self;
    /// Sine (radians).
    fn sin(self) -> Self;
    /// Cosine (radians).
    fn cos(self) -> Self;
    /// Exponential.
    fn exp(self) -> Self;
    /// Natural logarithm. Callers guarantee a positive argument.
    fn ln(self) -> Self;
    /// Four-quadrant arctangent of `self / x` (radians).
    fn atan2(self, x: Self) -> Self;
    /// True when the value and every derivative are finite.
    fn is_finite(self) -> bool;

    /// Zero constant.
    #[inline]
    fn zero() -> Self {
        Self::from_f64(0.0)
    }
    /// One constant.
    #[inline]
    fn one() -> Self {
        Self::from_f64(1.0)
    }
    /// `self²`.
    #[inline]
    fn sq(self) -> Self {
        self * self
    }
    /// `1/self`.
    #[inline]
    fn recip(self) -> Self {
        Self::one() / self
    }
    /// The larger of the two by real part (ties keep `self`).
    #[inline]
    fn max_re(self, other: Self) -> Self {
        if self.re() >= other.re() { self } else { other }
    }
    /// The smaller of the two by real part (ties keep `self`).
    #[inline]
    fn min_re(self, other: Self) -> Self {
        if self.re() <= other.re() { self } else { other }
    }
    /// Clamps the real part into `[lo, hi]`; a clamped value becomes the constant bound.
    /// NaN real parts map to `lo`, so a clamp never propagates NaN.
    #[inline]
    fn clamp_re(self, lo: f64, hi: f64) -> Self {
        let r = self.re();
        if r >= lo && r <= hi {
            self
        } else if r > hi {
            Self::from_f64(hi)
        } else {
            Self::from_f64(lo)
        }
    }
    /// `√max(self, 0)`: the square root of a quantity that is non-negative in exact
    /// arithmetic but may round slightly below zero.
    #[inline]
    fn sqrt_clamped(self) -> Self {
        if self.re() > 0.0 {
            self.sqrt()
        } else {
            Self::zero()
        }
    }
}

macro_rules! impl_real_float {
    ($t:ty) => {
        impl Real for $t {
            const EPSILON: f64 = <$t>::EPSILON as f64;
            #[inline]
            fn from_f64(value: f64) -> Self {
                value as $t
            }
            #[inline]
            fn re(self) -> f64 {
                self as f64
            }
            #[inline]
            fn sqrt(self) -> Self {
                <$t>::sqrt(self)
            }
            #[inline]
            fn abs(self) -> Self {
                <$t>::abs(self)
            }
            #[inline]
            fn sin(self) -> Self {
                <$t>::sin(self)
            }
            #[inline]
            fn cos(self) -> Self {
                <$t>::cos(self)
            }
            #[inline]
            fn exp(self) -> Self {
                <$t>::exp(self)
            }
            #[inline]
            fn ln(self) -> Self {
                <$t>::ln(self)
            }
            #[inline]
            fn atan2(self, x: Self) -> Self {
                <$t>::atan2(self, x)
            }
            #[inline]
            fn is_finite(self) -> bool {
                <$t>::is_finite(self)
            }
        }
    };
}

impl_real_float!(f32);
impl_real_float!(f64);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clamp_maps_nan_to_lower_bound_and_keeps_inside_values() {
        assert_eq!(f64::NAN.clamp_re(0.0, 1.0), 0.0);
        assert_eq!(2.0_f64.clamp_re(0.0, 1.0), 1.0);
        assert_eq!((-2.0_f32).clamp_re(0.0, 1.0), 0.0);
        assert_eq!(0.25_f64.clamp_re(0.0, 1.0), 0.25);
        assert_eq!((-1e-18_f64).sqrt_clamped(), 0.0);
        assert_eq!(4.0_f64.sqrt_clamped(), 2.0);
    }
}
