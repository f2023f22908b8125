//! `ellipso bench accuracy`: what accuracy costs in time — sweeps of photo count, solver effort
//! and vertex count on simulated captures with known truth (the sphere and the four-material
//! blob, 12-bit, shot + read noise), each run timed and scored against the truth, plus one large
//! run (100 000 vertices × 150 views) for throughput. Writes the report (Markdown table + two
//! PNG plots of error against seconds + JSON) — by default to `docs/accuracy-vs-time.md`.
//!
//! The `bracket` sweep (issue 18) compares, on the four-material blob and one photo budget in
//! seconds, one exposure (`multi_material.toml`, 200 photos at 500 ms) with the 3-step
//! flash-energy bracket (`multi_material_bracket.toml`, 600 photos, 1, ¼, 1⁄16 in turn), plus
//! the bracket scene's 600 views all at full energy (more views without the bracket), and scores
//! the clusters' σs and the samples kept at the lobe peak ([`crate::accuracy::specular`]).
//!
//! Every figure in one report comes from one run of this command on one machine, so ratios
//! between rows are meaningful even on a shared, noisy machine; absolute seconds are not
//! portable. The fit time is also reported divided by the time of one forward evaluation of
//! every observation, measured right after it in the same run.
//!
//! The sweeps and the command line are here; one timed, scored run is `run_one`, the report's
//! files (claims, plots, JSON) are `output`, its Markdown text `report`.

use std::path::{Path, PathBuf};
use std::time::Instant;

use ellipso_run_error::ensure;
use ellipso_run_error::{Context, RunError, Say};

mod output;
pub mod report;
mod run_one;

pub use run_one::RunResult;

use ellipso_fit::pipeline::FitConfig;
use ellipso_sim::scene::Scene;

use crate::accuracy::CaptureCase;
use output::{ReportFiles, write_report};
use run_one::one_run;

/// The commands' result.
type Result<T> = std::result::Result<T, RunError>;

/// Photo counts of the end-to-end sweep (the demo scene's capture path; 150 is its own).
const END_TO_END_PHOTOS: [usize; 3] = [50, 100, 150];

/// What `ellipso bench accuracy` runs (its flags, parsed by the binary).
#[derive(Debug, Clone)]
pub struct AccuracyOptions {
    /// Scenes to sweep (default: the shipped sphere and multi-material scenes).
    pub scenes: Vec<PathBuf>,
    /// Report file (Markdown); plots and JSON are written beside it (plots under `img/`).
    pub report: PathBuf,
    /// Small sweep for a smoke test (few vertices and photos; no large run).
    pub quick: bool,
    /// Skip the large runs (100 000 vertices × 150 and × 300 views, 500 000 × 60).
    pub no_large: bool,
    /// Noise and normal-tilt seed.
    pub seed: u64,
    /// Work directory of the end-to-end sweep's rendered sessions (kept and reused; shared with
    /// `ellipso bench chain`).
    pub work: PathBuf,
    /// Which sweeps to run (default all): photos, solver, vertices, bracket, large,
    /// end_to_end (rendered frames of the demo scene through tracking, carving and the fit).
    pub sweeps: Vec<String>,
    /// Photos of the solver and vertex sweeps (default 100; 25 with --quick).
    pub photos: Option<usize>,
    /// Fraction of the views held out of every fit and scored as a re-render (default 0.1).
    pub holdout: f64,
}

/// A solver setting of the effort sweep.
struct SolverSetting {
    label: &'static str,
    config: FitConfig,
}

fn solver_settings() -> Vec<SolverSetting> {
    let joint_only = |iterations: u32| {
        let mut c = FitConfig::joint_only();
        c.solver.max_iterations = iterations;
        c
    };
    vec![
        SolverSetting {
            label: "A, 12 iterations",
            config: joint_only(12),
        },
        SolverSetting {
            label: "A alone",
            config: FitConfig::joint_only(),
        },
        SolverSetting {
            label: "A, fast preset",
            config: FitConfig {
                solver: ellipso_fit::solve::SolverConfig::fast(),
                ..FitConfig::joint_only()
            },
        },
        SolverSetting {
            label: "A + B + C, 1 final pass (default)",
            config: FitConfig::default(),
        },
        SolverSetting {
            label: "A + B + C, 3 final passes",
            config: FitConfig::with_augmentation(3),
        },
    ]
}

