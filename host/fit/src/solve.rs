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

mod albedos;
mod jacobian;
mod lm;
mod problem;
mod uncertainty;

#[cfg(test)]
mod hard_cases;
#[cfg(test)]
pub(crate) mod tests;

use std::cmp::Ordering;

use ellipso_model::optics::measure::dop_diffuse_with_d_eta;
use ellipso_model::optics::pbrdf::PbrdfParams;
use rayon::prelude::*;

use super::data::{FitFlag, SampleSet, VertexFit, VertexGuide, VertexSamples, ViewGeometry};
use super::model::unit_sample_at;
use lm::{LmState, RawDual, physical, raw_from};

use problem::{Albedos, Chart, Problem, Scratch};

/// The guide of a vertex without one (no virtual samples, no floor, the default priors).
static NO_GUIDE: VertexGuide = VertexGuide {
    virtual_samples: Vec::new(),
    sigma_s_floor: 0.0,
    eta_prior: None,
    lobe_start: None,
};

/// Which least-squares loss the solver minimises (docs/fit-solver.md, docs/model.md §11 "Loss
/// terms").
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum LossMode {
    /// The paper's four terms L_d, L_s, L_ψ (DoP ratio), L_φ (azimuth with the observed DP),
    /// weighted by the λ's (reproduction; the DoP ratio is Rice-biased on dark samples).
    Paper,
    /// The observation channels I^d, I^s, I^α themselves, each residual whitened by its
    /// predicted shot + read noise (iteratively reweighted); no ratio of noisy quantities, so the
    /// estimate is asymptotically unbiased. λψ, λd, λφ and `noise_weighting` do not apply.
    Measurement,
}

/// How much effort the solver spends on starts and passes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Effort {
    /// Every cold start is run to convergence and every pass is run (the first solver's
    /// behaviour; ~4 LM runs per cold vertex).
    Exhaustive,
    /// Cold starts are ranked by their initial cost and LM runs from the best; the others are
    /// tried only when that run ends unconverged, with a roughness at its bound (`AtBound`'s σ
    /// margins), or (measurement mode) with a reduced χ² above `restart_reduced_chi2`. A later pass runs only when the previous one did not converge.
    Adaptive,
}

/// The sensor's noise, for the measurement-mode weights (DN = N × model units).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SensorNoiseModel {
    /// DN per photo-electron (shot-noise variance of a pixel = g·DN).
    pub dn_per_electron: f64,
    /// Read noise, DN RMS (quantisation's 1/12 DN² is added to its square).
    pub read_noise_dn: f64,
}

impl Default for SensorNoiseModel {
    /// The shipped IMX250 scenes at 0 dB: 4095 DN / 10 500 e⁻ full well ≈ 0.39 DN/e⁻, 2.3 e⁻
    /// read noise ≈ 0.9 DN. Only the ratio of read to shot noise matters for the fit (the
    /// overall scale cancels), so a gain off by 2× changes the weights of the darkest samples
    /// only.
    fn default() -> Self {
        Self {
            dn_per_electron: 0.39,
            read_noise_dn: 0.9,
        }
    }
}

