//! Rig files (TOML): what `ellipso capture --rig RIG.toml` needs to drive the physical rig.
//!
//! ```toml
//! [trigger]
//! port = "/dev/ttyACM0"          # serial device, pty, or unix:PATH (the trigger board)
//!
//! [sensor]
//! backend = "aravis"             # aravis (GigE/USB3 Vision, by numeric IP: never discovered) | v4l
//! address = "192.168.10.2"       # aravis: the camera's IP address; v4l: /dev/videoN
//! layout = "monopolar"           # monopolar (IMX250MZR) | colourpolar (IMX250MYR)
//! bit_depth = 12
//! exposure_us = 8000
//! gain_db = 0.0
//!
//! [camera]                       # optional until `ellipso calibrate` writes it; exactly its output
//! width = 2448
//! height = 2048
//! fx = 3500.0
//! # fy, cx, cy, k1, k2, k3, p1, p2
//!
//! [capture]
//! photos = 150
//! interval_ms = 500.0            # free run: one photo per interval
//! trigger = "free_run"           # free_run | grip_button
//! flash_delay_us = 100
//! flash_duration_us = 2000
//!
//! [flash]                        # optional; as `ellipso calibrate --sphere` writes it
//! offset_m = [0.0, -0.03, 0.0]   # flash position in the camera frame (x right, y down, z forward)
//!
//! [[boards]]
//! file = "boards/base_a4.toml"   # relative to this rig file
//! translation_m = [0.0, 0.0, 0.0]
//! rotation_deg = [0.0, 0.0, 0.0] # world from board, XYZ Euler angles
//! ```
//!
//! Unknown keys are refused; every error names the file, the key and, for syntax errors, the line.

use std::path::{Path, PathBuf};

use ellipso_model::camera::CameraModel;
use ellipso_model::mosaic::SensorLayout;
use ellipso_model::tags::PlacedBoard;
use ellipso_protocol::{CaptureConfig, PulseCount, TriggerSource};
use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use serde::Deserialize;

use ellipso_session::rig::TrackedBoard;

/// The trigger board.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TriggerSection {
    /// Serial device, pty, or `unix:PATH`.
    pub port: String,
}

/// Which camera backend drives the sensor.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Backend {
    /// GigE Vision / USB3 Vision through libaravis (feature `aravis`).
    Aravis,
    /// UVC through V4L2 (feature `v4l`).
    V4l,
}

/// The sensor and how to reach it.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorSection {
    /// Backend.
    pub backend: Backend,
    /// aravis: numeric IP address; v4l: device path.
    pub address: String,
    /// Mosaic layout.
    pub layout: SensorLayout,
    /// Significant bits per sample.
    pub bit_depth: u8,
    /// Exposure, µs.
    pub exposure_us: u32,
    /// Gain, dB.
    #[serde(default)]
    pub gain_db: f32,
}

/// What fires each photo.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum TriggerKind {
    /// One photo per interval.
    #[default]
    FreeRun,
    /// One photo per press of the grip button.
    GripButton,
}

/// The capture.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CaptureSection {
    /// Photos.
    pub photos: u32,
    /// Interval between photos (free run), or the minimum between presses, ms.
    pub interval_ms: f64,
    /// Trigger.
    #[serde(default)]
    pub trigger: TriggerKind,
    /// Flash delay after the exposure starts, µs.
    #[serde(default = "default_flash_delay")]
    pub flash_delay_us: u32,
    /// Flash on-time, µs.
    pub flash_duration_us: u32,
}

fn default_flash_delay() -> u32 {
    100
}

/// A board of the capture.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BoardEntry {
    /// Board file, relative to the rig file.
    pub file: PathBuf,
    /// World from board: translation, m.
    #[serde(default)]
    pub translation_m: [f64; 3],
    /// World from board: XYZ Euler angles, degrees.
    #[serde(default)]
    pub rotation_deg: [f64; 3],
}

/// The flash's place on the rig.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FlashSection {
    /// Flash position in the camera frame (OpenCV axes), m.
    pub offset_m: [f64; 3],
}

