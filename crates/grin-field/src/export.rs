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

/// The grids an exported file holds, in order.
pub const EXPORT_GRIDS: [&str; 2] = ["delta_n", "grad_n"];

/// Why a baked field could not be exported.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    #[error("{path}: grid {dims:?} is too large for OpenVDB")]
    TooLarge { path: String, dims: [usize; 3] },
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
    writer.add_file_meta("creator", "grin export")?;
    writer.add_file_meta("grin_input", &input.display().to_string())?;
    let staged = grin_output::stage_with(output, |tmp| {
        writer
            .write(tmp)
            .and_then(|()| verify(tmp))
            .map_err(|e| rename_path(e, output))
    })
    .map_err(|e| match e {
        grin_output::StageError::Output(e) => ExportError::Write(e),
        grin_output::StageError::Writer(e) => ExportError::Vdb(e),
    })?;
    grin_output::commit(vec![staged])?;
    Ok(())
}

/// Read the written file back: both grids present and of the right kind.
fn verify(path: &Path) -> Result<(), VdbError> {
    let file = VdbFile::open(path)?;
    for (name, vec3) in [(EXPORT_GRIDS[0], false), (EXPORT_GRIDS[1], true)] {
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