/// Solver settings. `Default` gives the documented values.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SolverConfig {
    /// The loss (default [`LossMode::Measurement`]; docs/fit-solver.md has the measurement).
    pub loss: LossMode,
    /// Starts and passes (default [`Effort::Adaptive`]).
    pub effort: Effort,
    /// Sensor noise for the measurement-mode weights.
    pub sensor: SensorNoiseModel,
    /// LM iteration cap per pass (default 50).
    pub max_iterations: u32,
    /// LM passes from the best start; each later pass restarts the damping (default 2; with
    /// [`Effort::Adaptive`] a later pass runs only after an unconverged one).
    pub passes: u32,
    /// Samples of the coarse level of a cold start (default 24; 0 disables): a vertex with at
    /// least twice as many first runs its starts on that many samples spread along the capture,
    /// then LM on all of them from the result (coarse to fine).
    pub coarse_samples: usize,
    /// Cold starts (η, σ_s, σ_ss) tried without `init` (default (1.5, 0.1, 0.3) and
    /// (1.5, 0.4, 0.8)); see [`Effort`].
    pub cold_starts: Vec<[f64; 3]>,
    /// Adaptive effort, measurement mode: a cold-start result with reduced χ² above this tries
    /// the other cold starts (default 4: ≈ 1 at a good fit with the right sensor model; 4 leaves
    /// room for a gain off by 2× and mild model error).
    pub restart_reduced_chi2: f64,
    /// LM also stops when the Gauss–Newton decrement (the cost decrease the undamped step
    /// predicts) is below this × s², s² = cost/(m − p): the parameters are then within ~√tol
    /// standard errors of the local optimum (default 1e-3; 0 disables).
    pub chi2_tolerance: f64,
    /// Weight of L_ψ (DoP) (default 10).
    pub lambda_psi: f64,
    /// Weight of L_d (default 1).
    pub lambda_d: f64,
    /// Weight of L_s (default 1).
    pub lambda_s: f64,
    /// Weight of L_φ (azimuth) (default 1).
    pub lambda_phi: f64,
    /// λg: total weight of virtual samples relative to real specular ones (default 0.1).
    pub lambda_g: f64,
    /// Floor of both roughnesses (default 0.01; docs/model.md §12, σ → 0).
    pub sigma_min: f64,
    /// Range of η (default [1.1, 3], the paper's bounds; dielectrics of everyday materials lie
    /// in it, and η → 1 — no polarisation — is flagged at the lower end).
    pub eta_bounds: [f64; 2],
    /// Upper bound of ρ_s, ρ_ss and ρ_d, model units (default 5: the paper caps ρ_s at 5·mean N
    /// in raw units; our samples are divided by N, so 5 is the same cap. Physical albedos are
    /// ≤ 1, so 5 leaves room for a radiometric calibration off by that much).
    pub albedo_cap: f64,
    /// Weak prior on η, (mean, sd) (default (1.5, 0.5)); replaced by a guide's pooled prior.
    pub eta_prior: [f64; 2],
    /// Prior on σ_s, (median, sd of ln σ_s) (default (0.2, 1.2): 95 % within ×10.5 of 0.2).
    pub sigma_s_prior: [f64; 2],
    /// Prior on σ_ss, (median, sd of ln σ_ss) (default (0.4, 1.2)).
    pub sigma_ss_prior: [f64; 2],
    /// 1σ width of the prior cone of the normal about the mesh normal, degrees (default 10;
    /// 0 disables).
    pub normal_prior_deg: f64,
    /// Weight residuals by shot-noise inverse variance from N (default false: the paper's
    /// uniform weights).
    pub noise_weighting: bool,
    /// Minimum usable samples (default 12 = `GateConfig::default().min_views`).
    pub min_views: usize,
    /// LM stops when the relative cost decrease of an accepted step is below this (1e-10).
    pub relative_tolerance: f64,
    /// LM stops when the step is below this relative to the raw parameters (1e-9).
    pub step_tolerance: f64,
    /// Initial Marquardt damping (1e-3).
    pub initial_damping: f64,
    /// `EtaUnidentifiable` when max |∂DoP/∂η| is below this (0.02 ≈ 25° view at η = 1.5).
    pub min_eta_sensitivity: f64,
    /// `EtaUnidentifiable` when the std error of η exceeds this (0.05).
    pub max_eta_std_error: f64,
    /// `GrazingOnly` when all views are beyond this angle from the normal, degrees (65).
    pub grazing_only_deg: f64,
    /// `Dark` when the mean diffuse signal is below this many DN (8).
    pub dark_signal_dn: f64,
    /// `Saturated` when saturated samples exceed this fraction of kept + saturated (0.05).
    pub saturated_fraction: f64,
    /// `AtBound` margin on η from either end of its range (0.005).
    pub bound_margin_eta: f64,
    /// `AtBound` margin on σ_s above σ_min and σ_ss below 1 (1e-3).
    pub bound_margin_sigma: f64,
    /// Prior (η, σ_s, σ_ss, ρ_s, ρ_ss) for vertices that cannot be fitted (1.5, 0.2, 0.5, 0.5, 0).
    pub prior: [f64; 5],
}

