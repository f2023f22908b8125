//! The physical rig of `ellipso capture --rig RIG.toml` ([`prepare`]): the trigger board on its
//! serial port and the camera through its backend, as the rig file describes them.
//!
//! Contract: the rig file is read by the caller (`ellipso_capture::rig_file`, which owns its
//! format and its boards) and handed over as a [`HardwareRig`]; the camera must deliver the
//! frame size of the rig's camera model; a backend not compiled in is refused by name with the
//! cargo feature that adds it. The session records the trigger port, the camera's backend and
//! address, and a relative-radiometry rig record with the calibrated flash offset. Nothing here
//! prints. [`prepare_with`] is the same with the link and the camera opened by the caller
//! (`ellipso rig check --fire --sim-camera` puts the simulated camera in the camera's place).

use std::path::PathBuf;

use ellipso_model::camera::CameraModel;
use ellipso_model::mosaic::SensorLayout;
use ellipso_protocol::CaptureConfig;
use ellipso_run_error::RunError;
use ellipso_session::manifest::{Manifest, SensorInfo, SessionSource};
use ellipso_session::rig::{RigRecord, SensorCalibrationRef, TrackedBoard};
use ellipso_session::time::HostClock;
use ellipso_session::writer::SessionWriter;

use super::ready::{ReadyCapture, capture_plan, check_plan};
use crate::camera::{Camera, CameraSettings};
use crate::link::{LinkConfig, TriggerLink};

/// Which camera backend drives the sensor.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Backend {
    /// GigE Vision / USB3 Vision through libaravis (feature `aravis`).
    Aravis,
    /// UVC through V4L2 (feature `v4l`).
    V4l,
}

/// The physical rig as a capture drives it (from a rig file).
#[derive(Debug, Clone)]
pub struct HardwareRig {
    /// The rig file it was read from (named in errors).
    pub rig_file: PathBuf,
    /// The trigger board's port (serial device, pty, or `unix:PATH`).
    pub trigger_port: String,
    /// The camera backend.
    pub backend: Backend,
    /// The camera's address (aravis: IP address; v4l: `/dev/videoN`).
    pub address: String,
    /// The sensor's mosaic layout.
    pub layout: SensorLayout,
    /// Exposure, gain and bit depth applied to the camera.
    pub settings: CameraSettings,
    /// The calibrated camera model; `None` before `ellipso calibrate` has written the rig file's
    /// `[camera]` (the capture then records [`provisional_camera`], enough to detect tags for
    /// the calibration itself).
    pub camera: Option<CameraModel>,
    /// The flash position in the camera frame, as `ellipso calibrate flash` measured it.
    pub flash_offset_m: Option<[f64; 3]>,
    /// The flash polariser's axis, degrees from camera x towards camera y, as `ellipso
    /// calibrate flash` measured it (`None`: 0°, parallel to the 0° analyser).
    pub flash_polariser_deg: Option<f64>,
    /// The board timing.
    pub board: CaptureConfig,
    /// Photos to take.
    pub photos: u32,
    /// The AprilTag boards of the capture.
    pub boards: Vec<TrackedBoard>,
    /// The sensor calibration the rig file names (its identity and file), recorded in the
    /// session.
    pub sensor_calibration: Option<SensorCalibrationRef>,
}

/// The camera model a capture records before calibration: a pinhole with the focal length
/// equal to the image's larger side (a 53° field of view across it, between the rig's 12 mm
/// and 8 mm lenses on the 2/3" sensor) centred, no distortion. Tag detection does not use it;
/// `ellipso calibrate` replaces it.
pub fn provisional_camera(width: u32, height: u32) -> CameraModel {
    let f = f64::from(width.max(height));
    CameraModel {
        width,
        height,
        intrinsics: ellipso_model::camera::Intrinsics {
            fx: f,
            fy: f,
            cx: (f64::from(width) - 1.0) / 2.0,
            cy: (f64::from(height) - 1.0) / 2.0,
        },
        distortion: Default::default(),
    }
}

/// Opens the camera and the trigger link and creates the session in `out`: a capture ready to
/// run.
pub fn prepare(rig: &HardwareRig, out: &std::path::Path) -> Result<ReadyCapture, RunError> {
    let clock = HostClock::new();
    let camera = open_camera(rig, clock)?;
    let link = TriggerLink::open(&rig.trigger_port, clock, LinkConfig::default())?;
    prepare_with(rig, out, clock, link, camera)
}

