//! `ellipso bench chain` ([`run`]): the error budget of the whole chain on a scene — the runs of
//! [`crate::chain::budget_specs`] (the full chain, then one stage at a time replaced by its
//! truth), each fitted and scored by [`crate::chain::Bench::run`], and the report files.
//!
//! Contract: the frames render at half the scene's resolution unless one is given (as the demo
//! captures); with `runs` only those runs are made, and no report is written unless one is
//! named (without, the report is `docs/error-budget.md`); its JSON and its plot go beside it
//! (`.json`, `img/<stem>.png` in its folder). With `json`, every run's result is written there
//! as each finishes. Stages and results go to the caller's callbacks; nothing here prints.

use std::path::{Path, PathBuf};

use ellipso_run_error::ensure;
use ellipso_run_error::{Context, RunError};
use ellipso_sim::scene::Scene;

use crate::chain::{Bench, RunResult, budget_specs};
use crate::report::ReportMeta;

/// What `ellipso bench chain` runs (its flags, parsed by the binary).
#[derive(Debug, Clone)]
pub struct BudgetOptions {
    /// Scene (default: the shipped demo scene).
    pub scene: Option<PathBuf>,
    /// Work directory: rendered sessions are kept here and reused.
    pub work: PathBuf,
    /// Render at WIDTHxHEIGHT (default: half the scene's resolution).
    pub resolution: Option<[u32; 2]>,
    /// Rays per raw pixel per axis.
    pub supersampling: u32,
    /// Only the runs named here (all when empty).
    pub runs: Vec<String>,
    /// The report (Markdown); default module doc.
    pub report: Option<PathBuf>,
    /// Where to write the JSON of every run as they finish.
    pub json: Option<PathBuf>,
}

/// The report files written.
#[derive(Debug, Clone)]
pub struct BudgetFiles {
    /// The Markdown report.
    pub report: PathBuf,
    /// Its JSON.
    pub json: PathBuf,
    /// Its plot.
    pub png: PathBuf,
}

/// Makes the runs in turn (`stage` sees each stage as it starts, `finished` each result) and
/// writes the report; returns its files when one was written.
pub fn run(
    options: &BudgetOptions,
    stage: &mut dyn FnMut(&str),
    finished: &mut dyn FnMut(&RunResult),
) -> Result<Option<BudgetFiles>, RunError> {
    let scene_path = options
        .scene
        .clone()
        .unwrap_or_else(|| ellipso_sim::scene::shipped_scene("demo.toml"));
    let scene = Scene::load(&scene_path)?;
    let [w, h] = scene.rig.camera.resolution_px;
    let resolution = options.resolution.unwrap_or([w / 2, h / 2]);
    let bench = Bench {
        scene_path: scene_path.clone(),
        scene,
        work: options.work.clone(),
        resolution: Some(resolution),
        fit: ellipso_fit::session::SessionFitConfig::default(),
    };
    let mut specs = budget_specs(&bench.scene, options.supersampling);
    if !options.runs.is_empty() {
        specs.retain(|s| options.runs.contains(&s.name));
    }
    ensure!(
        !specs.is_empty(),
        "no run matches --runs {:?}",
        options.runs
    );
    let report = options.report.clone().or_else(|| {
        options
            .runs
            .is_empty()
            .then(|| PathBuf::from("docs/error-budget.md"))
    });
    let started = std::time::Instant::now();
    let mut results = Vec::new();
    for spec in &specs {
        let r = bench
            .run(spec, stage)
            .with_context(|| format!("run '{}'", spec.name))?;
        finished(&r);
        results.push(r);
        if let Some(path) = &options.json {
            std::fs::write(path, serde_json::to_vec_pretty(&results)?)
                .with_context(|| format!("writing {}", path.display()))?;
        }
    }
    let Some(path) = report else {
        return Ok(None);
    };
    let meta = ReportMeta {
        command: command_line(options),
        scene: scene_path.file_name().map_or_else(
            || scene_path.display().to_string(),
            |n| n.to_string_lossy().into(),
        ),
        resolution,
        photos: bench.scene.camera_poses.len(),
        supersampling: options.supersampling,
        total_s: started.elapsed().as_secs_f64(),
        threads: rayon::current_num_threads(),
    };
    let md = crate::report::markdown(&results, &meta);
    ellipso_report::atomic_file::write(&path, md.as_bytes())
        .with_context(|| format!("writing {}", path.display()))?;
    let json = path.with_extension("json");
    ellipso_report::atomic_file::write(&json, serde_json::to_vec_pretty(&(&meta, &results))?)
        .with_context(|| format!("writing {}", json.display()))?;
    let stem = path
        .file_stem()
        .map_or("error-budget".into(), |s| s.to_string_lossy());
    let png = path
        .parent()
        .unwrap_or_else(|| Path::new("."))
        .join("img")
        .join(format!("{stem}.png"));
    if let Some(dir) = png.parent() {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    crate::report::plot(&results, &png)?;
    Ok(Some(BudgetFiles {
        report: path,
        json,
        png,
    }))
}

/// The command that regenerates the report (as the report states it).
fn command_line(options: &BudgetOptions) -> String {
    let mut c = String::from("ellipso bench chain");
    if let Some(s) = &options.scene {
        c += &format!(" --scene {}", s.display());
    }
    if let Some([w, h]) = options.resolution {
        c += &format!(" --resolution {w}x{h}");
    }
    if options.supersampling != 2 {
        c += &format!(" --supersampling {}", options.supersampling);
    }
    if !options.runs.is_empty() {
        c += &format!(" --runs \"{}\"", options.runs.join(","));
    }
    c
}
