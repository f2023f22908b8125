//! The rig as the simulator configures it and a session records it: the camera's intrinsics,
//! sensor and exposure settings ([`CameraSpec`]) and the flash — a point light rigidly mounted
//! next to the camera, behind a linear polariser ([`FlashSpec`]). Scene files (`[rig]`) and
//! session manifests (`rig`) share these types, so both spell a rig the same way.
//!
//! Contract: plain numbers with units in their names; serde defaults are the documented ones
//! (the scene loader range-checks them). Intrinsics use the OpenCV convention (pixel centres at
//! integer coordinates, camera frame x right, y down, z forward). The flash offset is in that
//! camera frame.
//!
//! Default flash geometry: 30 mm above the lens (`offset_m = [0, -0.03, 0]`), giving a
//! camera–flash angle of `atan(0.03 / 0.5) = 3.43°` at a 0.5 m working distance — the ~3.5°
//! near-coaxial geometry of the capture rig ([`FlashSpec::separation_deg_at`]).

use nalgebra::{Isometry3, Point3, Unit, Vector3};
use serde::{Deserialize, Serialize};

/// The camera's sensor (maps to `mosaic::SensorLayout`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum SensorKind {
    /// Sony IMX250MZR: monochrome with a 2×2 polariser mosaic (90°/45°/135°/0°).
    MonoPolar,
    /// Sony IMX250MYR: RGGB Bayer under a 2×2 polariser mosaic.
    ColourPolar,
}

/// Largest frame side, px, a scene (or a resolution override) may ask for: 16384 × 16384 raw
/// pixels is already 1 GiB of f32 DN per frame.
pub const MAX_SIDE_PX: u32 = 16_384;

fn default_bit_depth() -> u8 {
    12
}
fn default_full_well() -> f64 {
    10_500.0
}
fn default_pixel_pitch() -> f64 {
    3.45
}
fn default_f_number() -> f64 {
    5.6
}
fn default_qe() -> f64 {
    0.6
}
fn yes() -> bool {
    true
}

/// Pinhole + Brown–Conrady camera and sensor settings.
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct CameraSpec {
    /// `[width, height]` in pixels (even, for the 2×2 mosaic).
    pub resolution_px: [u32; 2],
    /// Focal length along x, pixels.
    pub fx_px: f64,
    /// Focal length along y, pixels.
    pub fy_px: f64,
    /// Principal point x, pixels.
    pub cx_px: f64,
    /// Principal point y, pixels.
    pub cy_px: f64,
    /// Radial distortion k1 (default 0).
    #[serde(default)]
    pub k1: f64,
    /// Radial distortion k2 (default 0).
    #[serde(default)]
    pub k2: f64,
    /// Radial distortion k3 (default 0).
    #[serde(default)]
    pub k3: f64,
    /// Tangential distortion p1 (default 0).
    #[serde(default)]
    pub p1: f64,
    /// Tangential distortion p2 (default 0).
    #[serde(default)]
    pub p2: f64,
    /// Sensor type.
    pub sensor: SensorKind,
    /// ADC output bit depth: 8, 12 or 16 (default 12).
    #[serde(default = "default_bit_depth")]
    pub bit_depth: u8,
    /// Exposure time, microseconds.
    pub exposure_us: f64,
    /// Analogue gain, dB (default 0).
    #[serde(default)]
    pub gain_db: f64,
    /// Full-well capacity, electrons (default 10 500, IMX250 class).
    #[serde(default = "default_full_well")]
    pub full_well_e: f64,
    /// Pixel pitch, micrometres (default 3.45).
    #[serde(default = "default_pixel_pitch")]
    pub pixel_pitch_um: f64,
    /// Lens f-number (default 5.6).
    #[serde(default = "default_f_number")]
    pub f_number: f64,
    /// Quantum efficiency, electrons per photon (default 0.6).
    #[serde(default = "default_qe")]
    pub quantum_efficiency: f64,
    /// Whether the on-chip polariser mosaic analyses polarisation (default true). `false` models
    /// an S0-only camera: every pixel sees the unpolarised intensity.
    #[serde(default = "yes")]
    pub analysers: bool,
}

