//! `ellipso sim …`: the simulator's command group.
//!
//! - `ellipso sim render SCENE --out DIR [--frames N | --frame I] [--truth]` renders a scene's
//!   capture as raw mosaic frames (`frame_00000.png`, 16-bit grey PNG holding the camera's
//!   unshifted DN, e.g. 0..=4095 for 12-bit), `truth.json` (per frame: pose, flash position,
//!   trigger time, camera, stage execution counts) and with `--truth` per-pixel truth as `.npy`
//!   (`normal_00000.npy` f32 H×W×3 world normals, `depth_00000.npy` f32 H×W camera z in metres
//!   with NaN for no hit, `material_00000.npy` u16 H×W material codes, see
//!   `ellipso_sim::render::truth`). `--width/--height` render at another resolution (intrinsics
//!   scaled) for a quick look.
//! - `ellipso sim plan SCENE [--json]` prints the effect plan: each stage, who runs it and why,
//!   and each stage left out with why.
//!
//! `serve` (the virtual trigger board on a pty) lives in [`super::sim_serve`].

use std::path::{Path, PathBuf};

use anyhow::{Context, anyhow, bail};
use ellipso_sim::effects::{EffectPlan, StageCounts};
use ellipso_sim::render::{FrameTruth, RenderOptions, RenderedFrame, Renderer};
use ellipso_sim::scene::Scene;
use serde::Serialize;

/// `ellipso sim` subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum Args {
    /// Render a scene's capture to raw mosaic PNGs plus ground truth.
    Render(RenderArgs),
    /// Print which simulation stages a scene needs, and why (and which it leaves out).
    Plan(PlanArgs),
    /// Serve the virtual trigger board (the real firmware core) on a pseudo-terminal.
    Serve(super::sim_serve::ServeArgs),
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
    #[arg(long, conflicts_with = "frame", value_parser = super::limits::count::<usize>)]
    pub frames: Option<usize>,
    /// Render only frame I.
    #[arg(long)]
    pub frame: Option<usize>,
    /// Also write per-pixel truth (normal, depth, material) as .npy.
    #[arg(long)]
    pub truth: bool,
    /// Render width in pixels, even, 2..=16384 (intrinsics scaled; needs --height too).
    #[arg(long, requires = "height", value_parser = super::limits::side_px)]
    pub width: Option<u32>,
    /// Render height in pixels, even, 2..=16384 (intrinsics scaled; needs --width too).
    #[arg(long, requires = "width", value_parser = super::limits::side_px)]
    pub height: Option<u32>,
    /// N×N rays per raw pixel (anti-aliasing), 1..=8.
    #[arg(long, default_value_t = 2, value_parser = super::limits::supersampling)]
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
    }
}

fn load(path: &Path) -> anyhow::Result<Scene> {
    Scene::load(path).map_err(|e| anyhow!("{e}"))
}

fn plan(args: PlanArgs) -> anyhow::Result<()> {
    let scene = load(&args.scene)?;
    let plan = EffectPlan::from_scene(&scene);
    if args.json {
        crate::outln!("{}", serde_json::to_string_pretty(&plan)?);
    } else {
        crate::out!("{}", plan.to_table());
    }
    Ok(())
}

/// One frame's entry in `truth.json`.
#[derive(Serialize)]
struct FrameEntry {
    file: String,
    #[serde(flatten)]
    truth: FrameTruth,
    stage_counts: StageCounts,
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pixel_truth_files: Vec<String>,
}

/// `truth.json`.
#[derive(Serialize)]
struct TruthFile<'a> {
    scene: String,
    sensor: &'a str,
    bit_depth: u8,
    exposure_us: f64,
    supersampling: u32,
    plan: &'a EffectPlan,
    frames: Vec<FrameEntry>,
}

/// Which frames to render.
fn frame_indices(args: &RenderArgs, count: usize) -> anyhow::Result<Vec<usize>> {
    match (args.frame, args.frames) {
        (Some(i), _) if i >= count => {
            bail!("--frame {i}: the scene's capture has {count} frames (0..{count})")
        }
        (Some(i), _) => Ok(vec![i]),
        (None, Some(n)) => Ok((0..n.min(count)).collect()),
        (None, None) => Ok((0..count).collect()),
    }
}

