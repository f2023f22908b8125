//! `ellipso-mesh`: geometry from the capture itself — a watertight triangle mesh of the object on the board,
//! carved from the posed flash photos alone — no scanner, no GPU, no external program.
//!
//! Method (docs/mesh.md has the reasoning and the measured limits):
//! 1. [`volume`]: the base board's plane, its tag footprint and the box above it.
//! 2. [`appearance`]: every texel of the board plane learns its appearance from the views that
//!    see it (s0 per colour band over the flash's normaliser, and the polarisation contrast);
//!    the value most views agree on wins, so views through the object do not count.
//! 3. [`silhouette`]: per view, the pixels that show the board as learned; their signed
//!    distance to the boundary.
//! 4. [`carve`]: a coarse then a fine voxel grid; every node takes the k-th largest signed
//!    distance its views give (voting: k views must see the board through a voxel to carve it).
//! 5. [`components`]: one connected part inside the footprint, or a clear error; [`coverage`]
//!    tells a capture short of views of that region from a misplaced object.
//! 6. [`extract`], [`remesh`]: marching tetrahedra, isotropic remeshing onto the carved surface
//!    to the target vertex count, Taubin smoothing; the bottom is the board plane.
//!
//! What takes the mesh further lives elsewhere: the session's poses, the mesh as the subcommands
//! write it and the fit of a session as `ellipso fit` runs it in `ellipso-pipeline`; the COLMAP
//! formats in `ellipso-colmap`; distances between meshes in `ellipso_model::geometry::distance`.
//!
//! Contract: [`build_mesh`] reads the session (frames twice, streamed, at most
//! `frames_in_flight` at once) and never writes to it; the mesh is in world (board)
//! coordinates, metres, closed, 2-manifold, counter-clockwise from outside; memory is bounded
//! by the board's size (texels, grid nodes) and one bit per pixel per view; the result does not
//! depend on the thread count.
#![forbid(unsafe_code)]

pub mod appearance;
pub mod carve;
pub mod components;
pub mod coverage;
pub mod debug;
pub mod edge;
pub mod error;
pub mod extract;
pub mod frames;
pub mod halfedge;
pub mod implicit;
pub mod pipeline;
pub mod print;
pub mod remesh;
pub mod silhouette;
pub mod volume;

#[cfg(test)]
mod tests;

pub use error::MeshError;
pub use pipeline::{MeshResult, build_mesh};

use appearance::AppearanceConfig;
use remesh::RemeshConfig;

/// Settings of [`build_mesh`].
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MeshConfig {
    /// The board appearance model.
    pub appearance: AppearanceConfig,
    /// Remeshing (target vertex count, rounds, smoothing).
    pub remesh: RemeshConfig,
    /// Views that must see the board through a voxel to carve it (k).
    pub votes: usize,
    /// Fewest usable posed frames.
    pub min_posed_frames: usize,
    /// Largest number of coarse grid nodes over the whole box (bounds the coarse pass).
    pub coarse_nodes: usize,
    /// Fine grid cells along the longest side of the object's box.
    pub fine_cells: usize,
    /// Smallest fine grid spacing, metres.
    pub min_fine_spacing_m: f64,
    /// Board islands smaller than this (superpixels) do not carve.
    pub min_island_px: usize,
    /// Enclosed board islands (not reaching the image border) with less than this fraction of a
    /// view's board pixels do not carve.
    pub max_enclosed_board: f64,
    /// Parts lower than this many coarse grid spacings are board-level residue (tag edges,
    /// glints), not objects: dropped.
    pub min_part_layers: usize,
    /// Parts smaller than this, m³, are residue too (blurred tag edges that disagree with their
    /// texels in many views leave uncarved specks of ~0.1 cm³ above the tags), not objects: the
    /// rig scans objects of centimetres, and at the hull's resolution (a fine node is ~0.5 mm)
    /// a part of 1 cm³ is already thousands of nodes. A smaller object cannot be meshed.
    pub min_part_m3: f64,
    /// How far (superpixels) the silhouette's edge is moved from the pixel boundary into the
    /// pixels that do not show the board where it cannot be measured from the pixels' cover
    /// ([`edge`]: the object does not stand out from the board, or the texel is unknown).
    /// A boundary pixel partly covered by the object already
    /// disagrees with its texel, so the not-board set is on average larger than the object's
    /// true silhouette by the part of a pixel the object does not cover; and the hull is the
    /// intersection of silhouettes, so it inherits that growth from every side (docs/mesh.md
    /// "Edge: where inside its boundary pixels"). 0 puts the edge on the pixel boundary.
    pub edge_inset_px: f64,
    /// Frames read at once.
    pub frames_in_flight: usize,
    /// Worker threads (`None`: rayon's global pool).
    pub threads: Option<usize>,
    /// A second part with at least this fraction of the main part's volume is an error; smaller
    /// ones are dropped and counted.
    pub max_second_part: f64,
    /// Where to write diagnostic pictures (each view's board pixels, slices of the coarse and
    /// fine fields), if anywhere.
    #[serde(skip)]
    pub debug_dir: Option<std::path::PathBuf>,
    /// The sensor calibration the frames are read with (`None`: an ideal sensor, dark level 0;
    /// [`frames::load_features`]).
    #[serde(skip)]
    pub sensor_calibration:
        Option<std::sync::Arc<ellipso_polar::sensor_calibration::SensorCalibration>>,
}

