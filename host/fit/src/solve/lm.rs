//! Levenberg–Marquardt over the five nonlinear unknowns of one vertex inside their physical box,
//! with exact Jacobians from dual numbers (docs/fit-solver.md "Bounds" and "LM").
//!
//! Contract:
//! - The unknowns are box coordinates `x` = (η, ln σ_s, v, p, q) with σ_ss = σ_s +
//!   (1 − σ_s)·v, so every bound is a plain interval: η ∈ [η_min, η_max], ln σ_s ∈
//!   [ln σ_floor, 0], v ∈ [0, 1]; p, q (the normal's tangent coordinates) are free. No iterate
//!   ever leaves the box (σ_floor ≤ σ_s ≤ σ_ss ≤ 1 always). The albedos, ρ_s included, are not
//!   LM unknowns: they are projected out exactly inside every evaluation (`albedos.rs`).
//! - Bounds are handled by projection with an active set (projected Levenberg–Marquardt, Kanzow,
//!   Yamashita & Fukushima 2004, "Levenberg–Marquardt methods with strong local convergence
//!   properties for solving nonlinear equations with convex constraints"): an unknown at a bound
//!   whose gradient points out of the box is held there for the step, the others take the damped
//!   Gauss–Newton step, and the trial point is clipped into the box. An optimum on a bound is
//!   reached in a step or two (a sigmoid reparameterisation puts it at infinity, where LM crawls
//!   a few logit units per iteration until the iteration cap).
//! - The damping follows the gain ratio of each step (Madsen, Nielsen & Tingleff 2004, "Methods
//!   for non-linear least squares problems", §3.2). A run stops when the Gauss–Newton decrement
//!   is below `chi2_tolerance`·s², when a step the linear model mispredicted (gain < ¼) bought
//!   less than that, or on the classic relative-decrease and step tolerances.

use ellipso_model::optics::{Dual, Real};

use super::problem::{Albedos, Bounds, Chart, Nonlinear, Problem, Scratch};
use super::{LossMode, SolverConfig};

pub(super) use super::box_coords::{Mat, N_RAW, RawDual, Vector};

/// The box of the coordinates: lower and upper bound per coordinate (±∞ for p, q).
fn box_of(bounds: &Bounds) -> ([f64; N_RAW], [f64; N_RAW]) {
    (
        [
            bounds.eta_min,
            bounds.sigma_s_min.ln(),
            0.0,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
        ],
        [bounds.eta_max, 0.0, 1.0, f64::INFINITY, f64::INFINITY],
    )
}

/// `x` clipped into the box; a non-finite coordinate becomes the middle of its interval (0 for
/// p, q).
fn project(mut x: [f64; N_RAW], bounds: &Bounds) -> [f64; N_RAW] {
    let (lo, hi) = box_of(bounds);
    for i in 0..N_RAW {
        x[i] = if !x[i].is_finite() {
            if lo[i].is_finite() {
                0.5 * (lo[i] + hi[i])
            } else {
                0.0
            }
        } else {
            x[i].clamp(lo[i], hi[i])
        };
    }
    x
}

/// Physical unknowns from box coordinates (inside the box by construction; the clamps only
/// guard rounding: σ_s ≤ 1, v ∈ [0, 1]).
pub(super) fn physical<T: Real>(x: [T; N_RAW]) -> Nonlinear<T> {
    let sigma_s = x[1].exp().min_re(T::one());
    let v = x[2].clamp_re(0.0, 1.0);
    Nonlinear {
        eta: x[0],
        sigma_s,
        sigma_ss: sigma_s + (T::one() - sigma_s) * v,
        p: x[3],
        q: x[4],
    }
}

/// Box coordinates (with p = q = 0) for physical values, clipped into the box.
pub(super) fn raw_from(eta: f64, sigma_s: f64, sigma_ss: f64, bounds: &Bounds) -> [f64; N_RAW] {
    let sigma_s_c = sigma_s.clamp(bounds.sigma_s_min, 1.0);
    let v = if sigma_s_c < 1.0 {
        (sigma_ss - sigma_s_c) / (1.0 - sigma_s_c)
    } else {
        0.0
    };
    project([eta, sigma_s_c.ln(), v, 0.0, 0.0], bounds)
}

