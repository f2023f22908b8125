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
//! calibration = "camera.senscal" # optional; `ellipso calibrate sensor` writes it
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
//! [flash]                        # optional; as `ellipso calibrate flash` writes it
//! offset_m = [0.0, -0.03, 0.0]   # flash position in the camera frame (x right, y down, z forward)
//! polariser_deg = 0.0            # optional (0): flash polariser axis, from camera x towards y
//!
//! [[boards]]
//! file = "boards/base_a4.toml"   # relative to this rig file
//! translation_m = [0.0, 0.0, 0.0]
//! rotation_deg = [0.0, 0.0, 0.0] # world from board, XYZ Euler angles
//! ```
//!
//! Unknown keys are refused; every error names the file, the key and, for syntax errors, the line.
//! The file is checked whole before anything looks for the camera backend or opens a port:
//! `sensor.gain_db` in [`GAIN_MIN_DB`, `GAIN_MAX_DB`]; the camera's sides even in
//! 2..=`MAX_SIDE_PX` and its parameters plausible (`CameraModel::check_plausible`);
//! `capture.interval_ms` within the board's u32 µs frame period; the flash delay plus duration
//! inside the exposure (summed without wrapping); the flash within 1 m of the lens; each board's
//! translation finite and within ±`BOARD_MAX_M`, its angles finite and within ±360°; an aravis
//! address one camera's (not unspecified, broadcast or multicast); the trigger port a serial
//! device, a pty or `unix:PATH` (a device the kernel does not class as a tty, such as
//! `/dev/zero`, is refused).

use std::path::{Path, PathBuf};

use ellipso_model::camera::CameraModel;
use ellipso_model::mosaic::SensorLayout;
use ellipso_model::tags::PlacedBoard;
use ellipso_protocol::{CaptureConfig, PulseCount, TriggerSource};
use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use serde::Deserialize;

use ellipso_session::rig::{SensorCalibrationRef, TrackedBoard};

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
    /// Sensor calibration file (`ellipso calibrate sensor`), relative to this rig file; its
    /// identity is recorded in every session and the frames are read with it.
    #[serde(default)]
    pub calibration: Option<PathBuf>,
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
    /// The flash polariser's transmission axis, degrees from camera x towards camera y (image
    /// down); absent: 0, parallel to the sensor's 0° analyser.
    #[serde(default)]
    pub polariser_deg: Option<f64>,
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

/// Lowest sensor gain, dB (the bound the fit puts on a frame's gain).
pub const GAIN_MIN_DB: f32 = -20.0;
/// Highest sensor gain, dB (the IMX250's analogue and digital gain together reach 48 dB).
pub const GAIN_MAX_DB: f32 = 60.0;
/// Farthest a board may be placed from the world origin, m (the bound the fit puts on cameras).
pub const BOARD_MAX_M: f64 = 100.0;
use ellipso_model::rig::MAX_SIDE_PX;

/// Whether `ip` can be one camera's address.
fn unicast(ip: std::net::IpAddr) -> bool {
    match ip {
        std::net::IpAddr::V4(v4) => {
            !(v4.is_unspecified() || v4.is_broadcast() || v4.is_multicast())
        }
        std::net::IpAddr::V6(v6) => !(v6.is_unspecified() || v6.is_multicast()),
    }
}

/// Refuses a trigger port that cannot be the trigger board: an existing path that is not a
/// character device, or a character device the kernel does not class as a tty (`/dev/zero`,
/// `/dev/null`: `/sys/dev/char/MAJOR:MINOR/subsystem` names another class). A path that does not
/// exist yet (a board not plugged in) is left to the open, which names it.
fn check_trigger_port(port: &str) -> Result<(), String> {
    use std::os::unix::fs::FileTypeExt;
    if port.starts_with("unix:") {
        return Ok(());
    }
    let Ok(meta) = std::fs::metadata(port) else {
        return Ok(());
    };
    if !meta.file_type().is_char_device() {
        return Err(format!(
            "'{port}' is not a serial device (a tty, a pty, or unix:PATH for a socket)"
        ));
    }
    use std::os::unix::fs::MetadataExt;
    let rdev = meta.rdev();
    let (major, minor) = (libc_major(rdev), libc_minor(rdev));
    let class = std::fs::read_link(format!("/sys/dev/char/{major}:{minor}/subsystem"))
        .ok()
        .and_then(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()));
    match class {
        Some(c) if c != "tty" => Err(format!(
            "'{port}' is a `{c}` device, not a serial port: give the trigger board's tty \
             (e.g. /dev/ttyACM0)"
        )),
        _ => Ok(()),
    }
}

/// The major number of a Linux device id (glibc's `gnu_dev_major`).
fn libc_major(dev: u64) -> u64 {
    ((dev >> 32) & 0xffff_f000) | ((dev >> 8) & 0x0000_0fff)
}

