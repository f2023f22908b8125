//! `ellipso fit SESSION --poses COLMAP_MODEL` and `--mesh M --mesh-frame colmap` /
//! `--mesh-model COLMAP_MODEL`: camera poses and a mesh from COLMAP, or any photogrammetry tool
//! that writes COLMAP models, brought into the board frame by the similarity that aligns the
//! model's cameras with the session's own AprilTag poses (`ellipso_mesh::colmap_import`;
//! docs/mesh.md, "The way in").
//!
//! Contract:
//! - The flags are checked and the models read before the session is opened: a contradictory
//!   flag or a bad model is refused first, in one line naming the flag or file.
//! - The alignment is printed on stderr — the similarity, the residual over the agreeing frames
//!   (RMS and max, mm and degrees), every frame's residual, the frames left out, gained and kept
//!   — and goes whole into `fit-summary.json` as `import` (`import.poses`, `import.mesh`).
//! - A mesh given in a model's frame is written into the output folder in the board frame
//!   (`mesh.ply`, binary PLY with double positions) before the fit: `ellipso fit SESSION --mesh
//!   OUT/mesh.ply` (a shard too) fits exactly that geometry.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use anyhow::Context;
use ellipso_mesh::colmap_import::{ImportReport, ModelImport, import_model, transform_mesh};
use ellipso_mesh::colmap_model::{ColmapModel, read_model};
use ellipso_model::geometry::TriangleMesh;
use ellipso_model::geometry::ply::{PlyFormat, write_ply};
use ellipso_model::geometry::similarity::AlignConfig;
use ellipso_session::reader::Session;
use nalgebra::Isometry3;

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
    pub summary: serde_json::Value,
}

/// Checks the flags and reads their models (module contract); `None` without import flags.
pub fn read(args: &ImportArgs, has_mesh: bool, sharded: bool) -> anyhow::Result<Option<Models>> {
    let mesh_in_model = match (args.mesh_frame, &args.mesh_model) {
        (Some(MeshFrame::Board), Some(_)) => anyhow::bail!(
            "--mesh-model puts the mesh in that model's frame, --mesh-frame board says it is in \
             the board frame: give one of them"
        ),
        (Some(MeshFrame::Colmap), _) | (None, Some(_)) => true,
        _ => false,
    };
    if !mesh_in_model && args.poses.is_none() {
        return Ok(None);
    }
    anyhow::ensure!(
        !sharded,
        "--poses, --mesh-frame colmap and --mesh-model are not taken with --shard: run the fit \
         once without --shard (it writes the aligned mesh to OUT/mesh.ply, which shards take as \
         --mesh); sharded fits use the session's tracked poses"
    );
    anyhow::ensure!(
        has_mesh || !mesh_in_model,
        "--mesh-frame colmap and --mesh-model say which frame --mesh is in: give --mesh MESH"
    );
    anyhow::ensure!(
        !mesh_in_model || args.mesh_model.is_some() || args.poses.is_some(),
        "--mesh-frame colmap needs the COLMAP model the mesh belongs to: --poses MODEL (its \
         poses are used too) or --mesh-model MODEL (the tracked poses are kept)"
    );
    let load = |path: &PathBuf| {
        read_model(path).with_context(|| format!("reading the COLMAP model {}", path.display()))
    };
    let poses = args.poses.as_ref().map(load).transpose()?;
    let mesh = match (mesh_in_model, &args.mesh_model) {
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
) -> anyhow::Result<(Option<TriangleMesh>, Option<Imported>)> {
    let Some(models) = models else {
        return Ok((mesh, None));
    };
    let tracked =
        ellipso_mesh::poses::poses_of(session, &super::out::Printed).map_err(super::out::failed)?;
    let frame_ids: BTreeSet<u64> = session.frames.iter().map(|f| f.frame_id).collect();
    let camera = ellipso_fit::observe::camera_of(session)?;
    let align = |model: &ColmapModel| -> anyhow::Result<ModelImport> {
        let import = import_model(
            model,
            &tracked,
            &frame_ids,
            &camera,
            &AlignConfig::default(),
        )?;
        print_report(&import.report);
        Ok(import)
    };
    let mut summary = serde_json::Map::new();
    let pose_import = models.poses.as_ref().map(align).transpose()?;
    let poses = pose_import.as_ref().map(|import| {
        let poses = import.fit_poses(&tracked);
        eprintln!(
            "  the fit uses {} poses: {} from the model, {} tracked only",
            poses.len(),
            import.aligned.len() - import.report.frames_dropped.len(),
            import.report.frames_tracked_only.len()
        );
        summary.insert("poses".into(), serde_json::json!(import.report));
        poses
    });
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
            eprintln!(
                "  the mesh ({} vertices) in the board frame: {}",
                board.positions().len(),
                path.display()
            );
            let mut m = serde_json::json!({
                "model": import.report.model,
                "board_from_model": import.report.board_from_model,
                "board_mesh": path,
            });
            if let Some(s) = &separate {
                m["alignment"] = serde_json::json!(s.report);
            }
            summary.insert("mesh".into(), m);
            Some(board)
        }
        (_, mesh) => mesh,
    };
    Ok((
        mesh,
        Some(Imported {
            poses,
            summary: serde_json::Value::Object(summary),
        }),
    ))
}

