//! `ellipso fit SESSION --mesh MESH --out DIR`: the polarimetric SVBRDF and refined shape of a
//! recorded session, per mesh vertex, with its pictures.
//!
//! Poses come from the session's `pose` events (tracked now and appended when the log has
//! none), or from a COLMAP model aligned to them (`--poses`, `fit_import`). The mesh is a
//! triangle mesh (PLY or OBJ) in board (world) coordinates, metres, from any scanner or
//! photogrammetry, or in a COLMAP model's frame (`--mesh-frame colmap`); without `--mesh` it is
//! carved from the session's own frames first (`ellipso mesh`, written to `OUT/mesh.ply`). Writes `fit.ply` (per-vertex parameters
//! and uncertainties), the pictures of the fitted model from one captured view, and
//! `fit-summary.json`.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use ellipso_model::geometry::TriangleMesh;
use nalgebra::Isometry3;

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
    /// Poses and a mesh from COLMAP or other photogrammetry (`--poses`, `--mesh-frame`,
    /// `--mesh-model`).
    #[command(flatten)]
    pub import: super::fit_import::ImportArgs,
}

/// Runs `ellipso fit`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let shard = shard_of(&args)?;
    // the output is claimed before any work: a bad --out is refused at once, not after the fit
    let mut inputs: Vec<&Path> = vec![&args.session];
    inputs.extend(args.mesh.as_deref());
    let out_dir = match &shard {
        Some(_) => None,
        None => Some(ellipso_report::output::OutputDir::claim(
            args.out.as_deref().unwrap_or(Path::new("ellipso-fit")),
            "fit",
            &inputs,
        )?),
    };
    let part_file = match (&shard, &args.out) {
        (Some(_), Some(out)) => Some(super::fit_shard::claim_part(out, &inputs)?),
        _ => None,
    };
    // A given mesh is read first: a bad mesh is refused before the session is opened.
    let given_mesh = args
        .mesh
        .as_ref()
        .map(|path| {
            TriangleMesh::load(path).with_context(|| format!("loading mesh {}", path.display()))
        })
        .transpose()?;
    let models = super::fit_import::read(&args.import, args.mesh.is_some(), args.shard.is_some())?;
    let session = ellipso_session::reader::open(&args.session)?;
    anyhow::ensure!(
        (0.0..=0.5).contains(&args.holdout),
        "--holdout {}: must be a fraction in [0, 0.5]",
        args.holdout
    );
    // --view names a frame of the session: checked now, not after the fit
    if let Some(id) = args.view {
        anyhow::ensure!(
            session
                .frames
                .iter()
                .any(|f| f.frame_id == id && f.complete),
            "--view {id}: {} has no complete frame {id}",
            args.session.display()
        );
    }
    let read = session.report.summary();
    if read != "intact" {
        crate::errln!("warning: {}: {read}", args.session.display());
    }
    if let Some(shard) = shard {
        let mesh_path = args.mesh.as_ref().expect("checked by shard_of");
        let mesh = given_mesh.expect("checked by shard_of");
        let out = part_file.expect("claimed above with the --out shard_of checked");
        let config = config_of(&args)?;
        return super::fit_shard::run_shard(
            &session,
            &args.session,
            mesh_path,
            &mesh,
            &out,
            shard,
            config,
        );
    }
    let out_dir = out_dir.expect("claimed above without --shard");
    let out = out_dir.path().to_path_buf();
    let (given_mesh, import) = super::fit_import::apply(models, &session, given_mesh, &out)?;
    let imported_poses = import.as_ref().and_then(|i| i.poses.as_deref());
    let (mesh, hull) = match given_mesh {
        Some(mesh) if args.no_hull => (mesh, None),
        Some(mesh) => {
            crate::errln!(
                "carving the visual hull from the frames (the surface update stays inside it)…"
            );
            let progress = super::progress::Progress::spinner("mesh");
            match ellipso_mesh::output::mesh_of_session(
                &session,
                imported_poses,
                &ellipso_mesh::MeshConfig::default(),
                &super::out::Printed,
                &mut |stage| progress.set_message(stage),
            )
            .map_err(super::out::failed)
            {
                Ok((_, report, hull)) => {
                    progress.finish(format!(
                        "{} vertices from {} frames",
                        report.vertices, report.frames_used
                    ));
                    (mesh, Some(hull))
                }
                Err(e) => {
                    crate::errln!(
                        "warning: no visual hull ({e:#}); the surface update runs without the \
                         silhouettes' constraint"
                    );
                    (mesh, None)
                }
            }
        }
        None => {
            crate::errln!("no --mesh: carving the object's mesh from the frames first…");
            let mut mesh_config = ellipso_mesh::MeshConfig::default();
            mesh_config.remesh.target_vertices = args.vertices;
            let progress = super::progress::Progress::spinner("mesh");
            let (mesh, report, hull) = ellipso_mesh::output::mesh_of_session(
                &session,
                imported_poses,
                &mesh_config,
                &super::out::Printed,
                &mut |stage| progress.set_message(stage),
            )
            .map_err(super::out::failed)?;
            progress.finish(format!(
                "{} vertices from {} frames",
                report.vertices, report.frames_used
            ));
            let path = out.join("mesh.ply");
            ellipso_mesh::output::write_mesh(&mesh, &report, &path).map_err(super::out::failed)?;
            crate::errln!(
                "  {} ({} vertices)",
                out_dir.published(&path).display(),
                report.vertices
            );
            (mesh, Some(hull))
        }
    };
    let mut config = config_of(&args)?;
    config.hull = hull.map(std::sync::Arc::new);
    let result = fit_and_export_with(
        &session,
        &mesh,
        import.as_ref(),
        &out,
        args.view,
        &config,
        &|p| out_dir.published(p),
    )?;
    let out = out_dir.commit()?;
    print_results(&out, &result, args.json);
    Ok(())
}