impl Default for SolverConfig {
    fn default() -> Self {
        Self {
            loss: LossMode::Measurement,
            effort: Effort::Adaptive,
            sensor: SensorNoiseModel::default(),
            max_iterations: 50,
            passes: 2,
            coarse_samples: 24,
            cold_starts: vec![[1.5, 0.1, 0.3], [1.5, 0.4, 0.8]],
            restart_reduced_chi2: 4.0,
            chi2_tolerance: 1e-3,
            lambda_psi: 10.0,
            lambda_d: 1.0,
            lambda_s: 1.0,
            lambda_phi: 1.0,
            lambda_g: 0.1,
            sigma_min: 0.01,
            eta_bounds: [1.1, 3.0],
            albedo_cap: 5.0,
            eta_prior: [1.5, 0.5],
            sigma_s_prior: [0.2, 1.2],
            sigma_ss_prior: [0.4, 1.2],
            normal_prior_deg: 10.0,
            noise_weighting: true,
            min_views: 12,
            relative_tolerance: 1e-10,
            step_tolerance: 1e-9,
            initial_damping: 1e-3,
            min_eta_sensitivity: 0.02,
            max_eta_std_error: 0.05,
            grazing_only_deg: 65.0,
            dark_signal_dn: 8.0,
            saturated_fraction: 0.05,
            bound_margin_eta: 0.005,
            bound_margin_sigma: 1e-3,
            prior: [1.5, 0.2, 0.5, 0.5, 0.0],
        }
    }
}

impl SolverConfig {
    /// The first solver's settings, for reproduction and before/after comparisons: paper loss
    /// (noise-weighted), every cold start and pass run, 100 iterations, only the relative and
    /// step tolerances.
    pub fn reference() -> Self {
        Self {
            loss: LossMode::Paper,
            effort: Effort::Exhaustive,
            max_iterations: 100,
            chi2_tolerance: 0.0,
            ..Self::default()
        }
    }

    /// The paper's loss with the default (adaptive) effort.
    pub fn paper() -> Self {
        Self {
            loss: LossMode::Paper,
            ..Self::default()
        }
    }

    /// Throughput preset (docs/fit-solver.md has its measured cost in accuracy): measurement
    /// loss, one start and one pass, at most 12 iterations, χ² tolerance 1e-2 (~0.1 σ), no
    /// fallback restart. Meant for many-vertex runs and warm-started passes.
    pub fn fast() -> Self {
        Self::default().with_fast_effort()
    }

    /// These settings without any prior (infinite widths, no normal cone): the data alone
    /// decides (tests of exact recovery, reproductions of the first solver).
    pub fn without_priors(&self) -> Self {
        Self {
            eta_prior: [self.eta_prior[0], f64::INFINITY],
            sigma_s_prior: [self.sigma_s_prior[0], f64::INFINITY],
            sigma_ss_prior: [self.sigma_ss_prior[0], f64::INFINITY],
            normal_prior_deg: 0.0,
            ..self.clone()
        }
    }

