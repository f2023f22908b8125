//! `ellipso export colmap SESSION --out DIR`: the session as a COLMAP sparse model with known
//! poses and undistorted s0 images (`ellipso_mesh::colmap`), for users who prefer
//! photogrammetry: COLMAP's `point_triangulator`, dense and meshing steps then give a mesh in
//! board coordinates that `ellipso fit --mesh` takes unchanged (docs/mesh.md).

use std::path::PathBuf;

use anyhow::Context;

use ellipso_mesh::colmap::{ColmapOptions, export_colmap};

/// `ellipso export` subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum Args {
    /// A COLMAP sparse model (cameras.txt, images.txt, empty points3D.txt) and undistorted s0
    /// images of the posed frames.
    Colmap(ColmapArgs),
}

/// Arguments of `ellipso export colmap`.
#[derive(Debug, clap::Args)]
pub struct ColmapArgs {
    /// The session directory.
    pub session: PathBuf,
    /// Output directory (gets `images/` and `sparse/`).
    #[arg(long)]
    pub out: PathBuf,
    /// Write the images as captured and the lens model (OPENCV / FULL_OPENCV) in cameras.txt
    /// instead of undistorting to PINHOLE.
    #[arg(long)]
    pub keep_distortion: bool,
}

/// Runs `ellipso export`.
pub fn run(args: Args) -> anyhow::Result<()> {
    match args {
        Args::Colmap(a) => {
            let session = ellipso_session::reader::open(&a.session)?;
            let poses = super::fit::poses_of(&session)?;
            let report = export_colmap(
                &session,
                &poses,
                &a.out,
                ColmapOptions {
                    keep_distortion: a.keep_distortion,
                },
            )
            .with_context(|| format!("exporting {} for COLMAP", a.session.display()))?;
            crate::outln!(
                "colmap       {} images, camera `{}`",
                report.images,
                report.camera
            );
            if !report.skipped.is_empty() {
                crate::outln!(
                    "             {} posed frames left out: {}",
                    report.skipped.len(),
                    ellipso_mesh::error::skipped_list(&report.skipped, 4)
                );
            }
            crate::outln!("  {}", a.out.join("sparse").display());
            crate::outln!("  {}", a.out.join("images").display());
            Ok(())
        }
    }
}
