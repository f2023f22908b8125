//! Forward-mode automatic differentiation: `Dual<N>` = value + N partial derivatives.
//!
//! Contract: `Dual<N>` implements [`Real`], so every optics function evaluated on duals returns
//! its value together with the exact derivatives (to rounding) with respect to the N seeded
//! inputs. Seed input `k` with [`Dual::variable`]`(value, k)`; constants have zero partials.
//! No external AD crate: the rules are the textbook chain rule per operation.
//!
//! One documented convention: `sqrt` at exactly 0 has derivative 0 (the true one-sided
//! derivative is infinite). Model code never relies on it except at isolated corner points
//! (η = 1 at grazing), where it keeps the Jacobian finite.

use core::ops::{Add, AddAssign, Div, DivAssign, Mul, MulAssign, Neg, Sub, SubAssign};

use super::Real;

/// A dual number with `N` partial derivatives, over `f64`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Dual<const N: usize> {
    /// The value.
    pub re: f64,
    /// ∂value/∂input_k for k in 0..N.
    pub du: [f64; N],
}

impl<const N: usize> Dual<N> {
    /// A constant: value `re`, all partials zero.
    #[inline]
    pub const fn constant(re: f64) -> Self {
        Self { re, du: [0.0; N] }
    }

    /// Independent variable number `index` (partial 1 in slot `index`). An out-of-range index
    /// yields a constant, so seeding never panics.
    #[inline]
    pub fn variable(re: f64, index: usize) -> Self {
        let mut du = [0.0; N];
        if let Some(slot) = du.get_mut(index) {
            *slot = 1.0;
        }
        Self { re, du }
    }

    /// Applies a scalar function with value `f` and derivative `df` at `self.re` (chain rule).
    #[inline]
    fn chain(self, f: f64, df: f64) -> Self {
        let mut du = self.du;
        for d in &mut du {
            *d *= df;
        }
        Self { re: f, du }
    }
}

impl<const N: usize> Add for Dual<N> {
    type Output = Self;
    #[inline]
    fn add(mut self, rhs: Self) -> Self {
        self.re += rhs.re;
        for (a, b) in self.du.iter_mut().zip(rhs.du) {
            *a += b;
        }
        self
    }
}

impl<const N: usize> Sub for Dual<N> {
    type Output = Self;
    #[inline]
    fn sub(mut self, rhs: Self) -> Self {
        self.re -= rhs.re;
        for (a, b) in self.du.iter_mut().zip(rhs.du) {
            *a -= b;
        }
        self
    }
}

impl<const N: usize> Mul for Dual<N> {
    type Output = Self;
    #[inline]
    fn mul(self, rhs: Self) -> Self {
        let mut du = [0.0; N];
        for ((d, a), b) in du.iter_mut().zip(self.du).zip(rhs.du) {
            *d = a * rhs.re + self.re * b;
        }
        Self {
            re: self.re * rhs.re,
            du,
        }
    }
}

impl<const N: usize> Div for Dual<N> {
    type Output = Self;
    #[inline]
    fn div(self, rhs: Self) -> Self {
        let inv = 1.0 / rhs.re;
        let q = self.re * inv;
        let mut du = [0.0; N];
        for ((d, a), b) in du.iter_mut().zip(self.du).zip(rhs.du) {
            *d = (a - q * b) * inv;
        }
        Self { re: q, du }
    }
}

impl<const N: usize> Neg for Dual<N> {
    type Output = Self;
    #[inline]
    fn neg(mut self) -> Self {
        self.re = -self.re;
        for d in &mut self.du {
            *d = -*d;
        }
        self
    }
}

macro_rules! assign_op {
    ($tr:ident, $f:ident, $op:tt) => {
        impl<const N: usize> $tr for Dual<N> {
            #[inline]
            fn $f(&mut self, rhs: Self) {
                *self = *self $op rhs;
            }
        }
    };
}
assign_op!(AddAssign, add_assign, +);
assign_op!(SubAssign, sub_assign, -);
assign_op!(MulAssign, mul_assign, *);
assign_op!(DivAssign, div_assign, /);

