//! `fit-view.json`: the camera and lights of the fit's pictures, so a later step (the Mitsuba
//! export) renders the same view from the fit directory alone.
//!
//! Contract: JSON with `width`, `height` (px), `focal_px` (ideal pinhole, square pixels, the
//! principal point at the image centre), `world_from_camera` (4×4 row-major, OpenCV axes: x
//! right, y down, z forward; world = the board frame, metres), `flash_position_world` (the
//! rig's flash at that pose), `flash_polariser_axis_world` (the transmission axis of the flash's
//! linear polariser at that pose, unit; absent or `null`: an unpolarised flash) and
//! `key_light_world` (the relit picture's light). [`read`] checks every number is finite, the
//! rotation orthonormal and the polariser axis a unit vector.

use std::path::Path;

use nalgebra::{Isometry3, Matrix3, Matrix4, Point3, Rotation3, Translation3, UnitQuaternion};

use super::raster::ViewCamera;

/// The file's name inside a fit directory.
pub const FILE_NAME: &str = "fit-view.json";

/// The pictures' view (module doc).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PictureView {
    /// Columns, px.
    pub width: u32,
    /// Rows, px.
    pub height: u32,
    /// Focal length, px.
    pub focal_px: f64,
    /// Camera → world, 4×4 row-major (OpenCV camera axes).
    pub world_from_camera: [[f64; 4]; 4],
    /// The rig's flash at this pose, world, metres.
    pub flash_position_world: [f64; 3],
    /// The flash polariser's transmission axis at this pose, world, unit (`None`: unpolarised).
    #[serde(default)]
    pub flash_polariser_axis_world: Option<[f64; 3]>,
    /// The relit picture's key light, world, metres.
    pub key_light_world: [f64; 3],
}

impl PictureView {
    /// The record of `camera` with its lights.
    pub fn new(camera: &ViewCamera, flash: &Point3<f64>, key_light: &Point3<f64>) -> Self {
        let m = camera.world_from_camera.to_homogeneous();
        Self {
            width: camera.width,
            height: camera.height,
            focal_px: camera.focal_px(),
            world_from_camera: std::array::from_fn(|r| std::array::from_fn(|c| m[(r, c)])),
            flash_position_world: flash.coords.into(),
            flash_polariser_axis_world: None,
            key_light_world: key_light.coords.into(),
        }
    }

    /// This record with the flash behind a linear polariser of transmission axis `axis`
    /// (world; `None`: unpolarised).
    pub fn with_polariser(mut self, axis: Option<[f64; 3]>) -> Self {
        self.flash_polariser_axis_world = axis;
        self
    }

    /// The pinhole camera of this record.
    pub fn camera(&self) -> ViewCamera {
        let m = Matrix4::from_fn(|r, c| self.world_from_camera[r][c]);
        let rotation = Rotation3::from_matrix_unchecked(m.fixed_view::<3, 3>(0, 0).into_owned());
        let translation = Translation3::new(m[(0, 3)], m[(1, 3)], m[(2, 3)]);
        ViewCamera::pinhole(
            Isometry3::from_parts(translation, UnitQuaternion::from_rotation_matrix(&rotation)),
            self.width,
            self.height,
            self.focal_px,
        )
    }

    /// Why this record cannot be used, if it cannot.
    fn problem(&self) -> Option<String> {
        let numbers = self
            .world_from_camera
            .iter()
            .flatten()
            .chain(&self.flash_position_world)
            .chain(&self.key_light_world)
            .chain(std::iter::once(&self.focal_px));
        if numbers.into_iter().any(|v| !v.is_finite()) {
            return Some("a number is not finite".into());
        }
        if let Some(a) = self.flash_polariser_axis_world {
            let norm = a.iter().map(|v| v * v).sum::<f64>().sqrt();
            if norm.is_nan() || (norm - 1.0).abs() >= 1e-6 {
                return Some("flash_polariser_axis_world is not a unit vector".into());
            }
        }
        if self.width == 0 || self.height == 0 || self.focal_px <= 0.0 {
            return Some("the image size and focal length must be positive".into());
        }
        let r = Matrix3::from_fn(|i, j| self.world_from_camera[i][j]);
        if (r.transpose() * r - Matrix3::identity()).amax() > 1e-6 || r.determinant() < 0.0 {
            return Some("world_from_camera is not a rigid transform".into());
        }
        None
    }
}

/// Writes `view` into `dir` (whole or not at all).
pub fn write(dir: &Path, view: &PictureView) -> std::io::Result<std::path::PathBuf> {
    let path = dir.join(FILE_NAME);
    let text = serde_json::to_string_pretty(view).map_err(std::io::Error::other)?;
    ellipso_report::atomic_file::write(&path, text + "\n")?;
    Ok(path)
}

/// Reads and checks `fit-view.json` of a fit directory; the error names the file and the fault.
pub fn read(dir: &Path) -> Result<PictureView, String> {
    let path = dir.join(FILE_NAME);
    let name = path.display();
    let text = ellipso_model::file_io::read_bounded_text(&path, ellipso_model::file_io::caps::SCENE).map_err(|e| {
        format!("{name}: {e} (a fit directory written by an older ellipso lacks it: re-run `ellipso fit`)")
    })?;
    let view: PictureView =
        serde_json::from_str(&text).map_err(|e| format!("{name}: not a picture view: {e}"))?;
    match view.problem() {
        Some(p) => Err(format!("{name}: {p}")),
        None => Ok(view),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    #[test]
    fn a_view_round_trips_and_bad_files_are_named() {
        let pose = Isometry3::from_parts(
            Translation3::new(0.1, -0.2, 0.5),
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 2.5),
        );
        let camera = ViewCamera::pinhole(pose, 64, 48, 80.0);
        let view = PictureView::new(
            &camera,
            &Point3::new(0.0, 0.0, 0.4),
            &Point3::new(1.0, 2.0, 3.0),
        );
        let dir = tempfile::tempdir().unwrap();
        write(dir.path(), &view).unwrap();
        let back = read(dir.path()).unwrap();
        assert_eq!(back, view);
        let c = back.camera();
        assert!((c.world_from_camera.to_homogeneous() - pose.to_homogeneous()).amax() < 1e-12);
        assert_eq!(
            (c.width, c.height, c.intrinsics),
            (64, 48, camera.intrinsics)
        );

        let mut bad = view.clone();
        bad.world_from_camera[0][0] = 2.0;
        write(dir.path(), &bad).unwrap();
        let e = read(dir.path()).unwrap_err();
        assert!(e.contains(FILE_NAME) && e.contains("rigid"), "{e}");
        let empty = tempfile::tempdir().unwrap();
        assert!(read(empty.path()).unwrap_err().contains("re-run"));
    }
}
