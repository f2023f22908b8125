//! `ellipso demo`: the main job on the simulated rig, end to end, in a few minutes on 2 cores —
//! capture, tracking, carving and fit, scored against the simulator's truth, with pictures and
//! a summary ([`ellipso_bench::demo`]). Here: the flags, the capture's progress bar and signal
//! handlers, the spinners, and the list of where everything is.

use std::path::PathBuf;

use ellipso_bench::demo::{DemoRequest, DemoRun};

use super::out;

/// Arguments of `ellipso demo`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Where to put the session and the results.
    #[arg(long, default_value = "ellipso-demo")]
    pub out: PathBuf,
    /// Scene to capture (default: the shipped four-material demo scene).
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Smaller and shorter: for a smoke test (the glass sphere scene unless --scene, quarter
    /// resolution, 24 photos).
    #[arg(long)]
    pub quick: bool,
    /// Take the photos at the scene's interval (a hand-held walk, 500 ms for the demo scene)
    /// instead of the fastest the rig allows (the flash's duty limit: 50 ms).
    #[arg(long)]
    pub real_time: bool,
}

/// Runs `ellipso demo`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let request = DemoRequest {
        out: args.out,
        scene: args.scene,
        quick: args.quick,
        real_time: args.real_time,
    };
    let done = ellipso_bench::demo::run(
        &request,
        &mut super::record::Recording { quiet: false },
        &mut super::progress::Spinners::default(),
        &out::Printed,
    )
    .map_err(out::failed)?;
    let r = match done {
        DemoRun::Done(report) => report,
        DemoRun::Stopped { signal } => return Err(super::interrupt::Stopped { signal }.into()),
    };
    let lines = [
        ("session (raw frames + event log) ", &r.session),
        ("polarisation images of frame 0   ", &r.polarisation),
        ("camera path plot                 ", &r.camera_path),
        ("fitted model (PLY, per vertex)   ", &r.fit_ply),
        (
            "fit pictures (maps, Mueller grid, relit, novel view) ",
            &r.fit_dir,
        ),
        ("summary                          ", &r.summary),
    ];
    crate::outln!("\nresults in {}:", r.published.display());
    for (what, path) in lines {
        crate::outln!("  {what} {}", path.display());
    }
    Ok(())
}
