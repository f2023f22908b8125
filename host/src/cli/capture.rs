//! `ellipso capture --sim SCENE --out DIR` / `--rig RIG.toml`: a capture on the simulated or the
//! physical rig, recorded as a session.
//!
//! The rigs are assembled in `ellipso-rig` ([`sim_rig::prepare`]: the real firmware core in a
//! virtual board behind a real pseudo-terminal, or an external `ellipso sim serve` with
//! `--trigger PTY --wire SOCKET`, and the simulator's camera; [`hardware::prepare`]: the serial
//! trigger board and the camera backend of the rig file) and run with this binary's progress bar
//! and signal handlers. After recording, poses are tracked and appended to the session
//! ([`process::track_and_append`]) unless `--no-track`; the session's rig record and boards come
//! from `ellipso-vision` too, so the binary composes the two crates (the rig crate does not link
//! the tracker).
//!
//! `--bracket 1,0.25,0.0625` asks the trigger board for a flash-energy bracket: frame `k` is lit
//! by step `k mod len` of the full pulse (the same exposure, a shorter LED on-time). 1 to 8
//! steps, each in (0, 1], in any order (they fire in the order given; start with the full pulse to
//! make the first frame of each cycle the brightest). `--photos` counts frames, so 600 photos with
//! a 3-step bracket are 200 per step. A simulated capture takes the scene's `capture.bracket`
//! unless `--bracket` is given; its camera renders every frame at the energy it really received.

use std::path::PathBuf;

use super::out;
use super::record::Recording;
use anyhow::Context;
use ellipso_protocol::Bracket;
use ellipso_rig::acquire::capture::CaptureReport;
use ellipso_rig::acquire::hardware::{self, HardwareRig};
use ellipso_rig::acquire::ready::{ReadyCapture, Recorded, Recorder, report_lines};
use ellipso_rig::acquire::sim_rig::{self, ExternalBoard, SimCaptureOptions};
use ellipso_rig::camera::CameraSettings;
use ellipso_vision::process;
use ellipso_vision::rig_file::{Backend, RigFile};

/// Arguments of `ellipso capture`.
#[derive(Debug, Clone, clap::Args)]
#[command(group(clap::ArgGroup::new("source").required(true).args(["sim", "rig"])))]
pub struct Args {
    /// Scene file of the simulated rig (`sim/scenes/*.toml`).
    #[arg(long, value_name = "SCENE")]
    pub sim: Option<PathBuf>,
    /// Rig file of the physical rig (trigger port, camera backend and address, camera model,
    /// capture, boards; see `host/vision/src/rig_file.rs`).
    #[arg(long, value_name = "RIG")]
    pub rig: Option<PathBuf>,
    /// Session directory to create.
    #[arg(long)]
    pub out: PathBuf,
    /// External trigger board (pty of `ellipso sim serve`, a serial device, or `unix:PATH`)
    /// instead of the in-process virtual board.
    #[arg(long, requires = "wire")]
    pub trigger: Option<String>,
    /// Trigger-wire socket of `ellipso sim serve --wire` (with `--trigger`).
    #[arg(long, requires = "trigger")]
    pub wire: Option<PathBuf>,
    /// Take only this many photos, ≥ 1 (default: the scene's capture path).
    #[arg(long, value_parser = super::limits::count::<u32>)]
    pub photos: Option<u32>,
    /// Render at WIDTHxHEIGHT instead of the scene's resolution (intrinsics scaled): even
    /// sides in 2..=16384, as in scene files.
    #[arg(long, value_parser = super::limits::resolution)]
    pub resolution: Option<[u32; 2]>,
    /// Rays per raw pixel per axis (N×N), 1..=8.
    #[arg(long, default_value_t = 2, value_parser = super::limits::supersampling)]
    pub supersampling: u32,
    /// Time between photos, ms, in (0, 3600000] (default: the scene's `capture.interval_ms`);
    /// the board checks it against the exposure before anything is recorded.
    #[arg(long, value_parser = super::limits::interval_ms)]
    pub interval_ms: Option<f64>,
    /// Skip pose tracking after recording.
    #[arg(long)]
    pub no_track: bool,
    /// Flash-energy bracket: relative energies in (0, 1], 1 to 8, comma-separated, fired in turn
    /// (e.g. `1,0.25,0.0625`). Default: the scene's `capture.bracket` (simulator), none (rig).
    #[arg(long, value_name = "E1,E2,…", value_parser = parse_bracket)]
    pub bracket: Option<Bracket>,
    /// Show the live view in the browser while capturing (prints its URL; `docs/view.md`).
    #[arg(long)]
    pub view: bool,
    /// Object mesh for the live view's coverage (with `--view`; default: a dome proxy).
    #[arg(long, value_name = "MESH", requires = "view")]
    pub view_mesh: Option<PathBuf>,
}

/// Parses `--bracket`: 1 to 8 comma-separated relative energies, each in (0, 1].
pub fn parse_bracket(s: &str) -> Result<Bracket, String> {
    let energies = s
        .split(',')
        .map(|v| {
            let v = v.trim();
            v.parse::<f64>()
                .map_err(|e| format!("'{v}' is not a number: {e}"))
        })
        .collect::<Result<Vec<f64>, String>>()?;
    let bracket = Bracket::from_relative(&energies).map_err(|e| e.to_string())?;
    if bracket.is_empty() {
        return Err("a bracket needs at least one step".into());
    }
    Ok(bracket)
}