/// The large runs (vertices, photos): the throughput target's 100 000 × 150, and 100 000 × 300
/// and 500 000 × 60, from which 500 000 × 300 is extrapolated.
pub const LARGE_RUNS: [(usize, usize); 3] = [(100_000, 150), (100_000, 300), (500_000, 60)];

/// Runs `ellipso bench accuracy`.
pub fn run(args: AccuracyOptions, say: &dyn Say) -> Result<()> {
    // the report's files are claimed before the hour of fitting, not after it
    let files = ReportFiles::claim(&args.report)?;
    let scenes = if args.scenes.is_empty() {
        vec![
            ellipso_sim::scene::shipped_scene("sphere.toml"),
            ellipso_sim::scene::shipped_scene("multi_material.toml"),
        ]
    } else {
        args.scenes.clone()
    };
    let (photo_sweep, subdivision_sweep, effort_photos): (Vec<usize>, Vec<u32>, usize) =
        if args.quick {
            (vec![25, 50], vec![2], args.photos.unwrap_or(25))
        } else {
            (
                vec![25, 50, 100, 200],
                vec![3, 4, 5],
                args.photos.unwrap_or(100),
            )
        };
    let wants = |sweep: &str| args.sweeps.is_empty() || args.sweeps.iter().any(|s| s == sweep);
    for s in &args.sweeps {
        ensure!(
            [
                "photos",
                "solver",
                "vertices",
                "bracket",
                "large",
                "end_to_end"
            ]
            .contains(&s.as_str()),
            "--sweeps: unknown sweep `{s}` (photos, solver, vertices, bracket, large, end_to_end)"
        );
    }
    ensure!(
        (0.0..0.9).contains(&args.holdout),
        "--holdout {}: must be in [0, 0.9)",
        args.holdout
    );
    let holdout = args.holdout;
    let base_subdivisions = if args.quick { Some(2) } else { None };
    let mut results = Vec::new();
    let started = Instant::now();
    for path in &scenes {
        let scene = Scene::load(path).with_context(|| format!("loading {}", path.display()))?;
        let name = scene
            .name
            .clone()
            .unwrap_or_else(|| path.display().to_string());
        let default = FitConfig::default();
        for &photos in photo_sweep.iter().filter(|_| wants("photos")) {
            let case = CaptureCase {
                photos,
                subdivisions: base_subdivisions,
                seed: args.seed,
                ..CaptureCase::default()
            };
            results.push(one_run(
                &scene, &name, "photos", "default", &case, &default, holdout, say,
            )?);
        }
        for setting in solver_settings().into_iter().filter(|_| wants("solver")) {
            let case = CaptureCase {
                photos: effort_photos,
                subdivisions: base_subdivisions,
                seed: args.seed,
                ..CaptureCase::default()
            };
            results.push(one_run(
                &scene,
                &name,
                "solver",
                setting.label,
                &case,
                &setting.config,
                holdout,
                say,
            )?);
        }
        for &s in subdivision_sweep.iter().filter(|_| wants("vertices")) {
            let case = CaptureCase {
                photos: effort_photos,
                subdivisions: Some(s),
                seed: args.seed,
                ..CaptureCase::default()
            };
            results.push(one_run(
                &scene, &name, "vertices", "default", &case, &default, holdout, say,
            )?);
        }
    }
    if wants("bracket") {
        results.extend(bracket_sweep(&args, base_subdivisions, holdout, say)?);
    }
    if !args.quick && !args.no_large && wants("large") {
        // Throughput and scale (issue 19): 100 000 × 150, then the two runs the 500 000 × 300
        // extrapolation rests on (report::scale_section).
        let scene = Scene::load(&ellipso_sim::scene::shipped_scene("sphere.toml"))?;
        for (vertices, photos) in LARGE_RUNS {
            let case = CaptureCase {
                photos,
                // Icosphere levels 7 and 8: 163 842 and 655 362 vertices, cut to `vertices`.
                subdivisions: Some(if vertices > 163_842 { 8 } else { 7 }),
                max_vertices: Some(vertices),
                seed: args.seed,
                ..CaptureCase::default()
            };
            results.push(one_run(
                &scene,
                "sphere",
                "large",
                "default",
                &case,
                &FitConfig::default(),
                holdout,
                say,
            )?);
        }
    }
    // What a capture really gives: rendered frames through the whole chain (not in --quick:
    // each capture renders 50–150 frames at 1224×1024).
    let end_to_end = if !args.quick && wants("end_to_end") {
        let scene_path = ellipso_sim::scene::shipped_scene("demo.toml");
        let scene = Scene::load(&scene_path)?;
        let [w, h] = scene.rig.camera.resolution_px;
        let bench = crate::chain::Bench {
            scene_path,
            scene,
            work: args.work.clone(),
            resolution: Some([w / 2, h / 2]),
            fit: ellipso_fit::session::SessionFitConfig::default(),
        };
        crate::chain::photo_sweep(&bench, &END_TO_END_PHOTOS, &mut |stage| {
            say.err(format_args!("  end to end: {stage}"))
        })?
    } else {
        Vec::new()
    };
    write_report(
        &files,
        &results,
        &end_to_end,
        started.elapsed().as_secs_f64(),
        &command_line(&args),
        say,
    )?;
    Ok(())
}

