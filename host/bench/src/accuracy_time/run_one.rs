//! One timed, scored run of `ellipso bench accuracy`: simulate a capture of a scene with known
//! truth, fit it (views held out when asked), time one forward evaluation of every observation
//! right after the fit, score against the truth and the held-out views, and print a summary
//! line — the [`RunResult`] every sweep and the report are made of.
//!
//! Contract: the simulation is timed apart from the fit (`simulate_s` is not part of `fit_s`);
//! the fit uses the scene's own sensor model; the run's peak resident memory is its own (reset
//! at its start) where the platform allows, `None` otherwise.

use std::time::Instant;

use ellipso_fit::data::{SampleSet, VertexFit};
use ellipso_fit::pipeline::{FitConfig, fit_sample_set};
use ellipso_run_error::{RunError, Say};
use ellipso_run_error::{ensure, say};
use ellipso_sim::scene::Scene;

use crate::accuracy::specular::LobeScores;
use crate::accuracy::{CaptureCase, Scores, evaluate, forward_all, simulate};

use super::Result;

/// One timed, scored run.
#[derive(Debug, Clone, serde::Serialize)]
pub struct RunResult {
    /// Scene name.
    pub scene: String,
    /// Which sweep the run belongs to.
    pub sweep: String,
    /// Solver setting label.
    pub solver: String,
    /// Photos.
    pub photos: usize,
    /// Views used by the fit (= photos).
    pub views: usize,
    /// Simulation wall time, s (not part of the fit).
    pub simulate_s: f64,
    /// Fit wall time (steps A + B + C), s.
    pub fit_s: f64,
    /// Stage times.
    pub times: ellipso_fit::pipeline::StageTimes,
    /// One forward evaluation of every observation, s.
    pub forward_s: f64,
    /// fit_s / forward_s.
    pub fit_over_forward: f64,
    /// The run's resident-memory high-water mark (simulation, fit, scoring), bytes (Linux).
    pub peak_rss_bytes: Option<u64>,
    /// Scores against the truth.
    pub scores: Scores,
    /// Re-render errors on the held-out views (`None` when none were held out).
    pub holdout: Option<ellipso_fit::holdout::FrameScore>,
    /// The clusters (when step B ran).
    pub clusters: Vec<ellipso_fit::augment::ClusterModel>,
    /// The uncertainty of η before and after pooling (when step B ran).
    pub pooling: Option<ellipso_fit::pipeline::PoolingSummary>,
    /// Vertices with virtual samples / with a pooled η prior (when step B ran).
    pub guided: Option<(usize, usize)>,
    /// Flash energies fired in turn (empty: one exposure).
    pub bracket: Vec<f64>,
    /// Cluster σs per material and samples kept at the lobe peak.
    pub lobes: LobeScores,
}

#[allow(clippy::too_many_arguments)] // the run's labels, its case and settings, and the printer
pub(super) fn one_run(
    scene: &Scene,
    name: &str,
    sweep: &str,
    solver: &str,
    case: &CaptureCase,
    config: &FitConfig,
    holdout: f64,
    say: &dyn Say,
) -> Result<RunResult> {
    // The run's own peak memory: the simulated capture (what a session's samples would be),
    // the fit and its scoring.
    let rss_reset = ellipso_report::memory::reset_peak_rss();
    let t = Instant::now();
    let full = simulate(scene, case).map_err(|e| RunError::from_boxed(e.into()))?;
    let simulate_s = t.elapsed().as_secs_f64();
    // The held-out views are taken out before the fit sees anything.
    let (train, held) = ellipso_fit::holdout::split_set(&full.set, holdout);
    let capture = crate::accuracy::SimulatedCapture {
        truth: full.truth,
        set: train,
        flash_energy_rel: full.flash_energy_rel,
        near_mirror: full.near_mirror,
    };
    let mut config = config.clone();
    config.solver.sensor = crate::accuracy::sensor_model(scene);
    let outcome = fit_sample_set(&capture.set, None, &config, &mut |_| {});
    let full_scale = crate::accuracy::full_scale_dn(scene);
    let holdout = (!held.views.is_empty())
        .then(|| ellipso_fit::holdout::score(&held, &outcome.fits, full_scale).overall);
    let fit_s = outcome.times.fit_s();
    let forward_s = fastest_forward_s(&capture.set, &outcome.fits)?;
    let scores = evaluate(&capture, &outcome.fits);
    let peak_rss_bytes = ellipso_report::memory::peak_rss_bytes().filter(|_| rss_reset);
    let lobes = crate::accuracy::specular::score(&capture, outcome.augmentation.as_ref());
    let bracket = case
        .bracket
        .clone()
        .unwrap_or_else(|| scene.capture.bracket.clone());
    let r = RunResult {
        scene: name.to_string(),
        sweep: sweep.to_string(),
        solver: solver.to_string(),
        photos: case.photos,
        views: capture.set.views.len(),
        simulate_s,
        fit_s,
        times: outcome.times,
        forward_s,
        fit_over_forward: fit_s / forward_s,
        peak_rss_bytes,
        scores,
        holdout,
        clusters: outcome
            .augmentation
            .as_ref()
            .map(|a| a.clusters.clone())
            .unwrap_or_default(),
        pooling: outcome.pooling,
        guided: outcome
            .augmentation
            .as_ref()
            .map(|a| (a.vertices_with_virtual_samples, a.vertices_with_eta_prior)),
        bracket,
        lobes,
    };
    say_run(&r, say);
    Ok(r)
}

