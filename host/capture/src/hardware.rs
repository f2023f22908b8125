//! A capture on the physical rig a rig file describes: the file read by its owner
//! ([`RigFile`], in `ellipso-vision` with the boards), turned into the rig crate's
//! [`HardwareRig`] (trigger port, camera backend and address, settings, camera model, flash
//! offset, board timing, boards) and recorded ([`hardware::prepare`]).
//!
//! Contract: the session directory must be new (checked before the rig is touched); a
//! `bracket` given by the caller replaces the rig file's; poses are tracked only when asked for
//! and the rig has boards.

use std::path::Path;

use crate::rig_file::{Backend, RigFile};
use ellipso_protocol::Bracket;
use ellipso_rig::acquire::hardware::{self, HardwareRig};
use ellipso_rig::acquire::ready::Recorder;
use ellipso_rig::camera::CameraSettings;
use ellipso_run_error::{RunError, Say};

use crate::Captured;

/// The rig of `rig` as the capture drives it, with `bracket` instead of the rig file's when
/// given.
pub fn rig_of_file(rig: &RigFile, bracket: Option<Bracket>) -> Result<HardwareRig, RunError> {
    let mut board = rig.board_config();
    if let Some(bracket) = bracket {
        board.bracket = bracket;
    }
    Ok(HardwareRig {
        rig_file: rig.path.clone(),
        trigger_port: rig.trigger.port.clone(),
        backend: match rig.sensor.backend {
            Backend::Aravis => hardware::Backend::Aravis,
            Backend::V4l => hardware::Backend::V4l,
        },
        address: rig.sensor.address.clone(),
        layout: rig.sensor.layout,
        settings: CameraSettings {
            exposure_us: rig.sensor.exposure_us,
            gain_db: rig.sensor.gain_db,
            bit_depth: rig.sensor.bit_depth,
            external_trigger: true,
        },
        camera: rig.camera,
        flash_offset_m: rig.flash.map(|f| f.offset_m),
        flash_polariser_deg: rig.flash.and_then(|f| f.polariser_deg),
        board,
        photos: rig.capture.photos,
        boards: rig.boards()?,
        sensor_calibration: rig.sensor_calibration()?,
    })
}

/// Records a capture on the rig of the rig file `rig_path` into the new session `out`, then
/// tracks its poses when `track` holds and the rig has boards.
pub fn capture(
    rig_path: &Path,
    out: &Path,
    bracket: Option<Bracket>,
    track: bool,
    recorder: &mut dyn Recorder,
    say: &dyn Say,
) -> Result<Captured, RunError> {
    let rig = RigFile::load(rig_path)?;
    ellipso_session::writer::check_fresh(out)?;
    let hardware_rig = rig_of_file(&rig, bracket)?;
    let ready = hardware::prepare(&hardware_rig, out)?;
    crate::record_and_track(
        ready,
        track && !hardware_rig.boards.is_empty(),
        recorder,
        say,
    )
}
