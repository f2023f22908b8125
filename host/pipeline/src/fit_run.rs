//! The fit of a recorded session as `ellipso fit` runs it (and the demo, through
//! [`fit_and_export`]): the output claimed, the inputs read and checked, the poses (tracked, or
//! imported from a COLMAP model, [`crate::fit_import`]), the mesh carved when none is given and
//! the visual hull with a given one, the fit, and its files ([`ellipso_fit::output`]); with a
//! shard, one shard's part file instead ([`crate::fit_shard`]).
//!
//! Contract:
//! - Everything that can be refused is refused before the long work: the output (a bad `--out`),
//!   a given mesh, the import flags and models, the session, the held-out fraction and the
//!   pictures' frame, in that order.
//! - The output folder is written beside and committed whole at the end (`ellipso_report::
//!   output`); the recorded paths are where the files are once committed.
//! - Nothing here prints: each long step (`mesh`, `fit`) is begun, staged and ended on the
//!   caller's [`Steps`] (the binary draws a spinner per step), and every other line goes to the
//!   caller's [`Say`].

use std::path::{Path, PathBuf};
use std::time::Instant;

use ellipso_fit::output::{FitRun, OutputTo, export_fit};
use ellipso_fit::session::{SessionFitConfig, fit_session, with_session_sensor};
use ellipso_fit::shape::hull::HullField;
use ellipso_fit::shard::Shard;
use ellipso_model::geometry::TriangleMesh;
use ellipso_report::output::{OutputDir, OutputFile};
use ellipso_run_error::{Context, RunError, Say};
use ellipso_session::reader::Session;
use nalgebra::Isometry3;

use crate::fit_import::{ImportFlags, Imported, Models};
use crate::fit_shard::{ShardInputs, ShardRun};
use crate::mesh::{mesh_of_session, write_mesh};
use crate::steps::Steps;

/// What `ellipso fit` is given (its flags, parsed).
pub struct FitRequest<'a> {
    /// The session folder.
    pub session: &'a Path,
    /// The object's mesh file (PLY or OBJ), board frame unless `import` says otherwise; `None`:
    /// carved from the session's frames first, and written to `OUT/mesh.ply`.
    pub mesh: Option<&'a Path>,
    /// The output folder; with `shard`, the part file.
    pub out: &'a Path,
    /// Frame id of the pictures' view (default: the first fitted frame).
    pub view: Option<u64>,
    /// Target vertex count of the mesh carved without `mesh`.
    pub vertices: usize,
    /// Do not carve the visual hull for a given mesh.
    pub no_hull: bool,
    /// The fit's settings (`holdout_fraction` is checked here, against [0, 0.5]).
    pub config: SessionFitConfig,
    /// One shard of the vertices (needs `mesh`, no `view`, no import).
    pub shard: Option<Shard>,
    /// `--poses`, `--mesh-frame`, `--mesh-model`.
    pub import: ImportFlags,
    /// `--sensor-calibration`: the file to read the frames with where the session recorded
    /// none (a session that recorded one accepts only that one; [`crate::sensor`]).
    pub sensor_calibration: Option<&'a Path>,
}

/// What `ellipso fit` did.
pub enum FitDone {
    /// A whole fit: the committed output folder and what was written into it.
    Whole {
        /// The output folder, committed.
        out: PathBuf,
        /// The fit and its files.
        run: Box<FitRun>,
    },
    /// One shard's part file.
    Shard(ShardRun),
}

/// Runs `ellipso fit` (module contract).
pub fn run(
    mut request: FitRequest<'_>,
    steps: &mut dyn Steps,
    say: &dyn Say,
) -> Result<FitDone, RunError> {
    let Checked {
        out_dir,
        part_file,
        given_mesh,
        models,
        session,
        mesh_config,
    } = check_request(&mut request, say)?;
    let FitRequest {
        session: session_dir,
        mesh: mesh_path,
        view,
        vertices,
        no_hull,
        mut config,
        shard,
        ..
    } = request;
    if let Some(shard) = shard {
        let inputs = ShardInputs {
            session: &session,
            session_dir,
            mesh_path: mesh_path.context("a shard needs --mesh")?,
            mesh: given_mesh.as_ref().context("a shard needs --mesh")?,
        };
        let part = part_file.expect("claimed above with --shard");
        return Ok(FitDone::Shard(crate::fit_shard::run_shard(
            inputs, &part, shard, config, say,
        )?));
    }
    let out_dir = out_dir.expect("claimed above without --shard");
    let out = out_dir.path().to_path_buf();
    let (given_mesh, import) = crate::fit_import::apply(models, &session, given_mesh, &out, say)?;
    // the poses, taken once (checked, tracked where needed, their warnings said once) for the
    // saved hull, the carving and the fit alike
    let poses = match import.as_ref().and_then(|i| i.poses.clone()) {
        Some(imported) => imported,
        None => crate::poses::poses_of(&session, say)?,
    };
    let (mesh, hull) = match given_mesh {
        Some(mesh) if no_hull => (mesh, None),
        Some(mesh) => {
            // the hull `ellipso mesh` saved beside this mesh, when it is this session's, carved
            // from the poses this fit takes, for this very file (crate::mesh_hull)
            let imported = import.as_ref().is_some_and(|i| i.poses.is_some());
            let saved_beside = mesh_path.filter(|_| !imported);
            let hull = hull_of_given_mesh(saved_beside, &session, &poses, &mesh_config, steps, say);
            (mesh, hull)
        }
        None => carve_mesh(
            &session,
            &poses,
            mesh_config,
            vertices,
            &out_dir,
            steps,
            say,
        )?,
    };
    config.hull = hull.map(std::sync::Arc::new);
    let run = fit_and_export(
        &session,
        &mesh,
        Some(&poses[..]),
        import.as_ref(),
        OutputTo {
            dir: &out,
            publish: &|p| out_dir.published(p),
        },
        view,
        &config,
        steps,
        say,
    )?;
    Ok(FitDone::Whole {
        out: out_dir.commit()?,
        run: Box::new(run),
    })
}

