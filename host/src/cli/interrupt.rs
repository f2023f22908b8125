//! Ctrl-C (SIGINT), SIGTERM and SIGHUP (the terminal closed) in every stage of every command.
//!
//! Contract: [`install`] (called once by `main`) watches both signals for the whole run. Where a
//! stage stops cleanly on its own — a capture ends its session, `sim serve` closes its link —
//! it holds a [`Deferred`] guard and the watcher leaves the signal to it. Anywhere else (tracking,
//! meshing, fitting, rendering, writing results) the watcher removes the staging directory of
//! every output the run has not committed ([`ellipso_report::output::abandon_active`]), says so
//! in one line and ends the process with the shell's status 128 + signal: the previous output,
//! if any, is left as it was, and a recorded session keeps every whole line already appended.

use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;

use anyhow::Context;

/// Stages that handle the signals themselves, alive now.
static DEFERRED: AtomicUsize = AtomicUsize::new(0);

/// Starts watching SIGINT, SIGTERM and SIGHUP (see the module doc).
pub fn install() -> anyhow::Result<()> {
    let pending = Arc::new(AtomicUsize::new(0));
    for sig in [
        signal_hook::consts::SIGINT,
        signal_hook::consts::SIGTERM,
        signal_hook::consts::SIGHUP,
    ] {
        signal_hook::flag::register_usize(sig, pending.clone(), sig as usize)
            .with_context(|| format!("cannot install the handler for signal {sig}"))?;
    }
    std::thread::Builder::new()
        .name("signals".into())
        .spawn(move || {
            loop {
                std::thread::sleep(Duration::from_millis(25));
                // a signal that arrived while a stage handled it was that stage's
                let sig = pending.swap(0, Ordering::AcqRel);
                if sig != 0 && DEFERRED.load(Ordering::Acquire) == 0 {
                    stop(sig);
                }
            }
        })
        .context("cannot start the signal watcher")?;
    Ok(())
}

/// Ends the process on signal `sig` after removing uncommitted outputs.
fn stop(sig: usize) -> ! {
    ellipso_report::output::abandon_active();
    let name = match i32::try_from(sig).unwrap_or(0) {
        signal_hook::consts::SIGINT => "SIGINT",
        signal_hook::consts::SIGHUP => "SIGHUP",
        _ => "SIGTERM",
    };
    // stderr may be gone too (a closed terminal): nothing to do about it then
    let _ = std::io::Write::write_all(
        &mut std::io::stderr(),
        format!(
            "interrupted ({name}): stopped; no new output was kept (an earlier one is unchanged)\n"
        )
        .as_bytes(),
    );
    std::process::exit(128 + i32::try_from(sig).unwrap_or(0));
}

/// While alive, SIGINT and SIGTERM are left to the stage holding it.
pub struct Deferred(());

impl Deferred {
    /// Takes the signals over from the watcher.
    pub fn take() -> Self {
        DEFERRED.fetch_add(1, Ordering::AcqRel);
        Deferred(())
    }
}

impl Drop for Deferred {
    fn drop(&mut self) {
        DEFERRED.fetch_sub(1, Ordering::AcqRel);
    }
}

/// A run stopped by SIGINT or SIGTERM inside a stage that handles the signal itself, with
/// nothing to keep (the demo's capture); the process exits with 128 + the signal number.
#[derive(Debug, thiserror::Error)]
#[error(
    "interrupted by signal {signal}: stopped; no new output was kept (an earlier one is unchanged)"
)]
pub struct Stopped {
    /// The signal number.
    pub signal: i32,
}
