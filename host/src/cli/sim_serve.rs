//! `ellipso sim serve SCENE --pty [--wire PATH] [--ber X]`: a virtual trigger board on a
//! pseudo-terminal ([`ellipso_rig::sim_serve`], whose doc is the contract). This parses the
//! flags, holds SIGINT/SIGTERM for a clean end, prints the endpoints on stdout (first line
//! `pty: /dev/pts/N`) and the board's one-line summary on stderr.

use std::io::Write;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use anyhow::Context;
use ellipso_rig::sim_serve;

use super::limits;

/// Arguments of `ellipso sim serve`.
#[derive(Debug, Clone, clap::Args)]
pub struct ServeArgs {
    /// Scene file (TOML): its seed and link faults drive the board.
    pub scene: PathBuf,
    /// Serve on a new pseudo-terminal and print its path (the only transport so far).
    #[arg(long)]
    pub pty: bool,
    /// Also publish the camera-trigger edges on this unix socket.
    #[arg(long, value_name = "PATH")]
    pub wire: Option<PathBuf>,
    /// Board → host bit error rate in [0, 0.5], overriding the scene's `link_corruption`.
    #[arg(long, value_name = "X", value_parser = |s: &str| limits::real_in(s, 0.0, 0.5))]
    pub ber: Option<f64>,
    /// Device clock rate error against the host, ppm.
    #[arg(long, default_value_t = 25.0, allow_negative_numbers = true, value_parser = limits::drift_ppm)]
    pub drift_ppm: f64,
    /// Device clock reading when serving starts, µs (default ≈ 11.6 days of uptime).
    #[arg(long, default_value_t = 1_000_000_000_000)]
    pub offset_us: u64,
}

/// `ellipso sim serve`: prints the endpoints on stdout, serves until SIGINT/SIGTERM.
pub fn run(args: ServeArgs) -> anyhow::Result<()> {
    // serving ends cleanly on the signal itself (the board's truth is printed)
    let _deferred = super::interrupt::Deferred::take();
    let stop = Arc::new(AtomicBool::new(false));
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(signal, stop.clone())
            .with_context(|| format!("cannot install the handler for signal {signal}"))?;
    }
    let options = sim_serve::ServeArgs {
        scene: args.scene,
        pty: args.pty,
        wire: args.wire,
        ber: args.ber,
        drift_ppm: args.drift_ppm,
        offset_us: args.offset_us,
    };
    let truth = sim_serve::serve(&options, &stop, |endpoints| {
        let mut out = std::io::stdout().lock();
        writeln!(out, "pty: {}", endpoints.pty)?;
        if let Some(w) = &endpoints.wire {
            writeln!(out, "wire: {}", w.display())?;
        }
        out.flush()?;
        Ok(())
    })
    .map_err(super::out::failed)?;
    crate::errln!(
        "sim serve: {} pulses, {} frames sent ({} corrupted, {} lost, {} stalled); {}",
        truth.pulses.len(),
        truth.frames_sent,
        truth.frames_corrupted,
        truth.frames_lost,
        truth.frames_stalled,
        truth.end_reason.as_deref().unwrap_or("ended")
    );
    Ok(())
}
