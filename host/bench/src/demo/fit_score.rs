//! The demo's fit and its scores: the object's mesh carved from the session's frames
//! (`ellipso mesh`), the fit on it (`ellipso fit`, its files and pictures), and only then the
//! simulator's truth — the mesh against the true surface before and after the fit's shape
//! refinement, each fitted vertex against the truth at the closest point of the true surface,
//! and the same session fitted on the true mesh for the η beside it.
//!
//! Contract: the truth is read only after the fit's files are written; the `fit` object of
//! `summary.json` ([`DemoFit::summary`]) keeps its keys (alphabetical, as `json!` orders them).

use std::path::PathBuf;

use ellipso_pipeline::steps::Steps;
use ellipso_run_error::say;
use ellipso_run_error::{Context, RunError, Say};
use ellipso_sim::scene::Scene;

/// The demo's fit: where it went and its scores.
pub struct DemoFit {
    /// The fit's folder (staged).
    pub dir: PathBuf,
    /// The fitted model (staged).
    pub ply: PathBuf,
    /// The `fit` object of `summary.json`.
    pub summary: serde_json::Value,
}

/// Builds the object's mesh from the session's frames (`ellipso mesh`), fits it (`ellipso fit`)
/// and only then compares with the simulator's truth: the mesh's distance to the true surface
/// before and after the fit's shape refinement, and each fitted vertex's parameters and normal
/// against the truth at the closest point of the true surface.
pub fn fit_and_score(
    scene: &Scene,
    session: &ellipso_session::reader::Session,
    out: &ellipso_report::output::OutputDir,
    quick: bool,
    steps: &mut dyn Steps,
    say: &dyn Say,
) -> Result<DemoFit, RunError> {
    let dir = out.path().join("fit");
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let fitted = carve_and_fit(session, out, &dir, quick, steps, say)?;
    // Only now the truth.
    let scored = score_against_truth(scene, session, &fitted, say)?;
    let summary = summary_json(&fitted, &scored);
    say_mesh_scores(&scored.scores, say);
    say_fit_scores(&fitted, &scored, say);
    Ok(DemoFit {
        ply: dir.join("fit.ply"),
        dir,
        summary,
    })
}

/// The carved mesh and the fit on it, before any look at the truth.
struct Fitted {
    /// The mesh carved from the session's frames (the fit's input).
    mesh: ellipso_model::geometry::TriangleMesh,
    /// The carving's wall time, s.
    mesh_s: f64,
    /// The fit and its export.
    run: ellipso_fit::output::FitRun,
    /// The fit's settings with the session's sensor (what the true-mesh fit repeats).
    config: ellipso_fit::session::SessionFitConfig,
}

/// Carves the mesh from the session's frames into `dir/mesh.ply` and fits it, its files and
/// pictures written to `dir` (one outer iteration when `quick`).
fn carve_and_fit(
    session: &ellipso_session::reader::Session,
    out: &ellipso_report::output::OutputDir,
    dir: &std::path::Path,
    quick: bool,
    steps: &mut dyn Steps,
    say: &dyn Say,
) -> Result<Fitted, RunError> {
    let started = std::time::Instant::now();
    // taken once for the carving and the fit (their warnings said once)
    let poses = ellipso_pipeline::poses::poses_of(session, say)?;
    let (mesh, mesh_report, hull) = ellipso_pipeline::mesh::mesh_of_session(
        session,
        Some(&poses[..]),
        &ellipso_mesh::MeshConfig::default(),
        say,
        steps,
    )?;
    let mesh_s = started.elapsed().as_secs_f64();
    let mesh_path = dir.join("mesh.ply");
    ellipso_pipeline::mesh::write_mesh(&mesh, &mesh_report, &mesh_path)?;
    say!(
        say,
        "mesh         {} vertices carved from {} frames in {mesh_s:.1} s",
        mesh.positions().len(),
        mesh_report.frames_used,
    );
    let config = ellipso_fit::session::SessionFitConfig {
        outer_iterations: if quick {
            1
        } else {
            ellipso_fit::session::SessionFitConfig::default().outer_iterations
        },
        hull: Some(std::sync::Arc::new(hull)),
        ..Default::default()
    };
    let to = ellipso_fit::output::OutputTo {
        dir,
        publish: &|p| out.published(p),
    };
    let run = ellipso_pipeline::fit_run::fit_and_export(
        session,
        &mesh,
        Some(&poses[..]),
        None,
        to,
        None,
        &config,
        steps,
        say,
    )?;
    let config = ellipso_fit::session::with_session_sensor(session, &config);
    Ok(Fitted {
        mesh,
        mesh_s,
        run,
        config,
    })
}

