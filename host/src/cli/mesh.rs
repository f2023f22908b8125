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

use ellipso_mesh::MeshConfig;
use ellipso_report::output::{FileFormat, OutputFile};

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
    let progress = super::progress::Progress::spinner("mesh");
    let (mesh, mut report, _) = ellipso_mesh::output::mesh_of_session(
        &session,
        None,
        &config,
        &super::out::Printed,
        &mut |stage| progress.set_message(stage),
    )
    .map_err(super::out::failed)?;
    progress.finish(format!(
        "{} vertices from {} frames",
        report.vertices, report.frames_used
    ));
    report.peak_rss_bytes = ellipso_report::memory::peak_rss_bytes();
    mesh_file.write(ellipso_mesh::output::mesh_bytes(&mesh, mesh_file.format()))?;
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
        &ellipso_mesh::output::report_path(out),
        "mesh",
        FileFormat::JSON,
        &[session],
        None,
    )?;
    Ok((mesh, report))
}
