//! The way in from other tools: a COLMAP model's camera poses — and any mesh in the model's
//! frame — brought into the board frame. The model's images are matched to the session's
//! frames by name, the similarity board_from_model (scale, rotation, translation) is estimated
//! robustly from the frames the session's own AprilTag tracking posed
//! (`ellipso_model::geometry::similarity::align_poses`), and every frame gets the pose the fit
//! uses (docs/mesh.md, "The way in").
//!
//! Contract:
//! - An image is the frame whose id the stem of its file name is (`00000148.png`, `148.jpg`,
//!   `images/00000148.png`: the session's and `ellipso export colmap`'s names, any extension,
//!   any folder). Images naming no frame of the session are listed, never guessed; two images
//!   naming one frame are refused.
//! - The alignment uses the frames posed by both; its refusals (too few such frames, centres
//!   on a line or on one spot, too few agreeing, residual above the limit) are errors that say
//!   how many frames were matched, tracked and common.
//! - Poses for the fit ([`ModelImport::fit_poses`]), per frame, board frame:
//!   - posed by both and agreeing (an inlier): the model's pose, aligned — poses and a mesh from
//!     one reconstruction agree with each other;
//!   - posed by both and disagreeing (an outlier): none — one of the two is wrong and nothing
//!     says which; the frame is left out and listed;
//!   - posed by the model only (tracking failed): the model's pose, aligned (*gained*);
//!   - tracked only (the model lacks the frame): the tracked pose.
//! - [`transform_mesh`] maps a mesh from the model's frame into the board frame (positions by
//!   the similarity, normals by its rotation; winding and regions kept).

use std::collections::{BTreeMap, BTreeSet};
use std::path::PathBuf;

use ellipso_model::camera::CameraModel;
use ellipso_model::geometry::similarity::{
    AlignConfig, AlignError, PosePair, PoseResidual, align_poses, apply_to_pose,
};
use ellipso_model::geometry::{MeshError, TriangleMesh};
use nalgebra::{Isometry3, Similarity3};

use crate::model::{ColmapModel, ModelFormat};

/// Why a model could not be brought in.
#[derive(Debug, thiserror::Error)]
pub enum ImportError {
    /// No image of the model names a frame of the session.
    #[error(
        "{}: none of its {images} images names a frame of the session (names seen: {examples}; \
         the session's frames are {frames}): the model must keep the session's frame names, as \
         `ellipso export colmap` writes them (00000148.png; any extension or folder)",
        model.display()
    )]
    NoFrames {
        /// The model's directory.
        model: PathBuf,
        /// Images in the model.
        images: usize,
        /// A few of their names.
        examples: String,
        /// The session's frame names, in short.
        frames: String,
    },
    /// Two images name one frame.
    #[error("{}: images {first} and {second} both name frame {frame_id}", model.display())]
    DuplicateFrame {
        /// The model's directory.
        model: PathBuf,
        /// The frame.
        frame_id: u64,
        /// One image's name.
        first: String,
        /// The other's.
        second: String,
    },
    /// The alignment refused.
    #[error(
        "{}: cannot be aligned to the board frame ({matched} of its images name session frames, \
         {tracked} frames tracked, {common} posed by both): {error}{hint}",
        model.display()
    )]
    Align {
        /// The model's directory.
        model: PathBuf,
        /// Images matched to frames.
        matched: usize,
        /// Frames the session's tracking posed.
        tracked: usize,
        /// Frames posed by both.
        common: usize,
        /// Why.
        error: AlignError,
        /// The likely cause where the model says it ([`intrinsics_hint`]), else empty.
        hint: String,
    },
}

/// How far a model camera's focal length may stray from the session's calibration before a
/// refused alignment names it as the likely cause: 0.5 %. A camera placed for a focal length
/// off by ε sits ε·d off along its axis; at the rig's 0.3–0.7 m working distance 0.5 % is
/// 1.5–3.5 mm, the order of the alignment's inlier threshold (`AlignConfig`, 5 mm), so beyond
/// it the poses of a model that refined its intrinsics cannot all agree with the tracked ones.
pub const FOCAL_RATIO_TOLERANCE: f64 = 0.005;

/// The likely cause of a refused alignment in the model's own cameras: a focal length that
/// strays from the calibration by more than [`FOCAL_RATIO_TOLERANCE`] (COLMAP's `mapper`
/// refines the intrinsics by default) — `"; likely cause: …"`, or empty.
pub fn intrinsics_hint(cameras: &[CameraReport]) -> String {
    let off: Vec<String> = cameras
        .iter()
        .filter(|c| {
            let off = (c.focal_ratio - 1.0).abs();
            off.is_nan() || off > FOCAL_RATIO_TOLERANCE
        })
        .map(|c| {
            format!(
                "camera {} {:+.1} %",
                c.camera_id,
                100.0 * (c.focal_ratio - 1.0)
            )
        })
        .collect();
    if off.is_empty() {
        return String::new();
    }
    format!(
        "; likely cause: the model's focal length is not the session's calibration ({}), so its \
         cameras are placed for another lens — COLMAP's mapper refines the intrinsics unless \
         told not to: run it with --Mapper.ba_refine_focal_length 0 \
         --Mapper.ba_refine_extra_params 0 (docs/mesh.md, \"The way in\")",
        off.join(", ")
    )
}

