//! Levenberg–Marquardt over the six raw (unbounded) nonlinear unknowns of one vertex, with
//! exact Jacobians from dual numbers and the bounds removed by reparameterisation
//! (docs/fit-solver.md "Bounds"; formulas in the `solve` module doc).

use ellipso_model::optics::{Dual, Real};
use nalgebra::{SMatrix, SVector};

use super::super::model::{tangent_basis, unit_tangent_normal};
use super::problem::{Albedos, Bounds, Chart, Nonlinear, Problem, Scratch};
use super::{LossMode, SolverConfig};

/// Raw unknowns: u (η), a (σ_s), b (σ_ss), c (ρ_s), p, q (tangent normal).
pub(super) const N_RAW: usize = 6;
pub(super) type RawDual = Dual<N_RAW>;
type Mat = SMatrix<f64, N_RAW, N_RAW>;
type Vector = SVector<f64, N_RAW>;

/// Raw values are clamped to ±[`RAW_LIMIT`]: sigmoid/softplus are saturated to 1e-26 there, so
/// nothing is lost, and exp() never overflows.
const RAW_LIMIT: f64 = 60.0;

/// 1/(1 + e⁻ˣ), overflow-free.
pub(crate) fn sigmoid<T: Real>(x: T) -> T {
    if x.re() >= 0.0 {
        T::one() / (T::one() + (-x).exp())
    } else {
        let e = x.exp();
        e / (T::one() + e)
    }
}

/// Inverse of the sigmoid, the argument clamped to [1e-12, 1 − 1e-12].
pub(super) fn logit(s: f64) -> f64 {
    let s = s.clamp(1e-12, 1.0 - 1e-12);
    (s / (1.0 - s)).ln()
}

/// Physical unknowns from raw ones (the reparameterisation): every unknown in its box.
pub(super) fn physical<T: Real>(raw: [T; N_RAW], bounds: &Bounds) -> Nonlinear<T> {
    let k = T::from_f64;
    let eta = k(bounds.eta_min) + k(bounds.eta_max - bounds.eta_min) * sigmoid(raw[0]);
    let smin = bounds.sigma_s_min;
    let sigma_s = k(smin) + k(1.0 - smin) * sigmoid(raw[1]);
    let sigma_ss = sigma_s + (T::one() - sigma_s) * sigmoid(raw[2]);
    Nonlinear {
        eta,
        sigma_s,
        sigma_ss,
        rho_s: k(bounds.albedo_cap) * sigmoid(raw[3]),
        p: raw[4],
        q: raw[5],
    }
}

/// Raw unknowns (with p = q = 0) for physical values, clamped into the open box.
pub(super) fn raw_from(
    eta: f64,
    sigma_s: f64,
    sigma_ss: f64,
    rho_s: f64,
    bounds: &Bounds,
) -> [f64; N_RAW] {
    let smin = bounds.sigma_s_min;
    let s = ((sigma_s - smin) / (1.0 - smin)).clamp(0.0, 1.0);
    let sigma_s_c = smin + (1.0 - smin) * s.clamp(1e-12, 1.0 - 1e-12);
    let t = ((sigma_ss - sigma_s_c) / (1.0 - sigma_s_c).max(1e-12)).clamp(0.0, 1.0);
    let e = (eta - bounds.eta_min) / (bounds.eta_max - bounds.eta_min);
    clamp_raw([
        logit(e),
        logit(s),
        logit(t),
        logit(rho_s / bounds.albedo_cap),
        0.0,
        0.0,
    ])
}

fn clamp_raw(mut raw: [f64; N_RAW]) -> [f64; N_RAW] {
    for v in &mut raw[..4] {
        *v = if v.is_finite() {
            v.clamp(-RAW_LIMIT, RAW_LIMIT)
        } else {
            0.0
        };
    }
    raw
}

/// The state LM returns.
#[derive(Clone, Debug)]
pub(super) struct LmState {
    pub raw: [f64; N_RAW],
    pub normal: [f64; 3],
    pub cost: f64,
    pub albedos: Albedos<f64>,
    pub iterations: u32,
    pub converged: bool,
}

pub(super) fn chart(normal: [f64; 3]) -> Chart {
    let (t1, t2) = tangent_basis(normal);
    Chart { n0: normal, t1, t2 }
}

/// Cost (Σ r²) and albedos in `f64`.
pub(super) fn cost_at(
    problem: &Problem,
    chart: &Chart,
    raw: [f64; N_RAW],
    scratch: &mut Scratch<f64>,
) -> (f64, Albedos<f64>) {
    let x = physical(raw, &problem.bounds);
    let mut cost = 0.0;
    let albedos = problem.evaluate(chart, &x, None, scratch, &mut |r: f64| cost += r * r);
    (cost, albedos)
}

/// Cost, JᵀJ and Jᵀr (the Jacobian includes the projected albedos' derivatives).
fn jacobian_at(
    problem: &Problem,
    chart: &Chart,
    raw: [f64; N_RAW],
    scratch: &mut Scratch<RawDual>,
) -> (f64, Mat, Vector, Albedos<f64>) {
    let seeded: [RawDual; N_RAW] = core::array::from_fn(|k| Dual::variable(raw[k], k));
    let x = physical(seeded, &problem.bounds);
    let mut cost = 0.0;
    let mut jtj = Mat::zeros();
    let mut jtr = Vector::zeros();
    let albedos = problem.evaluate(chart, &x, None, scratch, &mut |r: RawDual| {
        cost += r.re * r.re;
        let g = Vector::from(r.du);
        jtj.ger(1.0, &g, &g, 1.0);
        jtr.axpy(r.re, &g, 1.0);
    });
    let re = Albedos {
        rho_d: albedos.rho_d.map(|v| v.re),
        rho_ss: albedos.rho_ss.map(|v| v.re),
    };
    (cost, jtj, jtr, re)
}

