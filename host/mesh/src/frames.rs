//! The posed frames of a session as the carving reads them: which frames can be used (and why
//! the others cannot), each view's geometry in the volume frame, and a frame's pixels as
//! board-appearance features.
//!
//! Contract:
//! - A posed frame is usable when its PNG exists, it was not flagged incomplete at capture, and
//!   its `frame` event records the exposure and gain (the normaliser needs them) — the
//!   session's own rule, `Session::readable_frame`, which the fit applies too; others are
//!   listed as [`SkippedFrame`]s with the reason, never silently dropped. Unreadable pixels
//!   (corrupt PNG, wrong size) are skipped the same way when the frame is loaded.
//! - Pixels are superpixels of `ellipso_polar::demosaic` (no interpolation), at raw position
//!   `t·u + (t − 1)/2` (the tracker's convention, `ellipso_vision::track`). Per superpixel:
//!   `s0 = (I0 + I45 + I90 + I135)/2` per colour band in dark-subtracted DN, the co/cross
//!   polarisation contrast `p = Σ(I0 − I90) / Σ(I0 + I90)` over bands, and whether any raw
//!   sample of it is saturated.
//! - With a sensor calibration the frames are read at its black level and each superpixel
//!   through its own analysis matrix (`ellipso_polar::sensor_calibration::CalibratedDemosaic`,
//!   as the fit reads them); without one, the plain superpixel demosaic at dark level 0.
//! - Ray directions depend only on the camera model, so they are undistorted once per session
//!   ([`RayTable`]); a pixel whose distortion cannot be inverted has no ray.

use ellipso_model::camera::CameraModel;
use ellipso_model::mosaic::SensorLayout;
use nalgebra::{Isometry3, Point3, Vector3};

use super::volume::Volume;
use ellipso_fit::observe::SkippedFrame;
use ellipso_fit::observe::radiometry::{FrameRadiometry, SessionRadiometry};
use ellipso_polar::PolarConfig;
use ellipso_polar::demosaic::{DemosaicMethod, demosaic};
use ellipso_polar::frame::RawFrame;
use ellipso_polar::mask::MaskReason;
use ellipso_polar::sensor_calibration::CalibratedDemosaic;
use ellipso_session::reader::{FrameEntry, Session};

/// A posed frame that can be read.
#[derive(Clone, Debug)]
pub struct PosedFrame<'a> {
    /// Frame id.
    pub frame_id: u64,
    /// Its file and metadata.
    pub entry: &'a FrameEntry,
    /// Camera → world.
    pub world_from_camera: Isometry3<f64>,
    /// Recorded exposure, µs.
    pub exposure_us: f64,
    /// Recorded analogue gain, dB.
    pub gain_db: f64,
}

/// The usable posed frames of `session` in frame-id order, and the posed frames that are not.
pub fn posed_frames<'a>(
    session: &'a Session,
    poses: &[(u64, Isometry3<f64>)],
) -> (Vec<PosedFrame<'a>>, Vec<SkippedFrame>) {
    let mut poses = poses.to_vec();
    poses.sort_by_key(|p| p.0);
    poses.dedup_by_key(|p| p.0);
    let mut usable = Vec::new();
    let mut skipped = Vec::new();
    for (frame_id, pose) in poses {
        let skip = |reason: &str| SkippedFrame {
            frame_id,
            reason: reason.into(),
        };
        let finite = pose.translation.vector.iter().all(|v| v.is_finite())
            && pose.rotation.coords.iter().all(|v| v.is_finite());
        if !finite {
            skipped.push(skip("its pose is not finite"));
            continue;
        }
        match session.readable_frame(frame_id) {
            Ok(f) => usable.push(PosedFrame {
                frame_id,
                entry: f.entry,
                world_from_camera: pose,
                exposure_us: f.exposure_us,
                gain_db: f.gain_db,
            }),
            Err(why) => skipped.push(skip(&why.to_string())),
        }
    }
    (usable, skipped)
}

/// Undistorted ray directions (camera frame, z = 1) of every superpixel centre.
#[derive(Clone, Debug)]
pub struct RayTable {
    /// Superpixels per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Raw pixels per superpixel side.
    pub tile: usize,
    /// `(x, y)` with the ray `(x, y, 1)`; NaN where the distortion cannot be inverted.
    pub rays: Vec<[f32; 2]>,
}

impl RayTable {
    /// The table of `camera` (raw resolution) for a sensor with `tile × tile` superpixels.
    pub fn new(camera: &CameraModel, tile: usize) -> RayTable {
        let (width, height) = (camera.width as usize / tile, camera.height as usize / tile);
        let centre = (tile as f64 - 1.0) / 2.0;
        let rays = (0..width * height)
            .map(|k| {
                let raw = [
                    (tile * (k % width)) as f64 + centre,
                    (tile * (k / width)) as f64 + centre,
                ];
                camera
                    .undistort_pixel(raw)
                    .map_or([f32::NAN; 2], |[x, y]| [x as f32, y as f32])
            })
            .collect();
        RayTable {
            width,
            height,
            tile,
            rays,
        }
    }

    /// Raw pixel → superpixel coordinate (the inverse of `t·u + (t − 1)/2`).
    pub fn to_superpixel(&self, raw: [f64; 2]) -> [f64; 2] {
        let t = self.tile as f64;
        let c = (t - 1.0) / 2.0;
        [(raw[0] - c) / t, (raw[1] - c) / t]
    }
}

