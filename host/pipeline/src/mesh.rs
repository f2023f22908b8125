//! The session's mesh as the subcommands take it (`ellipso mesh`, `fit` without `--mesh` or
//! with its hull, bench mesh, the demo) and the files it is written to.
//!
//! Contract: [`mesh_of_session`] carves from the poses given, or from the session's tracked
//! poses ([`crate::poses::poses_of`], tracking and appending them first when the log has none),
//! and reports each stage to the caller's callback; it never prints. [`write_mesh`] writes the
//! binary PLY and its `<stem>-report.json` ([`report_path`]) whole, into a directory the caller
//! owns; [`mesh_bytes`] is the one encoding of a mesh file (binary little-endian PLY with
//! double coordinates, or OBJ). [`mesh_command`] is `ellipso mesh` whole: both files claimed
//! before the work (never inside the session, never over a file of another format), the mesh
//! carved (its step on the caller's [`Steps`]) and both written whole, with the carved hull
//! beside them ([`crate::mesh_hull`]).

use std::path::{Path, PathBuf};

use ellipso_fit::shape::hull::HullField;
use ellipso_model::geometry::TriangleMesh;
use ellipso_model::geometry::ply::{PlyFormat, write_ply};
use ellipso_report::output::FileFormat;
use ellipso_run_error::{Context, RunError, Say};
use ellipso_session::reader::Session;
use nalgebra::Isometry3;

use crate::steps::Steps;
use ellipso_mesh::{MeshConfig, MeshReport, build_mesh};

/// Carves the session's mesh from `poses`, or from its tracked poses (tracking it first if it
/// has none); also returns the carved hull (the fit's surface update stays inside it). The
/// carving is one step on `steps` (`mesh`, its stages, then "N vertices from M frames"; a
/// failure leaves the step unended, as the trait allows); the tracking's lines go to `say`.
pub fn mesh_of_session(
    session: &Session,
    poses: Option<&[(u64, Isometry3<f64>)]>,
    config: &MeshConfig,
    say: &dyn Say,
    steps: &mut dyn Steps,
) -> Result<(TriangleMesh, MeshReport, HullField), RunError> {
    steps.begin("mesh");
    // the session's recorded sensor calibration where the caller gave none (crate::sensor)
    let recorded;
    let config = if config.sensor_calibration.is_none() {
        recorded = MeshConfig {
            sensor_calibration: ellipso_polar::sensor_calibration::for_session(
                &session.manifest,
                None,
            )?
            .map(std::sync::Arc::new),
            ..config.clone()
        };
        &recorded
    } else {
        config
    };
    let poses = match poses {
        Some(p) => p.to_vec(),
        None => crate::poses::poses_of(session, say)?,
    };
    let result = build_mesh(session, &poses, config, &mut |stage| steps.stage(stage))
        .with_context(|| format!("meshing {}", session.dir.display()))?;
    steps.end(&format!(
        "{} vertices from {} frames",
        result.report.vertices, result.report.frames_used
    ));
    Ok((result.mesh, result.report, result.hull))
}

/// The report's path beside a mesh file: `<stem>-report.json`.
pub fn report_path(out: &Path) -> PathBuf {
    let stem = out.file_stem().and_then(|s| s.to_str()).unwrap_or("mesh");
    out.with_file_name(format!("{stem}-report.json"))
}

/// A mesh's bytes in `format` (binary PLY unless OBJ).
pub fn mesh_bytes(mesh: &TriangleMesh, format: FileFormat) -> Vec<u8> {
    if format == FileFormat::OBJ {
        ellipso_model::geometry::obj::write_obj(mesh)
    } else {
        // double: a fit on this file sees exactly the geometry the fit that wrote it used
        write_ply(mesh, PlyFormat::BinaryLittleEndian, true)
    }
}

