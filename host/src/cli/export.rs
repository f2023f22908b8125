//! `ellipso export colmap SESSION --out DIR`: the session as a COLMAP sparse model with known
//! poses and undistorted s0 images (`ellipso_pipeline::colmap_export::export_session`), for users who prefer
//! photogrammetry: COLMAP's `point_triangulator`, dense and meshing steps then give a mesh in
//! board coordinates that `ellipso fit --mesh` takes unchanged (docs/mesh.md).
//!
//! `ellipso export mitsuba FIT_DIR --out DIR`: a fit directory as a Mitsuba 3 scene with
//! ellipso's own render of the same view beside it (`ellipso_fit::export::mitsuba`,
//! docs/fit-outputs.md).

use std::path::PathBuf;

use anyhow::Context;

use ellipso_colmap::export::ColmapOptions;
use ellipso_pipeline::colmap_export::export_session;
use ellipso_report::output::OutputDir;

/// `ellipso export` subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum Args {
    /// A COLMAP sparse model (cameras.txt, images.txt, empty points3D.txt) and undistorted s0
    /// images of the posed frames.
    Colmap(ColmapArgs),
    /// A Mitsuba 3 scene of a fit (the mesh with the pplastic BSDF per vertex, the pictures'
    /// camera, the rig's flash) and ellipso's render of the same view to compare with.
    Mitsuba(MitsubaArgs),
}

/// Arguments of `ellipso export mitsuba`.
#[derive(Debug, clap::Args)]
pub struct MitsubaArgs {
    /// The fit directory (`fit.ply` and `fit-view.json` from `ellipso fit`).
    pub fit_dir: PathBuf,
    /// Output directory: new, empty, or an earlier `export mitsuba`'s (replaced whole).
    #[arg(long)]
    pub out: PathBuf,
    /// Samples per pixel written into the scene (Mitsuba's `-Dspp=N` overrides it).
    #[arg(long, default_value_t = 64, value_parser = clap::value_parser!(u32).range(1..=65536))]
    pub spp: u32,
}

/// Arguments of `ellipso export colmap`.
#[derive(Debug, clap::Args)]
pub struct ColmapArgs {
    /// The session directory.
    pub session: PathBuf,
    /// Output directory (gets `images/` and `sparse/`): new, empty, or an earlier `export
    /// colmap`'s (replaced whole).
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
        Args::Mitsuba(a) => {
            // written beside and swapped in whole; never into the fit it reads
            let out = OutputDir::claim(&a.out, "export-mitsuba", &[&a.fit_dir])?;
            let report = ellipso_fit::export::mitsuba::export(
                &a.fit_dir,
                out.path(),
                &ellipso_fit::export::mitsuba::MitsubaOptions { spp: a.spp },
            )
            .with_context(|| format!("exporting {} for Mitsuba 3", a.fit_dir.display()))?;
            crate::outln!(
                "mitsuba      {} vertices, {} faces{}",
                report.vertices,
                report.faces,
                if report.clamped > 0 {
                    format!(
                        " ({} with eta or alpha raised into Mitsuba's domain)",
                        report.clamped
                    )
                } else {
                    String::new()
                }
            );
            if report.albedo_scale > 1.0 {
                crate::outln!(
                    "             albedos ÷ {:.3} (every reflectance ≤ 1), the flash's intensity × {:.3}: the same render",
                    report.albedo_scale,
                    report.albedo_scale
                );
            }
            let files: Vec<_> = report.files.iter().map(|f| out.published(f)).collect();
            out.commit()?;
            for f in &files {
                crate::outln!("  {}", f.display());
            }
            Ok(())
        }
        Args::Colmap(a) => {
            let (report, published) = export_session(
                &a.session,
                &a.out,
                ColmapOptions {
                    keep_distortion: a.keep_distortion,
                },
                &super::out::Printed,
            )
            .map_err(super::out::failed)?;
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
            crate::outln!("  {}", published.join("sparse").display());
            crate::outln!("  {}", published.join("images").display());
            Ok(())
        }
    }
}
