//! The per-vertex solver of the polarimetric SVBRDF fit: box-constrained Levenberg–Marquardt
//! with exact Jacobians, the albedos by variable projection, standard errors and honest flags
//! (docs/model.md §11; docs/fit-solver.md has the derivations and measured numbers).
//!
//! # API
//! - [`fit_vertex`]`(views, vertex, colour, init, guide, config) -> VertexFit`
//! - [`fit_all`]`(set, init, guides, config) -> Vec<VertexFit>`: rayon over vertices,
//!   bit-identical for any thread count (no reduction crosses vertices).
//! - [`forward_cost_all`]`(set, fits) -> ForwardCost`: the model evaluated once per observation
//!   (f64, no derivatives): the unit the benchmark divides fit time by.
//!
//! # Unknowns and bounds (docs/fit-solver.md, "Bounds")
//! Every unknown has a physical range. LM unknowns (`lm.rs`), box coordinates handled by
//! projection with an active set: η ∈ [η_min, η_max] (default [1.1, 3], the paper's);
//! ln σ_s ∈ [ln σ_floor, 0] with σ_floor the larger of `sigma_min` and the guide's cluster floor;
//! v ∈ [0, 1] with σ_ss = σ_s + (1 − σ_s)·v (so σ_floor ≤ σ_s ≤ σ_ss ≤ 1); the normal's tangent
//! coordinates p, q (normal = normalise(n0 + p·t1 + q·t2), re-centred on the tangent plane of the
//! current normal after every accepted step). Projected (linear) unknowns (`albedos.rs`): ρ_d and
//! ρ_ss per colour channel and ρ_s, by exact box-constrained least squares in [0, cap] inside
//! every evaluation; the LM Jacobian includes the projection's derivative (`jacobian.rs`).
//!
//! # Priors (measurement mode)
//! Weak priors make directions the data leaves flat well defined instead of letting them run
//! to a bound: ln σ_s and ln σ_ss (a lobe seen only in its tail fixes only ρ_s·σ_s², so without
//! them σ_s runs to its floor and ρ_s to its cap), η (weak by default; the cluster's pooled η in
//! the final pass, which is how per-vertex η borrows strength from its material), and the
//! normal's tilt from the mesh normal (a prior cone: dark vertices cannot swing 30°).
//!
//! # Residuals and weights (docs/model.md §11 "Loss terms")
//! See `problem.rs`. Defaults λψ = 10, λd = λs = λφ = 1 (the released code's values). With
//! virtual samples, real specular residuals weigh (1 − λg)·λs each and a virtual sample of weight
//! w (weights sum to λg) weighs λs·N_real·w, i.e. the paper's (1 − λg)/N_real : w proportion,
//! scaled so the real specular term keeps the diffuse term's per-sample scale.
//! Optional noise weighting ([`SolverConfig::noise_weighting`]): intensity and azimuth residuals
//! weigh N/s0, DoP residuals N·s0 (shot-noise-limited inverse variances in model units), each
//! normalised to mean 1 over the vertex.
//!
//! # Flags (exact triggers)
//! - `TooFewViews`: fewer usable samples than `min_views`; parameters are the prior
//!   (`init`, else [`SolverConfig::prior`] with ρ_d from the data), std errors ∞.
//! - `Unobserved` (with `TooFewViews`): no sample, and no frame saw the vertex lit (every frame
//!   had it out of view, occluded or in the flash's shadow): no fitted view sees it. Seen but
//!   every sample gated is `TooFewViews` alone.
//! - `UnderDetermined`: fewer samples than unknowns (12 colour, 8 monochrome).
//! - `Dark`: more samples gated dark than kept, or the kept samples' mean diffuse signal
//!   (I^d·N) below `dark_signal_dn`.
//! - `Saturated`: saturated samples exceed `saturated_fraction` of (kept + saturated).
//! - `EtaUnidentifiable`: std error of η above `max_eta_std_error` (incl. ∞); η within
//!   `bound_margin_eta` of either end of its range (with `AtBound`: a value pinned at a bound
//!   is no measurement); without a pooled prior also when max over samples of |∂DoP_d/∂η| at
//!   the solution is below `min_eta_sensitivity`, or the polarisation SNR (mean model DoP_d /
//!   RMS of the DoP residuals) is below 1, or — measurement loss — the data carry less
//!   information on η than its prior ((JᵀJ)⁻¹_ηη of the whitened rows, prior row included,
//!   above half the prior's variance: the data did not move η from its start, whatever the
//!   recorded noise claims; with a pooled prior η comes from the material, and its std error —
//!   the posterior's — says how well).
//! - `GrazingOnly`: every sample views more than `grazing_only_deg` from the fitted normal, or
//!   more samples were gated grazing than kept.
//! - `AtBound`: η within `bound_margin_eta` of either end of its range, σ_s within
//!   `bound_margin_sigma` of its floor, σ_ss within it of 1, ρ_s, any ρ_ss or any ρ_d within
//!   0.1 % of the albedo cap, or the normal more than 2.5 prior-cone widths from the mesh
//!   normal.
//! - `NotConverged`: the last pass stopped at `max_iterations` (or the damping overflowed).
//! - `AlbedoAtCap`: ρ_s, any ρ_ss or any ρ_d within 0.1 % of the albedo cap (also `AtBound`;
//!   this one withholds the vertex from every output, `data::FitFlag::withholds_vertex`).
//!
//! Every returned parameter is finite and inside its bounds (`PbrdfParams::validate`).
//!
//! Here: the per-vertex driver (flags from the gates, starts, coarse to fine, passes) and
//! [`fit_all`]; the settings are in `config`, the step from a finished LM state to a
//! [`VertexFit`] (errors, flags, the prior result) in `finish`, [`forward_cost_all`] in
//! `forward`, one vertex's least-squares problem in `problem`.

