//! What `ellipso fit SESSION --poses COLMAP_MODEL` and `--mesh M --mesh-frame colmap` /
//! `--mesh-model COLMAP_MODEL` import: camera poses and a mesh from COLMAP, or any
//! photogrammetry tool that writes COLMAP models, brought into the board frame by the
//! similarity that aligns the model's cameras with the session's own AprilTag poses
//! ([`ellipso_colmap::import`]; docs/mesh.md, "The way in").
//!
//! Contract:
//! - [`read`] checks the flags and reads the models before the session is opened: a
//!   contradictory flag or a bad model is refused first, in one line naming the flag or file.
//! - [`apply`] says the alignment through the caller's [`Say`] (stderr) — the similarity, the
//!   residual over the agreeing frames (RMS and max, mm and degrees), every frame's residual, the
//!   frames left out, gained and kept ([`say_report`]) — and returns it whole as
//!   [`ImportSummary`], `fit-summary.json`'s `import` (`import.poses`, `import.mesh`).
//! - A mesh given in a model's frame is written into the output folder in the board frame
//!   (`mesh.ply`, binary PLY with double positions) before the fit: `ellipso fit SESSION --mesh
//!   OUT/mesh.ply` (a shard too) fits exactly that geometry.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use ellipso_model::geometry::TriangleMesh;
use ellipso_model::geometry::ply::{PlyFormat, write_ply};
use ellipso_model::geometry::similarity::AlignConfig;
use ellipso_run_error::{Context, RunError, Say};
use ellipso_session::reader::Session;
use nalgebra::Isometry3;

use ellipso_colmap::import::{
    ImportReport, ModelImport, SimilarityReport, import_model, transform_mesh,
};
use ellipso_colmap::model::{ColmapModel, read_model};

/// The frame a `--mesh` is in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MeshFrame {
    /// The board frame, metres.
    Board,
    /// The frame of a COLMAP model (`--mesh-model`, else `--poses`), its own scale.
    Colmap,
}

/// The import flags of `ellipso fit`.
#[derive(Debug, Clone, Default)]
pub struct ImportFlags {
    /// `--poses`: a COLMAP model of the session's frames whose poses the fit uses.
    pub poses: Option<PathBuf>,
    /// `--mesh-frame`: the frame `--mesh` is in.
    pub mesh_frame: Option<MeshFrame>,
    /// `--mesh-model`: the COLMAP model whose frame `--mesh` is in.
    pub mesh_model: Option<PathBuf>,
}

/// The models the flags name, read.
pub struct Models {
    /// `--poses`.
    poses: Option<ColmapModel>,
    /// The model the mesh's frame is: `--mesh-model`, or `--poses` (`None` here: reuse it), when
    /// the mesh is in a model's frame.
    mesh: Option<Option<ColmapModel>>,
}

/// What the import gives the fit.
pub struct Imported {
    /// The poses the fit uses, when `--poses` was given.
    pub poses: Option<Vec<(u64, Isometry3<f64>)>>,
    /// `fit-summary.json`'s `import`.
    pub summary: ImportSummary,
}

/// `fit-summary.json`'s `import` (docs/fit-outputs.md); fields in alphabetical order, as the
/// file lists them.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ImportSummary {
    /// With a mesh in a model's frame: where it went.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mesh: Option<MeshImport>,
    /// With `--poses`: that model's alignment.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub poses: Option<ImportReport>,
}

/// `import.mesh`: a mesh carried from a model's frame into the board frame.
#[derive(Clone, Debug, serde::Serialize)]
pub struct MeshImport {
    /// The whole alignment of a `--mesh-model` of its own (else `import.poses` is the mesh's).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub alignment: Option<ImportReport>,
    /// Model coordinates → board frame.
    pub board_from_model: SimilarityReport,
    /// The written board-frame mesh (`mesh.ply` in the output folder).
    pub board_mesh: PathBuf,
    /// The model's folder.
    pub model: PathBuf,
}

