//! `ellipso bench mesh`: the built-in mesh against the simulator's truth on the shipped scenes,
//! and what it costs ([`ellipso_bench::mesh_bench`]); here the flags, the spinners and the
//! files written.

use std::path::PathBuf;

use ellipso_bench::mesh_bench::MeshBenchRequest;

use crate::cli::out;

/// Arguments of `ellipso bench mesh`.
#[derive(Debug, clap::Args)]
pub struct MeshArgs {
    /// Shipped scenes (`sim/scenes/NAME.toml`).
    // the bench's DEFAULT_SCENES, written with commas for the help (test below)
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "sphere,multi_material,demo"
    )]
    pub scenes: Vec<String>,
    /// Capture resolution (the demo's: half the scenes' 2448×2048).
    #[arg(long, value_parser = crate::cli::limits::resolution, default_value = "1224x1024")]
    pub resolution: [u32; 2],
    /// Photos per capture (default: each scene's path).
    #[arg(long)]
    pub photos: Option<u32>,
    /// Where sessions are captured (and reused from).
    #[arg(long, default_value = "ellipso-bench-mesh")]
    pub work: PathBuf,
    /// Worker threads given to `ellipso mesh` (the target is stated for 2 cores).
    #[arg(long, default_value_t = 2)]
    pub threads: usize,
    /// Also fit each session on its built-in mesh and score the refined shape (observed and
    /// unobserved surface apart, normals, per-material η beside a fit on the true mesh).
    #[arg(long)]
    pub fit: bool,
    /// Also run `ellipso fit` as its own process on the demo session at these carved-mesh
    /// vertex counts and report its time, peak memory and observed-surface distance.
    #[arg(long, value_delimiter = ',', value_parser = crate::cli::limits::vertices)]
    pub scale_vertices: Vec<usize>,
    /// Also capture each scene with these scene seeds (another capture path where the scene's
    /// is seeded, other sensor noise) and bench each capture as its own row: the spread of the
    /// rows is what one capture's figures are worth.
    #[arg(long, value_delimiter = ',')]
    pub seeds: Vec<u64>,
    /// The Markdown report.
    #[arg(long, default_value = ellipso_bench::mesh_bench::DEFAULT_REPORT)]
    pub report: PathBuf,
}

/// Runs `ellipso bench mesh`.
pub fn run(args: MeshArgs) -> anyhow::Result<()> {
    let request = MeshBenchRequest {
        scenes: args.scenes,
        resolution: args.resolution,
        photos: args.photos,
        work: args.work,
        threads: args.threads,
        fit: args.fit,
        scale_vertices: args.scale_vertices,
        seeds: args.seeds,
        report: args.report,
        exe: std::env::current_exe()?,
    };
    let files = ellipso_bench::mesh_bench::run(
        &request,
        &mut crate::cli::record::Recording { quiet: true },
        &mut crate::cli::progress::Spinners::default(),
        &out::Printed,
    )
    .map_err(out::failed)?;
    crate::outln!(
        "written {} and {}",
        files.report.display(),
        files.json.display()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use clap::Parser;

    #[derive(Parser)]
    struct Wrapper {
        #[command(flatten)]
        args: super::MeshArgs,
    }

    #[test]
    fn the_flags_defaults_are_the_ones_the_report_leaves_out_of_its_command() {
        let w = Wrapper::parse_from(["bench-mesh"]);
        assert_eq!(w.args.scenes, ellipso_bench::mesh_bench::DEFAULT_SCENES);
        assert_eq!(
            w.args.report,
            std::path::Path::new(ellipso_bench::mesh_bench::DEFAULT_REPORT)
        );
    }
}
