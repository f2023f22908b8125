//! The unit lobes of one sample in `f64`, and in dual numbers through narrow duals.
//!
//! Contract: [`LobeScalar::unit_sample`] returns the same values in every scalar type (the
//! optics module's staged functions, `ellipso_model::optics::staged`, evaluated once), and in
//! `Dual<N>` the exact derivatives with respect to whatever the N slots are (the solver's box
//! coordinates, or the covariance's physical parameters).
//!
//! Why narrow: the lobes depend on few unknowns each — the cosines and the diffuse lobe's frames
//! on the normal's (p, q) only, the reflection's Fresnel terms on η only (θ_d and the
//! reflection's rotations do not depend on the normal), each microfacet weight on its σ and
//! (p, q) — so a `Dual<N>` carried through all of it spends most of its work on derivatives that
//! are zero. Here each piece runs in a dual over its own unknowns (`Dual<2>` over (p, q) for the
//! normal, `Dual<3>` over (η, p, q) for the diffuse lobe and over (σ, p, q) for a weight,
//! `Dual<1>` over η for the reflection), and the results are carried into the caller's N slots
//! by the chain rule: ∂out/∂slot = Σ_k ∂out/∂z_k · ∂z_k/∂slot over the physical unknowns
//! z = (η, σ_s, σ_ss, p, q), whose slot derivatives the caller's inputs carry.

use ellipso_model::optics::fresnel::FresnelTerms;
use ellipso_model::optics::measure::dop_diffuse;
use ellipso_model::optics::microfacet::microfacet_weight;
use ellipso_model::optics::staged::{NormalCosines, diffuse_stokes};
use ellipso_model::optics::{Dual, Real, Vec3};

use super::{SampleFrames, TangentNormal, UnitSample, light_stokes, observed};

/// A scalar the unit lobes can be evaluated in (module doc).
pub trait LobeScalar: Real {
    /// The unit-albedo observations of one sample (see [`super::unit_sample`]).
    fn unit_sample(
        frames: &SampleFrames,
        normal: &TangentNormal<Self>,
        eta: Self,
        sigma_s: Self,
        sigma_ss: Self,
        with_dop: bool,
    ) -> Option<UnitSample<Self>>;
}

/// The cosines of `normal` with the sample's fixed directions; `None` when degenerate or
/// back-facing.
fn cosines<T: Real>(frames: &SampleFrames, normal: Vec3<T>) -> Option<NormalCosines<T>> {
    let d = &frames.directions;
    let c = NormalCosines::new(
        normal,
        d.to_light.cast(),
        d.to_camera.cast(),
        frames.half.cast(),
    )?;
    c.front_facing.then_some(c)
}

/// The diffuse lobe's observation channels for `cosines` and `eta`.
fn diffuse<T: Real>(frames: &SampleFrames, cosines: &NormalCosines<T>, eta: T) -> [T; 3] {
    observed(diffuse_stokes(
        cosines,
        &frames.directions.cast(),
        eta,
        light_stokes(frames.polarised),
    ))
}

/// The reflection's observation channels without the scalar weight, for `eta`.
fn reflection<T: Real>(frames: &SampleFrames, eta: T) -> [T; 3] {
    let terms = FresnelTerms::reflection_terms(T::from_f64(frames.cos_theta_d), eta);
    observed(frames.reflection.cast::<T>().reflect(terms))
}

impl LobeScalar for f64 {
    fn unit_sample(
        frames: &SampleFrames,
        normal: &TangentNormal<f64>,
        eta: f64,
        sigma_s: f64,
        sigma_ss: f64,
        with_dop: bool,
    ) -> Option<UnitSample<f64>> {
        let c = cosines(frames, normal.vector())?;
        let refl = reflection(frames, eta);
        let w_s = microfacet_weight(c.cos_theta_i, c.cos_theta_o, c.cos_theta_h, sigma_s);
        let w_ss = microfacet_weight(c.cos_theta_i, c.cos_theta_o, c.cos_theta_h, sigma_ss);
        let (cos_theta_o, dop) = if with_dop {
            (c.cos_theta_o, dop_diffuse(c.cos_theta_o, eta))
        } else {
            (0.0, 0.0)
        };
        Some(UnitSample {
            diffuse: diffuse(frames, &c, eta),
            single_scattering: refl.map(|r| r * w_ss),
            specular: refl.map(|r| r * w_s),
            cos_theta_o,
            dop_diffuse: dop,
            front_facing: true,
        })
    }
}

