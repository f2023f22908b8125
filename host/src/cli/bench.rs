//! `ellipso bench …`: the benchmarks' flags. Each subcommand parses its flags into the options
//! of one library function ([`ellipso_bench`]: `pose`, `accuracy_time`, `calibration`,
//! `view_cost`, `chain`) and prints through [`out::Printed`]; the bodies and their report files
//! live in the library.

use std::path::PathBuf;

use ellipso_bench::accuracy_time::AccuracyOptions;
use ellipso_bench::calibration::CalibrationOptions;
use ellipso_bench::pose::PoseOptions;
use ellipso_bench::view_cost::ViewOptions;
use ellipso_vision::track::DetectImage;

use super::{limits, out};

pub mod chain;
pub mod generalize;
pub mod mesh;

/// `ellipso bench` subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum Args {
    /// Pose accuracy and speed on rendered frames of a scene.
    Pose(PoseArgs),
    /// What accuracy costs in time: fit error against seconds on simulated captures with known
    /// truth (photo count, solver effort, vertex count sweeps); writes docs/accuracy-vs-time.md.
    Accuracy(AccuracyArgs),
    /// The error budget of the whole chain: rendered frames, mosaic, tracked poses, carved mesh
    /// and fit, then one stage at a time replaced by its truth; writes docs/error-budget.md.
    Chain(chain::ChainArgs),
    /// Camera calibration accuracy on a rendered calibration capture.
    Calibration(CalibrationArgs),
    /// The whole chain on procedurally generated scenes (seeds ≥ 1000 are the held-out ones
    /// whose figures count): coverage, per-material η error, normals, σ calibration; writes
    /// docs/generalize.md and docs/generalize.json.
    Generalize(generalize::GeneralizeArgs),
    /// Sensor calibration on simulated captures (dark, flat, polariser-sheet) of a real
    /// sensor: what `ellipso calibrate sensor` recovers against the simulator's truth, and
    /// `ellipso polar` with it against the ideal sensor; writes docs/sensor-calibration.{md,json}.
    Sensor(SensorCalibrationArgs),
    /// Built-in mesh (`ellipso mesh`) against the simulator's truth on the shipped scenes:
    /// Chamfer / Hausdorff distance, time and peak memory; writes docs/mesh-bench.md.
    Mesh(mesh::MeshArgs),
    /// What the live view costs a simulated capture: the same capture without and with `--view`.
    View(ViewArgs),
    /// A fit of a simulated session scored against the scene's truth: per material, the share
    /// of the visible surface (decided from the true geometry) with a full parameter set, η and
    /// normal errors over it, and how many true errors fall within the reported 1σ.
    Score(ScoreArgs),
}

/// Arguments of `ellipso bench sensor`.
#[derive(Debug, clap::Args)]
pub struct SensorCalibrationArgs {
    /// Folder of the report (`sensor-calibration.json`; the table of `sensor-calibration.md`
    /// is replaced between its markers).
    #[arg(long, default_value = "docs")]
    pub out: PathBuf,
    /// Scratch folder for the rendered captures (created; must be empty or absent).
    #[arg(long)]
    pub work: PathBuf,
    /// Views of the demo's path each end-to-end fit uses (the η and normal change with the
    /// calibration; three fits); 0 skips them.
    #[arg(long, default_value_t = ellipso_bench::sensor_calibration::ETA_SHIFT_PHOTOS)]
    pub photos: usize,
}

