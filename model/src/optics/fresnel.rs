//! Fresnel terms of a dielectric interface (light arriving from air), with signed amplitudes.
//!
//! Contract (docs/model.md §2; Born & Wolf, *Principles of Optics*, §1.5.2, Verdet sign for r_p;
//! Mitsuba 3 `fresnel.h` / `mueller.h` current convention):
//! ```text
//! q   = η·c_t = √(η² − 1 + c²)                 (c = cos θ, η ≥ 1)
//! r_s = (c − q)/(c + q)          = −(η² − 1)/(c + q)²
//! r_p = (η²c − q)/(η²c + q)       = (η² − 1)((η² + 1)c² − 1)/(η²c + q)²
//! T_s = 4cq/(c + q)²             T_p = 4η²cq/(η²c + q)²     T× = 4ηcq/((c + q)(η²c + q))
//! R± = (R_s ± R_p)/2   R× = r_s·r_p   T± = (T_s ± T_p)/2
//! ```
//! The right-hand forms (used) multiply through by the conjugate denominators. They are
//! algebraically identical to the textbook ones but have no cancellation
//! (T = 1 − R is never formed by subtraction, η² − 1 is formed as (η−1)(η+1)) and are smooth
//! everywhere in c ∈ [0, 1], η ≥ 1, including through Brewster's angle: R× = r_s·r_p is the
//! signed product, never ∓√(R_s R_p) (whose derivative is infinite at R_p = 0).
//!
//! Clamps: c is clamped to [0, 1]; η to ≥ 1 (this model has no total internal reflection,
//! docs/model.md §2; callers validate η). At the single point η = 1, c = 0 the amplitudes are
//! 0/0; they are defined as 0 (no interface, as Mitsuba does for η = 1).

use super::{Mueller, Real};

/// All Fresnel quantities at one angle for a dielectric of relative index η.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FresnelTerms<T> {
    /// s amplitude r_s (≤ 0).
    pub r_s: T,
    /// p amplitude r_p, Verdet convention (> 0 below Brewster, < 0 above).
    pub r_p: T,
    /// s power transmittance T_s = 1 − r_s².
    pub t_s: T,
    /// p power transmittance T_p = 1 − r_p².
    pub t_p: T,
    /// R− = (R_s − R_p)/2 = 2(η² − 1)² c q sin²θ / ((c + q)(η²c + q))², formed without
    /// cancellation so that R− ≥ 0 and T− = −R− ≤ 0 hold exactly in floating point.
    pub r_minus: T,
    /// √(T_s T_p) (unused by the depolarising diffuse path, kept for completeness).
    pub t_cross: T,
}

impl<T: Real> FresnelTerms<T> {
    /// Fresnel terms at incidence cosine `cos_theta` (to the interface normal) for relative
    /// index `eta` (air → material). Exit transmission (material → air) at exterior angle θ_o
    /// has the same power transmittances (reciprocity, docs/model.md §2): call this with cos θ_o.
    pub fn dielectric(cos_theta: T, eta: T) -> Self {
        let Some(i) = Interface::new(cos_theta, eta) else {
            // η = 1 at c = 0: no interface.
            let (z, o) = (T::zero(), T::one());
            return Self {
                r_s: z,
                r_p: z,
                t_s: o,
                t_p: o,
                r_minus: z,
                t_cross: o,
            };
        };
        let (t_s, t_p) = i.transmittances();
        Self {
            r_s: i.r_s(),
            r_p: i.r_p(),
            t_s,
            t_p,
            r_minus: i.r_minus(),
            t_cross: (T::from_f64(4.0) * i.eta * i.c / i.den_s) * (i.q / i.den_p),
        }
    }

    /// Only the reflection's Mueller entries (R+, R−, R×) of [`FresnelTerms::dielectric`], same
    /// formulas and clamps, for callers that need nothing else (the microfacet reflection).
    pub fn reflection_terms(cos_theta: T, eta: T) -> [T; 3] {
        let Some(i) = Interface::new(cos_theta, eta) else {
            return [T::zero(); 3];
        };
        let (r_s, r_p) = (i.r_s(), i.r_p());
        [
            (r_s.sq() + r_p.sq()) * T::from_f64(0.5),
            i.r_minus(),
            r_s * r_p,
        ]
    }

