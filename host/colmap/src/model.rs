//! Reading a COLMAP sparse model — the cameras, images (poses) and 3-D points of a
//! reconstruction made by COLMAP or by any tool that writes its format — in the text or the
//! binary form, for `ellipso fit --poses` (docs/mesh.md, "The way in").
//!
//! Contract (COLMAP's "Output Format" of its manual, and `src/colmap/scene/reconstruction_io`):
//! - A model is a directory with `cameras`, `images` and `points3D`, either all `.bin` (read
//!   first, as COLMAP does) or all `.txt`. A directory without them is refused with a hint
//!   (COLMAP's `mapper` writes its models into `sparse/0`, `sparse/1`, …). `points3D` may be
//!   missing (some converters write none): the model then has no points.
//! - Text: `#` comment lines; `cameras.txt` lines `CAMERA_ID MODEL WIDTH HEIGHT PARAMS…`;
//!   `images.txt` two lines per image, `IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME` then its
//!   2-D points `(X Y POINT3D_ID)…` (that line may be empty); `points3D.txt` lines
//!   `POINT3D_ID X Y Z R G B ERROR TRACK…` with (IMAGE_ID POINT2D_IDX) pairs.
//! - Binary, little-endian: `u64` counts; a camera is `u32 id, i32 model, u64 width, u64
//!   height, f64 params[n(model)]`; an image `u32 id, f64 qw qx qy qz tx ty tz, u32 camera_id,
//!   NUL-terminated name, u64 n, (f64 x, f64 y, i64 point3D_id)×n`; a point `u64 id, f64 x y z,
//!   u8 r g b, f64 error, u64 n, (u32 image_id, u32 point2D_idx)×n`.
//! - The pose is camera_from_model (COLMAP's camera axes are OpenCV's: x right, y down, z
//!   forward); the quaternion is normalised (refused when its norm is not within 1e-3 of 1, or
//!   not finite).
//! - Cameras, images and points are returned sorted by id (COLMAP writes them in its hash
//!   maps' order, which differs between the two forms).
//! - Every error names the file and the line (text) or byte offset (binary): a missing file, a
//!   malformed or truncated record, an unknown camera model, an image whose camera is not in
//!   the model, a repeated image id or name.

use std::collections::HashSet;
use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Point3, Quaternion, Translation3, UnitQuaternion};

mod binary;
mod text;

/// A camera of the model.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ModelCamera {
    /// Its id.
    pub camera_id: u32,
    /// COLMAP's model name (`PINHOLE`, `OPENCV`, …).
    pub model: String,
    /// Image width, px.
    pub width: u64,
    /// Image height, px.
    pub height: u64,
    /// The model's parameters in COLMAP's order (the first is the focal length, px, in every
    /// model).
    pub params: Vec<f64>,
}

/// A registered image of the model.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelImage {
    /// Its id.
    pub image_id: u32,
    /// Its camera's id.
    pub camera_id: u32,
    /// Its file name (relative to the image folder, as the tool wrote it).
    pub name: String,
    /// Its pose: model coordinates to camera coordinates (OpenCV axes).
    pub camera_from_model: Isometry3<f64>,
    /// 2-D points listed for it.
    pub points2d: usize,
    /// Of those, the ones with a 3-D point.
    pub points2d_triangulated: usize,
}

/// A 3-D point of the model.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ModelPoint {
    /// Its id.
    pub point3d_id: u64,
    /// Its position, model frame.
    pub position: Point3<f64>,
    /// Its colour.
    pub rgb: [u8; 3],
    /// Its mean reprojection error, px.
    pub error_px: f64,
    /// Images that see it.
    pub track_length: usize,
}

/// Which form the model was read from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum ModelFormat {
    /// `cameras.txt`, `images.txt`, `points3D.txt`.
    Text,
    /// `cameras.bin`, `images.bin`, `points3D.bin`.
    Binary,
}

/// A COLMAP sparse model.
#[derive(Clone, Debug, PartialEq)]
pub struct ColmapModel {
    /// The directory it was read from.
    pub dir: PathBuf,
    /// Text or binary.
    pub format: ModelFormat,
    /// Its cameras.
    pub cameras: Vec<ModelCamera>,
    /// Its registered images.
    pub images: Vec<ModelImage>,
    /// Its 3-D points (empty when the model has no `points3D` file).
    pub points: Vec<ModelPoint>,
}

/// Why a model could not be read.
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    /// The directory holds no model.
    #[error(
        "{}: no COLMAP model here (expected cameras, images and points3D as .bin or .txt{hint})",
        dir.display()
    )]
    NotAModel {
        /// The directory.
        dir: PathBuf,
        /// Where a model might be instead.
        hint: String,
    },
    /// A file could not be read.
    #[error("{}: {error}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        error: std::io::Error,
    },
    /// A record is malformed.
    #[error("{}, {at}: {what}", path.display())]
    Malformed {
        /// The file.
        path: PathBuf,
        /// `line N` or `byte N`.
        at: String,
        /// What is wrong.
        what: String,
    },
}

