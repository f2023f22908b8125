//! `ellipso fit SESSION --mesh MESH --out DIR`: the polarimetric SVBRDF and refined shape of a
//! recorded session, per mesh vertex, with its pictures.
//!
//! Poses come from the session's `pose` events (tracked now and appended when the log has
//! none). The mesh is a triangle mesh (PLY or OBJ) in board (world) coordinates, metres, from
//! any scanner or photogrammetry; without `--mesh` it is carved from the session's own frames
//! first (`ellipso mesh`, written to `OUT/mesh.ply`). Writes `fit.ply` (per-vertex parameters
//! and uncertainties), the pictures of the fitted model from one captured view, and
//! `fit-summary.json`.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use ellipso_model::geometry::TriangleMesh;
use nalgebra::Isometry3;

use ellipso_fit::observe::poses_from_session;
use ellipso_fit::session::{SessionFit, SessionFitConfig, fit_session};
use ellipso_fit::shard::Shard;
use ellipso_session::reader::Session;

/// Arguments of `ellipso fit`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The session directory.
    pub session: PathBuf,
    /// Triangle mesh of the object (PLY or OBJ), board coordinates, metres (default: carved
    /// from the session's frames, as `ellipso mesh` does).
    #[arg(long)]
    pub mesh: Option<PathBuf>,
    /// Output directory (default `ellipso-fit`); with `--shard`, the part file to write
    /// (required).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Frame id of the view the pictures are rendered from (default: the first posed frame).
    #[arg(long)]
    pub view: Option<u64>,
    /// Outer iterations (solve ↔ surface update), 1..=20; 1 keeps the input geometry (default
    /// 4, fewer when the surface converges; a shard runs 1).
    #[arg(long, value_parser = super::limits::outer_iterations)]
    pub outer: Option<usize>,
    /// Target vertex count of the mesh carved without `--mesh`, 16..=2000000.
    #[arg(long, default_value_t = 2500, value_parser = super::limits::vertices)]
    pub vertices: usize,
    /// Do not carve the visual hull for a `--mesh` (the surface update then runs without the
    /// silhouettes' constraint); without `--mesh` the hull comes with the carved mesh.
    #[arg(long)]
    pub no_hull: bool,
    /// Step A alone: no clusters, virtual samples or pooled η (the paper's shared steps are
    /// on by default; docs/fit.md).
    #[arg(long)]
    pub joint_only: bool,
    /// 1σ width of the prior cone of each refined normal about the mesh normal, degrees: how
    /// far the mesh's normals can be trusted (0 disables the prior).
    #[arg(long, default_value_t = 10.0)]
    pub normal_prior_deg: f64,
    /// Samples seen more obliquely than this from the mesh normal are gated out, degrees.
    #[arg(long, default_value_t = ellipso_fit::gate::GateConfig::default().grazing_cutoff_deg)]
    pub grazing_cutoff_deg: f64,
    /// Fraction of the posed frames held out of the fit and scored as a re-render (0 fits all;
    /// default 0.1).
    #[arg(long, default_value_t = 0.1)]
    pub holdout: f64,
    /// Fit one shard of the vertices, `I/N` (those with `v % N == I`), and write a part file to
    /// `--out` for `ellipso fit-merge`; `env` reads the index from the job array's environment
    /// (Slurm, Kubernetes Indexed Job, AWS Batch; docs/scale.md). Needs `--mesh`.
    #[arg(long)]
    pub shard: Option<String>,
    /// Number of shards with `--shard env` where the environment does not say it (Kubernetes
    /// `spec.completions`, AWS Batch array size).
    #[arg(long)]
    pub shard_count: Option<u32>,
    /// Print one JSON object (output folder, files, the fit summary) instead of the text report.
    #[arg(long)]
    pub json: bool,
}