/// The fastest of at least 3 forward evaluations of every observation of `set` with `fits`
/// ([`forward_all`]) and 0.25 s of them in all, s; an error if one is not finite.
fn fastest_forward_s(set: &SampleSet, fits: &[VertexFit]) -> Result<f64> {
    // The forward pass is short (tens of milliseconds): its fastest of at least 3 repetitions
    // and 0.25 s in all, so one scheduling hiccup does not move the ratio.
    let mut forward_s = f64::INFINITY;
    let mut spent_s = 0.0;
    let mut repetitions = 0;
    while repetitions < 3 || spent_s < 0.25 {
        let t = Instant::now();
        let checksum = forward_all(set, fits);
        let s = t.elapsed().as_secs_f64().max(1e-9);
        ensure!(
            checksum.is_finite(),
            "forward evaluation produced a non-finite value"
        );
        forward_s = forward_s.min(s);
        spent_s += s;
        repetitions += 1;
    }
    Ok(forward_s)
}

/// Says the run's summary line, then its clusters, the lobes' scores and each material's.
fn say_run(r: &RunResult, say: &dyn Say) {
    say!(
        say,
        "{:<15} {:<8} {:<36} {:>4} photos {:>6} vertices ({:.3} of the observed scored) {:>8} samples  fit {:>7.2} s ({:>6.0}× forward)  η {:>6.2} % (median {:>5.2} %, material {:>5.2} %)  normal {:>5.2}°/{:>5.2}°  ρd {:>5.2} % (median {:>4.2} %)  re-render {:.4}  held-out s0 {}",
        r.scene,
        r.sweep,
        r.solver,
        r.photos,
        r.scores.vertices,
        r.scores.coverage,
        r.scores.samples,
        r.fit_s,
        r.fit_over_forward,
        r.scores.eta_mean_pct,
        r.scores.eta_median_pct,
        r.scores.eta_material_pct,
        r.scores.normal_median_deg,
        r.scores.normal_p90_deg,
        r.scores.rho_d_mean_pct,
        r.scores.rho_d_median_pct,
        r.scores.rerender_rmse,
        r.holdout
            .as_ref()
            .map_or("n/a".into(), |h| format!("{:.4}", h.s0.relative_rmse))
    );
    if let (Some(p), Some((virt, prior))) = (&r.pooling, r.guided) {
        say!(
            say,
            "    {} clusters, {virt} vertices with virtual samples, {prior} with a pooled η prior; median η se {:.4} → {:.4}",
            r.clusters.len(),
            p.median_eta_se_before,
            p.median_eta_se_after
        );
    }
    for c in &r.clusters {
        say!(
            say,
            "    cluster ({} members): η {:.4} (pooled {:.4} ± {:.4}, median {:.4}, τ {:.4}, {} used, {} trimmed)  σs {:.3}  σss {:.3}  ρs {:.3}",
            c.members,
            c.eta,
            c.eta_pooled.mean,
            c.eta_pooled.se,
            c.eta_pooled.median,
            c.eta_pooled.tau,
            c.eta_pooled.vertices,
            c.eta_pooled.trimmed,
            c.sigma_s,
            c.sigma_ss,
            c.rho_s
        );
    }
    for c in &r.lobes.clusters {
        say!(
            say,
            "    {:<16} cluster σs {:.4} (true {:.3}, {:+.1} %, {:.0} % of its vertices in that cluster)",
            c.material,
            c.sigma_s_cluster,
            c.sigma_s_true,
            c.sigma_s_error_pct,
            100.0 * c.share
        );
    }
    for p in &r.lobes.peaks {
        say!(
            say,
            "    {:<16} lobe peak: {} of {} vertices with a near-mirror view kept a peak sample ({} of {} near-mirror samples kept)",
            p.material,
            p.vertices_with_peak_kept,
            p.vertices_with_near_mirror_view,
            p.peak_samples_kept,
            p.near_mirror_views
        );
        for (energy, views, kept) in &p.by_energy {
            say!(say, "        at energy {energy}: {kept} of {views} kept");
        }
    }
    for m in &r.scores.materials {
        say!(
            say,
            "    {:<16} η {:.4} (true {:.3}, {:+.3} %; vertex median {:.2} %)  σs {:.3}  σss {:.3}  normal {:.2}°",
            m.name,
            m.eta_median,
            m.eta_true,
            100.0 * (m.eta_median - m.eta_true) / m.eta_true,
            m.eta_vertex_median_pct,
            m.sigma_s_median,
            m.sigma_ss_median,
            m.normal_median_deg
        );
    }
}