/// Runs `ellipso bench`.
pub fn run(args: Args) -> anyhow::Result<()> {
    match args {
        Args::Sensor(a) => {
            let r =
                ellipso_bench::sensor_calibration::run(&a.out, &a.work, a.photos, &out::Printed)
                    .map_err(out::failed)?;
            crate::outln!(
                "{}",
                serde_json::to_string_pretty(&r.recovered).unwrap_or_default()
            );
            crate::outln!("wrote {}", a.out.join("sensor-calibration.json").display());
            Ok(())
        }
        Args::Pose(a) => ellipso_bench::pose::run(
            &PoseOptions {
                scene: a.scene,
                frames: a.frames,
                resolution: a.resolution,
                seed: a.seed,
                out: a.out,
            },
            &out::Printed,
        )
        .map_err(out::failed),
        Args::Accuracy(a) => ellipso_bench::accuracy_time::run(
            AccuracyOptions {
                scenes: a.scenes,
                report: a.report,
                quick: a.quick,
                no_large: a.no_large,
                seed: a.seed,
                work: a.work,
                sweeps: a.sweeps,
                photos: a.photos,
                holdout: a.holdout,
            },
            &out::Printed,
        )
        .map_err(out::failed),
        Args::Calibration(a) => ellipso_bench::calibration::run(
            &CalibrationOptions {
                scene: a.scene,
                frames: a.frames,
                resolution: a.resolution,
                seed: a.seed,
                image: a.image,
                free_k3: a.free_k3,
                out: a.out,
            },
            &out::Printed,
        )
        .map_err(out::failed),
        Args::Chain(a) => chain::run(a),
        Args::Generalize(a) => generalize::run(a),
        Args::Score(a) => score(a),
        Args::Mesh(a) => mesh::run(a),
        Args::View(a) => ellipso_bench::view_cost::run(
            ViewOptions {
                scene: a.scene,
                photos: a.photos,
                interval_ms: a.interval_ms,
                resolution: a.resolution,
                runs: a.runs,
                bin: a.bin,
                keep_sessions: a.keep_sessions,
                out: a.out,
                children_cpu_s,
            },
            &out::Printed,
        )
        .map_err(out::failed),
    }
}

/// Arguments of `ellipso bench pose`.
#[derive(Debug, clap::Args)]
pub struct PoseArgs {
    /// Scene file.
    pub scene: PathBuf,
    /// Frames to render (spread over the capture path), ≥ 1.
    #[arg(long, default_value_t = 20, value_parser = limits::count::<usize>)]
    pub frames: usize,
    /// Render at WIDTHxHEIGHT instead of the scene's resolution (even sides, 2..=16384).
    #[arg(long, value_parser = limits::resolution)]
    pub resolution: Option<[u32; 2]>,
    /// Scene seed (capture poses of seeded paths and sensor noise); default the scene's.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Where to write pose-bench.json.
    #[arg(long, default_value = ".")]
    pub out: PathBuf,
}

/// Arguments of `ellipso bench accuracy`.
#[derive(Debug, clap::Args)]
pub struct AccuracyArgs {
    /// Scenes to sweep (default: the shipped sphere and multi-material scenes).
    #[arg(long, value_delimiter = ',')]
    pub scenes: Vec<PathBuf>,
    /// Report file (Markdown); plots and JSON are written beside it (plots under `img/`).
    #[arg(long, default_value = "docs/accuracy-vs-time.md")]
    pub report: PathBuf,
    /// Small sweep for a smoke test (few vertices and photos; no large run).
    #[arg(long)]
    pub quick: bool,
    /// Skip the large runs (100 000 vertices × 150 and × 300 views, 500 000 × 60).
    #[arg(long)]
    pub no_large: bool,
    /// Noise and normal-tilt seed.
    #[arg(long, default_value_t = 7)]
    pub seed: u64,
    /// Work directory of the end-to-end sweep's rendered sessions (kept and reused; shared with
    /// `ellipso bench chain`).
    #[arg(long, default_value = "ellipso-bench-chain")]
    pub work: PathBuf,
    /// Which sweeps to run (default all): photos, solver, vertices, bracket, large,
    /// end_to_end (rendered frames of the demo scene through tracking, carving and the fit).
    #[arg(long, value_delimiter = ',')]
    pub sweeps: Vec<String>,
    /// Photos of the solver and vertex sweeps (default 100; 25 with --quick).
    #[arg(long)]
    pub photos: Option<usize>,
    /// Fraction of the views held out of every fit and scored as a re-render (default 0.1).
    #[arg(long, default_value_t = 0.1)]
    pub holdout: f64,
}

