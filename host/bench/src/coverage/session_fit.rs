//! A fit of a session simulated from a scene, scored for coverage ([`score`]) against the
//! scene's truth: the truth at every fitted vertex and the frames that see its true point lit
//! ([`visible_frames`]), for a fit read from its folder or made in this process.
//!
//! Contract: only the frames the fit used count, at their true poses, with the session's camera
//! and flash and the fit's default grazing cut-off; the truth comes back beside every vertex.

use ellipso_fit::export::ply::FitVertex;
use nalgebra::{Isometry3, Point3};
use serde::Serialize;

use super::{CoverageScores, score, visible_frames};

/// Scores the fit in `fit_dir` (its `fit.ply` and `fit-summary.json`) of `session_dir`, a
/// session captured from `scene` ([`score_fit_vertices`] over the posed frames less the
/// held-out ones the summary lists).
pub fn score_fit_dir(
    scene: &ellipso_sim::scene::Scene,
    session_dir: &std::path::Path,
    fit_dir: &std::path::Path,
) -> Result<(CoverageScores, Vec<VertexRow>), ellipso_run_error::RunError> {
    use ellipso_run_error::Context;
    let session = ellipso_session::reader::open(session_dir)
        .with_context(|| format!("reading the session {}", session_dir.display()))?;
    let fit = ellipso_fit::export::ply::read_fit_ply(&fit_dir.join("fit.ply"))?;
    let summary_path = fit_dir.join("fit-summary.json");
    let summary: serde_json::Value = serde_json::from_slice(
        &std::fs::read(&summary_path)
            .with_context(|| format!("reading {}", summary_path.display()))?,
    )
    .with_context(|| format!("parsing {}", summary_path.display()))?;
    let held_out: Vec<u64> = summary["frames_held_out"]
        .as_array()
        .map(|a| a.iter().filter_map(serde_json::Value::as_u64).collect())
        .unwrap_or_default();
    let fitted: Vec<u64> = session
        .poses()
        .tracked()
        .into_iter()
        .map(|(id, _)| id)
        .filter(|id| !held_out.contains(id))
        .collect();
    score_fit_vertices(scene, &session, &fitted, &fit)
}

/// [`score_fit_vertices`] of a fit made in this process: its vertices as `fit.ply` writes them
/// and its fitted frames.
pub fn score_session_fit(
    scene: &ellipso_sim::scene::Scene,
    session: &ellipso_session::reader::Session,
    fit: &ellipso_fit::session::SessionFit,
) -> Result<(CoverageScores, Vec<VertexRow>), ellipso_run_error::RunError> {
    let vertices: Vec<FitVertex> = fit
        .outcome
        .fits
        .iter()
        .zip(fit.mesh.positions())
        .enumerate()
        .map(|(v, (f, p))| {
            let params = ellipso_fit::export::ply::params_of(f);
            let std = f.reported_std_error();
            FitVertex {
                position: [p.x as f32, p.y as f32, p.z as f32],
                normal: f.normal_world.map(|v| v as f32),
                params: params.map(|v| v as f32),
                std_error: std.map(|v| v as f32),
                normal_std_deg: f.reported_normal_std_deg() as f32,
                samples: f.samples_used,
                flags: f.output_mask(),
                material: fit
                    .completion
                    .as_ref()
                    .and_then(|c| c.labels.get(v).copied().flatten())
                    .map(|m| m as u32),
            }
        })
        .collect();
    let fitted: Vec<u64> = fit.poses_fitted.iter().map(|p| p.0).collect();
    score_fit_vertices(scene, session, &fitted, &vertices)
}

/// Scores `fit` (vertices as `fit.ply` holds them) of `session`, captured from `scene`, fitted
/// from the frames `fitted` (ids): the truth at every vertex, the visible frame counts over
/// those frames at their true poses (the session's camera and flash, the fit's default grazing
/// cut-off), then [`score`]; with the truth beside every vertex.
pub fn score_fit_vertices(
    scene: &ellipso_sim::scene::Scene,
    session: &ellipso_session::reader::Session,
    fitted: &[u64],
    fit: &[FitVertex],
) -> Result<(CoverageScores, Vec<VertexRow>), ellipso_run_error::RunError> {
    let poses: Vec<Isometry3<f64>> = crate::capture::true_poses(session, scene)
        .into_iter()
        .filter(|(id, _)| fitted.contains(id))
        .map(|(_, p)| p)
        .collect();
    let camera = ellipso_fit::observe::camera_of(session)?;
    let flash = ellipso_fit::observe::flash_of(session)?;
    let truth = crate::truth::truth_for_scoring(scene)?;
    let positions: Vec<Point3<f64>> = fit
        .iter()
        .map(|v| Point3::from(v.position.map(f64::from)))
        .collect();
    let at = crate::truth_map::truth_at(&truth, &positions);
    let points: Vec<([f64; 3], [f64; 3])> = at
        .iter()
        .map(|t| {
            t.map_or(([f64::NAN; 3], [0.0; 3]), |t| {
                (t.closest_world, t.normal_world)
            })
        })
        .collect();
    let grazing = ellipso_fit::gate::GateConfig::default().grazing_cutoff_deg;
    let visible = visible_frames(&truth.mesh, &points, &camera, &flash, &poses, grazing);
    let colour = session.manifest.sensor.layout == ellipso_model::mosaic::SensorLayout::ColourPolar;
    let scores = score(fit, &at, &visible, &truth.material_names, colour);
    let vertices = at
        .iter()
        .zip(&visible)
        .map(|(t, &seen)| VertexRow {
            material: t.map(|t| t.material),
            visible_frames: seen,
            eta_true: t.map_or(f64::NAN, |t| t.params.eta),
            normal_true: t.map_or([f64::NAN; 3], |t| t.normal_world),
            distance_m: t.map_or(f64::NAN, |t| t.signed_distance_m),
        })
        .collect();
    Ok((scores, vertices))
}

/// The truth beside one fitted vertex (`ellipso bench score --vertices`).
#[derive(Clone, Debug, Serialize)]
pub struct VertexRow {
    /// True material index.
    pub material: Option<usize>,
    /// Fitted frames that see its true point lit ([`visible_frames`]).
    pub visible_frames: u32,
    /// True η.
    pub eta_true: f64,
    /// True normal.
    pub normal_true: [f64; 3],
    /// Signed distance to the true surface, metres.
    pub distance_m: f64,
}
