//! The rig file's `[camera]` table from a [`Calibration`]: the keys
//! [`ellipso_model::camera::CameraModel`] deserialises (width, height, fx, fy, cx, cy, k1, k2, k3,
//! p1, p2), each estimated value followed by its 1σ standard error in a comment, fixed ones
//! marked `# fixed`. Floats are written in Rust's shortest round-trip form, so reading the table
//! back gives the identical model.

use std::fmt::Write as _;

use ellipso_model::camera::CAMERA_PARAM_NAMES;

use super::Calibration;

impl Calibration {
    /// The `[camera]` TOML section (see the module doc).
    pub fn to_toml_camera_section(&self) -> String {
        let mut out = String::new();
        let points: usize = self.views.iter().map(|v| v.points).sum();
        // Writing to a String cannot fail; the results are ignored deliberately.
        let _ = writeln!(out, "[camera]");
        let _ = writeln!(
            out,
            "# calibrated from {} views ({} points, {} rejected); reprojection RMS {:.4} px",
            self.views.len(),
            points,
            self.rejected.len(),
            self.rms_px
        );
        let _ = writeln!(
            out,
            "# values ± 1σ standard error; pixel centres at integer coordinates"
        );
        let _ = writeln!(out, "width = {}", self.camera.width);
        let _ = writeln!(out, "height = {}", self.camera.height);
        let params = self.camera.params();
        // Rig-file order: intrinsics, then k1, k2, k3, p1, p2.
        for name in ["fx", "fy", "cx", "cy", "k1", "k2", "k3", "p1", "p2"] {
            let k = CAMERA_PARAM_NAMES
                .iter()
                .position(|n| *n == name)
                .unwrap_or(0);
            let comment = if self.estimated[k] {
                format!("# ± {:.3e}", self.std_errors[k])
            } else {
                "# fixed".to_string()
            };
            let _ = writeln!(out, "{name} = {:?}  {comment}", params[k]);
        }
        out
    }
}