/// Checks the flags and reads their models (module contract); `None` without import flags.
pub fn read(
    flags: &ImportFlags,
    has_mesh: bool,
    sharded: bool,
) -> Result<Option<Models>, RunError> {
    let mesh_in_model = match (flags.mesh_frame, &flags.mesh_model) {
        (Some(MeshFrame::Board), Some(_)) => ellipso_run_error::bail!(
            "--mesh-model puts the mesh in that model's frame, --mesh-frame board says it is in \
             the board frame: give one of them"
        ),
        (Some(MeshFrame::Colmap), _) | (None, Some(_)) => true,
        _ => false,
    };
    if !mesh_in_model && flags.poses.is_none() {
        return Ok(None);
    }
    ellipso_run_error::ensure!(
        !sharded,
        "--poses, --mesh-frame colmap and --mesh-model are not taken with --shard: run the fit \
         once without --shard (it writes the aligned mesh to OUT/mesh.ply, which shards take as \
         --mesh); sharded fits use the session's tracked poses"
    );
    ellipso_run_error::ensure!(
        has_mesh || !mesh_in_model,
        "--mesh-frame colmap and --mesh-model say which frame --mesh is in: give --mesh MESH"
    );
    ellipso_run_error::ensure!(
        !mesh_in_model || flags.mesh_model.is_some() || flags.poses.is_some(),
        "--mesh-frame colmap needs the COLMAP model the mesh belongs to: --poses MODEL (its \
         poses are used too) or --mesh-model MODEL (the tracked poses are kept)"
    );
    let load = |path: &PathBuf| {
        read_model(path).with_context(|| format!("reading the COLMAP model {}", path.display()))
    };
    let poses = flags.poses.as_ref().map(load).transpose()?;
    let mesh = match (mesh_in_model, &flags.mesh_model) {
        (false, _) => None,
        (true, None) => Some(None),
        (true, Some(path)) => Some(Some(load(path)?)),
    };
    Ok(Some(Models { poses, mesh }))
}

/// Aligns the models to the session's board frame, gives the fit its poses, and brings a mesh
/// in a model's frame into the board frame, written to `out/mesh.ply` (module contract).
/// Without models it returns `mesh` unchanged.
pub fn apply(
    models: Option<Models>,
    session: &Session,
    mesh: Option<TriangleMesh>,
    out: &Path,
    say: &dyn Say,
) -> Result<(Option<TriangleMesh>, Option<Imported>), RunError> {
    let Some(models) = models else {
        return Ok((mesh, None));
    };
    let tracked = crate::poses::poses_of(session, say)?;
    let frame_ids: BTreeSet<u64> = session.frames.iter().map(|f| f.frame_id).collect();
    let camera = ellipso_fit::observe::camera_of(session)?;
    let align = |model: &ColmapModel| -> Result<ModelImport, RunError> {
        let import = import_model(
            model,
            &tracked,
            &frame_ids,
            &camera,
            &AlignConfig::default(),
        )?;
        say_report(&import.report, say);
        Ok(import)
    };
    let pose_import = models.poses.as_ref().map(align).transpose()?;
    let poses = pose_import.as_ref().map(|import| {
        let poses = import.fit_poses(&tracked);
        say.err(format_args!(
            "  the fit uses {} poses: {} from the model, {} tracked only",
            poses.len(),
            import.aligned.len() - import.report.frames_dropped.len(),
            import.report.frames_tracked_only.len()
        ));
        poses
    });
    let mut mesh_summary = None;
    let mesh = match (models.mesh, mesh) {
        (Some(mesh_model), Some(mesh)) => {
            let separate = mesh_model.as_ref().map(align).transpose()?;
            let import = separate
                .as_ref()
                .or(pose_import.as_ref())
                .expect("read() makes sure the mesh has a model");
            let board = transform_mesh(&mesh, &import.board_from_model)
                .context("the mesh carried into the board frame")?;
            std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
            let path = out.join("mesh.ply");
            ellipso_report::atomic_file::write(
                &path,
                write_ply(&board, PlyFormat::BinaryLittleEndian, true),
            )
            .with_context(|| format!("writing {}", path.display()))?;
            say.err(format_args!(
                "  the mesh ({} vertices) in the board frame: {}",
                board.positions().len(),
                path.display()
            ));
            mesh_summary = Some(MeshImport {
                board_from_model: import.report.board_from_model.clone(),
                board_mesh: path,
                model: import.report.model.clone(),
                alignment: separate.map(|s| s.report),
            });
            Some(board)
        }
        (_, mesh) => mesh,
    };
    let summary = ImportSummary {
        mesh: mesh_summary,
        poses: pose_import.map(|i| i.report),
    };
    Ok((mesh, Some(Imported { poses, summary })))
}

