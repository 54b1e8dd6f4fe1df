//! `grin export field.grinf -o out.vdb`: a baked field as OpenVDB grids `delta_n` (float)
//! and `grad_n` (vec3, covariant) so it can be inspected in Houdini or Blender.

use std::path::PathBuf;

use grin_field::IndexField;

/// Arguments of `grin export`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Baked field (.grinf) to export.
    pub input: PathBuf,
    /// Output OpenVDB file (written to a temporary file, then renamed).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Store the grids as 16-bit half floats (smaller files, ~3 significant digits).
    #[arg(long)]
    pub half: bool,
    /// Print a machine-readable summary (JSON) on stdout.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let field = grin_field::grinf::load(&args.input)?;
    let geometry = *field.geometry();
    let (dims, s, o) = (geometry.dims, geometry.spacing, geometry.origin);
    grin_field::export::export_vdb(&field, &args.input, &args.output, args.half)?;
    let size = std::fs::metadata(&args.output)
        .map(|m| m.len())
        .unwrap_or(0);
    // `-o -`: the VDB is stdout's; the summary goes to stderr.
    let to_stream = crate::is_stream(&args.output);
    if args.json {
        let summary = serde_json::json!({
            "input": args.input.display().to_string(),
            "output": args.output.display().to_string(),
            "grids": ["delta_n", "grad_n"],
            "dims": dims,
            "voxel_size": [s.x, s.y, s.z],
            "origin": [o.x, o.y, o.z],
            "n_ambient": field.ambient_index(),
            "half_float": args.half,
            "bytes": size,
        });
        crate::report(to_stream, summary);
    } else {
        crate::report(
            to_stream,
            format_args!(
                "exported {} -> {}: grids delta_n, grad_n ({}x{}x{} voxels, voxel {:.4}x{:.4}x{:.4}, {} bytes)",
                args.input.display(),
                args.output.display(),
                dims[0],
                dims[1],
                dims[2],
                s.x,
                s.y,
                s.z,
                size
            ),
        );
    }
    Ok(())
}
