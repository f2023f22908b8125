//! From a finished LM state to a [`VertexFit`]: the parameters clamped into their box, the
//! standard errors (`uncertainty.rs`) and the flags decided at the solution (`EtaUnidentifiable`,
//! `GrazingOnly`, `AtBound`, `AlbedoAtCap`, `NotConverged`; exact triggers in the `solve` module
//! doc); and the prior result for a vertex that cannot be fitted.
//!
//! Contract: every returned parameter is finite and inside its bounds; a state whose parameters
//! fail `PbrdfParams::validate` or whose cost is not finite falls back to the prior result with
//! `NotConverged`; the prior result has infinite standard errors, zero cost and iterations.

use std::cmp::Ordering;

use ellipso_model::optics::measure::dop_diffuse_with_d_eta;
use ellipso_model::optics::pbrdf::PbrdfParams;

use super::super::data::{FitFlag, VertexFit, VertexGuide, VertexSamples};
use super::lm::{self, LmState, physical, raw_from};
use super::problem::{self, Albedos, Chart, Problem, Scratch};
use super::{LossMode, SolverConfig, uncertainty, unit};

/// The result of a converged (or capped) LM state: parameters, errors, flags.
pub(super) fn finish(
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
pub(super) fn prior_fit(
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
