//! `ellipso sim serve SCENE --pty [--wire PATH] [--ber X]` ([`serve`]): a virtual trigger board on a
//! pseudo-terminal, for running the host (or another process) against the simulator.
//!
//! Contract:
//! - Creates a pty pair; the virtual board (the real firmware core, `ellipso_sim::rig`) owns the
//!   master end; the first line on stdout is `pty: /dev/pts/N` (the path a host opens like a
//!   serial port), then `wire: PATH` when `--wire` is given, then stdout is flushed. Everything
//!   else goes to stderr.
//! - The scene gives the seed and the link faults (`effects.link_corruption`,
//!   `effects.link_disconnect`); `--ber` overrides the board → host bit error rate.
//! - `--wire PATH` publishes every camera-trigger edge on a unix socket (16-byte records, see
//!   `ellipso_sim::rig::wire`) for simulated cameras in other processes.
//! - Serves until SIGINT or SIGTERM (then both outputs go low, the socket file is removed, and
//!   a one-line summary goes to stderr), or until the scene's permanent disconnect closes the
//!   link. The command keeps its own handle on the pty's device end, so a host may close and
//!   reopen the path any number of times; the board keeps its state in between, like a real board
//!   on a USB hub. Frames the board sends while no host is reading wait in the pty (a few KiB),
//!   then are dropped and counted.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use ellipso_run_error::bail;
use ellipso_run_error::{Context, RunError};
use ellipso_sim::rig::{BoardTruth, VirtualBoard, VirtualBoardConfig, WireServer, wire};
use ellipso_sim::scene::Scene;
use serialport::{SerialPort, TTYPort};

/// What `ellipso sim serve` serves (its flags, parsed by the binary).
#[derive(Debug, Clone)]
pub struct ServeArgs {
    /// Scene file (TOML): its seed and link faults drive the board.
    pub scene: PathBuf,
    /// Serve on a new pseudo-terminal and print its path (the only transport so far).
    pub pty: bool,
    /// Also publish the camera-trigger edges on this unix socket.
    pub wire: Option<PathBuf>,
    /// Board → host bit error rate in [0, 0.5], overriding the scene's `link_corruption`.
    pub ber: Option<f64>,
    /// Device clock rate error against the host, ppm.
    pub drift_ppm: f64,
    /// Device clock reading when serving starts, µs (default ≈ 11.6 days of uptime).
    pub offset_us: u64,
}

/// Where a running server can be reached.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ServeEndpoints {
    /// The pty path a host opens.
    pub pty: String,
    /// The trigger-wire socket, if any.
    pub wire: Option<PathBuf>,
}

