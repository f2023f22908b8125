//! `ellipso bench chain`: the error budget of the whole chain on a scene
//! ([`ellipso_bench::budget::run`]): the full chain, then one stage at a time replaced by its
//! truth; the binary keeps the flags and prints one row per run and the report's files.

use std::path::PathBuf;

use ellipso_bench::budget::BudgetOptions;
use ellipso_bench::chain::RunResult;

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
    let options = BudgetOptions {
        scene: args.scene,
        work: args.work,
        resolution: args.resolution,
        supersampling: args.supersampling,
        runs: args.runs,
        report: args.report,
        json: args.json,
    };
    let files = ellipso_bench::budget::run(
        &options,
        &mut |stage| crate::errln!("  {stage}"),
        &mut print_row,
    )
    .map_err(super::super::out::failed)?;
    if let Some(f) = files {
        crate::outln!(
            "wrote {}, {} and {}",
            f.report.display(),
            f.json.display(),
            f.png.display()
        );
    }
    Ok(())
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
