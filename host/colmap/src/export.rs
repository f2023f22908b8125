//! A session as a COLMAP sparse model with known poses: undistorted full-resolution s0 images,
//! the text files `cameras.txt`, `images.txt`, `points3D.txt`, and the feature database that
//! COLMAP's own pipeline (`feature_extractor`, `exhaustive_matcher`, `point_triangulator`) needs
//! to triangulate the known-pose model, so its dense and meshing steps build a mesh already in
//! board coordinates (`ellipso fit --mesh` takes it).
//!
//! Contract (COLMAP's documented text format, "Output Format" of its manual, and its database
//! schema as of COLMAP 3.8):
//! - `images/FRAMEID.png`: 8-bit s0 of every posed, readable frame at the sensor's full
//!   resolution (bilinear demosaic of the four analysers, colour bands summed), one tone curve
//!   for the whole session (scaled by the first frame's 99.5th percentile, gamma 1/2.2) so
//!   brightness is comparable across views. Undistorted by default: each output pixel samples
//!   (bilinear) where the calibrated lens model puts it.
//! - `sparse/cameras.txt`: one camera. Undistorted images: `PINHOLE fx fy cx cy`. With
//!   `keep_distortion` the images are written as captured and the model carries the
//!   calibration's Brown–Conrady coefficients: `OPENCV fx fy cx cy k1 k2 p1 p2`, or
//!   `FULL_OPENCV fx fy cx cy k1 k2 p1 p2 k3 0 0 0` when k3 ≠ 0. cx, cy are shifted by +0.5 px:
//!   COLMAP puts the centre of the top-left pixel at (0.5, 0.5), this project (OpenCV) at (0, 0).
//! - `sparse/images.txt`: per image `IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME` with the
//!   rotation and translation of camera_from_world (world = board frame, metres; COLMAP's camera
//!   axes are OpenCV's: x right, y down, z forward), `QW ≥ 0`, then an empty line of 2-D points.
//! - `sparse/points3D.txt`: no points (the header only).
//! - `database.db`: COLMAP's SQLite feature database holding that camera (its model, size and
//!   parameters, `prior_focal_length` = 1: the focal length is known) and every image under the
//!   id and name of `images.txt`. `feature_extractor` finds each image there by name and keeps
//!   its id (on its own it numbers images in whatever order its threads finish, and
//!   `point_triangulator` then aborts: "existing_image.Name() == image.second.Name()").

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use ellipso_model::camera::CameraModel;
use nalgebra::{Isometry3, UnitQuaternion};

use ellipso_fit::observe::{SkippedFrame, camera_of};
use ellipso_mesh::frames::posed_frames;
use ellipso_polar::frame::RawFrame;
use ellipso_session::reader::Session;

/// Settings of the export.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ColmapOptions {
    /// Write the images as captured with the lens model in `cameras.txt` instead of undistorting.
    pub keep_distortion: bool,
}

/// What was written.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ColmapReport {
    /// Images written.
    pub images: usize,
    /// The camera line of `cameras.txt`.
    pub camera: String,
    /// Posed frames left out, with reasons.
    pub skipped: Vec<SkippedFrame>,
    /// Files written.
    pub files: Vec<PathBuf>,
}

/// Errors of the export.
#[derive(Debug, thiserror::Error)]
pub enum ColmapError {
    /// The session cannot be read as needed.
    #[error("{0}")]
    Session(String),
    /// No frame could be written.
    #[error("no posed frame could be exported ({0})")]
    NoImages(String),
    /// Writing failed.
    #[error("{}: {error}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        error: std::io::Error,
    },
}

