//! Stokes vectors, Mueller matrices and the rotator C(θ).
//!
//! Contract (docs/model.md §1): a Stokes vector `[s0, s1, s2, s3]` is expressed in a frame
//! (x, y, z) with z the propagation direction, observed looking back along z (Mitsuba 3
//! `mueller.h` convention). s1 > 0 is polarisation along x; s2 > 0 along +45° (x toward y).
//! [`Rotator`] is C(θ) of docs/model.md §1 "The rotator C(θ)", identical to Mitsuba's
//! `rotator(θ)`: it re-expresses a Stokes vector in a frame rotated by +θ about z. It is stored
//! as (cos 2θ, sin 2θ) so that frame-to-frame rotations never need an angle (no atan2).

use super::Real;

/// A Stokes vector in some frame (the holder names the frame).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Stokes<T> {
    /// Total intensity.
    pub s0: T,
    /// Horizontal (x) minus vertical (y) linear polarisation.
    pub s1: T,
    /// +45° minus −45° linear polarisation.
    pub s2: T,
    /// Circular polarisation (carried, never observed by the rig).
    pub s3: T,
}

impl<T: Real> Stokes<T> {
    /// From components.
    #[inline]
    pub const fn new(s0: T, s1: T, s2: T, s3: T) -> Self {
        Self { s0, s1, s2, s3 }
    }
    /// Unpolarised light of intensity `s0`.
    #[inline]
    pub fn unpolarised(s0: T) -> Self {
        Self::new(s0, T::zero(), T::zero(), T::zero())
    }
    /// Fully linearly polarised light of intensity `s0` at angle `angle_rad` from x toward y.
    #[inline]
    pub fn linear(s0: T, angle_rad: T) -> Self {
        let two = angle_rad + angle_rad;
        Self::new(s0, s0 * two.cos(), s0 * two.sin(), T::zero())
    }
    /// As an array.
    #[inline]
    pub fn to_array(self) -> [T; 4] {
        [self.s0, self.s1, self.s2, self.s3]
    }
    /// From an array.
    #[inline]
    pub fn from_array(s: [T; 4]) -> Self {
        Self::new(s[0], s[1], s[2], s[3])
    }
    /// Polarised intensity √(s1² + s2² + s3²).
    #[inline]
    pub fn polarised_intensity(self) -> T {
        (self.s1.sq() + self.s2.sq() + self.s3.sq()).sqrt_clamped()
    }
    /// Degree of linear polarisation √(s1² + s2²)/s0; 0 when s0 ≤ 0 (no light, no polarisation).
    #[inline]
    pub fn dolp(self) -> T {
        if self.s0.re() > 0.0 {
            (self.s1.sq() + self.s2.sq()).sqrt_clamped() / self.s0
        } else {
            T::zero()
        }
    }
    /// Angle of linear polarisation ½·atan2(s2, s1) in [0, π) (radians, from x toward y).
    /// Undefined for unpolarised light; returns 0 there.
    pub fn aolp_rad(self) -> T {
        if self.s1.re() == 0.0 && self.s2.re() == 0.0 {
            return T::zero();
        }
        let half = self.s2.atan2(self.s1) * T::from_f64(0.5);
        if half.re() < 0.0 {
            half + T::from_f64(core::f64::consts::PI)
        } else {
            half
        }
    }
    /// True when the vector is physically realisable within a tolerance:
    /// s0 ≥ −tol·scale and √(s1²+s2²+s3²) ≤ s0 + tol·scale, with scale = max(|s0|, 1e-300).
    pub fn is_physical(self, rel_tol: f64) -> bool {
        let s0 = self.s0.re();
        let p = (self.s1.re().powi(2) + self.s2.re().powi(2) + self.s3.re().powi(2)).sqrt();
        let scale = s0.abs().max(1e-300);
        s0.is_finite() && p.is_finite() && s0 >= -rel_tol * scale && p <= s0 + rel_tol * scale
    }
    /// Scales every component.
    #[inline]
    pub fn scale(self, k: T) -> Self {
        Self::new(self.s0 * k, self.s1 * k, self.s2 * k, self.s3 * k)
    }
}

