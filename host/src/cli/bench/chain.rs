//! `ellipso bench chain`: the error budget of the whole chain on a scene (`ellipso_bench::chain`):
//! the full chain, then one stage at a time replaced by its truth; prints one row per run and
//! writes the report.

use std::path::PathBuf;

use anyhow::Context;
use ellipso_bench::chain::{Bench, RunResult, budget_specs};
use ellipso_sim::scene::Scene;

/// Arguments of `ellipso bench chain`.
#[derive(Debug, clap::Args)]
pub struct ChainArgs {
    /// Scene (default: the shipped demo scene).
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Work directory: rendered sessions are kept here and reused.
    #[arg(long, default_value = "ellipso-bench-chain")]
    pub work: PathBuf,
    /// Render at WIDTHxHEIGHT (default: half the scene's resolution, as the demo captures).
    #[arg(long, value_parser = crate::cli::limits::resolution)]
    pub resolution: Option<[u32; 2]>,
    /// Rays per raw pixel per axis, 1..=8 (default 2, as the demo).
    #[arg(long, default_value_t = 2, value_parser = crate::cli::limits::supersampling)]
    pub supersampling: u32,
    /// Only the runs named here (comma-separated, whole names as the report lists them).
    #[arg(long, value_delimiter = ',')]
    pub runs: Vec<String>,
    /// Where to write the report (default docs/error-budget.md when every run is made; with
    /// --runs, none unless given). Its JSON and plot go beside it (`.json`, and
    /// `img/<stem>.png` in its folder).
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Where to write the JSON of every run as they finish.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// Runs `ellipso bench chain`.
pub fn run(args: ChainArgs) -> anyhow::Result<()> {
    let scene_path = args
        .scene
        .clone()
        .unwrap_or_else(|| ellipso_sim::scene::shipped_scene("demo.toml"));
    let scene = Scene::load(&scene_path)?;
    let [w, h] = scene.rig.camera.resolution_px;
    let resolution = args.resolution.unwrap_or([w / 2, h / 2]);
    let bench = Bench {
        scene_path: scene_path.clone(),
        scene,
        work: args.work.clone(),
        resolution: Some(resolution),
        fit: ellipso_fit::session::SessionFitConfig::default(),
    };
    let mut specs = budget_specs(&bench.scene, args.supersampling);
    if !args.runs.is_empty() {
        specs.retain(|s| args.runs.contains(&s.name));
    }
    anyhow::ensure!(!specs.is_empty(), "no run matches --runs {:?}", args.runs);
    let report = args.report.clone().or_else(|| {
        args.runs
            .is_empty()
            .then(|| PathBuf::from("docs/error-budget.md"))
    });
    let started = std::time::Instant::now();
    let mut results = Vec::new();
    for spec in &specs {
        let r = bench
            .run(spec, &mut |stage| eprintln!("  {stage}"))
            .with_context(|| format!("run '{}'", spec.name))?;
        print_row(&r);
        results.push(r);
        if let Some(path) = &args.json {
            std::fs::write(path, serde_json::to_vec_pretty(&results)?)
                .with_context(|| format!("writing {}", path.display()))?;
        }
    }
    if let Some(path) = report {
        let meta = ellipso_bench::report::ReportMeta {
            command: command_line(&args),
            scene: scene_path.file_name().map_or_else(
                || scene_path.display().to_string(),
                |n| n.to_string_lossy().into(),
            ),
            resolution,
            photos: bench.scene.camera_poses.len(),
            supersampling: args.supersampling,
            total_s: started.elapsed().as_secs_f64(),
            threads: rayon::current_num_threads(),
        };
        let md = ellipso_bench::report::markdown(&results, &meta);
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
            .unwrap_or_else(|| std::path::Path::new("."))
            .join("img")
            .join(format!("{stem}.png"));
        if let Some(dir) = png.parent() {
            std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        }
        ellipso_bench::report::plot(&results, &png)?;
        crate::outln!(
            "wrote {}, {} and {}",
            path.display(),
            json.display(),
            png.display()
        );
    }
    Ok(())
}

/// The command that regenerates the report (as the report states it).
fn command_line(args: &ChainArgs) -> String {
    let mut c = String::from("ellipso bench chain");
    if let Some(s) = &args.scene {
        c += &format!(" --scene {}", s.display());
    }
    if let Some([w, h]) = args.resolution {
        c += &format!(" --resolution {w}x{h}");
    }
    if args.supersampling != 2 {
        c += &format!(" --supersampling {}", args.supersampling);
    }
    if !args.runs.is_empty() {
        c += &format!(" --runs \"{}\"", args.runs.join(","));
    }
    c
}

fn print_row(r: &RunResult) {
    let s = &r.scores;
    let mats: Vec<String> = s
        .materials
        .iter()
        .map(|m| {
            format!(
                "{} {:+.2}% (unpooled {:+.2}%{})",
                m.name,
                m.eta_error_pct,
                m.eta_unpooled_error_pct,
                if m.at_start_value { ", AT START" } else { "" }
            )
        })
        .collect();
    crate::outln!(
        "{:32} posed {}/{} · η/material {} · vertex median {:.2}% (unpooled {:.2}%) · normal {:.2}° · ρd {:.1}% · σs {:.3} σss {:.3}",
        r.spec.name,
        r.frames_posed,
        r.frames,
        mats.join(", "),
        s.eta_vertex_median_pct,
        s.eta_vertex_unpooled_median_pct,
        s.normal_median_deg,
        s.rho_d_median_pct,
        s.sigma_s_abs,
        s.sigma_ss_abs
    );
    if let Some(h) = &r.holdout {
        crate::outln!(
            "{:32} held-out s0 {:.4} (truth {:.4}) · I^s {:.3} (truth {:.3}) · I^α {:.3} (truth {:.3})",
            "",
            h.fit.s0.relative_rmse,
            h.truth.s0.relative_rmse,
            h.fit.specular.relative_rmse,
            h.truth.specular.relative_rmse,
            h.fit.alpha.relative_rmse,
            h.truth.alpha.relative_rmse
        );
    }
    for m in &r.residuals {
        crate::outln!(
            "{:32} residual at truth {:15} mean z [d s α t] {:+.2} {:+.2} {:+.2} {:+.2} · rms {:.2} {:.2} {:.2} {:.2} · rel bias {:+.4} {:+.4} {:+.4} {:+.4}",
            "",
            m.name,
            m.mean_z[0],
            m.mean_z[1],
            m.mean_z[2],
            m.mean_z[3],
            m.rms_z[0],
            m.rms_z[1],
            m.rms_z[2],
            m.rms_z[3],
            m.relative_bias[0],
            m.relative_bias[1],
            m.relative_bias[2],
            m.relative_bias[3]
        );
    }
    crate::outln!(
        "{:32} render {:.1} s · track {:.1} s · mesh {:.1} s · fit {:.1} s",
        "",
        r.times.render_s,
        r.times.track_s,
        r.times.mesh_s,
        r.times.fit_s
    );
}