/// What [`check_request`] claimed, read and checked before the long work.
struct Checked {
    /// The output folder, claimed (without a shard).
    out_dir: Option<OutputDir>,
    /// The part file, claimed (with a shard).
    part_file: Option<OutputFile>,
    /// The given mesh, read.
    given_mesh: Option<TriangleMesh>,
    /// The COLMAP models the import flags name, read.
    models: Option<Models>,
    /// The session, opened.
    session: Session,
    /// The carving's settings, with the sensor calibration the frames are read with.
    mesh_config: ellipso_mesh::MeshConfig,
}

/// Everything that can be refused, in the module contract's order: claims the output, reads
/// the given mesh and the import's models, opens the session, checks the held-out fraction and
/// the pictures' frame, and settles the sensor calibration (set into `request.config`); warns
/// when the session was not read intact.
fn check_request(request: &mut FitRequest<'_>, say: &dyn Say) -> Result<Checked, RunError> {
    let session_dir = request.session;
    let mesh_path = request.mesh;
    let shard = request.shard;
    let config = &mut request.config;
    // the output is claimed before any work: a bad --out is refused at once, not after the fit
    let mut inputs: Vec<&Path> = vec![session_dir];
    inputs.extend(mesh_path);
    let (out_dir, part_file) = match shard {
        Some(_) => (
            None,
            Some(crate::fit_shard::claim_part(request.out, &inputs)?),
        ),
        None => (Some(OutputDir::claim(request.out, "fit", &inputs)?), None),
    };
    // A given mesh is read first: a bad mesh is refused before the session is opened.
    let given_mesh = mesh_path
        .map(|path| {
            TriangleMesh::load(path).with_context(|| format!("loading mesh {}", path.display()))
        })
        .transpose()?;
    let models = crate::fit_import::read(&request.import, mesh_path.is_some(), shard.is_some())?;
    let session = ellipso_session::reader::open(session_dir)?;
    ellipso_run_error::ensure!(
        (0.0..=0.5).contains(&config.holdout_fraction),
        "--holdout {}: must be a fraction in [0, 0.5]",
        config.holdout_fraction
    );
    // --view names a frame of the session: checked now, not after the fit
    if let Some(id) = request.view {
        ellipso_run_error::ensure!(
            session
                .frames
                .iter()
                .any(|f| f.frame_id == id && f.complete),
            "--view {id}: {} has no complete frame {id}",
            session_dir.display()
        );
    }
    let sensor = crate::sensor::session_calibration(
        &session,
        request.sensor_calibration,
        config.observe.dark_level_dn,
        say,
    )?;
    config.observe.sensor_calibration = sensor.clone();
    let mesh_config = ellipso_mesh::MeshConfig {
        sensor_calibration: sensor,
        ..Default::default()
    };
    let read = session.report.summary();
    if read != "intact" {
        say.err(format_args!("warning: {}: {read}", session_dir.display()));
    }
    Ok(Checked {
        out_dir,
        part_file,
        given_mesh,
        models,
        session,
        mesh_config,
    })
}

