//! `grin bake`.

/// Arguments of `grin bake`.
#[derive(Debug, clap::Args)]
pub struct Args {}

pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`grin bake` is not implemented yet")
}