impl<T: Real> core::ops::Add for Stokes<T> {
    type Output = Self;
    /// Component-wise sum (incoherent superposition).
    #[inline]
    fn add(self, o: Self) -> Self {
        Self::new(
            self.s0 + o.s0,
            self.s1 + o.s1,
            self.s2 + o.s2,
            self.s3 + o.s3,
        )
    }
}

/// A 4×4 Mueller matrix, row-major: `m[row][col]`, acting on column Stokes vectors.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Mueller<T> {
    /// Entries, row-major.
    pub m: [[T; 4]; 4],
}

impl<T: Real> Mueller<T> {
    /// The zero matrix (a perfect absorber).
    pub fn zero() -> Self {
        Self {
            m: [[T::zero(); 4]; 4],
        }
    }
    /// The identity.
    pub fn identity() -> Self {
        Self::diagonal([T::one(); 4])
    }
    /// A diagonal matrix.
    pub fn diagonal(d: [T; 4]) -> Self {
        let mut m = [[T::zero(); 4]; 4];
        for (i, v) in d.into_iter().enumerate() {
            m[i][i] = v;
        }
        Self { m }
    }
    /// An ideal linear polariser with its transmission axis at `angle_rad` from x toward y.
    pub fn linear_polariser(angle_rad: T) -> Self {
        let two = angle_rad + angle_rad;
        let (c, s) = (two.cos(), two.sin());
        let h = T::from_f64(0.5);
        let z = T::zero();
        Self {
            m: [
                [h, h * c, h * s, z],
                [h * c, h * c * c, h * c * s, z],
                [h * s, h * c * s, h * s * s, z],
                [z, z, z, z],
            ],
        }
    }
    /// The ideal depolariser diag(1, 0, 0, 0).
    pub fn depolariser() -> Self {
        Self::diagonal([T::one(), T::zero(), T::zero(), T::zero()])
    }
    /// The outer product u·vᵀ (a rank-one Mueller matrix).
    pub fn outer(u: [T; 4], v: [T; 4]) -> Self {
        let mut m = [[T::zero(); 4]; 4];
        for (row, &ui) in m.iter_mut().zip(u.iter()) {
            for (e, &vj) in row.iter_mut().zip(v.iter()) {
                *e = ui * vj;
            }
        }
        Self { m }
    }
    /// Matrix product `self · o` (apply `o` first).
    pub fn mul(&self, o: &Self) -> Self {
        let mut m = [[T::zero(); 4]; 4];
        for (i, row) in m.iter_mut().enumerate() {
            for (j, e) in row.iter_mut().enumerate() {
                let mut acc = self.m[i][0] * o.m[0][j];
                for k in 1..4 {
                    acc += self.m[i][k] * o.m[k][j];
                }
                *e = acc;
            }
        }
        Self { m }
    }
    /// `self · s`.
    pub fn apply(&self, s: Stokes<T>) -> Stokes<T> {
        let v = s.to_array();
        let row = |i: usize| {
            self.m[i][0] * v[0] + self.m[i][1] * v[1] + self.m[i][2] * v[2] + self.m[i][3] * v[3]
        };
        Stokes::new(row(0), row(1), row(2), row(3))
    }
    /// Entry-wise sum.
    pub fn add(&self, o: &Self) -> Self {
        let mut m = self.m;
        for (row, orow) in m.iter_mut().zip(o.m.iter()) {
            for (e, &oe) in row.iter_mut().zip(orow.iter()) {
                *e += oe;
            }
        }
        Self { m }
    }
    /// Multiplies every entry by `k`.
    pub fn scale(&self, k: T) -> Self {
        let mut m = self.m;
        for row in &mut m {
            for e in row {
                *e *= k;
            }
        }
        Self { m }
    }
    /// Transpose.
    pub fn transpose(&self) -> Self {
        let mut m = self.m;
        for (i, row) in m.iter_mut().enumerate() {
            for (j, e) in row.iter_mut().enumerate() {
                *e = self.m[j][i];
            }
        }
        Self { m }
    }
    /// The linear (upper-left 3×3) block: what the rig observes (docs/model.md §1 "Scope: the
    /// linear block").
    pub fn linear3(&self) -> [[T; 3]; 3] {
        let mut b = [[T::zero(); 3]; 3];
        for (i, row) in b.iter_mut().enumerate() {
            row.copy_from_slice(&self.m[i][..3]);
        }
        b
    }
    /// Real parts as `f64`, row-major.
    pub fn re(&self) -> [[f64; 4]; 4] {
        self.m.map(|row| row.map(Real::re))
    }
    /// True when every entry (and derivative) is finite.
    pub fn is_finite(&self) -> bool {
        self.m.iter().flatten().all(|e| e.is_finite())
    }
}

