//! `grin info`: what is inside a `.vdb` or `.grinf` file. Dispatch is on the file's magic
//! (then its extension) to one function per format.

use std::io::Read;
use std::path::{Path, PathBuf};

use anyhow::Context;
use grin_field::IndexField;
use grin_field::grinf;

/// Arguments of `grin info`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// A `.vdb` (OpenVDB) or `.grinf` (baked field) file.
    pub path: PathBuf,
    /// Print a machine-readable summary (JSON) on stdout.
    #[arg(long)]
    pub json: bool,
    /// A `.vdb`'s up axis for the world boxes and `[medium]` blocks shown: `z` for a Z-up
    /// cache (Blender), turned to the scene's +y as the medium's `up = "z"` does.
    #[arg(long, value_enum, default_value = "y")]
    pub up: UpArg,
}

/// The up axis of a VDB cache.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum UpArg {
    Y,
    Z,
}

/// The formats `grin info` reads.
enum Format {
    Vdb,
    Grinf,
}

/// OpenVDB files start with this magic number (little-endian 0x56444220 " BDV").
const VDB_MAGIC: [u8; 4] = [0x20, 0x42, 0x44, 0x56];

fn detect(path: &Path) -> anyhow::Result<Format> {
    let mut head = [0u8; 8];
    let mut f =
        std::fs::File::open(path).with_context(|| format!("{}: cannot open", path.display()))?;
    let n = f
        .read(&mut head)
        .with_context(|| format!("{}: cannot read", path.display()))?;
    if n >= 8 && head == grinf::MAGIC {
        return Ok(Format::Grinf);
    }
    if n >= 4 && head[..4] == VDB_MAGIC {
        return Ok(Format::Vdb);
    }
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    match ext.as_deref() {
        Some("vdb") => Ok(Format::Vdb),
        // A .grinf with a bad magic: let the reader report it.
        Some("grinf") => Ok(Format::Grinf),
        _ => anyhow::bail!("{}: not a .vdb or .grinf file", path.display()),
    }
}

pub fn run(args: Args) -> anyhow::Result<()> {
    match detect(&args.path)? {
        Format::Vdb => crate::cmd::info_vdb::run(&args.path, args.json, args.up),
        Format::Grinf => info_grinf(&args.path, args.json),
    }
}

fn info_grinf(path: &Path, json: bool) -> anyhow::Result<()> {
    let field = match grinf::open(path)? {
        grinf::Grinf::Sparse(s) => return info_sparse(path, &s, json),
        grinf::Grinf::Dense(f) => f,
    };
    let h = grinf::read_header(path)?;
    let g = &h.geometry;
    let (lo, hi) = g.world_box();
    let (n_min, n_max) = field.n_range();
    let macro_grid = field.macro_grid();
    if json {
        let v = serde_json::json!({
            "path": path.display().to_string(),
            "format": "grinf",
            "version": h.version,
            "dims": g.dims,
            "origin": g.origin.to_array(),
            "spacing": g.spacing.to_array(),
            "world_min": lo.to_array(),
            "world_max": hi.to_array(),
            "storage": h.storage.name(),
            "interp": h.interp.name(),
            "outside": outside_name(h.outside),
            "ambient_index": h.ambient,
            "scale": h.scale,
            "bounds": bounds_json(&h.bounds),
            "source": h.provenance.source,
            "max_err_n": h.provenance.max_err_n,
            "rms_err_n": h.provenance.rms_err_n,
            "max_err_grad": h.provenance.max_err_grad,
            "rms_err_grad": h.provenance.rms_err_grad,
            "n_min": n_min,
            "n_max": n_max,
            "max_grad_n": field.max_grad_n(),
            "macro_cells": macro_grid.dims,
            "homogeneous_cells": macro_grid.homogeneous_fraction(),
            "file_bytes": h.file_bytes,
            "data_bytes": field.data_bytes(),
            "crc32": format!("{:08x}", h.crc32),
        });
        outln!("{}", serde_json::to_string_pretty(&v)?);
        return Ok(());
    }
    let [nx, ny, nz] = g.dims;
    outln!(
        "{}: grin baked field, format version {}",
        path.display(),
        h.version
    );
    outln!("  source        {}", h.provenance.source);
    outln!(
        "  grid          {nx}x{ny}x{nz}, {} storage, {} sampling, {:?} outside",
        h.storage.name(),
        h.interp.name(),
        h.outside
    );
    outln!(
        "  world_from_grid  origin {:?} + spacing {:?} * (i, j, k)",
        g.origin.to_array(),
        g.spacing.to_array()
    );
    outln!("  world box     {:?} .. {:?}", lo.to_array(), hi.to_array());
    outln!("  bounds        {:?}", h.bounds);
    outln!("  ambient n     {}", h.ambient);
    outln!("  scale         {:?}", h.scale);
    outln!(
        "  n range       {n_min} .. {n_max}, max |grad n| {:.4e}",
        field.max_grad_n()
    );
    outln!(
        "  bake error    n: max {:.3e} rms {:.3e}; grad n: max {:.3e} rms {:.3e}",
        h.provenance.max_err_n,
        h.provenance.rms_err_n,
        h.provenance.max_err_grad,
        h.provenance.rms_err_grad
    );
    outln!(
        "  macro cells   {:?} of {} voxels, {:.1}% homogeneous",
        macro_grid.dims,
        macro_grid.cell,
        100.0 * macro_grid.homogeneous_fraction()
    );
    outln!(
        "  size          {} bytes ({} of voxels), crc32 {:08x}",
        h.file_bytes,
        field.data_bytes(),
        h.crc32
    );
    Ok(())
}

