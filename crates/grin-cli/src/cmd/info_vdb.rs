//! `grin info file.vdb`: the grids of an OpenVDB file and their properties.

use std::path::Path;

use grin_field::vdb::{DATA_FRACTION, DataBox, affine_from_rows, locate_data, placement};
use grin_scene::UpAxis;
use serde_json::{Value, json};
use vdb_sys::{GridInfo, Meta, MetaValue, VdbFile};

use crate::cmd::info::UpArg;

/// What `grin info` reads to find where a grid's data is: bricks of its non-background
/// voxels within 2 GiB, and a data box of at most 2 Gi voxels.
const DATA_READ_CAP: u64 = 2 << 30;

/// Where one scalar grid's data is, in the scene frame of `--up`.
struct DataPlace {
    data: DataBox,
    /// Scene-from-index of the grid (its transform, then the up-axis turn).
    world_from_index: glam::DAffine3,
}

impl DataPlace {
    /// A `[medium]` block that holds the data, for a scene beside `path`'s directory.
    fn medium_block(&self, path: &Path, g: &GridInfo, up: UpArg) -> String {
        let file = path.file_name().map_or_else(
            || path.display().to_string(),
            |f| f.to_string_lossy().into_owned(),
        );
        let name = g.name.to_ascii_lowercase();
        let (map, note) = if name.contains("temp") || name.contains("heat") {
            (
                "{ gladstone-dale = { ambient_temperature_k = 293.15, scale_k = 300.0 } }",
                "# map: air by Gladstone-Dale, T = 293.15 K + scale_k * value: set scale_k to the kelvin per unit of this cache",
            )
        } else if name.contains("index") || name == "n" || name.contains("ior") {
            ("{ index = {} }", "# map: the grid holds n itself")
        } else {
            (
                "{ linear = { k = 1e-4 } }",
                "# map: n = ambient + k * value: set k to the index change per unit of this grid",
            )
        };
        let up = match up {
            UpArg::Y => "",
            UpArg::Z => ", up = \"z\"",
        };
        format!(
            "[medium]\n{note}\n{}\nambient_index = \"auto\"\nfield = {{ kind = \"vdb\", path = \"{file}\", grid = \"{}\", map = {map}{up} }}",
            self.data.bounds_line(&self.world_from_index),
            g.name
        )
    }

    fn world(&self) -> (glam::DVec3, glam::DVec3) {
        self.data.world(&self.world_from_index, 0.0)
    }
}

/// Find a scalar grid's data ([`locate_data`]); `Ok(None)` for a grid
/// whose values never leave the background; `Err` says why it was not looked at.
fn data_place(file: &VdbFile, g: &GridInfo, up: UpArg) -> Result<Option<DataPlace>, String> {
    if !g.kind.is_scalar() {
        return Err("not a scalar grid".into());
    }
    let turn = placement(
        match up {
            UpArg::Y => UpAxis::Y,
            UpArg::Z => UpAxis::Z,
        },
        1.0,
        [0.0; 3],
        [0.0; 3],
    );
    Ok(locate_data(file, g, DATA_READ_CAP)?.map(|data| DataPlace {
        data,
        world_from_index: turn * affine_from_rows(&g.transform.world_from_index),
    }))
}

/// Print the grids of `path` (text, or JSON on stdout with `json`).
pub fn run(path: &Path, json: bool, up: UpArg) -> anyhow::Result<()> {
    let file = VdbFile::open(path)?;
    if json {
        outln!(
            "{}",
            serde_json::to_string_pretty(&to_json(&file, path, up))?
        );
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
        if !g.kind.is_scalar() {
            continue;
        }
        match data_place(&file, g, up) {
            Ok(Some(place)) => {
                let (lo, hi) = place.world();
                outln!(
                    "  data (|value - background| > {DATA_FRACTION:e} of the largest): index box {:?}..={:?}, world box of voxel centres{} ({:.4}, {:.4}, {:.4}) .. ({:.4}, {:.4}, {:.4})",
                    place.data.min,
                    place.data.max,
                    if up == UpArg::Z {
                        " (Z-up turned to +y)"
                    } else {
                        ""
                    },
                    lo.x,
                    lo.y,
                    lo.z,
                    hi.x,
                    hi.y,
                    hi.z
                );
                outln!("  a [medium] that holds it (paste into a scene beside the file):");
                for line in place.medium_block(path, g, up).lines() {
                    outln!("    {line}");
                }
            }
            Ok(None) => outln!("  data: every voxel equals the background"),
            Err(why) => outln!("  data: not located ({why})"),
        }
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

fn to_json(file: &VdbFile, path: &Path, up: UpArg) -> Value {
    let grids: Vec<Value> = file
        .grids()
        .iter()
        .map(|g| {
            let (lo, hi) = world_box(g);
            let place = g
                .kind
                .is_scalar()
                .then(|| data_place(file, g, up).ok().flatten())
                .flatten();
            json!({
                "data_index_box": place.as_ref().map(|p| json!({"min": p.data.min, "max": p.data.max})),
                "data_world_box": place.as_ref().map(|p| {
                    let (lo, hi) = p.world();
                    json!({"min": lo.to_array(), "max": hi.to_array()})
                }),
                "medium_toml": place.as_ref().map(|p| p.medium_block(path, g, up)),
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
