//! The coaxial 3×3 form of the pBRDF (docs/model.md §5): DS, SS, DPα, DPβ.
//!
//! Contract: for ω_i = ω_o (θ_i = θ_o = θ_h = θ, θ_d = 0) and the normal at azimuth φ in the
//! camera frame (α = sin2φ, β = cos2φ), the talk's matrix
//! ```text
//!     | DS + SS   −DPβ    DPα |       DS  = ρ_d T+² cosθ
//! P ≈ |  −DPβ      SS      0  |       SS  = R(0)(ρ_s D_s G_s + ρ_ss D_ss G_ss)/(4 cosθ)
//!     |  −DPα      0     −SS  |       DPα = ρ_d T− T+ cosθ · α,  DPβ = … · β
//! ```
//! which drops only the τ² = T−² terms of the exact rank-one diffuse lobe. With s_light =
//! [1, 1, 0]: I^d = DS, I^s = SS − DPβ, I^α = DPα. The bound on its difference from the full
//! model at the rig's 3.5° flash offset is measured by a test and stated in docs/model.md.

use super::frame::DIRECTION_EPS_SQ;
use super::fresnel::{FresnelTerms, normal_incidence_reflectance};
use super::measure::ObservationChannels;
use super::microfacet::microfacet_weight;
use super::pbrdf::PbrdfParams;
use super::{Frame, Mueller, Real, Vec3};

/// Coaxial geometry: cosθ of the normal to the (shared) view/light direction and the normal's
/// doubled azimuth in the camera frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CoaxialGeometry<T> {
    /// cosθ = n·ω_o, clamped to [0, 1].
    pub cos_theta: T,
    /// α = sin 2φ (φ from image right toward image up).
    pub alpha: T,
    /// β = cos 2φ.
    pub beta: T,
}

impl<T: Real> CoaxialGeometry<T> {
    /// From the normal expressed in the camera frame (x right, y up, z toward camera).
    /// When the normal points straight at the camera the azimuth is undefined; α = 0, β = 1 is
    /// used there (T− = 0, so DP = 0 and the choice has no effect).
    ///
    /// The normal may have any non-zero length: it is normalised here (as in
    /// [`crate::optics::pbrdf::Geometry::new`]), so derivatives are those of the unit normal. A
    /// zero normal gives cosθ = 0 (no light returned).
    pub fn from_normal_in_camera(n_cam: Vec3<T>) -> Self {
        let n_cam = n_cam
            .normalized_or_none(DIRECTION_EPS_SQ)
            .unwrap_or(Vec3::new(T::zero(), T::zero(), T::zero()));
        let (a, b) = (n_cam.x, n_cam.y);
        let r2 = a.sq() + b.sq();
        let (alpha, beta) = if r2.re() > DIRECTION_EPS_SQ {
            ((a * b + a * b) / r2, (a.sq() - b.sq()) / r2)
        } else {
            (T::zero(), T::one())
        };
        Self {
            cos_theta: n_cam.z.clamp_re(0.0, 1.0),
            alpha,
            beta,
        }
    }
    /// From a world-space unit normal and the camera frame.
    pub fn from_world(normal: Vec3<T>, camera_frame: &Frame<T>) -> Self {
        Self::from_normal_in_camera(camera_frame.to_local(normal))
    }
}

/// The four coaxial terms of one colour channel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CoaxialTerms<T> {
    /// Diffuse shading DS.
    pub ds: T,
    /// Specular + single scattering SS.
    pub ss: T,
    /// Diffuse polarisation, sine part DPα (sign of T−, ≤ 0 for α > 0).
    pub dp_alpha: T,
    /// Diffuse polarisation, cosine part DPβ.
    pub dp_beta: T,
}

impl<T: Real> CoaxialTerms<T> {
    /// The approximate linear 3×3 block (talk form).
    pub fn linear3(&self) -> [[T; 3]; 3] {
        let z = T::zero();
        [
            [self.ds + self.ss, -self.dp_beta, self.dp_alpha],
            [-self.dp_beta, self.ss, z],
            [-self.dp_alpha, z, -self.ss],
        ]
    }
    /// The 4×4 version: a 4th row/column with −SS at (3, 3).
    pub fn mueller(&self) -> Mueller<T> {
        let b = self.linear3();
        let z = T::zero();
        Mueller {
            m: [
                [b[0][0], b[0][1], b[0][2], z],
                [b[1][0], b[1][1], b[1][2], z],
                [b[2][0], b[2][1], b[2][2], z],
                [z, z, z, -self.ss],
            ],
        }
    }
    /// Observation channels for the rig's flash (s_light = [1, 1, 0]).
    pub fn observation(&self) -> ObservationChannels<T> {
        ObservationChannels {
            diffuse: self.ds,
            specular: self.ss - self.dp_beta,
            alpha: self.dp_alpha,
        }
    }
}

