//! A folder of sensor-calibration captures: what `ellipso sim captures` writes (or a
//! user assembles from the rig) and `ellipso calibrate sensor` reads.
//!
//! Contract: the folder holds `captures.json` ([`CaptureSet`]) and the raw frames it names,
//! 16-bit PNGs as a session stores them ([`crate::frame_png`]), paths relative to the folder.
//! Each frame is one of
//! - `dark`: the lens capped, the flash off, at the exposure and gain of the object capture;
//! - `flat`: a uniformly lit, unpolarised diffuse target filling the view (a light panel or an
//!   opal diffuser) at a relative level (exposure time or panel brightness over a reference);
//!   at least two frames per level, several levels (photon transfer);
//! - `polariser`: the same target seen through a linear polariser sheet in front of the lens,
//!   its transmission axis at `polariser_deg` (from image-right toward image-up, the analyser
//!   convention of `docs/polar.md`), at least four angles.
//!
//! The camera block (intrinsics of the lens, from `ellipso calibrate`) lets the vignetting be
//! modelled as a function of the field angle. [`CaptureSet::read`] checks every field and names
//! it; a frame is read with [`crate::frame_png::read`] and checked against the sensor block.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use ellipso_model::camera::CameraModel;

use crate::manifest::SensorInfo;

/// The manifest's file name inside a captures folder.
pub const MANIFEST: &str = "captures.json";
/// The format name written in every manifest.
pub const FORMAT: &str = "ellipso-calibration-captures";
/// The format version this build reads and writes.
pub const VERSION: u32 = 1;

/// What one frame shows.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum CaptureKind {
    /// No light.
    Dark,
    /// Unpolarised uniform target at `level_rel`.
    Flat {
        /// Relative light level (exposure × brightness over the reference), > 0.
        level_rel: f64,
    },
    /// Uniform target through a linear polariser sheet at `polariser_deg`.
    Polariser {
        /// The sheet's transmission axis, degrees.
        polariser_deg: f64,
    },
}

/// One frame of the set (unknown fields are not refused here: serde cannot refuse them
/// through the flattened `kind`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CaptureFrame {
    /// PNG file, relative to the folder.
    pub file: String,
    /// What it shows.
    #[serde(flatten)]
    pub kind: CaptureKind,
}

/// `captures.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CaptureSet {
    /// Always [`FORMAT`].
    pub format: String,
    /// Always [`VERSION`].
    pub version: u32,
    /// The sensor every frame was taken with.
    pub sensor: SensorInfo,
    /// Camera gain during the captures, dB.
    pub gain_db: f64,
    /// The lens: intrinsics and distortion (`ellipso calibrate`'s result), for the field
    /// angle of each pixel.
    pub camera: CameraModel,
    /// Where the captures came from (a scene, a camera), in words.
    pub source: String,
    /// The frames.
    pub frames: Vec<CaptureFrame>,
}

/// Why a captures folder cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum CapturesError {
    /// The manifest cannot be read.
    #[error("{path}: {source}")]
    Io {
        /// The manifest.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// A field is wrong.
    #[error("{path}: {field}: {what}")]
    Field {
        /// The manifest.
        path: PathBuf,
        /// The field.
        field: String,
        /// What is wrong.
        what: String,
    },
}

impl CaptureSet {
    /// Reads and checks `dir/captures.json`.
    pub fn read(dir: &Path) -> Result<CaptureSet, CapturesError> {
        let path = dir.join(MANIFEST);
        let io = |source| CapturesError::Io {
            path: path.clone(),
            source,
        };
        ellipso_model::file_io::check_regular(&path, ellipso_model::file_io::caps::MANIFEST)
            .map_err(io)?;
        let text = std::fs::read_to_string(&path).map_err(io)?;
        let set: CaptureSet = serde_json::from_str(&text).map_err(|e| CapturesError::Field {
            path: path.clone(),
            field: "captures.json".into(),
            what: e.to_string(),
        })?;
        set.check()
            .map_err(|(field, what)| CapturesError::Field { path, field, what })?;
        Ok(set)
    }

