//! `ellipso rig check RIG.toml --fire [N]`: fires N test flashes through the capture
//! `ellipso capture --rig` runs ([`ellipso_rig::acquire::hardware::prepare`]: the rig file's
//! trigger board and camera, the real link, pairing and session writer) into a temporary
//! session, reads it back ([`super::flash_check`]) and removes it: nothing is written where the
//! user keeps data.
//!
//! The check fires in free run whatever `capture.trigger` says (it must not wait for the grip
//! button), `N` photos at the rig file's timing. With `--sim-camera SCENE --wire SOCKET` the
//! simulated camera of an `ellipso sim serve` board stands in for the rig file's camera
//! ([`ellipso_rig::acquire::sim_rig::stand_in_camera`]): how the check is tested without
//! hardware.

use std::path::PathBuf;

use anyhow::Context as _;
use ellipso_capture::rig_file::RigFile;
use ellipso_protocol::{PulseCount, TriggerSource};
use ellipso_rig::acquire::hardware;
use ellipso_rig::acquire::ready::Recorder as _;
use ellipso_rig::acquire::sim_rig::{StandInCamera, stand_in_camera};
use ellipso_rig::link::time::HostClock;
use ellipso_rig::link::{LinkConfig, TriggerLink};

use super::flash_check::{self, FlashCheck};
use crate::cli::out;
use crate::cli::record::Recording;

/// Most test flashes one check fires: a check needs a few; a capture is `ellipso capture`.
pub const MAX_FLASHES: u32 = 50;

/// Parses `--fire N`: 1..=[`MAX_FLASHES`].
pub fn flashes(s: &str) -> Result<u32, String> {
    let n: u32 = s
        .parse()
        .map_err(|_| format!("`{s}` is not a whole number of flashes"))?;
    if !(1..=MAX_FLASHES).contains(&n) {
        return Err(format!(
            "{n} flashes: a check fires 1 to {MAX_FLASHES} (a longer run is `ellipso capture \
             --rig`)"
        ));
    }
    Ok(n)
}

/// The simulated camera standing in for the rig file's (`--sim-camera`, `--wire`,
/// `--resolution`).
pub struct SimStandIn {
    /// Scene file.
    pub scene: PathBuf,
    /// Trigger-wire socket of `ellipso sim serve --wire`.
    pub wire: PathBuf,
    /// Render size.
    pub resolution: Option<[u32; 2]>,
}

/// Fires `n` flashes on the rig of `rig` and reads back what they show.
pub fn fire(rig: &RigFile, n: u32, stand_in: Option<&SimStandIn>) -> anyhow::Result<FlashCheck> {
    let mut hw = ellipso_capture::hardware::rig_of_file(rig, None).map_err(out::failed)?;
    hw.photos = n;
    hw.board.pulses = PulseCount::Count(n);
    hw.board.trigger = TriggerSource::FreeRun;
    let tmp = tempfile::Builder::new()
        .prefix("ellipso-rig-check-")
        .tempdir()
        .context("creating the check's temporary session folder")?;
    let dir = tmp.path().join("session");
    let ready = match stand_in {
        None => hardware::prepare(&hw, &dir).map_err(out::failed)?,
        Some(s) => {
            let clock = HostClock::new();
            let link = TriggerLink::open(&hw.trigger_port, clock, LinkConfig::default())
                .with_context(|| format!("trigger.port {}", hw.trigger_port))?;
            let cam = StandInCamera {
                scene: s.scene.clone(),
                wire: s.wire.clone(),
                resolution: s.resolution,
                exposure_us: hw.board.exposure_us,
                flash_duration_us: hw.board.flash_duration_us,
                gain_db: f64::from(hw.settings.gain_db),
            };
            let camera = stand_in_camera(&cam, &link, clock)
                .map_err(out::failed)
                .with_context(|| format!("--sim-camera {}", s.scene.display()))?;
            hardware::prepare_with(&hw, &dir, clock, link, camera).map_err(out::failed)?
        }
    };
    let recorded = Recording { quiet: true }
        .record(ready)
        .map_err(out::failed)?;
    if let Some(signal) = recorded.signal {
        anyhow::bail!("the check was stopped by signal {signal}; nothing was kept");
    }
    let session = ellipso_session::reader::open(&recorded.dir)
        .with_context(|| format!("reading back the check's session {}", dir.display()))?;
    let check = flash_check::read(&session, n, recorded.report.clock.as_ref());
    drop(session);
    tmp.close()
        .context("removing the check's temporary session")?;
    Ok(check)
}
