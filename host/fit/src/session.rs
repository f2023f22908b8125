//! The fit of a recorded session: observations from the frames, the per-vertex solve, the shape
//! update, repeated for a few outer iterations, then the augmentation and final passes
//! (docs/model.md §11 "Steps A, B, C and the outer loop": the paper alternates solve and
//! Poisson reconstruction; we alternate solve and a normal-guided vertex update on the fixed
//! connectivity, [`super::shape`]).
//!
//! Contract:
//! - **Held-out views.** A deterministic `holdout_fraction` of the posed frames
//!   ([`super::holdout::split`]) is set aside before anything else: no observation, solve,
//!   cluster or shape step sees them. After the last iteration their observations are extracted
//!   on the final mesh and the fitted model is scored on them ([`super::holdout::score`]).
//! - Outer iteration k = 1…K: extract observations of the current mesh from every posed frame
//!   ([`super::observe::extract`], visibility and shadows recomputed on the current geometry),
//!   run step A warm-started from iteration k − 1 (same vertices: the connectivity never
//!   changes, so results carry over by index; the mesh normal stays the centre of the normal
//!   prior), and — except after the last iteration — move the vertices towards the refined
//!   normals. The last iteration runs the whole pipeline
//!   ([`super::pipeline::fit_sample_set`]: step A, and B + C when enabled).
//! - After it, when a surface step was applied and `combine_normals` is on, each fit's normal
//!   is its refined normal combined with the final surface's by their precisions
//!   ([`super::shape::combine`]); the held-out views are scored with those normals.
//! - The session is only read; nothing recorded is changed.
//! - Deterministic for a given input on any thread count.

use std::time::Instant;

use ellipso_model::geometry::TriangleMesh;
use nalgebra::Isometry3;

use super::complete::{Completion, complete};
use super::data::{GateCounts, SampleSet, VertexFit};
use super::holdout::{HoldoutReport, score, split};
use super::observe::sampler::UNLABELLED;
use super::observe::{
    FrameImages, MosaicFrames, ObserveConfig, ObserveError, ObserveReport, extract_from,
    radiometry_of,
};
use super::pipeline::{FitConfig, FitOutcome, fit_sample_set};
use super::shape::ShapeError;
use super::shape::combine::{NormalCombination, combine_with_surface, surface_normal_std_deg};
use super::shape::hull::HullField;
use super::shape::surface::{SurfaceConfig, SurfaceIteration, SurfaceState, observed_vertices};
use super::shard::Shard;
use super::solve::fit_all;
use ellipso_session::reader::Session;

mod sharded;

pub use sharded::{ShardSolve, finish_from_joint, solve_shard};

/// Settings of a session fit.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SessionFitConfig {
    /// Observation extraction (gates, sampling).
    pub observe: ObserveConfig,
    /// The per-vertex fit.
    pub fit: FitConfig,
    /// Outer iterations (solve ↔ surface update); 1 = no surface update. The loop ends early
    /// once the surface has converged or a step was refused.
    pub outer_iterations: usize,
    /// The surface update between outer iterations.
    #[serde(default)]
    pub surface: SurfaceConfig,
    /// The visual hull (and the board plane) the surface must stay inside (`None`: the update
    /// runs unconstrained; `ellipso-mesh` carves one with the mesh).
    #[serde(skip)]
    pub hull: Option<std::sync::Arc<HullField>>,
    /// Fraction of the posed frames held out for validation (default 0.1; 0 fits all).
    pub holdout_fraction: f64,
    /// After the outer loop, report each vertex's refined normal combined with the refined
    /// surface's normal by their precisions ([`crate::shape::combine`]; default on).
    #[serde(default = "default_true")]
    pub combine_normals: bool,
}

fn default_true() -> bool {
    true
}

impl Default for SessionFitConfig {
    fn default() -> Self {
        Self {
            observe: ObserveConfig::default(),
            fit: FitConfig::default(),
            outer_iterations: 8,
            surface: SurfaceConfig::default(),
            hull: None,
            holdout_fraction: 0.1,
            combine_normals: true,
        }
    }
}

/// `config` with the sensor model the solver weights samples by: the session's where it
/// records one (simulator sessions), else the sensor calibration's measured conversion gain and
/// read noise where the frames are read with one, the documented default otherwise.
pub fn with_session_sensor(session: &Session, config: &SessionFitConfig) -> SessionFitConfig {
    let mut config = config.clone();
    if let Some(sensor) = crate::observe::sensor_noise_of(session) {
        config.fit.solver.sensor = sensor;
    } else if let Some(cal) = &config.observe.sensor_calibration {
        let f = &cal.header.figures;
        config.fit.solver.sensor = crate::solve::SensorNoiseModel {
            dn_per_electron: f.gain_dn_per_e,
            read_noise_dn: f.read_noise_dn,
        };
    }
    config
}

