//! `ellipso mesh SESSION --out mesh.ply [--vertices N]`: the object's watertight mesh carved
//! from the session's posed frames (`ellipso_mesh`), written as a binary PLY (or, for an `.obj`
//! name, Wavefront OBJ) in board coordinates (metres), with `<out stem>-report.json` beside it.
//! Both files are claimed before the work starts (never inside the session, never over a file of
//! another format) and written whole.
//!
//! Poses come from the session's `pose` events (tracked now and appended when the log has none,
//! as `ellipso fit` does).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use ellipso_model::geometry::TriangleMesh;
use ellipso_model::geometry::ply::{PlyFormat, write_ply};

use ellipso_fit::shape::hull::HullField;
use ellipso_mesh::{MeshConfig, MeshReport, build_mesh};
use ellipso_report::output::{FileFormat, OutputFile};
use ellipso_session::reader::Session;

/// Arguments of `ellipso mesh`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The session directory.
    pub session: PathBuf,
    /// Output mesh: `.ply` (binary PLY) or `.obj` (Wavefront OBJ).
    #[arg(long, default_value = "mesh.ply")]
    pub out: PathBuf,
    /// Target vertex count of the mesh, 100..=2000000 (a few hundred thousand follow the
    /// paper's Poisson depth 8–9; docs/mesh-bench.md has the fit's time and memory for each).
    #[arg(long, default_value_t = 2500, value_parser = super::limits::vertices)]
    pub vertices: usize,
    /// Views that must see the board through a voxel to carve it, 1..=100.
    #[arg(long, default_value_t = 3, value_parser = super::limits::votes)]
    pub votes: usize,
    /// Worker threads, 1..=256 (default: all cores).
    #[arg(long, value_parser = super::limits::threads)]
    pub threads: Option<usize>,
    /// Move each view's silhouette edge this far (superpixels) into the object's side of the
    /// pixel boundary (default: the built-in setting, see docs/mesh.md "Edge inset").
    #[arg(long, value_parser = super::limits::edge_inset_px)]
    pub edge_inset_px: Option<f64>,
    /// Print one JSON object (the files and the mesh report) instead of the text report.
    #[arg(long)]
    pub json: bool,
}

/// Runs `ellipso mesh`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let (mesh_file, report_file) = claim_mesh_files(&args.out, &args.session)?;
    let session = ellipso_session::reader::open(&args.session)?;
    let mut config = MeshConfig {
        votes: args.votes,
        threads: args.threads,
        edge_inset_px: args
            .edge_inset_px
            .unwrap_or(MeshConfig::default().edge_inset_px),
        ..MeshConfig::default()
    };
    config.remesh.target_vertices = args.vertices;
    let started = Instant::now();
    let (mesh, mut report, _) = mesh_of_session(&session, None, &config)?;
    report.peak_rss_bytes = ellipso_report::memory::peak_rss_bytes();
    mesh_file.write(mesh_bytes(&mesh, mesh_file.format()))?;
    report_file.write(serde_json::to_vec_pretty(&report)?)?;
    let json = report_file.shown().to_path_buf();
    if args.json {
        let object = serde_json::json!({
            "mesh": mesh_file.shown().display().to_string(),
            "report_file": json.display().to_string(),
            "wall_s": started.elapsed().as_secs_f64(),
            "report": report,
        });
        crate::outln!("{object}");
        return Ok(());
    }
    crate::outln!(
        "mesh         {} vertices, {} triangles, {:.1} cm³ from {} frames in {:.1} s",
        report.vertices,
        report.triangles,
        report.volume_m3 * 1e6,
        report.frames_used,
        started.elapsed().as_secs_f64()
    );
    if !report.skipped.is_empty() {
        crate::outln!(
            "             {} posed frames not used: {}",
            report.skipped.len(),
            ellipso_mesh::error::skipped_list(&report.skipped, 4)
        );
    }
    crate::outln!("  {}\n  {}", args.out.display(), json.display());
    Ok(())
}

/// Carves the session's mesh from `poses`, or from its tracked poses (tracking it first if it
/// has none); also returns the carved hull (the fit's surface update stays inside it).
pub fn mesh_of_session(
    session: &Session,
    poses: Option<&[(u64, nalgebra::Isometry3<f64>)]>,
    config: &MeshConfig,
) -> anyhow::Result<(TriangleMesh, MeshReport, HullField)> {
    let poses = match poses {
        Some(p) => p.to_vec(),
        None => ellipso_mesh::poses::poses_of(session, &super::out::Printed)
            .map_err(super::out::failed)?,
    };
    let progress = super::progress::Progress::spinner("mesh");
    let result = build_mesh(session, &poses, config, &mut |stage| {
        progress.set_message(stage)
    })
    .with_context(|| format!("meshing {}", session.dir.display()))?;
    progress.finish(format!(
        "{} vertices from {} frames",
        result.report.vertices, result.report.frames_used
    ));
    Ok((result.mesh, result.report, result.hull))
}

/// The report's path beside a mesh file: `<stem>-report.json`.
fn report_path(out: &Path) -> PathBuf {
    let stem = out.file_stem().and_then(|s| s.to_str()).unwrap_or("mesh");
    out.with_file_name(format!("{stem}-report.json"))
}

/// Claims the mesh file (PLY or OBJ by its extension) and its report for `ellipso mesh`.
fn claim_mesh_files(out: &Path, session: &Path) -> anyhow::Result<(OutputFile, OutputFile)> {
    let is_obj = out
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("obj"));
    let format = if is_obj {
        FileFormat::OBJ
    } else {
        FileFormat::PLY
    };
    let mesh = OutputFile::claim(out, "mesh", format, &[session], None)?;
    let report = OutputFile::claim(
        &report_path(out),
        "mesh",
        FileFormat::JSON,
        &[session],
        None,
    )?;
    Ok((mesh, report))
}

/// A mesh's bytes in `format` (binary PLY unless OBJ).
fn mesh_bytes(mesh: &TriangleMesh, format: FileFormat) -> Vec<u8> {
    if format == FileFormat::OBJ {
        ellipso_model::geometry::obj::write_obj(mesh)
    } else {
        // double: a fit on this file sees exactly the geometry the fit that wrote it used
        write_ply(mesh, PlyFormat::BinaryLittleEndian, true)
    }
}

/// Writes the mesh (binary PLY) and its report (`<stem>-report.json`) into a directory the
/// caller owns (a fit's or the demo's staging directory), each whole; returns the report path.
pub fn write_mesh(mesh: &TriangleMesh, report: &MeshReport, out: &Path) -> anyhow::Result<PathBuf> {
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
