//! VDB-sourced fields: an OpenVDB scalar grid (temperature, density or index) mapped to a
//! refractive index n(r) in world space, through vdb-sys.
//!
//! Mapping (scene `map`), applied to every voxel before interpolation:
//! - `index`: n = value, or n = n_ambient + value with `delta = true`;
//! - `linear`: n = n_ambient + k * value;
//! - `gladstone-dale` (air): T_K = T_ambient + scale_k * value, rho = P / (R_s T_K),
//!   n = 1 + K rho (docs/physics.md, Air; defaults K = 2.26e-4 m^3/kg, P = 101325 Pa,
//!   R_s = 287.05 J/(kg K)).
//!
//! World space: world (scene metres) = `units` * (A * ijk + t), where `[A | t]` is the
//! grid's affine index-to-world transform (voxel size, rotation, offset). Non-linear
//! (frustum) transforms are rejected. Integer index coordinates are voxel centres.
//!
//! Interpolation: tricubic Catmull-Rom on the mapped delta_n = n - n_ambient, with the
//! gradient the exact derivative of that interpolant. It passes through the voxel values,
//! reproduces quadratics and is C1, so grad n is continuous (no kinks for the
//! integrators); the interpolation error of a smooth field is O(h^3) in n and O(h^2) in
//! grad n (h = voxel size). For the Gaussian of `data/vdb/test/gaussian.vdb` (width
//! s = 10 voxels, f32 storage) tests/vdb.rs measures max |n error| = 1.2e-4 of the
//! amplitude, max |grad n error| = 6.6e-3 of max |grad n|, and ray exit directions within
//! 0.25 % of the rays' bend (asserted: 5e-4, 2e-2 and 1 %). The unit test
//! `catmull_rom_converges_at_third_order_in_n_and_second_in_grad` measures the orders:
//! 3.0 in n and 1.9 in grad n (s/h = 8 -> 16).
//! At a voxel centre the gradient equals the central difference of the mapped values.
//! The interpolant is clamped to the range of the mapped values (background included),
//! with a zero gradient where clamped: at a sharp edge Catmull-Rom rings past the data
//! (n above ambient beside a hot plume, a voxel outside a blob 1e-5 off ambient where
//! OpenVDB's own sampler gives ambient), and the clamp keeps every sample, and so every
//! bake, within what the mapping produces (`interpolant_stays_in_the_mapped_range`).
//! Smooth data away from its extreme voxels is unchanged (the orders below hold).
//! Outside the grid's data box the field is the mapped background value.
//!
//! Storage: the data box is read a brick of 32^3 voxels at a time (OpenVDB's copyToDense
//! of the brick) and only the bricks with a voxel whose index differs from the background
//! are kept ([`Bricks`]): memory follows the data, not its box (two blocks 300 voxels
//! apart: 0.5 MB kept where the dense copy took 344 MB; 32 voxels a side: smaller bricks
//! sent more samples across brick edges, 16 made fire-haze's bake 1.33 -> 1.7 s). `max_bytes` caps the bricks
//! kept, and the box itself at one voxel a byte (reading costs time for every voxel).
//!
//! One concept, one file: mapping, crop and interpolation of a grid share their state.

use std::path::{Path, PathBuf};

use glam::DVec3;
use grin_scene::{MediumSpec, NonFinitePolicy, UpAxis, VdbMap, VdbSpec};
use vdb_sys::{DenseGrid, IndexBox, VdbError, VdbFile};

use crate::bounds::Bounds;
use crate::field::{FieldError, FieldSample, IndexField};

/// Default cap on the memory of a grid's voxels as loaded (the stored bricks of mapped
/// delta_n): 2 GiB.
pub const DEFAULT_MAX_DENSE_BYTES: u64 = 2 << 30;
/// Reads the values of an index box (x fastest) into the vector: a grid's brick.
type ReadBrick<'a, E = FieldError> = dyn FnMut(IndexBox, &mut Vec<f32>) -> Result<(), E> + 'a;
/// Edge of a brick of the loaded voxels ([`Bricks`]), in voxels.
const BRICK: usize = 32;
/// Voxels in a brick.
const BRICK_VOXELS: usize = BRICK * BRICK * BRICK;
/// Voxels of background read around the active box, so the 4-tap stencil near the edge
/// of the data reads real (background) values.
pub const PAD_VOXELS: i32 = 2;
/// Largest allowed |n(background) - ambient_index|: a larger jump would refract every
/// ray at the invisible medium boundary (heat haze itself is ~1e-5).
pub const AMBIENT_MATCH_TOLERANCE: f64 = 1e-6;

/// Air's index by Gladstone-Dale for the scene's `gladstone-dale` parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GladstoneDale {
    pub ambient_temperature_k: f64,
    pub scale_k: f64,
    pub pressure_pa: f64,
    pub k_gd: f64,
    pub r_specific: f64,
}

impl GladstoneDale {
    /// n of air at absolute temperature `t_k` (ideal gas at constant pressure).
    pub fn n_at_temperature(&self, t_k: f64) -> f64 {
        let rho = self.pressure_pa / (self.r_specific * t_k);
        1.0 + self.k_gd * rho
    }

    /// T_K for a (unitless) simulation temperature.
    pub fn temperature_k(&self, value: f64) -> f64 {
        self.ambient_temperature_k + self.scale_k * value
    }
}

/// A scalar grid value -> n mapping (the scene's `map`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Mapping {
    Index { delta: bool },
    Linear { k: f64 },
    GladstoneDale(GladstoneDale),
}

impl Mapping {
    pub fn from_spec(map: &VdbMap) -> Self {
        match *map {
            VdbMap::Index { delta } => Mapping::Index { delta },
            VdbMap::Linear { k } => Mapping::Linear { k },
            VdbMap::GladstoneDale {
                ambient_temperature_k,
                scale_k,
                pressure_pa,
                k_gd,
                r_specific,
            } => Mapping::GladstoneDale(GladstoneDale {
                ambient_temperature_k,
                scale_k,
                pressure_pa,
                k_gd,
                r_specific,
            }),
        }
    }

    /// True where n is an offset from the ambient index (`index` with `delta`, `linear`).
    pub fn is_relative(&self) -> bool {
        matches!(
            self,
            Mapping::Index { delta: true } | Mapping::Linear { .. }
        )
    }

    /// n for one grid value; `Err(T_K)` for a non-positive absolute temperature.
    pub fn n(&self, value: f64, ambient: f64) -> Result<f64, f64> {
        match *self {
            Mapping::Index { delta: false } => Ok(value),
            Mapping::Index { delta: true } => Ok(ambient + value),
            Mapping::Linear { k } => Ok(ambient + k * value),
            Mapping::GladstoneDale(gd) => {
                let t = gd.temperature_k(value);
                if t > 0.0 {
                    Ok(gd.n_at_temperature(t))
                } else {
                    Err(t)
                }
            }
        }
    }

    fn describe(&self) -> String {
        match *self {
            Mapping::Index { delta } => format!("index (delta={delta})"),
            Mapping::Linear { k } => format!("linear k={k}"),
            Mapping::GladstoneDale(gd) => format!(
                "gladstone-dale T={}K+{}K*v",
                gd.ambient_temperature_k, gd.scale_k
            ),
        }
    }

