//! The values the crate reads and writes: index boxes, grid descriptions
//! ([`GridInfo`], [`ValueKind`], metadata) and dense grids ([`DenseGrid`]).

use crate::Transform;

/// An inclusive box of index coordinates (voxel centres are integer coordinates).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct IndexBox {
    pub min: [i32; 3],
    pub max: [i32; 3],
}

impl IndexBox {
    /// Voxels along each axis (0 where max < min).
    pub fn dims(&self) -> [u64; 3] {
        std::array::from_fn(|a| {
            let d = i64::from(self.max[a]) - i64::from(self.min[a]) + 1;
            u64::try_from(d.max(0)).unwrap_or(0)
        })
    }

    /// Total voxels, exact in u128 (no overflow for any i32 box).
    pub fn voxel_count(&self) -> u128 {
        self.dims().iter().map(|&d| u128::from(d)).product()
    }

    /// The box grown by `pad` voxels on every side (saturating at the i32 range).
    pub fn padded(&self, pad: i32) -> IndexBox {
        IndexBox {
            min: self.min.map(|v| v.saturating_sub(pad)),
            max: self.max.map(|v| v.saturating_add(pad)),
        }
    }
}

/// A metadata value.
#[derive(Debug, Clone, PartialEq)]
pub enum MetaValue {
    Text(String),
    Number(f64),
    /// Another type (vectors, matrices), as OpenVDB prints it.
    Other(String),
}

impl std::fmt::Display for MetaValue {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            MetaValue::Text(s) | MetaValue::Other(s) => f.write_str(s),
            MetaValue::Number(x) => write!(f, "{x}"),
        }
    }
}

/// One metadata entry of a file or grid.
#[derive(Debug, Clone, PartialEq)]
pub struct Meta {
    pub key: String,
    /// OpenVDB's type name (`string`, `float`, `vec3i`, ...).
    pub type_name: String,
    pub value: MetaValue,
}

/// What a grid holds, as far as grin is concerned.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ValueKind {
    Float,
    Double,
    Vec3s,
    Vec3d,
    Other,
}

impl ValueKind {
    pub fn is_scalar(self) -> bool {
        matches!(self, ValueKind::Float | ValueKind::Double)
    }
    pub fn is_vec3(self) -> bool {
        matches!(self, ValueKind::Vec3s | ValueKind::Vec3d)
    }
}

/// Everything `grin info` shows about one grid.
#[derive(Debug, Clone, PartialEq)]
pub struct GridInfo {
    pub name: String,
    /// OpenVDB value type name (`float`, `vec3s`, `int32`, ...).
    pub value_type: String,
    pub kind: ValueKind,
    /// Grid class (`fog volume`, `level set`, `unknown`, ...).
    pub grid_class: String,
    /// OpenVDB map type (`UniformScaleTranslateMap`, `FrustumMap`, ...).
    pub map_type: String,
    /// True for affine transforms (grin rejects the others).
    pub is_linear: bool,
    /// Stored as 16-bit floats.
    pub half_float: bool,
    pub voxel_size: [f64; 3],
    /// The affine part of the transform (exact for linear transforms).
    pub transform: Transform,
    /// Bounding box of the active voxels; `None` for an empty grid.
    pub active_bbox: Option<IndexBox>,
    pub active_voxel_count: u64,
    /// Scalar grids: the box of the active voxels (and tiles) whose value differs from the
    /// background, NaN/Inf included; `None` where every value is the background (or a
    /// vector grid). Found from the tree's active values, without a dense copy.
    pub data_bbox: Option<IndexBox>,
    pub data_voxel_count: u64,
    /// Active voxels that are NaN or Inf (any component).
    pub non_finite_count: u64,
    /// (min, max) over finite active values (|v| for vectors); `None` if there are none.
    pub value_range: Option<(f64, f64)>,
    /// The background value (|background| for vectors).
    pub background: f64,
    pub metadata: Vec<Meta>,
}

/// A dense box of voxels read from (or to be written to) a grid, x fastest.
#[derive(Debug, Clone, PartialEq)]
pub struct DenseGrid<T> {
    pub bbox: IndexBox,
    pub world_from_index: Transform,
    pub values: Vec<T>,
}

impl<T: Copy> DenseGrid<T> {
    /// Linear offset of index (i, j, k), or `None` outside the box.
    pub fn offset(&self, ijk: [i32; 3]) -> Option<usize> {
        let d = self.bbox.dims();
        let mut off = 0usize;
        let mut stride = 1usize;
        for a in 0..3 {
            let rel = i64::from(ijk[a]) - i64::from(self.bbox.min[a]);
            let rel = u64::try_from(rel).ok().filter(|&r| r < d[a])?;
            off += usize::try_from(rel).ok()? * stride;
            stride *= usize::try_from(d[a]).ok()?;
        }
        Some(off)
    }

    /// The value at index (i, j, k), or `None` outside the box.
    pub fn get(&self, ijk: [i32; 3]) -> Option<T> {
        self.offset(ijk).and_then(|o| self.values.get(o).copied())
    }
}
