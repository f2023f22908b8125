//! Ground truth written beside each rendered frame: per frame the camera pose, flash position
//! and trigger time ([`FrameTruth`]); on request per pixel the world normal, depth and material
//! ([`PixelTruth`]).
//!
//! Contract: the pose is the mid-exposure pose (the one the capture path lists; motion blur
//! samples symmetrically around it). Per-pixel truth comes from the ray through each raw pixel's
//! centre at that pose. Depth is the camera-frame z of the hit (metres along the optical axis),
//! `NaN` where nothing is hit. Material codes: scene material index for objects (a blend reports
//! its heaviest material), [`BOARD_MATERIAL_BASE`] + board index for boards,
//! [`NO_HIT_MATERIAL`] for background.

use crate::scene::{CameraPose, MaterialSample, Scene, SurfaceKind};
use ellipso_model::camera::CameraModel;
use nalgebra::Isometry3;
use serde::{Serialize, Serializer};

/// Material code of board `i`: `BOARD_MATERIAL_BASE + i`.
pub const BOARD_MATERIAL_BASE: u16 = 0xF000;
/// Material code where no surface is hit.
pub const NO_HIT_MATERIAL: u16 = 0xFFFF;

/// The JSON form of the camera a frame was rendered with ([`FrameTruth::camera`]): the truth
/// file's keys and layout, written from the shared [`CameraModel`].
#[derive(Serialize)]
struct CameraTruthJson {
    /// Width, pixels.
    width: u32,
    /// Height, pixels.
    height: u32,
    /// Focal lengths and principal point, pixels (OpenCV convention).
    fx_px: f64,
    fy_px: f64,
    cx_px: f64,
    cy_px: f64,
    /// Brown–Conrady coefficients `[k1, k2, p1, p2, k3]` (OpenCV order).
    distortion: [f64; 5],
}

impl From<&CameraModel> for CameraTruthJson {
    fn from(m: &CameraModel) -> Self {
        let d = m.distortion;
        Self {
            width: m.width,
            height: m.height,
            fx_px: m.intrinsics.fx,
            fy_px: m.intrinsics.fy,
            cx_px: m.intrinsics.cx,
            cy_px: m.intrinsics.cy,
            distortion: [d.k1, d.k2, d.p1, d.p2, d.k3],
        }
    }
}

/// Serialises [`FrameTruth::camera`] in its JSON form.
fn serialize_camera<S: Serializer>(camera: &CameraModel, s: S) -> Result<S::Ok, S::Error> {
    CameraTruthJson::from(camera).serialize(s)
}

/// Per-frame ground truth.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FrameTruth {
    /// Frame (pose) index.
    pub index: u32,
    /// Nominal trigger time, µs from the first trigger.
    pub t_trigger_us: u64,
    /// Rotation of `world_from_camera` (OpenCV camera: x right, y down, z forward), row-major.
    pub world_from_camera_rotation: [[f64; 3]; 3],
    /// Translation of `world_from_camera` (the camera centre in the world), metres.
    pub world_from_camera_translation_m: [f64; 3],
    /// The same rotation as a unit quaternion `[w, x, y, z]`.
    pub world_from_camera_quaternion_wxyz: [f64; 4],
    /// Flash position, world, metres.
    pub flash_position_world_m: [f64; 3],
    /// Flash polariser transmission axis, world (absent for an unpolarised flash).
    pub flash_polariser_axis_world: Option<[f64; 3]>,
    /// Camera the frame was rendered with (after any resolution override); written as `width`,
    /// `height`, `fx_px`, `fy_px`, `cx_px`, `cy_px` and `distortion: [k1, k2, p1, p2, k3]`.
    #[serde(serialize_with = "serialize_camera")]
    pub camera: CameraModel,
    /// Seed of this frame's noise streams.
    pub noise_seed: u64,
}

impl FrameTruth {
    /// Truth of `pose` in `scene`.
    pub fn new(scene: &Scene, pose: &CameraPose, camera: &CameraModel, noise_seed: u64) -> Self {
        let w: &Isometry3<f64> = &pose.world_from_camera;
        let r = w.rotation.to_rotation_matrix();
        let m = r.matrix();
        let q = w.rotation.quaternion();
        let flash = &scene.rig.flash;
        Self {
            index: pose.index,
            t_trigger_us: pose.t_trigger_us,
            world_from_camera_rotation: core::array::from_fn(|i| {
                core::array::from_fn(|j| m[(i, j)])
            }),
            world_from_camera_translation_m: w.translation.vector.into(),
            world_from_camera_quaternion_wxyz: [q.w, q.i, q.j, q.k],
            flash_position_world_m: flash.position_world(w).coords.into(),
            flash_polariser_axis_world: flash
                .polariser_axis_world(w)
                .map(|a| a.into_inner().into()),
            camera: *camera,
            noise_seed,
        }
    }
}

/// Per-pixel ground truth, row-major, one entry per raw pixel.
#[derive(Clone, Debug, PartialEq)]
pub struct PixelTruth {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// Shading normal, world frame (zero where nothing is hit).
    pub normal_world: Vec<[f32; 3]>,
    /// Camera-frame depth z, metres (`NaN` where nothing is hit).
    pub depth_m: Vec<f32>,
    /// Material code (see the module doc).
    pub material: Vec<u16>,
}

/// The material code of a hit.
pub fn material_code(kind: &SurfaceKind) -> u16 {
    match kind {
        SurfaceKind::Board { index, .. } => {
            BOARD_MATERIAL_BASE.saturating_add(u16::try_from(*index).unwrap_or(u16::MAX))
        }
        SurfaceKind::Object { material, .. } => {
            let id = match material {
                MaterialSample::Uniform(id) => *id,
                MaterialSample::Blend(items) => {
                    items
                        .iter()
                        .copied()
                        .fold((0, f64::NEG_INFINITY), |best, (id, w)| {
                            if w > best.1 { (id, w) } else { best }
                        })
                        .0
                }
            };
            u16::try_from(id).unwrap_or(NO_HIT_MATERIAL - 1)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ellipso_model::camera::{Distortion, Intrinsics};

    #[test]
    fn the_camera_is_written_in_the_truth_files_keys_and_order() {
        let camera = CameraModel {
            width: 64,
            height: 48,
            intrinsics: Intrinsics {
                fx: 100.0,
                fy: 101.0,
                cx: 31.5,
                cy: 23.5,
            },
            distortion: Distortion {
                k1: 0.1,
                k2: 0.2,
                k3: 0.3,
                p1: 0.4,
                p2: 0.5,
            },
        };
        let truth = FrameTruth {
            index: 3,
            t_trigger_us: 7,
            world_from_camera_rotation: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            world_from_camera_translation_m: [0.0; 3],
            world_from_camera_quaternion_wxyz: [1.0, 0.0, 0.0, 0.0],
            flash_position_world_m: [0.0; 3],
            flash_polariser_axis_world: None,
            camera,
            noise_seed: 9,
        };
        let json = serde_json::to_string(&truth).expect("serialises");
        assert!(
            json.contains(
                r#""camera":{"width":64,"height":48,"fx_px":100.0,"fy_px":101.0,"cx_px":31.5,"cy_px":23.5,"distortion":[0.1,0.2,0.4,0.5,0.3]},"noise_seed":9}"#
            ),
            "{json}"
        );
    }
}