    fn check(&self, field: &str) -> Result<(), FieldError> {
        let bad = |param: &str, message: &str| {
            Err(FieldError::Param {
                field: field.to_owned(),
                param: param.to_owned(),
                message: message.to_owned(),
            })
        };
        match *self {
            Mapping::Index { .. } => Ok(()),
            Mapping::Linear { k } if !k.is_finite() => bad("k", "must be finite"),
            Mapping::Linear { .. } => Ok(()),
            Mapping::GladstoneDale(gd) => {
                if !(gd.ambient_temperature_k > 0.0 && gd.ambient_temperature_k.is_finite()) {
                    bad(
                        "ambient_temperature_k",
                        "must be a positive temperature in kelvin",
                    )
                } else if !gd.scale_k.is_finite() {
                    bad("scale_k", "must be finite")
                } else if !(gd.pressure_pa > 0.0 && gd.pressure_pa.is_finite()) {
                    bad("pressure_pa", "must be positive")
                } else if !(gd.k_gd >= 0.0 && gd.k_gd.is_finite()) {
                    bad("k_gd", "must be non-negative")
                } else if !(gd.r_specific > 0.0 && gd.r_specific.is_finite()) {
                    bad("r_specific", "must be positive")
                } else {
                    Ok(())
                }
            }
        }
    }
}

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
    /// Where the grid (in metres, after `units`) goes in the scene: [`placement`] of the
    /// scene's `up`, `scale`, `rotate_deg` and `translate`; [`IDENTITY`] for none.
    pub placement: [[f64; 4]; 3],
}

/// The affine map that changes nothing.
pub const IDENTITY: [[f64; 4]; 3] = [
    [1.0, 0.0, 0.0, 0.0],
    [0.0, 1.0, 0.0, 0.0],
    [0.0, 0.0, 1.0, 0.0],
];

/// The scene's placement of a VDB grid (world = placement * grid metres): first the up
/// axis (a Z-up cache, as Blender writes, is turned so its +z is the scene's +y and its +y
/// the scene's -z), then the uniform `scale`, then rotations by `rotate_deg` about the
/// scene's x, then y, then z axes (right-handed, degrees), then `translate` (metres).
pub fn placement(
    up: UpAxis,
    scale: f64,
    rotate_deg: [f64; 3],
    translate: [f64; 3],
) -> [[f64; 4]; 3] {
    let up_m = match up {
        UpAxis::Y => IDENTITY,
        UpAxis::Z => [
            [1.0, 0.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
            [0.0, -1.0, 0.0, 0.0],
        ],
    };
    let scaled = IDENTITY.map(|row| row.map(|v| v * scale));
    let rot = |axis: usize, deg: f64| {
        let (s, c) = deg.to_radians().sin_cos();
        let (a, b) = ((axis + 1) % 3, (axis + 2) % 3);
        let mut m = IDENTITY;
        m[a][a] = c;
        m[a][b] = -s;
        m[b][a] = s;
        m[b][b] = c;
        m
    };
    let mut m = compose(&scaled, &up_m);
    for (axis, &deg) in rotate_deg.iter().enumerate() {
        m = compose(&rot(axis, deg), &m);
    }
    for (row, t) in m.iter_mut().zip(translate) {
        row[3] += t;
    }
    m
}

/// The affine map `a` after `b` (a * b).
pub fn compose(a: &[[f64; 4]; 3], b: &[[f64; 4]; 3]) -> [[f64; 4]; 3] {
    std::array::from_fn(|r| {
        std::array::from_fn(|c| {
            let lin: f64 = (0..3).map(|k| a[r][k] * b[k][c]).sum();
            if c == 3 { lin + a[r][3] } else { lin }
        })
    })
}

/// An OpenVDB grid mapped to n, sampled by tricubic Catmull-Rom interpolation.
#[derive(Debug, Clone)]
pub struct VdbField {
    label: String,
    bounds: Bounds,
    ambient: f64,
    /// delta_n = n - ambient at the voxels read (0 where not stored: the background is
    /// the ambient, see `from_bricks`).
    voxels: Bricks,
    /// The box of the voxels that change the index, plus [`PAD_VOXELS`]: delta_n is 0
    /// outside it.
    bbox: IndexBox,
    dims: [usize; 3],
    /// index = grid_from_world * (p, 1), p in scene metres.
    grid_from_world: [[f64; 4]; 3],
    /// world = world_from_grid * (ijk, 1), in scene metres.
    world_from_grid: [[f64; 4]; 3],
    n_range: (f64, f64),
    max_grad: f64,
    non_finite_replaced: u64,
    mapping: Mapping,
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
        let mut in_metres = grid_transform.world_from_index;
        for row in &mut in_metres {
            for v in row.iter_mut() {
                *v *= params.units;
            }
        }
        let world_from_grid = compose(&params.placement, &in_metres);
        let inverse = vdb_sys::Transform {
            world_from_index: world_from_grid,
        }
        .inverse()
        .ok_or_else(|| FieldError::Other(format!("{label}: the grid transform is singular")))?;

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

        let transform = vdb_sys::Transform {
            world_from_index: world_from_grid,
        };
        let world_of = |ijk: [i32; 3]| transform.index_to_world(ijk.map(f64::from));

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

        check_data_placement(
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
            grid_from_world: inverse.world_from_index,
            world_from_grid,
            n_range: (lo, hi),
            max_grad: 0.0,
            non_finite_replaced: non_finite,
            mapping,
        };
        field.max_grad = field.max_node_gradient();
        Ok(field)
    }

    /// NaN/Inf voxels replaced by the ambient index (policy `ambient`).
    pub fn non_finite_replaced(&self) -> u64 {
        self.non_finite_replaced
    }

    /// Bytes of the voxels kept (the stored bricks and their table).
    pub fn voxel_bytes(&self) -> u64 {
        self.voxels.stored_bytes()
    }

    /// The dense box (index space) the field holds.
    pub fn index_box(&self) -> IndexBox {
        self.bbox
    }

    /// World (scene metres) position of index coordinates.
    pub fn world_from_index(&self, ijk: DVec3) -> DVec3 {
        DVec3::from_array(apply(&self.world_from_grid, ijk.to_array()))
    }

    /// Fractional index coordinates of a world point.
    pub fn index_from_world(&self, p: DVec3) -> DVec3 {
        DVec3::from_array(apply(&self.grid_from_world, p.to_array()))
    }

    /// World-space axis-aligned box around the dense data.
    pub fn world_aabb(&self) -> (DVec3, DVec3) {
        let mut lo = DVec3::splat(f64::INFINITY);
        let mut hi = DVec3::splat(f64::NEG_INFINITY);
        for c in 0..8 {
            let pick = |a: usize| {
                if c >> a & 1 == 0 {
                    f64::from(self.bbox.min[a])
                } else {
                    f64::from(self.bbox.max[a])
                }
            };
            let w = self.world_from_index(DVec3::new(pick(0), pick(1), pick(2)));
            lo = lo.min(w);
            hi = hi.max(w);
        }
        (lo, hi)
    }

    /// delta_n at index (i, j, k) relative to the box's minimum corner (0 outside it).
    fn node(&self, i: i64, j: i64, k: i64) -> f64 {
        let d = &self.dims;
        if i < 0 || j < 0 || k < 0 || i >= d[0] as i64 || j >= d[1] as i64 || k >= d[2] as i64 {
            return 0.0;
        }
        let m = self.bbox.min.map(i64::from);
        self.voxels.get([i + m[0], j + m[1], k + m[2]])
    }

    /// Gradient (world) from index-space derivatives: grad_world = A^-T grad_index.
    fn grad_to_world(&self, g: [f64; 3]) -> DVec3 {
        let m = &self.grid_from_world;
        DVec3::new(
            m[0][0] * g[0] + m[1][0] * g[1] + m[2][0] * g[2],
            m[0][1] * g[0] + m[1][1] * g[1] + m[2][1] * g[2],
            m[0][2] * g[0] + m[1][2] * g[1] + m[2][2] * g[2],
        )
    }

    /// The largest |grad n| of the voxels' central differences: over the stored bricks
    /// and the voxels next to them (elsewhere every difference is 0).
    fn max_node_gradient(&self) -> f64 {
        let d = self.dims.map(|v| v as i64);
        let m = self.bbox.min.map(i64::from);
        let mut max2: f64 = 0.0;
        for part in self.voxels.stored_boxes() {
            let lo: [i64; 3] = std::array::from_fn(|a| (i64::from(part.min[a]) - 1 - m[a]).max(0));
            let hi: [i64; 3] =
                std::array::from_fn(|a| (i64::from(part.max[a]) + 1 - m[a]).min(d[a] - 1));
            for k in lo[2]..=hi[2] {
                for j in lo[1]..=hi[1] {
                    for i in lo[0]..=hi[0] {
                        let g = [
                            0.5 * (self.node(i + 1, j, k) - self.node(i - 1, j, k)),
                            0.5 * (self.node(i, j + 1, k) - self.node(i, j - 1, k)),
                            0.5 * (self.node(i, j, k + 1) - self.node(i, j, k - 1)),
                        ];
                        max2 = max2.max(self.grad_to_world(g).length_squared());
                    }
                }
            }
        }
        max2.sqrt()
    }

    /// delta_n and its index-space gradient at fractional index coordinates `u`
    /// (relative to the dense box's minimum corner).
    fn catmull_rom(&self, u: [f64; 3]) -> (f64, [f64; 3]) {
        let base: [f64; 3] = u.map(f64::floor);
        let t = [u[0] - base[0], u[1] - base[1], u[2] - base[2]];
        let w = t.map(catmull_rom_weights);
        let dw = t.map(catmull_rom_weight_derivatives);
        // Far outside the box (also NaN/huge coordinates): background, flat.
        let far = base
            .iter()
            .zip(self.dims.iter())
            .any(|(&b, &d)| !(b >= -3.0 && b <= d as f64 + 2.0));
        if far {
            return (0.0, [0.0; 3]);
        }
        let m = self.bbox.min.map(i64::from);
        let taps = self
            .voxels
            .stencil(std::array::from_fn(|a| base[a] as i64 - 1 + m[a]));
        let (mut v, mut gx, mut gy, mut gz) = (0.0, 0.0, 0.0, 0.0);
        for c in 0..4 {
            for bj in 0..4 {
                let mut row_v = 0.0;
                let mut row_dx = 0.0;
                for a in 0..4 {
                    let f = taps[a + 4 * (bj + 4 * c)];
                    row_v += w[0][a] * f;
                    row_dx += dw[0][a] * f;
                }
                let wyz = w[1][bj] * w[2][c];
                v += wyz * row_v;
                gx += wyz * row_dx;
                gy += dw[1][bj] * w[2][c] * row_v;
                gz += w[1][bj] * dw[2][c] * row_v;
            }
        }
        (v, [gx, gy, gz])
    }
}

