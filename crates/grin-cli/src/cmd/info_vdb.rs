//! `grin info file.vdb`: the grids of an OpenVDB file and their properties.

use std::path::Path;

use serde_json::{Value, json};
use vdb_sys::{GridInfo, Meta, MetaValue, VdbFile};

/// Print the grids of `path` (text, or JSON on stdout with `json`).
pub fn run(path: &Path, json: bool) -> anyhow::Result<()> {
    let file = VdbFile::open(path)?;
    if json {
        outln!("{}", serde_json::to_string_pretty(&to_json(&file))?);
        return Ok(());
    }
    outln!(
        "{}: OpenVDB file, {} grid(s)",
        path.display(),
        file.grids().len()
    );
    for m in file.metadata() {
        outln!("  file metadata: {} = {}", m.key, m.value);
    }
    for g in file.grids() {
        print_grid(g);
    }
    Ok(())
}

fn print_grid(g: &GridInfo) {
    outln!(
        "grid `{}`: {}, class {}{}",
        g.name,
        g.value_type,
        g.grid_class,
        if g.half_float {
            ", stored as half floats"
        } else {
            ""
        }
    );
    let v = g.voxel_size;
    outln!(
        "  transform: {}{}, voxel size {} x {} x {}",
        g.map_type,
        if g.is_linear {
            ""
        } else {
            " (non-linear: grin cannot import it)"
        },
        v[0],
        v[1],
        v[2]
    );
    for (axis, row) in ["x", "y", "z"]
        .iter()
        .zip(g.transform.world_from_index.iter())
    {
        outln!(
            "    world {axis} = {} i + {} j + {} k + {}",
            row[0],
            row[1],
            row[2],
            row[3]
        );
    }
    match g.active_bbox {
        Some(b) => {
            let d = b.dims();
            let (lo, hi) = world_box(g);
            outln!(
                "  active voxels: {} in index box {:?}..={:?} ({}x{}x{})",
                g.active_voxel_count,
                b.min,
                b.max,
                d[0],
                d[1],
                d[2]
            );
            outln!(
                "  world box of voxel centres: ({:.4}, {:.4}, {:.4}) .. ({:.4}, {:.4}, {:.4})",
                lo[0],
                lo[1],
                lo[2],
                hi[0],
                hi[1],
                hi[2]
            );
        }
        None => outln!("  active voxels: 0 (empty grid)"),
    }
    match g.value_range {
        Some((lo, hi)) => outln!(
            "  values: {lo:.6e} .. {hi:.6e}{} (background {})",
            if g.kind.is_vec3() { " (magnitude)" } else { "" },
            g.background
        ),
        None => outln!("  values: none finite (background {})", g.background),
    }
    if g.non_finite_count > 0 {
        outln!("  NaN/Inf voxels: {}", g.non_finite_count);
    }
    for m in &g.metadata {
        outln!("  metadata: {} = {}", m.key, m.value);
    }
}

/// World-space box of the active voxel centres (corners through the affine transform).
fn world_box(g: &GridInfo) -> ([f64; 3], [f64; 3]) {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    if let Some(b) = g.active_bbox {
        for c in 0..8 {
            let ijk: [f64; 3] = std::array::from_fn(|a| {
                f64::from(if c >> a & 1 == 0 { b.min[a] } else { b.max[a] })
            });
            let w = g.transform.index_to_world(ijk);
            for a in 0..3 {
                lo[a] = lo[a].min(w[a]);
                hi[a] = hi[a].max(w[a]);
            }
        }
    }
    (lo, hi)
}

fn meta_json(meta: &[Meta]) -> Value {
    let map: serde_json::Map<String, Value> = meta
        .iter()
        .map(|m| {
            let v = match &m.value {
                MetaValue::Number(x) => json!(x),
                MetaValue::Text(s) | MetaValue::Other(s) => json!(s),
            };
            (m.key.clone(), v)
        })
        .collect();
    Value::Object(map)
}

fn finite_or_null(x: f64) -> Value {
    if x.is_finite() { json!(x) } else { Value::Null }
}

fn to_json(file: &VdbFile) -> Value {
    let grids: Vec<Value> = file
        .grids()
        .iter()
        .map(|g| {
            let (lo, hi) = world_box(g);
            json!({
                "name": g.name,
                "value_type": g.value_type,
                "class": g.grid_class,
                "half_float": g.half_float,
                "map_type": g.map_type,
                "linear": g.is_linear,
                "voxel_size": g.voxel_size,
                "world_from_index": g.transform.world_from_index,
                "active_bbox": g.active_bbox.map(|b| json!({"min": b.min, "max": b.max})),
                "world_bbox": g.active_bbox.map(|_| json!({
                    "min": lo.map(finite_or_null), "max": hi.map(finite_or_null)
                })),
                "active_voxel_count": g.active_voxel_count,
                "non_finite_count": g.non_finite_count,
                "value_range": g.value_range.map(|(a, b)| [a, b]),
                "background": finite_or_null(g.background),
                "metadata": meta_json(&g.metadata),
            })
        })
        .collect();
    json!({
        "path": file.path().display().to_string(),
        "format": "vdb",
        "metadata": meta_json(file.metadata()),
        "grids": grids,
    })
}