/// Writes the mesh (binary PLY) and its report (`<stem>-report.json`) into a directory the
/// caller owns (a fit's or the demo's staging directory), each whole; returns the report path.
pub fn write_mesh(
    mesh: &TriangleMesh,
    report: &MeshReport,
    out: &Path,
) -> Result<PathBuf, RunError> {
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    ellipso_report::atomic_file::write(out, mesh_bytes(mesh, FileFormat::PLY))
        .with_context(|| format!("writing {}", out.display()))?;
    let json = report_path(out);
    ellipso_report::atomic_file::write(&json, serde_json::to_vec_pretty(report)?)
        .with_context(|| format!("writing {}", json.display()))?;
    Ok(json)
}

/// The least the mesh file of `config` takes, bytes: a lower bound, so that a disk refused
/// for it is certainly too full. A closed triangle mesh of V vertices has 2V − 4 faces; the
/// binary PLY stores 3 doubles a vertex (24 B) and a count byte and 3 indices a face (13 B),
/// so 24 V + 13 (2V − 4) ≈ 50 V bytes (an OBJ's text is longer). The remesher aims at
/// `target_vertices` only approximately; half of it is taken for V, a margin so that the bound
/// stays below the file. The report and the hull come on top.
pub fn least_mesh_bytes(config: &MeshConfig) -> u64 {
    let v = (config.remesh.target_vertices / 2) as u64;
    (24 * v + 13 * (2 * v).saturating_sub(4)).max(1)
}

/// What `ellipso mesh` wrote.
#[derive(Debug)]
pub struct MeshWritten {
    /// The mesh's report (`peak_rss_bytes` filled in).
    pub report: MeshReport,
    /// The mesh file, as shown.
    pub mesh_file: PathBuf,
    /// The report file, as shown.
    pub report_file: PathBuf,
    /// The hull's sidecar (`<stem>-hull.json`, with `<stem>-hull.npy`), as shown.
    pub hull_file: PathBuf,
    /// Seconds from the session's opening to both files written.
    pub wall_s: f64,
}

/// `ellipso mesh SESSION --out OUT`: the mesh (PLY, or OBJ for an `.obj` name) and its report
/// claimed, the session opened and carved with `config`, both written (module contract).
pub fn mesh_command(
    session_dir: &Path,
    out: &Path,
    config: &MeshConfig,
    steps: &mut dyn Steps,
    say: &dyn Say,
) -> Result<MeshWritten, RunError> {
    use ellipso_report::output::OutputFile;
    let is_obj = out
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("obj"));
    let format = if is_obj {
        FileFormat::OBJ
    } else {
        FileFormat::PLY
    };
    let mesh_file = OutputFile::claim(out, "mesh", format, &[session_dir], None)?;
    let report_file = OutputFile::claim(
        &report_path(out),
        "mesh",
        FileFormat::JSON,
        &[session_dir],
        None,
    )?;
    let hull_files = crate::mesh_hull::HullFiles::claim(out, session_dir)?;
    // a full disk is said now, not after the carving
    mesh_file.ensure_room(least_mesh_bytes(config))?;
    let session = ellipso_session::reader::open(session_dir)?;
    let started = std::time::Instant::now();
    let poses = crate::poses::poses_of(&session, say)?;
    let (mesh, mut report, hull) = mesh_of_session(&session, Some(&poses[..]), config, say, steps)?;
    report.peak_rss_bytes = ellipso_report::memory::peak_rss_bytes();
    let bytes = mesh_bytes(&mesh, mesh_file.format());
    mesh_file.write(&bytes)?;
    report_file.write(serde_json::to_vec_pretty(&report)?)?;
    // the hull beside the mesh: `ellipso fit --mesh` on this session takes it instead of
    // carving again (crate::mesh_hull)
    let identity = crate::mesh_hull::SessionIdentity::of(&session);
    hull_files.write(&identity, &poses, &bytes, &hull)?;
    Ok(MeshWritten {
        report,
        mesh_file: mesh_file.shown().to_path_buf(),
        report_file: report_file.shown().to_path_buf(),
        hull_file: hull_files.shown().to_path_buf(),
        wall_s: started.elapsed().as_secs_f64(),
    })
}
