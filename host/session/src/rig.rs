//! The rig section of a session's manifest (`manifest.rig`): the camera model the capture used
//! and the flash as configured; and the sensor layout the manifest names.
//!
//! Contract: [`RigRecord`] is what `ellipso capture` writes and every later stage (tracking,
//! calibration, the fit) reads; [`layout_of`] reads the layout under either spelling older
//! captures wrote (`mono_polar` from the camera backends, `monopolar` from the simulator).

use ellipso_model::camera::CameraModel;
use ellipso_model::mosaic::SensorLayout;

use crate::manifest::Manifest;

/// The rig section a capture records in `manifest.rig`.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct RigRecord {
    /// The camera model (full raw resolution).
    pub camera: CameraModel,
    /// The flash as configured (position relative to the camera, polariser, profile).
    #[serde(default)]
    pub flash: serde_json::Value,
}

/// A manifest whose sensor layout names no known layout.
#[derive(Debug, thiserror::Error)]
#[error("{}: sensor layout '{name}': {reason}", crate::paths::MANIFEST)]
pub struct LayoutError {
    /// The name the manifest gives.
    pub name: String,
    /// Why it was not understood.
    pub reason: String,
}

/// The sensor layout named in a manifest.
pub fn layout_of(manifest: &Manifest) -> Result<SensorLayout, LayoutError> {
    // `mono_polar` (camera backends) and `monopolar` (the simulator) name the same layout
    let name = manifest.sensor.layout.replace('_', "");
    serde_json::from_value(serde_json::Value::String(name)).map_err(|e| LayoutError {
        name: manifest.sensor.layout.clone(),
        reason: e.to_string(),
    })
}