/// Every frame of a VDB sequence (frames `first..=last` of `scene`, whose medium's path
/// holds a frame token) before any is rendered or baked: each file opens and holds the
/// grid, as a scalar grid with a linear transform, of the same value type as the first
/// frame's. The error names the frame, its file and what differs. Not a VDB sequence: Ok.
pub fn check_sequence(
    scene: &grin_scene::Scene,
    scene_dir: &Path,
    first: i64,
    last: i64,
) -> Result<(), FieldError> {
    let Some(grin_scene::FieldSpec::Vdb(spec)) = scene.medium.as_ref().map(|m| &m.field) else {
        return Ok(());
    };
    if !grin_scene::frames::has_frame_token(&spec.path) {
        return Ok(());
    }
    let mut first_type: Option<(i64, String)> = None;
    for f in first..=last {
        let Some(name) = grin_scene::frames::substitute_frame(&spec.path, f) else {
            continue;
        };
        let path = resolve(scene_dir, &name);
        let in_frame = |e: String| FieldError::Other(format!("frame {f}: {e}"));
        let file = VdbFile::open(&path).map_err(|e| in_frame(e.to_string()))?;
        let info = file.grid(&spec.grid).map_err(|e| in_frame(e.to_string()))?;
        if !info.kind.is_scalar() {
            return Err(in_frame(format!(
                "{}: grid `{}` has value type `{}`, a scalar grid (float or double) is needed",
                path.display(),
                spec.grid,
                info.value_type
            )));
        }
        if !info.is_linear {
            return Err(in_frame(format!(
                "{}: grid `{}` has a non-linear transform ({})",
                path.display(),
                spec.grid,
                info.map_type
            )));
        }
        match &first_type {
            None => first_type = Some((f, info.value_type.clone())),
            Some((f0, t0)) if *t0 != info.value_type => {
                return Err(in_frame(format!(
                    "{}: grid `{}` is `{}`, but `{t0}` in frame {f0}: a sequence keeps one type",
                    path.display(),
                    spec.grid,
                    info.value_type
                )));
            }
            Some(_) => {}
        }
    }
    Ok(())
}

/// Voxels whose change from the background is at most this fraction of the largest change
/// count as background when framing the data (faint residue is not what a user frames).
pub const DATA_FRACTION: f64 = 1e-3;

/// Voxel values (delta_n) over an index box in bricks of [`BRICK`]^3 (x fastest within a
/// brick), only the bricks with a non-zero value stored: a cache's data box is mostly
/// background (smoke in one corner of it, a shell), and a dense copy of the box was most
/// of the memory a load used.
#[derive(Debug, Clone)]
struct Bricks {
    /// Index of the store's first voxel.
    origin: [i32; 3],
    /// Voxels along each axis.
    dims: [usize; 3],
    /// Bricks along each axis.
    counts: [usize; 3],
    bricks: Vec<Option<Box<[f64]>>>,
}

impl Bricks {
    /// An empty store (every value 0) over `bbox`.
    fn new(bbox: IndexBox) -> Self {
        let dims = bbox
            .dims()
            .map(|d| usize::try_from(d).unwrap_or(usize::MAX));
        let counts = dims.map(|d| d.div_ceil(BRICK));
        Bricks {
            origin: bbox.min,
            dims,
            counts,
            bricks: vec![None; counts.iter().product()],
        }
    }

    /// The store over `bbox`, read a brick at a time by `read` (the brick's box -> its
    /// values, x fastest). A brick all at `background` is skipped (most bricks of a sparse
    /// cache); the others keep `voxel(index, value)` of each voxel and are stored where one
    /// of those is not 0. An error of `read` or `voxel`, or `over_cap()` once the store
    /// holds more than `max_bytes`, ends the read.
    fn read<E>(
        bbox: IndexBox,
        background: f64,
        max_bytes: u64,
        read: &mut ReadBrick<'_, E>,
        mut voxel: impl FnMut([i32; 3], f32) -> Result<f64, E>,
        over_cap: impl Fn() -> E,
    ) -> Result<Self, E> {
        let mut store = Bricks::new(bbox);
        let mut values = Vec::new();
        for b in store.brick_indices() {
            let part = store.brick_box(b);
            read(part, &mut values)?;
            if values.iter().all(|&v| f64::from(v) == background) {
                continue;
            }
            let mut brick = vec![0.0f64; BRICK_VOXELS].into_boxed_slice();
            let mut it = values.iter();
            for k in part.min[2]..=part.max[2] {
                for j in part.min[1]..=part.max[1] {
                    for i in part.min[0]..=part.max[0] {
                        let Some(&v) = it.next() else { break };
                        brick[store.local_offset([i, j, k])] = voxel([i, j, k], v)?;
                    }
                }
            }
            store.put(b, brick);
            if store.stored_bytes() > max_bytes {
                return Err(over_cap());
            }
        }
        Ok(store)
    }

    /// Every brick's position in the brick grid, x fastest.
    fn brick_indices(&self) -> impl Iterator<Item = [usize; 3]> + use<> {
        let c = self.counts;
        (0..c[2]).flat_map(move |k| (0..c[1]).flat_map(move |j| (0..c[0]).map(move |i| [i, j, k])))
    }

    /// The index box of brick `b`, clipped to the store.
    fn brick_box(&self, b: [usize; 3]) -> IndexBox {
        IndexBox {
            min: std::array::from_fn(|a| self.origin[a] + (b[a] * BRICK) as i32),
            max: std::array::from_fn(|a| {
                self.origin[a] + ((b[a] * BRICK + BRICK).min(self.dims[a]) - 1) as i32
            }),
        }
    }

