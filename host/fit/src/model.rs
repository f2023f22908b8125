//! Per-sample prediction for the fit: the observation channels of the unit-albedo lobes, with
//! exact derivatives, cheap enough for 10⁵ vertices × 150 views.
//!
//! Contract (docs/model.md §4, §6 "Observation channels", §11 "Unknowns"):
//! - Observations are linear in the albedos. Per colour channel c,
//!   `[I^d, I^s, I^α]_c = ρ_d,c·A + ρ_ss,c·B(σ_ss) + ρ_s·C(σ_s)`, where A, B, C are the
//!   observation channels of the diffuse, single-scattering and specular lobes with unit albedo
//!   ([`UnitSample`]). They come from the optics module's own functions
//!   (`ellipso_model::optics::measure::observe_unit_lobes`, i.e. `pbrdf::apply_unit_lobes`): no
//!   formula is restated here.
//! - Everything is generic over [`Real`]: `f64` for cost-only evaluations, [`Dual`] over only the
//!   nonlinear unknowns (η, σ_s, σ_ss, the normal's two tangent coordinates; the solver also
//!   carries ρ_s in the same dual) for exact Jacobians.
//! - The normal is `n0 + p·t1 + q·t2` with (t1, t2) an orthonormal tangent basis of the unit
//!   `n0` ([`tangent_basis`]); the optics model normalises it, so (p, q) are tangent-plane
//!   coordinates (radians to first order).
//! - Virtual samples (docs/fit-augment.md "Virtual profile and kernel"):
//!   [`coaxial_unit_specular`] gives the two reflection lobes at an exactly coaxial geometry
//!   (θ_i = θ_o = θ_h, Fresnel R(0)), through `ellipso_model::optics::coaxial::specular_term`.
//! - A sample whose geometry is degenerate or back-facing has no prediction (`None`).

mod lobes;

use ellipso_model::optics::coaxial::unit_specular_terms;
use ellipso_model::optics::measure::{AnalyserAngles, ObservationChannels, SensorIntensities};
use ellipso_model::optics::staged::{Directions, ReflectionFrames, half_vector};
use ellipso_model::optics::{Real, Stokes, Vec3};
use nalgebra::Point3;

#[cfg(doc)]
use ellipso_model::optics::Dual;

use super::data::ViewGeometry;

pub use lobes::LobeScalar;

/// The fixed (normal- and material-independent) part of one (vertex, view) geometry, prepared
/// once per vertex: directions, frames, the half vector, the reflection's rotations
/// (`ellipso_model::optics::staged`) and the analyser rows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SampleFrames {
    /// Unit directions surface → flash and surface → camera (world) and their Stokes frames:
    /// light frame z = −ω_i, x along the flash polariser; camera frame z = ω_o, y = image up.
    pub directions: Directions<f64>,
    /// Unit half vector of the two directions.
    pub half: Vec3<f64>,
    /// cos θ_d = h·ω_i clamped to [0, 1]: the Fresnel angle of the microfacet reflection.
    pub cos_theta_d: f64,
    /// Whether the flash is polarised (s_light = [1, 1, 0, 0]) or bare ([1, 0, 0, 0]).
    pub polarised: bool,
    /// The microfacet reflection's rotations for this configuration and flash.
    pub reflection: ReflectionFrames<f64>,
    /// The analyser pixels as linear functions of the observation channels: row k (nominal
    /// 0°, 45°, 90°, 135°) gives I_k = r·[I^d, I^s, I^α] with the analysers' effective angles
    /// for this ray ([`AnalyserAngles::for_ray`]; nominal when the view has no optical axis).
    pub pixel_rows: [[f64; 3]; 4],
}

/// The analyser pixels [I0, I45, I90, I135] of stored observation channels
/// [I^d, I^s, I^α, I^t] (I90 = I^d/2, I0 = I^s + I^d/2, I45 = (I^t − I^α)/2,
/// I135 = (I^t + I^α)/2): the exact inverse of how they were formed, so the measured pixels
/// themselves are compared.
pub fn observed_pixels(c: [f64; 4]) -> [f64; 4] {
    let half_d = 0.5 * c[0];
    [
        c[1] + half_d,
        0.5 * (c[3] - c[2]),
        half_d,
        0.5 * (c[3] + c[2]),
    ]
}