/// Bounds as the scene file writes them: `{"sphere": {"center": .., "radius": ..}}` or
/// `{"box": {"min": .., "max": ..}}`.
pub fn bounds_json(b: &grin_field::Bounds) -> serde_json::Value {
    match *b {
        grin_field::Bounds::Sphere { center, radius } => {
            serde_json::json!({"sphere": {"center": center.to_array(), "radius": radius}})
        }
        grin_field::Bounds::Box { min, max } => {
            serde_json::json!({"box": {"min": min.to_array(), "max": max.to_array()}})
        }
    }
}

/// The stable name of what a baked grid gives outside its nodes.
fn outside_name(o: grin_field::baked::Outside) -> &'static str {
    o.into()
}

/// `grin info` of a sparse (version-2) `.grinf`.
fn info_sparse(path: &Path, f: &grin_field::sparse::SparseField, json: bool) -> anyhow::Result<()> {
    let top = f.top();
    let p = f.provenance();
    let (n_min, n_max) = f.n_range();
    let file_bytes = std::fs::metadata(path).map(|m| m.len()).unwrap_or(0);
    let levels = f.level_counts();
    if json {
        let v = serde_json::json!({
            "path": path.display().to_string(),
            "format": "grinf",
            "version": grin_field::sparse::file::VERSION,
            "sparse": true,
            "bricks_per_axis": top.dims,
            "brick_edge": top.edge,
            "origin": top.origin.to_array(),
            "active_bricks": f.bricks().len(),
            "levels": levels,
            "finest_spacing": f.finest_spacing(),
            "storage": f.storage().name(),
            "interp": f.interp().name(),
            "apron": f.apron(),
            "gradient_of_n": f.gradient_of_n(),
            "ambient_index": f.ambient_index(),
            "bounds": bounds_json(&f.bounds()),
            "source": p.source,
            "max_err_n": p.max_err_n,
            "rms_err_n": p.rms_err_n,
            "max_err_grad": p.max_err_grad,
            "rms_err_grad": p.rms_err_grad,
            "n_min": n_min,
            "n_max": n_max,
            "max_grad_n": f.max_grad_n(),
            "file_bytes": file_bytes,
            "data_bytes": f.data_bytes(),
            "memory_bytes": f.memory_bytes(),
        });
        outln!("{}", serde_json::to_string_pretty(&v)?);
        return Ok(());
    }
    outln!(
        "{}: grin sparse baked field, format version {}",
        path.display(),
        grin_field::sparse::file::VERSION
    );
    outln!("  source        {}", p.source);
    outln!(
        "  bricks        {} of {} active ({}x{}x{}, edge {}), {} storage, {}",
        f.bricks().len(),
        f.table().len(),
        top.dims[0],
        top.dims[1],
        top.dims[2],
        top.edge,
        f.storage().name(),
        match (f.interp(), f.gradient_of_n()) {
            (grin_field::baked::Interp::Trilinear, _) => "trilinear",
            (grin_field::baked::Interp::Tricubic, false) =>
                "tricubic Catmull-Rom (bricks with an apron)",
            (grin_field::baked::Interp::Tricubic, true) =>
                "tricubic Catmull-Rom (bricks with an apron; the gradient the derivative of n)",
        }
    );
    for (l, n) in levels.iter().enumerate().filter(|(_, n)| **n > 0) {
        outln!(
            "  level {l}       {n} bricks of {}^3 nodes (spacing {:.4e})",
            grin_field::sparse::nodes_of(grin_field::sparse::cells_of(l as u8), f.apron()),
            f.spacing(l as u8)
        );
    }
    outln!("  origin        {:?}", top.origin.to_array());
    outln!("  bounds        {:?}", f.bounds());
    outln!("  ambient n     {}", f.ambient_index());
    outln!(
        "  n range       {n_min} .. {n_max}, max |grad n| {:.4e}",
        f.max_grad_n()
    );
    outln!(
        "  bake error    n: max {:.3e} rms {:.3e}; grad n: max {:.3e} rms {:.3e}",
        p.max_err_n,
        p.rms_err_n,
        p.max_err_grad,
        p.rms_err_grad
    );
    outln!(
        "  bytes         {} on disk, {} of voxels, {} in memory",
        file_bytes,
        f.data_bytes(),
        f.memory_bytes()
    );
    Ok(())
}
