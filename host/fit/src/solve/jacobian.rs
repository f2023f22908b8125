//! The measurement loss's normal equations with the Jacobian written out (docs/fit-solver.md
//! "LM", "Uncertainty"): the same residuals as `Problem::evaluate` emits in
//! [`LossMode::Measurement`](super::LossMode), accumulated from the unit lobes' partials with
//! plain `f64` arithmetic instead of carrying dual numbers through the albedo projection and
//! every residual.
//!
//! Contract:
//! - [`lm_normal_equations`]: cost, JᵀJ and Jᵀr over the LM's box coordinates, with the albedos
//!   projected exactly (`albedos.rs`) and their derivatives included — the variable-projection
//!   Jacobian. On the minimiser's face the free albedos α_F solve H_FF·α_F = g_F − H_FA·α_A, so
//!   ∂α_F/∂θ = −H_FF⁻¹·∂(Hα − g)_F/∂θ, and ∂(Hα − g)/∂θ = Σ_rows w·(∂φ·r + φ·∂pred) with φ the
//!   row's lobe values; albedos on a bound are constants. Equal to the dual-number evaluation to
//!   rounding (tested).
//! - [`physical_normal_matrix`]: JᵀJ over all 12 parameters in physical units (η, σ_s, σ_ss,
//!   ρ_s, ρ_ss RGB, ρ_d RGB, p, q) at given albedos, for the covariance: a residual row touches
//!   the 5 nonlinear unknowns and its own channel's ρ_d, ρ_ss and ρ_s only.
//! - Paper mode is not handled here (its DoP and azimuth rows mix the channels nonlinearly): the
//!   callers keep the dual-number evaluation for it.

use ellipso_model::optics::Dual;
use nalgebra::{DMatrix, DVector, SMatrix, SVector};

use super::albedos::{AlbedoSystem, Albedos};
use super::box_coords::{Mat, N_RAW, RawDual, Vector};
use super::problem::{Chart, Nonlinear, Problem, Scratch};

/// Physical unknowns with a dual slot each: η, σ_s, σ_ss, p, q.
type Physical = Dual<5>;

/// `acc += k·d` on derivative arrays.
#[inline]
fn axpy<const N: usize>(acc: &mut [f64; N], k: f64, d: &[f64; N]) {
    for (a, v) in acc.iter_mut().zip(d) {
        *a += k * v;
    }
}

/// The derivative of the prediction ρ_d·a + ρ_ss·b + ρ_s·s (albedos held).
#[inline]
fn d_prediction<const N: usize>(
    alpha: (f64, f64, f64),
    a: &Dual<N>,
    b: &Dual<N>,
    s: &Dual<N>,
) -> [f64; N] {
    core::array::from_fn(|k| alpha.0 * a.du[k] + alpha.1 * b.du[k] + alpha.2 * s.du[k])
}

/// Σ r², JᵀJ and Jᵀr of residual rows given as dual numbers (value and gradient), and their
/// count: what every Jacobian of the solver accumulates.
pub(super) struct NormalEquations<const N: usize> {
    pub cost: f64,
    pub rows: usize,
    pub jtj: SMatrix<f64, N, N>,
    pub jtr: SVector<f64, N>,
}

impl<const N: usize> NormalEquations<N> {
    pub fn new() -> Self {
        Self {
            cost: 0.0,
            rows: 0,
            jtj: SMatrix::zeros(),
            jtr: SVector::zeros(),
        }
    }

    /// Adds the residual row `r` (value and gradient).
    pub fn add(&mut self, r: Dual<N>) {
        self.cost += r.re * r.re;
        self.rows += 1;
        let g = SVector::<f64, N>::from(r.du);
        self.jtj.ger(1.0, &g, &g, 1.0);
        self.jtr.axpy(r.re, &g, 1.0);
    }
}

