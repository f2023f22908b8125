//! Progress of the commands that take more than a second: an `indicatif` bar (or a spinner,
//! for work of unknown length) on stderr while stderr is a terminal, and in every case one
//! summary line on stderr when the work is done — so a log or a pipe gets one line per step,
//! not a bar's redraws, and stdout keeps only results.
//!
//! Contract: [`Progress::finish`] clears the bar and prints `label: summary (T s)`; dropping a
//! `Progress` without finishing (an error path) clears the bar and prints nothing.
//! [`Progress::hidden`] draws nothing and prints nothing (`--quiet`).

use std::fmt::Display;
use std::io::IsTerminal;
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// A running step's progress (see the module doc).
pub struct Progress {
    bar: ProgressBar,
    label: String,
    started: Instant,
    silent: bool,
}

impl Progress {
    /// A bar over `len` items of `unit` (e.g. "frames").
    pub fn bar(label: &str, len: u64, unit: &str) -> Self {
        let bar = ProgressBar::with_draw_target(Some(len), target());
        bar.set_style(
            ProgressStyle::with_template(&format!(
                "{{spinner}} {label} [{{bar:30}}] {{pos}}/{{len}} {unit} · {{elapsed}} (eta {{eta}}) {{msg}}"
            ))
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
        );
        Self::with(bar, label)
    }

    /// A spinner for work of unknown length; [`Progress::set_message`] names the current stage.
    pub fn spinner(label: &str) -> Self {
        let bar = ProgressBar::with_draw_target(None, target());
        bar.set_style(
            ProgressStyle::with_template(&format!("{{spinner}} {label} · {{elapsed}} · {{msg}}"))
                .unwrap_or_else(|_| ProgressStyle::default_spinner()),
        );
        bar.enable_steady_tick(Duration::from_millis(120));
        Self::with(bar, label)
    }

    /// Draws nothing and prints nothing.
    pub fn hidden() -> Self {
        Self {
            bar: ProgressBar::hidden(),
            label: String::new(),
            started: Instant::now(),
            silent: true,
        }
    }

    fn with(bar: ProgressBar, label: &str) -> Self {
        Self {
            bar,
            label: label.to_string(),
            started: Instant::now(),
            silent: false,
        }
    }

    /// Advances by `n` items.
    pub fn inc(&self, n: u64) {
        self.bar.inc(n);
    }

    /// Sets the position to `n` items.
    pub fn set_position(&self, n: u64) {
        self.bar.set_position(n);
    }

    /// The text after the bar (the current stage, rates, counts).
    pub fn set_message(&self, message: impl Into<String>) {
        self.bar.set_message(message.into());
    }

    /// Clears the bar and prints the one summary line.
    pub fn finish(self, summary: impl Display) {
        self.bar.finish_and_clear();
        if !self.silent {
            crate::errln!(
                "{}: {summary} ({:.1} s)",
                self.label,
                self.started.elapsed().as_secs_f64()
            );
        }
    }
}

impl Drop for Progress {
    fn drop(&mut self) {
        if !self.bar.is_finished() {
            self.bar.finish_and_clear();
        }
    }
}

/// A library run's long steps ([`ellipso_pipeline::steps::Steps`]) shown as one
/// [`Progress::spinner`] each; a step not ended is cleared when the next begins.
#[derive(Default)]
pub struct Spinners(Option<Progress>);

impl ellipso_pipeline::steps::Steps for Spinners {
    fn begin(&mut self, label: &str) {
        self.0 = Some(Progress::spinner(label));
    }
    fn stage(&mut self, name: &str) {
        if let Some(p) = &self.0 {
            p.set_message(name);
        }
    }
    fn end(&mut self, summary: &str) {
        if let Some(p) = self.0.take() {
            p.finish(summary);
        }
    }
}

/// stderr when it is a terminal, nothing otherwise.
fn target() -> ProgressDrawTarget {
    if std::io::stderr().is_terminal() {
        ProgressDrawTarget::stderr()
    } else {
        ProgressDrawTarget::hidden()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_and_finishes_without_a_terminal() {
        let p = Progress::bar("render", 3, "frames");
        p.inc(2);
        p.set_position(3);
        assert_eq!(p.bar.position(), 3);
        assert_eq!(p.bar.length(), Some(3));
        p.finish("3 frames");
        let s = Progress::spinner("fit");
        s.set_message("solving");
        drop(s);
        Progress::hidden().finish("nothing printed");
    }
}