    /// Only the transmission's T+ and T− of [`FresnelTerms::dielectric`], same formulas and
    /// clamps (the diffuse lobe's entry and exit).
    pub fn transmission_terms(cos_theta: T, eta: T) -> [T; 2] {
        let Some(i) = Interface::new(cos_theta, eta) else {
            return [T::one(), T::zero()];
        };
        let (t_s, t_p) = i.transmittances();
        [(t_s + t_p) * T::from_f64(0.5), -i.r_minus()]
    }
    /// R_s = r_s².
    pub fn reflectance_s(&self) -> T {
        self.r_s.sq()
    }
    /// R_p = r_p².
    pub fn reflectance_p(&self) -> T {
        self.r_p.sq()
    }
    /// R+ = (R_s + R_p)/2: reflectance for unpolarised light.
    pub fn r_plus(&self) -> T {
        (self.r_s.sq() + self.r_p.sq()) * T::from_f64(0.5)
    }
    /// R− = (R_s − R_p)/2 ≥ 0.
    pub fn r_minus(&self) -> T {
        self.r_minus
    }
    /// R× = r_s·r_p: negative below Brewster, 0 at θ_B = atan η, positive above, → 1 at grazing.
    pub fn r_cross(&self) -> T {
        self.r_s * self.r_p
    }
    /// T+ = (T_s + T_p)/2.
    pub fn t_plus(&self) -> T {
        (self.t_s + self.t_p) * T::from_f64(0.5)
    }
    /// T− = (T_s − T_p)/2 ≤ 0 (transmitted light is p-rich).
    pub fn t_minus(&self) -> T {
        -self.r_minus
    }
    /// F^R in the local (s, p) frame (docs/model.md §2).
    pub fn reflection_mueller(&self) -> Mueller<T> {
        symmetric_block(self.r_plus(), self.r_minus(), self.r_cross())
    }
    /// F^T in the local (s, p) frame (docs/model.md §2).
    pub fn transmission_mueller(&self) -> Mueller<T> {
        symmetric_block(self.t_plus(), self.t_minus(), self.t_cross)
    }
}

/// The quantities every Fresnel term is formed from (module doc), with the clamps applied:
/// c ∈ [0, 1], η ≥ 1, q = √(η² − 1 + c²) and the two denominators. `None` at the single point
/// η = 1, c = 0 (no interface).
struct Interface<T> {
    c: T,
    eta: T,
    eta_sq: T,
    eta_sq_m1: T,
    q: T,
    den_s: T,
    den_p: T,
}

impl<T: Real> Interface<T> {
    fn new(cos_theta: T, eta: T) -> Option<Self> {
        let c = cos_theta.clamp_re(0.0, 1.0);
        let eta = eta.max_re(T::one());
        let eta_sq = eta.sq();
        let eta_sq_m1 = (eta - T::one()) * (eta + T::one());
        // q = √(η² − 1 + c²); where the radicand underflows (η = 1, c² below the f32 range)
        // q = c exactly.
        let q_sq = eta_sq_m1 + c.sq();
        let q = if q_sq.re() > 0.0 { q_sq.sqrt() } else { c };
        let den_s = c + q;
        let den_p = eta_sq * c + q;
        (den_s.re() > 0.0 && den_p.re() > 0.0).then_some(Self {
            c,
            eta,
            eta_sq,
            eta_sq_m1,
            q,
            den_s,
            den_p,
        })
    }

    // Every quotient is formed as a product of ratios, never as x/(den·den): with η → 1 and
    // c → 0 both denominators are tiny and their product would underflow in f32.

    fn r_s(&self) -> T {
        -(self.eta_sq_m1 / self.den_s) / self.den_s
    }

    fn r_p(&self) -> T {
        let one = T::one();
        (self.eta_sq_m1 / self.den_p) * (((self.eta_sq + one) * self.c.sq() - one) / self.den_p)
    }

    fn transmittances(&self) -> (T, T) {
        let four = T::from_f64(4.0);
        (
            (four * self.c / self.den_s) * (self.q / self.den_s),
            (four * self.eta_sq * self.c / self.den_p) * (self.q / self.den_p),
        )
    }

    /// R− = ½(r_s − r_p)(r_s + r_p) with r_s − r_p = −2cq·u, r_s + r_p = −2 sin²θ·u,
    /// u = (η² − 1)/((c + q)(η²c + q)).
    fn r_minus(&self) -> T {
        let one = T::one();
        let sin_sq = (one - self.c) * (one + self.c);
        let u = self.eta_sq_m1 / self.den_s / self.den_p;
        T::from_f64(2.0) * self.c * self.q * sin_sq * u.sq()
    }
}

/// The matrix [[a, b, 0, 0], [b, a, 0, 0], [0, 0, c, 0], [0, 0, 0, c]].
pub(crate) fn symmetric_block<T: Real>(a: T, b: T, c: T) -> Mueller<T> {
    let z = T::zero();
    Mueller {
        m: [[a, b, z, z], [b, a, z, z], [z, z, c, z], [z, z, z, c]],
    }
}

/// Brewster's angle atan η (radians).
pub fn brewster_angle_rad(eta: f64) -> f64 {
    eta.atan()
}

