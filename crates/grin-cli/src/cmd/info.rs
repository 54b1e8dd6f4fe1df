//! `grin info`.

/// Arguments of `grin info`.
#[derive(Debug, clap::Args)]
pub struct Args {}

pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`grin info` is not implemented yet")
}
