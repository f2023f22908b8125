//! The rig section of a session's manifest (`manifest.rig`): everything later stages need to
//! know about the rig that took the frames — the camera model, the flash, and for the fit the
//! radiometry, the sensor noise and the analysers' extinction — so that a recorded session
//! stands on its own: no stage re-opens the scene or rig file it was captured from.
//!
//! Contract:
//! - [`RigRecord`] is written once, by the capture (from the scene for a simulated capture, from
//!   the rig file for a hardware one), and read once, when the manifest is opened
//!   ([`crate::reader::open`]); every later stage reads the typed record.
//! - Completeness: a hardware or replayed session is complete with its camera and flash (its
//!   radiometry is relative, its noise the fit's documented default). A simulator session also
//!   needs its absolute radiometry and noise; sessions recorded before they were written lack
//!   them, and [`Manifest::fit_inputs`](crate::manifest::Manifest::fit_inputs) then refuses with
//!   [`RigError::NeedsUpgrade`], which names `ellipso session upgrade`.
//! - The sensor layout is [`crate::manifest::SensorInfo::layout`], a typed
//!   [`SensorLayout`](ellipso_model::mosaic::SensorLayout) written as `mono_polar` /
//!   `colour_polar`; the simulator's older `monopolar` / `colourpolar` are still read.

use ellipso_model::camera::CameraModel;
use ellipso_model::radiometry::{CameraRadiometry, SensorNoiseSpec};
use ellipso_model::rig::FlashSpec;

/// Where a session's normaliser gets its absolute scale from.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum RadiometryRecord {
    /// The renderer's camera equation with these parameters (simulator sessions); each frame's
    /// exposure and gain come from its own record.
    Absolute(CameraRadiometry),
    /// No absolute calibration (hardware sessions): the fit's documented relative normaliser.
    Relative,
}

/// The rig section a capture records in `manifest.rig`.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RigRecord {
    /// The camera model (full raw resolution).
    #[serde(deserialize_with = "named::camera")]
    pub camera: CameraModel,
    /// The flash as configured (position relative to the camera, polariser, intensity,
    /// profile); `None` when the rig's flash was never measured.
    #[serde(default, deserialize_with = "named::flash")]
    pub flash: Option<FlashSpec>,
    /// The radiometry of the frames; absent in sessions recorded before it was written.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radiometry: Option<RadiometryRecord>,
    /// The sensor's noise as characterised (simulator sessions); `None`: unknown, the fit
    /// weights by its documented default.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub noise: Option<SensorNoiseSpec>,
    /// Extinction ratio of the on-chip analysers where known (`None`: ideal analysers).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub analyser_extinction_ratio: Option<f64>,
    /// The sensor calibration the rig file named when the frames were taken (`None`: none;
    /// the fit then assumes an ideal sensor and says so for a hardware session).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensor_calibration: Option<SensorCalibrationRef>,
}

/// Which sensor calibration file a session's frames were taken with: its identity (the CRC-64
/// the file carries, 16 hex digits) and where it was when the capture read it.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorCalibrationRef {
    /// The file's identity (`ellipso calibrate sensor` prints it).
    pub id: String,
    /// The file, as the capture resolved it (absolute where the rig file's path was).
    pub file: std::path::PathBuf,
}

/// Field readers whose errors name the manifest key (serde's own name only the type).
mod named {
    use ellipso_model::camera::CameraModel;
    use ellipso_model::rig::FlashSpec;
    use serde::de::Error;
    use serde::{Deserialize, Deserializer};

    pub fn camera<'de, D: Deserializer<'de>>(d: D) -> Result<CameraModel, D::Error> {
        CameraModel::deserialize(d).map_err(|e| D::Error::custom(format!("rig.camera: {e}")))
    }

    pub fn flash<'de, D: Deserializer<'de>>(d: D) -> Result<Option<FlashSpec>, D::Error> {
        Option::<FlashSpec>::deserialize(d).map_err(|e| D::Error::custom(format!("rig.flash: {e}")))
    }
}

impl RigRecord {
    /// A record of a rig without absolute radiometry (hardware capture): camera and flash,
    /// relative radiometry, unknown noise, ideal analysers.
    pub fn relative(camera: CameraModel, flash: Option<FlashSpec>) -> Self {
        Self {
            camera,
            flash,
            radiometry: Some(RadiometryRecord::Relative),
            noise: None,
            analyser_extinction_ratio: None,
            sensor_calibration: None,
        }
    }
}