    /// These settings with the [`SolverConfig::fast`] preset's effort (iterations, passes,
    /// tolerance, no fallback restart); loss, sensor, bounds and priors unchanged.
    pub fn with_fast_effort(&self) -> Self {
        Self {
            max_iterations: 12,
            passes: 1,
            chi2_tolerance: 1e-2,
            restart_reduced_chi2: f64::INFINITY,
            ..self.clone()
        }
    }
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
    let start_normal = init
        .map(|f| f.normal_world)
        .filter(|v| unit(*v).is_some())
        .or_else(|| unit(vertex.normal_world))
        .unwrap_or([0.0, 0.0, 1.0]);
    let start_normal = unit(start_normal).unwrap_or([0.0, 0.0, 1.0]);
    if n < config.min_views.max(1) {
        flags.push(FitFlag::TooFewViews);
        if vertex.samples.is_empty() && g.seen_lit() == 0 {
            flags.push(FitFlag::Unobserved);
        }
        return prior_fit(&problem, vertex, start_normal, init, flags, config);
    }
    let bounds = problem.bounds;
    let virtuals = problem.virtuals.len();
    let mut scratch_f = Scratch::<f64>::new(n, virtuals);
    let mut scratch_d = Scratch::<RawDual>::new(n, virtuals);
    let mut starts: Vec<[f64; lm::N_RAW]> = match init {
        Some(f) => {
            let p = &f.params;
            // A warm start may sit on a bound: the projected LM leaves it as soon as the
            // gradient points into the box (lm.rs).
            let mut s = vec![raw_from(p.eta, p.sigma_s, p.sigma_ss, &bounds)];
            if let Some([eta, _]) = guide.eta_prior {
                // The vertex's own lobes at the material's η: the starts are ranked by their
                // cost, where an own η a few prior widths off would outweigh everything else
                // although LM corrects it in one step.
                s.push(raw_from(eta, p.sigma_s, p.sigma_ss, &bounds));
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
                    s.push(raw_from(eta, sigma_s, sigma_ss, &bounds));
                }
                let mut broad = sigma_ss.max(p.sigma_ss);
                if broad < 1.5 * sigma_s {
                    broad = (3.0 * sigma_s).min(1.0);
                }
                if broad != sigma_ss {
                    s.push(raw_from(eta, sigma_s, broad, &bounds));
                }
            }
            s
        }
        None => config
            .cold_starts
            .iter()
            .map(|s| raw_from(s[0], s[1], s[2], &bounds))
            .collect(),
    };
    if starts.is_empty() {
        let p = config.prior;
        starts.push(raw_from(p[0], p[1], p[2], &bounds));
    }
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
    for _ in 1..config.passes {
        // Measurement mode: the weights at the current solution (the run used the weights of
        // its start); another pass only if they moved by more than 10 %.
        let moved = if measurement {
            reweight_at(&mut problem, &state, &mut scratch_f)
        } else {
            0.0
        };
        if adaptive && state.converged && moved <= 0.1 {
            break;
        }
        let again = lm::run(
            &mut problem,
            state.raw,
            state.normal,
            config,
            &mut scratch_f,
            &mut scratch_d,
        );
        let iterations = again.iterations;
        // Measurement mode: a later pass has better weights, so its cost is not comparable;
        // it is kept whenever it is finite.
        if again.cost <= state.cost || (measurement && again.cost.is_finite()) {
            state = again;
        } else {
            state.iterations = iterations;
        }
    }
    // The unit lobes at the final state, with their DoP fields (for the flags), and from them
    // the weights at the final state (for the standard errors).
    let x = physical(state.raw);
    problem.units_at(&Chart::at(state.normal), &x, true, &mut scratch_f);
    if measurement {
        let _ = problem.reweight(&scratch_f, &state.albedos);
    }
    finish(&problem, vertex, state, flags, guide, config, &scratch_f)
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

fn unit(v: [f64; 3]) -> Option<[f64; 3]> {
    let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    (l.is_finite() && l > 1e-12).then(|| v.map(|x| x / l))
}

