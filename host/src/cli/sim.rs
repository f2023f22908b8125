//! `ellipso sim …`: the simulator's command group.
//!
//! - `ellipso sim render SCENE --out DIR [--frames N | --frame I] [--truth]` renders a scene's
//!   capture as raw mosaic frames and its truth: [`ellipso_bench::sim_render`] (the files are
//!   listed there). `--width/--height` render at another resolution (intrinsics scaled) for a
//!   quick look.
//! - `ellipso sim plan SCENE [--json]` prints the effect plan: each stage, who runs it and why,
//!   and each stage left out with why.
//!
//! - `ellipso sim captures SCENE --out DIR` renders the sensor-calibration captures
//!   of the scene's camera and sensor effects (dark frames, flat fields at 8 levels, flats
//!   through a polariser sheet at 8 angles): [`ellipso_sim::calibration_captures`], the folder
//!   `ellipso calibrate sensor` reads.
//!
//! `serve` (the virtual trigger board on a pty) lives in [`super::sim_serve`].

use std::path::PathBuf;

use anyhow::anyhow;
use ellipso_bench::sim_render;
use ellipso_sim::effects::EffectPlan;
use ellipso_sim::scene::Scene;

use super::{limits, out, progress::Progress};

/// `ellipso sim` subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum Args {
    /// Render a scene's capture to raw mosaic PNGs plus ground truth.
    Render(RenderArgs),
    /// Print which simulation stages a scene needs, and why (and which it leaves out).
    Plan(PlanArgs),
    /// Serve the virtual trigger board (the real firmware core) on a pseudo-terminal.
    Serve(super::sim_serve::ServeArgs),
    /// Render the sensor-calibration captures (dark, flat, polariser-sheet frames) of a scene's
    /// camera, for `ellipso calibrate sensor`.
    Captures(CapturesArgs),
}

/// Arguments of `ellipso sim captures`.
#[derive(Debug, clap::Args)]
pub struct CapturesArgs {
    /// Scene file (TOML): its camera and sensor effects.
    pub scene: PathBuf,
    /// Output directory (created; must be empty or absent).
    #[arg(long)]
    pub out: PathBuf,
    /// Render width in pixels, even (intrinsics scaled; needs --height too).
    #[arg(long, requires = "height", value_parser = limits::side_px)]
    pub width: Option<u32>,
    /// Render height in pixels, even (intrinsics scaled; needs --width too).
    #[arg(long, requires = "width", value_parser = limits::side_px)]
    pub height: Option<u32>,
    /// Noise seed (default: the scene's seed).
    #[arg(long)]
    pub seed: Option<u64>,
}

/// Arguments of `ellipso sim render`.
#[derive(Debug, clap::Args)]
pub struct RenderArgs {
    /// Scene file (TOML).
    pub scene: PathBuf,
    /// Output directory (created if missing).
    #[arg(long)]
    pub out: PathBuf,
    /// Render only the first N frames, N ≥ 1.
    #[arg(long, conflicts_with = "frame", value_parser = limits::count::<usize>)]
    pub frames: Option<usize>,
    /// Render only frame I.
    #[arg(long)]
    pub frame: Option<usize>,
    /// Also write per-pixel truth (normal, depth, material) as .npy.
    #[arg(long)]
    pub truth: bool,
    /// Render width in pixels, even, 2..=16384 (intrinsics scaled; needs --height too).
    #[arg(long, requires = "height", value_parser = limits::side_px)]
    pub width: Option<u32>,
    /// Render height in pixels, even, 2..=16384 (intrinsics scaled; needs --width too).
    #[arg(long, requires = "width", value_parser = limits::side_px)]
    pub height: Option<u32>,
    /// N×N rays per raw pixel (anti-aliasing), 1..=8.
    #[arg(long, default_value_t = 2, value_parser = limits::supersampling)]
    pub supersampling: u32,
    /// Noise seed (default: the scene's seed).
    #[arg(long)]
    pub seed: Option<u64>,
}

/// Arguments of `ellipso sim plan`.
#[derive(Debug, clap::Args)]
pub struct PlanArgs {
    /// Scene file (TOML).
    pub scene: PathBuf,
    /// Print the plan as JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// Runs an `ellipso sim` subcommand.
pub fn run(args: Args) -> anyhow::Result<()> {
    match args {
        Args::Render(a) => render(a),
        Args::Plan(a) => plan(a),
        Args::Serve(a) => super::sim_serve::run(a),
        Args::Captures(a) => calibration_captures(a),
    }
}

fn calibration_captures(args: CapturesArgs) -> anyhow::Result<()> {
    use ellipso_sim::calibration_captures as cc;
    let scene = Scene::load(&args.scene).map_err(|e| anyhow!("{e}"))?;
    let options = ellipso_sim::render::RenderOptions {
        supersampling: 1,
        seed: args.seed,
        resolution_px: args.width.zip(args.height).map(|(w, h)| [w, h]),
        pixel_truth: false,
    };
    let plan = ellipso_bench::sensor_calibration::capture_plan(&scene).map_err(out::failed)?;
    let captures =
        cc::render(&scene, &plan, options).map_err(|e| anyhow!("{}: {e}", args.scene.display()))?;
    cc::write(&captures, &args.out).map_err(|e| anyhow!("{e}"))?;
    crate::outln!(
        "wrote {} calibration frames ({}×{}) and captures.json into {}",
        captures.frames.len(),
        captures.set.sensor.width,
        captures.set.sensor.height,
        args.out.display()
    );
    Ok(())
}

fn plan(args: PlanArgs) -> anyhow::Result<()> {
    let scene = Scene::load(&args.scene).map_err(|e| anyhow!("{e}"))?;
    let plan = EffectPlan::from_scene(&scene);
    if args.json {
        crate::outln!("{}", serde_json::to_string_pretty(&plan)?);
    } else {
        crate::out!("{}", plan.to_table());
    }
    Ok(())
}

fn render(args: RenderArgs) -> anyhow::Result<()> {
    let options = sim_render::RenderArgs {
        scene: args.scene,
        out: args.out,
        frames: args.frames,
        frame: args.frame,
        truth: args.truth,
        width: args.width,
        height: args.height,
        supersampling: args.supersampling,
        seed: args.seed,
    };
    let mut bar: Option<Progress> = None;
    let rendered = sim_render::render(&options, &mut |done, total| match &bar {
        None => bar = Some(Progress::bar("render", total as u64, "frames")),
        Some(b) => b.inc((done > 0) as u64),
    })
    .map_err(out::failed)?;
    if let Some(b) = bar {
        b.finish(format!(
            "{} frames into {}",
            rendered.frames,
            options.out.display()
        ));
    }
    crate::outln!(
        "rendered {} frame(s) of '{}' at {}×{} into {} (frame_NNNNN.png, truth.json{})",
        rendered.frames,
        rendered.scene,
        rendered.width_px,
        rendered.height_px,
        options.out.display(),
        if options.truth {
            ", normal/depth/material_NNNNN.npy"
        } else {
            ""
        }
    );
    Ok(())
}
