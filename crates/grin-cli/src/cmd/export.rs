//! `grin export`.

/// Arguments of `grin export`.
#[derive(Debug, clap::Args)]
pub struct Args {}

pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`grin export` is not implemented yet")
}
