//! `grin view`.

/// Arguments of `grin view`.
#[derive(Debug, clap::Args)]
pub struct Args {}

pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`grin view` is not implemented yet")
}
