//! `grin info`: what is inside a `.vdb` or `.grinf` file.

use std::path::PathBuf;

/// Arguments of `grin info`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// A `.vdb` (OpenVDB) or `.grinf` (baked field) file.
    pub path: PathBuf,
    /// Print a machine-readable summary (JSON) on stdout.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let is_vdb = args
        .path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("vdb"));
    if is_vdb {
        return crate::cmd::info_vdb::run(&args.path, args.json);
    }
    anyhow::bail!(
        "{}: `grin info` of baked (.grinf) files is not implemented yet",
        args.path.display()
    )
}