/// A rig file.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RigFile {
    /// Trigger board.
    pub trigger: TriggerSection,
    /// Sensor.
    pub sensor: SensorSection,
    /// Camera model; optional until `ellipso calibrate` has written it (a capture before
    /// calibration records a provisional model).
    #[serde(default)]
    pub camera: Option<CameraModel>,
    /// Capture.
    pub capture: CaptureSection,
    /// Flash position (from `ellipso calibrate --sphere`), if known.
    #[serde(default)]
    pub flash: Option<FlashSection>,
    /// AprilTag boards.
    #[serde(default)]
    pub boards: Vec<BoardEntry>,
    /// Where it was read from (for relative paths).
    #[serde(skip)]
    pub path: PathBuf,
}

/// Errors reading a rig file.
#[derive(Debug, thiserror::Error)]
pub enum RigFileError {
    /// The file could not be read.
    #[error("{path}: {error}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        error: std::io::Error,
    },
    /// The TOML is malformed or has unknown or missing keys.
    #[error("{path}: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// What the parser said (with line and column).
        message: String,
    },
    /// A value is out of range.
    #[error("{path}: `{key}` {message}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// The key.
        key: String,
        /// What is wrong.
        message: String,
    },
}

impl RigFile {
    /// Reads and checks a rig file.
    pub fn load(path: &Path) -> Result<Self, RigFileError> {
        let text =
            ellipso_model::file_io::read_bounded_text(path, ellipso_model::file_io::caps::SCENE)
                .map_err(|error| RigFileError::Io {
                    path: path.into(),
                    error,
                })?;
        let mut rig: RigFile = toml::from_str(&text).map_err(|e| RigFileError::Parse {
            path: path.into(),
            message: e.to_string().trim_end().to_string(),
        })?;
        rig.path = path.to_path_buf();
        rig.check()?;
        Ok(rig)
    }

    fn check(&self) -> Result<(), RigFileError> {
        let bad = |key: &str, message: String| RigFileError::Invalid {
            path: self.path.clone(),
            key: key.into(),
            message,
        };
        if !matches!(self.sensor.bit_depth, 8 | 10 | 12 | 16) {
            return Err(bad(
                "sensor.bit_depth",
                format!("is {}; expected 8, 10, 12 or 16", self.sensor.bit_depth),
            ));
        }
        if self.sensor.exposure_us == 0 {
            return Err(bad("sensor.exposure_us", "must be > 0".into()));
        }
        if self.capture.photos == 0 {
            return Err(bad("capture.photos", "must be ≥ 1".into()));
        }
        if !(self.capture.interval_ms.is_finite() && self.capture.interval_ms > 0.0) {
            return Err(bad(
                "capture.interval_ms",
                format!("is {}; must be > 0", self.capture.interval_ms),
            ));
        }
        if let Some(f) = &self.flash
            && !f.offset_m.iter().all(|v| v.is_finite())
        {
            return Err(bad(
                "flash.offset_m",
                format!("{:?} has a non-finite value", f.offset_m),
            ));
        }
        if self.capture.flash_delay_us + self.capture.flash_duration_us > self.sensor.exposure_us {
            return Err(bad(
                "capture.flash_duration_us",
                format!(
                    "puts the flash outside the exposure: delay {} + duration {} > exposure {} µs",
                    self.capture.flash_delay_us,
                    self.capture.flash_duration_us,
                    self.sensor.exposure_us
                ),
            ));
        }
        if self.sensor.backend == Backend::Aravis
            && self.sensor.address.parse::<std::net::IpAddr>().is_err()
        {
            return Err(bad(
                "sensor.address",
                format!(
                    "'{}' is not a numeric IP address (names would trigger network discovery)",
                    self.sensor.address
                ),
            ));
        }
        Ok(())
    }

    /// The board timing.
    pub fn board_config(&self) -> CaptureConfig {
        CaptureConfig {
            exposure_us: self.sensor.exposure_us,
            flash_delay_us: self.capture.flash_delay_us,
            flash_duration_us: self.capture.flash_duration_us,
            frame_period_us: (self.capture.interval_ms * 1e3).round() as u32,
            pulses: PulseCount::Count(self.capture.photos),
            trigger: match self.capture.trigger {
                TriggerKind::FreeRun => TriggerSource::FreeRun,
                TriggerKind::GripButton => TriggerSource::GripButton,
            },
            report_edges: false,
            // `ellipso capture --bracket` sets one for a capture.
            bracket: ellipso_protocol::Bracket::NONE,
        }
    }