/// The COLMAP camera of a superpixel image of `camera` (module contract).
pub fn camera_line(camera: &CameraModel, tile: usize, keep_distortion: bool) -> String {
    let t = tile as f64;
    let i = camera.intrinsics;
    let offset = (t - 1.0) / 2.0;
    let (fx, fy) = (i.fx / t, i.fy / t);
    let (cx, cy) = ((i.cx - offset) / t + 0.5, (i.cy - offset) / t + 0.5);
    let (w, h) = (camera.width as usize / tile, camera.height as usize / tile);
    let d = camera.distortion;
    let params = if !keep_distortion {
        format!("PINHOLE {w} {h} {fx} {fy} {cx} {cy}")
    } else if d.k3 == 0.0 {
        format!(
            "OPENCV {w} {h} {fx} {fy} {cx} {cy} {} {} {} {}",
            d.k1, d.k2, d.p1, d.p2
        )
    } else {
        format!(
            "FULL_OPENCV {w} {h} {fx} {fy} {cx} {cy} {} {} {} {} {} 0 0 0",
            d.k1, d.k2, d.p1, d.p2, d.k3
        )
    };
    format!("1 {params}")
}

/// COLMAP's model id and parameters of a `cameras.txt` line (`1 MODEL W H P…`).
fn camera_row(line: &str) -> Option<(i64, i64, i64, Vec<f64>)> {
    let f: Vec<&str> = line.split_whitespace().collect();
    let model = match *f.get(1)? {
        "SIMPLE_PINHOLE" => 0,
        "PINHOLE" => 1,
        "OPENCV" => 4,
        "FULL_OPENCV" => 6,
        _ => return None,
    };
    let params = f[4..]
        .iter()
        .map(|v| v.parse().ok())
        .collect::<Option<Vec<f64>>>()?;
    Some((
        model,
        f.get(2)?.parse().ok()?,
        f.get(3)?.parse().ok()?,
        params,
    ))
}

/// Writes COLMAP's feature database at `path` (module contract): the camera of `camera_line`
/// and `images` (id, name), in COLMAP 3.8's schema; COLMAP adds its other tables on opening.
fn write_database(
    path: &Path,
    camera_line: &str,
    images: &[(usize, String)],
) -> Result<(), ColmapError> {
    let fail = |what: String| ColmapError::Io {
        path: path.to_path_buf(),
        error: std::io::Error::other(what),
    };
    let (model, width, height, params) =
        camera_row(camera_line).ok_or_else(|| fail(format!("camera `{camera_line}`")))?;
    // whole or nothing: built under a temporary name, renamed into place
    let tmp = path.with_extension("db.partial");
    let _ = std::fs::remove_file(&tmp);
    let db = rusqlite::Connection::open(&tmp).map_err(|e| fail(e.to_string()))?;
    let blob: Vec<u8> = params.iter().flat_map(|p| p.to_le_bytes()).collect();
    let sql = |e: rusqlite::Error| fail(e.to_string());
    db.execute_batch(
        "CREATE TABLE IF NOT EXISTS cameras (camera_id INTEGER PRIMARY KEY AUTOINCREMENT NOT NULL, \
         model INTEGER NOT NULL, width INTEGER NOT NULL, height INTEGER NOT NULL, params BLOB, \
         prior_focal_length INTEGER NOT NULL);\n\
         CREATE TABLE IF NOT EXISTS images (image_id INTEGER PRIMARY KEY AUTOINCREMENT NOT NULL, \
         name TEXT NOT NULL UNIQUE, camera_id INTEGER NOT NULL, prior_qw REAL, prior_qx REAL, \
         prior_qy REAL, prior_qz REAL, prior_tx REAL, prior_ty REAL, prior_tz REAL, \
         CONSTRAINT image_id_check CHECK(image_id >= 0 and image_id < 2147483647), \
         FOREIGN KEY(camera_id) REFERENCES cameras(camera_id));\n\
         CREATE UNIQUE INDEX IF NOT EXISTS index_name ON images(name);\n\
         BEGIN;",
    )
    .map_err(sql)?;
    db.execute(
        "INSERT INTO cameras VALUES (1, ?1, ?2, ?3, ?4, 1)",
        rusqlite::params![model, width, height, blob],
    )
    .map_err(sql)?;
    for (id, name) in images {
        db.execute(
            "INSERT INTO images (image_id, name, camera_id) VALUES (?1, ?2, 1)",
            rusqlite::params![*id as i64, name],
        )
        .map_err(sql)?;
    }
    db.execute_batch("COMMIT;").map_err(sql)?;
    db.close().map_err(|(_, e)| sql(e))?;
    std::fs::rename(&tmp, path).map_err(|error| ColmapError::Io {
        path: path.to_path_buf(),
        error,
    })
}

