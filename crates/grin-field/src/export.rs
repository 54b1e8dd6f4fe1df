//! Export of a baked field as an OpenVDB file: grids `delta_n` (float) and `grad_n`
//! (vec3, covariant), so it can be inspected in Houdini or Blender. The file is staged
//! through grin-output and read back through OpenVDB before it replaces anything: a write
//! that OpenVDB did not report as failed (a full disk) is still caught.

use std::path::Path;

use vdb_sys::{
    DenseGrid, IndexBox, MetaValue, Transform, VdbError, VdbFile, VdbWriter, WriteOptions,
};

use crate::baked::BakedField;
use crate::field::IndexField;
use crate::sparse::SparseField;

/// The grids an exported file holds, in order.
pub const EXPORT_GRIDS: [&str; 2] = ["delta_n", "grad_n"];

/// Why a baked field could not be exported.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    #[error("{path}: grid {dims:?} is too large for OpenVDB")]
    TooLarge { path: String, dims: [usize; 3] },
    #[error(
        "{path}: the sparse bake has no bricks (the index is ambient everywhere): nothing to export"
    )]
    Empty { path: String },
    #[error(transparent)]
    Vdb(#[from] VdbError),
    #[error(transparent)]
    Write(#[from] grin_output::OutputError),
}

/// Write `field` (read from `input`, recorded in the file's metadata) to `output`;
/// `half` stores 16-bit floats.
pub fn export_vdb(
    field: &BakedField,
    input: &Path,
    output: &Path,
    half: bool,
) -> Result<(), ExportError> {
    let geometry = *field.geometry();
    let dims = geometry.dims;
    let max_index = |d: usize| i32::try_from(d.saturating_sub(1)).ok();
    let (Some(mx), Some(my), Some(mz)) =
        (max_index(dims[0]), max_index(dims[1]), max_index(dims[2]))
    else {
        return Err(ExportError::TooLarge {
            path: input.display().to_string(),
            dims,
        });
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
    let (delta_n, grad_n) = channels(field);
    let mut meta = provenance_meta(field.ambient_index(), field.provenance(), field.storage());
    meta.push((
        "grin_interp".to_owned(),
        MetaValue::Text(field.interp().name().to_owned()),
    ));
    let scalar_opts = WriteOptions {
        half_float: half,
        metadata: meta.clone(),
        ..WriteOptions::default()
    };
    let vec_opts = WriteOptions {
        half_float: half,
        metadata: meta,
        ..WriteOptions::default()
    };
    let mut writer = VdbWriter::new()?;
    writer.add_float(
        EXPORT_GRIDS[0],
        &DenseGrid {
            bbox,
            world_from_index,
            values: delta_n,
        },
        &scalar_opts,
    )?;
    writer.add_vec3(
        EXPORT_GRIDS[1],
        &DenseGrid {
            bbox,
            world_from_index,
            values: grad_n,
        },
        &vec_opts,
    )?;
    let grids = [
        (EXPORT_GRIDS[0].to_owned(), false),
        (EXPORT_GRIDS[1].to_owned(), true),
    ];
    write_verified(writer, input, output, &grids)
}

/// One brick resolution of a sparse bake's export: `cells` a brick side, its bricks, and
/// its two grids' names (`delta_n_<cells>`, `grad_n_<cells>`).
#[derive(Debug, Clone, PartialEq)]
pub struct SparseGrids {
    pub cells: usize,
    pub bricks: usize,
    pub delta_n: String,
    pub grad_n: String,
}

/// The grids of a sparse bake's export, one pair per brick resolution present, coarsest
/// first.
fn sparse_export_grids(field: &SparseField) -> Vec<SparseGrids> {
    (0..=crate::sparse::MAX_LEVEL)
        .zip(field.level_counts())
        .filter(|&(_, bricks)| bricks > 0)
        .map(|(level, bricks)| {
            let cells = crate::sparse::cells_of(level);
            SparseGrids {
                cells,
                bricks,
                delta_n: format!("delta_n_{cells}"),
                grad_n: format!("grad_n_{cells}"),
            }
        })
        .collect()
}

/// Write a sparse bake to `output` as OpenVDB grids, one pair per brick resolution
/// present, coarsest first: each grid holds the stored nodes of the bricks of that
/// resolution, brick by brick (nothing is resampled, no dense box is ever made), index
/// (i, j, k) at top origin + spacing (i, j, k). Empty space is the background
/// (delta_n 0, the ambient index). `half` stores 16-bit floats. Returns the grids written.
pub fn export_sparse_vdb(
    field: &SparseField,
    input: &Path,
    output: &Path,
    half: bool,
) -> Result<Vec<SparseGrids>, ExportError> {
    let levels = sparse_export_grids(field);
    if levels.is_empty() {
        return Err(ExportError::Empty {
            path: input.display().to_string(),
        });
    }
    let top = *field.top();
    let o = top.origin;
    let mut base_meta = provenance_meta(field.ambient_index(), field.provenance(), field.storage());
    base_meta.push(("grin_brick_edge".to_owned(), MetaValue::Number(top.edge)));
    let mut writer = VdbWriter::new()?;
    let mut grids = Vec::new();
    for &SparseGrids {
        cells,
        delta_n: ref delta_name,
        grad_n: ref grad_name,
        ..
    } in &levels
    {
        let s = top.edge / cells as f64;
        let world_from_index = Transform {
            world_from_index: [[s, 0.0, 0.0, o.x], [0.0, s, 0.0, o.y], [0.0, 0.0, s, o.z]],
        };
        let mut meta = base_meta.clone();
        meta.push((
            "grin_brick_cells".to_owned(),
            MetaValue::Number(cells as f64),
        ));
        let opts = WriteOptions {
            half_float: half,
            metadata: meta,
            ..WriteOptions::default()
        };
        let bricks = || field.bricks().iter().filter(move |b| b.cells() == cells);
        let too_large = || ExportError::TooLarge {
            path: input.display().to_string(),
            dims: top.dims.map(|d| d * cells),
        };
        let mut boxes = Vec::new();
        for b in bricks() {
            boxes.push(brick_box(b).ok_or_else(too_large)?);
        }
        // A brick's own nodes (a Catmull-Rom bake's apron is the neighbours' to export).
        let node = |b: &crate::sparse::Brick, v: usize| field.voxel_f32(b, v);
        writer.add_float_boxes(
            delta_name,
            world_from_index,
            bricks()
                .zip(&boxes)
                .map(|(b, &bbox)| (bbox, b.inner_voxels().map(|v| node(b, v)[0]).collect())),
            &opts,
        )?;
        writer.add_vec3_boxes(
            grad_name,
            world_from_index,
            bricks().zip(&boxes).map(|(b, &bbox)| {
                let grad = b
                    .inner_voxels()
                    .map(|v| {
                        let x = node(b, v);
                        [x[1], x[2], x[3]]
                    })
                    .collect();
                (bbox, grad)
            }),
            &opts,
        )?;
        grids.push((delta_name.clone(), false));
        grids.push((grad_name.clone(), true));
    }
    write_verified(writer, input, output, &grids)?;
    Ok(levels)
}

/// Every exported grid's metadata: the ambient index, the bake's source and storage.
fn provenance_meta(
    ambient: f64,
    provenance: &crate::baked::BakeProvenance,
    storage: crate::baked::Storage,
) -> Vec<(String, MetaValue)> {
    vec![
        ("n_ambient".to_owned(), MetaValue::Number(ambient)),
        (
            "grin_source".to_owned(),
            MetaValue::Text(provenance.source.clone()),
        ),
        (
            "grin_storage".to_owned(),
            MetaValue::Text(storage.name().to_owned()),
        ),
    ]
}

/// The index box of brick `b`'s nodes in the grid of its resolution (`None` past i32).
fn brick_box(b: &crate::sparse::Brick) -> Option<IndexBox> {
    let m = b.cells();
    let min = b.at.map(|a| i32::try_from(a as usize * m).ok());
    let [Some(x), Some(y), Some(z)] = min else {
        return None;
    };
    let m = i32::try_from(m).ok()?;
    Some(IndexBox {
        min: [x, y, z],
        max: [x.checked_add(m)?, y.checked_add(m)?, z.checked_add(m)?],
    })
}

/// Add the file metadata, write `writer`'s grids to a staged file, read it back
/// (`grids`: each name and whether it is vec3) and put it in place of `output`.
fn write_verified(
    mut writer: VdbWriter,
    input: &Path,
    output: &Path,
    grids: &[(String, bool)],
) -> Result<(), ExportError> {
    writer.add_file_meta("creator", "grin export")?;
    writer.add_file_meta("grin_input", &input.display().to_string())?;
    let staged = grin_output::stage_with(output, |tmp| {
        writer
            .write(tmp)
            .and_then(|()| verify(tmp, grids))
            .map_err(|e| rename_path(e, output))
    })
    .map_err(|e| match e {
        grin_output::StageError::Output(e) => ExportError::Write(e),
        grin_output::StageError::Writer(e) => ExportError::Vdb(e),
    })?;
    grin_output::commit(vec![staged])?;
    Ok(())
}

/// Read the written file back: every grid present and of the right kind.
fn verify(path: &Path, grids: &[(String, bool)]) -> Result<(), VdbError> {
    let file = VdbFile::open(path)?;
    for (name, vec3) in grids {
        let (name, vec3) = (name.as_str(), *vec3);
        let grid = file.grid(name)?;
        if grid.kind.is_vec3() != vec3 {
            return Err(VdbError::Open {
                path: path.display().to_string(),
                message: format!("grid `{name}` was written as {}", grid.value_type),
            });
        }
    }
    Ok(())
}

/// Errors from the staged file name the user's target, not the temporary file.
fn rename_path(e: VdbError, output: &Path) -> VdbError {
    let path = output.display().to_string();
    match e {
        VdbError::Write { message, .. } => VdbError::Write { path, message },
        VdbError::Open { message, .. } => VdbError::Write {
            path,
            message: format!(
                "the written file does not read back ({message}); nothing was replaced"
            ),
        },
        other => VdbError::Write {
            path,
            message: format!("the written file does not read back ({other}); nothing was replaced"),
        },
    }
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