    /// The boards, loaded from their files and placed in the world.
    pub fn boards(&self) -> Result<Vec<TrackedBoard>, RigFileError> {
        let base = self.path.parent().unwrap_or(Path::new("."));
        self.boards
            .iter()
            .enumerate()
            .map(|(i, b)| {
                let file = base.join(&b.file);
                let board = ellipso_sim::scene::load_board_file(&file).map_err(|e| {
                    RigFileError::Invalid {
                        path: self.path.clone(),
                        key: format!("boards[{i}].file"),
                        message: e.to_string(),
                    }
                })?;
                let [rx, ry, rz] = b.rotation_deg.map(f64::to_radians);
                let [tx, ty, tz] = b.translation_m;
                let world_from_board = Isometry3::from_parts(
                    Translation3::new(tx, ty, tz),
                    UnitQuaternion::from_euler_angles(rx, ry, rz),
                );
                Ok(TrackedBoard::from_placed(&PlacedBoard {
                    board,
                    world_from_board,
                }))
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(dir: &Path, text: &str) -> PathBuf {
        let p = dir.join("rig.toml");
        std::fs::write(&p, text).unwrap();
        p
    }

    fn good() -> String {
        let board = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../sim/boards/base_a4.toml");
        format!(
            r#"
[trigger]
port = "/dev/ttyACM0"

[sensor]
backend = "aravis"
address = "192.168.10.2"
layout = "monopolar"
bit_depth = 12
exposure_us = 8000

[camera]
width = 2448
height = 2048
fx = 3500.0
fy = 3500.0
cx = 1223.5
cy = 1023.5
k1 = 0.0
k2 = 0.0
k3 = 0.0
p1 = 0.0
p2 = 0.0

[capture]
photos = 150
interval_ms = 500.0
flash_duration_us = 2000

[[boards]]
file = "{}"
"#,
            board.display()
        )
    }

    #[test]
    fn a_good_rig_file_loads_with_its_board() {
        let tmp = tempfile::tempdir().unwrap();
        let rig = RigFile::load(&write(tmp.path(), &good())).unwrap();
        assert_eq!(rig.board_config().frame_period_us, 500_000);
        assert_eq!(rig.board_config().pulses, PulseCount::Count(150));
        let boards = rig.boards().unwrap();
        assert_eq!(boards.len(), 1);
        assert!(!boards[0].corners_board_m.is_empty());
    }

    #[test]
    fn the_flash_section_calibrate_writes_loads_back() {
        let estimate = ellipso_vision::calibrate::flash::FlashEstimate {
            flash_camera_m: nalgebra::Point3::new(0.000_1, -0.030_2, 0.001_7),
            covariance_m2: nalgebra::Matrix3::identity() * 1e-8,
            std_m: [1e-4; 3],
            ray_angle_residuals_rad: vec![1e-3; 12],
            rms_angle_rad: 1e-3,
        };
        let tmp = tempfile::tempdir().unwrap();
        let text = format!("{}\n{}", good(), estimate.to_toml_flash_section());
        let rig = RigFile::load(&write(tmp.path(), &text)).unwrap();
        assert_eq!(
            rig.flash.map(|f| f.offset_m),
            Some([0.000_1, -0.030_2, 0.001_7])
        );
        assert!(
            RigFile::load(&write(tmp.path(), &good()))
                .unwrap()
                .flash
                .is_none()
        );
    }

    #[test]
    fn errors_name_the_file_and_the_key() {
        let tmp = tempfile::tempdir().unwrap();
        let cases = [
            (
                good().replace("bit_depth = 12", "bit_depth = 11"),
                "sensor.bit_depth",
            ),
            (
                good().replace("192.168.10.2", "camera.local"),
                "sensor.address",
            ),
            (
                good().replace("flash_duration_us = 2000", "flash_duration_us = 9000"),
                "flash outside the exposure",
            ),
            (
                good().replace("photos = 150", "photos = 0"),
                "capture.photos",
            ),
            (good().replace("port = ", "prot = "), "unknown field `prot`"),
            (
                format!("{}\n[flash]\noffset_m = [0.0, nan, 0.0]\n", good()),
                "flash.offset_m",
            ),
            (good().replace("[capture]", "[capture\n"), "rig.toml"),
        ];
        for (text, expected) in cases {
            let p = write(tmp.path(), &text);
            let e = RigFile::load(&p).unwrap_err().to_string();
            assert!(
                e.contains(expected) && e.contains("rig.toml"),
                "{expected}: {e}"
            );
        }
    }
}
