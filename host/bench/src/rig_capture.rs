//! A scene captured on the simulated rig (the firmware core behind a real pty, the host's real
//! link, pairing and session code), for the demo and `ellipso bench mesh`: the capture
//! `ellipso capture --sim SCENE --no-track` makes, recorded by the caller's [`Recorder`] (the
//! binary's progress bar and signal handlers).
//!
//! Contract: 2×2 rays per raw pixel, the scene's bracket, the interval asked (the scene's by
//! default); the session records the
//! rig and boards of the scene ([`ellipso_capture::sim`], the code `ellipso capture` runs);
//! poses are not tracked here.

use std::path::Path;

use ellipso_rig::acquire::ready::{Recorded, Recorder};
use ellipso_rig::acquire::sim_rig::SimCaptureOptions;
use ellipso_run_error::RunError;

/// Captures `scene` into the new session `out` (`photos`: at most the scene's path; at
/// `resolution` instead of the scene's; `interval_ms`: the time between photos, default the
/// scene's).
pub fn capture_on_sim_rig(
    scene: &Path,
    out: &Path,
    photos: Option<u32>,
    resolution: [u32; 2],
    interval_ms: Option<f64>,
    recorder: &mut dyn Recorder,
) -> Result<Recorded, RunError> {
    let options = SimCaptureOptions {
        scene: scene.to_path_buf(),
        out: out.to_path_buf(),
        external: None,
        photos,
        resolution: Some(resolution),
        supersampling: 2,
        interval_ms,
        bracket: None,
    };
    ellipso_capture::sim::record(&options, recorder)
}