/// The model's four analyser pixels for observation channels `x` = [I^d, I^s, I^α] of a sample
/// with [`SampleFrames::pixel_rows`] `rows`.
pub fn predicted_pixels<T: Real>(rows: &[[f64; 3]; 4], x: [T; 3]) -> [T; 4] {
    let k = T::from_f64;
    core::array::from_fn(|j| k(rows[j][0]) * x[0] + k(rows[j][1]) * x[1] + k(rows[j][2]) * x[2])
}

/// The pixel rows of [`SampleFrames::pixel_rows`] for analyser angles `a`: with
/// s0 = I^d + I^s, s1 = I^s, s2 = −I^α (docs/model.md), I_k = ½(s0 + s1 cos2ψ_k + s2 sin2ψ_k).
pub fn pixel_rows(a: &AnalyserAngles) -> [[f64; 3]; 4] {
    core::array::from_fn(|k| [0.5, 0.5 * (1.0 + a.cos2[k]), -0.5 * a.sin2[k]])
}

impl SampleFrames {
    /// The frames of `view` at `position_world`, from [`crate::data::SampleGeometry::model`];
    /// `None` when the geometry is degenerate (see [`ViewGeometry::geometry_at`]) or the flash
    /// is exactly opposite the camera (no half vector).
    pub fn new(view: &ViewGeometry, position_world: [f64; 3]) -> Option<Self> {
        let g = view.geometry_at(&Point3::from(position_world))?;
        // Directions and frames as the model's geometry builds them; the normal only enters
        // later, so any valid one serves here.
        let fixed = g.model::<f64>(Vec3::from_f64(g.to_camera)).ok()?;
        let half = half_vector(fixed.to_light, fixed.to_camera)?;
        let polarised = view.polarised();
        let angles = view.analyser_angles(&g);
        let directions = fixed.directions();
        Some(Self {
            directions,
            half,
            cos_theta_d: fixed.cos_theta_d,
            polarised,
            reflection: ReflectionFrames::new(&directions, light_stokes(polarised)),
            pixel_rows: pixel_rows(&angles),
        })
    }
}

/// The flash's Stokes vector in the light frame at unit intensity: [1, 1, 0, 0] behind the
/// rig's polariser (along light x), [1, 0, 0, 0] bare.
pub fn light_stokes<T: Real>(polarised: bool) -> Stokes<T> {
    if polarised {
        Stokes::new(T::one(), T::one(), T::zero(), T::zero())
    } else {
        Stokes::unpolarised(T::one())
    }
}

/// Observation channels `[I^d, I^s, I^α]` of the three unit-albedo lobes at one sample, plus
/// the cosines the losses need.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UnitSample<T> {
    /// A: the diffuse lobe, ρ_d = 1.
    pub diffuse: [T; 3],
    /// B: the single-scattering lobe, ρ_ss = 1.
    pub single_scattering: [T; 3],
    /// C: the specular lobe, ρ_s = 1.
    pub specular: [T; 3],
    /// cos θ_o = n·ω_o clamped to [0, 1].
    pub cos_theta_o: T,
    /// DoP_d(η, θ_o) (docs/model.md §6 "Diffuse DoP and its η-derivative").
    pub dop_diffuse: T,
    /// Whether the normal faces the light and the camera; false only for the all-zero stand-in
    /// of a sample the normal turns away (`unit_sample` returns `None` for it).
    pub front_facing: bool,
}

impl<T: Real> UnitSample<T> {
    /// The prediction `ρ_d·A + ρ_ss·B + ρ_s·C` for one colour channel.
    pub fn predict(&self, rho_d: T, rho_ss: T, rho_s: T) -> [T; 3] {
        core::array::from_fn(|k| {
            rho_d * self.diffuse[k] + rho_ss * self.single_scattering[k] + rho_s * self.specular[k]
        })
    }
}

fn channels<T: Real>(o: ObservationChannels<T>) -> [T; 3] {
    [o.diffuse, o.specular, o.alpha]
}

/// The observation channels [I^d, I^s, I^α] of a Stokes vector in the camera frame.
fn observed<T: Real>(s: Stokes<T>) -> [T; 3] {
    channels(SensorIntensities::from_stokes(s).observation())
}