/// A `Dual<2>` over (p, q) as a `Dual<3>` over (x, p, q) (slot 0 free for η or a σ).
fn widen(d: Dual<2>) -> Dual<3> {
    Dual {
        re: d.re,
        du: [0.0, d.du[0], d.du[1]],
    }
}

fn widen_cosines(c: &NormalCosines<Dual<2>>) -> NormalCosines<Dual<3>> {
    let v = c.normal;
    NormalCosines {
        normal: Vec3::new(widen(v.x), widen(v.y), widen(v.z)),
        cos_theta_i: widen(c.cos_theta_i),
        cos_theta_o: widen(c.cos_theta_o),
        cos_theta_h: widen(c.cos_theta_h),
        front_facing: c.front_facing,
    }
}

/// The caller's slots of the physical unknowns (η, σ_s, σ_ss, p, q): value and ∂/∂slot each.
struct Slots<const N: usize> {
    eta: [f64; N],
    sigma_s: [f64; N],
    sigma_ss: [f64; N],
    p: [f64; N],
    q: [f64; N],
}

impl<const N: usize> Slots<N> {
    /// The `Dual<N>` of a value with the given partials with respect to the physical unknowns
    /// (η, σ_s, σ_ss, p, q): the chain rule into the caller's slots.
    #[inline]
    fn lift(&self, re: f64, d: [f64; 5]) -> Dual<N> {
        let mut du = [0.0; N];
        for (k, out) in du.iter_mut().enumerate() {
            *out = d[0] * self.eta[k]
                + d[1] * self.sigma_s[k]
                + d[2] * self.sigma_ss[k]
                + d[3] * self.p[k]
                + d[4] * self.q[k];
        }
        Dual { re, du }
    }
}

impl<const N: usize> LobeScalar for Dual<N> {
    fn unit_sample(
        frames: &SampleFrames,
        normal: &TangentNormal<Dual<N>>,
        eta: Dual<N>,
        sigma_s: Dual<N>,
        sigma_ss: Dual<N>,
        with_dop: bool,
    ) -> Option<UnitSample<Dual<N>>> {
        let slots = Slots {
            eta: eta.du,
            sigma_s: sigma_s.du,
            sigma_ss: sigma_ss.du,
            p: normal.p.du,
            q: normal.q.du,
        };
        // The normal and its cosines over (p, q).
        let n2 = normal.chart.normal(
            Dual::<2>::variable(normal.p.re, 0),
            Dual::<2>::variable(normal.q.re, 1),
        );
        let c3 = widen_cosines(&cosines(frames, n2)?);
        // The diffuse lobe over (η, p, q).
        let a = diffuse(frames, &c3, Dual::<3>::variable(eta.re, 0));
        // The reflection over η; the weights over (σ, p, q).
        let r = reflection(frames, Dual::<1>::variable(eta.re, 0));
        let weight = |sigma: f64| {
            microfacet_weight(
                c3.cos_theta_i,
                c3.cos_theta_o,
                c3.cos_theta_h,
                Dual::<3>::variable(sigma, 0),
            )
        };
        let (w_s, w_ss) = (weight(sigma_s.re), weight(sigma_ss.re));
        let lobe = |w: Dual<3>, r: Dual<1>, sigma_slot: usize| {
            let mut d = [w.re * r.du[0], 0.0, 0.0, w.du[1] * r.re, w.du[2] * r.re];
            d[sigma_slot] = w.du[0] * r.re;
            slots.lift(w.re * r.re, d)
        };
        let diffuse = a.map(|v| slots.lift(v.re, [v.du[0], 0.0, 0.0, v.du[1], v.du[2]]));
        let (cos_theta_o, dop) = if with_dop {
            let c = c3.cos_theta_o;
            let dop = dop_diffuse(c, Dual::<3>::variable(eta.re, 0));
            (
                slots.lift(c.re, [0.0, 0.0, 0.0, c.du[1], c.du[2]]),
                slots.lift(dop.re, [dop.du[0], 0.0, 0.0, dop.du[1], dop.du[2]]),
            )
        } else {
            (Dual::constant(0.0), Dual::constant(0.0))
        };
        Some(UnitSample {
            diffuse,
            single_scattering: r.map(|r| lobe(w_ss, r, 2)),
            specular: r.map(|r| lobe(w_s, r, 1)),
            cos_theta_o,
            dop_diffuse: dop,
            front_facing: true,
        })
    }
}