/// Normal-incidence reflectance R(0) = ((η − 1)/(η + 1))².
pub fn normal_incidence_reflectance<T: Real>(eta: T) -> T {
    ((eta - T::one()) / (eta + T::one())).sq()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at_deg(theta_deg: f64, eta: f64) -> FresnelTerms<f64> {
        FresnelTerms::dielectric(theta_deg.to_radians().cos(), eta)
    }

    #[test]
    fn reproduces_the_eta_1_5_table() {
        // docs/model.md §8 "Fresnel and diffuse DoP values": θ, r_s, r_p, R_s, R_p, R+, R−, T+,
        // T−, R×.
        let table = [
            [0.0, -0.2, 0.2, 0.04, 0.04, 0.04, 0.0, 0.96, 0.0, -0.04],
            [
                30.0, -0.240408, 0.158900, 0.057796, 0.025249, 0.041523, 0.016273, 0.958477,
                -0.016273, -0.038201,
            ],
            [
                45.0, -0.303337, 0.092013, 0.092013, 0.008466, 0.050240, 0.041773, 0.949760,
                -0.041773, -0.027911,
            ],
            [
                60.0, -0.420204, -0.042449, 0.176571, 0.001802, 0.089187, 0.087385, 0.910813,
                -0.087385, 0.017837,
            ],
        ];
        for row in table {
            let f = at_deg(row[0], 1.5);
            let got = [
                f.r_s,
                f.r_p,
                f.reflectance_s(),
                f.reflectance_p(),
                f.r_plus(),
                f.r_minus(),
                f.t_plus(),
                f.t_minus(),
                f.r_cross(),
            ];
            for (g, w) in got.iter().zip(&row[1..]) {
                assert!((g - w).abs() < 6e-7, "θ={}: {got:?} vs {row:?}", row[0]);
            }
        }
        // r_p = r_s² at 45° for any η (same section).
        for eta in [1.2, 1.5, 2.7] {
            let f = at_deg(45.0, eta);
            assert!((f.r_p - f.r_s * f.r_s).abs() < 1e-15);
        }
    }

    #[test]
    fn normal_incidence_brewster_grazing_and_energy() {
        for eta in [1.0, 1.0 + 1e-9, 1.3, 1.5, 1.7, 2.3, 3.0] {
            let r0: f64 = normal_incidence_reflectance(eta);
            let m = FresnelTerms::dielectric(1.0, eta).reflection_mueller();
            let want = Mueller::diagonal([r0, r0, -r0, -r0]);
            for i in 0..4 {
                for j in 0..4 {
                    assert!((m.m[i][j] - want.m[i][j]).abs() < 1e-15, "η={eta}");
                }
            }
            // Brewster: R_p = 0, R× = 0, fully s-polarised reflection; sign change across it.
            let tb = brewster_angle_rad(eta);
            let fb = FresnelTerms::dielectric(tb.cos(), eta);
            assert!(fb.reflectance_p() < 1e-30 && fb.r_cross().abs() < 1e-15);
            assert!((fb.r_plus() - fb.r_minus()).abs() < 1e-15);
            if eta > 1.01 {
                let below = FresnelTerms::dielectric((tb - 1e-6).cos(), eta).r_cross();
                let above = FresnelTerms::dielectric((tb + 1e-6).cos(), eta).r_cross();
                assert!(below < 0.0 && above > 0.0, "η={eta}: {below} {above}");
                // Grazing reflects everything: F^R = identity.
                let g = FresnelTerms::dielectric(0.0, eta).reflection_mueller();
                let id = Mueller::<f64>::identity();
                assert!(
                    g.m.iter()
                        .flatten()
                        .zip(id.m.iter().flatten())
                        .all(|(a, b)| (a - b).abs() < 1e-15)
                );
            }
            // T = 1 − R at many angles.
            for k in 0..=100 {
                let f = FresnelTerms::dielectric(k as f64 / 100.0, eta);
                assert!((f.t_s + f.reflectance_s() - 1.0).abs() < 1e-14);
                assert!((f.t_p + f.reflectance_p() - 1.0).abs() < 1e-14);
                assert!((f.t_cross - (f.t_s * f.t_p).sqrt()).abs() < 1e-14);
                assert!(f.r_minus() >= 0.0 && f.t_minus() <= 0.0);
                let r_minus_naive = 0.5 * (f.reflectance_s() - f.reflectance_p());
                assert!((f.r_minus() - r_minus_naive).abs() < 1e-15);
                assert!((f.t_minus() - 0.5 * (f.t_s - f.t_p)).abs() < 1e-15);
            }
        }
        // Brewster value at η = 1.5: the 2×2 block is R_s/2 = 0.0739645.
        let fb = FresnelTerms::dielectric(brewster_angle_rad(1.5).cos(), 1.5).reflection_mueller();
        for (i, j) in [(0, 0), (0, 1), (1, 0), (1, 1)] {
            assert!((fb.m[i][j] - 0.0739645).abs() < 1e-7);
        }
        // Normal-incidence transmission F^T = 0.96·I.
        let t = FresnelTerms::dielectric(1.0, 1.5).transmission_mueller();
        for i in 0..4 {
            assert!((t.m[i][i] - 0.96).abs() < 1e-15);
        }
    }

    #[test]
    fn eta_one_at_grazing_is_finite_and_transparent() {
        let f = FresnelTerms::dielectric(0.0, 1.0);
        assert_eq!((f.r_s, f.r_p, f.t_s), (0.0, 0.0, 1.0));
        let g = FresnelTerms::<f32>::dielectric(0.0, 1.0);
        assert!(g.r_cross().is_finite());
    }
}