/// Runs the server until `stop` is set or the board ends by itself; `ready` is called once with
/// the endpoints as soon as a host may connect. Returns what the board did.
pub fn serve(
    args: &ServeArgs,
    stop: &AtomicBool,
    ready: impl FnOnce(&ServeEndpoints) -> std::io::Result<()>,
) -> Result<BoardTruth, RunError> {
    if !args.pty {
        bail!("sim serve needs a transport: pass --pty (the only one so far)");
    }
    let scene = Scene::load(&args.scene)
        .with_context(|| format!("cannot load scene {}", args.scene.display()))?;
    let mut config = VirtualBoardConfig::from_scene(&scene);
    config.clock_drift_ppm = args.drift_ppm;
    config.clock_offset_us = args.offset_us;
    if let Some(ber) = args.ber {
        config.link.ber_to_host = ber;
    }
    let (mut master, device_end) = TTYPort::pair().context("cannot create a pseudo-terminal")?;
    let pty = device_end
        .name()
        .context("the pseudo-terminal has no path")?;
    // Short timeouts: the board's reader checks its stop flag, its writer never blocks long.
    master
        .set_timeout(Duration::from_millis(20))
        .context("cannot set the pty timeout")?;
    let reader = master
        .try_clone_native()
        .context("cannot clone the pty master")?;
    let (edges, wire_server) = match &args.wire {
        Some(path) => {
            let (tx, rx) = wire::wire();
            (Some(tx), Some(WireServer::bind(path, rx)?))
        }
        None => (None, None),
    };
    let board = VirtualBoard::spawn(config, Box::new(reader), Box::new(master), edges)?;
    ready(&ServeEndpoints {
        pty,
        wire: args.wire.clone(),
    })
    .context("cannot print the endpoints")?;
    while !stop.load(Ordering::Acquire) && !board.is_finished() {
        std::thread::sleep(Duration::from_millis(20));
    }
    let truth = board.shutdown();
    if let Some(w) = wire_server {
        w.shutdown();
    }
    drop(device_end);
    Ok(truth)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::link::{LinkConfig, TriggerLink};
    use ellipso_session::time::HostClock;
    use std::sync::Arc;

    fn scene_file(dir: &std::path::Path) -> PathBuf {
        let path = dir.join("scene.toml");
        std::fs::write(
            &path,
            r#"
seed = 5
[materials.matte]
eta = 1.5
sigma_s = 0.3
sigma_ss = 0.5
rho_s = 0.2
rho_ss = [0.0, 0.0, 0.0]
rho_d = [0.5, 0.5, 0.5]
[[objects]]
name = "ball"
shape = "sphere"
radius_m = 0.03
pose = { translation_m = [0.0, 0.0, 0.03] }
material = "matte"
[rig.camera]
resolution_px = [64, 48]
fx_px = 60.0
fy_px = 60.0
cx_px = 32.0
cy_px = 24.0
sensor = "mono_polar"
exposure_us = 1000.0
[capture]
path = "orbit"
photo_count = 4
look_at_m = [0.0, 0.0, 0.03]
radius_m = 0.45
elevation_deg = [30.0, 60.0]
"#,
        )
        .unwrap();
        path
    }

    #[test]
    fn serves_a_pty_a_host_can_open_twice_and_stops_on_request() {
        let dir = tempfile::tempdir().unwrap();
        let args = ServeArgs {
            scene: scene_file(dir.path()),
            pty: true,
            wire: Some(dir.path().join("wire.sock")),
            ber: None,
            drift_ppm: 25.0,
            offset_us: 1_000_000_000_000,
        };
        let stop = Arc::new(AtomicBool::new(false));
        let (tx, rx) = std::sync::mpsc::channel();
        let server = {
            let stop = stop.clone();
            std::thread::spawn(move || {
                serve(&args, &stop, |e| {
                    tx.send(e.clone()).map_err(std::io::Error::other)
                })
            })
        };
        let Ok(endpoints) = rx.recv_timeout(Duration::from_secs(10)) else {
            panic!("the server did not start: {:?}", server.join());
        };
        assert!(endpoints.pty.starts_with("/dev/pts/"), "{}", endpoints.pty);
        assert!(endpoints.wire.as_ref().unwrap().exists());
        // A camera in "another process" listens on the wire socket.
        let edges = ellipso_sim::rig::connect_wire(endpoints.wire.as_ref().unwrap()).unwrap();
        for round in 0..2 {
            let link =
                TriggerLink::open(&endpoints.pty, HostClock::new(), LinkConfig::default()).unwrap();
            assert_eq!(link.board().board_name.as_str(), "ellipso-virtual");
            for _ in 0..3 {
                link.ping().unwrap();
            }
            if round == 1 {
                // The board kept serving across the host's reopen; run a short capture.
                let config = ellipso_protocol::CaptureConfig {
                    exposure_us: 1_000,
                    flash_delay_us: 100,
                    flash_duration_us: 500,
                    frame_period_us: 25_000,
                    pulses: ellipso_protocol::PulseCount::Count(3),
                    trigger: ellipso_protocol::TriggerSource::FreeRun,
                    report_edges: false,
                    bracket: ellipso_protocol::Bracket::NONE,
                };
                link.configure(config).unwrap();
                link.arm().unwrap();
                link.start().unwrap();
                let mut triggers = Vec::new();
                while triggers.len() < 3 {
                    match link.events().recv_timeout(Duration::from_secs(5)).unwrap() {
                        crate::link::LinkEvent::Pulse { event, .. } => {
                            triggers.push(event.t_trigger_us)
                        }
                        crate::link::LinkEvent::Disconnected { reason } => panic!("{reason}"),
                        _ => {}
                    }
                }
                // 3 pulses × (trigger ↑↓, flash ↑↓): the flash's light crosses the socket too.
                let wire: Vec<_> = (0..12)
                    .map(|_| edges.recv_timeout(Duration::from_secs(5)).unwrap())
                    .collect();
                let rising: Vec<u64> = wire
                    .iter()
                    .filter(|e| e.rising && e.output == ellipso_protocol::Output::CameraTrigger)
                    .map(|e| e.t_device_us)
                    .collect();
                let lit: Vec<u64> = wire
                    .iter()
                    .filter(|e| e.output == ellipso_protocol::Output::Flash)
                    .collect::<Vec<_>>()
                    .chunks(2)
                    .map(|p| p[1].t_device_us - p[0].t_device_us)
                    .collect();
                assert_eq!(lit, [500; 3]);
                assert_eq!(
                    rising, triggers,
                    "the wire's rising edges are the pulses' triggers"
                );
            }
            drop(link);
        }
        stop.store(true, Ordering::Release);
        let truth = server.join().unwrap().unwrap();
        assert_eq!(truth.end_reason.as_deref(), Some("stopped by its owner"));
        assert!(!dir.path().join("wire.sock").exists());
    }

    #[test]
    fn refuses_to_run_without_a_transport_or_scene() {
        let dir = tempfile::tempdir().unwrap();
        let mut args = ServeArgs {
            scene: scene_file(dir.path()),
            pty: false,
            wire: None,
            ber: None,
            drift_ppm: 25.0,
            offset_us: 0,
        };
        let stop = AtomicBool::new(true);
        let e = serve(&args, &stop, |_| Ok(())).unwrap_err().to_string();
        assert!(e.contains("--pty"), "{e}");
        args.pty = true;
        args.scene = dir.path().join("missing.toml");
        let e = serve(&args, &stop, |_| Ok(())).unwrap_err().to_string();
        assert!(e.contains("missing.toml"), "{e}");
    }
}
