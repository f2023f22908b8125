//! The fit pipeline on a fixed set of observations (docs/model.md §11 "Steps A, B, C and the
//! outer loop"):
//!
//! 1. **Step A** — joint per-vertex solve (normal + pBRDF) of every vertex
//!    ([`super::solve::fit_all`]), warm-started from a previous result when one is given;
//! 2. **Step B** (on by default, see [`FitConfig`]) — k-means clusters on (ρd, η), a two-lobe
//!    specular model per cluster, virtual specular samples per vertex with total weight λg, the
//!    σs floor and the pooled η prior ([`super::augment`]);
//! 3. **Step C** (with B) — `final_passes` per-vertex passes with the guides (virtual samples,
//!    σs floors and, with [`FitConfig::pool_eta`], the pooled η priors from step A's results),
//!    each warm-started from the previous pass and, in the first, also from the cluster's lobe
//!    (the better initial cost runs first).
//!
//! Contract: deterministic for a given input on any thread count (every stage is); every
//! vertex of the input gets a [`VertexFit`] (flagged where it cannot be trusted); the wall time
//! of each stage is measured and returned. The outer loop with the shape update, which needs
//! fresh observations after every geometry change, lives with the session driver
//! ([`super::session`]).

use std::time::Instant;

use super::augment::{AugmentConfig, Augmentation, augment, pool_eta};
use super::data::FitFlag;
use super::data::{SampleSet, VertexFit};
use super::solve::{SolverConfig, fit_all};

/// Settings of the whole fit.
///
/// The default is the paper's recipe with one final pass: step A, clusters with virtual
/// samples, σs floors and pooled η (B), one final pass (C) — measured by `ellipso bench
/// accuracy` (docs/accuracy-vs-time.md) never worse than step A alone on the shipped scenes and
/// better on σs, σss and per-vertex η. [`FitConfig::joint_only`] stops after step A.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FitConfig {
    /// The per-vertex solver (iterations, loss weights, bounds).
    pub solver: SolverConfig,
    /// Clusters, virtual samples and pooling (steps B and C); `None` stops after step A.
    pub augment: Option<AugmentConfig>,
    /// Step C passes with the virtual samples (paper: 3; default 1: later passes moved no
    /// measured figure).
    pub final_passes: usize,
    /// Pool η per cluster from step A's results and give the final passes the pooled priors
    /// (default true).
    pub pool_eta: bool,
    /// With the shared steps on, run every per-vertex solve with the fast preset's effort
    /// ([`SolverConfig::with_fast_effort`]): step A only seeds the clusters and each final pass
    /// is warm-started, so the full effort bought no measured accuracy and cost 1.5× the time
    /// (default true).
    pub fast_passes: bool,
}

impl Default for FitConfig {
    fn default() -> Self {
        Self::with_augmentation(1)
    }
}

impl FitConfig {
    /// Step A, then clusters, virtual samples and pooling (B) and `passes` final passes (C).
    pub fn with_augmentation(passes: usize) -> Self {
        Self {
            solver: SolverConfig::default(),
            augment: Some(AugmentConfig::default()),
            final_passes: passes,
            pool_eta: true,
            fast_passes: true,
        }
    }

    /// The solver settings of step A as [`fit_sample_set`] runs it (the fast preset's effort
    /// with the shared steps on and [`FitConfig::fast_passes`]): sharded runs solve step A with
    /// exactly these.
    pub fn joint_solver(&self) -> SolverConfig {
        if self.augment.is_some() && self.fast_passes {
            self.solver.with_fast_effort()
        } else {
            self.solver.clone()
        }
    }

    /// Step A alone (per-vertex, nothing shared between vertices).
    pub fn joint_only() -> Self {
        Self {
            augment: None,
            pool_eta: false,
            ..Self::with_augmentation(0)
        }
    }
}

/// Wall time of each stage, seconds.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct StageTimes {
    /// Observation extraction (filled by drivers that extract).
    pub observe_s: f64,
    /// Step A.
    pub joint_s: f64,
    /// Step B.
    pub augment_s: f64,
    /// Step C.
    pub final_s: f64,
    /// Shape updates (filled by the session driver).
    pub shape_s: f64,
}

impl StageTimes {
    /// The fit proper: steps A + B + C.
    pub fn fit_s(&self) -> f64 {
        self.joint_s + self.augment_s + self.final_s
    }
}

/// How pooling changed the per-vertex η uncertainty (standard errors from the Jacobian at
/// the solution; the final pass's include the pooled prior).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct PoolingSummary {
    /// Vertices with a pooled η prior in the final pass.
    pub vertices_pooled: usize,
    /// Median η standard error of those vertices after step A.
    pub median_eta_se_before: f64,
    /// Median η standard error of the same vertices after the final pass.
    pub median_eta_se_after: f64,
}

/// What the pipeline produced.
#[derive(Clone, Debug)]
pub struct FitOutcome {
    /// One result per vertex of the sample set, in order.
    pub fits: Vec<VertexFit>,
    /// Clusters and virtual samples (when step B ran).
    pub augmentation: Option<Augmentation>,
    /// The uncertainty of η before and after pooling (when step B ran).
    pub pooling: Option<PoolingSummary>,
    /// Stage timings.
    pub times: StageTimes,
}

/// The shared median (NaN when empty) of an owned vector.
fn median(mut v: Vec<f64>) -> f64 {
    ellipso_model::stats::median(&mut v)
}

