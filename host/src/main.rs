//! `ellipso`: capture a polarimetric SVBRDF with a hand-held flash rig, or with its simulator.

use clap::{Parser, Subcommand};
mod cli;
#[cfg(test)]
mod quoted_commands;

/// ellipso: Sparse Ellipsometry on a hand-held polarisation camera and flash.
#[derive(Debug, Parser)]
#[command(name = "ellipso", version, about, long_about = None)]
struct Cli {
    /// Print tracing logs (debug level) to stderr.
    #[arg(long, global = true)]
    verbose: bool,
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run the main job on the simulated rig: capture a shipped scene, then every later stage.
    Demo(cli::demo::Args),
    /// Capture a session on the simulated rig (`--sim SCENE`) or the physical one (`--rig RIG`).
    Capture(cli::capture::Args),
    /// Inspect the polarimetric model: Fresnel terms, diffuse DoP, Mueller matrices.
    Model(cli::model::Args),
    /// Turn one raw polarisation-mosaic frame into s0, DoLP, AoLP and observation-channel images.
    Polar(cli::polar::Args),
    /// Calibrate the camera (intrinsics, distortion) from a session of AprilTag board frames;
    /// `calibrate sensor`: the sensor (EMVA 1288 figures, per-pixel analysers) from captures.
    Calibrate(cli::calibrate::Args),
    /// Fit the per-vertex polarimetric SVBRDF and refined shape of a session to a mesh.
    Fit(cli::fit::Args),
    /// Merge the part files of a sharded fit (`fit --shard I/N`) and run its global steps.
    FitMerge(cli::fit_shard::MergeArgs),
    /// Carve the object's watertight mesh from a session's posed frames.
    Mesh(cli::mesh::Args),
    /// Write for other tools: a session as a COLMAP sparse model with undistorted images, or a
    /// fit as a Mitsuba 3 scene.
    #[command(subcommand)]
    Export(cli::export::Args),
    /// Benchmarks that write reports (pose accuracy and speed; the fit's accuracy vs time).
    #[command(subcommand)]
    Bench(cli::bench::Args),
    /// AprilTag boards to print (`board print`, `board new`); the trigger board's firmware
    /// (`board flash`).
    #[command(subcommand)]
    Board(cli::board::Args),
    /// What is attached and answers: trigger boards (asked over the protocol), boards in DFU
    /// mode, video devices and, with --gige, GigE cameras; `--json` too.
    Devices(cli::devices::Args),
    /// Rig files: write one to start from (`rig init`), check one and its trigger board
    /// (`rig check`).
    #[command(subcommand)]
    Rig(cli::rig::Args),
    /// Replay a recorded session through the stages after capture (pose tracking).
    Replay(cli::replay::Args),
    /// Recorded sessions: upgrade one written by an older ellipso.
    #[command(subcommand)]
    Session(cli::session::Args),
    /// The simulator: render a scene's capture, or show which effects it needs.
    #[command(subcommand)]
    Sim(cli::sim::Args),
    /// A local web page: the live capture of a session, or a fitted material in 3-D.
    View(cli::view::Args),
}

fn main() -> std::process::ExitCode {
    cli::allocator::tune();
    let cli = Cli::parse();
    let filter = if cli.verbose { "debug" } else { "warn" };
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(filter)),
        )
        .with_writer(std::io::stderr)
        // colour codes only for a terminal: never into a log file or a pipe
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        // a closed stderr must not turn into a panic (its default reports write errors there)
        .log_internal_errors(false)
        .init();
    if let Err(e) = cli::interrupt::install() {
        errln!("error: {e:#}");
        return std::process::ExitCode::FAILURE;
    }
    // one clear line: the error and its causes, joined
    match run(cli.command) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            // a capture stopped by SIGINT/SIGTERM: the shell's 128 + signal
            if let Some(i) = e.downcast_ref::<cli::capture::Interrupted>() {
                errln!("{i}");
                return std::process::ExitCode::from(
                    u8::try_from(128 + i.signal).unwrap_or(u8::MAX),
                );
            }
            if let Some(i) = e.downcast_ref::<cli::interrupt::Stopped>() {
                errln!("{i}");
                return std::process::ExitCode::from(
                    u8::try_from(128 + i.signal).unwrap_or(u8::MAX),
                );
            }
            errln!("error: {}", one_line(&e));
            std::process::ExitCode::FAILURE
        }
    }
}

/// The error and its causes joined with ": ", each cause said once: a cause whose text its
/// parent already quotes (an OS error inside a message naming the file) is not repeated.
/// Control characters (a terminal escape quoted from a file) are printed escaped, never sent
/// to the terminal.
fn one_line(e: &anyhow::Error) -> String {
    let mut line = String::new();
    let mut last = String::new();
    for cause in e.chain() {
        let text = cause.to_string();
        if !last.is_empty() && last.contains(&text) {
            continue;
        }
        if !line.is_empty() {
            line.push_str(": ");
        }
        line.push_str(&text);
        last = text;
    }
    line.chars()
        .flat_map(|c| {
            let escaped = (c.is_control() && c != '\n' && c != '\t')
                .then(|| c.escape_default().collect::<String>());
            escaped
                .unwrap_or_else(|| c.to_string())
                .chars()
                .collect::<Vec<_>>()
        })
        .collect()
}

fn run(command: Command) -> anyhow::Result<()> {
    match command {
        Command::Demo(args) => cli::demo::run(args),
        Command::Capture(args) => cli::capture::run(args),
        Command::Model(args) => cli::model::run(args),
        Command::Polar(args) => cli::polar::run(args),
        Command::Replay(args) => cli::replay::run(args),
        Command::Session(args) => cli::session::run(args),
        Command::Board(args) => cli::board::run(args),
        Command::Rig(args) => cli::rig::run(args),
        Command::Devices(args) => cli::devices::run(args),
        Command::Bench(args) => cli::bench::run(args),
        Command::Calibrate(args) => cli::calibrate::run(args),
        Command::Fit(args) => cli::fit::run(args),
        Command::FitMerge(args) => cli::fit_shard::run_merge(args),
        Command::Mesh(args) => cli::mesh::run(args),
        Command::Export(args) => cli::export::run(args),
        Command::Sim(args) => cli::sim::run(args),
        Command::View(args) => cli::view::run(args),
    }
}