impl Default for MeshConfig {
    fn default() -> Self {
        Self {
            appearance: AppearanceConfig::default(),
            remesh: RemeshConfig::default(),
            votes: 3,
            min_posed_frames: 8,
            coarse_nodes: 250_000,
            fine_cells: 140,
            min_fine_spacing_m: 2e-4,
            min_island_px: 12,
            max_enclosed_board: 0.1,
            min_part_layers: 4,
            min_part_m3: 1e-6,
            edge_inset_px: 0.3,
            frames_in_flight: 4,
            threads: None,
            max_second_part: 0.02,
            debug_dir: None,
            sensor_calibration: None,
        }
    }
}

/// What [`build_mesh`] did.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MeshReport {
    /// Poses given.
    pub frames_posed: usize,
    /// Frames carved from.
    pub frames_used: usize,
    /// Posed frames not used, with reasons.
    pub skipped: Vec<ellipso_fit::observe::SkippedFrame>,
    /// Index of the board the object stands on.
    pub board: usize,
    /// Its name.
    pub board_name: Option<String>,
    /// The box above the board, volume frame: lower corner, metres.
    pub volume_min_m: [f64; 3],
    /// Upper corner.
    pub volume_max_m: [f64; 3],
    /// Texel side, metres.
    pub texel_m: f64,
    /// Texels.
    pub texels: usize,
    /// Fraction of texels learned.
    pub texels_learned: f64,
    /// Median over views of the fraction of pixels that show the board as learned.
    pub board_pixels_median: f64,
    /// Coarse grid.
    pub coarse: Option<carve::Grid>,
    /// Fine grid.
    pub fine: Option<carve::Grid>,
    /// Fine nodes voted on (the rest take the coarse answer).
    pub fine_nodes_voted: usize,
    /// Nodes seen by fewer than `votes` views (counted outside).
    pub nodes_unseen: usize,
    /// Separate small parts dropped.
    pub parts_dropped: usize,
    /// Their volume, m³.
    pub parts_dropped_m3: f64,
    /// Enclosed empty nodes filled.
    pub cavity_nodes_filled: usize,
    /// Vertices of the extracted surface before remeshing.
    pub extracted_vertices: usize,
    /// Vertices of the mesh.
    pub vertices: usize,
    /// Triangles of the mesh.
    pub triangles: usize,
    /// Enclosed volume of the mesh, m³.
    pub volume_m3: f64,
    /// Seconds per stage, in order.
    pub times_s: Vec<(String, f64)>,
    /// Largest memory held at once by the big buffers (accounted), bytes.
    pub peak_bytes: u64,
    /// The process's resident high-water mark when the report was written (Linux; filled in by
    /// `ellipso mesh`), bytes.
    #[serde(default)]
    pub peak_rss_bytes: Option<u64>,
}
