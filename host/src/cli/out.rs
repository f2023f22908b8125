//! Standard output and standard error that a closed reader cannot kill.
//!
//! `ellipso fit … | head -1` closed the pipe after one line, and the next `println!` panicked
//! before any result was written (with `2>&1`, the next `eprintln!`). Every subcommand prints
//! through [`outln!`](crate::outln), [`out!`](crate::out) and [`errln!`](crate::errln) instead:
//! the first failed write to stdout (a broken pipe, a full disk behind a redirection) stops all
//! further printing — noted once on stderr unless the reader just went away, as other command
//! line tools stay quiet on EPIPE — and the work goes on, so results are still written and the
//! exit status still says how the work went. A failed write to stderr is dropped silently
//! (there is nowhere left to say it).

use std::fmt;
use std::io::Write;
use std::sync::atomic::{AtomicBool, Ordering};

static CLOSED: AtomicBool = AtomicBool::new(false);

/// Writes `args` to stdout unless an earlier write failed; a failing write closes the output.
pub fn write(args: fmt::Arguments<'_>) {
    if CLOSED.load(Ordering::Relaxed) {
        return;
    }
    let mut stdout = std::io::stdout().lock();
    if let Err(e) = stdout.write_fmt(args).and_then(|()| stdout.flush()) {
        if !CLOSED.swap(true, Ordering::Relaxed) && e.kind() != std::io::ErrorKind::BrokenPipe {
            // a reader that went away needs no note; anything else (a full disk) does
            let _ = writeln!(
                std::io::stderr(),
                "note: standard output failed ({e}); printing stopped"
            );
        }
    }
}

/// Writes `args` to stderr; a failure (stderr closed) is dropped.
pub fn write_err(args: fmt::Arguments<'_>) {
    let mut stderr = std::io::stderr().lock();
    let _ = stderr.write_fmt(args).and_then(|()| stderr.flush());
}

/// `eprintln!` that never panics on a closed stderr.
#[macro_export]
macro_rules! errln {
    ($($arg:tt)*) => {
        $crate::cli::out::write_err(format_args!("{}\n", format_args!($($arg)*)))
    };
}

/// `println!` that stops printing, instead of panicking, once stdout is closed.
#[macro_export]
macro_rules! outln {
    () => {
        $crate::cli::out::write(format_args!("\n"))
    };
    ($($arg:tt)*) => {
        $crate::cli::out::write(format_args!("{}\n", format_args!($($arg)*)))
    };
}

/// `print!` that stops printing, instead of panicking, once stdout is closed.
#[macro_export]
macro_rules! out {
    ($($arg:tt)*) => {
        $crate::cli::out::write(format_args!($($arg)*))
    };
}

/// A library function's error as the binary's: its text and causes unchanged.
pub fn failed(e: ellipso_run_error::RunError) -> anyhow::Error {
    anyhow::anyhow!(e.into_boxed())
}

/// The library bodies' lines ([`ellipso_run_error::Say`]) printed as [`outln!`] and
/// [`errln!`] print them.
pub struct Printed;

impl ellipso_run_error::Say for Printed {
    fn out(&self, line: std::fmt::Arguments<'_>) {
        crate::outln!("{line}");
    }
    fn err(&self, line: std::fmt::Arguments<'_>) {
        crate::errln!("{line}");
    }
}
