//! `ellipso capture --sim SCENE --out DIR` / `--rig RIG.toml`: a capture on the simulated or the
//! physical rig, recorded as a session.
//!
//! The capture itself is [`ellipso_capture`] (the simulated rig: the real firmware core in a
//! virtual board behind a real pseudo-terminal, or an external `ellipso sim serve` with
//! `--trigger PTY --wire SOCKET`, and the simulator's camera; the physical rig: the serial
//! trigger board and the camera backend of the rig file; then the poses tracked unless
//! `--no-track`), run with this binary's progress bar and signal handlers ([`Recording`]).
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
use ellipso_capture::Captured;
use ellipso_protocol::Bracket;
use ellipso_rig::acquire::ready::report_lines;
use ellipso_rig::acquire::sim_rig::{ExternalBoard, SimCaptureOptions};

/// Arguments of `ellipso capture`.
#[derive(Debug, Clone, clap::Args)]
#[command(group(clap::ArgGroup::new("source").required(true).args(["sim", "rig"])))]
pub struct Args {
    /// Scene file of the simulated rig (`sim/scenes/*.toml`).
    #[arg(long, value_name = "SCENE")]
    pub sim: Option<PathBuf>,
    /// Rig file of the physical rig (trigger port, camera backend and address, camera model,
    /// capture, boards; see `host/capture/src/rig_file.rs`).
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
    #[arg(long, value_name = "E1,E2,…", value_parser = ellipso_capture::bracket::parse_bracket)]
    pub bracket: Option<Bracket>,
    /// Show the live view in the browser while capturing (prints its URL; `docs/view.md`).
    #[arg(long)]
    pub view: bool,
    /// Object mesh for the live view's coverage (with `--view`; default: a dome proxy).
    #[arg(long, value_name = "MESH", requires = "view")]
    pub view_mesh: Option<PathBuf>,
}

/// Records the capture `args` ask for on the simulated rig or the rig file's physical rig
/// ([`ellipso_capture`]) with the progress bar and signal handlers, tracking its poses unless
/// `--no-track`.
fn capture(args: &Args) -> anyhow::Result<Captured> {
    let recorder = &mut Recording { quiet: false };
    let track = !args.no_track;
    if let Some(rig) = &args.rig {
        return ellipso_capture::hardware::capture(
            rig,
            &args.out,
            args.bracket,
            track,
            recorder,
            &out::Printed,
        )
        .map_err(out::failed);
    }
    let options = SimCaptureOptions {
        scene: args
            .sim
            .clone()
            .context("--sim SCENE is required for a simulated capture")?,
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
    ellipso_capture::sim::capture(&options, track, recorder, &out::Printed).map_err(out::failed)
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
    let captured = capture(&args)?;
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
