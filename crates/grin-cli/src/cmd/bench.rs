//! `grin bench`.

/// Arguments of `grin bench`.
#[derive(Debug, clap::Args)]
pub struct Args {}

pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`grin bench` is not implemented yet")
}