/// Says the alignment (stderr): the similarity, the residual overall and per frame, what
/// happens to the frames.
pub fn say_report(r: &ImportReport, say: &dyn Say) {
    let s = &r.board_from_model;
    let format = serde_json::to_value(r.format).unwrap_or_default();
    say.err(format_args!(
        "COLMAP model {} ({} form; {}, {}, {}) → board frame: scale {:.6} m per model unit",
        r.model.display(),
        format.as_str().unwrap_or("?"),
        count(r.images, "image"),
        count(r.cameras.len(), "camera"),
        count(r.points, "point"),
        s.scale
    ));
    say.err(format_args!(
        "  alignment residual over the {} of {} frames posed by both that agree: RMS {:.3} mm, \
         {:.3}° (max {:.3} mm, {:.3}°)",
        r.frames_inliers,
        r.frames_common,
        r.rms_position_mm,
        r.rms_rotation_deg,
        r.max_position_mm,
        r.max_rotation_deg
    ));
    for chunk in r.per_frame.chunks(5) {
        let row: Vec<String> = chunk
            .iter()
            .map(|f| {
                let disagrees = if f.residual.inlier {
                    ""
                } else {
                    " (disagrees)"
                };
                format!(
                    "{} {:.2} mm {:.3}°{disagrees}",
                    f.frame_id, f.residual.position_mm, f.residual.rotation_deg
                )
            })
            .collect();
        say.err(format_args!("    {}", row.join(", ")));
    }
    let list = |ids: &[u64]| {
        let shown: Vec<String> = ids.iter().take(12).map(u64::to_string).collect();
        match ids.len().saturating_sub(12) {
            0 => shown.join(", "),
            more => format!("{} and {more} more", shown.join(", ")),
        }
    };
    if !r.frames_dropped.is_empty() {
        say.err(format_args!(
            "  {} left out of the fit (tracking and the model disagree): {}",
            count(r.frames_dropped.len(), "frame"),
            list(&r.frames_dropped)
        ));
    }
    if !r.frames_gained.is_empty() {
        say.err(format_args!(
            "  {} posed through the alignment only (AprilTag tracking failed there): {}",
            count(r.frames_gained.len(), "frame"),
            list(&r.frames_gained)
        ));
    }
    if !r.frames_tracked_only.is_empty() {
        say.err(format_args!(
            "  {} not in the model: tracked poses kept",
            count(r.frames_tracked_only.len(), "tracked frame"),
        ));
    }
    if !r.images_unmatched.is_empty() {
        let shown: Vec<&str> = r
            .images_unmatched
            .iter()
            .take(4)
            .map(String::as_str)
            .collect();
        say.err(format_args!(
            "  {} naming no frame of the session: {}",
            count(r.images_unmatched.len(), "image"),
            shown.join(", ")
        ));
    }
    for c in &r.cameras {
        // a focal length 2 % off the calibration places the cameras for another lens
        let off = (c.focal_ratio - 1.0).abs();
        if off.is_nan() || off > 0.02 {
            say.err(format_args!(
                "  warning: camera {} ({} {}×{}) has a focal length {:+.1} % from the session's \
                 calibration: the model's poses are for that lens",
                c.camera_id,
                c.model,
                c.width,
                c.height,
                (c.focal_ratio - 1.0) * 100.0
            ));
        }
    }
}

/// `n thing` or `n things`.
fn count(n: usize, thing: &str) -> String {
    format!("{n} {thing}{}", if n == 1 { "" } else { "s" })
}