impl CameraSpec {
    /// The shared pinhole + Brown–Conrady model ([`crate::camera::CameraModel`]) with this
    /// camera's resolution, intrinsics and distortion.
    pub fn camera_model(&self) -> crate::camera::CameraModel {
        use crate::camera::{CameraModel, Distortion, Intrinsics};
        CameraModel {
            width: self.resolution_px[0],
            height: self.resolution_px[1],
            intrinsics: Intrinsics {
                fx: self.fx_px,
                fy: self.fy_px,
                cx: self.cx_px,
                cy: self.cy_px,
            },
            distortion: Distortion {
                k1: self.k1,
                k2: self.k2,
                k3: self.k3,
                p1: self.p1,
                p2: self.p2,
            },
        }
    }

    /// Whether any distortion coefficient is non-zero.
    pub fn has_distortion(&self) -> bool {
        [self.k1, self.k2, self.k3, self.p1, self.p2]
            .iter()
            .any(|&k| k != 0.0)
    }
}

/// Angular emission profile of the flash, relative to its on-axis intensity.
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct FlashProfileSpec {
    /// `cos_power` (default) or `table`.
    #[serde(default)]
    pub kind: FlashProfileKind,
    /// Exponent n of `cos^n θ` (cos_power only; default 1, a Lambertian LED).
    #[serde(default)]
    pub exponent: Option<f64>,
    /// Off-axis angles, degrees, strictly increasing from 0 (table only).
    #[serde(default)]
    pub angle_deg: Option<Vec<f64>>,
    /// Relative intensity at each angle, 1 at 0° (table only; linear interpolation, 0 beyond).
    #[serde(default)]
    pub relative: Option<Vec<f64>>,
}

impl Default for FlashProfileSpec {
    fn default() -> Self {
        Self {
            kind: FlashProfileKind::CosPower,
            exponent: None,
            angle_deg: None,
            relative: None,
        }
    }
}

/// Profile kinds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum FlashProfileKind {
    /// `cos^n θ`.
    #[default]
    CosPower,
    /// Tabulated.
    Table,
}

fn default_offset() -> [f64; 3] {
    [0.0, -0.03, 0.0]
}
fn default_intensity() -> f64 {
    0.5
}

/// The flash: a point light at a fixed offset from the camera centre, aimed along the camera's
/// optical axis.
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct FlashSpec {
    /// Position in the camera frame (x right, y down, z forward), metres (default `[0, -0.03, 0]`).
    #[serde(default = "default_offset")]
    pub offset_m: [f64; 3],
    /// Whether a linear polariser sits in front of the flash (default true).
    #[serde(default = "yes")]
    pub polarised: bool,
    /// Polariser transmission axis, degrees in the image plane from the camera x axis towards y;
    /// 0 = parallel to the sensor's 0° analyser (default 0).
    #[serde(default)]
    pub polariser_deg: f64,
    /// On-axis radiant intensity after the polariser, W/sr (default 0.5).
    #[serde(default = "default_intensity")]
    pub radiant_intensity_w_per_sr: f64,
    /// Angular falloff.
    #[serde(default)]
    pub profile: FlashProfileSpec,
}

impl Default for FlashSpec {
    fn default() -> Self {
        Self {
            offset_m: default_offset(),
            polarised: true,
            polariser_deg: 0.0,
            radiant_intensity_w_per_sr: default_intensity(),
            profile: FlashProfileSpec::default(),
        }
    }
}

impl FlashSpec {
    /// Angle between the camera and flash rays to a point on the optical axis at `distance_m`.
    pub fn separation_deg_at(&self, distance_m: f64) -> f64 {
        let [x, y, z] = self.offset_m;
        let lateral = (x * x + y * y).sqrt();
        // atan2 handles distance_m ≤ z (flash in front of the target) without division.
        lateral.atan2(distance_m - z).to_degrees()
    }