/// The text or JSON report of a written fit (files already as published).
pub fn print_results(out: &Path, result: &FitRun, json: bool) {
    if json {
        let json = serde_json::json!({
            "out": out.display().to_string(),
            "files": result.files.iter().map(|f| f.display().to_string()).collect::<Vec<_>>(),
            "summary": result.summary,
        });
        crate::outln!("{json}");
        return;
    }
    crate::outln!("\nresults in {}:", out.display());
    for f in &result.files {
        crate::outln!("  {}", f.display());
    }
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

/// Fits `mesh` to `session` and writes the outputs into `out` (see the module doc); `publish`
/// maps a path under `out` to where it will be once the output is committed (recorded paths).
pub fn fit_and_export(
    session: &Session,
    mesh: &TriangleMesh,
    out: &Path,
    view: Option<u64>,
    config: &SessionFitConfig,
    publish: &dyn Fn(&Path) -> PathBuf,
) -> anyhow::Result<FitRun> {
    fit_and_export_with(session, mesh, None, out, view, config, publish)
}

/// [`fit_and_export`] with what `--poses`/`--mesh-frame` imported: its poses (else the
/// session's) and its summary (`import` in `fit-summary.json`).
pub fn fit_and_export_with(
    session: &Session,
    mesh: &TriangleMesh,
    import: Option<&super::fit_import::Imported>,
    out: &Path,
    view: Option<u64>,
    config: &SessionFitConfig,
    publish: &dyn Fn(&Path) -> PathBuf,
) -> anyhow::Result<FitRun> {
    let started = Instant::now();
    let poses = match import.and_then(|i| i.poses.clone()) {
        Some(poses) => poses,
        None => ellipso_mesh::poses::poses_of(session, &super::out::Printed)
            .map_err(super::out::failed)?,
    };
    // the pictures' frame is checked before the long work, not after it
    if let Some(id) = view {
        anyhow::ensure!(
            poses.iter().any(|p| p.0 == id),
            "--view {id}: frame {id} has no pose in {} ({} posed frames, ids {}…{})",
            session.dir.display(),
            poses.len(),
            poses.first().map_or(0, |p| p.0),
            poses.last().map_or(0, |p| p.0)
        );
    }
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
        crate::errln!(
            "{}{}",
            if refused { "warning: " } else { "  " },
            step.describe()
        );
    }
    export_fit(
        session,
        &poses,
        fit,
        OutputTo { dir: out, publish },
        view,
        started,
        import.map(|i| &i.summary),
    )
}

