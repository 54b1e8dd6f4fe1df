//! Building a [`VdbField`]: the parameters ([`VdbFieldParams`]), reading a grid from a
//! file or a dense copy a brick at a time, and mapping its voxels to delta_n with the
//! checks on units, ambient index, non-finite voxels and the data's placement.

use std::path::Path;

use glam::{DAffine3, DVec3};
use grin_scene::{MediumSpec, NonFinitePolicy, VdbSpec};
use vdb_sys::{DenseGrid, IndexBox, VdbError, VdbFile};

use super::bricks::{BRICK, Bricks, ReadBrick};
use super::locate::{DATA_FRACTION, check_data_placement};
use super::mapping::Mapping;
use super::placement::{affine_from_rows, placement};
use super::{AMBIENT_MATCH_TOLERANCE, PAD_VOXELS, VdbField, resolve};
use crate::bounds::Bounds;
use crate::field::FieldError;

/// How a grid becomes a field, besides the data itself.
#[derive(Debug, Clone, PartialEq)]
pub struct VdbFieldParams {
    pub mapping: Mapping,
    /// Metres per VDB world unit.
    pub units: f64,
    pub non_finite: NonFinitePolicy,
    /// The medium's bounds (world) and the index outside them; `None` takes the index the
    /// grid's background maps to (`ambient_index = "auto"`).
    pub bounds: Bounds,
    pub ambient: Option<f64>,
    /// Cap on the bytes the loaded voxels (the stored bricks) may use.
    pub max_bytes: u64,
    /// Where the grid (in metres, after `units`) goes in the scene: [`placement()`] of the
    /// scene's `up`, `scale`, `rotate_deg` and `translate`; [`IDENTITY`](super::IDENTITY)
    /// for none.
    pub placement: DAffine3,
}

fn field_error(e: VdbError) -> FieldError {
    FieldError::Vdb(e)
}

impl VdbField {
    /// Build the field of a scene's `[medium]` with `field = { kind = "vdb", ... }`;
    /// relative paths are resolved against `base_dir` (the scene file's directory).
    pub fn from_medium(
        medium: &MediumSpec,
        spec: &VdbSpec,
        base_dir: &Path,
        max_bytes: u64,
    ) -> Result<Self, FieldError> {
        let params = VdbFieldParams {
            mapping: Mapping::from_spec(&spec.map),
            units: spec.units,
            non_finite: spec.non_finite,
            bounds: Bounds::from_spec(&medium.bounds),
            ambient: medium.ambient(),
            max_bytes,
            placement: placement(spec.up, spec.scale, spec.rotate_deg, spec.translate),
        };
        let path = resolve(base_dir, &spec.path);
        Self::load(&path, &spec.grid, &params)
    }

    /// Open `path`, read grid `grid` over its active box (plus padding) and map it.
    pub fn load(path: &Path, grid: &str, params: &VdbFieldParams) -> Result<Self, FieldError> {
        let file = VdbFile::open(path).map_err(field_error)?;
        let info = file.grid(grid).map_err(field_error)?;
        let shown = path.display().to_string();
        let grid_err = |message: String| {
            field_error(VdbError::Grid {
                path: shown.clone(),
                grid: grid.to_owned(),
                message,
            })
        };
        if !info.kind.is_scalar() {
            return Err(field_error(VdbError::WrongType {
                path: shown,
                grid: grid.to_owned(),
                found: info.value_type.clone(),
                expected: "a scalar grid (float or double)",
            }));
        }
        if !info.is_linear {
            return Err(grid_err(format!(
                "non-linear transform ({}); grin supports linear (affine) transforms only",
                info.map_type
            )));
        }
        let Some(active) = info.active_bbox else {
            return Err(grid_err("the grid is empty (no active voxels)".into()));
        };
        // Only the voxels that differ from the background are read (OpenVDB finds their
        // box from its sparse tree): a cache's active box is often its whole domain, and
        // a dense copy of it would be most of the memory a bake uses. A grid with no such
        // voxel is read over its active box (and warned about below).
        let bbox = info.data_bbox.unwrap_or(active).padded(PAD_VOXELS);
        let label = format!("vdb {}:{grid}", path.display());
        // Read brick by brick (OpenVDB's copyToDense of each brick's box): only the bricks
        // with a voxel off the background are kept, so memory follows the data, not its box.
        let mut read = |part: IndexBox, out: &mut Vec<f32>| -> Result<(), FieldError> {
            *out = file
                .read_scalar(grid, part, params.max_bytes)
                .map_err(field_error)?
                .values;
            Ok(())
        };
        Self::from_bricks(
            label,
            bbox,
            &info.transform,
            info.background,
            params,
            &mut read,
        )
    }