/// What the fit reads of a session's rig, complete (see
/// [`Manifest::fit_inputs`](crate::manifest::Manifest::fit_inputs)).
#[derive(Debug, Clone, PartialEq)]
pub struct FitInputs {
    /// The flash.
    pub flash: FlashSpec,
    /// Absolute or relative radiometry.
    pub radiometry: RadiometryRecord,
    /// The sensor noise, where known.
    pub noise: Option<SensorNoiseSpec>,
    /// Extinction ratio of the analysers, where known.
    pub analyser_extinction_ratio: Option<f64>,
}

/// Why a session's rig record cannot serve the fit.
#[derive(Debug, thiserror::Error)]
pub enum RigError {
    /// The manifest records no rig at all.
    #[error(
        "{}: no `rig` recorded (camera model and flash)",
        crate::paths::MANIFEST
    )]
    Missing,
    /// The manifest records no flash.
    #[error(
        "{}: `rig.flash` is not recorded: the fit needs the flash position (run `ellipso \
         calibrate --sphere` on the rig, then capture again)",
        crate::paths::MANIFEST
    )]
    MissingFlash,
    /// A simulator session recorded before the radiometry and noise were written.
    #[error(
        "{}: this simulator session was recorded before sessions carried their radiometry and \
         sensor noise; run `ellipso session upgrade {dir}` once to add them from its scene file",
        crate::paths::MANIFEST
    )]
    NeedsUpgrade {
        /// The session directory, as the command needs it.
        dir: String,
    },
    /// A value outside its physical range ([`crate::rig_ranges`]).
    #[error("{manifest}: {0}", manifest = crate::paths::MANIFEST)]
    OutOfRange(#[from] RangeError),
}

/// A rig value outside its physical range.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("`{key}` = {value} is outside its physical range ({range})")]
pub struct RangeError {
    /// The manifest key, e.g. `rig.noise.read_noise_e`.
    pub key: String,
    /// The value as recorded.
    pub value: String,
    /// The range, in words with units.
    pub range: &'static str,
}

/// What tracking needs of a board — its tag corners and its place in the world — in the form a
/// session manifest records (`boards`), so a recorded session can be tracked without its scene.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TrackedBoard {
    /// Board name, if any.
    #[serde(default)]
    pub name: Option<String>,
    /// Tag family (`tag36h11`, `tag25h9`, `tag16h5`); sessions written before it was recorded
    /// used tag36h11, the only family tracked then.
    #[serde(default = "default_family")]
    pub family: String,
    /// Tag id → its four corners in the board frame, metres, AprilTag detection order.
    pub corners_board_m: std::collections::BTreeMap<u32, [[f64; 3]; 4]>,
    /// Board origin in the world, metres.
    pub world_from_board_translation_m: [f64; 3],
    /// Board rotation into the world, axis-angle, radians.
    pub world_from_board_rotation: [f64; 3],
}

fn default_family() -> String {
    "tag36h11".into()
}

impl TrackedBoard {
    /// The record of a board placed in the world (a scene's or a rig file's).
    pub fn from_placed(placed: &ellipso_model::tags::PlacedBoard) -> Self {
        let corners_board_m = placed
            .board
            .tags
            .iter()
            .map(|t| (t.id, t.corners_board_m.map(|p| [p.x, p.y, p.z])))
            .collect();
        let t = placed.world_from_board.translation.vector;
        let r = placed.world_from_board.rotation.scaled_axis();
        Self {
            name: placed.board.name.clone(),
            family: placed.board.family.name().to_string(),
            corners_board_m,
            world_from_board_translation_m: [t.x, t.y, t.z],
            world_from_board_rotation: [r.x, r.y, r.z],
        }
    }