/// The state LM returns.
#[derive(Clone, Debug)]
pub(super) struct LmState {
    /// Box coordinates at the end (p = q = 0: the chart is centred on `normal`).
    pub raw: [f64; N_RAW],
    pub normal: [f64; 3],
    pub cost: f64,
    pub albedos: Albedos<f64>,
    pub iterations: u32,
    pub converged: bool,
}

/// Cost (Σ r²) and albedos in `f64`.
pub(super) fn cost_at(
    problem: &Problem,
    chart: &Chart,
    raw: [f64; N_RAW],
    scratch: &mut Scratch<f64>,
) -> (f64, Albedos<f64>) {
    let x = physical(raw);
    let mut cost = 0.0;
    let albedos = problem.evaluate(chart, &x, None, scratch, &mut |r: f64| cost += r * r);
    (cost, albedos)
}

/// Cost, JᵀJ and Jᵀr (the Jacobian includes the projected albedos' derivatives): written out
/// for the measurement loss (`jacobian.rs`), dual numbers through every residual for the paper
/// loss.
fn jacobian_at(
    problem: &Problem,
    chart: &Chart,
    raw: [f64; N_RAW],
    scratch: &mut Scratch<RawDual>,
) -> (f64, Mat, Vector, Albedos<f64>) {
    let seeded: [RawDual; N_RAW] = core::array::from_fn(|k| Dual::variable(raw[k], k));
    let x = physical(seeded);
    if problem.loss == LossMode::Measurement {
        return super::jacobian::lm_normal_equations(problem, chart, &x, scratch);
    }
    let mut ne = super::jacobian::NormalEquations::<N_RAW>::new();
    let albedos = problem.evaluate(chart, &x, None, scratch, &mut |r: RawDual| ne.add(r));
    let re = Albedos {
        rho_d: albedos.rho_d.map(|v| v.re),
        rho_ss: albedos.rho_ss.map(|v| v.re),
        rho_s: albedos.rho_s.re,
    };
    (ne.cost, ne.jtj, ne.jtr, re)
}

/// Which coordinates are held at their bound for the next step: at (within 1e-12 of the
/// interval) a bound with the gradient `jtr` pointing out of the box.
fn active_set(x: &[f64; N_RAW], jtr: &Vector, bounds: &Bounds) -> [bool; N_RAW] {
    let (lo, hi) = box_of(bounds);
    core::array::from_fn(|i| {
        if !lo[i].is_finite() {
            return false;
        }
        let eps = 1e-12 * (hi[i] - lo[i]).max(1.0);
        (x[i] <= lo[i] + eps && jtr[i] > 0.0) || (x[i] >= hi[i] - eps && jtr[i] < 0.0)
    })
}

/// JᵀJ and Jᵀr with the `active` coordinates removed (their rows and columns replaced by the
/// identity and zero), so a solve moves only the free ones.
fn restricted(jtj: &Mat, jtr: &Vector, active: &[bool; N_RAW]) -> (Mat, Vector) {
    let mut a = *jtj;
    let mut g = *jtr;
    for i in (0..N_RAW).filter(|&i| active[i]) {
        for j in 0..N_RAW {
            a[(i, j)] = 0.0;
            a[(j, i)] = 0.0;
        }
        a[(i, i)] = 1.0;
        g[i] = 0.0;
    }
    (a, g)
}

/// The Gauss–Newton decrement rᵀJ(JᵀJ)⁻¹Jᵀr over the free coordinates: the cost decrease the
/// undamped step predicts, i.e. the squared distance to the local optimum in the metric of
/// JᵀJ. Divided by s² it is that distance in standard errors squared, so it does not stop early
/// in flat valleys (where a small actual decrease says little). JᵀJ gets a 1e-9·max-diagonal
/// ridge so null directions count as far (large decrement) only where the gradient points along
/// them; ∞ if singular.
fn newton_decrement(jtj: &Mat, jtr: &Vector) -> f64 {
    let max_diag = (0..N_RAW).map(|i| jtj[(i, i)]).fold(0.0, f64::max);
    let mut a = *jtj;
    for i in 0..N_RAW {
        a[(i, i)] += 1e-9 * max_diag + 1e-300;
    }
    a.cholesky()
        .map_or(f64::INFINITY, |c| jtr.dot(&c.solve(jtr)))
}