    /// Map a dense grid (with its transform and background value) to a field.
    pub fn from_dense(
        label: String,
        dense: &DenseGrid<f32>,
        background: f64,
        params: &VdbFieldParams,
    ) -> Result<Self, FieldError> {
        let d = dense.bbox.dims();
        let dims = d.map(|v| usize::try_from(v).unwrap_or(usize::MAX));
        let count = dims.iter().try_fold(1usize, |acc, &v| acc.checked_mul(v));
        if count != Some(dense.values.len()) || dense.values.is_empty() {
            return Err(FieldError::Other(format!(
                "{label}: dense data has {} values for a {dims:?} box",
                dense.values.len()
            )));
        }
        let mut read = |part: IndexBox, out: &mut Vec<f32>| -> Result<(), FieldError> {
            out.clear();
            let run = (part.max[0] - part.min[0] + 1) as usize;
            for k in part.min[2]..=part.max[2] {
                for j in part.min[1]..=part.max[1] {
                    let start = dense.offset([part.min[0], j, k]).ok_or_else(|| {
                        FieldError::Other(format!("{label}: brick outside the dense data"))
                    })?;
                    out.extend_from_slice(&dense.values[start..start + run]);
                }
            }
            Ok(())
        };
        Self::from_bricks(
            label.clone(),
            dense.bbox,
            &dense.world_from_index,
            background,
            params,
            &mut read,
        )
    }

