//! The one Levenberg–Marquardt loop of the vision crate: the damping schedule, the acceptance
//! test and the stopping rules shared by single-pose refinement ([`crate::pose::refine`]) and
//! the calibration bundle ([`crate::calibrate::bundle`]). Both are the same problem class —
//! unbounded least squares of pixel reprojection error over a camera and rigid poses (left
//! updates on SE(3)) — so they take the same steps; each supplies only how it solves its damped
//! normal equations (dense 6×6 Cholesky; Schur complement over the pose blocks).
//!
//! Contract of [`minimise`] (Marquardt 1963; the λ schedule of Press et al., *Numerical Recipes*
//! §15.5):
//! - Each iteration asks the problem for the step at damping λ (`propose(state, λ)`), where the
//!   problem solves (JᵀJ + λ·D) δ = −Jᵀr with D its Marquardt diagonal. A singular damped system
//!   ([`Step::Singular`]) raises λ ×10 and counts as an iteration.
//! - A trial whose cost is finite and **not above** the current cost is accepted and λ falls ×0.1
//!   (floored at 1e-12); a trial that is worse, non-finite or invalid (`None`: a point behind the
//!   camera, an invalid camera) is rejected and λ rises ×10.
//! - It stops after `max_iterations` iterations, when λ exceeds 1e12 (no descent step at this
//!   precision), or after an accepted step whose cost decrease is ≤
//!   `relative_cost_tolerance`·cost or whose step norm is below `step_tolerance`.
//!
//! Not the `levenberg-marquardt` crate: it solves by QR on the full residual Jacobian, where
//! these problems form JᵀJ directly (6×6, or a 9×9 Schur complement for hundreds of views).
//!
//! The fit's two loops stay separate (docs/fit-solver.md "One LM per problem class"): the
//! per-vertex solver is *bounded* (projected LM with an active set, gain-ratio damping, a step
//! cap and a statistical stop) and the lobe fit is reparameterised through sigmoids with its own
//! statistical stop; both feed the recorded fit results, which must not move.

/// Damping 10× up after a rejected trial; ×0.1 down after an accepted one.
const GROW: f64 = 10.0;
/// See [`GROW`].
const SHRINK: f64 = 0.1;
/// Floor of λ after an accepted step.
const MIN_DAMPING: f64 = 1e-12;
/// λ above which no descent step exists at this precision: stop.
const MAX_DAMPING: f64 = 1e12;

/// A problem's stopping thresholds and starting damping (module contract).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Schedule {
    /// λ at the start.
    pub initial_damping: f64,
    /// Stop after an accepted step that lowered the cost by at most this fraction.
    pub relative_cost_tolerance: f64,
    /// Stop after an accepted step shorter than this (the problem's step norm; 0 = never).
    pub step_tolerance: f64,
}

/// What the problem made of one damped system.
pub(crate) enum Step<S> {
    /// The damped system could not be solved (not positive definite).
    Singular,
    /// The trial state (`None` if invalid) and the norm of the step to it.
    Tried {
        /// The state after the step, with its cost.
        trial: Option<S>,
        /// ‖δ‖ in the problem's units.
        step_norm: f64,
    },
}

/// Runs the loop from `state` (module contract); returns the final state and the iterations
/// taken.
pub(crate) fn minimise<S>(
    mut state: S,
    cost: impl Fn(&S) -> f64,
    schedule: &Schedule,
    max_iterations: usize,
    mut propose: impl FnMut(&S, f64) -> Step<S>,
) -> (S, usize) {
    let mut lambda = schedule.initial_damping;
    let mut iterations = 0;
    while iterations < max_iterations {
        iterations += 1;
        let accepted = match propose(&state, lambda) {
            Step::Singular => None,
            Step::Tried { trial, step_norm } => trial
                .filter(|t| cost(t) <= cost(&state))
                .map(|t| (t, step_norm)),
        };
        let Some((trial, step_norm)) = accepted else {
            lambda *= GROW;
            if lambda > MAX_DAMPING {
                break;
            }
            continue;
        };
        let (before, after) = (cost(&state), cost(&trial));
        let small_change = before - after <= schedule.relative_cost_tolerance * before.max(1e-300);
        let small_step = step_norm < schedule.step_tolerance;
        state = trial;
        lambda = (lambda * SHRINK).max(MIN_DAMPING);
        if small_change || small_step {
            break;
        }
    }
    (state, iterations)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rosenbrock's valley as a 2-residual least-squares problem, solved with a dense damped
    /// Gauss–Newton step: the loop must reach the minimum (1, 1).
    #[test]
    fn the_loop_solves_rosenbrock() {
        let residual = |x: [f64; 2]| [10.0 * (x[1] - x[0] * x[0]), 1.0 - x[0]];
        let cost = |x: &[f64; 2]| residual(*x).iter().map(|r| r * r).sum::<f64>();
        let schedule = Schedule {
            initial_damping: 1e-3,
            relative_cost_tolerance: 1e-14,
            step_tolerance: 1e-14,
        };
        let (x, iterations) = minimise([-1.2, 1.0], cost, &schedule, 200, |x, lambda| {
            let r = residual(*x);
            let j = [[-20.0 * x[0], 10.0], [-1.0, 0.0]];
            let jtj = |a: usize, b: usize| j[0][a] * j[0][b] + j[1][a] * j[1][b];
            let g = [
                j[0][0] * r[0] + j[1][0] * r[1],
                j[0][1] * r[0] + j[1][1] * r[1],
            ];
            let (a, b, d) = (
                jtj(0, 0) * (1.0 + lambda),
                jtj(0, 1),
                jtj(1, 1) * (1.0 + lambda),
            );
            let det = a * d - b * b;
            if det <= 0.0 {
                return Step::Singular;
            }
            let delta = [(-d * g[0] + b * g[1]) / det, (b * g[0] - a * g[1]) / det];
            Step::Tried {
                trial: Some([x[0] + delta[0], x[1] + delta[1]]),
                step_norm: delta[0].hypot(delta[1]),
            }
        });
        assert!(
            (x[0] - 1.0).abs() < 1e-6 && (x[1] - 1.0).abs() < 1e-6,
            "{x:?}"
        );
        assert!(iterations < 200);
    }

    #[test]
    fn a_problem_without_descent_stops_at_the_damping_cap() {
        let schedule = Schedule {
            initial_damping: 1.0,
            relative_cost_tolerance: 0.0,
            step_tolerance: 0.0,
        };
        let (x, iterations) = minimise(
            0.0,
            |_: &f64| 1.0,
            &schedule,
            1000,
            |_, _| Step::Tried {
                trial: Some(1.0),
                step_norm: 1.0,
            },
        );
        // every trial is as good as the state: accepted, converged at once (no decrease)
        assert_eq!((x, iterations), (1.0, 1));
        let (_, iterations) = minimise(0.0, |x: &f64| -x, &schedule, 1000, |_, _| Step::Singular);
        // 1 → 1e13 in 13 rejections
        assert_eq!(iterations, 13);
    }
}
