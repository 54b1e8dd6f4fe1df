//! `grin trace`.

/// Arguments of `grin trace`.
#[derive(Debug, clap::Args)]
pub struct Args {}

pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`grin trace` is not implemented yet")
}