/// The result of a converged (or capped) LM state: parameters, errors, flags.
fn finish(
    problem: &Problem,
    vertex: &VertexSamples,
    state: LmState,
    mut flags: Vec<FitFlag>,
    guide: &VertexGuide,
    config: &SolverConfig,
    final_units: &Scratch<f64>,
) -> VertexFit {
    let bounds = problem.bounds;
    let x = physical(state.raw);
    let ch = Chart::at(state.normal);
    let params = PbrdfParams {
        eta: x.eta,
        sigma_s: x.sigma_s,
        sigma_ss: x.sigma_ss.max(x.sigma_s).min(1.0),
        rho_s: state.albedos.rho_s.max(0.0),
        rho_ss: state.albedos.rho_ss.map(|v| v.max(0.0)),
        rho_d: state.albedos.rho_d.map(|v| v.max(0.0)),
    };
    if params.validate().is_err() || !state.cost.is_finite() {
        flags.push(FitFlag::NotConverged);
        return prior_fit(problem, vertex, state.normal, None, flags, config);
    }
    let u = uncertainty::standard_errors(problem, &ch, &x, &state.albedos);
    // Identifiability of η and grazing, at the solution (`final_units`: the unit lobes there),
    // over the samples the fitted normal faces.
    let mut max_sensitivity: f64 = 0.0;
    let mut max_cos_o: f64 = 0.0;
    let mut dop_sum = 0.0;
    for s in final_units.units.iter().filter(|s| s.front_facing) {
        let (dop, d) = dop_diffuse_with_d_eta(s.cos_theta_o, x.eta);
        max_sensitivity = max_sensitivity.max(d.abs());
        max_cos_o = max_cos_o.max(s.cos_theta_o);
        dop_sum += dop;
    }
    // Polarisation SNR: RMS of the (unweighted) DoP residuals against the mean model DoP. Below
    // 1 the observed DoP is dominated by noise and its Rice bias (docs/model.md §12, dark
    // pixels), so the std error (which assumes zero-mean noise) understates η's error.
    let dop_sq: f64 = problem
        .dop_residuals(final_units, &state.albedos)
        .map(|r| r * r)
        .sum();
    let n = problem.len().max(1) as f64;
    let dop_snr = (dop_sum / n) / (dop_sq / n).sqrt().max(1e-300);
    let eta_std_too_large = u.std_error[0]
        .partial_cmp(&config.max_eta_std_error)
        .is_none_or(|o| o == Ordering::Greater);
    let own_data_weak = max_sensitivity < config.min_eta_sensitivity || dop_snr < 1.0;
    let data_did_not_move_eta = guide.eta_prior.is_none()
        && problem.loss == LossMode::Measurement
        && problem.priors.eta.is_some_and(|prior| {
            // posterior information = data + prior; below twice the prior's, the data carry
            // less than the prior on its own: the "estimate" is the start value
            u.eta_variance_unscaled.is_nan() || u.eta_variance_unscaled > 0.5 * prior.sd * prior.sd
        });
    // η pinned within the margin of a bound is not a measurement either (it is withheld, with
    // `AtBound` saying why), never reported as a value with a small σ
    let eta_at_bound = params.eta < bounds.eta_min + config.bound_margin_eta
        || params.eta > bounds.eta_max - config.bound_margin_eta;
    if eta_std_too_large
        || (guide.eta_prior.is_none() && own_data_weak)
        || data_did_not_move_eta
        || eta_at_bound
    {
        flags.push(FitFlag::EtaUnidentifiable);
    }
    if max_cos_o < config.grazing_only_deg.to_radians().cos() {
        flags.push(FitFlag::GrazingOnly);
    }
    if at_bound(&params, state.normal, vertex.normal_world, &bounds, config) {
        flags.push(FitFlag::AtBound);
    }
    if crate::data::albedo_at_cap(&params, bounds.albedo_cap) {
        flags.push(FitFlag::AlbedoAtCap);
    }
    if !state.converged {
        flags.push(FitFlag::NotConverged);
    }
    flags.sort();
    flags.dedup();
    VertexFit {
        vertex: vertex.vertex,
        params,
        normal_world: state.normal,
        std_error: u.std_error,
        normal_std_error_deg: u.normal_std_error_deg,
        samples_used: problem.len() as u32,
        cost: state.cost,
        iterations: state.iterations,
        flags,
        eta_unpooled: None,
        eta_prior_only: data_did_not_move_eta,
        gates: vertex.gates.clone(),
    }
}

/// Whether any parameter ends at (within the documented margin of) its bound: η at either end,
/// σ_s at its floor, σ_ss at 1, any albedo at the cap, the normal beyond 2.5 widths of the prior
/// cone from the mesh normal.
fn at_bound(
    p: &PbrdfParams<f64>,
    normal: [f64; 3],
    mesh_normal: [f64; 3],
    bounds: &problem::Bounds,
    config: &SolverConfig,
) -> bool {
    let cap = bounds.albedo_cap * (1.0 - 1e-3);
    let cone = match unit(mesh_normal) {
        Some(m) if config.normal_prior_deg > 0.0 => {
            let c = (m[0] * normal[0] + m[1] * normal[1] + m[2] * normal[2]).clamp(-1.0, 1.0);
            c.acos().to_degrees() > 2.5 * config.normal_prior_deg
        }
        _ => false,
    };
    p.eta < bounds.eta_min + config.bound_margin_eta
        || p.eta > bounds.eta_max - config.bound_margin_eta
        || p.sigma_s < bounds.sigma_s_min + config.bound_margin_sigma
        || p.sigma_ss > 1.0 - config.bound_margin_sigma
        || p.rho_s >= cap
        || p.rho_ss.iter().chain(&p.rho_d).any(|v| *v >= cap)
        || cone
}