/// An orthonormal tangent basis (t1, t2) of the unit normal `n` (t1 × t2 = n), built from the
/// world axis least aligned with `n` (no branch near any particular direction).
pub fn tangent_basis(n: [f64; 3]) -> ([f64; 3], [f64; 3]) {
    let a = n.map(f64::abs);
    let axis = if a[0] <= a[1] && a[0] <= a[2] {
        [1.0, 0.0, 0.0]
    } else if a[1] <= a[2] {
        [0.0, 1.0, 0.0]
    } else {
        [0.0, 0.0, 1.0]
    };
    let d = axis[0] * n[0] + axis[1] * n[1] + axis[2] * n[2];
    let t = [axis[0] - d * n[0], axis[1] - d * n[1], axis[2] - d * n[2]];
    // |t|² ≥ 2/3 for a unit n (the least aligned axis has |n_k| ≤ 1/√3).
    let len = (t[0] * t[0] + t[1] * t[1] + t[2] * t[2]).sqrt();
    let t1 = t.map(|v| v / len);
    let t2 = [
        n[1] * t1[2] - n[2] * t1[1],
        n[2] * t1[0] - n[0] * t1[2],
        n[0] * t1[1] - n[1] * t1[0],
    ];
    (t1, t2)
}

/// The (unnormalised) normal `n0 + p·t1 + q·t2`.
pub fn tangent_normal<T: Real>(n0: [f64; 3], t1: [f64; 3], t2: [f64; 3], p: T, q: T) -> Vec3<T> {
    let c = |k: usize| T::from_f64(n0[k]) + p * T::from_f64(t1[k]) + q * T::from_f64(t2[k]);
    Vec3::new(c(0), c(1), c(2))
}

/// A unit vector from `n0 + p·t1 + q·t2` in `f64` (the re-centred normal after a step).
pub fn unit_tangent_normal(n0: [f64; 3], t1: [f64; 3], t2: [f64; 3], p: f64, q: f64) -> [f64; 3] {
    let v = tangent_normal(n0, t1, t2, p, q);
    let len = v.norm_squared().sqrt();
    // |n0 + p t1 + q t2| ≥ 1 since t1, t2 ⟂ n0.
    [v.x / len, v.y / len, v.z / len]
}

/// A chart of the normal's directions about a unit `n0`: `n0 + p·t1 + q·t2` with (t1, t2) its
/// orthonormal tangent basis ([`tangent_basis`]), so (p, q) are tangent-plane coordinates
/// (radians to first order). The solver re-centres it on every accepted normal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Chart {
    /// Unit centre normal.
    pub n0: [f64; 3],
    /// First tangent.
    pub t1: [f64; 3],
    /// Second tangent, t1 × t2 = n0.
    pub t2: [f64; 3],
}

impl Chart {
    /// The chart centred on the unit normal `n0`.
    pub fn at(n0: [f64; 3]) -> Self {
        let (t1, t2) = tangent_basis(n0);
        Self { n0, t1, t2 }
    }

    /// The (unnormalised) normal at (p, q): [`tangent_normal`].
    pub fn normal<T: Real>(&self, p: T, q: T) -> Vec3<T> {
        tangent_normal(self.n0, self.t1, self.t2, p, q)
    }

    /// The unit normal at (p, q): [`unit_tangent_normal`].
    pub fn unit_normal(&self, p: f64, q: f64) -> [f64; 3] {
        unit_tangent_normal(self.n0, self.t1, self.t2, p, q)
    }
}

/// A normal on a [`Chart`]: (p, q) are the solver's unknowns; a fixed normal is `p = q = 0`
/// (any non-zero length; the optics normalise it).
#[derive(Clone, Copy, Debug)]
pub struct TangentNormal<T> {
    /// The chart.
    pub chart: Chart,
    /// Coordinate along the chart's t1.
    pub p: T,
    /// Coordinate along the chart's t2.
    pub q: T,
}

impl<T: Real> TangentNormal<T> {
    /// The (unnormalised) normal `n0 + p·t1 + q·t2`.
    pub fn vector(&self) -> Vec3<T> {
        self.chart.normal(self.p, self.q)
    }
}

impl TangentNormal<f64> {
    /// A fixed unit normal (p = q = 0).
    pub fn fixed(n: [f64; 3]) -> Self {
        Self {
            chart: Chart::at(n),
            p: 0.0,
            q: 0.0,
        }
    }
}