    /// Checks format, version, sensor, camera and frames; `Err((field, what))`.
    pub fn check(&self) -> Result<(), (String, String)> {
        if self.format != FORMAT {
            return Err((
                "format".into(),
                format!("'{}' is not '{FORMAT}'", self.format),
            ));
        }
        if self.version != VERSION {
            return Err((
                "version".into(),
                format!("{}: this build reads version {VERSION}", self.version),
            ));
        }
        self.sensor.check().map_err(|(f, w)| (f.to_string(), w))?;
        self.camera
            .validate()
            .map_err(|e| ("camera".to_string(), e.to_string()))?;
        if (self.camera.width, self.camera.height) != (self.sensor.width, self.sensor.height) {
            return Err((
                "camera".into(),
                format!(
                    "{}×{} px, the sensor is {}×{}",
                    self.camera.width, self.camera.height, self.sensor.width, self.sensor.height
                ),
            ));
        }
        if !self.gain_db.is_finite() {
            return Err(("gain_db".into(), "not finite".into()));
        }
        for (i, f) in self.frames.iter().enumerate() {
            let field = format!("frames[{i}]");
            if f.file.is_empty() || Path::new(&f.file).is_absolute() || f.file.contains("..") {
                return Err((
                    field,
                    format!("file '{}' must be inside the folder", f.file),
                ));
            }
            match f.kind {
                CaptureKind::Flat { level_rel } if !(level_rel.is_finite() && level_rel > 0.0) => {
                    return Err((field, format!("level_rel {level_rel} must be > 0")));
                }
                CaptureKind::Polariser { polariser_deg } if !polariser_deg.is_finite() => {
                    return Err((field, "polariser_deg is not finite".into()));
                }
                _ => {}
            }
        }
        Ok(())
    }

    /// Writes the manifest into `dir` (the frames are the caller's).
    pub fn write(&self, dir: &Path) -> std::io::Result<()> {
        let text = serde_json::to_string_pretty(self).map_err(std::io::Error::other)?;
        std::fs::write(dir.join(MANIFEST), text + "\n")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ellipso_model::mosaic::SensorLayout;

    fn set() -> CaptureSet {
        CaptureSet {
            format: FORMAT.into(),
            version: VERSION,
            sensor: SensorInfo {
                layout: SensorLayout::MonoPolar,
                width: 8,
                height: 8,
                bit_depth: 12,
            },
            gain_db: 0.0,
            camera: CameraModel {
                width: 8,
                height: 8,
                intrinsics: ellipso_model::camera::Intrinsics {
                    fx: 10.0,
                    fy: 10.0,
                    cx: 3.5,
                    cy: 3.5,
                },
                distortion: Default::default(),
            },
            source: "test".into(),
            frames: vec![
                CaptureFrame {
                    file: "dark_000.png".into(),
                    kind: CaptureKind::Dark,
                },
                CaptureFrame {
                    file: "pol_000.png".into(),
                    kind: CaptureKind::Polariser {
                        polariser_deg: 45.0,
                    },
                },
            ],
        }
    }

    #[test]
    fn manifest_round_trips_and_bad_fields_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let s = set();
        s.write(dir.path()).unwrap();
        assert_eq!(CaptureSet::read(dir.path()).unwrap(), s);
        let text = std::fs::read_to_string(dir.path().join(MANIFEST)).unwrap();
        assert!(text.contains("\"kind\": \"polariser\""), "{text}");
        let mut bad = set();
        bad.frames[0].file = "../x.png".into();
        bad.write(dir.path()).unwrap();
        let e = CaptureSet::read(dir.path()).unwrap_err().to_string();
        assert!(
            e.contains("frames[0]") && e.contains("inside the folder"),
            "{e}"
        );
        let mut bad = set();
        bad.version = 9;
        bad.write(dir.path()).unwrap();
        let e = CaptureSet::read(dir.path()).unwrap_err().to_string();
        assert!(e.contains("version"), "{e}");
    }
}
