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

/// Every string in `value` that names an existing file or directory (written relative to the
/// working directory, or absolute) rewritten relative to `base`: the summaries' rule that a
/// path inside a summary file is relative to that file's own folder, so the folder can be moved
/// or read from anywhere. Other strings are left alone.
pub fn paths_relative_to(value: &mut serde_json::Value, base: &std::path::Path) {
    match value {
        serde_json::Value::String(s) => {
            let p = std::path::Path::new(s.as_str());
            let looks_like_path = s.contains(std::path::MAIN_SEPARATOR) || p.extension().is_some();
            if looks_like_path && p.exists() {
                if let Some(r) = relative_path(p, base) {
                    *s = r.display().to_string();
                }
            }
        }
        serde_json::Value::Array(a) => a.iter_mut().for_each(|v| paths_relative_to(v, base)),
        serde_json::Value::Object(o) => o.values_mut().for_each(|v| paths_relative_to(v, base)),
        _ => {}
    }
}

/// `path` relative to the directory `base` (both resolved; `..` where needed), or `None` when
/// either cannot be resolved.
pub fn relative_path(path: &std::path::Path, base: &std::path::Path) -> Option<std::path::PathBuf> {
    let path = path.canonicalize().ok()?;
    let base = base.canonicalize().ok()?;
    let common = path
        .components()
        .zip(base.components())
        .take_while(|(a, b)| a == b)
        .count();
    let mut out = std::path::PathBuf::new();
    for _ in base.components().skip(common) {
        out.push("..");
    }
    for c in path.components().skip(common) {
        out.push(c);
    }
    if out.as_os_str().is_empty() {
        out.push(".");
    }
    Some(out)
}

/// A library function's error as the binary's: its text and causes unchanged.
pub fn failed(e: ellipso_model::run_error::RunError) -> anyhow::Error {
    anyhow::anyhow!(e.into_boxed())
}

/// The library bodies' lines ([`ellipso_model::run_error::Say`]) printed as [`outln!`] and
/// [`errln!`] print them.
pub struct Printed;

impl ellipso_model::run_error::Say for Printed {
    fn out(&self, line: std::fmt::Arguments<'_>) {
        crate::outln!("{line}");
    }
    fn err(&self, line: std::fmt::Arguments<'_>) {
        crate::errln!("{line}");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn summary_paths_become_relative_to_the_summary_folder() {
        let tmp = tempfile::tempdir().unwrap();
        let out = tmp.path().join("demo").join("fit");
        std::fs::create_dir_all(&out).unwrap();
        let session = tmp.path().join("demo").join("session");
        std::fs::create_dir_all(&session).unwrap();
        std::fs::write(out.join("fit.ply"), b"x").unwrap();
        let mut v = serde_json::json!({
            "session": session.display().to_string(),
            "files": [out.join("fit.ply").display().to_string()],
            "note": "intact",
        });
        paths_relative_to(&mut v, &out);
        assert_eq!(v["session"], "../session");
        assert_eq!(v["files"][0], "fit.ply");
        assert_eq!(v["note"], "intact");
    }
}
