//! `grin render`.

/// Arguments of `grin render`.
#[derive(Debug, clap::Args)]
pub struct Args {}

pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`grin render` is not implemented yet")
}