/// Runs `ellipso fit`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let shard = shard_of(&args)?;
    // A given mesh is read first: a bad mesh is refused before the session is opened.
    let given_mesh = args
        .mesh
        .as_ref()
        .map(|path| {
            TriangleMesh::load(path).with_context(|| format!("loading mesh {}", path.display()))
        })
        .transpose()?;
    let session = ellipso_session::reader::open(&args.session)?;
    anyhow::ensure!(
        (0.0..=0.5).contains(&args.holdout),
        "--holdout {}: must be a fraction in [0, 0.5]",
        args.holdout
    );
    let read = session.report.summary();
    if read != "intact" {
        eprintln!("warning: {}: {read}", args.session.display());
    }
    if let Some(shard) = shard {
        let mesh_path = args.mesh.as_ref().expect("checked by shard_of");
        let mesh = given_mesh.expect("checked by shard_of");
        let out = args.out.as_ref().expect("checked by shard_of");
        let config = config_of(&args)?;
        return super::fit_shard::run_shard(
            &session,
            &args.session,
            mesh_path,
            &mesh,
            out,
            shard,
            config,
        );
    }
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("ellipso-fit"));
    let (mesh, hull) = match given_mesh {
        Some(mesh) if args.no_hull => (mesh, None),
        Some(mesh) => {
            eprintln!(
                "carving the visual hull from the frames (the surface update stays inside it)…"
            );
            match super::mesh::mesh_of_session(&session, &ellipso_mesh::MeshConfig::default()) {
                Ok((_, _, hull)) => (mesh, Some(hull)),
                Err(e) => {
                    eprintln!(
                        "warning: no visual hull ({e:#}); the surface update runs without the \
                         silhouettes' constraint"
                    );
                    (mesh, None)
                }
            }
        }
        None => {
            eprintln!("no --mesh: carving the object's mesh from the frames first…");
            let mut mesh_config = ellipso_mesh::MeshConfig::default();
            mesh_config.remesh.target_vertices = args.vertices;
            let (mesh, report, hull) = super::mesh::mesh_of_session(&session, &mesh_config)?;
            let path = out.join("mesh.ply");
            super::mesh::write_mesh(&mesh, &report, &path)?;
            eprintln!("  {} ({} vertices)", path.display(), report.vertices);
            (mesh, Some(hull))
        }
    };
    let mut config = config_of(&args)?;
    config.hull = hull.map(std::sync::Arc::new);
    let result = fit_and_export(&session, &mesh, &out, args.view, &config)?;
    if args.json {
        let json = serde_json::json!({
            "out": out.display().to_string(),
            "files": result.files.iter().map(|f| f.display().to_string()).collect::<Vec<_>>(),
            "summary": result.summary,
        });
        crate::outln!("{json}");
        return Ok(());
    }
    crate::outln!("\nresults in {}:", out.display());
    for f in &result.files {
        crate::outln!("  {}", f.display());
    }
    Ok(())
}

/// The shard of `--shard`/`--shard-count`, with the flags a shard needs checked.
fn shard_of(args: &Args) -> anyhow::Result<Option<Shard>> {
    let Some(spec) = args.shard.as_deref() else {
        anyhow::ensure!(
            args.shard_count.is_none(),
            "--shard-count is only used with --shard env"
        );
        return Ok(None);
    };
    let shard = if spec == "env" {
        Shard::from_env(&|var| std::env::var(var).ok(), args.shard_count)?
    } else {
        anyhow::ensure!(
            args.shard_count.is_none(),
            "--shard-count is only used with --shard env (--shard {spec} gives the count)"
        );
        Shard::parse(spec)?
    };
    anyhow::ensure!(
        args.mesh.is_some(),
        "--shard needs --mesh: every shard must fit the same mesh (carve it once with `ellipso \
         mesh` first)"
    );
    anyhow::ensure!(
        args.out.is_some(),
        "--shard needs --out PART: the part file this shard writes for `ellipso fit-merge`"
    );
    if let Some(outer) = args.outer {
        anyhow::ensure!(
            outer == 1,
            "--outer {outer} with --shard: a sharded fit runs one outer iteration (the shape \
             update needs every vertex's solve; docs/scale.md)"
        );
    }
    anyhow::ensure!(
        args.view.is_none(),
        "--view is given to `ellipso fit-merge`, which renders the pictures"
    );
    Ok(Some(shard))
}