/// Cost, JᵀJ and Jᵀr of the measurement loss over the LM's box coordinates at `x` (seeded
/// duals), and the projected albedos (module doc).
pub(super) fn lm_normal_equations(
    problem: &Problem,
    chart: &Chart,
    x: &Nonlinear<RawDual>,
    scratch: &mut Scratch<RawDual>,
) -> (f64, Mat, Vector, Albedos<f64>) {
    problem.units_at(chart, x, false, scratch);
    problem.virtuals_at(x, scratch);
    // The albedos, in f64, and their face.
    let mut sys = AlbedoSystem::<f64>::new();
    problem.measurement_rows(scratch, |c, w, [a, b, s], o| {
        sys.add_row(c, w, a.re, b.re, s.re, o)
    });
    let (albedos, free) = sys.solve_faces(problem.channels, problem.bounds.albedo_cap);
    let alpha = |c: usize| (albedos.rho_d[c], albedos.rho_ss[c], albedos.rho_s);
    // ∂(Hα − g)/∂θ per albedo (layout of `AlbedoSystem::solve_faces`).
    let mut m = [[0.0; N_RAW]; 7];
    problem.measurement_rows(scratch, |c, w, [a, b, s], o| {
        let al = alpha(c);
        let r = al.0 * a.re + al.1 * b.re + al.2 * s.re - o;
        let dp = d_prediction(al, &a, &b, &s);
        for (k, lobe) in [(c, a), (3 + c, b), (6, s)] {
            axpy(&mut m[k], w * r, &lobe.du);
            axpy(&mut m[k], w * lobe.re, &dp);
        }
    });
    let d_alpha = albedo_derivatives(&sys.hessian(), &free, &m);
    let mut ne = NormalEquations::<N_RAW>::new();
    problem.measurement_rows(scratch, |c, w, [a, b, s], o| {
        let al = alpha(c);
        let r = al.0 * a.re + al.1 * b.re + al.2 * s.re - o;
        let mut j = d_prediction(al, &a, &b, &s);
        axpy(&mut j, a.re, &d_alpha[c]);
        axpy(&mut j, b.re, &d_alpha[3 + c]);
        axpy(&mut j, s.re, &d_alpha[6]);
        // Written out rather than through `NormalEquations::add`: the weight w multiplies the
        // squared residual, and w·r² is the cost the f64 evaluation adds up.
        let sw = w.sqrt();
        let g = Vector::from(j) * sw;
        ne.cost += w * r * r;
        ne.jtj.ger(1.0, &g, &g, 1.0);
        ne.jtr.axpy(sw * r, &g, 1.0);
    });
    let normal = chart.normal(x.p, x.q);
    problem.prior_rows(x, normal, &mut |r: RawDual| ne.add(r));
    (ne.cost, ne.jtj, ne.jtr, albedos)
}

/// ∂α/∂θ for the free albedos: −H_FF⁻¹·m_F (module doc); zero for albedos on a bound, and for
/// all of them if H_FF is numerically singular (the dual evaluation's box2 treats such a face
/// as not free either).
fn albedo_derivatives(
    h: &[[f64; 7]; 7],
    free: &[bool; 7],
    m: &[[f64; N_RAW]; 7],
) -> [[f64; N_RAW]; 7] {
    let mut out = [[0.0; N_RAW]; 7];
    let idx: Vec<usize> = (0..7).filter(|&k| free[k]).collect();
    if idx.is_empty() {
        return out;
    }
    let n = idx.len();
    let hff = DMatrix::from_fn(n, n, |r, c| h[idx[r]][idx[c]]);
    let Some(lu) = Some(hff.lu()).filter(|lu| lu.is_invertible()) else {
        return out;
    };
    for k in 0..N_RAW {
        let rhs = DVector::from_fn(n, |r, _| -m[idx[r]][k]);
        if let Some(sol) = lu.solve(&rhs) {
            for (r, &i) in idx.iter().enumerate() {
                out[i][k] = sol[r];
            }
        }
    }
    out
}

/// Slot of each physical unknown (η, σ_s, σ_ss, p, q) in the covariance's 12-parameter layout.
pub(super) const PHYSICAL_SLOTS: [usize; 5] = [0, 1, 2, 10, 11];

/// JᵀJ over all 12 parameters in physical units (layout of `uncertainty.rs`: η, σ_s, σ_ss,
/// ρ_s, ρ_ss RGB, ρ_d RGB, p, q) at `x` (p = q = 0 on `chart`) and the given `albedos`, with
/// the cost and the number of residual rows.
pub(super) fn physical_normal_matrix(
    problem: &Problem,
    chart: &Chart,
    x: &Nonlinear<f64>,
    albedos: &Albedos<f64>,
) -> (f64, usize, SMatrix<f64, 12, 12>) {
    let xd: Nonlinear<Physical> = x.seeded([0, 1, 2, 3, 4]);
    let mut scratch = Scratch::new(problem.len(), problem.virtuals.len());
    problem.units_at(chart, &xd, false, &mut scratch);
    problem.virtuals_at(&xd, &mut scratch);
    let mut ne = NormalEquations::<12>::new();
    problem.measurement_rows(&scratch, |c, w, [a, b, s], o| {
        let al = (albedos.rho_d[c], albedos.rho_ss[c], albedos.rho_s);
        let r = al.0 * a.re + al.1 * b.re + al.2 * s.re - o;
        let sw = w.sqrt();
        let dp = d_prediction(al, &a, &b, &s);
        // The row's non-zero entries: the 5 nonlinear unknowns, then ρ_s, ρ_ss,c, ρ_d,c.
        let mut entries = [(0usize, 0.0); 8];
        for (k, slot) in PHYSICAL_SLOTS.iter().enumerate() {
            entries[k] = (*slot, sw * dp[k]);
        }
        entries[5] = (3, sw * s.re);
        entries[6] = (4 + c, sw * b.re);
        entries[7] = (7 + c, sw * a.re);
        for (i, gi) in entries {
            for (j, gj) in entries {
                ne.jtj[(i, j)] += gi * gj;
            }
        }
        ne.cost += w * r * r;
        ne.rows += 1;
    });
    // The prior rows, in the 12-parameter duals.
    let x12: Nonlinear<Dual<12>> = x.seeded(PHYSICAL_SLOTS);
    let normal = chart.normal(x12.p, x12.q);
    problem.prior_rows(&x12, normal, &mut |r: Dual<12>| ne.add(r));
    (ne.cost, ne.rows, ne.jtj)
}

