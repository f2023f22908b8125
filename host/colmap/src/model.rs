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

/// The text form.
mod text {
    use super::*;

    /// The data lines of a file with their 1-based line numbers (comments and, unless
    /// `keep_empty`, empty lines dropped).
    fn lines(path: &Path, keep_empty: bool) -> Result<Vec<(usize, String)>, ModelError> {
        let text = std::fs::read_to_string(path).map_err(|error| ModelError::Io {
            path: path.to_path_buf(),
            error,
        })?;
        Ok(text
            .lines()
            .enumerate()
            .map(|(i, l)| (i + 1, l.trim().to_string()))
            .filter(|(_, l)| !l.starts_with('#') && (keep_empty || !l.is_empty()))
            .collect())
    }

    fn malformed(path: &Path, line: usize, what: impl Into<String>) -> ModelError {
        ModelError::Malformed {
            path: path.to_path_buf(),
            at: format!("line {line}"),
            what: what.into(),
        }
    }

    /// Parses field `k` of `f`.
    fn field<T: std::str::FromStr>(
        path: &Path,
        line: usize,
        f: &[&str],
        k: usize,
        name: &str,
    ) -> Result<T, ModelError> {
        let v = f
            .get(k)
            .ok_or_else(|| malformed(path, line, format!("no {name} (field {})", k + 1)))?;
        v.parse()
            .map_err(|_| malformed(path, line, format!("{name} `{v}` is not a number")))
    }

    pub(super) fn cameras(path: &Path) -> Result<Vec<ModelCamera>, ModelError> {
        lines(path, false)?
            .into_iter()
            .map(|(n, l)| {
                let f: Vec<&str> = l.split_whitespace().collect();
                let model = f.get(1).copied().unwrap_or_default().to_string();
                let params = (4..f.len())
                    .map(|k| field(path, n, &f, k, "parameter"))
                    .collect::<Result<Vec<f64>, _>>()?;
                let expected = CAMERA_MODELS.iter().find(|m| m.0 == model).map(|m| m.1);
                if let Some(count) = expected.filter(|&c| c != params.len()) {
                    return Err(malformed(
                        path,
                        n,
                        format!("{model} has {count} parameters, the line {}", params.len()),
                    ));
                }
                if params.is_empty() {
                    return Err(malformed(path, n, "a camera without parameters"));
                }
                Ok(ModelCamera {
                    camera_id: field(path, n, &f, 0, "CAMERA_ID")?,
                    model,
                    width: field(path, n, &f, 2, "WIDTH")?,
                    height: field(path, n, &f, 3, "HEIGHT")?,
                    params,
                })
            })
            .collect()
    }

    pub(super) fn images(path: &Path) -> Result<Vec<ModelImage>, ModelError> {
        // as COLMAP reads it: an image line, then whatever line follows is its 2-D points
        let all = lines(path, true)?;
        let mut out = Vec::new();
        let mut rows = all.iter().peekable();
        while let Some((n, l)) = rows.next() {
            if l.is_empty() {
                continue;
            }
            let f: Vec<&str> = l.split_whitespace().collect();
            if f.len() < 10 {
                return Err(malformed(
                    path,
                    *n,
                    "an image line needs IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME",
                ));
            }
            let q: [f64; 4] = [
                field(path, *n, &f, 1, "QW")?,
                field(path, *n, &f, 2, "QX")?,
                field(path, *n, &f, 3, "QY")?,
                field(path, *n, &f, 4, "QZ")?,
            ];
            let t: [f64; 3] = [
                field(path, *n, &f, 5, "TX")?,
                field(path, *n, &f, 6, "TY")?,
                field(path, *n, &f, 7, "TZ")?,
            ];
            let camera_from_model = pose(q, t)
                .ok_or_else(|| malformed(path, *n, "the rotation is not a unit quaternion"))?;
            // names may hold spaces: everything after CAMERA_ID
            let name = f[9..].join(" ");
            let (mut points2d, mut triangulated) = (0, 0);
            if let Some((m, p)) = rows.next() {
                let g: Vec<&str> = p.split_whitespace().collect();
                if g.len() % 3 != 0 {
                    return Err(malformed(
                        path,
                        *m,
                        "2-D points come in triples X Y POINT3D_ID",
                    ));
                }
                for k in (0..g.len()).step_by(3) {
                    let id: i64 = field(path, *m, &g, k + 2, "POINT3D_ID")?;
                    points2d += 1;
                    triangulated += usize::from(id >= 0);
                }
            }
            out.push(ModelImage {
                image_id: field(path, *n, &f, 0, "IMAGE_ID")?,
                camera_id: field(path, *n, &f, 8, "CAMERA_ID")?,
                name,
                camera_from_model,
                points2d,
                points2d_triangulated: triangulated,
            });
        }
        Ok(out)
    }

