//! `ellipso fit-merge PARTS… --out DIR`: the part files of a sharded fit (`ellipso fit --shard
//! I/N --out PART`) merged into what `ellipso fit` writes — bit-identical to an unsharded
//! `ellipso fit --outer 1` (docs/scale.md; the body is `ellipso_pipeline::fit_shard`).

use std::path::PathBuf;

/// Arguments of `ellipso fit-merge`.
#[derive(Debug, clap::Args)]
pub struct MergeArgs {
    /// The part files of every shard (`ellipso fit --shard I/N --out PART`), in any order.
    #[arg(required = true)]
    pub parts: Vec<PathBuf>,
    /// Output directory (what `ellipso fit` writes).
    #[arg(long)]
    pub out: PathBuf,
    /// Frame id of the view the pictures are rendered from (default: the first fitted frame).
    #[arg(long)]
    pub view: Option<u64>,
    /// The session directory, where it is not at the path the shards recorded (another mount).
    #[arg(long)]
    pub session: Option<PathBuf>,
    /// The mesh file, where it is not at the path the shards recorded.
    #[arg(long)]
    pub mesh: Option<PathBuf>,
}

/// Runs `ellipso fit-merge`.
pub fn run_merge(args: MergeArgs) -> anyhow::Result<()> {
    let request = ellipso_pipeline::fit_shard::MergeRequest {
        parts: &args.parts,
        out: &args.out,
        view: args.view,
        session: args.session.as_deref(),
        mesh: args.mesh.as_deref(),
    };
    let (out, run) = ellipso_pipeline::fit_shard::run_merge(&request, &super::out::Printed)
        .map_err(super::out::failed)?;
    super::fit::print_results(&out, &run, false);
    Ok(())
}