    /// Map the voxels of `read_box`, read a brick at a time by `read` (the brick's index
    /// box -> its values, x fastest), to a field. Only bricks with a voxel whose index
    /// differs from the background are kept, within `params.max_bytes`.
    fn from_bricks(
        label: String,
        read_box: IndexBox,
        grid_transform: &vdb_sys::Transform,
        background: f64,
        params: &VdbFieldParams,
        read: &mut ReadBrick<'_>,
    ) -> Result<Self, FieldError> {
        let param_err = |param: &str, message: String| FieldError::Param {
            field: label.clone(),
            param: param.to_owned(),
            message,
        };
        params.mapping.check(&label)?;
        if !(params.units > 0.0 && params.units.is_finite()) {
            return Err(param_err(
                "units",
                format!(
                    "{} must be a positive number of metres per VDB unit",
                    params.units
                ),
            ));
        }
        if read_box.voxel_count() == 0 {
            return Err(FieldError::Other(format!(
                "{label}: the grid's box is empty"
            )));
        }
        let grid = affine_from_rows(&grid_transform.world_from_index);
        let in_metres = DAffine3::from_mat3_translation(
            grid.matrix3 * params.units,
            grid.translation * params.units,
        );
        let world_from_grid = params.placement * in_metres;
        let det = world_from_grid.matrix3.determinant();
        if !det.is_finite() || det.abs() < f64::MIN_POSITIVE {
            return Err(FieldError::Other(format!(
                "{label}: the grid transform is singular"
            )));
        }
        let grid_from_world = world_from_grid.inverse();

        let mapping = params.mapping;
        // "auto": the index the background maps to. A relative mapping (`index` with
        // `delta`, `linear`) gives n as an offset from the ambient, so there "auto" is 1.0
        // and its background offset must be within the tolerance like any other ambient.
        let ambient = match params.ambient {
            Some(a) => a,
            None if mapping.is_relative() => 1.0,
            None => mapping.n(background, 1.0).map_err(|t| {
                param_err(
                    "map",
                    format!("the grid background {background} maps to T = {t} K <= 0"),
                )
            })?,
        };
        if !(ambient.is_finite() && ambient > 0.0) {
            return Err(param_err(
                "ambient_index",
                format!("the grid background {background} maps to n = {ambient}, not > 0"),
            ));
        }
        let n_background = mapping.n(background, ambient).map_err(|t| {
            param_err(
                "map",
                format!("the grid background {background} maps to T = {t} K <= 0"),
            )
        })?;
        if (n_background - ambient).abs() > AMBIENT_MATCH_TOLERANCE {
            return Err(param_err(
                "ambient_index",
                format!(
                    "the grid background {background} maps to n = {n_background:.9}, but the \
                     medium's ambient_index is {ambient}; set [medium] ambient_index = \
                     {n_background:.9} (or \"auto\") so rays do not refract at the medium \
                     boundary"
                ),
            ));
        }
        // Within the tolerance the background is taken as the ambient: every mapped index
        // moves by this (<= 1e-6), so the medium's box does not refract and the data's
        // crop sees only the voxels that differ from the background.
        let shift = ambient - n_background;

        let world_of =
            |ijk: [i32; 3]| world_from_grid.transform_point3(DVec3::from_array(ijk.map(f64::from)));

        // Reading costs time for every voxel of the box (the background too), memory only
        // for the bricks kept: a box of more voxels than the cap has bytes is refused as
        // absurd before anything is read (2 Gi voxels, ~10 s of reading, at the default).
        let box_voxels = read_box.voxel_count();
        if box_voxels > u128::from(params.max_bytes) {
            return Err(FieldError::Other(format!(
                "{label}: the grid's data box {:?}..={:?} is {box_voxels} voxels, more than the memory cap of {} bytes allows (one voxel a byte: the box is read a brick at a time and only the bricks that change the index are kept); raise it (`grin bake --max-memory`) or crop the grid",
                read_box.min, read_box.max, params.max_bytes
            )));
        }
        let (mut lo, mut hi) = (ambient, ambient);
        let mut non_finite = 0u64;
        let mut first_non_finite = None;
        let mut checked = |part: IndexBox, out: &mut Vec<f32>| -> Result<(), FieldError> {
            read(part, out)?;
            if out.len() as u128 != part.voxel_count() {
                return Err(FieldError::Other(format!(
                    "{label}: read {} values for a brick of {} voxels",
                    out.len(),
                    part.voxel_count()
                )));
            }
            Ok(())
        };
        let delta_n = |ijk: [i32; 3], v: f32| -> Result<f64, FieldError> {
            if !v.is_finite() {
                non_finite += 1;
                first_non_finite.get_or_insert(ijk);
                return Ok(0.0);
            }
            let n = mapping.n(f64::from(v), ambient).map_err(|t| {
                let p = world_of(ijk);
                param_err(
                    "map",
                    format!(
                        "grid value {v} maps to T = {t} K <= 0 at world ({:.4}, {:.4}, {:.4})",
                        p[0], p[1], p[2]
                    ),
                )
            })? + shift;
            if n <= 0.0 || !n.is_finite() {
                let p = world_of(ijk);
                return Err(FieldError::NonPositive {
                    field: label.clone(),
                    n,
                    x: p[0],
                    y: p[1],
                    z: p[2],
                });
            }
            // What a bake's storage and the GPU's f32 can carry (a value of 1e32 in the
            // grid rendered OPD -inf and rays that left after a few steps).
            if (n - ambient).abs() > crate::baked::MAX_BAKED_DELTA_N {
                let p = world_of(ijk);
                return Err(param_err(
                    "map",
                    format!(
                        "grid value {v} maps to n = {n:e} at world ({:.4}, {:.4}, {:.4}): \
                         |n - ambient| must be at most {} (what a bake and the GPU can carry)",
                        p[0],
                        p[1],
                        p[2],
                        crate::baked::MAX_BAKED_DELTA_N
                    ),
                ));
            }
            lo = lo.min(n);
            hi = hi.max(n);
            Ok(n - ambient)
        };
        let voxels = Bricks::read(
            read_box,
            background,
            params.max_bytes,
            &mut checked,
            delta_n,
            || {
                FieldError::Other(format!(
                    "{label}: the voxels that change the index (in bricks of {BRICK}^3 within the index box {:?}..={:?}) need more than the memory cap of {} bytes; raise it (`grin bake --max-memory`) or crop the grid",
                    read_box.min, read_box.max, params.max_bytes
                ))
            },
        )?;
        if let (Some(ijk), NonFinitePolicy::Reject) = (first_non_finite, params.non_finite) {
            let p = world_of(ijk);
            return Err(FieldError::Other(format!(
                "{label}: {non_finite} NaN/Inf voxel(s) (first at world ({:.4}, {:.4}, {:.4})); \
                 fix the grid or set non_finite = \"ambient\" in the scene to replace them by \
                 the ambient index",
                p[0], p[1], p[2]
            )));
        }

        let warnings = check_data_placement(
            &label,
            voxels.data_box(DATA_FRACTION),
            &world_from_grid,
            &params.bounds,
        )?;

        // Keep the box of the voxels that change the index (and PAD_VOXELS of background
        // around them): a cache's active box is often its whole domain. Exact: what is
        // outside is background, which the field returns there anyway.
        let bbox = match voxels.data_box(0.0) {
            Some(data) => {
                let pad = i64::from(PAD_VOXELS);
                IndexBox {
                    min: std::array::from_fn(|a| {
                        (data.min[a] - pad).max(i64::from(read_box.min[a])) as i32
                    }),
                    max: std::array::from_fn(|a| {
                        (data.max[a] + pad).min(i64::from(read_box.max[a])) as i32
                    }),
                }
            }
            None => read_box,
        };
        let dims = bbox.dims().map(|d| d as usize);

        let mut field = VdbField {
            label,
            bounds: params.bounds,
            ambient,
            voxels,
            bbox,
            dims,
            grid_from_world,
            world_from_grid,
            n_range: (lo, hi),
            max_grad: 0.0,
            non_finite_replaced: non_finite,
            mapping,
            warnings,
        };
        field.max_grad = field.max_node_gradient();
        Ok(field)
    }
}
