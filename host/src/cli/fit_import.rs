//! `ellipso fit SESSION --poses COLMAP_MODEL` and `--mesh M --mesh-frame colmap` /
//! `--mesh-model COLMAP_MODEL`: camera poses and a mesh from COLMAP, or any photogrammetry tool
//! that writes COLMAP models, brought into the board frame by the similarity that aligns the
//! model's cameras with the session's own AprilTag poses (docs/mesh.md, "The way in"). The
//! flags only: `ellipso_pipeline::fit_import` checks them, reads and aligns the models, says the
//! alignment and writes the board-frame mesh.

use std::path::PathBuf;

/// The frame a `--mesh` is in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum MeshFrame {
    /// The board frame, metres (a mesh from `ellipso mesh`, a scanner registered to the board,
    /// or COLMAP run on `ellipso export colmap`'s known poses).
    Board,
    /// The frame of a COLMAP model (`--mesh-model`, else `--poses`), its own scale.
    Colmap,
}

/// The import flags of `ellipso fit`.
#[derive(Debug, Clone, clap::Args)]
pub struct ImportArgs {
    /// A COLMAP sparse model of this session's frames (a folder with cameras, images and
    /// points3D as .bin or .txt, e.g. COLMAP's sparse/0), from COLMAP or any tool that writes
    /// its format, with the session's frame names (00000148.png): its poses are aligned to the
    /// board frame on the frames AprilTag tracking posed, and the fit uses them, including for
    /// frames tracking could not pose (docs/mesh.md, "The way in").
    #[arg(long, value_name = "COLMAP_MODEL")]
    pub poses: Option<PathBuf>,
    /// The frame `--mesh` is in: `board` (default, metres) or `colmap` (the frame and scale of
    /// `--mesh-model`, else of `--poses`).
    #[arg(long, value_enum, value_name = "FRAME")]
    pub mesh_frame: Option<MeshFrame>,
    /// The COLMAP model whose frame `--mesh` is in, where the fit should keep the tracked poses
    /// (or take other poses from `--poses`); implies `--mesh-frame colmap`.
    #[arg(long, value_name = "COLMAP_MODEL")]
    pub mesh_model: Option<PathBuf>,
}

impl ImportArgs {
    /// The flags as the library takes them (`ellipso_pipeline::fit_import` checks them).
    pub fn flags(&self) -> ellipso_pipeline::fit_import::ImportFlags {
        ellipso_pipeline::fit_import::ImportFlags {
            poses: self.poses.clone(),
            mesh_frame: self.mesh_frame.map(|f| match f {
                MeshFrame::Board => ellipso_pipeline::fit_import::MeshFrame::Board,
                MeshFrame::Colmap => ellipso_pipeline::fit_import::MeshFrame::Colmap,
            }),
            mesh_model: self.mesh_model.clone(),
        }
    }
}