/// Errors of a session fit.
#[derive(Debug, thiserror::Error)]
pub enum SessionFitError {
    /// Reading observations failed.
    #[error(transparent)]
    Observe(#[from] ObserveError),
    /// The shape update failed.
    #[error("shape update: {0}")]
    Shape(#[from] ShapeError),
    /// No posed frame.
    #[error("no frame of the session has a pose: track poses first")]
    NoPoses,
    /// An input no capture can produce (`crate::inputs`).
    #[error(transparent)]
    Inputs(#[from] crate::inputs::InputError),
    /// A shard was asked to run more than one outer iteration.
    #[error(
        "a sharded fit runs one outer iteration (the shape update between iterations needs \
         every vertex's solve); got {0}"
    )]
    ShardedOuterLoop(usize),
    /// Not one vertex has a sample: a fit would report the prior everywhere.
    #[error(
        "no vertex of the mesh has a single sample, so nothing can be fitted: {}",
        describe_empty(.0)
    )]
    NoSamples(Box<ObserveReport>),
}

/// Why an extraction gave no samples, in words: frames read and skipped (by reason), gates.
fn describe_empty(r: &ObserveReport) -> String {
    let mut reasons: std::collections::BTreeMap<&str, usize> = std::collections::BTreeMap::new();
    for s in &r.skipped {
        // the reason up to its first detail (frame paths differ per frame)
        let key = s.reason.split(": ").last().unwrap_or(&s.reason);
        *reasons.entry(key).or_insert(0) += 1;
    }
    let mut skipped: Vec<String> = reasons
        .iter()
        .take(5)
        .map(|(k, n)| format!("{n} × {k}"))
        .collect();
    if reasons.len() > 5 {
        skipped.push("…".into());
    }
    let g = &r.gates;
    format!(
        "{} of {} posed frames read{}; per (vertex, frame): {} not in view, {} occluded, {} in \
         shadow, {} grazing, {} saturated, {} dark, {} non-finite — check that the mesh is in the \
         boards' frame in metres and that the frames are readable",
        r.frames_used,
        r.frames_posed,
        if skipped.is_empty() {
            String::new()
        } else {
            format!(" ({} skipped: {})", r.skipped.len(), skipped.join("; "))
        },
        g.not_in_view,
        g.occluded,
        g.shadowed,
        g.grazing,
        g.saturated,
        g.dark,
        g.non_finite
    )
}

/// A session fit's results.
pub struct SessionFit {
    /// The refined mesh (input connectivity, updated positions and normals).
    pub mesh: TriangleMesh,
    /// The observations of the last outer iteration.
    pub set: SampleSet,
    /// The last iteration's fit (steps A, B, C) with stage timings summed over iterations.
    pub outcome: FitOutcome,
    /// One entry per surface update step (convergence, refusals).
    pub surface: Vec<SurfaceIteration>,
    /// How the reported normals were combined with the refined surface's (`None`: no surface
    /// step was applied, or `combine_normals` is off; the normals are the solve's).
    pub normal_combination: Option<NormalCombination>,
    /// What the completion gave the vertices the views see but their samples do not identify
    /// (`None` without step B: no materials to take values from).
    pub completion: Option<Completion>,
    /// Per vertex of `mesh`: observed by at least one fitted frame (a kept sample).
    pub observed: Vec<bool>,
    /// Gate counts of the last extraction, summed over vertices.
    pub gates: GateCounts,
    /// The last extraction's report (frames used and skipped, with reasons).
    pub observe: ObserveReport,
    /// The poses the fit used (the held-out ones excluded), by frame id.
    pub poses_fitted: Vec<(u64, Isometry3<f64>)>,
    /// The held-out frames' poses.
    pub poses_held_out: Vec<(u64, Isometry3<f64>)>,
    /// The re-render errors on the held-out frames (`None` when none were held out or none
    /// gave samples).
    pub holdout: Option<HoldoutReport>,
    /// The held-out observations on the final mesh (empty when none were held out).
    pub held_out_set: Option<SampleSet>,
}

/// Fits `mesh` to `session` seen from `poses` (frame id, `world_from_camera`).
pub fn fit_session(
    session: &Session,
    mesh: &TriangleMesh,
    poses: &[(u64, Isometry3<f64>)],
    config: &SessionFitConfig,
    progress: &mut dyn FnMut(&str),
) -> Result<SessionFit, SessionFitError> {
    // The outer loop reads every frame once per iteration: keep their sampled parts.
    let frames = MosaicFrames::caching(session, &config.observe)?;
    fit_session_with(session, mesh, poses, config, &frames, progress)
}