/// The prior result for a vertex that cannot be fitted: `init` if given, else the configured
/// prior with ρ_d, ρ_ss projected from whatever samples exist (0 without samples).
fn prior_fit(
    problem: &Problem,
    vertex: &VertexSamples,
    normal: [f64; 3],
    init: Option<&VertexFit>,
    mut flags: Vec<FitFlag>,
    config: &SolverConfig,
) -> VertexFit {
    let p = config.prior;
    let b = &problem.bounds;
    let mut params = match init {
        Some(f) if f.params.validate().is_ok() => f.params,
        _ => PbrdfParams {
            eta: p[0].clamp(b.eta_min, b.eta_max),
            sigma_s: p[1].clamp(b.sigma_s_min, 1.0),
            sigma_ss: p[2].clamp(p[1].clamp(b.sigma_s_min, 1.0), 1.0),
            rho_s: p[3].clamp(0.0, b.albedo_cap),
            rho_ss: [p[4].clamp(0.0, b.albedo_cap); 3],
            rho_d: [0.0; 3],
        },
    };
    if init.is_none() && problem.len() > 0 {
        let raw = raw_from(params.eta, params.sigma_s, params.sigma_ss, b);
        let mut scratch = Scratch::<f64>::new(problem.len(), problem.virtuals.len());
        let (_, a): (f64, Albedos<f64>) =
            lm::cost_at(problem, &Chart::at(normal), raw, &mut scratch);
        if a.rho_d
            .iter()
            .chain(&a.rho_ss)
            .chain([&a.rho_s])
            .all(|v| v.is_finite() && *v >= 0.0)
        {
            params.rho_d = a.rho_d;
            params.rho_ss = a.rho_ss;
            params.rho_s = a.rho_s;
        }
    }
    flags.sort();
    flags.dedup();
    VertexFit {
        vertex: vertex.vertex,
        params,
        normal_world: normal,
        std_error: [f64::INFINITY; 10],
        normal_std_error_deg: f64::INFINITY,
        samples_used: problem.len() as u32,
        cost: 0.0,
        iterations: 0,
        flags,
        eta_unpooled: None,
        eta_prior_only: false,
        gates: vertex.gates.clone(),
    }
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

/// One forward evaluation of the whole set.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ForwardCost {
    /// Σ over observations of the squared differences of I^d, I^s, I^α (model units).
    pub sum_squared: f64,
    /// Observations evaluated (samples × colour channels).
    pub observations: u64,
}

/// Evaluates the model (f64, no derivatives) once for every observation of `set` at `fits`
/// (indexed like `set.vertices`): the unit of work the benchmark divides fit time by. Per-vertex
/// sums are added in vertex order, so the result does not depend on the thread count.
pub fn forward_cost_all(set: &SampleSet, fits: &[VertexFit]) -> ForwardCost {
    let channels = if set.colour { 3 } else { 1 };
    let per_vertex: Vec<(f64, u64)> = set
        .vertices
        .par_iter()
        .zip(fits.par_iter())
        .map(|(v, fit)| {
            let p = &fit.params;
            let mut sum = 0.0;
            let mut count = 0u64;
            for s in &v.samples {
                let Some(view) = set.views.get(s.view as usize) else {
                    continue;
                };
                let Some(f) = super::model::SampleFrames::new(view, v.position_world) else {
                    continue;
                };
                let Some(u) = unit_sample_at(&f, fit.normal_world, p.eta, p.sigma_s, p.sigma_ss)
                else {
                    continue;
                };
                for c in 0..channels {
                    let pred = u.predict(p.rho_d[c], p.rho_ss[c], p.rho_s);
                    for (pk, ok) in pred.iter().zip(s.channels[c]) {
                        let d = pk - f64::from(ok);
                        sum += d * d;
                    }
                    count += 1;
                }
            }
            (sum, count)
        })
        .collect();
    let mut out = ForwardCost {
        sum_squared: 0.0,
        observations: 0,
    };
    for (s, c) in per_vertex {
        out.sum_squared += s;
        out.observations += c;
    }
    out
}