    fn slot(&self, b: [usize; 3]) -> usize {
        b[0] + self.counts[0] * (b[1] + self.counts[1] * b[2])
    }

    /// Offset of index `ijk` (inside the store) within its brick.
    fn local_offset(&self, ijk: [i32; 3]) -> usize {
        let l: [usize; 3] = std::array::from_fn(|a| (ijk[a] - self.origin[a]) as usize % BRICK);
        l[0] + BRICK * (l[1] + BRICK * l[2])
    }

    /// Keep brick `b`'s values unless every one is 0.
    fn put(&mut self, b: [usize; 3], values: Box<[f64]>) {
        if values.iter().any(|&v| v != 0.0) {
            let slot = self.slot(b);
            self.bricks[slot] = Some(values);
        }
    }

    /// The value at index `ijk`: 0 outside the store or in a brick not stored.
    fn get(&self, ijk: [i64; 3]) -> f64 {
        let mut l = [0usize; 3];
        for a in 0..3 {
            let r = ijk[a] - i64::from(self.origin[a]);
            if r < 0 || r >= self.dims[a] as i64 {
                return 0.0;
            }
            l[a] = r as usize;
        }
        match &self.bricks[self.slot(l.map(|v| v / BRICK))] {
            Some(v) => v[l[0] % BRICK + BRICK * (l[1] % BRICK + BRICK * (l[2] % BRICK))],
            None => 0.0,
        }
    }

    /// The 4x4x4 values from index `min` on (x fastest): straight from one brick when the
    /// block lies in it (most samples), else value by value.
    fn stencil(&self, min: [i64; 3]) -> [f64; 64] {
        let mut out = [0.0; 64];
        let r: [i64; 3] = std::array::from_fn(|a| min[a] - i64::from(self.origin[a]));
        let one_brick = (0..3).all(|a| {
            r[a] >= 0
                && r[a] + 3 < self.dims[a] as i64
                && r[a] as usize / BRICK == (r[a] as usize + 3) / BRICK
        });
        if one_brick {
            let r = r.map(|v| v as usize);
            if let Some(v) = &self.bricks[self.slot(r.map(|x| x / BRICK))] {
                let l = r.map(|x| x % BRICK);
                for c in 0..4 {
                    for j in 0..4 {
                        let at = l[0] + BRICK * (l[1] + j + BRICK * (l[2] + c));
                        out[4 * (j + 4 * c)..4 * (j + 4 * c) + 4].copy_from_slice(&v[at..at + 4]);
                    }
                }
            }
            return out;
        }
        // Across bricks: each axis's 4 taps as (brick, offset in it), or outside.
        let axis = |a: usize| -> [Option<(usize, usize)>; 4] {
            std::array::from_fn(|t| {
                let v = r[a] + t as i64;
                (v >= 0 && v < self.dims[a] as i64)
                    .then_some((v as usize / BRICK, v as usize % BRICK))
            })
        };
        let (ax, ay, az) = (axis(0), axis(1), axis(2));
        for (c, z) in az.iter().enumerate() {
            let Some((bz, lz)) = *z else { continue };
            for (j, y) in ay.iter().enumerate() {
                let Some((by, ly)) = *y else { continue };
                for (i, x) in ax.iter().enumerate() {
                    let Some((bx, lx)) = *x else { continue };
                    if let Some(v) = &self.bricks[self.slot([bx, by, bz])] {
                        out[i + 4 * (j + 4 * c)] = v[lx + BRICK * (ly + BRICK * lz)];
                    }
                }
            }
        }
        out
    }

    /// Bytes held: the stored bricks and the brick table.
    fn stored_bytes(&self) -> u64 {
        let stored = self.bricks.iter().filter(|b| b.is_some()).count() as u64;
        stored * (BRICK_VOXELS * 8) as u64 + self.bricks.len() as u64 * 16
    }

    /// The index boxes of the stored bricks.
    fn stored_boxes(&self) -> Vec<IndexBox> {
        self.brick_indices()
            .filter(|&b| self.bricks[self.slot(b)].is_some())
            .map(|b| self.brick_box(b))
            .collect()
    }

    /// `f(index, value)` for every voxel of the stored bricks.
    fn each_stored(&self, mut f: impl FnMut([i64; 3], f64)) {
        for part in self.stored_boxes() {
            for k in part.min[2]..=part.max[2] {
                for j in part.min[1]..=part.max[1] {
                    for i in part.min[0]..=part.max[0] {
                        let ijk = [i64::from(i), i64::from(j), i64::from(k)];
                        f(ijk, self.get(ijk));
                    }
                }
            }
        }
    }

    /// The box of the voxels whose |value| is above `fraction` of the largest (0: every
    /// voxel that is not 0); `None` when every value is 0.
    fn data_box(&self, fraction: f64) -> Option<DataBox> {
        let mut peak = 0.0f64;
        self.each_stored(|_, d| {
            if d.is_finite() {
                peak = peak.max(d.abs());
            }
        });
        if peak == 0.0 {
            return None;
        }
        let (mut lo, mut hi) = ([i64::MAX; 3], [i64::MIN; 3]);
        self.each_stored(|ijk, d| {
            if d.abs() > fraction * peak {
                for a in 0..3 {
                    lo[a] = lo[a].min(ijk[a]);
                    hi[a] = hi[a].max(ijk[a]);
                }
            }
        });
        (lo[0] != i64::MAX).then_some(DataBox { min: lo, max: hi })
    }
}

/// Where scalar grid `grid` of `file` has its data ([`DataBox`]: the voxels whose change
/// from the background is above [`DATA_FRACTION`] of the largest), read a brick at a
/// time over the box OpenVDB gives for its non-background values (else its active box),
/// keeping only the bricks that change anything: `Ok(None)` where no value leaves the
/// background. `max_bytes` caps the bricks kept and the box at one voxel a byte.
pub fn locate_data(
    file: &VdbFile,
    grid: &vdb_sys::GridInfo,
    max_bytes: u64,
) -> Result<Option<DataBox>, String> {
    let Some(bbox) = grid.data_bbox.or(grid.active_bbox) else {
        return Ok(None);
    };
    if bbox.voxel_count() > u128::from(max_bytes) {
        return Err(format!(
            "its data box {:?}..={:?} is {} voxels, more than the {max_bytes} read here",
            bbox.min,
            bbox.max,
            bbox.voxel_count()
        ));
    }
    let mut read = |part: IndexBox, out: &mut Vec<f32>| -> Result<(), String> {
        *out = file
            .read_scalar(&grid.name, part, max_bytes)
            .map_err(|e| e.to_string())?
            .values;
        Ok(())
    };
    let change = Bricks::read(
        bbox,
        grid.background,
        max_bytes,
        &mut read,
        |_, v| {
            let d = (f64::from(v) - grid.background).abs();
            Ok(if d.is_finite() { d } else { 0.0 })
        },
        || format!("its non-background voxels need more than the {max_bytes} bytes read here"),
    )?;
    Ok(change.data_box(DATA_FRACTION))
}

/// The index box of a grid's data: the voxels whose change from the background is above
/// [`DATA_FRACTION`] of the largest change.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DataBox {
    /// Inclusive index bounds (the grid's own index space).
    pub min: [i64; 3],
    pub max: [i64; 3],
}

impl DataBox {
    /// The data box of `change` (|value - background| per voxel, x fastest over `dims`,
    /// starting at index `min_index`); `None` when no voxel changes anything.
    pub fn find(change: &[f64], dims: [usize; 3], min_index: [i32; 3]) -> Option<DataBox> {
        Self::find_above(change, dims, min_index, DATA_FRACTION)
    }