/// The unit-albedo observations of one sample for `normal` and the nonlinear parameters, or
/// `None` when the normal is degenerate or the geometry back-facing (n·ω_i < 0 or n·ω_o < 0).
/// `with_dop` also fills [`UnitSample::cos_theta_o`] and [`UnitSample::dop_diffuse`] (zero
/// otherwise): only the paper loss and the fit's flags read them.
pub fn unit_sample<T: LobeScalar>(
    frames: &SampleFrames,
    normal: &TangentNormal<T>,
    eta: T,
    sigma_s: T,
    sigma_ss: T,
    with_dop: bool,
) -> Option<UnitSample<T>> {
    T::unit_sample(frames, normal, eta, sigma_s, sigma_ss, with_dop)
}

/// [`unit_sample`] in `f64` at a fixed unit `normal` (the lobes only, no DoP fields).
pub fn unit_sample_at(
    frames: &SampleFrames,
    normal: [f64; 3],
    eta: f64,
    sigma_s: f64,
    sigma_ss: f64,
) -> Option<UnitSample<f64>> {
    unit_sample(
        frames,
        &TangentNormal::fixed(normal),
        eta,
        sigma_s,
        sigma_ss,
        false,
    )
}

/// The coaxial specular I^s of the two unit-albedo reflection lobes at `cos_theta_h`
/// (θ_i = θ_o = θ_h, Fresnel at normal incidence): `(single_scattering, specular)`, so a
/// virtual sample predicts `ρ_ss,c·B_v + ρ_s·C_v` (docs/fit-augment.md "Virtual profile and
/// kernel").
pub fn coaxial_unit_specular<T: Real>(cos_theta_h: f64, eta: T, sigma_s: T, sigma_ss: T) -> (T, T) {
    unit_specular_terms(T::from_f64(cos_theta_h), eta, sigma_s, sigma_ss)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ellipso_model::optics::Dual;
    use ellipso_model::optics::coaxial::specular_term;
    use ellipso_model::optics::measure::{FlashPolariser, observe};
    use ellipso_model::optics::pbrdf::PbrdfParams;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn view(rng: &mut ChaCha8Rng) -> ViewGeometry {
        let az: f64 = rng.random_range(0.0..std::f64::consts::TAU);
        let el: f64 = rng.random_range(0.3..1.4);
        let cam = [
            0.5 * el.cos() * az.cos(),
            0.5 * el.cos() * az.sin(),
            0.5 * el.sin(),
        ];
        let right = [-az.sin(), az.cos(), 0.0];
        let fwd = cam.map(|v| -v / 0.5);
        let up = [
            right[1] * fwd[2] - right[2] * fwd[1],
            right[2] * fwd[0] - right[0] * fwd[2],
            right[0] * fwd[1] - right[1] * fwd[0],
        ];
        ViewGeometry {
            frame_id: 0,
            camera_position_world: cam,
            camera_up_world: up,
            flash_position_world: [
                cam[0] + 0.03 * up[0],
                cam[1] + 0.03 * up[1],
                cam[2] + 0.03 * up[2],
            ],
            polariser_axis_world: Some(right),
            camera_axis_world: Some(fwd),
        }
    }

    fn params() -> PbrdfParams<f64> {
        PbrdfParams {
            eta: 1.55,
            sigma_s: 0.12,
            sigma_ss: 0.35,
            rho_s: 0.9,
            rho_ss: [0.2, 0.1, 0.05],
            rho_d: [0.6, 0.3, 0.1],
        }
    }

    #[test]
    #[expect(clippy::needless_range_loop, reason = "parallel per-channel arrays")]
    fn linear_model_matches_observe() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let p = params();
        let n = [0.1, -0.2, 1.0];
        let mut checked = 0;
        for _ in 0..200 {
            let v = view(&mut rng);
            let Some(f) = SampleFrames::new(&v, [0.0; 3]) else {
                continue;
            };
            let Some(u) = unit_sample_at(&f, n, p.eta, p.sigma_s, p.sigma_ss) else {
                continue;
            };
            let g = v
                .geometry_at(&Point3::origin())
                .unwrap()
                .model::<f64>(Vec3::from_f64(n))
                .unwrap();
            let full = observe(&g, &p, FlashPolariser { angle_rad: 0.0 });
            for c in 0..3 {
                let mine = u.predict(p.rho_d[c], p.rho_ss[c], p.rho_s);
                let want = channels(full[c]);
                for k in 0..3 {
                    assert!(
                        (mine[k] - want[k]).abs() <= 1e-12 * (1.0 + want[k].abs()),
                        "{mine:?} vs {want:?}"
                    );
                }
            }
            checked += 1;
        }
        assert!(checked > 100);
    }

    #[test]
    fn dual_derivatives_match_central_differences() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let n0 = {
            let v = [0.2f64, 0.1, 1.0];
            let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            v.map(|x| x / l)
        };
        let (t1, t2) = tangent_basis(n0);
        let x0 = [1.45, 0.2, 0.45, 0.03, -0.02];
        let eval = |f: &SampleFrames, x: [f64; 5]| {
            let normal = TangentNormal {
                chart: Chart { n0, t1, t2 },
                p: x[3],
                q: x[4],
            };
            unit_sample(f, &normal, x[0], x[1], x[2], true)
        };
        let mut checked = 0;
        for _ in 0..60 {
            let v = view(&mut rng);
            let Some(f) = SampleFrames::new(&v, [0.0; 3]) else {
                continue;
            };
            let d = |k: usize| Dual::<5>::variable(x0[k], k);
            let normal = TangentNormal {
                chart: Chart { n0, t1, t2 },
                p: d(3),
                q: d(4),
            };
            let Some(u) = unit_sample(&f, &normal, d(0), d(1), d(2), true) else {
                continue;
            };
            for k in 0..5 {
                let h = 1e-6;
                let mut xp = x0;
                let mut xm = x0;
                xp[k] += h;
                xm[k] -= h;
                let (Some(up), Some(um)) = (eval(&f, xp), eval(&f, xm)) else {
                    continue;
                };
                let fields = |s: &UnitSample<f64>| {
                    let mut out = [0.0; 11];
                    out[..3].copy_from_slice(&s.diffuse);
                    out[3..6].copy_from_slice(&s.single_scattering);
                    out[6..9].copy_from_slice(&s.specular);
                    out[9] = s.cos_theta_o;
                    out[10] = s.dop_diffuse;
                    out
                };
                let duals = {
                    let mut out = [Dual::<5>::constant(0.0); 11];
                    out[..3].copy_from_slice(&u.diffuse);
                    out[3..6].copy_from_slice(&u.single_scattering);
                    out[6..9].copy_from_slice(&u.specular);
                    out[9] = u.cos_theta_o;
                    out[10] = u.dop_diffuse;
                    out
                };
                let (fp, fm) = (fields(&up), fields(&um));
                // The narrow duals carry the f64 evaluation's values (to rounding).
                let at = fields(&eval(&f, x0).expect("front-facing at x0"));
                for j in 0..11 {
                    assert!((duals[j].re - at[j]).abs() <= 1e-13 * (1.0 + at[j].abs()));
                }
                for j in 0..11 {
                    let fd = (fp[j] - fm[j]) / (2.0 * h);
                    let ad = duals[j].du[k];
                    let scale = 1.0 + duals[j].re.abs() + ad.abs();
                    assert!(
                        (fd - ad).abs() < 1e-6 * scale,
                        "field {j} var {k}: {fd} vs {ad}"
                    );
                }
            }
            checked += 1;
        }
        assert!(checked > 30);
    }

    #[test]
    #[expect(clippy::needless_range_loop, reason = "parallel per-channel arrays")]
    fn coaxial_lobes_recombine_and_tangent_basis_is_orthonormal() {
        let p = params();
        for c in [0.05, 0.4, 0.9, 1.0] {
            let (b, s) = coaxial_unit_specular(c, p.eta, p.sigma_s, p.sigma_ss);
            let full = specular_term(c, &p);
            for k in 0..3 {
                assert!((p.rho_ss[k] * b + p.rho_s * s - full[k]).abs() < 1e-12 * full[k].abs());
            }
        }
        for n in [
            [0.0, 0.0, 1.0],
            [1.0, 0.0, 0.0],
            [0.6, -0.8, 0.0],
            [0.48, 0.6, 0.64],
        ] {
            let (t1, t2) = tangent_basis(n);
            let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
            for (a, b, want) in [
                (t1, t1, 1.0),
                (t2, t2, 1.0),
                (t1, t2, 0.0),
                (t1, n, 0.0),
                (t2, n, 0.0),
            ] {
                assert!((dot(a, b) - want).abs() < 1e-14);
            }
            let m = unit_tangent_normal(n, t1, t2, 0.0, 0.0);
            assert!((dot(m, n) - 1.0).abs() < 1e-15);
        }
    }
}
