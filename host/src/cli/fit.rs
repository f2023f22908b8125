//! `ellipso fit SESSION --mesh MESH --out DIR`: the polarimetric SVBRDF and refined shape of a
//! recorded session, per mesh vertex, with its pictures (`fit.ply`, the pictures from one
//! captured view, `fit-summary.json`; docs/fit-outputs.md).
//!
//! The flags only: `ellipso_pipeline::fit_run::run` claims the output, reads the mesh (board frame,
//! or a COLMAP model's with `--mesh-frame colmap`; carved from the session's frames without
//! `--mesh`), takes the poses (the session's, tracked first where needed, or `--poses`), fits
//! and writes; with `--shard`, one shard's part file (`ellipso_pipeline::fit_shard`).

use std::path::{Path, PathBuf};

use ellipso_fit::output::FitRun;
use ellipso_fit::session::SessionFitConfig;
use ellipso_fit::shard::Shard;
use ellipso_pipeline::fit_run::{FitDone, FitRequest};

/// Arguments of `ellipso fit`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The session directory.
    pub session: PathBuf,
    /// Triangle mesh of the object (PLY or OBJ), board coordinates, metres (default: carved
    /// from the session's frames, as `ellipso mesh` does).
    #[arg(long)]
    pub mesh: Option<PathBuf>,
    /// Output directory (default `ellipso-fit`); with `--shard`, the part file to write
    /// (required).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Frame id of the view the pictures are rendered from (default: the first posed frame).
    #[arg(long)]
    pub view: Option<u64>,
    /// Outer iterations (solve ↔ surface update), 1..=20; 1 keeps the input geometry (default
    /// 8, fewer when the surface converges; a shard runs 1).
    #[arg(long, value_parser = super::limits::outer_iterations)]
    pub outer: Option<usize>,
    /// Target vertex count of the mesh carved without `--mesh`, 100..=2000000.
    #[arg(long, default_value_t = 2500, value_parser = super::limits::vertices)]
    pub vertices: usize,
    /// Do not carve the visual hull for a `--mesh` (the surface update then runs without the
    /// silhouettes' constraint); without `--mesh` the hull comes with the carved mesh.
    #[arg(long)]
    pub no_hull: bool,
    /// Step A alone: no clusters, virtual samples or pooled η (the paper's shared steps are
    /// on by default; docs/fit.md).
    #[arg(long)]
    pub joint_only: bool,
    /// 1σ width of the prior cone of each refined normal about the mesh normal, degrees: how
    /// far the mesh's normals can be trusted (0 disables the prior).
    #[arg(long, default_value_t = 10.0)]
    pub normal_prior_deg: f64,
    /// Samples seen more obliquely than this from the mesh normal are gated out, degrees.
    #[arg(long, default_value_t = ellipso_fit::gate::GateConfig::default().grazing_cutoff_deg)]
    pub grazing_cutoff_deg: f64,
    /// Fraction of the posed frames held out of the fit and scored as a re-render (0 fits all;
    /// default 0.1).
    #[arg(long, default_value_t = 0.1)]
    pub holdout: f64,
    /// Fit one shard of the vertices, `I/N` (those with `v % N == I`), and write a part file to
    /// `--out` for `ellipso fit-merge`; `env` reads the index from the job array's environment
    /// (Slurm, Kubernetes Indexed Job, AWS Batch; docs/scale.md). Needs `--mesh`.
    #[arg(long)]
    pub shard: Option<String>,
    /// Number of shards with `--shard env` where the environment does not say it (Kubernetes
    /// `spec.completions`, AWS Batch array size).
    #[arg(long)]
    pub shard_count: Option<u32>,
    /// Sensor calibration file (`ellipso calibrate sensor`) to read the frames with, for a
    /// session that did not record one (a session that did accepts only that file's identity).
    #[arg(long)]
    pub sensor_calibration: Option<PathBuf>,
    /// Print one JSON object (output folder, files, the fit summary) instead of the text report.
    #[arg(long)]
    pub json: bool,
    /// Poses and a mesh from COLMAP or other photogrammetry (`--poses`, `--mesh-frame`,
    /// `--mesh-model`).
    #[command(flatten)]
    pub import: super::fit_import::ImportArgs,
}