mod albedos;
mod box_coords;
mod config;
mod finish;
mod forward;
mod jacobian;
mod lm;
mod problem;
mod uncertainty;

#[cfg(test)]
mod hard_cases;
#[cfg(test)]
pub(crate) mod tests;

use std::cmp::Ordering;

use rayon::prelude::*;

pub use config::{Effort, LossMode, SensorNoiseModel, SolverConfig};
pub use forward::{ForwardCost, forward_cost_all};

use super::data::{FitFlag, SampleSet, VertexFit, VertexGuide, VertexSamples, ViewGeometry};
use finish::{finish, prior_fit};
use lm::{LmState, RawDual, physical, raw_from};

use problem::{Bounds, Chart, Problem, Scratch};

/// The guide of a vertex without one (no virtual samples, no floor, the default priors).
static NO_GUIDE: VertexGuide = VertexGuide {
    virtual_samples: Vec::new(),
    sigma_s_floor: 0.0,
    eta_prior: None,
    lobe_start: None,
};

fn unit(v: [f64; 3]) -> Option<[f64; 3]> {
    let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    (l.is_finite() && l > 1e-12).then(|| v.map(|x| x / l))
}

/// Fits one vertex (see the module doc). `init` warm-starts every parameter and the normal
/// (η is not reset, unlike the released code's step A: docs/model.md §11 "Steps A, B, C and the
/// outer loop"); `guide` carries the shared steps' virtual samples, σ_s floor, pooled η prior
/// and cluster lobe (a second start beside `init`; the better initial cost runs first).
pub fn fit_vertex(
    views: &[ViewGeometry],
    vertex: &VertexSamples,
    colour: bool,
    init: Option<&VertexFit>,
    guide: &VertexGuide,
    config: &SolverConfig,
) -> VertexFit {
    let mut problem = Problem::new(views, vertex, colour, guide, config);
    let n = problem.len();
    let mut flags = gate_flags(&problem, vertex, colour, config);
    let start_normal = start_normal(vertex, init);
    if n < config.min_views.max(1) {
        flags.push(FitFlag::TooFewViews);
        if vertex.samples.is_empty() && vertex.gates.seen_lit() == 0 {
            flags.push(FitFlag::Unobserved);
        }
        return prior_fit(&problem, vertex, start_normal, init, flags, config);
    }
    let virtuals = problem.virtuals.len();
    let mut scratch_f = Scratch::<f64>::new(n, virtuals);
    let mut scratch_d = Scratch::<RawDual>::new(n, virtuals);
    let starts = lm_starts(init, guide, &problem.bounds, config);
    let adaptive = config.effort == Effort::Adaptive;
    let rank = starts.len() > 1 && (adaptive || init.is_some());
    // Coarse to fine: a cold start ranks its starts and runs LM on a subsample of the views,
    // then LM runs on every sample from that result.
    let mut coarse =
        coarse_subset(&problem, init.is_none(), config).map(|keep| problem.subset(&keep));
    let first = best_start(
        coarse.as_mut().unwrap_or(&mut problem),
        &starts,
        start_normal,
        rank,
        config,
        &mut scratch_f,
        &mut scratch_d,
    );
    let mut state = if coarse.is_some() {
        let fine = lm::run(
            &mut problem,
            first.raw,
            first.normal,
            config,
            &mut scratch_f,
            &mut scratch_d,
        );
        LmState {
            iterations: first.iterations + fine.iterations,
            ..fine
        }
    } else {
        first
    };
    let measurement = problem.loss == LossMode::Measurement;
    further_passes(
        &mut problem,
        &mut state,
        config,
        &mut scratch_f,
        &mut scratch_d,
    );
    // The unit lobes at the final state, with their DoP fields (for the flags), and from them
    // the weights at the final state (for the standard errors).
    let x = physical(state.raw);
    problem.units_at(&Chart::at(state.normal), &x, true, &mut scratch_f);
    if measurement {
        let _ = problem.reweight(&scratch_f, &state.albedos);
    }
    finish(&problem, vertex, state, flags, guide, config, &scratch_f)
}