/// Largest step of one coordinate per LM iteration: 0.5 in η, 1.5 in ln σ_s (a factor 4.5),
/// 0.5 in v, 0.35 rad (20°) for the normal's tangent coordinates. A longer step is shortened as
/// a whole, so it keeps its direction (a trust region in the box's own units).
const MAX_STEP: [f64; N_RAW] = [0.5, 1.5, 0.5, 0.35, 0.35];

/// `delta` shortened so no component exceeds [`MAX_STEP`].
fn capped_step(delta: Vector) -> Vector {
    let over = (0..N_RAW)
        .map(|i| delta[i].abs() / MAX_STEP[i])
        .fold(1.0, f64::max);
    if over.is_finite() {
        delta / over
    } else {
        delta
    }
}

/// A run's current point: its box coordinates (p = q = 0 on `chart`), and the cost, normal
/// equations and albedos there.
struct Iterate {
    raw: [f64; N_RAW],
    chart: Chart,
    cost: f64,
    jtj: Mat,
    jtr: Vector,
    albedos: Albedos<f64>,
}

/// A trial point that lowered the cost, with the decrease the linearised model predicted for
/// the step to it and that step's length.
struct Accepted {
    trial: [f64; N_RAW],
    cost: f64,
    albedos: Albedos<f64>,
    predicted: f64,
    delta_norm: f64,
}

/// What the stopping rules of [`Iterate::take`] read besides the iterate.
struct StepContext<'a> {
    config: &'a SolverConfig,
    bounds: &'a Bounds,
    /// Residuals less parameters (the statistical scale's degrees of freedom).
    dof: f64,
    /// The absolute cost floor.
    abs_tol: f64,
    /// The Gauss–Newton decrement at the point the step left.
    here: f64,
}