/// Runs `ellipso fit`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let shard = shard_of(&args)?;
    let request = FitRequest {
        session: &args.session,
        mesh: args.mesh.as_deref(),
        out: args.out.as_deref().unwrap_or(Path::new("ellipso-fit")),
        view: args.view,
        vertices: args.vertices,
        no_hull: args.no_hull,
        config: config_of(&args)?,
        shard,
        import: args.import.flags(),
        sensor_calibration: args.sensor_calibration.as_deref(),
    };
    let done = ellipso_pipeline::fit_run::run(
        request,
        &mut super::progress::Spinners::default(),
        &super::out::Printed,
    )
    .map_err(super::out::failed)?;
    match done {
        FitDone::Whole { out, run } => print_results(&out, &run, args.json),
        FitDone::Shard(s) => crate::outln!(
            "shard {}: {} vertices, {} samples in {:.1} s (observations {:.1} s, step A {:.1} s) → {}",
            shard.expect("a shard's run"),
            s.vertices,
            s.samples,
            s.wall_s,
            s.observe_s,
            s.joint_s,
            s.part.display()
        ),
    }
    Ok(())
}

/// The text or JSON report of a written fit (files already as published).
pub fn print_results(out: &Path, result: &FitRun, json: bool) {
    if json {
        let json = serde_json::json!({
            "out": out.display().to_string(),
            "files": result.files.iter().map(|f| f.display().to_string()).collect::<Vec<_>>(),
            "summary": result.summary,
        });
        crate::outln!("{json}");
        return;
    }
    if let Some(coverage) = &result.summary.coverage {
        crate::outln!();
        for line in ellipso_fit::materials::report_lines(&result.summary.materials, coverage) {
            crate::outln!("{line}");
        }
    }
    crate::outln!("\nresults in {}:", out.display());
    for f in &result.files {
        crate::outln!("  {}", f.display());
    }
}

/// The shard of `--shard`/`--shard-count`, with the flags a shard needs checked.
fn shard_of(args: &Args) -> anyhow::Result<Option<Shard>> {
    let Some(spec) = args.shard.as_deref() else {
        anyhow::ensure!(
            args.shard_count.is_none(),
            "--shard-count is only used with --shard env"
        );
        return Ok(None);
    };
    let shard = if spec == "env" {
        Shard::from_env(&|var| std::env::var(var).ok(), args.shard_count)?
    } else {
        anyhow::ensure!(
            args.shard_count.is_none(),
            "--shard-count is only used with --shard env (--shard {spec} gives the count)"
        );
        Shard::parse(spec)?
    };
    anyhow::ensure!(
        args.mesh.is_some(),
        "--shard needs --mesh: every shard must fit the same mesh (carve it once with `ellipso \
         mesh` first)"
    );
    anyhow::ensure!(
        args.out.is_some(),
        "--shard needs --out PART: the part file this shard writes for `ellipso fit-merge`"
    );
    if let Some(outer) = args.outer {
        anyhow::ensure!(
            outer == 1,
            "--outer {outer} with --shard: a sharded fit runs one outer iteration (the shape \
             update needs every vertex's solve; docs/scale.md)"
        );
    }
    anyhow::ensure!(
        args.view.is_none(),
        "--view is given to `ellipso fit-merge`, which renders the pictures"
    );
    Ok(Some(shard))
}

/// The fit's settings from the flags (shared by whole and sharded runs).
fn config_of(args: &Args) -> anyhow::Result<SessionFitConfig> {
    let mut config = SessionFitConfig {
        outer_iterations: args.outer.unwrap_or(if args.shard.is_some() {
            1
        } else {
            SessionFitConfig::default().outer_iterations
        }),
        holdout_fraction: args.holdout,
        ..SessionFitConfig::default()
    };
    anyhow::ensure!(
        args.normal_prior_deg.is_finite() && (0.0..=90.0).contains(&args.normal_prior_deg),
        "--normal-prior-deg {}: must be in [0, 90]",
        args.normal_prior_deg
    );
    if args.joint_only {
        config.fit = ellipso_fit::pipeline::FitConfig::joint_only();
    }
    config.fit.solver.normal_prior_deg = args.normal_prior_deg;
    anyhow::ensure!(
        args.grazing_cutoff_deg.is_finite() && (10.0..=89.0).contains(&args.grazing_cutoff_deg),
        "--grazing-cutoff-deg {}: must be in [10, 89]",
        args.grazing_cutoff_deg
    );
    config.observe.gate.grazing_cutoff_deg = args.grazing_cutoff_deg;
    Ok(config)
}
