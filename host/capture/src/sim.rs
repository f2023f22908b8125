//! A scene captured on the simulated rig: the real firmware core in a virtual board behind a
//! real pseudo-terminal (or an external `ellipso sim serve`), the host's real link, pairing and
//! session code, and the simulator's camera ([`ellipso_rig::acquire::sim_rig`]).
//!
//! Contract: the session records the scene's rig record and boards as the tracker reads them
//! ([`record::rig_record_of_scene`], [`record::boards_of_scene`]), so a simulated session is
//! self-contained: the fit never opens the scene file.

use ellipso_rig::acquire::ready::{ReadyCapture, Recorded, Recorder};
use ellipso_rig::acquire::sim_rig::{self, SimCaptureOptions};
use ellipso_run_error::{RunError, Say};
use ellipso_sim::record;

use crate::Captured;

/// The simulated rig of `options`, ready to record (nothing recorded yet).
pub fn prepare(options: &SimCaptureOptions) -> Result<ReadyCapture, RunError> {
    sim_rig::prepare(options, |scene, camera| {
        (
            record::rig_record_of_scene(scene, camera),
            record::boards_of_scene(scene),
        )
    })
}

/// Records the capture of `options` with `recorder`; poses are not tracked (the demo and
/// `ellipso bench mesh` track through their own steps).
pub fn record(
    options: &SimCaptureOptions,
    recorder: &mut dyn Recorder,
) -> Result<Recorded, RunError> {
    recorder.record(prepare(options)?)
}

/// Records the capture of `options` with `recorder`, then tracks its poses when `track` holds
/// ([`crate::record_and_track`]).
pub fn capture(
    options: &SimCaptureOptions,
    track: bool,
    recorder: &mut dyn Recorder,
    say: &dyn Say,
) -> Result<Captured, RunError> {
    crate::record_and_track(prepare(options)?, track, recorder, say)
}