/// One frame in the alignment.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct FrameResidual {
    /// The frame.
    pub frame_id: u64,
    /// Its image in the model.
    pub image: String,
    /// Its residual.
    #[serde(flatten)]
    pub residual: PoseResidual,
}

/// A camera of the model against the session's.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct CameraReport {
    /// Its id.
    pub camera_id: u32,
    /// COLMAP's model name.
    pub model: String,
    /// Image size, px.
    pub width: u64,
    /// Image height, px.
    pub height: u64,
    /// Its focal length scaled to the session's image width over the session camera's fx (1:
    /// the same lens; the poses do not depend on it, but a tool that refined the focal length
    /// far from the calibration placed its cameras for another lens).
    pub focal_ratio: f64,
}

/// The similarity, readable.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct SimilarityReport {
    /// Scale: board metres per model unit.
    pub scale: f64,
    /// Rotation as a quaternion (w, x, y, z).
    pub rotation_wxyz: [f64; 4],
    /// Translation, metres.
    pub translation_m: [f64; 3],
    /// The 4×4 matrix, row-major (`x_board = M · [x_model; 1]`).
    pub matrix: [[f64; 4]; 4],
}

impl From<&Similarity3<f64>> for SimilarityReport {
    fn from(s: &Similarity3<f64>) -> Self {
        let q = s.isometry.rotation;
        let t = s.isometry.translation.vector;
        let m = s.to_homogeneous();
        Self {
            scale: s.scaling(),
            rotation_wxyz: [q.w, q.i, q.j, q.k],
            translation_m: [t.x, t.y, t.z],
            matrix: std::array::from_fn(|r| std::array::from_fn(|c| m[(r, c)])),
        }
    }
}

/// What the import found and did (the fit's summary holds it as `import`).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ImportReport {
    /// The model's directory.
    pub model: PathBuf,
    /// Text or binary.
    pub format: ModelFormat,
    /// Its cameras against the session's.
    pub cameras: Vec<CameraReport>,
    /// Its registered images.
    pub images: usize,
    /// Its 3-D points.
    pub points: usize,
    /// Images naming no frame of the session.
    pub images_unmatched: Vec<String>,
    /// Model coordinates → board frame.
    pub board_from_model: SimilarityReport,
    /// Frames posed by both (the alignment's input).
    pub frames_common: usize,
    /// Of those, the ones that agree.
    pub frames_inliers: usize,
    /// RMS centre residual over the inliers, mm.
    pub rms_position_mm: f64,
    /// RMS rotation residual over the inliers, degrees.
    pub rms_rotation_deg: f64,
    /// Largest inlier centre residual, mm.
    pub max_position_mm: f64,
    /// Largest inlier rotation residual, degrees.
    pub max_rotation_deg: f64,
    /// Every common frame's residual, by frame id.
    pub per_frame: Vec<FrameResidual>,
    /// Frames posed by both that disagree: left out of the fit.
    pub frames_dropped: Vec<u64>,
    /// Frames only the model posed (tracking failed): posed through the alignment.
    pub frames_gained: Vec<u64>,
    /// Frames tracked that the model lacks (keep their tracked pose).
    pub frames_tracked_only: Vec<u64>,
}

/// A model aligned to the board frame.
#[derive(Clone, Debug)]
pub struct ModelImport {
    /// Model coordinates → board frame.
    pub board_from_model: Similarity3<f64>,
    /// Every matched frame's model pose in the board frame, by frame id.
    pub aligned: Vec<(u64, Isometry3<f64>)>,
    /// The report.
    pub report: ImportReport,
}

impl ModelImport {
    /// The poses the fit uses, by frame id (module contract).
    pub fn fit_poses(&self, tracked: &[(u64, Isometry3<f64>)]) -> Vec<(u64, Isometry3<f64>)> {
        let dropped: BTreeSet<u64> = self.report.frames_dropped.iter().copied().collect();
        let mut poses: BTreeMap<u64, Isometry3<f64>> = tracked.iter().copied().collect();
        for (id, pose) in &self.aligned {
            poses.insert(*id, *pose);
        }
        poses.retain(|id, _| !dropped.contains(id));
        poses.into_iter().collect()
    }
}

/// The frame an image names: the number its file name's stem is, if the session has that frame.
pub fn frame_of_image(name: &str, frame_ids: &BTreeSet<u64>) -> Option<u64> {
    let file = name.rsplit(['/', '\\']).next()?;
    let stem = file.split('.').next()?;
    if stem.is_empty() || !stem.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    stem.parse().ok().filter(|id| frame_ids.contains(id))
}