/// The fit's settings from the flags (shared by whole and sharded runs).
fn config_of(args: &Args) -> anyhow::Result<SessionFitConfig> {
    let mut config = SessionFitConfig {
        outer_iterations: args.outer.unwrap_or(if args.shard.is_some() {
            1
        } else {
            SessionFitConfig::default().outer_iterations
        }),
        holdout_fraction: args.holdout,
        ..SessionFitConfig::default()
    };
    anyhow::ensure!(
        args.normal_prior_deg.is_finite() && (0.0..=90.0).contains(&args.normal_prior_deg),
        "--normal-prior-deg {}: must be in [0, 90]",
        args.normal_prior_deg
    );
    if args.joint_only {
        config.fit = ellipso_fit::pipeline::FitConfig::joint_only();
    }
    config.fit.solver.normal_prior_deg = args.normal_prior_deg;
    anyhow::ensure!(
        args.grazing_cutoff_deg.is_finite() && (10.0..=89.0).contains(&args.grazing_cutoff_deg),
        "--grazing-cutoff-deg {}: must be in [10, 89]",
        args.grazing_cutoff_deg
    );
    config.observe.gate.grazing_cutoff_deg = args.grazing_cutoff_deg;
    Ok(config)
}

/// What a session fit wrote.
pub struct FitRun {
    /// The fit.
    pub fit: SessionFit,
    /// Every file written.
    pub files: Vec<PathBuf>,
    /// Wall time, seconds.
    pub wall_s: f64,
    /// What `fit-summary.json` holds.
    pub summary: serde_json::Value,
}

/// The session's recorded poses (`pose` events), tracking first every complete frame that has
/// neither a pose nor a rejection (none tracked yet, or a tracking run cut short).
pub fn poses_of(session: &Session) -> anyhow::Result<Vec<(u64, Isometry3<f64>)>> {
    let untracked = ellipso_vision::process::untracked_frames(session);
    let mut poses = poses_from_session(session);
    if !untracked.is_empty() {
        eprintln!(
            "{} of {} complete frames have no pose yet: tracking their AprilTags first…",
            untracked.len(),
            session.frames.iter().filter(|f| f.complete).count()
        );
        let tracked = ellipso_vision::process::track_frames(
            session,
            &ellipso_vision::track::TrackConfig::default(),
            |id| untracked.contains(&id),
        )?;
        ellipso_vision::process::append_poses(
            &session.dir,
            &tracked,
            ellipso_session::time::HostClock::new().now(),
        )
        .context(
            "recording the new poses failed part-way (every line written is whole; the next \
             fit tracks the frames still without one)",
        )?;
        poses = poses_from_session(&ellipso_session::reader::open(&session.dir)?);
    }
    anyhow::ensure!(
        !poses.is_empty(),
        "{}: no frame could be posed from the AprilTags",
        session.dir.display()
    );
    Ok(poses)
}

/// Fits `mesh` to `session` and writes the outputs into `out` (see the module doc).
pub fn fit_and_export(
    session: &Session,
    mesh: &TriangleMesh,
    out: &Path,
    view: Option<u64>,
    config: &SessionFitConfig,
) -> anyhow::Result<FitRun> {
    let started = Instant::now();
    let poses = poses_of(session)?;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    // The solver weights samples by their expected noise (the session's sensor where known).
    let config = with_session_sensor(session, config);
    let progress = super::progress::Progress::spinner("fit");
    let fit = fit_session(session, mesh, &poses, &config, &mut |stage| {
        progress.set_message(stage)
    })?;
    progress.finish(format!(
        "{} vertices from {} posed frames",
        mesh.positions().len(),
        fit.observe.frames_posed
    ));
    for step in &fit.surface {
        let refused = !step.applied;
        eprintln!(
            "{}{}",
            if refused { "warning: " } else { "  " },
            step.describe()
        );
    }
    export_fit(session, &poses, fit, out, view, started)
}

/// The sensor model the solver weights by: the session's where it says it (simulator
/// sessions), the documented default otherwise.
pub fn with_session_sensor(session: &Session, config: &SessionFitConfig) -> SessionFitConfig {
    let mut config = config.clone();
    if let Some(scene) = ellipso_fit::observe::radiometry::scene_of(session) {
        config.fit.solver.sensor = ellipso_fit::accuracy::sensor_model(&scene);
    }
    config
}