/// [`fit_session`] with each frame's analyser pixels from `frames` (the recorded mosaic,
/// [`MosaicFrames`], or an ideal sensor's images of the same frames in the error budget).
pub fn fit_session_with(
    session: &Session,
    mesh: &TriangleMesh,
    poses: &[(u64, Isometry3<f64>)],
    config: &SessionFitConfig,
    frames: &dyn FrameImages,
    progress: &mut dyn FnMut(&str),
) -> Result<SessionFit, SessionFitError> {
    if poses.is_empty() {
        return Err(SessionFitError::NoPoses);
    }
    crate::inputs::check(session, mesh, poses, &crate::observe::camera_of(session)?)?;
    let (fitted, poses_held_out) = split_poses(poses, config.holdout_fraction);
    let poses = fitted.as_slice();
    let mut mesh = mesh.clone();
    let mut previous: Option<Vec<VertexFit>> = None;
    let mut observe_s = 0.0;
    let mut joint_s = 0.0;
    let mut shape_s = 0.0;
    let iterations = config.outer_iterations.max(1);
    // (The solve starts from the previous iteration's normals through its warm start; the
    // samples keep the mesh normal, the centre of the normal prior.)
    let radiometry = radiometry_of(session)?;
    // The first extraction knows no materials; every later one gates samples whose footprint
    // mixes two of the previous iteration's materials (`material_labels`).
    let mut observe_config = config.observe.clone();
    let extract =
        |mesh: &TriangleMesh, poses: &[(u64, Isometry3<f64>)], observe_config: &ObserveConfig| {
            extract_from(
                session,
                &radiometry,
                mesh,
                poses,
                observe_config,
                Shard::ALL,
                frames,
                &|_, _| {},
            )
        };
    let observe = |mesh: &TriangleMesh, observe_config: &ObserveConfig| {
        let started = Instant::now();
        let e = extract(mesh, poses, observe_config)?;
        if e.report.samples == 0 {
            return Err(SessionFitError::NoSamples(Box::new(e.report)));
        }
        Ok::<_, SessionFitError>((e, started.elapsed().as_secs_f64()))
    };
    let announce = |k: usize, mesh: &TriangleMesh| {
        format!(
            "outer iteration {k}/{iterations}: observations from {} posed frames of {} vertices",
            poses.len(),
            mesh.positions().len()
        )
    };
    // The input mesh's normals: where a vertex's own data do not pin its normal, how far
    // these stray from the fitted ones elsewhere is its σ (`complete::mesh_normal_std_deg`).
    let input_normals: Vec<[f64; 3]> = mesh.normals().iter().map(|n| (**n).into()).collect();
    let mut surface = SurfaceState::new(&mesh);
    for k in 1..iterations {
        progress(&announce(k, &mesh));
        let (extraction, seconds) = observe(&mesh, &observe_config)?;
        let set = extraction.samples;
        observe_s += seconds;
        progress(&format!(
            "outer iteration {k}/{iterations}: joint per-vertex solve"
        ));
        let started = Instant::now();
        let fits = fit_all(&set, previous.as_deref(), None, &config.fit.solver);
        joint_s += started.elapsed().as_secs_f64();
        observe_config.vertex_labels = Some(labels_of(&fits, mesh.positions().len(), config));
        progress(&format!(
            "outer iteration {k}/{iterations}: surface update from the refined normals"
        ));
        let started = Instant::now();
        let moved = surface_step(&mut surface, &mesh, &fits, &set, config)?;
        shape_s += started.elapsed().as_secs_f64();
        if let Some(step) = surface.iterations.last() {
            progress(&step.describe());
        }
        previous = Some(fits);
        if let Some(m) = moved {
            mesh = m;
        }
        if surface.done() {
            break;
        }
    }
    progress(&announce(iterations, &mesh));
    let (extraction, seconds) = observe(&mesh, &observe_config)?;
    let set = extraction.samples;
    observe_s += seconds;
    let mut outcome = fit_sample_set(&set, previous.as_deref(), &config.fit, progress);
    let normal_combination = match surface_normal_std_deg(&surface.iterations) {
        Some(sigma) if config.combine_normals => {
            let c = combine_with_surface(&mut outcome.fits, mesh.normals(), sigma)?;
            progress(&c.describe());
            Some(c)
        }
        _ => None,
    };
    let completion = complete_fits(
        &set,
        &mut outcome,
        &mesh,
        surface_normal_std_deg(&surface.iterations),
        &input_normals,
        config,
    );
    if let Some(c) = &completion {
        progress(&c.describe());
    }
    outcome.times.observe_s = observe_s;
    outcome.times.joint_s += joint_s;
    outcome.times.shape_s = shape_s;
    let mut gates = GateCounts::default();
    for v in &set.vertices {
        gates.add(&v.gates);
    }
    let held_out_set = if poses_held_out.is_empty() {
        None
    } else {
        progress(&format!(
            "re-rendering {} held-out frames",
            poses_held_out.len()
        ));
        let held = extract(&mesh, &poses_held_out, &observe_config)?;
        Some(held.samples)
    };
    let holdout = score_held_out(session, held_out_set.as_ref(), &outcome.fits, config)?;
    let observed = observed_vertices(&set, mesh.positions().len());
    Ok(SessionFit {
        mesh,
        set,
        outcome,
        surface: surface.iterations,
        normal_combination,
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

/// Completes the fits of `outcome` from its materials ([`super::complete`]) on the final
/// `mesh`: a completed vertex's normal is the surface's, with the surface update's normal σ
/// (`surface_std_deg`) — or, without an applied surface step, the solver's normal prior: how
/// far the input mesh's normals are trusted. `None` without step B.
fn complete_fits(
    set: &SampleSet,
    outcome: &mut FitOutcome,
    mesh: &TriangleMesh,
    surface_std_deg: Option<f64>,
    input_normals: &[[f64; 3]],
    config: &SessionFitConfig,
) -> Option<Completion> {
    let a = outcome.augmentation.as_ref()?;
    // A completed vertex's normal is the surface's: its σ is the larger of the refined
    // surface's (at the fitted vertices) and the input mesh's measured stray.
    let surface = surface_std_deg.unwrap_or(config.fit.solver.normal_prior_deg);
    let normal_std_deg = crate::complete::mesh_normal_std_deg(&outcome.fits, input_normals)
        .map_or(surface, |m| m.max(surface));
    Some(complete(
        set,
        &mut outcome.fits,
        a,
        mesh,
        normal_std_deg,
        config.fit.solver.albedo_cap,
        config.fit.solver.max_eta_std_error,
    ))
}

/// The material label of every vertex from step A's `fits` ([`super::augment::material_labels`]
/// with the fit's clustering settings; [`UNLABELLED`] without a finite fit).
fn labels_of(fits: &[VertexFit], vertices: usize, config: &SessionFitConfig) -> Vec<u32> {
    let cluster = config
        .fit
        .augment
        .as_ref()
        .map(|a| a.cluster.clone())
        .unwrap_or_default();
    super::augment::material_labels(vertices, fits, &cluster)
        .into_iter()
        .map(|l| l.map_or(UNLABELLED, |l| l as u32))
        .collect()
}

/// One surface step of the outer loop ([`super::shape::surface`]): the mesh moved towards the
/// refined normals inside the hull, or `None` when the step was refused or the surface has
/// converged (the reason is in `surface.iterations`). Vertex identity is kept, so the fits of
/// this iteration warm-start the next one by index.
fn surface_step(
    surface: &mut SurfaceState,
    mesh: &TriangleMesh,
    fits: &[VertexFit],
    set: &SampleSet,
    config: &SessionFitConfig,
) -> Result<Option<TriangleMesh>, SessionFitError> {
    let observed = observed_vertices(set, mesh.positions().len());
    let cameras: Vec<nalgebra::Point3<f64>> = set
        .views
        .iter()
        .map(|v| nalgebra::Point3::from(v.camera_position_world))
        .collect();
    Ok(surface.step(
        mesh,
        fits,
        &observed,
        &cameras,
        config.hull.as_deref(),
        &config.surface,
    )?)
}

/// Poses by frame id (`world_from_camera`).
pub type Poses = Vec<(u64, Isometry3<f64>)>;

/// The deterministic split of `poses` into the fitted and the held-out ones
/// ([`super::holdout::split`]).
pub fn split_poses(poses: &[(u64, Isometry3<f64>)], holdout_fraction: f64) -> (Poses, Poses) {
    let ids: Vec<u64> = poses.iter().map(|p| p.0).collect();
    let held_idx = split(&ids, holdout_fraction);
    let mut held = Vec::with_capacity(held_idx.len());
    let mut fitted = Vec::with_capacity(poses.len());
    for (i, p) in poses.iter().enumerate() {
        if held_idx.binary_search(&i).is_ok() {
            held.push(*p);
        } else {
            fitted.push(*p);
        }
    }
    (fitted, held)
}

/// The re-render errors of `fits` on the held-out observations (`None` without any or when
/// none gave a sample).
pub fn score_held_out(
    session: &Session,
    held_out_set: Option<&SampleSet>,
    fits: &[VertexFit],
    _config: &SessionFitConfig,
) -> Result<Option<HoldoutReport>, SessionFitError> {
    let Some(held) = held_out_set else {
        return Ok(None);
    };
    let full_scale = radiometry_of(session)?.full_scale_dn;
    let report = score(held, fits, full_scale);
    Ok((report.overall.samples > 0).then_some(report))
}