/// The Gauss–Newton decrement rᵀJ(JᵀJ)⁻¹Jᵀr: the cost decrease the undamped step predicts,
/// i.e. the squared distance to the local optimum in the metric of JᵀJ. Divided by s² it is
/// that distance in standard errors squared, so it does not stop early in flat valleys (where
/// a small actual decrease says little). JᵀJ gets a 1e-9·max-diagonal ridge so null directions
/// count as far (large decrement) only where the gradient points along them; ∞ if singular.
fn newton_decrement(jtj: &Mat, jtr: &Vector) -> f64 {
    let max_diag = (0..N_RAW).map(|i| jtj[(i, i)]).fold(0.0, f64::max);
    let mut a = *jtj;
    for i in 0..N_RAW {
        a[(i, i)] += 1e-9 * max_diag + 1e-300;
    }
    a.cholesky()
        .map_or(f64::INFINITY, |c| jtr.dot(&c.solve(jtr)))
}

/// One LM run from (`raw`, `normal`). In measurement mode the problem is first reweighted from
/// the model at the start (`Problem::reweight`); the weights then stay fixed for the run, so
/// every accepted step really lowers one fixed objective (reweighting after every step let the
/// model shrink its own weights by predicting ever brighter samples: measured, η → 61).
pub(super) fn run(
    problem: &mut Problem,
    raw: [f64; N_RAW],
    normal: [f64; 3],
    config: &SolverConfig,
    scratch_f: &mut Scratch<f64>,
    scratch_d: &mut Scratch<RawDual>,
) -> LmState {
    let mut raw = clamp_raw(raw);
    raw[4] = 0.0;
    raw[5] = 0.0;
    let mut ch = chart(normal);
    let reweighting = problem.loss == LossMode::Measurement;
    if reweighting {
        let (_, a) = cost_at(problem, &ch, raw, scratch_f);
        let _ = problem.reweight(scratch_f, &a, physical(raw, &problem.bounds).rho_s);
    }
    let (mut cost, mut jtj, mut jtr, mut albedos) = jacobian_at(problem, &ch, raw, scratch_d);
    // Statistical scale of the cost: s² = cost/(m − p) (module doc of `solve`).
    let dof = problem
        .residual_count()
        .saturating_sub(problem.parameter_count())
        .max(1) as f64;
    let mut mu = config.initial_damping;
    let mut iterations = 0;
    let mut converged = false;
    let abs_tol = 1e-28 * problem.data_scale.max(1e-300);
    if !cost.is_finite() {
        return LmState {
            raw,
            normal,
            cost,
            albedos,
            iterations,
            converged,
        };
    }
    if cost <= abs_tol {
        converged = true;
    }
    while !converged && iterations < config.max_iterations {
        iterations += 1;
        let max_diag = (0..N_RAW).map(|i| jtj[(i, i)]).fold(0.0, f64::max);
        let mut accepted = false;
        while !accepted {
            let mut a = jtj;
            for i in 0..N_RAW {
                // Marquardt scaling with a floor so flat directions are still damped.
                a[(i, i)] += mu * jtj[(i, i)].max(1e-9 * max_diag).max(1e-300);
            }
            let Some(chol) = a.cholesky() else {
                mu *= 10.0;
                if mu > 1e20 {
                    break;
                }
                continue;
            };
            let delta = chol.solve(&(-jtr));
            let mut trial = raw;
            for i in 0..N_RAW {
                trial[i] += delta[i];
            }
            let trial = {
                let mut t = clamp_raw(trial);
                t[4] = trial[4];
                t[5] = trial[5];
                t
            };
            let (trial_cost, _) = cost_at(problem, &ch, trial, scratch_f);
            if trial_cost.is_finite() && trial_cost < cost {
                accepted = true;
                let decrease = (cost - trial_cost) / cost;
                let step = delta.norm();
                let size = raw[..4].iter().map(|v| v * v).sum::<f64>().sqrt();
                // Re-centre the normal chart on the accepted normal.
                let new_normal = unit_tangent_normal(ch.n0, ch.t1, ch.t2, trial[4], trial[5]);
                ch = chart(new_normal);
                raw = trial;
                raw[4] = 0.0;
                raw[5] = 0.0;
                (cost, jtj, jtr, albedos) = jacobian_at(problem, &ch, raw, scratch_d);
                mu = (mu / 3.0).max(1e-12);
                let near_optimum = config.chi2_tolerance > 0.0
                    && newton_decrement(&jtj, &jtr) < config.chi2_tolerance * cost / dof;
                if decrease < config.relative_tolerance
                    || near_optimum
                    || step < config.step_tolerance * (size + config.step_tolerance)
                    || cost <= abs_tol
                {
                    converged = true;
                }
            } else {
                mu *= 4.0;
                if mu > 1e16 {
                    // No damped step decreases the cost: a stationary point to working precision.
                    converged = true;
                    break;
                }
            }
        }
        if !accepted && !converged {
            break;
        }
    }
    LmState {
        raw,
        normal: ch.n0,
        cost,
        albedos,
        iterations,
        converged,
    }
}