/// The flags the gates and the sample count decide before any fit: `UnderDetermined`, `Dark`,
/// `Saturated` and `GrazingOnly` (see the module doc for their triggers).
fn gate_flags(
    problem: &Problem,
    vertex: &VertexSamples,
    colour: bool,
    config: &SolverConfig,
) -> Vec<FitFlag> {
    let n = problem.len();
    let unknowns = if colour { 12 } else { 8 };
    let mut flags = Vec::new();
    if n < unknowns {
        flags.push(FitFlag::UnderDetermined);
    }
    let g = &vertex.gates;
    let mean_signal_dn = if n > 0 {
        problem
            .obs
            .iter()
            .enumerate()
            .map(|(k, o)| {
                let s: f64 = o.iter().take(problem.channels).map(|c| c[0]).sum();
                s / problem.channels as f64 * problem.normalisers[k]
            })
            .sum::<f64>()
            / n as f64
    } else {
        0.0
    };
    if g.dark > g.kept || (n > 0 && mean_signal_dn < config.dark_signal_dn) {
        flags.push(FitFlag::Dark);
    }
    if g.saturated > 0
        && g.saturated as f64 > config.saturated_fraction * (g.kept + g.saturated) as f64
    {
        flags.push(FitFlag::Saturated);
    }
    if g.grazing > g.kept {
        flags.push(FitFlag::GrazingOnly);
    }
    flags
}

/// The normal the fit starts from: `init`'s where it is a usable direction, else the mesh
/// normal, else +z; unit length.
fn start_normal(vertex: &VertexSamples, init: Option<&VertexFit>) -> [f64; 3] {
    let start_normal = init
        .map(|f| f.normal_world)
        .filter(|v| unit(*v).is_some())
        .or_else(|| unit(vertex.normal_world))
        .unwrap_or([0.0, 0.0, 1.0]);
    unit(start_normal).unwrap_or([0.0, 0.0, 1.0])
}

