//! `ellipso model …`: inspect the polarimetric model (Fresnel, diffuse DoP, Mueller matrices).

/// Arguments of `ellipso model`.
#[derive(Debug, clap::Args)]
pub struct Args {}

/// Runs `ellipso model`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`ellipso model` lands with the optics module (issue 3)")
}
