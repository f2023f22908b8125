//! `manifest.json`: what a session captured, with what, by which software, in which schema.
//!
//! Every section is typed: the sensor ([`SensorInfo`], its layout a
//! [`SensorLayout`]), the rig ([`RigRecord`]: camera, flash, radiometry, noise) and the boards
//! ([`TrackedBoard`]), so a session is self-describing and is parsed in one place, when it is
//! opened. Sections older sessions wrote differently are still read (`docs/session-format.md`).

use ellipso_model::mosaic::SensorLayout;
use serde::{Deserialize, Serialize};

use crate::rig::{FitInputs, RadiometryRecord, RigError, RigRecord, TrackedBoard};

/// The sensor layout as a manifest spells it: `mono_polar` / `colour_polar` written; the
/// simulator's older `monopolar` / `colourpolar` also read. An unknown name is refused with
/// the field's name.
mod layout_name {
    use ellipso_model::mosaic::SensorLayout;
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(layout: &SensorLayout, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(name(*layout))
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<SensorLayout, D::Error> {
        let text = String::deserialize(d)?;
        match text.as_str() {
            "mono_polar" | "monopolar" => Ok(SensorLayout::MonoPolar),
            "colour_polar" | "colourpolar" => Ok(SensorLayout::ColourPolar),
            other => Err(serde::de::Error::custom(format!(
                "sensor.layout: '{other}' is not a sensor layout (mono_polar or colour_polar)"
            ))),
        }
    }

    /// The written name of `layout`.
    pub fn name(layout: SensorLayout) -> &'static str {
        match layout {
            SensorLayout::MonoPolar => "mono_polar",
            SensorLayout::ColourPolar => "colour_polar",
        }
    }
}

/// The name a manifest writes for `layout` (`mono_polar`, `colour_polar`).
pub fn layout_name(layout: SensorLayout) -> &'static str {
    layout_name::name(layout)
}

/// How the sensor's raw frames are laid out.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorInfo {
    /// Mosaic layout, written `mono_polar` (IMX250MZR) or `colour_polar` (IMX250MYR).
    #[serde(with = "layout_name")]
    pub layout: SensorLayout,
    /// Frame width, px.
    pub width: u32,
    /// Frame height, px.
    pub height: u32,
    /// Significant bits per pixel (8, 10, 12, 16) in the 16-bit PNG container.
    pub bit_depth: u8,
}

/// Largest frame side a session may record, px (the scene files' limit).
pub const MAX_SIDE_PX: u32 = 16_384;

impl SensorInfo {
    /// Checks the fields against what a raw mosaic frame can be (the layout is checked when
    /// it is parsed): even sides in `2..=16384` (2×2 polariser blocks), 1–16 significant bits in
    /// the 16-bit container. `Err((field, what))` names the field.
    pub fn check(&self) -> Result<(), (&'static str, String)> {
        for (field, v) in [("sensor.width", self.width), ("sensor.height", self.height)] {
            if !(2..=MAX_SIDE_PX).contains(&v) || v % 2 != 0 {
                return Err((
                    field,
                    format!(
                        "{v} px: need an even size in 2..={MAX_SIDE_PX} (2×2 polariser blocks)"
                    ),
                ));
            }
        }
        if !(1..=16).contains(&self.bit_depth) {
            return Err((
                "sensor.bit_depth",
                format!(
                    "{} bits: need 1..=16 significant bits in the 16-bit PNG container",
                    self.bit_depth
                ),
            ));
        }
        Ok(())
    }
}

/// Where the frames came from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum SessionSource {
    /// The simulated rig.
    Simulator {
        /// Scene file as given.
        scene: String,
        /// Seed.
        seed: u64,
    },
    /// The physical rig.
    Hardware {
        /// Trigger board port.
        trigger_port: String,
        /// Camera backend and identifier, e.g. `aravis:127.0.0.1`.
        camera: String,
    },
    /// A replay of another session.
    Replay {
        /// The original session directory.
        original: String,
    },
}

/// How a session ended (absent while capturing, or when killed).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EndRecord {
    /// Wall time at the end, µs since the Unix epoch.
    pub ended_unix_us: u64,
    /// Why it ended: `completed`, `stopped by user`, `trigger link disconnected`, ….
    pub reason: String,
    /// Frames written.
    pub frames: u64,
    /// Frames paired with a pulse.
    pub paired: u64,
}

/// The manifest.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    /// [`SCHEMA_VERSION`](super::SCHEMA_VERSION) of the writer.
    pub schema_version: u32,
    /// Writer software and version, e.g. `ellipso 0.1.0`.
    pub software: String,
    /// Wall time of the host clock's epoch (host times in the log count from it), µs since Unix epoch.
    pub host_epoch_unix_us: u64,
    /// Source of the frames.
    pub source: SessionSource,
    /// Sensor layout of the raw frames.
    pub sensor: SensorInfo,
    /// The rig: camera model, flash, radiometry, noise ([`RigRecord`]); `None` when the
    /// capture recorded none.
    #[serde(default)]
    pub rig: Option<RigRecord>,
    /// AprilTag boards of the capture, as tracking needs them.
    #[serde(default)]
    pub boards: Vec<TrackedBoard>,
    /// Set when the session ended cleanly; absent (not `null`) otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub end: Option<EndRecord>,
}

impl Manifest {
    /// A manifest for a new session written by this build.
    pub fn new(source: SessionSource, sensor: SensorInfo, host_epoch_unix_us: u64) -> Self {
        Self {
            schema_version: super::SCHEMA_VERSION,
            software: format!("ellipso {}", env!("CARGO_PKG_VERSION")),
            host_epoch_unix_us,
            source,
            sensor,
            rig: None,
            boards: Vec::new(),
            end: None,
        }
    }
}

impl Manifest {
    /// What the fit needs of this session's rig: the flash, the radiometry (relative for
    /// hardware and replayed sessions whose record predates it), noise and extinction, each
    /// value checked against its physical range ([`crate::rig_ranges`]).
    /// `dir` is the session directory (named in [`RigError::NeedsUpgrade`]).
    pub fn fit_inputs(&self, dir: &std::path::Path) -> Result<FitInputs, RigError> {
        let rig = self.rig.as_ref().ok_or(RigError::Missing)?;
        let flash = rig.flash.clone().ok_or(RigError::MissingFlash)?;
        crate::rig_ranges::check(rig)?;
        let radiometry = match (&rig.radiometry, &self.source) {
            (Some(r), _) => r.clone(),
            (None, SessionSource::Simulator { .. }) => {
                return Err(RigError::NeedsUpgrade {
                    dir: dir.display().to_string(),
                });
            }
            // the old form of a hardware or replayed session is complete: relative radiometry
            (None, SessionSource::Hardware { .. } | SessionSource::Replay { .. }) => {
                RadiometryRecord::Relative
            }
        };
        Ok(FitInputs {
            flash,
            radiometry,
            noise: rig.noise.clone(),
            analyser_extinction_ratio: rig.analyser_extinction_ratio,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn manifests_name_layouts_as_the_session_format_does() {
        assert_eq!(layout_name(SensorLayout::MonoPolar), "mono_polar");
        assert_eq!(layout_name(SensorLayout::ColourPolar), "colour_polar");
    }
}