/// The LM starts (raw coordinates): from `init` and the guide's pooled η and cluster lobes on a
/// warm start, the configured cold starts otherwise, and the prior when that leaves none.
fn lm_starts(
    init: Option<&VertexFit>,
    guide: &VertexGuide,
    bounds: &Bounds,
    config: &SolverConfig,
) -> Vec<[f64; lm::N_RAW]> {
    let mut starts: Vec<[f64; lm::N_RAW]> = match init {
        Some(f) => {
            let p = &f.params;
            // A warm start may sit on a bound: the projected LM leaves it as soon as the
            // gradient points into the box (lm.rs).
            let mut s = vec![raw_from(p.eta, p.sigma_s, p.sigma_ss, bounds)];
            if let Some([eta, _]) = guide.eta_prior {
                // The vertex's own lobes at the material's η: the starts are ranked by their
                // cost, where an own η a few prior widths off would outweigh everything else
                // although LM corrects it in one step.
                s.push(raw_from(eta, p.sigma_s, p.sigma_ss, bounds));
            }
            if let Some([sigma_s, sigma_ss, _]) = guide.lobe_start {
                // The cluster's lobes with the material's η where it is pooled (the albedos,
                // ρ_s included, are projected: only the lobe shapes are a start), and its sharp
                // lobe with the broader of its and the vertex's own second lobe. Where the two
                // lobes would start (nearly) equal — a cluster that saw one lobe returns
                // σss = σs — the second starts at 3σs: on equal lobes the split of the light
                // between them is undetermined and LM cannot tell which way to separate them.
                let eta = guide.eta_prior.map_or(p.eta, |prior| prior[0]);
                if sigma_ss >= 1.5 * sigma_s {
                    s.push(raw_from(eta, sigma_s, sigma_ss, bounds));
                }
                let mut broad = sigma_ss.max(p.sigma_ss);
                if broad < 1.5 * sigma_s {
                    broad = (3.0 * sigma_s).min(1.0);
                }
                if broad != sigma_ss {
                    s.push(raw_from(eta, sigma_s, broad, bounds));
                }
            }
            s
        }
        None => config
            .cold_starts
            .iter()
            .map(|s| raw_from(s[0], s[1], s[2], bounds))
            .collect(),
    };
    if starts.is_empty() {
        let p = config.prior;
        starts.push(raw_from(p[0], p[1], p[2], bounds));
    }
    starts
}

/// Passes 2…[`SolverConfig::passes`] from `state` (updated in place): each reweights first in
/// measurement mode; adaptive effort stops once converged and the weights moved ≤ 10 %.
fn further_passes(
    problem: &mut Problem,
    state: &mut LmState,
    config: &SolverConfig,
    scratch_f: &mut Scratch<f64>,
    scratch_d: &mut Scratch<RawDual>,
) {
    let adaptive = config.effort == Effort::Adaptive;
    let measurement = problem.loss == LossMode::Measurement;
    for _ in 1..config.passes {
        // Measurement mode: the weights at the current solution (the run used the weights of
        // its start); another pass only if they moved by more than 10 %.
        let moved = if measurement {
            reweight_at(problem, state, scratch_f)
        } else {
            0.0
        };
        if adaptive && state.converged && moved <= 0.1 {
            break;
        }
        let again = lm::run(
            problem,
            state.raw,
            state.normal,
            config,
            scratch_f,
            scratch_d,
        );
        let iterations = again.iterations;
        // Measurement mode: a later pass has better weights, so its cost is not comparable;
        // it is kept whenever it is finite.
        if again.cost <= state.cost || (measurement && again.cost.is_finite()) {
            *state = again;
        } else {
            state.iterations = iterations;
        }
    }
}