/// Brings `model` into the board frame of a session whose frames are `frame_ids`, with
/// `tracked` its AprilTag poses (board frame) and `camera` its calibrated camera (module
/// contract).
pub fn import_model(
    model: &ColmapModel,
    tracked: &[(u64, Isometry3<f64>)],
    frame_ids: &BTreeSet<u64>,
    camera: &CameraModel,
    config: &AlignConfig,
) -> Result<ModelImport, ImportError> {
    // images → frames
    let mut matched: BTreeMap<u64, (&str, Isometry3<f64>)> = BTreeMap::new();
    let mut unmatched = Vec::new();
    for image in &model.images {
        let Some(frame_id) = frame_of_image(&image.name, frame_ids) else {
            unmatched.push(image.name.clone());
            continue;
        };
        if let Some((first, _)) = matched.get(&frame_id) {
            return Err(ImportError::DuplicateFrame {
                model: model.dir.clone(),
                frame_id,
                first: first.to_string(),
                second: image.name.clone(),
            });
        }
        matched.insert(frame_id, (&image.name, image.camera_from_model.inverse()));
    }
    if matched.is_empty() {
        let first = frame_ids.first().copied().unwrap_or_default();
        let last = frame_ids.last().copied().unwrap_or_default();
        return Err(ImportError::NoFrames {
            model: model.dir.clone(),
            images: model.images.len(),
            examples: unmatched
                .iter()
                .take(3)
                .cloned()
                .collect::<Vec<_>>()
                .join(", "),
            frames: format!(
                "{first:08}.png … {last:08}.png ({} frames)",
                frame_ids.len()
            ),
        });
    }
    // the frames posed by both
    let tracked_map: BTreeMap<u64, Isometry3<f64>> = tracked.iter().copied().collect();
    let common: Vec<u64> = matched
        .keys()
        .copied()
        .filter(|id| tracked_map.contains_key(id))
        .collect();
    let pairs: Vec<PosePair> = common
        .iter()
        .map(|id| PosePair {
            source_from_camera: matched[id].1,
            target_from_camera: tracked_map[id],
        })
        .collect();
    let cameras: Vec<CameraReport> = model
        .cameras
        .iter()
        .map(|c| CameraReport {
            camera_id: c.camera_id,
            model: c.model.clone(),
            width: c.width,
            height: c.height,
            // the first parameter is the focal length in every COLMAP model; guard: a zero
            // width or fx gives NaN, reported as such
            focal_ratio: c.params[0] * f64::from(camera.width)
                / (c.width as f64 * camera.intrinsics.fx),
        })
        .collect();
    let alignment = align_poses(&pairs, config).map_err(|error| ImportError::Align {
        model: model.dir.clone(),
        matched: matched.len(),
        tracked: tracked_map.len(),
        common: common.len(),
        hint: match error {
            AlignError::TooFewInliers { .. } | AlignError::ResidualTooLarge { .. } => {
                intrinsics_hint(&cameras)
            }
            _ => String::new(),
        },
        error,
    })?;
    let board_from_model = alignment.target_from_source;
    let per_frame: Vec<FrameResidual> = common
        .iter()
        .zip(&alignment.residuals)
        .map(|(id, r)| FrameResidual {
            frame_id: *id,
            image: matched[id].0.to_string(),
            residual: *r,
        })
        .collect();
    let report = ImportReport {
        model: model.dir.clone(),
        format: model.format,
        cameras,
        images: model.images.len(),
        points: model.points.len(),
        images_unmatched: unmatched,
        board_from_model: SimilarityReport::from(&board_from_model),
        frames_common: common.len(),
        frames_inliers: alignment.inliers,
        rms_position_mm: alignment.rms_position_mm,
        rms_rotation_deg: alignment.rms_rotation_deg,
        max_position_mm: alignment.max_position_mm,
        max_rotation_deg: alignment.max_rotation_deg,
        frames_dropped: per_frame
            .iter()
            .filter(|f| !f.residual.inlier)
            .map(|f| f.frame_id)
            .collect(),
        frames_gained: matched
            .keys()
            .copied()
            .filter(|id| !tracked_map.contains_key(id))
            .collect(),
        frames_tracked_only: tracked_map
            .keys()
            .copied()
            .filter(|id| !matched.contains_key(id))
            .collect(),
        per_frame,
    };
    let aligned = matched
        .iter()
        .map(|(id, (_, model_from_camera))| {
            (*id, apply_to_pose(&board_from_model, model_from_camera))
        })
        .collect();
    Ok(ModelImport {
        board_from_model,
        aligned,
        report,
    })
}

/// `mesh` (in the model's frame) in the board frame (module contract).
pub fn transform_mesh(
    mesh: &TriangleMesh,
    board_from_model: &Similarity3<f64>,
) -> Result<TriangleMesh, MeshError> {
    let positions = mesh
        .positions()
        .iter()
        .map(|p| board_from_model.transform_point(p))
        .collect();
    let rotation = board_from_model.isometry.rotation;
    let normals = mesh
        .normals()
        .iter()
        .map(|n| rotation * n.into_inner())
        .collect();
    TriangleMesh::new(
        positions,
        Some(normals),
        mesh.regions().map(<[u32]>::to_vec),
        mesh.triangles().to_vec(),
    )
}

#[cfg(test)]
pub(crate) mod tests;
