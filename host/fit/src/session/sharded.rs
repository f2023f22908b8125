//! The sharded session fit: what one shard computes ([`solve_shard`]: its vertices'
//! observations and step A) and the rest of a one-iteration fit once the shards' parts are
//! merged ([`finish_from_joint`]: steps B and C and the held-out score). Together they give
//! what [`super::fit_session`] gives with one outer iteration.

use std::time::Instant;

use ellipso_model::geometry::TriangleMesh;
use ellipso_session::reader::Session;
use nalgebra::Isometry3;

use super::{
    SessionFit, SessionFitConfig, SessionFitError, complete_fits, score_held_out, split_poses,
};
use crate::data::{GateCounts, SampleSet, VertexFit};
use crate::observe::{Extraction, extract_shard, radiometry_of};
use crate::pipeline::fit_shared_steps;
use crate::shape::surface::observed_vertices;
use crate::shard::Shard;
use crate::solve::fit_all;

/// What one shard of a sharded fit computes (`crate::shard`): the observations and step A of
/// the vertices it owns, and their held-out observations.
#[derive(Clone, Debug, PartialEq)]
pub struct ShardSolve {
    /// The shard's fitted observations (its vertices only, ascending).
    pub extraction: Extraction,
    /// Step A's result per vertex of `extraction.samples.vertices`, in order.
    pub fits: Vec<VertexFit>,
    /// The shard's held-out observations (`None` when no frame is held out).
    pub held_out: Option<SampleSet>,
    /// Seconds spent extracting (fitted and held-out frames).
    pub observe_s: f64,
    /// Seconds of step A.
    pub joint_s: f64,
}

/// The part of [`fit_session`](super::fit_session) that shard `shard` runs: the observations
/// of its vertices from the fitted frames, step A on them with the solver
/// [`fit_session`](super::fit_session)'s step A uses
/// ([`crate::pipeline::FitConfig::joint_solver`]), and their held-out observations. Needs
/// `config.outer_iterations == 1` (the shape update between iterations needs every vertex).
pub fn solve_shard(
    session: &Session,
    mesh: &TriangleMesh,
    poses: &[(u64, Isometry3<f64>)],
    config: &SessionFitConfig,
    shard: Shard,
    progress: &mut dyn FnMut(&str),
) -> Result<ShardSolve, SessionFitError> {
    if config.outer_iterations != 1 {
        return Err(SessionFitError::ShardedOuterLoop(config.outer_iterations));
    }
    if poses.is_empty() {
        return Err(SessionFitError::NoPoses);
    }
    crate::inputs::check(session, mesh, poses, &crate::observe::camera_of(session)?)?;
    let (fitted, held) = split_poses(poses, config.holdout_fraction);
    let radiometry = radiometry_of(session)?;
    progress(&format!(
        "shard {shard}: observations from {} posed frames of {} of {} vertices",
        fitted.len(),
        shard.vertices(mesh.positions().len()).count(),
        mesh.positions().len()
    ));
    let started = Instant::now();
    let extraction = extract_shard(
        session,
        &radiometry,
        mesh,
        &fitted,
        &config.observe,
        shard,
        &|_, _| {},
    )?;
    let mut observe_s = started.elapsed().as_secs_f64();
    progress(&format!("shard {shard}: joint per-vertex solve (step A)"));
    let started = Instant::now();
    let fits = fit_all(&extraction.samples, None, None, &config.fit.joint_solver());
    let joint_s = started.elapsed().as_secs_f64();
    let held_out = if held.is_empty() {
        None
    } else {
        progress(&format!(
            "shard {shard}: observations from {} held-out frames",
            held.len()
        ));
        let started = Instant::now();
        let e = extract_shard(
            session,
            &radiometry,
            mesh,
            &held,
            &config.observe,
            shard,
            &|_, _| {},
        )?;
        observe_s += started.elapsed().as_secs_f64();
        Some(e.samples)
    };
    Ok(ShardSolve {
        extraction,
        fits,
        held_out,
        observe_s,
        joint_s,
    })
}

/// The rest of a one-iteration [`fit_session`](super::fit_session) from every vertex's
/// observations and step-A results (assembled from the shards, `crate::shard::merge`): steps B
/// and C, then the held-out score. `mesh` is the input mesh (one iteration changes no vertex).
#[expect(
    clippy::too_many_arguments,
    reason = "the pieces a merge assembles, named"
)]
pub fn finish_from_joint(
    session: &Session,
    mesh: &TriangleMesh,
    poses: &[(u64, Isometry3<f64>)],
    extraction: Extraction,
    fits: Vec<VertexFit>,
    held_out_set: Option<SampleSet>,
    config: &SessionFitConfig,
    progress: &mut dyn FnMut(&str),
) -> Result<SessionFit, SessionFitError> {
    if extraction.report.samples == 0 {
        return Err(SessionFitError::NoSamples(Box::new(extraction.report)));
    }
    let (fitted, poses_held_out) = split_poses(poses, config.holdout_fraction);
    let mut set = extraction.samples;
    if set.vertices.len() == mesh.positions().len() {
        set.rings = crate::neighbours::rings(mesh);
    }
    let mut outcome = fit_shared_steps(&set, fits, &config.fit, progress);
    // One pass on the input mesh: its normals are the input ones.
    let input_normals: Vec<[f64; 3]> = mesh.normals().iter().map(|n| (**n).into()).collect();
    let completion = complete_fits(&set, &mut outcome, mesh, None, &input_normals, config);
    if let Some(c) = &completion {
        progress(&c.describe());
    }
    let mut gates = GateCounts::default();
    for v in &set.vertices {
        gates.add(&v.gates);
    }
    let holdout = score_held_out(session, held_out_set.as_ref(), &outcome.fits, config)?;
    let observed = observed_vertices(&set, mesh.positions().len());
    Ok(SessionFit {
        mesh: mesh.clone(),
        set,
        outcome,
        surface: Vec::new(),
        normal_combination: None,
        completion,
        observed,
        gates,
        observe: extraction.report,
        poses_fitted: fitted,
        poses_held_out,
        holdout,
        held_out_set,
    })
}
