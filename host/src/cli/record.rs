//! A ready capture recorded as the command line shows it: a progress bar (hidden when quiet or
//! not on a terminal) and the signal handlers of [`StopOnSignal`] — the binary's
//! [`Recorder`], for `ellipso capture`, the demo and `ellipso bench mesh`.
//!
//! Contract: SIGINT, SIGTERM and SIGHUP (the terminal closed) stop the capture cleanly (the
//! session is complete up to the stop, with its end record; [`Recorded::signal`] says which); a
//! second signal while it winds down ends the process.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use anyhow::Context;
use ellipso_rig::acquire::ready::{ReadyCapture, Recorded, Recorder};
use ellipso_run_error::RunError;

use super::progress::Progress;

/// Records with a progress bar (none when `quiet`) and the signal handlers.
pub struct Recording {
    /// No progress bar.
    pub quiet: bool,
}

impl Recorder for Recording {
    fn record(&mut self, ready: ReadyCapture) -> Result<Recorded, RunError> {
        let bar = if self.quiet {
            Progress::hidden()
        } else {
            Progress::bar("capture", u64::from(ready.photos()), "frames")
        };
        let stop = StopOnSignal::install().map_err(|e| RunError::from_boxed(e.into()))?;
        let result = ready.run(stop.flag(), |p| {
            bar.set_position(p.frames);
            bar.set_message(format!(
                "{:.1} fps · paired {} · pairing errors {} · flagged {}",
                p.fps, p.paired, p.pairing_errors, p.camera_drops
            ));
        });
        match &result {
            Ok((report, _)) => bar.finish(format!("{} frames", report.frames)),
            Err(_) => drop(bar),
        }
        let signal = stop.signal();
        drop(stop);
        let (report, dir) = result?;
        Ok(Recorded {
            report,
            dir,
            signal,
        })
    }
}

/// SIGINT, SIGTERM and SIGHUP stop a running capture cleanly: the stop flag is set, the board is told
/// to stop, frames in flight are drained and the end record written. A second SIGINT while it
/// winds down ends the process at once. Dropping this restores the default handling.
struct StopOnSignal {
    stop: Arc<AtomicBool>,
    signal: Arc<AtomicUsize>,
    ids: Vec<signal_hook::SigId>,
    /// The process-wide watcher leaves the signals to this capture (dropped after `ids`).
    _deferred: super::interrupt::Deferred,
}

impl StopOnSignal {
    fn install() -> anyhow::Result<Self> {
        use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
        let deferred = super::interrupt::Deferred::take();
        let stop = Arc::new(AtomicBool::new(false));
        let signal = Arc::new(AtomicUsize::new(0));
        let mut ids = Vec::new();
        for sig in [SIGINT, SIGTERM, SIGHUP] {
            let context = || format!("cannot install the handler for signal {sig}");
            // registered first, so it sees the flag as it was before this signal
            ids.push(
                signal_hook::flag::register_conditional_shutdown(sig, 130, stop.clone())
                    .with_context(context)?,
            );
            ids.push(
                signal_hook::flag::register_usize(sig, signal.clone(), sig as usize)
                    .with_context(context)?,
            );
            ids.push(signal_hook::flag::register(sig, stop.clone()).with_context(context)?);
        }
        Ok(Self {
            stop,
            signal,
            ids,
            _deferred: deferred,
        })
    }

    fn flag(&self) -> &AtomicBool {
        &self.stop
    }

    /// The signal that stopped the capture, if one did.
    fn signal(&self) -> Option<i32> {
        match self.signal.load(Ordering::Acquire) {
            0 => None,
            s => i32::try_from(s).ok(),
        }
    }
}

impl Drop for StopOnSignal {
    fn drop(&mut self) {
        for id in self.ids.drain(..) {
            signal_hook::low_level::unregister(id);
        }
    }
}
