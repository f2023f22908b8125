//! `ellipso polar FRAME.png --out DIR`: one raw mosaic frame to s0, DoLP, AoLP and I^d/I^s/I^α images.

/// Arguments of `ellipso polar`.
#[derive(Debug, clap::Args)]
pub struct Args {}

/// Runs `ellipso polar`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`ellipso polar` lands with the polarisation module (issue 5)")
}