/// SS per channel: R(0)·(ρ_s D_s G_s + ρ_ss D_ss G_ss)/(4 cosθ) at θ_h = θ_i = θ_o = θ.
pub fn specular_term<T: Real>(cos_theta: T, p: &PbrdfParams<T>) -> [T; 3] {
    let (ss, s) = unit_specular_terms(cos_theta, p.eta, p.sigma_s, p.sigma_ss);
    p.rho_ss.map(|r| p.rho_s * s + r * ss)
}

/// The two reflection lobes of [`specular_term`] with unit albedo, (single scattering at σ_ss,
/// specular at σ_s): `specular_term = ρ_ss,c·ss + ρ_s·s`, each lobe evaluated once.
pub fn unit_specular_terms<T: Real>(cos_theta: T, eta: T, sigma_s: T, sigma_ss: T) -> (T, T) {
    let c = cos_theta.clamp_re(0.0, 1.0);
    let r0 = normal_incidence_reflectance(eta.max_re(T::one()));
    (
        r0 * microfacet_weight(c, c, c, sigma_ss),
        r0 * microfacet_weight(c, c, c, sigma_s),
    )
}

/// The coaxial terms per RGB channel.
pub fn terms<T: Real>(g: &CoaxialGeometry<T>, p: &PbrdfParams<T>) -> [CoaxialTerms<T>; 3] {
    let c = g.cos_theta;
    let f = FresnelTerms::dielectric(c, p.eta);
    let (tp, tm) = (f.t_plus(), f.t_minus());
    let ss = specular_term(c, p);
    core::array::from_fn(|k| {
        let base = p.rho_d[k] * c;
        let dp = base * tm * tp;
        CoaxialTerms {
            ds: base * tp * tp,
            ss: ss[k],
            dp_alpha: dp * g.alpha,
            dp_beta: dp * g.beta,
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn worked_example_of_optics_md() {
        // docs/model.md §8 "Coaxial worked example": η = 1.5, θ = 45°, φ = 30°, ρ_d = 0.5,
        // SS = 0.02, s_light = [1, 1, 0].
        let (t, phi) = (45f64.to_radians(), 30f64.to_radians());
        let n = Vec3::new(t.sin() * phi.cos(), t.sin() * phi.sin(), t.cos());
        let g = CoaxialGeometry::from_normal_in_camera(n);
        let p = PbrdfParams {
            eta: 1.5,
            sigma_s: 0.2,
            sigma_ss: 0.5,
            rho_s: 0.0,
            rho_ss: [0.0; 3],
            rho_d: [0.5; 3],
        };
        let mut k = terms(&g, &p)[0];
        k.ss = 0.02;
        assert!((k.ds - 0.318921).abs() < 1e-6);
        assert!((k.dp_alpha + 0.012148).abs() < 1e-6);
        assert!((k.dp_beta + 0.007014).abs() < 1e-6);
        let dop = (k.dp_alpha.hypot(k.dp_beta)) / k.ds;
        assert!((dop - 0.043983).abs() < 1e-6);
        let m = k.linear3();
        let s = [0, 1, 2].map(|r| m[r][0] + m[r][1]);
        let i = [
            0.5 * (s[0] + s[1]),
            0.5 * (s[0] + s[2]),
            0.5 * (s[0] - s[1]),
            0.5 * (s[0] - s[2]),
        ];
        for (got, want) in i.iter().zip([0.186474, 0.179041, 0.159460, 0.166893]) {
            assert!((got - want).abs() < 1e-6, "{i:?}");
        }
        let o = k.observation();
        assert!((o.diffuse - 0.318921).abs() < 1e-6);
        assert!((o.specular - 0.027014).abs() < 1e-6);
        assert!((o.alpha + 0.012148).abs() < 1e-6);
        assert!((2.0 * i[2] - o.diffuse).abs() < 1e-12 && (i[0] - i[2] - o.specular).abs() < 1e-12);
        assert!((i[3] - i[1] - o.alpha).abs() < 1e-12);
        // AoLP of the diffuse-only polarisation (s1 − SS, s2) is the normal azimuth.
        let aolp = 0.5 * s[2].atan2(s[1] - k.ss);
        assert!((aolp.to_degrees() - 30.0).abs() < 1e-3);
    }

    #[test]
    fn straight_on_normal_has_no_diffuse_polarisation() {
        let g = CoaxialGeometry::from_normal_in_camera(Vec3::<f32>::from_f64([0.0, 0.0, 1.0]));
        let p = PbrdfParams::<f64> {
            eta: 1.5,
            sigma_s: 0.0,
            sigma_ss: 0.0,
            rho_s: 1.0,
            rho_ss: [1.0; 3],
            rho_d: [1.0; 3],
        }
        .cast();
        for k in terms(&g, &p) {
            assert!(k.dp_alpha.is_finite() && k.ss.is_finite());
            assert_eq!(k.dp_alpha, 0.0);
        }
    }
}
