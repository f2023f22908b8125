//! The rig as the simulator configures it and a session records it: the camera's intrinsics,
//! sensor and exposure settings ([`CameraSpec`]) and the flash — a point light rigidly mounted
//! next to the camera, behind a linear polariser ([`FlashSpec`]). Scene files (`[rig]`) and
//! session manifests (`rig`) share these types, so both spell a rig the same way.
//!
//! Contract: plain numbers with units in their names; serde defaults are the documented ones
//! (the scene loader range-checks them). The lens is the camera model's own
//! [`Intrinsics`] and [`Distortion`] ([`crate::camera`]), read from the file's flat keys; OpenCV
//! convention (pixel centres at integer coordinates, camera frame x right, y down, z forward).
//! The flash offset is in that camera frame.
//!
//! Default flash geometry: 30 mm above the lens (`offset_m = [0, -0.03, 0]`), giving a
//! camera–flash angle of `atan(0.03 / 0.5) = 3.43°` at a 0.5 m working distance — the ~3.5°
//! near-coaxial geometry of the capture rig ([`FlashSpec::separation_deg_at`]).

use crate::camera::{CameraModel, Distortion, Intrinsics};
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

/// Pinhole + Brown–Conrady camera and sensor settings. The lens is the shared camera model's
/// [`Intrinsics`] and [`Distortion`]; the file spells them as flat keys (`fx_px`…`cy_px`,
/// `k1`…`p2`) through the private `CameraSpecToml`, so scene files read and write as before.
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(from = "CameraSpecToml", into = "CameraSpecToml")]
pub struct CameraSpec {
    /// `[width, height]` in pixels (even, for the 2×2 mosaic).
    pub resolution_px: [u32; 2],
    /// Focal lengths and principal point, pixels (the file's `fx_px`, `fy_px`, `cx_px`,
    /// `cy_px`).
    pub intrinsics: Intrinsics,
    /// Lens distortion (the file's `k1`, `k2`, `k3`, `p1`, `p2`; each 0 by default).
    pub distortion: Distortion,
    /// Sensor type.
    pub sensor: SensorKind,
    /// ADC output bit depth: 8, 12 or 16 (default 12).
    pub bit_depth: u8,
    /// Exposure time, microseconds.
    pub exposure_us: f64,
    /// Analogue gain, dB (default 0).
    pub gain_db: f64,
    /// Full-well capacity, electrons (default 10 500, IMX250 class).
    pub full_well_e: f64,
    /// Pixel pitch, micrometres (default 3.45).
    pub pixel_pitch_um: f64,
    /// Lens f-number (default 5.6).
    pub f_number: f64,
    /// Quantum efficiency, electrons per photon (default 0.6).
    pub quantum_efficiency: f64,
    /// Whether the on-chip polariser mosaic analyses polarisation (default true). `false` models
    /// an S0-only camera: every pixel sees the unpolarised intensity.
    pub analysers: bool,
}

/// The flat file form of [`CameraSpec`] (a scene's `[rig.camera]` table): its keys, their order
/// and their defaults are the scene format's.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
struct CameraSpecToml {
    resolution_px: [u32; 2],
    fx_px: f64,
    fy_px: f64,
    cx_px: f64,
    cy_px: f64,
    #[serde(default)]
    k1: f64,
    #[serde(default)]
    k2: f64,
    #[serde(default)]
    k3: f64,
    #[serde(default)]
    p1: f64,
    #[serde(default)]
    p2: f64,
    sensor: SensorKind,
    #[serde(default = "default_bit_depth")]
    bit_depth: u8,
    exposure_us: f64,
    #[serde(default)]
    gain_db: f64,
    #[serde(default = "default_full_well")]
    full_well_e: f64,
    #[serde(default = "default_pixel_pitch")]
    pixel_pitch_um: f64,
    #[serde(default = "default_f_number")]
    f_number: f64,
    #[serde(default = "default_qe")]
    quantum_efficiency: f64,
    #[serde(default = "yes")]
    analysers: bool,
}