/// The `bracket` sweep (module doc): one exposure against the 3-step bracket on the same photo
/// budget in seconds, and the bracket scene's views at full energy. Each scene keeps its own
/// photo count (a third of it with `--quick`).
fn bracket_sweep(
    args: &AccuracyOptions,
    subdivisions: Option<u32>,
    holdout: f64,
    say: &dyn Say,
) -> Result<Vec<RunResult>> {
    let load = |name: &str| -> Result<Scene> {
        let path = ellipso_sim::scene::shipped_scene(name);
        Scene::load(&path).with_context(|| format!("loading {}", path.display()))
    };
    let single = load("multi_material.toml")?;
    let bracketed = load("multi_material_bracket.toml")?;
    let photos = |scene: &Scene| {
        let n = scene.camera_poses.len();
        if args.quick { n.div_ceil(3) } else { n }
    };
    let runs: [(&Scene, &str, Option<Vec<f64>>); 3] = [
        (&single, "one exposure", None),
        (&bracketed, "bracket", None),
        (&bracketed, "same views, full energy", Some(Vec::new())),
    ];
    let mut results = Vec::new();
    for (scene, label, bracket) in runs {
        let case = CaptureCase {
            photos: photos(scene),
            subdivisions,
            seed: args.seed,
            bracket,
            ..CaptureCase::default()
        };
        results.push(one_run(
            scene,
            "multi_material",
            "bracket",
            label,
            &case,
            &FitConfig::default(),
            holdout,
            say,
        )?);
    }
    Ok(results)
}

/// The command that reproduces a report made with `args` (options at their defaults left out).
fn command_line(args: &AccuracyOptions) -> String {
    let mut c = String::from("bench accuracy");
    let list = |v: &[String]| v.join(",");
    if !args.scenes.is_empty() {
        let scenes: Vec<String> = args
            .scenes
            .iter()
            .map(|p| p.display().to_string())
            .collect();
        c += &format!(" --scenes {}", list(&scenes));
    }
    if args.quick {
        c += " --quick";
    }
    if args.no_large {
        c += " --no-large";
    }
    if !args.sweeps.is_empty() {
        c += &format!(" --sweeps {}", list(&args.sweeps));
    }
    if args.seed != 7 {
        c += &format!(" --seed {}", args.seed);
    }
    if let Some(p) = args.photos {
        c += &format!(" --photos {p}");
    }
    if args.holdout != 0.1 {
        c += &format!(" --holdout {}", args.holdout);
    }
    if args.report != Path::new("docs/accuracy-vs-time.md") {
        c += &format!(" --report {}", args.report.display());
    }
    c
}