    pub(super) fn points(path: &Path) -> Result<Vec<ModelPoint>, ModelError> {
        lines(path, false)?
            .into_iter()
            .map(|(n, l)| {
                let f: Vec<&str> = l.split_whitespace().collect();
                if f.len() < 8 || (f.len() - 8) % 2 != 0 {
                    return Err(malformed(
                        path,
                        n,
                        "a point line is POINT3D_ID X Y Z R G B ERROR then (IMAGE_ID POINT2D_IDX) pairs",
                    ));
                }
                let position: Point3<f64> = Point3::new(
                    field(path, n, &f, 1, "X")?,
                    field(path, n, &f, 2, "Y")?,
                    field(path, n, &f, 3, "Z")?,
                );
                if !position.coords.iter().all(|v| v.is_finite()) {
                    return Err(malformed(path, n, "a non-finite position"));
                }
                Ok(ModelPoint {
                    point3d_id: field(path, n, &f, 0, "POINT3D_ID")?,
                    position,
                    rgb: [
                        field(path, n, &f, 4, "R")?,
                        field(path, n, &f, 5, "G")?,
                        field(path, n, &f, 6, "B")?,
                    ],
                    error_px: field(path, n, &f, 7, "ERROR")?,
                    track_length: (f.len() - 8) / 2,
                })
            })
            .collect()
    }
}

/// The binary form.
mod binary {
    use super::*;