/// The minor number of a Linux device id (glibc's `gnu_dev_minor`).
fn libc_minor(dev: u64) -> u64 {
    ((dev >> 12) & 0xffff_ff00) | (dev & 0x0000_00ff)
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
        // in u64: a delay near u32::MAX plus a short duration must not wrap past the check
        if u64::from(self.capture.flash_delay_us) + u64::from(self.capture.flash_duration_us)
            > u64::from(self.sensor.exposure_us)
        {
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
        if self.sensor.backend == Backend::Aravis {
            match self.sensor.address.parse::<std::net::IpAddr>() {
                Err(_) => {
                    return Err(bad(
                        "sensor.address",
                        format!(
                            "'{}' is not a numeric IP address (names would trigger network \
                             discovery)",
                            self.sensor.address
                        ),
                    ));
                }
                Ok(ip) if !unicast(ip) => {
                    return Err(bad(
                        "sensor.address",
                        format!(
                            "{ip} is not one camera's address (unspecified, broadcast or \
                             multicast): give the camera's own IP address"
                        ),
                    ));
                }
                Ok(_) => {}
            }
        }
        self.check_ranges()?;
        check_trigger_port(&self.trigger.port).map_err(|m| bad("trigger.port", m))
    }

    /// The values of physical quantities against their ranges (module doc).
    fn check_ranges(&self) -> Result<(), RigFileError> {
        let bad = |key: &str, message: String| RigFileError::Invalid {
            path: self.path.clone(),
            key: key.into(),
            message,
        };
        let g = self.sensor.gain_db;
        if !(g.is_finite() && (GAIN_MIN_DB..=GAIN_MAX_DB).contains(&g)) {
            return Err(bad(
                "sensor.gain_db",
                format!("is {g}; must be within [{GAIN_MIN_DB}, {GAIN_MAX_DB}] dB"),
            ));
        }
        // The camera section is optional until `calibrate` fills it (docs/rig-file.md).
        if let Some(c) = &self.camera {
            for (key, side) in [("camera.width", c.width), ("camera.height", c.height)] {
                if side < 2 || side % 2 != 0 || side > MAX_SIDE_PX {
                    return Err(bad(
                        key,
                        format!(
                            "is {side}; must be even (the 2×2 polariser mosaic) and in \
                             2..={MAX_SIDE_PX} px"
                        ),
                    ));
                }
            }
            if let Err(m) = c.check_plausible() {
                let key = ["fx", "fy", "cx", "cy", "k1", "k2", "k3", "p1", "p2"]
                    .into_iter()
                    .find(|k| m.starts_with(&format!("{k} ")) || m.contains(&format!("`{k}`")))
                    .unwrap_or("camera");
                let key = if key == "camera" {
                    key.to_string()
                } else {
                    format!("camera.{key}")
                };
                return Err(bad(&key, m));
            }
        }
        let max_interval_ms = f64::from(u32::MAX) / 1e3;
        if self.capture.interval_ms > max_interval_ms {
            return Err(bad(
                "capture.interval_ms",
                format!(
                    "is {}; the board's frame period is at most {max_interval_ms} ms (u32 µs)",
                    self.capture.interval_ms
                ),
            ));
        }
        if let Some(f) = &self.flash {
            if let Some(deg) = f.polariser_deg
                && !(deg.is_finite() && deg.abs() <= 180.0)
            {
                return Err(bad(
                    "flash.polariser_deg",
                    format!("is {deg}; an axis angle is finite, within ±180°"),
                ));
            }
            let d = nalgebra::Vector3::from(f.offset_m).norm();
            if d > ellipso_session::rig_ranges::MAX_FLASH_OFFSET_M {
                return Err(bad(
                    "flash.offset_m",
                    format!(
                        "{:?} is {d:e} m from the lens; a flash mounted on the camera is within \
                         {} m",
                        f.offset_m,
                        ellipso_session::rig_ranges::MAX_FLASH_OFFSET_M
                    ),
                ));
            }
        }
        for (i, b) in self.boards.iter().enumerate() {
            if !b
                .translation_m
                .iter()
                .all(|v| v.is_finite() && v.abs() <= BOARD_MAX_M)
            {
                return Err(bad(
                    &format!("boards[{i}].translation_m"),
                    format!(
                        "{:?}: each component must be finite and within ±{BOARD_MAX_M} m",
                        b.translation_m
                    ),
                ));
            }
            if !b
                .rotation_deg
                .iter()
                .all(|v| v.is_finite() && v.abs() <= 360.0)
            {
                return Err(bad(
                    &format!("boards[{i}].rotation_deg"),
                    format!(
                        "{:?}: each angle must be finite and within ±360°",
                        b.rotation_deg
                    ),
                ));
            }
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
    /// The sensor calibration `[sensor] calibration` names, read and checked against the
    /// sensor's layout and the camera model's size: its identity and absolute path (`None`
    /// when none is named).
    pub fn sensor_calibration(&self) -> Result<Option<SensorCalibrationRef>, RigFileError> {
        let Some(file) = &self.sensor.calibration else {
            return Ok(None);
        };
        let base = self.path.parent().unwrap_or(Path::new("."));
        let file = base.join(file);
        let bad = |message: String| RigFileError::Invalid {
            path: self.path.clone(),
            key: "sensor.calibration".into(),
            message,
        };
        let file =
            std::path::absolute(&file).map_err(|e| bad(format!("{}: {e}", file.display())))?;
        let cal = ellipso_polar::sensor_calibration::file::read(&file, None)
            .map_err(|e| bad(e.to_string()))?;
        let s = &cal.header.sensor;
        if s.layout != self.sensor.layout {
            return Err(bad(format!(
                "sensor calibration {} is for a {} sensor, `sensor.layout` is {}",
                cal.id(),
                ellipso_session::manifest::layout_name(s.layout),
                ellipso_session::manifest::layout_name(self.sensor.layout)
            )));
        }
        if let Some(camera) = &self.camera
            && (camera.width, camera.height) != (s.width, s.height)
        {
            return Err(bad(format!(
                "sensor calibration {} is for a {}×{} sensor, [camera] is {}×{}",
                cal.id(),
                s.width,
                s.height,
                camera.width,
                camera.height
            )));
        }
        Ok(Some(SensorCalibrationRef { id: cal.id(), file }))
    }

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
mod tests;