fn render(args: RenderArgs) -> anyhow::Result<()> {
    // claimed before rendering; written beside and swapped in whole
    let claimed =
        ellipso_report::output::OutputDir::claim(&args.out, "sim-render", &[&args.scene])?;
    let out = claimed.path().to_path_buf();
    let scene = load(&args.scene)?;
    let options = RenderOptions {
        supersampling: args.supersampling,
        seed: args.seed,
        resolution_px: args.width.zip(args.height).map(|(w, h)| [w, h]),
        pixel_truth: args.truth,
    };
    let renderer = Renderer::new(&scene, options).map_err(|e| anyhow!("{e}"))?;
    let indices = frame_indices(&args, renderer.frame_count())?;
    let progress = super::progress::Progress::bar("render", indices.len() as u64, "frames");
    let mut frames = Vec::with_capacity(indices.len());
    for &k in &indices {
        let f = renderer.render_frame(k).map_err(|e| anyhow!("{e}"))?;
        frames.push(write_frame(&out, k, &f)?);
        progress.inc(1);
    }
    progress.finish(format!(
        "{} frames into {}",
        indices.len(),
        args.out.display()
    ));
    let camera = &scene.rig.camera;
    let truth = TruthFile {
        scene: renderer.plan().scene.clone(),
        sensor: match renderer.layout() {
            ellipso_model::mosaic::SensorLayout::MonoPolar => "mono_polar",
            ellipso_model::mosaic::SensorLayout::ColourPolar => "colour_polar",
        },
        bit_depth: camera.bit_depth,
        exposure_us: camera.exposure_us,
        supersampling: args.supersampling,
        plan: renderer.plan(),
        frames,
    };
    let path = out.join("truth.json");
    ellipso_report::atomic_file::write(&path, serde_json::to_string_pretty(&truth)?)
        .with_context(|| format!("cannot write {}", claimed.published(&path).display()))?;
    claimed.commit()?;
    let c = renderer.camera();
    crate::outln!(
        "rendered {} frame(s) of '{}' at {}×{} into {} (frame_NNNNN.png, truth.json{})",
        indices.len(),
        truth.scene,
        c.width,
        c.height,
        args.out.display(),
        if args.truth {
            ", normal/depth/material_NNNNN.npy"
        } else {
            ""
        }
    );
    Ok(())
}

/// Writes one frame's PNG (and per-pixel truth); returns its `truth.json` entry.
fn write_frame(out: &Path, k: usize, f: &RenderedFrame) -> anyhow::Result<FrameEntry> {
    let file = format!("frame_{k:05}.png");
    let path = out.join(&file);
    let img = image::ImageBuffer::<image::Luma<u16>, _>::from_raw(f.width, f.height, f.raw())
        .ok_or_else(|| anyhow!("frame {k}: buffer does not match {}×{}", f.width, f.height))?;
    ellipso_report::atomic_file::write_png(&path, &img)
        .with_context(|| format!("cannot write {}", path.display()))?;
    let mut pixel_truth_files = Vec::new();
    if let Some(p) = &f.pixels {
        let (w, h) = (p.width as usize, p.height as usize);
        let normals: Vec<f32> = p.normal_world.iter().flatten().copied().collect();
        for (name, bytes) in [
            (
                format!("normal_{k:05}.npy"),
                ellipso_report::npy::encode(&[h, w, 3], &normals),
            ),
            (
                format!("depth_{k:05}.npy"),
                ellipso_report::npy::encode(&[h, w], &p.depth_m),
            ),
            (
                format!("material_{k:05}.npy"),
                ellipso_report::npy::encode(&[h, w], &p.material),
            ),
        ] {
            let path = out.join(&name);
            ellipso_report::atomic_file::write(&path, bytes)
                .with_context(|| format!("cannot write {}", path.display()))?;
            pixel_truth_files.push(name);
        }
    }
    Ok(FrameEntry {
        file,
        truth: f.truth.clone(),
        stage_counts: f.counts,
        pixel_truth_files,
    })
}

#[cfg(test)]
mod tests;