/// LM from the best of `starts`: ranked by their cost at `start_normal` when `rank` (one f64
/// evaluation each), then run in that order; with adaptive effort the next start runs only
/// when the result so far is [`poor`]. The lowest cost wins.
fn best_start(
    problem: &mut Problem,
    starts: &[[f64; lm::N_RAW]],
    start_normal: [f64; 3],
    rank: bool,
    config: &SolverConfig,
    scratch_f: &mut Scratch<f64>,
    scratch_d: &mut Scratch<RawDual>,
) -> LmState {
    let mut starts = starts.to_vec();
    if rank {
        let ch = Chart::at(start_normal);
        let mut ranked: Vec<(f64, [f64; lm::N_RAW])> = starts
            .iter()
            .map(|s| {
                let (c, _) = lm::cost_at(problem, &ch, *s, scratch_f);
                (if c.is_finite() { c } else { f64::INFINITY }, *s)
            })
            .collect();
        ranked.sort_by(|a, b| a.0.total_cmp(&b.0));
        starts = ranked.into_iter().map(|(_, s)| s).collect();
    }
    let adaptive = config.effort == Effort::Adaptive;
    let mut best: Option<LmState> = None;
    for (k, s) in starts.iter().enumerate() {
        if adaptive && k > 0 && best.as_ref().is_some_and(|b| !poor(problem, b, config)) {
            break;
        }
        let st = lm::run(problem, *s, start_normal, config, scratch_f, scratch_d);
        if best.as_ref().is_none_or(|b| {
            !matches!(
                b.cost.partial_cmp(&st.cost),
                Some(Ordering::Less | Ordering::Equal)
            )
        }) {
            best = Some(st);
        }
    }
    best.expect("at least one start")
}

/// The samples of the coarse level of a cold start (`cold`, no virtual samples), or `None`
/// when the vertex has fewer than twice [`SolverConfig::coarse_samples`]: that many samples
/// spread evenly along the capture (samples come in view order), with the brightest specular
/// sample among them (the one a sharp lobe is seen in).
fn coarse_subset(problem: &Problem, cold: bool, config: &SolverConfig) -> Option<Vec<usize>> {
    let n = problem.len();
    let m = config.coarse_samples;
    if !cold || m == 0 || n < 2 * m || !problem.virtuals.is_empty() {
        return None;
    }
    let mut keep: Vec<usize> = (0..m).map(|k| ((2 * k + 1) * n) / (2 * m)).collect();
    let brightest = (0..n)
        .max_by(|&a, &b| problem.mono[a][1].total_cmp(&problem.mono[b][1]))
        .unwrap_or(0);
    if !keep.contains(&brightest) {
        let nearest = keep
            .iter()
            .enumerate()
            .min_by_key(|(_, k)| k.abs_diff(brightest))
            .map_or(0, |(i, _)| i);
        keep[nearest] = brightest;
        keep.sort_unstable();
    }
    Some(keep)
}

/// Measurement mode: reweights `problem` from the model at `state`; returns the largest
/// relative change of any 1/σ.
fn reweight_at(problem: &mut Problem, state: &LmState, scratch: &mut Scratch<f64>) -> f64 {
    let (_, albedos) = lm::cost_at(problem, &Chart::at(state.normal), state.raw, scratch);
    problem.reweight(scratch, &albedos)
}

/// Adaptive effort: whether a start's result warrants trying the next start.
fn poor(problem: &Problem, state: &LmState, config: &SolverConfig) -> bool {
    if !state.converged || !state.cost.is_finite() {
        return true;
    }
    // A lobe at its bound often means the start's basin, not the data (noiseless glaze from
    // (0.1, 0.3): σ_ss → 1, Δcost 1.1 above the truth's 0).
    let x = physical(state.raw);
    if x.sigma_s < problem.bounds.sigma_s_min + config.bound_margin_sigma
        || x.sigma_ss > 1.0 - config.bound_margin_sigma
    {
        return true;
    }
    if problem.loss != LossMode::Measurement {
        return false;
    }
    let m = problem.residual_count();
    let p = problem.parameter_count();
    m > p && state.cost / (m - p) as f64 > config.restart_reduced_chi2
}

/// Fits every vertex of `set` in parallel (rayon); `init` and `guides`, when given, are indexed
/// like `set.vertices`. Deterministic for any thread count.
pub fn fit_all(
    set: &SampleSet,
    init: Option<&[VertexFit]>,
    guides: Option<&[VertexGuide]>,
    config: &SolverConfig,
) -> Vec<VertexFit> {
    set.vertices
        .par_iter()
        .enumerate()
        .map(|(i, v)| {
            let warm = init.and_then(|f| f.get(i));
            let guide = guides.and_then(|g| g.get(i)).unwrap_or(&NO_GUIDE);
            fit_vertex(&set.views, v, set.colour, warm, guide, config)
        })
        .collect()
}