/// The `images.txt` line of one image.
pub fn image_line(image_id: usize, world_from_camera: &Isometry3<f64>, name: &str) -> String {
    let camera_from_world = world_from_camera.inverse();
    let q: UnitQuaternion<f64> = camera_from_world.rotation;
    let s = if q.w < 0.0 { -1.0 } else { 1.0 };
    let t = camera_from_world.translation.vector;
    format!(
        "{image_id} {} {} {} {} {} {} {} 1 {name}",
        s * q.w,
        s * q.i,
        s * q.j,
        s * q.k,
        t.x,
        t.y,
        t.z
    )
}

/// The undistorted (or as-captured) 8-bit image of an s0 plane.
fn render(
    s0: &[f32],
    w: usize,
    h: usize,
    camera: &CameraModel,
    tile: usize,
    scale: f32,
    keep_distortion: bool,
) -> Vec<u8> {
    let t = tile as f64;
    let offset = (t - 1.0) / 2.0;
    let i = camera.intrinsics;
    let tone = |v: f32| ((v * scale).clamp(0.0, 1.0).powf(1.0 / 2.2) * 255.0).round() as u8;
    if keep_distortion {
        return s0.iter().map(|&v| tone(v)).collect();
    }
    let at = |x: usize, y: usize| s0[y * w + x];
    (0..w * h)
        .map(|k| {
            let (u, v) = ((k % w) as f64, (k / w) as f64);
            // superpixel → raw → normalised (pinhole) → distorted raw → superpixel
            let raw = [u * t + offset, v * t + offset];
            let n = [(raw[0] - i.cx) / i.fx, (raw[1] - i.cy) / i.fy];
            let d = camera.distortion.distort(n);
            let src = camera.normalised_to_pixel(d);
            let (x, y) = ((src[0] - offset) / t, (src[1] - offset) / t);
            if !(x >= 0.0 && y >= 0.0 && x <= (w - 1) as f64 && y <= (h - 1) as f64) {
                return 0;
            }
            let (x0, y0) = (
                (x as usize).min(w.saturating_sub(2)),
                (y as usize).min(h.saturating_sub(2)),
            );
            let (fx, fy) = ((x - x0 as f64) as f32, (y - y0 as f64) as f32);
            let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
            let value = (1.0 - fy) * ((1.0 - fx) * at(x0, y0) + fx * at(x1, y0))
                + fy * ((1.0 - fx) * at(x0, y1) + fx * at(x1, y1));
            tone(value)
        })
        .collect()
}

fn write(path: &Path, bytes: &[u8]) -> Result<(), ColmapError> {
    std::fs::write(path, bytes).map_err(|error| ColmapError::Io {
        path: path.to_path_buf(),
        error,
    })
}

/// s0 of a raw frame at the sensor's full resolution (bilinear demosaic, colour bands summed),
/// in fractions of full scale: `(plane, width, height)`.
fn full_resolution_s0(raw: &RawFrame) -> Result<(Vec<f32>, usize, usize), String> {
    let config = ellipso_polar::PolarConfig {
        demosaic: ellipso_polar::DemosaicMethod::Bilinear,
        ..Default::default()
    };
    let image = ellipso_polar::process(raw, &config).map_err(|e| e.to_string())?;
    let (w, h) = (image.width(), image.height());
    let mut plane = vec![0f32; w * h];
    for band in &image.bands {
        for (p, v) in plane.iter_mut().zip(band.s0.data()) {
            *p += if v.is_finite() { *v } else { 0.0 };
        }
    }
    Ok((plane, w, h))
}

