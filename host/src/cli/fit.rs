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
use ellipso_sim::geometry::TriangleMesh;
use nalgebra::Isometry3;

use crate::fit::observe::poses_from_session;
use crate::fit::session::{SessionFit, SessionFitConfig, fit_session};
use crate::session::reader::Session;

/// Arguments of `ellipso fit`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The session directory.
    pub session: PathBuf,
    /// Triangle mesh of the object (PLY or OBJ), board coordinates, metres (default: carved
    /// from the session's frames, as `ellipso mesh` does).
    #[arg(long)]
    pub mesh: Option<PathBuf>,
    /// Output directory.
    #[arg(long, default_value = "ellipso-fit")]
    pub out: PathBuf,
    /// Frame id of the view the pictures are rendered from (default: the first posed frame).
    #[arg(long)]
    pub view: Option<u64>,
    /// Outer iterations (solve ↔ shape update); 1 keeps the input geometry.
    #[arg(long, default_value_t = 2)]
    pub outer: usize,
    /// Add the paper's specular augmentation (clusters, virtual samples, 3 final passes); off
    /// by default: on the shipped scenes it costs 3–10× the time and measured worse
    /// (docs/accuracy-vs-time.md).
    #[arg(long)]
    pub augment: bool,
}

/// Runs `ellipso fit`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let session = crate::session::reader::open(&args.session)?;
    let mesh = match &args.mesh {
        Some(path) => {
            TriangleMesh::load(path).with_context(|| format!("loading mesh {}", path.display()))?
        }
        None => {
            println!("no --mesh: carving the object's mesh from the frames first…");
            let (mesh, report) =
                super::mesh::mesh_of_session(&session, &crate::mesh::MeshConfig::default())?;
            let path = args.out.join("mesh.ply");
            super::mesh::write_mesh(&mesh, &report, &path)?;
            println!("  {} ({} vertices)", path.display(), report.vertices);
            mesh
        }
    };
    let mut config = SessionFitConfig {
        outer_iterations: args.outer.max(1),
        ..SessionFitConfig::default()
    };
    if args.augment {
        config.fit = crate::fit::pipeline::FitConfig {
            solver: config.fit.solver.clone(),
            ..crate::fit::pipeline::FitConfig::with_augmentation(3)
        };
    }
    let result = fit_and_export(&session, &mesh, &args.out, args.view, &config)?;
    println!("\nresults in {}:", args.out.display());
    for f in &result.files {
        println!("  {}", f.display());
    }
    Ok(())
}

/// What a session fit wrote.
pub struct FitRun {
    /// The fit.
    pub fit: SessionFit,
    /// Every file written.
    pub files: Vec<PathBuf>,
    /// Wall time, seconds.
    pub wall_s: f64,
}

/// The session's recorded poses (`pose` events), tracking them first when there are none.
pub fn poses_of(session: &Session) -> anyhow::Result<Vec<(u64, Isometry3<f64>)>> {
    let mut poses = poses_from_session(session);
    if poses.is_empty() {
        println!("no poses recorded: tracking the AprilTags first…");
        super::capture::track_and_append(&session.dir)?;
        poses = poses_from_session(&crate::session::reader::open(&session.dir)?);
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
    // The solver weights samples by their expected noise: the sensor's gain and read noise
    // where the session says them (simulator sessions), the documented default otherwise.
    let mut config = config.clone();
    if let Some(scene) = crate::fit::observe::radiometry::scene_of(session) {
        config.fit.solver.sensor = crate::fit::accuracy::sensor_model(&scene);
    }
    let fit = fit_session(session, mesh, &poses, &config, &mut |stage| {
        println!("  {stage}…")
    })?;
    let (frame_id, world_from_camera) = match view {
        Some(id) => *poses
            .iter()
            .find(|p| p.0 == id)
            .with_context(|| format!("frame {id} has no pose"))?,
        None => poses[0],
    };
    let rig: crate::process::RigRecord = serde_json::from_value(session.manifest.rig.clone())
        .context("the session's manifest has no usable rig section")?;
    let flash: ellipso_sim::scene::FlashSpec = serde_json::from_value(rig.flash.clone())
        .context("the session's manifest has no usable flash section")?;
    println!("  pictures from frame {frame_id}…");
    let captured_s0 = crate::export::captured_s0(session, frame_id, world_from_camera).ok();
    let report = crate::export::export_all(
        out,
        &fit.mesh,
        &fit.outcome.fits,
        &rig.camera,
        &world_from_camera,
        &flash,
        &crate::export::ExportConfig::default(),
        captured_s0.as_ref(),
    )?;
    let wall_s = started.elapsed().as_secs_f64();
    let mut files = report.files.clone();
    let summary = out.join("fit-summary.json");
    let json = serde_json::json!({
        "session": session.dir.display().to_string(),
        "vertices": fit.outcome.fits.len(),
        "frames_posed": poses.len(),
        "view_frame_id": frame_id,
        "times_s": fit.outcome.times,
        "wall_s": wall_s,
        "gates": fit.gates,
        "shape_updates_rms_mm": fit.shape_updates.iter().map(|u| u.rms_displacement_m * 1e3).collect::<Vec<_>>(),
        "clusters": fit.outcome.augmentation.as_ref().map(|a| &a.clusters),
        "export": report,
    });
    std::fs::write(&summary, serde_json::to_vec_pretty(&json)?)
        .with_context(|| format!("writing {}", summary.display()))?;
    files.push(summary);
    Ok(FitRun { fit, files, wall_s })
}