/// The rotator C(θ) (docs/model.md §1 "The rotator C(θ)"), stored as (cos 2θ, sin 2θ).
///
/// ```text
/// C(θ) = | 1    0      0     0 |
///        | 0  cos2θ  sin2θ   0 |
///        | 0 −sin2θ  cos2θ   0 |
///        | 0    0      0     1 |
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rotator<T> {
    /// cos 2θ.
    pub cos2: T,
    /// sin 2θ.
    pub sin2: T,
}

impl<T: Real> Rotator<T> {
    /// C(0).
    pub fn identity() -> Self {
        Self {
            cos2: T::one(),
            sin2: T::zero(),
        }
    }
    /// C(θ) for an angle in radians.
    pub fn from_angle(theta_rad: T) -> Self {
        let two = theta_rad + theta_rad;
        Self {
            cos2: two.cos(),
            sin2: two.sin(),
        }
    }
    /// C(θ) for the angle θ of the planar vector (c, s) = k·(cos θ, sin θ), k > 0, without
    /// trigonometry: cos2θ = (c² − s²)/(c² + s²), sin2θ = 2cs/(c² + s²).
    /// Returns `None` when c² + s² ≤ `min_norm_sq` (angle undefined).
    pub fn from_direction(c: T, s: T, min_norm_sq: f64) -> Option<Self> {
        // Decide in f64 on the real parts (no underflow for f32 inputs), then rescale by the
        // larger component so that c² + s² ∈ [1, 2] and its reciprocal cannot overflow.
        let n2 = c.re() * c.re() + s.re() * s.re();
        if !(n2.is_finite() && n2 > min_norm_sq && n2 > 0.0) {
            return None;
        }
        let m = c.abs().max_re(s.abs());
        let (c, s) = (c / m, s / m);
        let inv = (c.sq() + s.sq()).recip();
        Some(Self {
            cos2: (c.sq() - s.sq()) * inv,
            sin2: (c * s + c * s) * inv,
        })
    }
    /// C(−θ) = C(θ)⁻¹.
    pub fn inverse(self) -> Self {
        Self {
            cos2: self.cos2,
            sin2: -self.sin2,
        }
    }
    /// C(θ1 + θ2) = C(θ1)·C(θ2) (rotations about one axis commute).
    pub fn then(self, o: Self) -> Self {
        Self {
            cos2: self.cos2 * o.cos2 - self.sin2 * o.sin2,
            sin2: self.sin2 * o.cos2 + self.cos2 * o.sin2,
        }
    }
    /// The 4×4 Mueller matrix.
    pub fn mueller(self) -> Mueller<T> {
        let (o, z) = (T::one(), T::zero());
        Mueller {
            m: [
                [o, z, z, z],
                [z, self.cos2, self.sin2, z],
                [z, -self.sin2, self.cos2, z],
                [z, z, z, o],
            ],
        }
    }
    /// C(θ)·s.
    pub fn apply(self, s: Stokes<T>) -> Stokes<T> {
        Stokes::new(
            s.s0,
            self.cos2 * s.s1 + self.sin2 * s.s2,
            -self.sin2 * s.s1 + self.cos2 * s.s2,
            s.s3,
        )
    }
    /// Row vector v·C(θ) (used for rank-one lobes: the row acts on the incoming Stokes vector).
    pub fn apply_row(self, v: [T; 4]) -> [T; 4] {
        [
            v[0],
            v[1] * self.cos2 - v[2] * self.sin2,
            v[1] * self.sin2 + v[2] * self.cos2,
            v[3],
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::f64::consts::PI;

    #[test]
    fn rotator_matches_mitsuba_test_value() {
        // docs/model.md §1 "The rotator C(θ)": C(45°)·[1,1,0,0] = [1,0,−1,0].
        let s = Rotator::from_angle(PI / 4.0).apply(Stokes::new(1.0, 1.0, 0.0, 0.0));
        assert!((s.s1).abs() < 1e-15 && (s.s2 + 1.0).abs() < 1e-15);
        let m = Rotator::from_angle(PI / 4.0)
            .mueller()
            .apply(Stokes::new(1.0, 1.0, 0.0, 0.0));
        assert_eq!(m, s);
    }

    #[test]
    fn rotation_shifts_aolp_and_keeps_dolp() {
        // docs/model.md §8 "Camera channel identities": AoLP(C(θ)s) = AoLP(s) − θ (mod π);
        // DoLP invariant.
        let s = Stokes::linear(2.0, 0.3) + Stokes::unpolarised(1.0);
        for k in 0..12 {
            let theta = -1.4 + 0.27 * k as f64;
            let r = Rotator::from_angle(theta).apply(s);
            let mut d = (r.aolp_rad() - (s.aolp_rad() - theta)).rem_euclid(PI);
            if d > PI / 2.0 {
                d -= PI;
            }
            assert!(d.abs() < 1e-12, "theta {theta}: {d}");
            assert!((r.dolp() - s.dolp()).abs() < 1e-14);
        }
    }

    #[test]
    fn rotator_algebra() {
        let a = Rotator::from_angle(0.4_f64);
        let b = Rotator::from_angle(-1.1_f64);
        let ab = a.then(b);
        let c = Rotator::from_angle(-0.7_f64);
        assert!((ab.cos2 - c.cos2).abs() < 1e-15 && (ab.sin2 - c.sin2).abs() < 1e-15);
        let id = a.then(a.inverse());
        assert!((id.cos2 - 1.0).abs() < 1e-15 && id.sin2.abs() < 1e-15);
        let d = Rotator::from_direction(0.3_f64.cos() * 5.0, 0.3_f64.sin() * 5.0, 0.0).unwrap();
        let e = Rotator::from_angle(0.3_f64);
        assert!((d.cos2 - e.cos2).abs() < 1e-15 && (d.sin2 - e.sin2).abs() < 1e-15);
        assert!(Rotator::<f64>::from_direction(0.0, 0.0, 0.0).is_none());
        // Row action equals vᵀ·C.
        let v = [1.0, 0.2, -0.5, 0.1];
        let m = a.mueller();
        let row = a.apply_row(v);
        for (j, r) in row.iter().enumerate() {
            let want: f64 = (0..4).map(|k| v[k] * m.m[k][j]).sum();
            assert!((r - want).abs() < 1e-15);
        }
    }

    #[test]
    fn malus_law_through_two_polarisers() {
        // Unpolarised → polariser at a → polariser at b: I = ½ cos²(a − b).
        for k in 0..20 {
            let (a, b) = (0.1 * k as f64, -0.37 * k as f64);
            let out = Mueller::linear_polariser(b)
                .mul(&Mueller::linear_polariser(a))
                .apply(Stokes::unpolarised(1.0));
            assert!((out.s0 - 0.5 * (a - b).cos().powi(2)).abs() < 1e-14);
        }
    }
}