/// Parameters of each COLMAP camera model, by its id (COLMAP's `CAMERA_MODEL_CASES`).
const CAMERA_MODELS: [(&str, usize); 12] = [
    ("SIMPLE_PINHOLE", 3),
    ("PINHOLE", 4),
    ("SIMPLE_RADIAL", 4),
    ("RADIAL", 5),
    ("OPENCV", 8),
    ("OPENCV_FISHEYE", 8),
    ("FULL_OPENCV", 12),
    ("FOV", 5),
    ("SIMPLE_RADIAL_FISHEYE", 4),
    ("RADIAL_FISHEYE", 5),
    ("THIN_PRISM_FISHEYE", 12),
    ("RAD_TAN_THIN_PRISM_FISHEYE", 16),
];

/// Reads the COLMAP model in `dir` (module contract).
pub fn read_model(dir: &Path) -> Result<ColmapModel, ModelError> {
    let has = |ext: &str| {
        dir.join(format!("cameras.{ext}")).is_file() && dir.join(format!("images.{ext}")).is_file()
    };
    let format = if has("bin") {
        ModelFormat::Binary
    } else if has("txt") {
        ModelFormat::Text
    } else {
        return Err(ModelError::NotAModel {
            dir: dir.to_path_buf(),
            hint: model_hint(dir),
        });
    };
    let ext = match format {
        ModelFormat::Binary => "bin",
        ModelFormat::Text => "txt",
    };
    let file = |stem: &str| dir.join(format!("{stem}.{ext}"));
    let (cameras, images, points) = match format {
        ModelFormat::Binary => {
            let points = file("points3D");
            (
                binary::cameras(&file("cameras"))?,
                binary::images(&file("images"))?,
                if points.is_file() {
                    binary::points(&points)?
                } else {
                    Vec::new()
                },
            )
        }
        ModelFormat::Text => {
            let points = file("points3D");
            (
                text::cameras(&file("cameras"))?,
                text::images(&file("images"))?,
                if points.is_file() {
                    text::points(&points)?
                } else {
                    Vec::new()
                },
            )
        }
    };
    check(&file("images"), &cameras, &images)?;
    // one order whatever the writer's (COLMAP writes its hash maps' order)
    let (mut cameras, mut images, mut points) = (cameras, images, points);
    cameras.sort_by_key(|c| c.camera_id);
    images.sort_by_key(|i| i.image_id);
    points.sort_by_key(|p| p.point3d_id);
    Ok(ColmapModel {
        dir: dir.to_path_buf(),
        format,
        cameras,
        images,
        points,
    })
}

/// Sub-directories of `dir` that hold a model (COLMAP's `sparse/0` layout), as a hint.
fn model_hint(dir: &Path) -> String {
    let mut found: Vec<String> = std::fs::read_dir(dir)
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| e.path())
        .filter(|p| {
            ["bin", "txt"]
                .iter()
                .any(|e| p.join(format!("cameras.{e}")).is_file())
        })
        .map(|p| p.display().to_string())
        .collect();
    found.sort();
    match found.as_slice() {
        [] if !dir.is_dir() => "; it is not a directory".into(),
        [] => String::new(),
        f => format!("; models found in {}", f.join(", ")),
    }
}

/// Every image's camera is in the model; image ids and names are unique.
fn check(path: &Path, cameras: &[ModelCamera], images: &[ModelImage]) -> Result<(), ModelError> {
    let camera_ids: HashSet<u32> = cameras.iter().map(|c| c.camera_id).collect();
    let mut ids = HashSet::new();
    let mut names = HashSet::new();
    for image in images {
        let fail = |what: String| ModelError::Malformed {
            path: path.to_path_buf(),
            at: format!("image {}", image.image_id),
            what,
        };
        if !camera_ids.contains(&image.camera_id) {
            return Err(fail(format!(
                "its camera {} is not in the model's cameras",
                image.camera_id
            )));
        }
        if !ids.insert(image.image_id) {
            return Err(fail("the image id is repeated".into()));
        }
        if !names.insert(image.name.as_str()) {
            return Err(fail(format!("the name {} is repeated", image.name)));
        }
    }
    Ok(())
}

/// The pose of an image from COLMAP's quaternion (w, x, y, z) and translation; `None` when the
/// quaternion is not (within 1e-3) a unit quaternion or a value is not finite.
fn pose(q: [f64; 4], t: [f64; 3]) -> Option<Isometry3<f64>> {
    let quaternion = Quaternion::new(q[0], q[1], q[2], q[3]);
    let norm = quaternion.norm();
    if !q.iter().chain(&t).all(|v| v.is_finite()) || (norm - 1.0).abs() > 1e-3 {
        return None;
    }
    Some(Isometry3::from_parts(
        Translation3::new(t[0], t[1], t[2]),
        UnitQuaternion::from_quaternion(quaternion),
    ))
}