/// Records a simulated capture into `args.out` ([`sim_rig::prepare`], the session's rig record
/// and boards from [`process`]), then records it and tracks its poses unless `--no-track`
/// ([`record_and_track`]).
pub fn capture_sim(args: &Args) -> anyhow::Result<Captured> {
    let scene = args
        .sim
        .clone()
        .context("--sim SCENE is required for a simulated capture")?;
    let options = SimCaptureOptions {
        scene,
        out: args.out.clone(),
        external: match (&args.trigger, &args.wire) {
            (Some(trigger), Some(wire)) => Some(ExternalBoard {
                trigger: trigger.clone(),
                wire: wire.clone(),
            }),
            _ => None,
        },
        photos: args.photos,
        resolution: args.resolution,
        supersampling: args.supersampling,
        interval_ms: args.interval_ms,
        bracket: args.bracket,
    };
    let ready = sim_rig::prepare(&options, |scene, camera| {
        (
            process::rig_record_of_scene(scene, camera),
            process::boards_of_scene(scene),
        )
    })
    .map_err(out::failed)?;
    record_and_track(ready, !args.no_track)
}

/// Records `ready` with a progress bar and the signal handlers ([`Recording`]), then tracks
/// the session's poses when `track` holds and no signal stopped the capture (after a stop by
/// signal the user wants the process to end: poses can be tracked later).
fn record_and_track(ready: ReadyCapture, track: bool) -> anyhow::Result<Captured> {
    let Recorded {
        report,
        dir,
        signal,
    } = Recording { quiet: false }
        .record(ready)
        .map_err(out::failed)?;
    let tracked = if track && signal.is_none() {
        Some(process::track_and_append(&dir, &out::Printed).map_err(out::failed)?)
    } else {
        None
    };
    Ok(Captured {
        report,
        dir,
        tracked,
        signal,
    })
}

/// A finished capture.
pub struct Captured {
    /// What happened.
    pub report: CaptureReport,
    /// The session directory.
    pub dir: PathBuf,
    /// Poses tracked after recording (unless `--no-track` or stopped by a signal).
    pub tracked: Option<Vec<process::TrackedFrame>>,
    /// The signal (SIGINT, SIGTERM) that stopped the capture, if one did.
    pub signal: Option<i32>,
}

/// A capture stopped by SIGINT or SIGTERM (the session is complete up to the stop); the process
/// exits with 128 + the signal number.
#[derive(Debug, thiserror::Error)]
#[error("capture stopped by signal {signal}; the session in {} is complete up to the stop (poses not tracked: run `ellipso replay` on it)", dir.display())]
pub struct Interrupted {
    /// The signal number.
    pub signal: i32,
    /// The session directory.
    pub dir: PathBuf,
}

/// Records a capture on the physical rig described by `--rig` ([`RigFile`] read here, then
/// [`hardware::prepare`]), then tracks its poses unless `--no-track`, the rig has no boards, or
/// a signal stopped it.
pub fn capture_hw(args: &Args) -> anyhow::Result<Captured> {
    let rig_path = args
        .rig
        .as_ref()
        .context("--rig RIG.toml is required for a hardware capture")?;
    let rig = RigFile::load(rig_path)?;
    ellipso_session::writer::check_fresh(&args.out)?;
    let boards = rig.boards()?;
    let mut board = rig.board_config();
    if let Some(bracket) = args.bracket {
        board.bracket = bracket;
    }
    let hardware_rig = HardwareRig {
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
        board,
        photos: rig.capture.photos,
        boards,
    };
    let ready = hardware::prepare(&hardware_rig, &args.out).map_err(out::failed)?;
    record_and_track(ready, !args.no_track && !hardware_rig.boards.is_empty())
}

/// Runs `ellipso capture`.
pub fn run(args: Args) -> anyhow::Result<()> {
    // The live view follows the session directory from its own threads (read-only).
    let view = if args.view {
        let v = ellipso_view::live::start_live(
            args.out.clone(),
            args.view_mesh.clone(),
            true,
            Default::default(),
        )
        .map_err(out::failed)?;
        crate::outln!("live view    open {}", v.server.url());
        Some(v)
    } else {
        None
    };
    let captured = if args.rig.is_some() {
        capture_hw(&args)?
    } else {
        capture_sim(&args)?
    };
    for line in report_lines(&captured.report) {
        crate::outln!("{line}");
    }
    if let Some(tracked) = &captured.tracked {
        let summary =
            ellipso_vision::replay::report(&captured.dir, Some(tracked)).map_err(out::failed)?;
        for line in summary.summary_lines() {
            crate::outln!("{line}");
        }
    }
    crate::outln!("session      {}", captured.dir.display());
    if let Some(signal) = captured.signal {
        return Err(Interrupted {
            signal,
            dir: captured.dir,
        }
        .into());
    }
    if view.is_some() && std::io::IsTerminal::is_terminal(&std::io::stdin()) {
        crate::outln!("live view    still open; press Enter to close it");
        let _ = std::io::stdin().read_line(&mut String::new());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bracket_argument_keeps_its_order_and_names_what_is_wrong() {
        let b = parse_bracket("1, 0.25,0.0625").unwrap();
        assert_eq!(b.steps_q15(), [0x8000, 0x2000, 0x0800]);
        let any_order = parse_bracket("0.25,1,0.5").unwrap();
        assert_eq!(any_order.steps_q15(), [0x2000, 0x8000, 0x4000]);
        for (bad, fragment) in [
            ("", "not a number"),
            ("1,,0.5", "not a number"),
            ("1,x", "'x' is not a number"),
            ("1,0", "step 1 is 0"),
            ("1.5", "(0, 1]"),
            ("-0.5", "(0, 1]"),
            ("nan", "(0, 1]"),
            ("1,1,1,1,1,1,1,1,1", "at most 8"),
            ("0.00001", "1/65536"),
        ] {
            let e = parse_bracket(bad).unwrap_err();
            assert!(e.contains(fragment), "{bad:?}: {e}");
        }
    }
}