    /// The box of the voxels whose change is above `fraction` of the largest (0: every
    /// voxel that changes anything).
    pub fn find_above(
        change: &[f64],
        dims: [usize; 3],
        min_index: [i32; 3],
        fraction: f64,
    ) -> Option<DataBox> {
        let peak = change
            .iter()
            .filter(|d| d.is_finite())
            .fold(0.0f64, |a, d| a.max(d.abs()));
        if peak == 0.0 {
            return None;
        }
        let mut lo = [usize::MAX; 3];
        let mut hi = [0usize; 3];
        for (off, &d) in change.iter().enumerate() {
            // NaN compares false: not data.
            if d.abs().partial_cmp(&(fraction * peak)) != Some(std::cmp::Ordering::Greater) {
                continue;
            }
            let ijk = [
                off % dims[0],
                (off / dims[0]) % dims[1],
                off / (dims[0] * dims[1]),
            ];
            for a in 0..3 {
                lo[a] = lo[a].min(ijk[a]);
                hi[a] = hi[a].max(ijk[a]);
            }
        }
        (lo[0] != usize::MAX).then(|| DataBox {
            min: std::array::from_fn(|a| lo[a] as i64 + i64::from(min_index[a])),
            max: std::array::from_fn(|a| hi[a] as i64 + i64::from(min_index[a])),
        })
    }

    /// World box of the box's voxel centres widened by `pad` voxels, through the affine
    /// `world_from_index`.
    pub fn world(&self, world_from_index: &[[f64; 4]; 3], pad: f64) -> (DVec3, DVec3) {
        let (mut lo, mut hi) = (DVec3::splat(f64::MAX), DVec3::splat(f64::MIN));
        for c in 0..8 {
            let ijk: [f64; 3] = std::array::from_fn(|a| {
                if c >> a & 1 == 0 {
                    self.min[a] as f64 - pad
                } else {
                    self.max[a] as f64 + pad
                }
            });
            let w = DVec3::from_array(apply(world_from_index, ijk));
            lo = lo.min(w);
            hi = hi.max(w);
        }
        (lo, hi)
    }

    /// The `bounds` line of a scene that holds the data (half a voxel past the centres).
    pub fn bounds_line(&self, world_from_index: &[[f64; 4]; 3]) -> String {
        let (lo, hi) = self.world(world_from_index, 0.5);
        format!(
            "bounds = {{ box = {{ min = {}, max = {} }} }}",
            fmt3(lo),
            fmt3(hi)
        )
    }
}

fn fmt3(v: DVec3) -> String {
    format!("[{:.4}, {:.4}, {:.4}]", v.x, v.y, v.z)
}

/// Where the grid's data ([`DataBox`]) lies against the medium's bounds: bounds that miss
/// it are an error, bounds that cut it and data that changes nothing are warnings on
/// stderr. Each names the data's world box and a `bounds` line that holds it.
fn check_data_placement(
    label: &str,
    data: Option<DataBox>,
    world_from_index: &[[f64; 4]; 3],
    bounds: &Bounds,
) -> Result<(), FieldError> {
    let Some(data) = data else {
        eprintln!(
            "grin: warning: {label}: every voxel maps to the background's index (a constant grid, or a mapping that changes nothing): the medium bends no ray"
        );
        return Ok(());
    };
    // The data's world box through its voxel centres (what the bounds must hold), and
    // half a voxel out (what the suggested bounds give).
    let (lo, hi) = data.world(world_from_index, 0.0);
    let (plo, phi) = data.world(world_from_index, 0.5);
    let fix = data.bounds_line(world_from_index);
    if !bounds.meets_box(lo, hi, 0.0) {
        return Err(FieldError::Param {
            field: label.to_owned(),
            param: "bounds".into(),
            message: format!(
                "the [medium] bounds miss the grid's data, which lies in world box {} .. {}; to hold it: {fix}",
                fmt3(plo),
                fmt3(phi)
            ),
        });
    }
    let corners_inside = (0..8).all(|c: u32| {
        let p = DVec3::new(
            if c & 1 == 0 { lo.x } else { hi.x },
            if c & 2 == 0 { lo.y } else { hi.y },
            if c & 4 == 0 { lo.z } else { hi.z },
        );
        bounds.signed_distance(p) <= 1e-9 * (1.0 + p.length())
    });
    if !corners_inside {
        eprintln!(
            "grin: warning: {label}: the [medium] bounds cut the grid's data (world box {} .. {}): rays see only the part inside; to hold it all: {fix}",
            fmt3(plo),
            fmt3(phi)
        );
    }
    Ok(())
}

/// Catmull-Rom weights of the taps at offsets -1, 0, 1, 2 for fraction `t`.
fn catmull_rom_weights(t: f64) -> [f64; 4] {
    let t2 = t * t;
    let t3 = t2 * t;
    [
        0.5 * (-t3 + 2.0 * t2 - t),
        0.5 * (3.0 * t3 - 5.0 * t2 + 2.0),
        0.5 * (-3.0 * t3 + 4.0 * t2 + t),
        0.5 * (t3 - t2),
    ]
}

/// d/dt of [`catmull_rom_weights`].
fn catmull_rom_weight_derivatives(t: f64) -> [f64; 4] {
    let t2 = t * t;
    [
        0.5 * (-3.0 * t2 + 4.0 * t - 1.0),
        0.5 * (9.0 * t2 - 10.0 * t),
        0.5 * (-9.0 * t2 + 8.0 * t + 1.0),
        0.5 * (3.0 * t2 - 2.0 * t),
    ]
}

fn apply(m: &[[f64; 4]; 3], p: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|r| m[r][0] * p[0] + m[r][1] * p[1] + m[r][2] * p[2] + m[r][3])
}

/// A scene-relative path resolved against the scene's directory.
pub fn resolve(base_dir: &Path, path: &str) -> PathBuf {
    let p = Path::new(path);
    if p.is_absolute() {
        p.to_path_buf()
    } else {
        base_dir.join(p)
    }
}

impl IndexField for VdbField {
    fn sample(&self, p: DVec3) -> FieldSample<f64> {
        let idx = self.index_from_world(p);
        let u = [
            idx.x - f64::from(self.bbox.min[0]),
            idx.y - f64::from(self.bbox.min[1]),
            idx.z - f64::from(self.bbox.min[2]),
        ];
        let (dn, g) = self.catmull_rom(u);
        let n = self.ambient + dn;
        // Clamped to what the mapping produced: Catmull-Rom rings at a sharp edge (air
        // colder than ambient beside a hot plume, n past every voxel's); flat where
        // clamped.
        let (lo, hi) = self.n_range;
        if n > hi || n < lo {
            return FieldSample {
                n: n.clamp(lo, hi),
                grad_n: DVec3::ZERO,
            };
        }
        FieldSample {
            n,
            grad_n: self.grad_to_world(g),
        }
    }

    fn bounds(&self) -> Bounds {
        self.bounds
    }

    fn ambient_index(&self) -> f64 {
        self.ambient
    }

    fn n_range(&self) -> (f64, f64) {
        self.n_range
    }

    /// Two voxels.
    fn feature_size(&self) -> Option<f64> {
        self.source_spacing().map(|h| 2.0 * h)
    }

    /// The voxel size: the shortest column of the grid-to-world transform.
    fn source_spacing(&self) -> Option<f64> {
        let m = &self.world_from_grid;
        let voxel = (0..3)
            .map(|c| DVec3::new(m[0][c], m[1][c], m[2][c]).length())
            .fold(f64::INFINITY, f64::min);
        (voxel > 0.0 && voxel.is_finite()).then_some(voxel)
    }
    fn max_grad_n(&self) -> f64 {
        self.max_grad
    }

