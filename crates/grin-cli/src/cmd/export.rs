//! `grin export field.grinf -o out.vdb`: a baked field as OpenVDB grids `delta_n` (float)
//! and `grad_n` (vec3, covariant) so it can be inspected in Houdini or Blender; a sparse
//! bake as one such pair per brick resolution (`delta_n_<m>`, `grad_n_<m>`).

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
    let _input = grin_output::protect_inputs([&args.input]);
    let field = match grin_field::grinf::open(&args.input)? {
        grin_field::grinf::Grinf::Dense(field) => field,
        grin_field::grinf::Grinf::Sparse(field) => return run_sparse(&args, &field),
    };
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

/// A sparse bake: a pair of grids per brick resolution (`delta_n_<m>`, `grad_n_<m>`).
fn run_sparse(args: &Args, field: &grin_field::sparse::SparseField) -> anyhow::Result<()> {
    let levels =
        grin_field::export::export_sparse_vdb(field, &args.input, &args.output, args.half)?;
    let size = std::fs::metadata(&args.output)
        .map(|m| m.len())
        .unwrap_or(0);
    let to_stream = crate::is_stream(&args.output);
    let edge = field.top().edge;
    if args.json {
        let grids: Vec<&str> = levels
            .iter()
            .flat_map(|l| [l.delta_n.as_str(), l.grad_n.as_str()])
            .collect();
        let per_level: Vec<serde_json::Value> = levels
            .iter()
            .map(|l| {
                serde_json::json!({
                    "cells": l.cells,
                    "voxel_size": edge / l.cells as f64,
                    "bricks": l.bricks,
                    "grids": [l.delta_n, l.grad_n],
                })
            })
            .collect();
        let summary = serde_json::json!({
            "input": args.input.display().to_string(),
            "output": args.output.display().to_string(),
            "layout": "sparse",
            "grids": grids,
            "levels": per_level,
            "origin": field.top().origin.to_array(),
            "n_ambient": field.ambient_index(),
            "half_float": args.half,
            "bytes": size,
        });
        crate::report(to_stream, summary);
    } else {
        let shown: Vec<String> = levels
            .iter()
            .map(|l| {
                let s = if l.bricks == 1 { "" } else { "s" };
                format!(
                    "{} brick{s} of {}^3 cells (voxel {:.4})",
                    l.bricks,
                    l.cells,
                    edge / l.cells as f64
                )
            })
            .collect();
        crate::report(
            to_stream,
            format_args!(
                "exported {} -> {}: sparse, grids delta_n_<m> and grad_n_<m> for {} ({} bytes)",
                args.input.display(),
                args.output.display(),
                shown.join(", "),
                size
            ),
        );
    }
    Ok(())
}
