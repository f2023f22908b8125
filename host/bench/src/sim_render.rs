//! `ellipso sim render SCENE --out DIR [--frames N | --frame I] [--truth]` ([`render`]): a
//! scene's capture as raw mosaic frames (`frame_00000.png`, 16-bit grey PNG holding the camera's
//! unshifted DN, e.g. 0..=4095 for 12-bit), `truth.json` (per frame: pose, flash position,
//! trigger time, camera, stage execution counts) and with `--truth` per-pixel truth as `.npy`
//! (`normal_00000.npy` f32 H×W×3 world normals, `depth_00000.npy` f32 H×W camera z in metres
//! with NaN for no hit, `material_00000.npy` u16 H×W material codes, see
//! `ellipso_sim::render::truth`). `width/height` render at another resolution (intrinsics
//! scaled) for a quick look. Here rather than in ellipso-sim: it writes through ellipso-report.

use std::path::{Path, PathBuf};

use ellipso_run_error::bail;
use ellipso_run_error::{Context, RunError};

/// The command's result.
type Result<T> = std::result::Result<T, RunError>;
use ellipso_sim::effects::{EffectPlan, StageCounts};
use ellipso_sim::render::{FrameTruth, RenderOptions, RenderedFrame, Renderer};
use ellipso_sim::scene::Scene;
use serde::Serialize;

/// What `ellipso sim render` renders (its flags, parsed by the binary).
#[derive(Debug, Clone)]
pub struct RenderArgs {
    /// Scene file (TOML).
    pub scene: PathBuf,
    /// Output directory (created if missing).
    pub out: PathBuf,
    /// Render only the first N frames, N ≥ 1.
    pub frames: Option<usize>,
    /// Render only frame I.
    pub frame: Option<usize>,
    /// Also write per-pixel truth (normal, depth, material) as .npy.
    pub truth: bool,
    /// Render width in pixels, even, 2..=16384 (intrinsics scaled; needs --height too).
    pub width: Option<u32>,
    /// Render height in pixels, even, 2..=16384 (intrinsics scaled; needs --width too).
    pub height: Option<u32>,
    /// N×N rays per raw pixel (anti-aliasing), 1..=8.
    pub supersampling: u32,
    /// Noise seed (default: the scene's seed).
    pub seed: Option<u64>,
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
fn frame_indices(args: &RenderArgs, count: usize) -> Result<Vec<usize>> {
    match (args.frame, args.frames) {
        (Some(i), _) if i >= count => {
            bail!("--frame {i}: the scene's capture has {count} frames (0..{count})")
        }
        (Some(i), _) => Ok(vec![i]),
        (None, Some(n)) => Ok((0..n.min(count)).collect()),
        (None, None) => Ok((0..count).collect()),
    }
}

/// What [`render`] rendered, for the caller to say.
#[derive(Debug, Clone)]
pub struct Rendered {
    /// Frames written.
    pub frames: usize,
    /// The scene's name (as `truth.json` records it).
    pub scene: String,
    /// The rendered size, pixels.
    pub width_px: u32,
    /// The rendered height, pixels.
    pub height_px: u32,
}

/// Renders the scene's capture into `args.out` (claimed first, swapped in whole);
/// `progress(done, total)` after each frame (and once with 0 before the first).
pub fn render(args: &RenderArgs, progress: &mut dyn FnMut(usize, usize)) -> Result<Rendered> {
    // claimed before rendering; written beside and swapped in whole
    let claimed =
        ellipso_report::output::OutputDir::claim(&args.out, "sim-render", &[&args.scene])?;
    let out = claimed.path().to_path_buf();
    let scene = Scene::load(&args.scene).map_err(RunError::msg)?;
    let options = RenderOptions {
        supersampling: args.supersampling,
        seed: args.seed,
        resolution_px: args.width.zip(args.height).map(|(w, h)| [w, h]),
        pixel_truth: args.truth,
    };
    let renderer = Renderer::new(&scene, options).map_err(RunError::msg)?;
    let indices = frame_indices(args, renderer.frame_count())?;
    progress(0, indices.len());
    let mut frames = Vec::with_capacity(indices.len());
    for &k in &indices {
        // the error's own line, as the command always said it (no causes appended)
        let f = renderer.render_frame(k).map_err(RunError::msg)?;
        frames.push(write_frame(&out, k, &f)?);
        progress(frames.len(), indices.len());
    }
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
    Ok(Rendered {
        frames: indices.len(),
        scene: truth.scene,
        width_px: c.width,
        height_px: c.height,
    })
}
/// Writes one frame's PNG (and per-pixel truth); returns its `truth.json` entry.
fn write_frame(out: &Path, k: usize, f: &RenderedFrame) -> Result<FrameEntry> {
    let file = format!("frame_{k:05}.png");
    let path = out.join(&file);
    let img = image::ImageBuffer::<image::Luma<u16>, _>::from_raw(f.width, f.height, f.raw())
        .ok_or_else(|| {
            RunError::msg(format!(
                "frame {k}: buffer does not match {}×{}",
                f.width, f.height
            ))
        })?;
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