#[cfg(test)]
mod tests {
    use super::super::lm;
    use super::super::tests::{TILTED, material, synth, views};
    use super::super::{LossMode, SolverConfig};
    use super::*;
    use crate::data::{VertexGuide, VirtualSample};
    use crate::model::coaxial_unit_specular;

    /// The written-out normal equations equal the dual-number evaluation through the albedo
    /// projection, for colour and monochrome vertices, with and without virtual samples and at
    /// points where albedos sit on a bound.
    #[test]
    fn written_out_jacobians_equal_the_dual_evaluation() {
        let views = views();
        let (mut checked, mut on_bound, mut rho_s_free) = (0, 0, 0);
        for (k, name) in ["ceramic", "glaze", "rubber", "glossy_plastic"]
            .iter()
            .enumerate()
        {
            let truth = material(name);
            for colour in [true, false] {
                let v = synth(&views, TILTED, &truth, None, 1.0, 3 + k as u64);
                let virtuals: Vec<VirtualSample> = (0..16)
                    .map(|m| {
                        let c = (m as f64 * 5.0).to_radians().cos();
                        let (b, s) = coaxial_unit_specular(c, 1.5, 0.1, 0.3);
                        VirtualSample {
                            cos_theta_h: c,
                            specular: [0.2 * b + 0.8 * s; 3],
                            weight: 0.1 / 16.0,
                        }
                    })
                    .collect();
                for guide in [
                    VertexGuide::default(),
                    VertexGuide {
                        virtual_samples: virtuals,
                        ..VertexGuide::default()
                    },
                ] {
                    let config = SolverConfig::default();
                    assert_eq!(config.loss, LossMode::Measurement);
                    let problem = Problem::new(&views, &v, colour, &guide, &config);
                    let ch = Chart::at(v.normal_world);
                    for raw in [[1.45, -1.6, 0.3, 0.01, -0.02], [2.9, -4.0, 0.0, 0.0, 0.0]] {
                        let seeded: [RawDual; N_RAW] =
                            core::array::from_fn(|k| Dual::variable(raw[k], k));
                        let x = lm::physical(seeded);
                        let mut scratch = Scratch::new(problem.len(), guide.virtual_samples.len());
                        let (cost, jtj, jtr, albedos) =
                            lm_normal_equations(&problem, &ch, &x, &mut scratch);
                        let mut dual = NormalEquations::<N_RAW>::new();
                        let dual_albedos =
                            problem.evaluate(&ch, &x, None, &mut scratch, &mut |r: RawDual| {
                                dual.add(r)
                            });
                        let (dual_cost, dual_jtj, dual_jtr) = (dual.cost, dual.jtj, dual.jtr);
                        let close = |a: f64, b: f64, scale: f64| (a - b).abs() <= 1e-8 * scale;
                        assert!(close(cost, dual_cost, dual_cost), "{cost} vs {dual_cost}");
                        let jscale = dual_jtj.abs().max();
                        for (a, b) in jtj.iter().zip(dual_jtj.iter()) {
                            assert!(close(*a, *b, jscale), "{jtj} vs {dual_jtj}");
                        }
                        let rscale = dual_jtr.abs().max().max(1e-12 * jscale);
                        for (a, b) in jtr.iter().zip(dual_jtr.iter()) {
                            assert!(close(*a, *b, rscale), "{jtr} vs {dual_jtr}");
                        }
                        assert!((albedos.rho_s - dual_albedos.rho_s.re).abs() < 1e-12);
                        // The covariance's 12-parameter normal matrix, likewise.
                        let xf = lm::physical(raw);
                        let (c12, m12, j12) = physical_normal_matrix(&problem, &ch, &xf, &albedos);
                        let (dc12, dm12, dj12) =
                            super::super::uncertainty::all_duals(&problem, &ch, &xf, &albedos);
                        assert_eq!(m12, dm12);
                        assert!(close(c12, dc12, dc12), "{c12} vs {dc12}");
                        let scale12 = dj12.abs().max();
                        for (a, b) in j12.iter().zip(dj12.iter()) {
                            assert!(close(*a, *b, scale12), "{j12} vs {dj12}");
                        }
                        checked += 1;
                        let all = albedos
                            .rho_d
                            .iter()
                            .chain(&albedos.rho_ss)
                            .chain([&albedos.rho_s]);
                        let values: Vec<f64> = all.copied().collect();
                        on_bound += usize::from(values.contains(&0.0));
                        rho_s_free += usize::from(albedos.rho_s > 0.0 && albedos.rho_s < 5.0);
                    }
                }
            }
        }
        assert_eq!(checked, 32);
        // Both kinds of face were exercised.
        assert!(
            on_bound >= 4 && rho_s_free >= 4,
            "{on_bound} on a bound, {rho_s_free} free ρs"
        );
    }
}