/// Runs steps A, B, C on `set`; `init` warm-starts step A (one entry per vertex).
/// `progress` is told each stage as it starts.
pub fn fit_sample_set(
    set: &SampleSet,
    init: Option<&[VertexFit]>,
    config: &FitConfig,
    progress: &mut dyn FnMut(&str),
) -> FitOutcome {
    progress("joint per-vertex solve (normal + pBRDF)");
    let started = Instant::now();
    let fits = fit_all(set, init, None, &config.joint_solver());
    let joint_s = started.elapsed().as_secs_f64();
    let mut outcome = fit_shared_steps(set, fits, config, progress);
    outcome.times.joint_s = joint_s;
    outcome
}

/// Steps B and C on `set` from step A's results `fits` (one per vertex, in order): what
/// [`fit_sample_set`] runs after step A, and what a merge of sharded step-A results runs
/// (`super::shard`). Without [`FitConfig::augment`] the fits are returned as they are.
pub fn fit_shared_steps(
    set: &SampleSet,
    fits: Vec<VertexFit>,
    config: &FitConfig,
    progress: &mut dyn FnMut(&str),
) -> FitOutcome {
    let mut times = StageTimes::default();
    let solver = config.joint_solver();
    let mut fits = fits;
    let mut augmentation = None;
    let mut pooling = None;
    if let Some(augment_config) = &config.augment {
        progress("clusters, virtual specular samples and pooled eta");
        let started = Instant::now();
        let mut a = augment(set, &fits, augment_config);
        if config.pool_eta {
            pool_eta(
                &mut a,
                set,
                &fits,
                config.solver.eta_prior,
                config.solver.max_eta_std_error,
            );
        }
        times.augment_s = started.elapsed().as_secs_f64();
        let pooled: Vec<usize> = (0..fits.len())
            .filter(|&v| a.guides[v].eta_prior.is_some())
            .collect();
        let before = median(pooled.iter().map(|&v| fits[v].std_error[0]).collect());
        let started = Instant::now();
        for pass in 0..config.final_passes {
            progress(&format!(
                "final pass {}/{} with the clusters' guides",
                pass + 1,
                config.final_passes
            ));
            fits = final_pass(set, &fits, &a.guides, &solver);
            // The cluster lobe is a start of the first final pass only.
            a.guides.iter_mut().for_each(|g| g.lobe_start = None);
        }
        times.final_s = started.elapsed().as_secs_f64();
        if config.pool_eta {
            pooled_standard_errors(&mut fits, &a);
        }
        if config.pool_eta {
            pooling = Some(PoolingSummary {
                vertices_pooled: pooled.len(),
                median_eta_se_before: before,
                median_eta_se_after: median(pooled.iter().map(|&v| fits[v].std_error[0]).collect()),
            });
        }
        augmentation = Some(a);
    }
    FitOutcome {
        fits,
        augmentation,
        pooling,
        times,
    }
}

/// The η standard error of every vertex the pool entered ([`FitFlag::EtaPooled`]), as the
/// error of the shrinkage estimate around a material whose η is one bulk value: with the
/// vertex's own standard error s (step A's), the pool's between-vertex spread τ and the
/// material's standard error se (`Pooled::se_reported`, spatial blocks included),
/// w = τ²/(τ² + s²) is the weight the vertex's own estimate keeps and
/// σ² = w²(s² + τ²) + (1 − w)²se². η is a property of the material, not of the vertex: τ is
/// scatter of the vertices' estimates that their own s does not account for, not a difference
/// of the truth between them. The solver's posterior, which takes τ as a real difference and
/// leaves out the material's own uncertainty, is replaced (docs/fit-augment.md "Pooled η").
fn pooled_standard_errors(fits: &mut [VertexFit], a: &Augmentation) {
    for (v, fit) in fits.iter_mut().enumerate() {
        if !fit.flags.contains(&FitFlag::EtaPooled) {
            continue;
        }
        let Some(pool) = a
            .assignment
            .get(v)
            .copied()
            .flatten()
            .and_then(|j| a.clusters.get(j))
            .map(|c| c.eta_pooled)
            .filter(|p| p.usable)
        else {
            continue;
        };
        let own = fit.eta_unpooled.map_or(f64::INFINITY, |u| u[1]);
        let tau2 = pool.tau * pool.tau;
        let w = if own.is_finite() && tau2 + own * own > 0.0 {
            tau2 / (tau2 + own * own)
        } else {
            0.0
        };
        let se = pool.se_reported();
        let own_part = if w > 0.0 {
            w * w * (own * own + tau2)
        } else {
            0.0
        };
        let sigma = (own_part + (1.0 - w).powi(2) * se * se).sqrt();
        if sigma.is_finite() && sigma > 0.0 {
            fit.std_error[0] = sigma;
        }
    }
}

/// One final pass: every vertex with something from the clusters (virtual samples, floor,
/// pooled η) is re-solved warm from `fits`; a vertex without a guide would re-converge where it
/// is, so it keeps its result (the pass costs only what the clusters changed).
fn final_pass(
    set: &SampleSet,
    fits: &[VertexFit],
    guides: &[crate::data::VertexGuide],
    solver: &SolverConfig,
) -> Vec<VertexFit> {
    use rayon::prelude::*;
    set.vertices
        .par_iter()
        .enumerate()
        .map(|(i, v)| {
            // One fit per vertex (step A's output); the guides are indexed alike.
            let fit = &fits[i];
            let Some(guide) = guides.get(i) else {
                return fit.clone();
            };
            if guide.virtual_samples.is_empty() && guide.eta_prior.is_none() {
                return fit.clone();
            }
            let mut out =
                crate::solve::fit_vertex(&set.views, v, set.colour, Some(fit), guide, solver);
            if guide.eta_prior.is_some() {
                // The pool's prior entered: keep the vertex's own estimate beside it.
                out.flags.push(crate::data::FitFlag::EtaPooled);
                out.eta_unpooled = Some(
                    fit.eta_unpooled
                        .unwrap_or([fit.params.eta, fit.std_error[0]]),
                );
            }
            out
        })
        .collect()
}