    fn describe(&self) -> String {
        let mut s = format!(
            "{} ({}x{}x{} voxels, {})",
            self.label,
            self.dims[0],
            self.dims[1],
            self.dims[2],
            self.mapping.describe()
        );
        if self.non_finite_replaced > 0 {
            s.push_str(&format!(
                ", {} NaN/Inf voxels replaced by ambient",
                self.non_finite_replaced
            ));
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use vdb_sys::Transform;

    /// The brick store returns what was put, 0 in bricks not stored (all-zero ones are
    /// dropped), and its 4x4x4 stencil equals value-by-value reads on and across brick
    /// edges and the store's own edges.
    #[test]
    fn bricks_hold_what_was_put_and_stencils_match_reads() {
        let e = BRICK as i32;
        let bbox = IndexBox {
            min: [-5, 3, 0],
            max: [e + 2, e + 8, e + 4],
        };
        let mut store = Bricks::new(bbox);
        let f = |ijk: [i32; 3]| {
            // Zero in the second layer of bricks along z (not stored).
            if ijk[2] >= e {
                0.0
            } else {
                f64::from(ijk[0]) + 100.0 * f64::from(ijk[1]) + 1e4 * f64::from(ijk[2]) + 0.5
            }
        };
        for b in store.brick_indices().collect::<Vec<_>>() {
            let part = store.brick_box(b);
            let mut values = vec![0.0; BRICK_VOXELS].into_boxed_slice();
            for k in part.min[2]..=part.max[2] {
                for j in part.min[1]..=part.max[1] {
                    for i in part.min[0]..=part.max[0] {
                        values[store.local_offset([i, j, k])] = f([i, j, k]);
                    }
                }
            }
            store.put(b, values);
        }
        let stored = store.stored_boxes().len();
        assert_eq!(
            stored,
            2 * 2,
            "the second layer along z is all zero: not stored"
        );
        for k in -1..=e + 6 {
            for j in 2..=e + 10 {
                for i in -6..=e + 4 {
                    let inside = (-5..=e + 2).contains(&i)
                        && (3..=e + 8).contains(&j)
                        && (0..=e + 4).contains(&k);
                    let want = if inside { f([i, j, k]) } else { 0.0 };
                    let ijk = [i64::from(i), i64::from(j), i64::from(k)];
                    assert_eq!(store.get(ijk), want, "{ijk:?}");
                    let taps = store.stencil(ijk);
                    for c in 0..4 {
                        for b in 0..4 {
                            for a in 0..4 {
                                let at = [ijk[0] + a, ijk[1] + b, ijk[2] + c];
                                assert_eq!(taps[(a + 4 * (b + 4 * c)) as usize], store.get(at));
                            }
                        }
                    }
                }
            }
        }
    }

    fn params(mapping: Mapping, ambient: f64) -> VdbFieldParams {
        VdbFieldParams {
            mapping,
            units: 1.0,
            non_finite: NonFinitePolicy::Reject,
            bounds: Bounds::Sphere {
                center: DVec3::ZERO,
                radius: 10.0,
            },
            ambient: Some(ambient),
            max_bytes: DEFAULT_MAX_DENSE_BYTES,
            placement: IDENTITY,
        }
    }

    fn gd_default() -> GladstoneDale {
        GladstoneDale {
            ambient_temperature_k: 293.15,
            scale_k: 300.0,
            pressure_pa: 101_325.0,
            k_gd: 2.26e-4,
            r_specific: 287.05,
        }
    }

    /// docs/physics.md, Air: n - 1 at 101325 Pa = 2.92e-4 (0 C), 2.77e-4 (15 C),
    /// 2.72e-4 (20 C), 0.80e-4 (1000 K), 0.53e-4 (1500 K), quoted to 3 significant digits.
    #[test]
    fn gladstone_dale_reproduces_reference_table() {
        let gd = gd_default();
        for (t_k, expected) in [
            (273.15, 2.92e-4),
            (288.15, 2.77e-4),
            (293.15, 2.72e-4),
            (1000.0, 0.80e-4),
            (1500.0, 0.53e-4),
        ] {
            let got = gd.n_at_temperature(t_k) - 1.0;
            assert!(
                (got - expected).abs() <= 0.005e-4,
                "T = {t_k} K: n - 1 = {got:e}, table {expected:e}"
            );
        }
        // The map: value 0 is ambient temperature; value v is T_amb + scale * v.
        let m = Mapping::GladstoneDale(gd);
        let v = (1000.0 - 293.15) / 300.0;
        let n = m.n(v, 1.0).expect("positive T");
        assert!((n - 1.0 - 0.80e-4).abs() < 0.005e-4, "{n}");
        assert!(m.n(-2.0, 1.0).is_err(), "T = 293.15 - 600 K is negative");
    }

    fn cube(values: impl Fn(i32, i32, i32) -> f32, n: i32, xf: Transform) -> DenseGrid<f32> {
        let bbox = IndexBox {
            min: [-n, -n + 1, -n + 2],
            max: [n, n + 1, n + 2],
        };
        let mut v = Vec::new();
        for k in bbox.min[2]..=bbox.max[2] {
            for j in bbox.min[1]..=bbox.max[1] {
                for i in bbox.min[0]..=bbox.max[0] {
                    v.push(values(i, j, k));
                }
            }
        }
        DenseGrid {
            bbox,
            world_from_index: xf,
            values: v,
        }
    }

    #[test]
    fn catmull_rom_is_exact_for_quadratics_and_honours_transform_and_units() {
        // delta_n = q(world) with q quadratic: Catmull-Rom reproduces it (and its gradient)
        // exactly away from the box edges, under a non-uniform, rotated, offset transform.
        let xf = Transform {
            world_from_index: [
                [0.04, 0.01, 0.0, -0.3],
                [0.0, 0.05, 0.0, 0.7],
                [0.005, 0.0, 0.06, -1.1],
            ],
        };
        let units = 2.0;
        let q = |p: DVec3| 1e-3 * (0.5 * p.x * p.x - 0.3 * p.y * p.z + 0.2 * p.z + 0.1);
        let grad_q = |p: DVec3| 1e-3 * DVec3::new(p.x, -0.3 * p.z, -0.3 * p.y + 0.2);
        let world = |i: i32, j: i32, k: i32| {
            DVec3::from_array(xf.index_to_world([f64::from(i), f64::from(j), f64::from(k)])) * units
        };
        let dense = cube(|i, j, k| q(world(i, j, k)) as f32, 6, xf);
        // Recompute with f32-rounded nodes: compare against the f64 polynomial with a
        // tolerance covering the f32 storage (values ~1e-3 -> ~1e-10).
        let mut p = params(Mapping::Index { delta: true }, 1.0);
        p.units = units;
        let f = VdbField::from_dense("quad".into(), &dense, 0.0, &p).expect("field");
        for &(i, j, k) in &[(0.3, 1.7, 2.2), (-1.5, 0.25, 3.9), (2.0, 2.0, 2.0)] {
            let w = f.world_from_index(DVec3::new(i, j, k));
            let s = f.sample(w);
            assert!(
                (s.n - 1.0 - q(w)).abs() < 1e-9,
                "n at {w}: {} vs {}",
                s.n - 1.0,
                q(w)
            );
            assert!(
                (s.grad_n - grad_q(w)).length() < 1e-7,
                "grad at {w}: {} vs {}",
                s.grad_n,
                grad_q(w)
            );
            // Index/world round trip, world in metres = units * VDB world.
            let back = f.index_from_world(w);
            assert!((back - DVec3::new(i, j, k)).length() < 1e-12);
        }
        let w = f.world_from_index(DVec3::new(1.0, 2.0, 3.0));
        let raw = xf.index_to_world([1.0, 2.0, 3.0]);
        assert!((w - DVec3::from_array(raw) * units).length() < 1e-12);
    }

    #[test]
    fn gradient_matches_finite_difference_of_n() {
        // The gradient is the derivative of the interpolant itself (a conservative field).
        let xf = Transform::uniform(0.1, [0.2, -0.1, 0.0]);
        let dense = cube(
            |i, j, k| (0.01 * ((i * 7 + j * 3 - k * 5) % 11) as f32).sin(),
            4,
            xf,
        );
        let f = VdbField::from_dense(
            "bumpy".into(),
            &dense,
            0.0,
            &params(Mapping::Linear { k: 0.01 }, 1.2),
        )
        .expect("field");
        let e = 1e-6;
        for p in [DVec3::new(0.23, 0.05, 0.31), DVec3::new(-0.12, 0.27, 0.13)] {
            let g = f.sample(p).grad_n;
            let fd = DVec3::new(
                f.n(p + DVec3::X * e) - f.n(p - DVec3::X * e),
                f.n(p + DVec3::Y * e) - f.n(p - DVec3::Y * e),
                f.n(p + DVec3::Z * e) - f.n(p - DVec3::Z * e),
            ) / (2.0 * e);
            assert!((g - fd).length() < 1e-7 * (1.0 + g.length()), "{g} vs {fd}");
        }
    }

    #[test]
    fn non_finite_voxels_are_rejected_or_replaced_with_a_count() {
        let xf = Transform::uniform(0.1, [0.0; 3]);
        let dense = cube(
            |i, j, k| match (i, j, k) {
                (0, 1, 2) => f32::NAN,
                (1, 1, 2) => f32::INFINITY,
                _ => 0.5,
            },
            2,
            xf,
        );
        let gd = Mapping::GladstoneDale(gd_default());
        let ambient = gd.n(0.0, 1.0).expect("ambient");
        let mut p = params(gd, ambient);
        let e = VdbField::from_dense("nf".into(), &dense, 0.0, &p).expect_err("rejected");
        assert!(e.to_string().contains("2 NaN/Inf voxel(s)"), "{e}");
        p.non_finite = NonFinitePolicy::Ambient;
        let f = VdbField::from_dense("nf".into(), &dense, 0.0, &p).expect("replaced");
        assert_eq!(f.non_finite_replaced(), 2);
        let at = f.sample(f.world_from_index(DVec3::new(0.0, 1.0, 2.0)));
        assert!(
            (at.n - ambient).abs() < 1e-15,
            "replaced voxel holds ambient"
        );
        assert!(f.describe().contains("2 NaN/Inf voxels replaced"));
    }

    #[test]
    fn background_must_map_to_the_ambient_index() {
        let xf = Transform::uniform(0.1, [0.0; 3]);
        let dense = cube(|_, _, _| 0.1, 2, xf);
        let e = VdbField::from_dense(
            "gd".into(),
            &dense,
            0.0,
            &params(Mapping::GladstoneDale(gd_default()), 1.0),
        )
        .expect_err("mismatch");
        assert!(e.to_string().contains("ambient_index = 1.000272"), "{e}");
    }

    /// Max |n error| and max |grad n error| of a Gaussian (width s) sampled at voxel size
    /// s / per_s, over points of the inner ball.
    fn gaussian_errors(per_s: f64) -> (f64, f64) {
        let (a, s) = (1e-3, 0.2);
        let h = s / per_s;
        let half = (2.5 * per_s).ceil() as i32;
        let xf = Transform::uniform(h, [0.0; 3]);
        let f = |p: DVec3| a * (-p.length_squared() / (s * s)).exp();
        let bbox = IndexBox {
            min: [-half; 3],
            max: [half; 3],
        };
        let mut values = Vec::new();
        for k in -half..=half {
            for j in -half..=half {
                for i in -half..=half {
                    let p = DVec3::new(f64::from(i), f64::from(j), f64::from(k)) * h;
                    values.push(f(p) as f32);
                }
            }
        }
        let dense = DenseGrid {
            bbox,
            world_from_index: xf,
            values,
        };
        let field = VdbField::from_dense(
            "gauss".into(),
            &dense,
            0.0,
            &params(Mapping::Index { delta: true }, 1.0),
        )
        .expect("field");
        let (mut en, mut eg) = (0.0f64, 0.0f64);
        for i in 0..4000 {
            // A deterministic spiral of points within 1.5 s of the centre.
            let t = f64::from(i) * 0.618_033_988_75;
            let r = 1.5 * s * (f64::from(i) / 4000.0).cbrt();
            let z = 1.0 - 2.0 * (f64::from(i) + 0.5) / 4000.0;
            let q = (1.0 - z * z).sqrt();
            let p = DVec3::new(
                q * (t * std::f64::consts::TAU).cos(),
                q * (t * std::f64::consts::TAU).sin(),
                z,
            ) * r;
            let smp = field.sample(p);
            let g = p * (-2.0 * f(p) / (s * s));
            en = en.max((smp.n - 1.0 - f(p)).abs());
            eg = eg.max((smp.grad_n - g).length());
        }
        (en / a, eg / (a / s))
    }

    /// A step-edged block (hot: delta_n = -1e-3 inside, 0 outside): Catmull-Rom alone
    /// rings past both ends; the field never leaves [ambient - 1e-3, ambient], is exactly
    /// ambient one voxel outside the block, and a bake of it keeps that range.
    #[test]
    fn interpolant_stays_in_the_mapped_range() {
        let xf = Transform {
            world_from_index: [
                [0.1, 0.0, 0.0, 0.0],
                [0.0, 0.1, 0.0, 0.0],
                [0.0, 0.0, 0.1, 0.0],
            ],
        };
        let inside =
            |i: i32, j: i32, k: i32| i.abs() <= 3 && (j - 1).abs() <= 3 && (k - 2).abs() <= 3;
        let dense = cube(|i, j, k| if inside(i, j, k) { -1e-3 } else { 0.0 }, 8, xf);
        let field = VdbField::from_dense(
            "block".into(),
            &dense,
            0.0,
            &params(Mapping::Index { delta: true }, 1.0),
        )
        .expect("field");
        let (mut lo, mut hi) = (f64::MAX, f64::MIN);
        let mut rung = 0;
        for i in 0..=120 {
            for j in 0..=40 {
                let p = DVec3::new(-0.6 + 0.01 * f64::from(i), -0.3 + 0.03 * f64::from(j), 0.2);
                let smp = field.sample(p);
                lo = lo.min(smp.n);
                hi = hi.max(smp.n);
                let (raw, _) = field.catmull_rom({
                    let idx = field.index_from_world(p);
                    [
                        idx.x - f64::from(field.bbox.min[0]),
                        idx.y - f64::from(field.bbox.min[1]),
                        idx.z - f64::from(field.bbox.min[2]),
                    ]
                });
                if !(-1e-3..=0.0).contains(&raw) {
                    rung += 1;
                }
            }
        }
        assert!(rung > 0, "Catmull-Rom alone rings at the edge");
        let floor = 1.0 + f64::from(-1e-3f32);
        assert!(lo >= floor && hi <= 1.0, "n in [{lo}, {hi}]");
        // One voxel and a half outside the block's face (x = 0.3): exactly ambient.
        let out = field.sample(DVec3::new(0.45, 0.1, 0.2));
        assert_eq!(out.n, 1.0);
        assert_eq!(out.grad_n, DVec3::ZERO);
        // The bake of it stays in range too.
        let opts = crate::bake::BakeOptions {
            resolution: Some(32),
            ..Default::default()
        };
        let (baked, report) = crate::bake::bake(&field, &opts, &|_, _, _| {}).expect("bake");
        let (blo, bhi) = crate::field::IndexField::n_range(&baked);
        assert!(
            blo >= floor - 1e-9 && bhi <= 1.0 + 1e-9,
            "baked [{blo}, {bhi}], {report:?}"
        );
    }

    /// Bounds that miss the data are refused with the data's world box and a bounds line
    /// that holds it; bounds that cut it load (with a warning).
    #[test]
    fn bounds_that_miss_the_data_are_refused_with_where_it_is() {
        let xf = Transform {
            world_from_index: [
                [0.1, 0.0, 0.0, 5.0],
                [0.0, 0.1, 0.0, 0.0],
                [0.0, 0.0, 0.1, 0.0],
            ],
        };
        let dense = cube(|i, _, _| if i.abs() <= 2 { -1e-3 } else { 0.0 }, 4, xf);
        let mut far = params(Mapping::Index { delta: true }, 1.0);
        far.bounds = Bounds::Sphere {
            center: DVec3::ZERO,
            radius: 1.0,
        };
        let msg = match VdbField::from_dense("blob".into(), &dense, 0.0, &far) {
            Ok(_) => panic!("the bounds are far from x = 5"),
            Err(e) => e.to_string(),
        };
        assert!(
            msg.contains("miss the grid's data")
                && msg.contains("bounds = { box = { min = [4.7500"),
            "{msg}"
        );
        let mut cut = params(Mapping::Index { delta: true }, 1.0);
        cut.bounds = Bounds::Box {
            min: DVec3::new(4.9, -1.0, -1.0),
            max: DVec3::new(6.0, 1.0, 1.0),
        };
        assert!(VdbField::from_dense("blob".into(), &dense, 0.0, &cut).is_ok());
    }

    /// The stated interpolation error: O(h^3) in n and O(h^2) in grad n (Catmull-Rom).
    #[test]
    fn catmull_rom_converges_at_third_order_in_n_and_second_in_grad() {
        let (n1, g1) = gaussian_errors(4.0);
        let (n2, g2) = gaussian_errors(8.0);
        let (n3, g3) = gaussian_errors(16.0);
        let order = |e1: f64, e2: f64| (e1 / e2).log2();
        let (on, og) = (order(n2, n3), order(g2, g3));
        eprintln!(
            "Catmull-Rom on a Gaussian, s/h = 4, 8, 16: n error {n1:.2e} {n2:.2e} {n3:.2e} \
             (order {on:.2}), grad error {g1:.2e} {g2:.2e} {g3:.2e} (order {og:.2})"
        );
        assert!(on > 2.6, "n order {on} ({n1:.2e}, {n2:.2e}, {n3:.2e})");
        assert!(og > 1.8, "grad order {og} ({g1:.2e}, {g2:.2e}, {g3:.2e})");
        // 10 voxels per width: the level tests/vdb.rs relies on.
        let (n10, g10) = gaussian_errors(10.0);
        assert!(
            n10 < 5e-4 && g10 < 2e-2,
            "s/h = 10: n {n10:.2e}, grad {g10:.2e}"
        );
    }

    /// The placement: a Z-up point turns to +y, a 90 degree turn about +y takes +x to -z
    /// (right-handed), scale and translate come after; composed on the grid's transform.
    #[test]
    fn placement_turns_scales_rotates_then_translates() {
        let at = |m: &[[f64; 4]; 3], p: [f64; 3]| DVec3::from_array(apply(m, p));
        let close = |a: DVec3, b: DVec3| (a - b).length() < 1e-12;
        let up = placement(UpAxis::Z, 1.0, [0.0; 3], [0.0; 3]);
        assert!(close(at(&up, [0.0, 0.0, 1.0]), DVec3::Y));
        assert!(close(at(&up, [0.0, 1.0, 0.0]), -DVec3::Z));
        assert!(close(at(&up, [1.0, 0.0, 0.0]), DVec3::X));
        let m = placement(UpAxis::Y, 2.0, [0.0, 90.0, 0.0], [1.0, 2.0, 3.0]);
        assert!(close(at(&m, [1.0, 0.0, 0.0]), DVec3::new(1.0, 2.0, 1.0)));
        assert!(close(at(&m, [0.0, 1.0, 0.0]), DVec3::new(1.0, 4.0, 3.0)));
        let rz = placement(UpAxis::Y, 1.0, [0.0, 0.0, 90.0], [0.0; 3]);
        assert!(close(at(&rz, [1.0, 0.0, 0.0]), DVec3::Y));
        let rx = placement(UpAxis::Y, 1.0, [90.0, 0.0, 0.0], [0.0; 3]);
        assert!(close(at(&rx, [0.0, 1.0, 0.0]), DVec3::Z));
        // x first, then y: (0, 1, 0) -> (0, 0, 1) -> (1, 0, 0).
        let rxy = placement(UpAxis::Y, 1.0, [90.0, 90.0, 0.0], [0.0; 3]);
        assert!(close(at(&rxy, [0.0, 1.0, 0.0]), DVec3::X));

        // Through a field: the voxel at index 0 of a unit grid, placed, lands there.
        let xf = Transform {
            world_from_index: IDENTITY,
        };
        let dense = cube(
            |i, j, k| if (i, j, k) == (0, 0, 0) { 1e-3 } else { 0.0 },
            3,
            xf,
        );
        let mut prm = params(Mapping::Index { delta: true }, 1.0);
        prm.placement = placement(UpAxis::Z, 0.5, [0.0, 0.0, 0.0], [10.0, 0.0, 0.0]);
        prm.bounds = Bounds::Sphere {
            center: DVec3::new(10.0, 0.0, 0.0),
            radius: 5.0,
        };
        let field = VdbField::from_dense("placed".into(), &dense, 0.0, &prm).expect("field");
        assert!((field.n(DVec3::new(10.0, 0.0, 0.0)) - (1.0 + 1e-3)).abs() < 1e-9);
        assert!(close(
            field.world_from_index(DVec3::new(0.0, 0.0, 2.0)),
            DVec3::new(10.0, 1.0, 0.0)
        ));
    }

    /// "auto" takes the background's index; an explicit ambient within the tolerance is
    /// taken as the background (the data moves by the difference): outside the data the
    /// field is the ambient exactly, and the dense copy keeps only the voxels that change
    /// the index (plus padding), not the cache's whole active box.
    #[test]
    fn ambient_auto_and_near_ambient_leave_the_background_exactly_ambient() {
        let xf = Transform {
            world_from_index: [
                [0.1, 0.0, 0.0, 0.0],
                [0.0, 0.1, 0.0, 0.0],
                [0.0, 0.0, 0.1, 0.0],
            ],
        };
        // A hot core in a big box of background (0 = ambient temperature).
        let dense = cube(
            |i, j, k| {
                if i.abs() <= 1 && (j - 1).abs() <= 1 && (k - 2).abs() <= 1 {
                    1.0
                } else {
                    0.0
                }
            },
            12,
            xf,
        );
        let gd = Mapping::GladstoneDale(gd_default());
        let n_bg = gd.n(0.0, 1.0).expect("n");
        let mut auto = params(gd, 1.0);
        auto.ambient = None;
        let field = VdbField::from_dense("auto".into(), &dense, 0.0, &auto).expect("field");
        assert_eq!(field.ambient_index(), n_bg);
        let far = DVec3::new(0.9, 0.9, 0.9);
        assert_eq!(field.n(far), n_bg);
        let b = field.index_box();
        assert_eq!(
            (b.min, b.max),
            ([-3, -2, -1], [3, 4, 5]),
            "cropped to the core + 2"
        );
        assert_eq!(field.dims, [7, 7, 7]);
        let core = field.n(DVec3::new(0.0, 0.1, 0.2));
        assert!((core - gd.n(1.0, 1.0).expect("n")).abs() < 1e-12, "{core}");

        // 5e-7 off the background's index: accepted, and taken as that index.
        let near = params(gd, n_bg + 5e-7);
        let field = VdbField::from_dense("near".into(), &dense, 0.0, &near).expect("field");
        assert_eq!(field.n(far), n_bg + 5e-7);
        assert_eq!(field.sample(DVec3::new(0.6, 0.1, 0.2)).grad_n, DVec3::ZERO);
        let core = field.n(DVec3::new(0.0, 0.1, 0.2));
        assert!((core - (gd.n(1.0, 1.0).expect("n") + 5e-7)).abs() < 1e-12);
        // 2e-6 off: refused, naming the value to use.
        let e = VdbField::from_dense("far".into(), &dense, 0.0, &params(gd, n_bg + 2e-6))
            .expect_err("refused");
        assert!(e.to_string().contains("ambient_index = 1.000272"), "{e}");

        // A relative mapping: "auto" is 1.0.
        let mut rel = params(Mapping::Linear { k: 1e-4 }, 1.0);
        rel.ambient = None;
        let field = VdbField::from_dense("rel".into(), &dense, 0.0, &rel).expect("field");
        assert_eq!(field.ambient_index(), 1.0);
    }
}
