//! "Never silently wrong", across processes: the `ellipso` binary on the inputs a hostile new
//! user tries (issue 16). Each test is the regression test of one defect:
//! - a capture at 20 fps pairs every frame with its own pulse (not the next one);
//! - `capture` refuses an `--out` that holds anything (an older recording above all);
//! - SIGINT / SIGTERM end a capture cleanly: frames in flight drained, end record written,
//!   the board stopped;
//! - `fit` refuses to report nothing, warns about and counts every skipped frame, and refuses a
//!   manifest whose sensor fields are impossible;
//! - pose appends start on a fresh line and frames without a pose are re-tracked;
//! - numeric flags are checked against the same limits as the files; a closed stdout ends the
//!   output, not the process.
//!
//! The tests are split by topic: `capture.rs` (pairing, refused outputs, signals), `flags.rs`
//! (numeric and path flags, documented flags) and `tracking.rs` (board families, tiny frames).

#[path = "cli_reliability/capture.rs"]
mod capture;
#[path = "cli_reliability/flags.rs"]
mod flags;
#[path = "cli_reliability/tracking.rs"]
mod tracking;

use std::path::Path;
use std::process::{Command, Output};

use ellipso_tests::ellipso_bin;

fn ellipso(args: &[&str]) -> Output {
    Command::new(ellipso_bin())
        .args(args)
        .output()
        .expect("run ellipso")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Every file under `dir` with its bytes (to prove nothing recorded changed).
fn snapshot(dir: &Path) -> Vec<(std::path::PathBuf, Vec<u8>)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap().filter_map(Result::ok) {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push((p.clone(), std::fs::read(&p).unwrap()));
            }
        }
    }
    out.sort();
    out
}