/// [`prepare`] with the trigger link and the camera already open (both on `clock`): what
/// `ellipso rig check --fire --sim-camera` uses to put the simulated camera of an `ellipso sim
/// serve` board in the rig file's place, so its check runs the very capture `prepare` sets up.
pub fn prepare_with(
    rig: &HardwareRig,
    out: &std::path::Path,
    clock: HostClock,
    link: TriggerLink,
    camera: Box<dyn Camera>,
) -> Result<ReadyCapture, RunError> {
    let info = camera.info();
    let model = match rig.camera {
        Some(model) => {
            ellipso_run_error::ensure!(
                (info.width, info.height) == (model.width, model.height),
                "{}: the camera delivers {}×{} but the rig's camera model is {}×{}; recalibrate or fix [camera]",
                rig.rig_file.display(),
                info.width,
                info.height,
                model.width,
                model.height
            );
            model
        }
        None => {
            tracing::warn!(
                "{}: no [camera] yet: recording a provisional camera model; run `ellipso \
                 calibrate` on this session and add the [camera] it writes",
                rig.rig_file.display()
            );
            provisional_camera(info.width, info.height)
        }
    };
    let mut manifest = Manifest::new(
        SessionSource::Hardware {
            trigger_port: rig.trigger_port.clone(),
            camera: format!("{}:{}", info.backend, rig.address),
        },
        SensorInfo {
            layout: rig.layout,
            width: info.width,
            height: info.height,
            bit_depth: rig.settings.bit_depth,
        },
        clock.wall_at_epoch_unix_us(),
    );
    manifest.rig = Some(RigRecord::relative(
        model,
        // The flash as `ellipso calibrate flash` measured it (the fit needs it); the rest of
        // the flash description takes the rig's defaults (polarised parallel to the 0° analyser
        // unless the polariser angle was measured).
        rig.flash_offset_m
            .map(|offset_m| ellipso_model::rig::FlashSpec {
                offset_m,
                polariser_deg: rig.flash_polariser_deg.unwrap_or(0.0),
                ..Default::default()
            }),
    ));
    if let Some(cal) = &rig.sensor_calibration {
        tracing::info!(
            "sensor calibration {} ({}) recorded in the session",
            cal.id,
            cal.file.display()
        );
    }
    if let Some(record) = manifest.rig.as_mut() {
        record.sensor_calibration = rig.sensor_calibration.clone();
    }
    manifest.boards = rig.boards.clone();
    check_plan(&link, rig.board)?;
    let session = SessionWriter::create(out, manifest)?;
    Ok(ReadyCapture {
        link,
        camera,
        session,
        plan: capture_plan(rig.board, rig.settings, rig.photos),
        photos: rig.photos,
        board: None,
    })
}

/// Opens the rig's camera through its backend (features permitting).
fn open_camera(rig: &HardwareRig, clock: HostClock) -> Result<Box<dyn Camera>, RunError> {
    match rig.backend {
        #[cfg(feature = "aravis")]
        Backend::Aravis => {
            let options = crate::camera::aravis::AravisOptions {
                layout: ellipso_session::manifest::layout_name(rig.layout).to_string(),
                ..Default::default()
            };
            Ok(Box::new(crate::camera::aravis::AravisCamera::open(
                &rig.address,
                options,
                clock,
            )?))
        }
        #[cfg(feature = "v4l")]
        Backend::V4l => Ok(Box::new(crate::camera::v4l::V4lCamera::open(
            &rig.address,
            clock,
        )?)),
        #[cfg(not(feature = "aravis"))]
        Backend::Aravis => missing_backend(rig, "aravis", clock),
        #[cfg(not(feature = "v4l"))]
        Backend::V4l => missing_backend(rig, "v4l", clock),
    }
}

#[cfg(not(all(feature = "aravis", feature = "v4l")))]
fn missing_backend(
    rig: &HardwareRig,
    feature: &str,
    _clock: HostClock,
) -> Result<Box<dyn Camera>, RunError> {
    ellipso_run_error::bail!(
        "{}: camera backend `{feature}` is not in this build; rebuild with `--features {feature}`",
        rig.rig_file.display()
    )
}
