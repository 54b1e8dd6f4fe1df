//! `grin export field.grinf -o out.vdb`: a baked field as OpenVDB grids `delta_n` (float)
//! and `grad_n` (vec3, covariant) so it can be inspected in Houdini or Blender.

use std::path::{Path, PathBuf};

use anyhow::Context;
use grin_field::IndexField;
use grin_field::baked::BakedField;
use vdb_sys::{DenseGrid, IndexBox, MetaValue, Transform, VdbWriter, WriteOptions};

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
    let dims = geometry.dims;
    let max_index = |d: usize| i32::try_from(d.saturating_sub(1)).ok();
    let (Some(mx), Some(my), Some(mz)) =
        (max_index(dims[0]), max_index(dims[1]), max_index(dims[2]))
    else {
        anyhow::bail!(
            "{}: grid {dims:?} is too large for OpenVDB",
            args.input.display()
        );
    };
    let bbox = IndexBox {
        min: [0, 0, 0],
        max: [mx, my, mz],
    };
    // Node (i, j, k) of the baked grid sits at origin + spacing * (i, j, k): the same
    // convention as OpenVDB's voxel centres at integer index coordinates.
    let o = geometry.origin;
    let s = geometry.spacing;
    let world_from_index = Transform {
        world_from_index: [
            [s.x, 0.0, 0.0, o.x],
            [0.0, s.y, 0.0, o.y],
            [0.0, 0.0, s.z, o.z],
        ],
    };
    let (delta_n, grad_n) = channels(&field);
    let meta = vec![
        (
            "n_ambient".to_owned(),
            MetaValue::Number(field.ambient_index()),
        ),
        (
            "grin_source".to_owned(),
            MetaValue::Text(field.provenance().source.clone()),
        ),
        (
            "grin_storage".to_owned(),
            MetaValue::Text(field.storage().name().to_owned()),
        ),
        (
            "grin_interp".to_owned(),
            MetaValue::Text(field.interp().name().to_owned()),
        ),
    ];
    let scalar_opts = WriteOptions {
        half_float: args.half,
        metadata: meta.clone(),
        ..WriteOptions::default()
    };
    let vec_opts = WriteOptions {
        half_float: args.half,
        metadata: meta,
        ..WriteOptions::default()
    };
    let mut writer = VdbWriter::new()?;
    writer.add_float(
        "delta_n",
        &DenseGrid {
            bbox,
            world_from_index,
            values: delta_n,
        },
        &scalar_opts,
    )?;
    writer.add_vec3(
        "grad_n",
        &DenseGrid {
            bbox,
            world_from_index,
            values: grad_n,
        },
        &vec_opts,
    )?;
    writer.add_file_meta("creator", "grin export")?;
    writer.add_file_meta("grin_input", &args.input.display().to_string())?;
    write_atomic(&mut writer, &args.output)?;

    let size = std::fs::metadata(&args.output)
        .map(|m| m.len())
        .unwrap_or(0);
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
        println!("{summary}");
    } else {
        println!(
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
        );
    }
    Ok(())
}

/// delta_n and grad n of every node, x fastest (the baked grid's own order).
fn channels(field: &BakedField) -> (Vec<f32>, Vec<[f32; 3]>) {
    let voxels = field.voxels();
    let n = voxels.len();
    let mut delta_n = Vec::with_capacity(n);
    let mut grad_n = Vec::with_capacity(n);
    for idx in 0..n {
        let v = voxels.get(idx);
        delta_n.push(v[0]);
        grad_n.push([v[1], v[2], v[3]]);
    }
    (delta_n, grad_n)
}

/// Write to a temporary file beside `path`, then rename: no half-written output.
fn write_atomic(writer: &mut VdbWriter, path: &Path) -> anyhow::Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = dir.join(format!(".{name}.tmp{}", std::process::id()));
    let result = writer
        .write(&tmp)
        .map_err(anyhow::Error::from)
        .and_then(|()| {
            std::fs::rename(&tmp, path).with_context(|| format!("{}: cannot write", path.display()))
        });
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}