/// The fit's scores against the simulator's truth.
struct Scored {
    /// Each fitted vertex against the truth at its closest true point.
    score: crate::score::FitScores,
    /// What the fit covers of the visible true surface.
    coverage: crate::coverage::CoverageScores,
    /// The held-out views' re-render errors, the fit's beside the truth's own.
    held_out: Option<crate::score::HoldoutBeside>,
    /// The meshes against the true surface and the same session fitted on the true mesh.
    scores: crate::mesh_bench::MeshScores,
}

/// Reads the truth and scores the fit against it; fits the same session on the true mesh for
/// the η beside it.
fn score_against_truth(
    scene: &Scene,
    session: &ellipso_session::reader::Session,
    fitted: &Fitted,
    say: &dyn Say,
) -> Result<Scored, RunError> {
    let run = &fitted.run;
    let truth = crate::truth::truth_for_scoring(scene)?;
    let at = crate::truth_map::truth_at(&truth, run.fit.mesh.positions());
    let fits = &run.fit.outcome.fits;
    let score = crate::score::score_fit(fits, &at, &truth.material_names, run.fit.set.colour);
    let (coverage, _) = crate::coverage::score_session_fit(scene, session, &run.fit)?;
    let held_out = run.fit.held_out_set.as_ref().map(|held| {
        crate::score::holdout_beside_truth(held, fits, &at, crate::accuracy::full_scale_dn(scene))
    });
    say!(
        say,
        "scoring: the same session fitted on the true mesh, for η beside it…"
    );
    let scores = crate::mesh_bench::mesh_scores(
        scene,
        session,
        &fitted.mesh,
        &run.fit,
        run.wall_s,
        &fitted.config,
        say,
    )?;
    Ok(Scored {
        score,
        coverage,
        held_out,
        scores,
    })
}

/// The `fit` object of `summary.json`.
fn summary_json(fitted: &Fitted, scored: &Scored) -> serde_json::Value {
    let run = &fitted.run;
    let (score, scores) = (&scored.score, &scored.scores);
    // the carved and refined meshes against the truth, as the mesh bench scores them
    let (before, after) = (&scores.distance_before, &scores.distance_after);
    serde_json::json!({
        "vertices": run.fit.outcome.fits.len(),
        "fitted": score.scored,
        "mesh_s": fitted.mesh_s,
        "wall_s": run.wall_s,
        "times_s": run.fit.outcome.times,
        "mesh_before_fit": before,
        "mesh_after_fit": after,
        "materials": score.materials,
        "coverage": scored.coverage,
        "eta_material_mean_abs_error_pct": score.eta_material_mean_pct,
        "eta_material_max_abs_error_pct": score.eta_material_max_pct,
        "eta_vertex_median_error_pct": score.eta_vertex_median_pct,
        "eta_vertex_unpooled_median_error_pct": score.eta_vertex_unpooled_median_pct,
        "normal_median_error_deg": score.normal_median_deg,
        "normal_p90_error_deg": score.normal_p90_deg,
        "rho_d_median_error_pct": score.rho_d_median_pct,
        "held_out_beside_truth": scored.held_out,
        "input_mesh": "fit/mesh.ply",
        "surface": {
            "before": scores.before,
            "after": scores.after,
            "update": scores.surface_update,
        },
        "eta_carved_vs_true_mesh": scores.eta,
        "true_mesh_fit_s": scores.true_mesh_fit_s,
    })
}

/// Says the meshes against the truth (Chamfer, Hausdorff, the observed and unobserved surface)
/// and each material's η from the carved mesh beside the true mesh's.
fn say_mesh_scores(scores: &crate::mesh_bench::MeshScores, say: &dyn Say) {
    let (before, after) = (&scores.distance_before, &scores.distance_after);
    say!(
        say,
        "mesh vs truth  Chamfer {:.3} mm before the fit, {:.3} mm after its shape refinement (Hausdorff {:.2} → {:.2} mm)",
        before.chamfer_m * 1e3,
        after.chamfer_m * 1e3,
        before.hausdorff_m * 1e3,
        after.hausdorff_m * 1e3,
    );
    say!(
        say,
        "surface      observed {} vertices: {:.3} mm mean from the truth before the fit, {:.3} mm after (p90 {:.3} mm, signed median {:+.3} mm); unobserved {}: {:.3} → {:.3} mm; normals {} median (mesh before {:.2}°)",
        scores.after.observed_vertices,
        scores.before.observed_mean_m * 1e3,
        scores.after.observed_mean_m * 1e3,
        scores.after.observed_p90_m * 1e3,
        scores.after.observed_signed_median_m * 1e3,
        scores.after.unobserved_vertices,
        scores.before.unobserved_mean_m * 1e3,
        scores.after.unobserved_mean_m * 1e3,
        scores
            .after
            .fit_normal_median_deg
            .filter(|d| d.is_finite())
            .map_or("— (no refined normal)".to_string(), |d| format!(
                "{d:.2}°"
            )),
        scores.before.mesh_normal_median_deg,
    );
    for m in &scores.eta {
        let difference = if m.difference_points().is_finite() {
            format!(
                " (difference {:.2} ± {:.2} points, 1σ noise)",
                m.difference_points(),
                m.noise_points
            )
        } else {
            String::new()
        };
        say!(
            say,
            "η            {:<15} carved mesh {}, true mesh {}{difference}; from {} / {} vertices",
            m.name,
            signed_pct(m.carved_pct),
            signed_pct(m.true_mesh_pct),
            m.vertices[0],
            m.vertices[1]
        );
    }
}