/// One view in the volume frame.
#[derive(Clone, Debug)]
pub struct View {
    /// Frame id.
    pub frame_id: u64,
    /// Volume frame → camera frame.
    pub camera_from_volume: Isometry3<f64>,
    /// Camera centre, volume frame.
    pub centre: Point3<f64>,
    /// Flash position, volume frame.
    pub flash: Point3<f64>,
    /// Flash axis (the optical axis), volume frame, unit.
    pub axis: Vector3<f64>,
    /// The frame's normaliser.
    pub radiometry: FrameRadiometry,
}

impl View {
    /// The view of `frame` in `volume`'s frame.
    pub fn new(frame: &PosedFrame<'_>, volume: &Volume, radiometry: &SessionRadiometry) -> View {
        let volume_from_camera = volume.world_from_volume.inverse() * frame.world_from_camera;
        View {
            frame_id: frame.frame_id,
            camera_from_volume: volume_from_camera.inverse(),
            centre: Point3::from(volume_from_camera.translation.vector),
            flash: volume_from_camera * Point3::from(radiometry.flash.offset_m),
            axis: volume_from_camera * Vector3::z(),
            radiometry: radiometry.for_frame(frame.exposure_us, frame.gain_db),
        }
    }

    /// The ray direction (volume frame, not unit) of a camera-frame direction `(x, y, 1)`.
    pub fn ray(&self, xy: [f32; 2]) -> Vector3<f64> {
        self.camera_from_volume.rotation.inverse()
            * Vector3::new(f64::from(xy[0]), f64::from(xy[1]), 1.0)
    }

    /// DN per unit of board appearance at board point `(x, y, 0)`: the normaliser times the
    /// cosine of the flash's incidence on the board (a Lambertian board's DN are albedo × this).
    /// `None` where the board is not lit (behind the flash's profile or edge-on).
    pub fn board_scale(&self, x: f64, y: f64) -> Option<f64> {
        let p = Point3::new(x, y, 0.0);
        let to_flash = self.flash - p;
        let d = to_flash.norm();
        let to_camera = self.centre - p;
        let c = to_camera.norm();
        if !(d > 1e-6 && c > 1e-6) {
            return None;
        }
        let cos_incidence = to_flash.z / d;
        let cos_axis = (-to_flash / d).dot(&self.axis).clamp(-1.0, 1.0);
        let cos_field = ((-to_camera / c).dot(&self.axis)).clamp(-1.0, 1.0);
        let n = self
            .radiometry
            .normaliser(d, cos_axis.acos(), cos_field.acos());
        let scale = n * cos_incidence;
        (scale.is_finite() && scale > 0.0 && cos_incidence > 0.05).then_some(scale)
    }
}

/// A frame's pixels as appearance features (see the module contract).
#[derive(Clone, Debug)]
pub struct FeatureImage {
    /// Superpixels per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Colour bands (1 or 3).
    pub bands: usize,
    /// Per superpixel: s0 per band (DN; unused bands 0), then `p`.
    pub features: Vec<[f32; 4]>,
    /// Per superpixel: a raw sample is saturated.
    pub saturated: Vec<bool>,
}

/// Loads a frame and computes its features.
pub fn load_features(
    session: &Session,
    layout: SensorLayout,
    frame: &PosedFrame<'_>,
    calibrated: Option<&CalibratedDemosaic>,
) -> Result<FeatureImage, String> {
    let (w, h, px) = session.load_frame(frame.entry).map_err(|e| e.to_string())?;
    let raw = RawFrame::new(w, h, session.manifest.sensor.bit_depth, layout, px)
        .map_err(|e| format!("{}: {e}", frame.entry.path.display()))?;
    let image = match calibrated {
        Some(c) => {
            let config = c
                .config(&PolarConfig::default())
                .map_err(|e| e.to_string())?;
            let levels = config.levels(&raw).map_err(|e| e.to_string())?;
            (
                c.demosaic(&raw, &levels).map_err(|e| e.to_string())?,
                levels,
            )
        }
        None => {
            let levels = PolarConfig::default()
                .levels(&raw)
                .map_err(|e| e.to_string())?;
            (demosaic(&raw, &levels, DemosaicMethod::Superpixel), levels)
        }
    };
    let (image, levels) = image;
    // DN per normalised unit, from the levels themselves (as the fit's sampler does).
    let dn_per_unit = 1.0 / (levels.normalise(1) - levels.normalise(0));
    let first = image.bands.first().ok_or("no colour band")?;
    let (width, height) = (first.mask.width(), first.mask.height());
    let n = width * height;
    let mut features = vec![[0f32; 4]; n];
    let mut saturated = vec![false; n];
    let mut co = vec![0f32; n];
    let mut total = vec![0f32; n];
    for (b, band) in image.bands.iter().enumerate().take(3) {
        let [i0, i45, i90, i135] = &band.intensity;
        let (i0, i45, i90, i135) = (i0.data(), i45.data(), i90.data(), i135.data());
        for k in 0..n {
            features[k][b] = 0.5 * (i0[k] + i45[k] + i90[k] + i135[k]) * dn_per_unit;
            co[k] += i0[k] - i90[k];
            total[k] += i0[k] + i90[k];
            if band.mask.data()[k]
                .reasons()
                .any(|r| r == MaskReason::Saturated)
            {
                saturated[k] = true;
            }
        }
    }
    for k in 0..n {
        // p is left at 0 where there is no light to measure it (the test skips dark pixels).
        features[k][3] = if total[k] > 1e-6 {
            (co[k] / total[k]).clamp(-1.0, 1.0)
        } else {
            0.0
        };
    }
    Ok(FeatureImage {
        width,
        height,
        bands: image.bands.len().min(3),
        features,
        saturated,
    })
}