/// Writes a finished fit's outputs into `out` (pictures from frame `view`, `fit-summary.json`);
/// `started` is when the whole run began.
pub fn export_fit(
    session: &Session,
    poses: &[(u64, Isometry3<f64>)],
    fit: SessionFit,
    out: &Path,
    view: Option<u64>,
    started: Instant,
) -> anyhow::Result<FitRun> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    // every posed frame that gave nothing is said, with its reason, and counted in the summary
    for s in &fit.observe.skipped {
        tracing::warn!("frame {} skipped: {}", s.frame_id, s.reason);
    }
    if !fit.observe.skipped.is_empty() {
        eprintln!(
            "warning: {} of {} posed frames skipped (reasons above and in fit-summary.json)",
            fit.observe.skipped.len(),
            fit.observe.frames_posed
        );
    }
    let (frame_id, world_from_camera) = match view {
        Some(id) => *poses
            .iter()
            .find(|p| p.0 == id)
            .with_context(|| format!("frame {id} has no pose"))?,
        None => fit.poses_fitted.first().copied().unwrap_or(poses[0]),
    };
    // The comparison picture shows the held-out frame with the most samples (one the fit never
    // saw); without held-out frames, the view of the maps.
    let comparison = fit
        .holdout
        .as_ref()
        .and_then(|h| h.per_frame.iter().max_by_key(|f| f.samples))
        .and_then(|f| f.frame_id)
        .and_then(|id| fit.poses_held_out.iter().find(|p| p.0 == id))
        .map(|p| (p.0, p.1, true))
        .unwrap_or((frame_id, world_from_camera, false));
    if let Some(h) = &fit.holdout {
        eprintln!(
            "held-out views: {} frames, {} samples: s0 relative RMSE {:.3} (PSNR {:.1} dB), I^s {:.3}, I^alpha {:.3}",
            h.per_frame.len(),
            h.overall.samples,
            h.overall.s0.relative_rmse,
            h.overall.s0.psnr_db,
            h.overall.specular.relative_rmse,
            h.overall.alpha.relative_rmse
        );
    }
    let rig: ellipso_session::rig::RigRecord = serde_json::from_value(session.manifest.rig.clone())
        .context("the session's manifest has no usable rig section")?;
    let flash: ellipso_sim::scene::FlashSpec = serde_json::from_value(rig.flash.clone())
        .context("the session's manifest has no usable flash section")?;
    eprintln!("pictures from frame {frame_id}…");
    let captured_s0 =
        match ellipso_fit::export::captured_s0(session, comparison.0, comparison.1, comparison.2) {
            Ok(c) => Some(c),
            Err(e) => {
                eprintln!("note: no comparison picture: frame {}: {e}", comparison.0);
                None
            }
        };
    let report = ellipso_fit::export::export_all(
        out,
        &fit.mesh,
        &fit.outcome.fits,
        &rig.camera,
        &world_from_camera,
        &flash,
        &ellipso_fit::export::ExportConfig::default(),
        captured_s0.as_ref(),
    )?;
    let wall_s = started.elapsed().as_secs_f64();
    let mut files = report.files.clone();
    let summary = out.join("fit-summary.json");
    let json = serde_json::json!({
        "session": session.dir.display().to_string(),
        "vertices": fit.outcome.fits.len(),
        "frames_posed": poses.len(),
        "frames_fitted": fit.poses_fitted.len(),
        "frames_held_out": fit.poses_held_out.iter().map(|p| p.0).collect::<Vec<_>>(),
        "held_out": fit.holdout,
        "pooling": fit.outcome.pooling,
        "frames_used": fit.observe.frames_used,
        "frames_skipped": fit.observe.skipped,
        "observe": fit.observe,
        "session_report": session.report.summary(),
        "view_frame_id": frame_id,
        "times_s": fit.outcome.times,
        "wall_s": wall_s,
        "gates": fit.gates,
        "surface_update": fit.surface,
        "surface_stopped": fit.surface.iter().rev().find_map(|s| s.stopped.clone()),
        "observed_vertices": fit.observed.iter().filter(|o| **o).count(),
        "peak_rss_bytes": super::memory::peak_rss_bytes(),
        "clusters": fit.outcome.augmentation.as_ref().map(|a| &a.clusters),
        "export": report,
    });
    ellipso_report::atomic_file::write(&summary, serde_json::to_vec_pretty(&json)?)
        .with_context(|| format!("writing {}", summary.display()))?;
    files.push(summary);
    Ok(FitRun {
        fit,
        files,
        wall_s,
        summary: json,
    })
}
