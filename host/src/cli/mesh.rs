//! `ellipso mesh SESSION --out mesh.ply [--vertices N]`: the object's watertight mesh carved
//! from the session's posed frames (`ellipso_pipeline::mesh::mesh_command`), written as a binary PLY (or, for an `.obj`
//! name, Wavefront OBJ) in board coordinates (metres), with `<out stem>-report.json` beside it.
//! `<out stem>-hull.json`/`.npy` hold the carved visual hull, which `ellipso fit --mesh` on the
//! same session reuses instead of carving again (`ellipso_pipeline::mesh_hull`).
//! The files are claimed before the work starts (never inside the session, never over a file of
//! another format) and written whole.
//!
//! Poses come from the session's `pose` events (tracked now and appended when the log has none,
//! as `ellipso fit` does).

use std::path::PathBuf;

use ellipso_mesh::MeshConfig;

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
    /// Where a view's silhouette edge cannot be measured inside its boundary pixels, move it
    /// this far (superpixels) into the object's side of the pixel boundary (default: the
    /// built-in setting; docs/mesh.md "Edge: where inside its boundary pixels").
    #[arg(long, value_parser = super::limits::edge_inset_px)]
    pub edge_inset_px: Option<f64>,
    /// Write diagnostic pictures into DIR (created; not inside the session): every view's board
    /// pixels (`board-FRAMEID.png`, superpixels, white = shows the board as learned), the
    /// learned board and slices of the carved fields (docs/mesh.md).
    #[arg(long, value_name = "DIR")]
    pub debug: Option<PathBuf>,
    /// Print one JSON object (the files and the mesh report) instead of the text report.
    #[arg(long)]
    pub json: bool,
}

/// Runs `ellipso mesh`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let mut config = MeshConfig {
        votes: args.votes,
        threads: args.threads,
        edge_inset_px: args
            .edge_inset_px
            .unwrap_or(MeshConfig::default().edge_inset_px),
        ..MeshConfig::default()
    };
    config.remesh.target_vertices = args.vertices;
    if let Some(dir) = &args.debug {
        // checked before anything is created, both paths resolved as every output's are
        // (links followed, a missing tail lexical)
        let resolve = ellipso_report::output::place::resolve;
        anyhow::ensure!(
            !resolve(dir)?.starts_with(resolve(&args.session)?),
            "--debug {}: inside the session {} (a session is never written to)",
            dir.display(),
            args.session.display()
        );
        // the debug pictures' folder is never one of the files `--out` names (created here, it
        // would only then be found to be a directory)
        let out_files = [
            args.out.clone(),
            ellipso_pipeline::mesh::report_path(&args.out),
        ];
        for f in &out_files {
            anyhow::ensure!(
                resolve(dir)? != resolve(f)?,
                "--debug {}: the same path as the output file {} (from --out); the debug \
                 pictures go into a folder of their own, e.g. --debug {}-debug",
                dir.display(),
                f.display(),
                args.out.with_extension("").display()
            );
        }
        std::fs::create_dir_all(dir)
            .map_err(|e| anyhow::anyhow!("--debug {}: {e}", dir.display()))?;
        config.debug_dir = Some(dir.clone());
    }
    let done = ellipso_pipeline::mesh::mesh_command(
        &args.session,
        &args.out,
        &config,
        &mut super::progress::Spinners::default(),
        &super::out::Printed,
    )
    .map_err(super::out::failed)?;
    let report = &done.report;
    if args.json {
        let object = serde_json::json!({
            "mesh": done.mesh_file.display().to_string(),
            "report_file": done.report_file.display().to_string(),
            "hull_file": done.hull_file.display().to_string(),
            "wall_s": done.wall_s,
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
        done.wall_s
    );
    if !report.skipped.is_empty() {
        crate::outln!(
            "             {} posed frames not used: {}",
            report.skipped.len(),
            ellipso_mesh::error::skipped_list(&report.skipped, 4)
        );
    }
    crate::outln!(
        "  {}\n  {}\n  {} (the visual hull: `ellipso fit --mesh {}` on this session reuses it)",
        args.out.display(),
        done.report_file.display(),
        done.hull_file.display(),
        args.out.display()
    );
    Ok(())
}