    /// A bounds-checked little-endian reader that names the byte offset of what it cannot read.
    struct Reader<'a> {
        path: &'a Path,
        bytes: Vec<u8>,
        at: usize,
    }

    impl<'a> Reader<'a> {
        fn open(path: &'a Path) -> Result<Self, ModelError> {
            let bytes = std::fs::read(path).map_err(|error| ModelError::Io {
                path: path.to_path_buf(),
                error,
            })?;
            Ok(Self { path, bytes, at: 0 })
        }

        fn fail(&self, what: impl Into<String>) -> ModelError {
            ModelError::Malformed {
                path: self.path.to_path_buf(),
                at: format!("byte {}", self.at),
                what: what.into(),
            }
        }

        fn take<const N: usize>(&mut self, what: &str) -> Result<[u8; N], ModelError> {
            let Some(slice) = self.bytes.get(self.at..self.at + N) else {
                return Err(self.fail(format!(
                    "the file ends inside {what} ({} bytes long)",
                    self.bytes.len()
                )));
            };
            let out = slice.try_into().expect("N bytes");
            self.at += N;
            Ok(out)
        }

        fn u8(&mut self, what: &str) -> Result<u8, ModelError> {
            Ok(self.take::<1>(what)?[0])
        }
        fn u32(&mut self, what: &str) -> Result<u32, ModelError> {
            self.take(what).map(u32::from_le_bytes)
        }
        fn i32(&mut self, what: &str) -> Result<i32, ModelError> {
            self.take(what).map(i32::from_le_bytes)
        }
        fn u64(&mut self, what: &str) -> Result<u64, ModelError> {
            self.take(what).map(u64::from_le_bytes)
        }
        fn f64(&mut self, what: &str) -> Result<f64, ModelError> {
            self.take(what).map(f64::from_le_bytes)
        }

        /// A count of records of at least `min_bytes` each, checked against what is left (a
        /// corrupt count must not allocate).
        fn count(&mut self, what: &str, min_bytes: usize) -> Result<usize, ModelError> {
            let n = self.u64(what)?;
            let left = (self.bytes.len() - self.at) as u64;
            if n > left / min_bytes.max(1) as u64 {
                return Err(self.fail(format!("{n} {what} cannot fit in the {left} bytes left")));
            }
            Ok(n as usize)
        }

        fn name(&mut self) -> Result<String, ModelError> {
            let rest = &self.bytes[self.at..];
            let Some(end) = rest.iter().position(|&b| b == 0) else {
                return Err(self.fail("the file ends inside an image name"));
            };
            let name = String::from_utf8(rest[..end].to_vec())
                .map_err(|_| self.fail("an image name is not UTF-8"))?;
            self.at += end + 1;
            Ok(name)
        }

        fn finish<T>(self, value: T) -> Result<T, ModelError> {
            if self.at != self.bytes.len() {
                return Err(self.fail(format!(
                    "{} bytes after the last record",
                    self.bytes.len() - self.at
                )));
            }
            Ok(value)
        }
    }

    pub(super) fn cameras(path: &Path) -> Result<Vec<ModelCamera>, ModelError> {
        let mut r = Reader::open(path)?;
        let n = r.count("cameras", 24)?;
        let mut out = Vec::with_capacity(n);
        for _ in 0..n {
            let camera_id = r.u32("a camera id")?;
            let model_at = r.at;
            let model_id = r.i32("a camera model")?;
            let Some(&(model, count)) = usize::try_from(model_id)
                .ok()
                .and_then(|k| CAMERA_MODELS.get(k))
            else {
                r.at = model_at;
                return Err(r.fail(format!(
                    "camera {camera_id}: unknown camera model id {model_id}"
                )));
            };
            let width = r.u64("a width")?;
            let height = r.u64("a height")?;
            let params = (0..count)
                .map(|_| r.f64("camera parameters"))
                .collect::<Result<Vec<f64>, _>>()?;
            out.push(ModelCamera {
                camera_id,
                model: model.to_string(),
                width,
                height,
                params,
            });
        }
        r.finish(out)
    }

    pub(super) fn images(path: &Path) -> Result<Vec<ModelImage>, ModelError> {
        let mut r = Reader::open(path)?;
        let n = r.count("images", 73)?;
        let mut out = Vec::with_capacity(n);
        for _ in 0..n {
            let start = r.at;
            let image_id = r.u32("an image id")?;
            let mut v = [0.0; 7];
            for x in &mut v {
                *x = r.f64("a pose")?;
            }
            let camera_id = r.u32("a camera id")?;
            let name = r.name()?;
            let points = r.count("2-D points", 24)?;
            let mut triangulated = 0;
            for _ in 0..points {
                r.f64("a 2-D point")?;
                r.f64("a 2-D point")?;
                // COLMAP writes an invalid id as -1 (u64::MAX read as unsigned)
                triangulated += usize::from(r.u64("a 3-D point id")? != u64::MAX);
            }
            let Some(camera_from_model) = pose([v[0], v[1], v[2], v[3]], [v[4], v[5], v[6]]) else {
                r.at = start;
                return Err(r.fail(format!(
                    "image {image_id}: the rotation is not a unit quaternion"
                )));
            };
            out.push(ModelImage {
                image_id,
                camera_id,
                name,
                camera_from_model,
                points2d: points,
                points2d_triangulated: triangulated,
            });
        }
        r.finish(out)
    }

    pub(super) fn points(path: &Path) -> Result<Vec<ModelPoint>, ModelError> {
        let mut r = Reader::open(path)?;
        let n = r.count("points", 51)?;
        let mut out = Vec::with_capacity(n);
        for _ in 0..n {
            let point3d_id = r.u64("a point id")?;
            let position = Point3::new(
                r.f64("a position")?,
                r.f64("a position")?,
                r.f64("a position")?,
            );
            let rgb = [r.u8("a colour")?, r.u8("a colour")?, r.u8("a colour")?];
            let error_px = r.f64("an error")?;
            let track_length = r.count("track elements", 8)?;
            for _ in 0..track_length {
                r.u32("a track element")?;
                r.u32("a track element")?;
            }
            out.push(ModelPoint {
                point3d_id,
                position,
                rgb,
                error_px,
                track_length,
            });
        }
        r.finish(out)
    }
}