/// Says the fit's scores: its normals and ρd, η per material with its coverage, the coverage of
/// the visible surface with the σ calibration, η per vertex and the held-out views.
fn say_fit_scores(fitted: &Fitted, scored: &Scored, say: &dyn Say) {
    let run = &fitted.run;
    let fits = &run.fit.outcome.fits;
    let (score, coverage, held_out) = (&scored.score, &scored.coverage, &scored.held_out);
    say!(
        say,
        "fit          {}/{} vertices in {:.1} s · normal error median {:.2}° (90th percentile {:.2}°) · ρd error median {}",
        score.scored,
        fits.len(),
        run.wall_s,
        score.normal_median_deg,
        score.normal_p90_deg,
        unsigned_pct(score.rho_d_median_pct),
    );
    say!(
        say,
        "η per material (median over the vertices that report η, against the truth):"
    );
    let visible = |name: &str| {
        coverage
            .materials
            .iter()
            .find(|c| c.name == name)
            .map_or(String::new(), |c| {
                format!(
                    " · coverage {:.3} of {} visible vertices ({} from the material)",
                    c.coverage, c.visible, c.from_material
                )
            })
    };
    for m in &score.materials {
        let verdict = if m.vertices == 0 {
            "unidentified: no vertex's data fix η".to_string()
        } else {
            format!(
                "{:.4} (true {:.4}, {:+.2} %; before pooling {:+.2} %)",
                m.eta_median, m.eta_true, m.eta_error_pct, m.eta_unpooled_error_pct
            )
        };
        say!(
            say,
            "  {:16} {verdict} · {} vertices report η, {} withheld{}",
            m.name,
            m.vertices,
            m.unidentified_vertices,
            visible(&m.name)
        );
    }
    say!(
        say,
        "coverage     {} of {} vertices the true geometry makes visible have a full parameter set \
         ({:.3}; lowest material {:.3}; {} from their material) · within 1σ: η {:.2} own / {:.2} \
         from material, normals {:.2} / {:.2}, ρd {:.2} / {:.2}",
        coverage.full_set,
        coverage.visible,
        coverage.coverage_visible,
        coverage.coverage_material_min,
        coverage.from_material,
        coverage.sigma_eta.own,
        coverage.sigma_eta.from_material,
        coverage.sigma_normal.own,
        coverage.sigma_normal.from_material,
        coverage.sigma_rho_d.own,
        coverage.sigma_rho_d.from_material,
    );
    say!(
        say,
        "η per vertex  median error {} (before pooling {})",
        unsigned_pct(score.eta_vertex_median_pct),
        unsigned_pct(score.eta_vertex_unpooled_median_pct)
    );
    if let Some(h) = &held_out {
        say!(
            say,
            "held-out     re-render relative RMSE, fit / the truth's own on the same samples: s0 {:.3} / {:.3} · I^s {:.3} / {:.3} · I^α {:.3} / {:.3}",
            h.fit.s0.relative_rmse,
            h.truth.s0.relative_rmse,
            h.fit.specular.relative_rmse,
            h.truth.specular.relative_rmse,
            h.fit.alpha.relative_rmse,
            h.truth.alpha.relative_rmse,
        );
    }
}

/// A signed percentage, or what its absence means: a median over no vertex is NaN, which the
/// demo says in words (`summary.json` keeps `null`).
fn signed_pct(v: f64) -> String {
    if v.is_finite() {
        format!("{v:+.2} %")
    } else {
        "not identified (no vertex reports η)".into()
    }
}

/// An unsigned percentage, or "none reported" where no vertex gave one ([`signed_pct`]).
fn unsigned_pct(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.2} %")
    } else {
        "— (no vertex reports it)".into()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_median_over_no_vertex_is_said_in_words() {
        assert_eq!(signed_pct(0.25), "+0.25 %");
        assert!(!signed_pct(f64::NAN).contains("NaN"));
        assert_eq!(unsigned_pct(1.5), "1.50 %");
        assert!(!unsigned_pct(f64::NAN).contains("NaN"));
    }
}