/// Writes the COLMAP model of `session` seen from `poses` into `out` (module contract).
pub fn export_colmap(
    session: &Session,
    poses: &[(u64, Isometry3<f64>)],
    out: &Path,
    options: ColmapOptions,
) -> Result<ColmapReport, ColmapError> {
    let camera = camera_of(session).map_err(|e| ColmapError::Session(e.to_string()))?;
    let layout = session.manifest.sensor.layout;
    // full resolution: one image pixel per raw pixel
    let tile = 1;
    let (frames, mut skipped) = posed_frames(session, poses);
    let images_dir = out.join("images");
    let sparse = out.join("sparse");
    for dir in [&images_dir, &sparse] {
        std::fs::create_dir_all(dir).map_err(|error| ColmapError::Io {
            path: dir.clone(),
            error,
        })?;
    }
    let mut files = Vec::new();
    let mut lines = Vec::new();
    let mut scale: Option<f32> = None;
    let mut names = Vec::new();
    for frame in &frames {
        let plane = session
            .load_frame(frame.entry)
            .map_err(|e| e.to_string())
            .and_then(|(w, h, px)| {
                RawFrame::new(w, h, session.manifest.sensor.bit_depth, layout, px)
                    .map_err(|e| e.to_string())
            })
            .and_then(|raw| full_resolution_s0(&raw));
        let (s0, w, h) = match plane {
            Ok(p) => p,
            Err(reason) => {
                skipped.push(SkippedFrame {
                    frame_id: frame.frame_id,
                    reason,
                });
                continue;
            }
        };
        let scale = *scale.get_or_insert_with(|| {
            let mut v: Vec<f32> = s0.iter().copied().filter(|x| x.is_finite()).collect();
            v.sort_by(f32::total_cmp);
            let p = v
                .get(v.len().saturating_sub(1) * 995 / 1000)
                .copied()
                .unwrap_or(1.0);
            if p > 1e-6 { 1.0 / p } else { 1.0 }
        });
        let pixels = render(&s0, w, h, &camera, tile, scale, options.keep_distortion);
        let name = format!("{:08}.png", frame.frame_id);
        let path = images_dir.join(&name);
        image::save_buffer(
            &path,
            &pixels,
            w as u32,
            h as u32,
            image::ExtendedColorType::L8,
        )
        .map_err(|e| ColmapError::Io {
            path: path.clone(),
            error: std::io::Error::other(e.to_string()),
        })?;
        files.push(path);
        let id = lines.len() + 1;
        lines.push(image_line(id, &frame.world_from_camera, &name));
        names.push((id, name));
    }
    if lines.is_empty() {
        return Err(ColmapError::NoImages(ellipso_mesh::error::skipped_list(
            &skipped, 6,
        )));
    }
    let camera_line = camera_line(&camera, tile, options.keep_distortion);
    let mut cameras = String::new();
    let _ = writeln!(cameras, "# Camera list with one line of data per camera:");
    let _ = writeln!(cameras, "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]");
    let _ = writeln!(cameras, "# Number of cameras: 1");
    let _ = writeln!(cameras, "{camera_line}");
    let mut images = String::new();
    let _ = writeln!(images, "# Image list with two lines of data per image:");
    let _ = writeln!(
        images,
        "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME"
    );
    let _ = writeln!(images, "#   POINTS2D[] as (X, Y, POINT3D_ID)");
    let _ = writeln!(
        images,
        "# Number of images: {}, mean observations per image: 0",
        lines.len()
    );
    for l in &lines {
        let _ = writeln!(images, "{l}\n");
    }
    let points = "# 3D point list with one line of data per point:\n\
                  #   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n\
                  # Number of points: 0, mean track length: 0\n";
    for (name, text) in [
        ("cameras.txt", cameras.as_str()),
        ("images.txt", images.as_str()),
        ("points3D.txt", points),
    ] {
        let path = sparse.join(name);
        write(&path, text.as_bytes())?;
        files.push(path);
    }
    let database = out.join("database.db");
    write_database(&database, &camera_line, &names)?;
    files.push(database);
    skipped.sort_by_key(|s| s.frame_id);
    Ok(ColmapReport {
        images: lines.len(),
        camera: camera_line,
        skipped,
        files,
    })
}