/// Arguments of `ellipso bench calibration`.
#[derive(Debug, clap::Args)]
pub struct CalibrationArgs {
    /// Scene file (a board-only calibration capture).
    #[arg(default_value = "sim/scenes/calibration.toml")]
    pub scene: PathBuf,
    /// Frames to use (spread over the capture path; default all), ≥ 1.
    #[arg(long, value_parser = limits::count::<usize>)]
    pub frames: Option<usize>,
    /// Render at WIDTHxHEIGHT instead of the scene's resolution (even sides, 2..=16384).
    #[arg(long, value_parser = limits::resolution)]
    pub resolution: Option<[u32; 2]>,
    /// Scene seed (capture poses of seeded paths and sensor noise); default the scene's.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Detection image.
    #[arg(long, value_enum, default_value_t = DetectImage::S0)]
    pub image: DetectImage,
    /// Also estimate k3.
    #[arg(long)]
    pub free_k3: bool,
    /// Where to write calibration-bench.json.
    #[arg(long, default_value = ".")]
    pub out: PathBuf,
}

/// Arguments of `ellipso bench view`.
#[derive(Debug, clap::Args)]
pub struct ViewArgs {
    /// Scene file.
    #[arg(default_value = "sim/scenes/sphere.toml")]
    pub scene: PathBuf,
    /// Photos per capture.
    #[arg(long, default_value_t = 100)]
    pub photos: u32,
    /// Time between photos, ms (50: 20 fps).
    #[arg(long, default_value_t = 50)]
    pub interval_ms: u32,
    /// Frame size.
    #[arg(long, value_parser = limits::resolution, default_value = "306x256")]
    pub resolution: [u32; 2],
    /// Rounds (each: one capture without and one with the view).
    #[arg(long, default_value_t = 3)]
    pub runs: usize,
    /// The `ellipso` binary that captures (default: this one), e.g. an older build to compare.
    #[arg(long)]
    pub bin: Option<PathBuf>,
    /// Keep the recorded sessions (under OUT/view-bench-sessions).
    #[arg(long)]
    pub keep_sessions: bool,
    /// Where to write view-bench.json.
    #[arg(long, default_value = ".")]
    pub out: PathBuf,
}

/// CPU seconds (user + system) of this process's waited-for children.
fn children_cpu_s() -> f64 {
    #[cfg(unix)]
    {
        // SAFETY: getrusage writes one rusage into the zeroed struct it is given
        let usage = unsafe {
            let mut u: libc::rusage = std::mem::zeroed();
            libc::getrusage(libc::RUSAGE_CHILDREN, &mut u);
            u
        };
        let s = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
        s(usage.ru_utime) + s(usage.ru_stime)
    }
    #[cfg(not(unix))]
    {
        f64::NAN
    }
}

/// Arguments of `ellipso bench score`.
#[derive(Debug, clap::Args)]
pub struct ScoreArgs {
    /// The scene the session was captured from.
    #[arg(long)]
    pub scene: PathBuf,
    /// The scene seed the capture used (default the scene's).
    #[arg(long)]
    pub seed: Option<u64>,
    /// The session.
    #[arg(long)]
    pub session: PathBuf,
    /// The fit's folder (`fit.ply`, `fit-summary.json`).
    #[arg(long)]
    pub fit: PathBuf,
    /// Print one JSON object instead of the text.
    #[arg(long)]
    pub json: bool,
    /// Also write the truth beside every fitted vertex (material, visible frames, true η and
    /// normal, signed distance) to this file, one JSON object per line.
    #[arg(long)]
    pub vertices: Option<PathBuf>,
}

/// Runs `ellipso bench score`.
fn score(a: ScoreArgs) -> anyhow::Result<()> {
    let scene = ellipso_bench::pose::load_scene(&a.scene, a.seed).map_err(out::failed)?;
    let (scores, rows) =
        ellipso_bench::coverage::score_fit_dir(&scene, &a.session, &a.fit).map_err(out::failed)?;
    if let Some(path) = &a.vertices {
        let mut text = String::new();
        for r in &rows {
            text.push_str(&serde_json::to_string(r)?);
            text.push('\n');
        }
        std::fs::write(path, text)
            .map_err(|e| anyhow::anyhow!("writing {}: {e}", path.display()))?;
    }
    if a.json {
        println!("{}", serde_json::to_string_pretty(&scores)?);
    } else {
        println!(
            "{}: {} vertices, {} visible",
            a.fit.display(),
            scores.vertices,
            scores.visible
        );
        for line in ellipso_bench::coverage::describe(&scores) {
            println!("{line}");
        }
    }
    Ok(())
}