/// The alignment on stderr: the similarity, the residual overall and per frame, what happens
/// to the frames.
fn print_report(r: &ImportReport) {
    let s = &r.board_from_model;
    let format = serde_json::to_value(r.format).unwrap_or_default();
    eprintln!(
        "COLMAP model {} ({} form; {}, {}, {}) → board frame: scale {:.6} m per model unit",
        r.model.display(),
        format.as_str().unwrap_or("?"),
        count(r.images, "image"),
        count(r.cameras.len(), "camera"),
        count(r.points, "point"),
        s.scale
    );
    eprintln!(
        "  alignment residual over the {} of {} frames posed by both that agree: RMS {:.3} mm, \
         {:.3}° (max {:.3} mm, {:.3}°)",
        r.frames_inliers,
        r.frames_common,
        r.rms_position_mm,
        r.rms_rotation_deg,
        r.max_position_mm,
        r.max_rotation_deg
    );
    for chunk in r.per_frame.chunks(5) {
        let row: Vec<String> = chunk
            .iter()
            .map(|f| {
                format!(
                    "{} {:.2} mm {:.3}°{}",
                    f.frame_id,
                    f.residual.position_mm,
                    f.residual.rotation_deg,
                    if f.residual.inlier {
                        ""
                    } else {
                        " (disagrees)"
                    }
                )
            })
            .collect();
        eprintln!("    {}", row.join(", "));
    }
    let list = |ids: &[u64]| {
        let shown: Vec<String> = ids.iter().take(12).map(u64::to_string).collect();
        let more = ids.len().saturating_sub(12);
        if more > 0 {
            format!("{} and {more} more", shown.join(", "))
        } else {
            shown.join(", ")
        }
    };
    if !r.frames_dropped.is_empty() {
        eprintln!(
            "  {} left out of the fit (tracking and the model disagree): {}",
            count(r.frames_dropped.len(), "frame"),
            list(&r.frames_dropped)
        );
    }
    if !r.frames_gained.is_empty() {
        eprintln!(
            "  {} posed through the alignment only (AprilTag tracking failed there): {}",
            count(r.frames_gained.len(), "frame"),
            list(&r.frames_gained)
        );
    }
    if !r.frames_tracked_only.is_empty() {
        eprintln!(
            "  {} not in the model: tracked poses kept",
            count(r.frames_tracked_only.len(), "tracked frame"),
        );
    }
    if !r.images_unmatched.is_empty() {
        let shown: Vec<&str> = r
            .images_unmatched
            .iter()
            .take(4)
            .map(String::as_str)
            .collect();
        eprintln!(
            "  {} naming no frame of the session: {}",
            count(r.images_unmatched.len(), "image"),
            shown.join(", ")
        );
    }
    for c in &r.cameras {
        // a focal length 2 % off the calibration places the cameras for another lens
        let off = (c.focal_ratio - 1.0).abs();
        if off.is_nan() || off > 0.02 {
            eprintln!(
                "  warning: camera {} ({} {}×{}) has a focal length {:+.1} % from the session's \
                 calibration: the model's poses are for that lens",
                c.camera_id,
                c.model,
                c.width,
                c.height,
                (c.focal_ratio - 1.0) * 100.0
            );
        }
    }
}

/// `n thing` or `n things`.
fn count(n: usize, thing: &str) -> String {
    format!("{n} {thing}{}", if n == 1 { "" } else { "s" })
}
