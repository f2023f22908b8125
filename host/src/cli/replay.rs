//! `ellipso replay DIR`: a recorded session through the same stages as a live capture.
//!
//! Prints what reading the session found, the capture's own figures and the pose tracking run
//! again ([`ellipso_vision::replay::report`]), and writes `replay.json` in `--out` (default:
//! `DIR/replay`). Deterministic: replaying twice writes identical files.

use std::path::PathBuf;

use anyhow::Context;
use ellipso_vision::replay;

/// Arguments of `ellipso replay`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Session directory.
    pub session: PathBuf,
    /// Where to write the replay report (default: SESSION/replay).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// Runs `ellipso replay`.
pub fn run(args: Args) -> anyhow::Result<()> {
    // a path that is no session is said as such first (opening reads only its manifest and log)
    ellipso_session::reader::open(&args.session)?;
    // the session's own `replay/` by default (docs/session-format.md, "Derived outputs")
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| args.session.join("replay"));
    let claimed = ellipso_report::output::OutputDir::claim_in_session(
        &out,
        "replay",
        &[&args.session],
        Some("replay"),
    )?;
    let r = replay::report(&args.session, None).map_err(super::out::failed)?;
    for line in r.summary_lines() {
        crate::outln!("{line}");
    }
    let path = claimed.path().join("replay.json");
    ellipso_report::atomic_file::write(&path, serde_json::to_vec_pretty(&r)?)
        .with_context(|| format!("writing {}", claimed.published(&path).display()))?;
    let published = claimed.commit()?;
    crate::outln!("report       {}", published.join("replay.json").display());
    Ok(())
}