    /// Board frame → world frame.
    pub fn world_from_board(&self) -> nalgebra::Isometry3<f64> {
        let [tx, ty, tz] = self.world_from_board_translation_m;
        let [rx, ry, rz] = self.world_from_board_rotation;
        nalgebra::Isometry3::from_parts(
            nalgebra::Translation3::new(tx, ty, tz),
            nalgebra::UnitQuaternion::from_scaled_axis(nalgebra::Vector3::new(rx, ry, rz)),
        )
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::manifest::{Manifest, SensorInfo, SessionSource};
    use ellipso_model::camera::Intrinsics;
    use ellipso_model::mosaic::SensorLayout;

    /// A small pinhole camera for the tests' manifests.
    pub(crate) fn camera() -> CameraModel {
        CameraModel::pinhole(
            8,
            6,
            Intrinsics {
                fx: 10.0,
                fy: 10.0,
                cx: 4.0,
                cy: 3.0,
            },
        )
    }

    fn manifest(source: SessionSource, rig: RigRecord) -> Manifest {
        let sensor = SensorInfo {
            layout: SensorLayout::MonoPolar,
            width: 8,
            height: 6,
            bit_depth: 12,
        };
        let mut m = Manifest::new(source, sensor, 1);
        m.rig = Some(rig);
        m
    }

    fn simulator() -> SessionSource {
        SessionSource::Simulator {
            scene: "sphere.toml".into(),
            seed: 7,
        }
    }

    pub(crate) fn complete() -> RigRecord {
        RigRecord {
            camera: camera(),
            flash: Some(FlashSpec::default()),
            radiometry: Some(RadiometryRecord::Absolute(CameraRadiometry {
                f_number: 5.6,
                quantum_efficiency: 0.6,
                pixel_pitch_um: 3.45,
                full_well_e: 10_500.0,
                bit_depth: 12,
                vignetting_exponent: Some(4.0),
            })),
            noise: Some(SensorNoiseSpec {
                read_noise_e: 2.3,
                shot_noise: true,
                quantised: true,
                gain_db: 0.0,
                full_well_e: 10_500.0,
                bit_depth: 12,
            }),
            analyser_extinction_ratio: Some(200.0),
            sensor_calibration: None,
        }
    }

    /// `m` as a session recorded before the radiometry was written: `rig` without
    /// `radiometry`, `noise`, `analyser_extinction_ratio`, and the old `calibration: null`.
    fn old_form(m: &Manifest) -> String {
        let mut v = serde_json::to_value(m).unwrap();
        for key in ["radiometry", "noise", "analyser_extinction_ratio"] {
            v["rig"].as_object_mut().unwrap().remove(key);
        }
        v["calibration"] = serde_json::Value::Null;
        v["sensor"]["layout"] = "monopolar".into();
        serde_json::to_string_pretty(&v).unwrap()
    }

    #[test]
    fn a_complete_record_round_trips_and_serves_the_fit() {
        let m = manifest(simulator(), complete());
        let text = serde_json::to_string(&m).unwrap();
        assert!(text.contains("\"layout\":\"mono_polar\""), "{text}");
        let back: Manifest = serde_json::from_str(&text).unwrap();
        assert_eq!(back, m);
        let inputs = back.fit_inputs(std::path::Path::new("s")).unwrap();
        assert_eq!(inputs.radiometry, complete().radiometry.unwrap());
        assert_eq!(inputs.noise, complete().noise);
        assert_eq!(inputs.analyser_extinction_ratio, Some(200.0));
    }

    #[test]
    fn an_old_simulator_manifest_opens_and_the_fit_is_told_to_upgrade_it() {
        let m = manifest(simulator(), complete());
        let old: Manifest = serde_json::from_str(&old_form(&m)).unwrap();
        assert_eq!(old.sensor.layout, SensorLayout::MonoPolar);
        let rig = old.rig.as_ref().unwrap();
        assert_eq!((rig.radiometry.as_ref(), rig.noise.as_ref()), (None, None));
        let e = old
            .fit_inputs(std::path::Path::new("/data/s1"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("ellipso session upgrade /data/s1"), "{e}");
    }

    #[test]
    fn an_old_hardware_manifest_is_complete_with_relative_radiometry() {
        let source = SessionSource::Hardware {
            trigger_port: "/dev/ttyACM0".into(),
            camera: "aravis:1".into(),
        };
        let m = manifest(source, RigRecord::relative(camera(), None));
        let mut v: serde_json::Value = serde_json::from_str(&old_form(&m)).unwrap();
        // the hardware capture recorded only the measured flash offset
        v["rig"]["flash"] = serde_json::json!({ "offset_m": [0.01, -0.02, 0.0] });
        let old: Manifest = serde_json::from_value(v).unwrap();
        let inputs = old.fit_inputs(std::path::Path::new("s")).unwrap();
        assert_eq!(inputs.radiometry, RadiometryRecord::Relative);
        assert_eq!(inputs.flash.offset_m, [0.01, -0.02, 0.0]);
        assert_eq!(inputs.flash.radiant_intensity_w_per_sr, 0.5);
        assert!(inputs.noise.is_none());
        // without a flash the fit is told how to get one
        let mut no_flash = old.clone();
        no_flash.rig.as_mut().unwrap().flash = None;
        let e = no_flash.fit_inputs(std::path::Path::new("s")).unwrap_err();
        assert!(matches!(e, RigError::MissingFlash), "{e}");
    }
}