impl Iterate {
    /// Moves to an accepted trial point: re-centres the normal chart on it, relinearises,
    /// updates the damping `mu` by the gain ratio, and applies the stopping rules (module doc).
    /// Returns whether the run has converged.
    fn take(
        &mut self,
        step: Accepted,
        mu: &mut f64,
        context: &StepContext<'_>,
        problem: &Problem,
        scratch_d: &mut Scratch<RawDual>,
    ) -> bool {
        let StepContext {
            config,
            bounds,
            dof,
            abs_tol,
            here,
        } = *context;
        let Accepted {
            trial,
            cost: trial_cost,
            albedos: trial_albedos,
            predicted,
            delta_norm,
        } = step;
        let actual = self.cost - trial_cost;
        let decrease = actual / self.cost;
        // Gain ratio (module doc): the damping falls where the linear model predicted
        // the decrease well and rises where it did not, so a step across a kink of the
        // projected cost (an albedo meeting its bound) is not followed by an undamped
        // step straight back.
        let gain = if predicted > 0.0 {
            actual / predicted
        } else {
            0.0
        };
        let size = self.raw[..3].iter().map(|v| v * v).sum::<f64>().sqrt();
        // Re-centre the normal chart on the accepted normal.
        self.chart = Chart::at(self.chart.unit_normal(trial[3], trial[4]));
        self.raw = trial;
        self.raw[3] = 0.0;
        self.raw[4] = 0.0;
        // A nearly undamped step from within 10× the tolerance of the optimum whose
        // decrease the linear model predicted (gain ≈ 1) lands on the model's minimiser:
        // the decrement there is far below the tolerance, so the run ends without
        // relinearising (the caller evaluates what it needs at the end point).
        if config.chi2_tolerance > 0.0
            && here < 10.0 * config.chi2_tolerance * self.cost / dof
            && (0.75..=1.25).contains(&gain)
            && *mu <= 1e-2
        {
            self.cost = trial_cost;
            self.albedos = trial_albedos;
            return true;
        }
        (self.cost, self.jtj, self.jtr, self.albedos) =
            jacobian_at(problem, &self.chart, self.raw, scratch_d);
        let factor = 1.0 - (2.0 * gain - 1.0).powi(3);
        *mu = (*mu * factor.clamp(1.0 / 3.0, 2.0)).max(1e-12);
        let s2 = self.cost / dof;
        let next_active = active_set(&self.raw, &self.jtr, bounds);
        let (fj, fr) = restricted(&self.jtj, &self.jtr, &next_active);
        let near_optimum =
            config.chi2_tolerance > 0.0 && newton_decrement(&fj, &fr) < config.chi2_tolerance * s2;
        // The linear model failed (gain < ¼) and the step bought a decrease below the
        // χ² tolerance: what the model still promises lies across a kink no step can
        // take, and what is left to gain is statistically nothing.
        let stalled =
            config.chi2_tolerance > 0.0 && gain < 0.25 && actual < config.chi2_tolerance * s2;
        decrease < config.relative_tolerance
            || near_optimum
            || stalled
            || delta_norm < config.step_tolerance * (size + config.step_tolerance)
            || self.cost <= abs_tol
    }
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
    let bounds = problem.bounds;
    let mut raw = project(raw, &bounds);
    raw[3] = 0.0;
    raw[4] = 0.0;
    let chart = Chart::at(normal);
    let reweighting = problem.loss == LossMode::Measurement;
    if reweighting {
        let (_, a) = cost_at(problem, &chart, raw, scratch_f);
        let _ = problem.reweight(scratch_f, &a);
    }
    let (cost, jtj, jtr, albedos) = jacobian_at(problem, &chart, raw, scratch_d);
    let mut it = Iterate {
        raw,
        chart,
        cost,
        jtj,
        jtr,
        albedos,
    };
    // Statistical scale of the cost: s² = cost/(m − p) (module doc of `solve`).
    let dof = problem
        .residual_count()
        .saturating_sub(problem.parameter_count())
        .max(1) as f64;
    let mut mu = config.initial_damping;
    let mut iterations = 0;
    let mut converged = false;
    let abs_tol = 1e-28 * problem.data_scale.max(1e-300);
    if !it.cost.is_finite() {
        return LmState {
            raw: it.raw,
            normal,
            cost: it.cost,
            albedos: it.albedos,
            iterations,
            converged,
        };
    }
    if it.cost <= abs_tol {
        converged = true;
    }
    while !converged && iterations < config.max_iterations {
        iterations += 1;
        let active = active_set(&it.raw, &it.jtr, &bounds);
        let (free_jtj, free_jtr) = restricted(&it.jtj, &it.jtr, &active);
        // The Gauss–Newton decrement here: how far the optimum is, in cost.
        let here = newton_decrement(&free_jtj, &free_jtr);
        let max_diag = (0..N_RAW)
            .filter(|&i| !active[i])
            .map(|i| it.jtj[(i, i)])
            .fold(0.0, f64::max);
        let context = StepContext {
            config,
            bounds: &bounds,
            dof,
            abs_tol,
            here,
        };
        let mut accepted = false;
        // Growth factor of the damping on a rejected step, doubled at every rejection (Madsen,
        // Nielsen & Tingleff 2004, §3.2): a far-off linearisation is left in a few trials.
        let mut growth = 2.0;
        while !accepted {
            let mut a = free_jtj;
            for i in (0..N_RAW).filter(|&i| !active[i]) {
                // Marquardt scaling with a floor so flat directions are still damped.
                a[(i, i)] += mu * it.jtj[(i, i)].max(1e-9 * max_diag).max(1e-300);
            }
            let Some(chol) = a.cholesky() else {
                mu *= 10.0;
                if mu > 1e20 {
                    break;
                }
                continue;
            };
            let proposed = capped_step(chol.solve(&(-free_jtr)));
            let trial = {
                let mut t = it.raw;
                for i in 0..N_RAW {
                    t[i] += proposed[i];
                }
                project(t, &bounds)
            };
            // The step actually taken (clipped into the box) and the decrease the linearised
            // model predicts for it: |r|² − |r + Jδ|² = −2δᵀJᵀr − δᵀJᵀJδ.
            let delta = Vector::from_fn(|i, _| trial[i] - it.raw[i]);
            let predicted = -2.0 * delta.dot(&it.jtr) - delta.dot(&(it.jtj * delta));
            let (trial_cost, trial_albedos) = cost_at(problem, &it.chart, trial, scratch_f);
            if trial_cost.is_finite() && trial_cost < it.cost {
                accepted = true;
                let step = Accepted {
                    trial,
                    cost: trial_cost,
                    albedos: trial_albedos,
                    predicted,
                    delta_norm: delta.norm(),
                };
                converged = it.take(step, &mut mu, &context, problem, scratch_d);
            } else {
                mu *= growth;
                growth *= 2.0;
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
        raw: it.raw,
        normal: it.chart.n0,
        cost: it.cost,
        albedos: it.albedos,
        iterations,
        converged,
    }
}