macro_rules! scalar_op {
    ($tr:ident, $f:ident, $body:expr) => {
        impl<const N: usize> $tr<f64> for Dual<N> {
            type Output = Self;
            /// Mixed operation with an `f64` constant.
            #[inline]
            fn $f(self, k: f64) -> Self {
                let g: fn(Self, f64) -> Self = $body;
                g(self, k)
            }
        }
    };
}
scalar_op!(Add, add, |mut a, k| {
    a.re += k;
    a
});
scalar_op!(Sub, sub, |mut a, k| {
    a.re -= k;
    a
});
scalar_op!(Mul, mul, |a, k| a.chain(a.re * k, k));
scalar_op!(Div, div, |a, k| a.chain(a.re / k, 1.0 / k));

impl<const N: usize> Real for Dual<N> {
    const EPSILON: f64 = f64::EPSILON;

    #[inline]
    fn from_f64(value: f64) -> Self {
        Self::constant(value)
    }
    #[inline]
    fn re(self) -> f64 {
        self.re
    }
    #[inline]
    fn sqrt(self) -> Self {
        let r = self.re.sqrt();
        // Convention: derivative 0 at exactly 0 (documented in the module header).
        let dr = if r > 0.0 { 0.5 / r } else { 0.0 };
        self.chain(r, dr)
    }
    #[inline]
    fn abs(self) -> Self {
        if self.re < 0.0 { -self } else { self }
    }
    #[inline]
    fn sin(self) -> Self {
        self.chain(self.re.sin(), self.re.cos())
    }
    #[inline]
    fn cos(self) -> Self {
        self.chain(self.re.cos(), -self.re.sin())
    }
    #[inline]
    fn exp(self) -> Self {
        let e = self.re.exp();
        self.chain(e, e)
    }
    #[inline]
    fn ln(self) -> Self {
        self.chain(self.re.ln(), 1.0 / self.re)
    }
    #[inline]
    fn atan2(self, x: Self) -> Self {
        // d atan2(y, x) = (x dy − y dx) / (x² + y²)
        let r2 = x.re * x.re + self.re * self.re;
        let inv = if r2 > 0.0 { 1.0 / r2 } else { 0.0 };
        let mut du = [0.0; N];
        for ((d, dy), dx) in du.iter_mut().zip(self.du).zip(x.du) {
            *d = (x.re * dy - self.re * dx) * inv;
        }
        Self {
            re: self.re.atan2(x.re),
            du,
        }
    }
    #[inline]
    fn is_finite(self) -> bool {
        self.re.is_finite() && self.du.iter().all(|d| d.is_finite())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    type D2 = Dual<2>;

    fn central<F: Fn(f64) -> f64>(f: F, x: f64) -> f64 {
        let h = 1e-6 * x.abs().max(1.0);
        (f(x + h) - f(x - h)) / (2.0 * h)
    }

    #[test]
    fn arithmetic_and_functions_match_central_differences() {
        let x0 = 0.7;
        let x = D2::variable(x0, 0);
        let y = D2::constant(1.3);
        let f =
            |x: D2| (x * x + y).sqrt() / (x.exp() - x.sin() * x.cos()) + (x + y).ln() - x.atan2(y);
        let g = |x: f64| {
            (x * x + 1.3).sqrt() / (x.exp() - x.sin() * x.cos()) + (x + 1.3).ln() - x.atan2(1.3)
        };
        let v = f(x);
        assert!((v.re - g(x0)).abs() < 1e-14);
        assert!(
            (v.du[0] - central(g, x0)).abs() < 1e-8,
            "{} vs {}",
            v.du[0],
            central(g, x0)
        );
        assert_eq!(v.du[1], 0.0);
    }

    #[test]
    fn two_variables_and_sqrt_at_zero_is_finite() {
        let a = D2::variable(2.0, 0);
        let b = D2::variable(3.0, 1);
        let p = a * b - a / b;
        assert!((p.du[0] - (3.0 - 1.0 / 3.0)).abs() < 1e-15);
        assert!((p.du[1] - (2.0 + 2.0 / 9.0)).abs() < 1e-15);
        let z = (a - a).sqrt();
        assert!(z.is_finite());
        assert_eq!(z.re, 0.0);
        assert_eq!(D2::variable(1.0, 7), D2::constant(1.0));
        assert_eq!((-a).abs().du[0], 1.0);
        let m = (a * 3.0 + 1.0 - 0.5) / 2.0;
        assert_eq!((m.re, m.du[0], m.du[1]), (3.25, 1.5, 0.0));
    }
}
