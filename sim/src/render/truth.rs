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
use serde::Serialize;

/// Material code of board `i`: `BOARD_MATERIAL_BASE + i`.
pub const BOARD_MATERIAL_BASE: u16 = 0xF000;
/// Material code where no surface is hit.
pub const NO_HIT_MATERIAL: u16 = 0xFFFF;

/// Intrinsics and distortion a frame was rendered with (after any resolution override).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct CameraTruth {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// Focal lengths and principal point, pixels (OpenCV convention).
    pub fx_px: f64,
    /// See `fx_px`.
    pub fy_px: f64,
    /// See `fx_px`.
    pub cx_px: f64,
    /// See `fx_px`.
    pub cy_px: f64,
    /// Brown–Conrady coefficients `[k1, k2, p1, p2, k3]` (OpenCV order).
    pub distortion: [f64; 5],
}

impl CameraTruth {
    /// From the model the renderer used.
    pub fn of(m: &CameraModel) -> Self {
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
    /// Camera the frame was rendered with.
    pub camera: CameraTruth,
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
            camera: CameraTruth::of(camera),
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