/// The visual hull for a given mesh: the one `ellipso mesh` saved beside `saved_beside` (the
/// mesh file, `None` where the poses are imported) when it is reusable, else carved from the
/// frames; `None`, with a warning, when the carving fails.
fn hull_of_given_mesh(
    saved_beside: Option<&Path>,
    session: &Session,
    poses: &[(u64, Isometry3<f64>)],
    mesh_config: &ellipso_mesh::MeshConfig,
    steps: &mut dyn Steps,
    say: &dyn Say,
) -> Option<HullField> {
    let saved = match saved_beside {
        Some(path) => {
            let identity = crate::mesh_hull::SessionIdentity::of(session);
            match crate::mesh_hull::reusable_hull(path, &identity, poses) {
                Ok(hull) => hull.map(|h| (h, path)),
                Err(why) => {
                    say.err(format_args!("not reusing the saved hull: {why}"));
                    None
                }
            }
        }
        None => None,
    };
    if let Some((hull, path)) = saved {
        say.err(format_args!(
            "reusing the visual hull `ellipso mesh` saved beside {} (same session, \
             poses and mesh file; the surface update stays inside it)",
            path.display()
        ));
        Some(hull)
    } else {
        say.err(format_args!(
            "carving the visual hull from the frames (the surface update stays inside it)…"
        ));
        match mesh_of_session(session, Some(poses), mesh_config, say, steps) {
            Ok((_, _, hull)) => Some(hull),
            Err(e) => {
                let e = e.into_boxed();
                say.err(format_args!(
                    "warning: no visual hull ({}); the surface update runs without the \
                 silhouettes' constraint",
                    chain(e.as_ref())
                ));
                None
            }
        }
    }
}

/// Without `--mesh`: the object's mesh carved from the frames (`vertices` vertices), written to
/// `OUT/mesh.ply`, with its visual hull.
fn carve_mesh(
    session: &Session,
    poses: &[(u64, Isometry3<f64>)],
    mut mesh_config: ellipso_mesh::MeshConfig,
    vertices: usize,
    out_dir: &OutputDir,
    steps: &mut dyn Steps,
    say: &dyn Say,
) -> Result<(TriangleMesh, Option<HullField>), RunError> {
    say.err(format_args!(
        "no --mesh: carving the object's mesh from the frames first…"
    ));
    mesh_config.remesh.target_vertices = vertices;
    let (mesh, report, hull) = mesh_of_session(session, Some(poses), &mesh_config, say, steps)?;
    let path = out_dir.path().join("mesh.ply");
    write_mesh(&mesh, &report, &path)?;
    say.err(format_args!(
        "  {} ({} vertices)",
        out_dir.published(&path).display(),
        report.vertices
    ));
    Ok((mesh, Some(hull)))
}

/// An error and its causes on one line, `a: b: c` (as `anyhow`'s `{:#}` writes it).
fn chain(e: &(dyn std::error::Error + 'static)) -> String {
    let mut text = e.to_string();
    let mut cause = e.source();
    while let Some(c) = cause {
        text.push_str(&format!(": {c}"));
        cause = c.source();
    }
    text
}

/// Fits `mesh` to `session` and writes the outputs into `to` ([`ellipso_fit::output`]): with
/// `poses` where given (the caller took them already), else those of `import` (`--poses`,
/// `--mesh-frame`), else the session's poses (tracked first where the log has none); the
/// summary of `import` where given; pictures from frame `view`.
#[expect(
    clippy::too_many_arguments,
    reason = "the session, mesh, import, output and settings are independent values"
)]
pub fn fit_and_export(
    session: &Session,
    mesh: &TriangleMesh,
    poses: Option<&[(u64, Isometry3<f64>)]>,
    import: Option<&Imported>,
    to: OutputTo<'_>,
    view: Option<u64>,
    config: &SessionFitConfig,
    steps: &mut dyn Steps,
    say: &dyn Say,
) -> Result<FitRun, RunError> {
    let started = Instant::now();
    let poses = match (poses, import.and_then(|i| i.poses.clone())) {
        (Some(given), _) => given.to_vec(),
        (None, Some(imported)) => imported,
        (None, None) => crate::poses::poses_of(session, say)?,
    };
    // the pictures' frame is checked before the long work, not after it
    if let Some(id) = view {
        ellipso_run_error::ensure!(
            poses.iter().any(|p| p.0 == id),
            "--view {id}: frame {id} has no pose in {} ({} posed frames, ids {}…{})",
            session.dir.display(),
            poses.len(),
            poses.first().map_or(0, |p| p.0),
            poses.last().map_or(0, |p| p.0)
        );
    }
    std::fs::create_dir_all(to.dir).with_context(|| format!("creating {}", to.dir.display()))?;
    // The solver weights samples by their expected noise (the session's sensor where known).
    let config = with_session_sensor(session, config);
    steps.begin("fit");
    let fit = fit_session(session, mesh, &poses, &config, &mut |stage| {
        steps.stage(stage)
    })?;
    steps.end(&format!(
        "{} vertices from {} posed frames",
        mesh.positions().len(),
        fit.observe.frames_posed
    ));
    for step in &fit.surface {
        let refused = !step.applied;
        say.err(format_args!(
            "{}{}",
            if refused { "warning: " } else { "  " },
            step.describe()
        ));
    }
    if let Some(c) = &fit.normal_combination {
        say.err(format_args!("  {}", c.describe()));
    }
    let import = import
        .map(|i| serde_json::to_value(&i.summary))
        .transpose()?;
    export_fit(session, &poses, fit, to, view, started, import, say)
}