/// The sensor model the solver weights by: the session's where it records it (simulator
/// sessions), the documented default otherwise.
pub fn with_session_sensor(session: &Session, config: &SessionFitConfig) -> SessionFitConfig {
    let mut config = config.clone();
    if let Some(sensor) = ellipso_fit::observe::sensor_noise_of(session) {
        config.fit.solver.sensor = sensor;
    }
    config
}

/// Where a fit's outputs go: the (staging) folder written now, and where a path under it will
/// be once the output is committed (the paths recorded and shown).
pub struct OutputTo<'a> {
    pub dir: &'a Path,
    pub publish: &'a dyn Fn(&Path) -> PathBuf,
}

/// Writes a finished fit's outputs into `to.dir` (pictures from frame `view`, `fit-summary.json`
/// with `import` where poses or a mesh were imported); `started` is when the whole run began.
pub fn export_fit(
    session: &Session,
    poses: &[(u64, Isometry3<f64>)],
    fit: SessionFit,
    to: OutputTo<'_>,
    view: Option<u64>,
    started: Instant,
    import: Option<&serde_json::Value>,
) -> anyhow::Result<FitRun> {
    let (out, publish) = (to.dir, to.publish);
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    // every posed frame that gave nothing is said, with its reason, and counted in the summary
    for s in &fit.observe.skipped {
        tracing::warn!("frame {} skipped: {}", s.frame_id, s.reason);
    }
    if !fit.observe.skipped.is_empty() {
        crate::errln!(
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
        crate::errln!(
            "held-out views: {} frames, {} samples: s0 relative RMSE {:.3} (PSNR {:.1} dB), I^s {:.3}, I^alpha {:.3}",
            h.per_frame.len(),
            h.overall.samples,
            h.overall.s0.relative_rmse,
            h.overall.s0.psnr_db,
            h.overall.specular.relative_rmse,
            h.overall.alpha.relative_rmse
        );
    }
    let rig = (session.manifest.rig.as_ref())
        .context("the session's manifest has no usable rig section")?;
    let flash = ellipso_fit::observe::flash_of(session)?;
    crate::errln!("pictures from frame {frame_id}…");
    let captured_s0 =
        match ellipso_fit::export::captured_s0(session, comparison.0, comparison.1, comparison.2) {
            Ok(c) => Some(c),
            Err(e) => {
                crate::errln!("note: no comparison picture: frame {}: {e}", comparison.0);
                None
            }
        };
    let mut report = ellipso_fit::export::export_all(
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
    // recorded and printed paths are where the files will be, not the staging directory
    for f in &mut report.files {
        *f = publish(f);
    }
    let mut files = report.files.clone();
    let summary = out.join("fit-summary.json");
    let mut json = serde_json::json!({
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
        "peak_rss_bytes": ellipso_report::memory::peak_rss_bytes(),
        "clusters": fit.outcome.augmentation.as_ref().map(|a| &a.clusters),
        "export": report,
    });
    if let Some(import) = import {
        json["import"] = import.clone();
    }
    // every path in the summary is relative to its own folder
    super::out::paths_relative_to(&mut json, out);
    ellipso_report::atomic_file::write(&summary, serde_json::to_vec_pretty(&json)?)
        .with_context(|| format!("writing {}", publish(&summary).display()))?;
    files.push(publish(&summary));
    Ok(FitRun {
        fit,
        files,
        wall_s,
        summary: json,
    })
}