    /// Flash position in the world for a camera pose.
    pub fn position_world(&self, world_from_camera: &Isometry3<f64>) -> Point3<f64> {
        world_from_camera * Point3::from(self.offset_m)
    }

    /// Flash axis (the camera's optical axis) in the world.
    pub fn axis_world(&self, world_from_camera: &Isometry3<f64>) -> Unit<Vector3<f64>> {
        world_from_camera * Vector3::z_axis()
    }

    /// Transmission axis of the flash polariser in the world: the camera x axis turned by
    /// `polariser_deg` towards camera y (`None` for an unpolarised flash).
    pub fn polariser_axis_world(
        &self,
        world_from_camera: &Isometry3<f64>,
    ) -> Option<Unit<Vector3<f64>>> {
        let (s, c) = self.polariser_deg.to_radians().sin_cos();
        self.polarised
            .then(|| world_from_camera * Unit::new_normalize(Vector3::new(c, s, 0.0)))
    }

    /// Relative intensity at `theta_deg` off the flash axis (1 on axis).
    pub fn relative_intensity(&self, theta_deg: f64) -> f64 {
        match self.profile.kind {
            FlashProfileKind::CosPower => {
                // Clamp: no light behind the emitter plane.
                let c = theta_deg.to_radians().cos().max(0.0);
                c.powf(self.profile.exponent.unwrap_or(1.0))
            }
            FlashProfileKind::Table => {
                let (a, r) = match (&self.profile.angle_deg, &self.profile.relative) {
                    (Some(a), Some(r)) if !a.is_empty() && a.len() == r.len() => (a, r),
                    // Unvalidated, malformed table: no light rather than a panic.
                    _ => return 0.0,
                };
                let theta = theta_deg.abs();
                let last = a.len() - 1;
                if theta >= a[last] {
                    return if theta == a[last] { r[last] } else { 0.0 };
                }
                // a[0] = 0 ≤ theta < a[last], so 1 ≤ i ≤ last.
                let i = a.partition_point(|&x| x <= theta).max(1);
                let f = (theta - a[i - 1]) / (a[i] - a[i - 1]);
                r[i - 1] + f * (r[i] - r[i - 1])
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_flash_is_about_three_and_a_half_degrees_at_half_a_metre() {
        let f = FlashSpec::default();
        let a = f.separation_deg_at(0.5);
        assert!((a - 3.4336).abs() < 1e-3, "{a}");
    }

    #[test]
    fn flash_frame_follows_the_camera() {
        let mut f = FlashSpec {
            polariser_deg: 90.0,
            ..FlashSpec::default()
        };
        let pose = Isometry3::new(Vector3::new(1.0, 2.0, 3.0), Vector3::new(0.0, 0.0, 0.5));
        let p = f.position_world(&pose);
        assert!((p - pose * Point3::new(0.0, -0.03, 0.0)).norm() < 1e-15);
        let axis = f.polariser_axis_world(&pose).expect("polarised");
        // 90° turns the transmission axis from camera x to camera y.
        assert!((axis.into_inner() - pose * Vector3::y()).norm() < 1e-12);
        assert!(
            axis.dot(&f.axis_world(&pose)).abs() < 1e-12,
            "perpendicular to the beam"
        );
        f.polarised = false;
        assert!(f.polariser_axis_world(&pose).is_none());
    }

    #[test]
    fn profiles_fall_off_as_documented() {
        let mut f = FlashSpec::default();
        assert!((f.relative_intensity(60.0) - 0.5).abs() < 1e-12);
        assert_eq!(f.relative_intensity(120.0), 0.0);
        f.profile = FlashProfileSpec {
            kind: FlashProfileKind::Table,
            exponent: None,
            angle_deg: Some(vec![0.0, 10.0, 30.0]),
            relative: Some(vec![1.0, 0.8, 0.2]),
        };
        assert!((f.relative_intensity(5.0) - 0.9).abs() < 1e-12);
        assert!((f.relative_intensity(30.0) - 0.2).abs() < 1e-12);
        assert_eq!(f.relative_intensity(31.0), 0.0);
        assert_eq!(f.relative_intensity(0.0), 1.0);
    }
}