impl From<CameraSpecToml> for CameraSpec {
    fn from(t: CameraSpecToml) -> Self {
        CameraSpec {
            resolution_px: t.resolution_px,
            intrinsics: Intrinsics {
                fx: t.fx_px,
                fy: t.fy_px,
                cx: t.cx_px,
                cy: t.cy_px,
            },
            distortion: Distortion {
                k1: t.k1,
                k2: t.k2,
                k3: t.k3,
                p1: t.p1,
                p2: t.p2,
            },
            sensor: t.sensor,
            bit_depth: t.bit_depth,
            exposure_us: t.exposure_us,
            gain_db: t.gain_db,
            full_well_e: t.full_well_e,
            pixel_pitch_um: t.pixel_pitch_um,
            f_number: t.f_number,
            quantum_efficiency: t.quantum_efficiency,
            analysers: t.analysers,
        }
    }
}

impl From<CameraSpec> for CameraSpecToml {
    fn from(c: CameraSpec) -> Self {
        let (i, d) = (c.intrinsics, c.distortion);
        CameraSpecToml {
            resolution_px: c.resolution_px,
            fx_px: i.fx,
            fy_px: i.fy,
            cx_px: i.cx,
            cy_px: i.cy,
            k1: d.k1,
            k2: d.k2,
            k3: d.k3,
            p1: d.p1,
            p2: d.p2,
            sensor: c.sensor,
            bit_depth: c.bit_depth,
            exposure_us: c.exposure_us,
            gain_db: c.gain_db,
            full_well_e: c.full_well_e,
            pixel_pitch_um: c.pixel_pitch_um,
            f_number: c.f_number,
            quantum_efficiency: c.quantum_efficiency,
            analysers: c.analysers,
        }
    }
}

impl CameraSpec {
    /// The shared pinhole + Brown–Conrady model ([`CameraModel`]) with this camera's resolution,
    /// intrinsics and distortion.
    pub fn camera_model(&self) -> CameraModel {
        CameraModel {
            width: self.resolution_px[0],
            height: self.resolution_px[1],
            intrinsics: self.intrinsics,
            distortion: self.distortion,
        }
    }

    /// Whether any distortion coefficient is non-zero.
    pub fn has_distortion(&self) -> bool {
        let d = self.distortion;
        [d.k1, d.k2, d.k3, d.p1, d.p2].iter().any(|&k| k != 0.0)
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
    fn the_camera_reads_and_writes_the_scene_files_flat_keys() {
        let text = "resolution_px = [64, 48]\nfx_px = 100.0\nfy_px = 101.0\ncx_px = 31.5\n\
                    cy_px = 23.5\nk2 = 0.2\nsensor = \"mono_polar\"\nexposure_us = 2500.0\n";
        let c: CameraSpec = toml::from_str(text).expect("parses");
        assert_eq!(
            c.camera_model(),
            CameraModel {
                width: 64,
                height: 48,
                intrinsics: Intrinsics {
                    fx: 100.0,
                    fy: 101.0,
                    cx: 31.5,
                    cy: 23.5
                },
                distortion: Distortion {
                    k2: 0.2,
                    ..Distortion::ZERO
                },
            }
        );
        assert!(c.has_distortion());
        assert_eq!(
            (c.bit_depth, c.full_well_e, c.analysers),
            (12, 10_500.0, true)
        );
        let written = toml::to_string(&c).expect("writes");
        let keys: Vec<&str> = written
            .lines()
            .filter_map(|l| l.split(" = ").next())
            .collect();
        assert_eq!(
            keys,
            [
                "resolution_px",
                "fx_px",
                "fy_px",
                "cx_px",
                "cy_px",
                "k1",
                "k2",
                "k3",
                "p1",
                "p2",
                "sensor",
                "bit_depth",
                "exposure_us",
                "gain_db",
                "full_well_e",
                "pixel_pitch_um",
                "f_number",
                "quantum_efficiency",
                "analysers",
            ]
        );
        assert_eq!(
            toml::from_str::<CameraSpec>(&written).expect("reads back"),
            c
        );
        let e = toml::from_str::<CameraSpec>(&format!("{text}fx = 1.0\n")).unwrap_err();
        assert!(e.to_string().contains("unknown field `fx`"), "{e}");
    }

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
