//! The sensor calibration a command reads a session's frames with, and what it says about it.
//!
//! Contract: [`session_calibration`] takes the file given on the command line (`ellipso fit
//! --sensor-calibration`) or the one the session recorded (`capture`, from the rig file's
//! `[sensor] calibration`), refusing a stale identity, another sensor size or layout, a corrupt
//! file or another format each by name (`ellipso_polar::sensor_calibration::for_session`). With
//! one, it says which file and its figures; without one on a session from the physical rig, it
//! says — as a warning, never silently — what the fit assumes instead: ideal analysers (or the
//! recorded extinction ratio), the black level it subtracts, and the noise model's constants.
//! Simulator sessions say nothing: their sensor is what the scene simulated and the session
//! records.

use std::path::Path;
use std::sync::Arc;

use ellipso_fit::solve::SensorNoiseModel;
use ellipso_polar::sensor_calibration::{SensorCalibration, for_session};
use ellipso_run_error::{RunError, Say};
use ellipso_session::manifest::SessionSource;
use ellipso_session::reader::Session;

/// The calibration for `session`'s frames (module contract); `dark_level_dn` is the black level
/// the fit subtracts without one.
pub fn session_calibration(
    session: &Session,
    given: Option<&Path>,
    dark_level_dn: f32,
    say: &dyn Say,
) -> Result<Option<Arc<SensorCalibration>>, RunError> {
    let cal = for_session(&session.manifest, given)?;
    match &cal {
        Some(cal) => {
            let f = &cal.header.figures;
            say.err(format_args!(
                "sensor calibration {}: black level {:.2} DN, {:.4} DN/e⁻, read noise {:.2} DN, \
                 analyser angle sd {:.2}° (applied per superpixel)",
                cal.id(),
                f.black_level_dn,
                f.gain_dn_per_e,
                f.read_noise_dn,
                f.analyser_angle_sd_deg
            ));
        }
        None if matches!(session.manifest.source, SessionSource::Hardware { .. }) => {
            say.err(format_args!(
                "warning: {}",
                assumed_sensor(session, dark_level_dn)
            ));
        }
        None => {}
    }
    Ok(cal.map(Arc::new))
}

/// What a hardware session without a sensor calibration is read with, in words.
pub fn assumed_sensor(session: &Session, dark_level_dn: f32) -> String {
    let analysers = match session
        .manifest
        .rig
        .as_ref()
        .and_then(|r| r.analyser_extinction_ratio)
    {
        Some(er) => format!("analysers at exactly 0/45/90/135° with extinction ratio {er}"),
        None => "ideal analysers (exactly 0/45/90/135°, infinite extinction, equal gains)".into(),
    };
    let noise = session.manifest.rig.as_ref().and_then(|r| r.noise.as_ref());
    let noise = match noise {
        Some(n) => format!(
            "the recorded noise model ({:.2} e⁻ read noise)",
            n.read_noise_e
        ),
        None => {
            let d = SensorNoiseModel::default();
            format!(
                "the default noise model ({} DN/e⁻, read noise {} DN: an IMX250 at 0 dB)",
                d.dn_per_electron, d.read_noise_dn
            )
        }
    };
    format!(
        "{}: a session from the physical rig fitted without a sensor calibration: assuming \
         {analysers}, a black level of {dark_level_dn} DN with no dark-signal or \
         photo-response non-uniformity, no vignetting and {noise}; measure the sensor with \
         `ellipso calibrate sensor` and name the file in the rig file (`[sensor] calibration`) \
         or with `--sensor-calibration FILE`",
        session.dir.display()
    )
}
