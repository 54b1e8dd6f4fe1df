//! Reading a `.vdb` file ([`VdbFile`]): opening it (after the checker), its grids and
//! metadata, and dense reads of scalar and vec3 grids.

use std::ffi::c_char;
use std::path::{Path, PathBuf};
use std::ptr::NonNull;

use crate::checker::check_in_child;
use crate::{
    BYTES_PER_SCALAR_VOXEL, DenseGrid, ERR_LEN, GridInfo, IndexBox, Meta, MetaValue, Transform,
    ValueKind, VdbError, c_path, err_text, ffi, loaded, owned,
};

/// `len` zeros, or [`VdbError::Memory`] where the allocation fails (no abort).
fn try_zeros(len: usize, path: &Path, grid: &str) -> Result<Vec<f32>, VdbError> {
    let mut v = Vec::new();
    v.try_reserve_exact(len).map_err(|_| VdbError::Memory {
        path: path.display().to_string(),
        grid: grid.to_owned(),
        bytes: len as u64 * BYTES_PER_SCALAR_VOXEL,
    })?;
    v.resize(len, 0f32);
    Ok(v)
}

/// An open VDB file: all grids are read into memory (sparse) when it is opened.
#[derive(Debug)]
pub struct VdbFile {
    raw: NonNull<ffi::GrinVdbFile>,
    path: PathBuf,
    grids: Vec<GridInfo>,
    metadata: Vec<Meta>,
}

// SAFETY: the handle owns its grids exclusively; the shim only reads them through const
// access, so moving the handle to another thread is sound.
unsafe impl Send for VdbFile {}

impl Drop for VdbFile {
    fn drop(&mut self) {
        // SAFETY: `raw` came from grin_vdb_open and is closed exactly once.
        unsafe { ffi::grin_vdb_close(self.raw.as_ptr()) };
    }
}

impl VdbFile {
    /// Open a `.vdb` file and read its grids and metadata, after the checker has read it
    /// in a child process.
    pub fn open(path: impl AsRef<Path>) -> Result<Self, VdbError> {
        Self::open_checked(path.as_ref(), true)
    }

    /// Open in this process without the child-process check (the checker itself).
    pub(crate) fn open_in_process(path: &Path) -> Result<Self, VdbError> {
        Self::open_checked(path, false)
    }

    fn open_checked(path: &Path, check: bool) -> Result<Self, VdbError> {
        let shown = path.display().to_string();
        if !path.exists() {
            return Err(VdbError::Missing { path: shown });
        }
        if std::fs::metadata(path).is_ok_and(|m| m.is_file() && m.len() == 0) {
            return Err(VdbError::Open {
                path: shown,
                message: "the file is empty".into(),
            });
        }
        let c = c_path(path)?;
        loaded()?;
        if check {
            check_in_child(path)?;
        }
        let mut err = [0 as c_char; ERR_LEN];
        let mut raw: *mut ffi::GrinVdbFile = std::ptr::null_mut();
        // SAFETY: valid C string, out-pointer and error buffer of the stated length.
        let status = unsafe { ffi::grin_vdb_open(c.as_ptr(), &mut raw, err.as_mut_ptr(), ERR_LEN) };
        let Some(raw) = NonNull::new(raw).filter(|_| status == ffi::GRIN_VDB_OK) else {
            return Err(VdbError::Open {
                path: shown,
                message: err_text(&err),
            });
        };
        let mut file = VdbFile {
            raw,
            path: path.to_path_buf(),
            grids: Vec::new(),
            metadata: Vec::new(),
        };
        file.metadata = file.read_meta(usize::MAX)?;
        // SAFETY: live handle.
        let count = unsafe { ffi::grin_vdb_grid_count(file.raw.as_ptr()) };
        for g in 0..count {
            let info = file.read_info(g)?;
            file.grids.push(info);
        }
        Ok(file)
    }

    fn open_error(&self, message: String) -> VdbError {
        VdbError::Open {
            path: self.path.display().to_string(),
            message,
        }
    }

    fn read_meta(&self, grid: usize) -> Result<Vec<Meta>, VdbError> {
        let count = if grid == usize::MAX {
            // SAFETY: live handle.
            unsafe { ffi::grin_vdb_file_meta_count(self.raw.as_ptr()) }
        } else {
            self.raw_info(grid)?.meta_count
        };
        let mut out = Vec::with_capacity(count);
        for i in 0..count {
            let mut key = std::ptr::null();
            let mut type_name = std::ptr::null();
            let mut text = std::ptr::null();
            let mut kind = 0i32;
            let mut number = 0f64;
            let mut err = [0 as c_char; ERR_LEN];
            // SAFETY: live handle; all out-pointers are valid locals.
            let status = unsafe {
                ffi::grin_vdb_meta(
                    self.raw.as_ptr(),
                    grid,
                    i,
                    &mut key,
                    &mut type_name,
                    &mut kind,
                    &mut text,
                    &mut number,
                    err.as_mut_ptr(),
                    ERR_LEN,
                )
            };
            if status != ffi::GRIN_VDB_OK {
                return Err(self.open_error(err_text(&err)));
            }
            // SAFETY: on success the strings are owned by the live handle.
            let (key, type_name, text) = unsafe { (owned(key), owned(type_name), owned(text)) };
            let value = match kind {
                ffi::GRIN_VDB_META_STRING => MetaValue::Text(text),
                ffi::GRIN_VDB_META_NUMBER => MetaValue::Number(number),
                _ => MetaValue::Other(text),
            };
            out.push(Meta {
                key,
                type_name,
                value,
            });
        }
        Ok(out)
    }

    /// The shim's description of grid number `grid` (its strings owned by the handle).
    fn raw_info(&self, grid: usize) -> Result<ffi::GrinVdbGridInfo, VdbError> {
        let mut info = std::mem::MaybeUninit::<ffi::GrinVdbGridInfo>::zeroed();
        let mut err = [0 as c_char; ERR_LEN];
        // SAFETY: live handle, valid out-pointer and buffer.
        let status = unsafe {
            ffi::grin_vdb_grid_info(
                self.raw.as_ptr(),
                grid,
                info.as_mut_ptr(),
                err.as_mut_ptr(),
                ERR_LEN,
            )
        };
        if status != ffi::GRIN_VDB_OK {
            return Err(self.open_error(err_text(&err)));
        }
        // SAFETY: the shim filled the struct on success.
        Ok(unsafe { info.assume_init() })
    }

    fn read_info(&self, grid: usize) -> Result<GridInfo, VdbError> {
        let r = self.raw_info(grid)?;
        // SAFETY: the strings are owned by the live handle.
        let (name, value_type, grid_class, map_type) = unsafe {
            (
                owned(r.name),
                owned(r.value_type),
                owned(r.grid_class),
                owned(r.map_type),
            )
        };
        let kind = match r.type_code {
            ffi::GRIN_VDB_TYPE_FLOAT => ValueKind::Float,
            ffi::GRIN_VDB_TYPE_DOUBLE => ValueKind::Double,
            ffi::GRIN_VDB_TYPE_VEC3S => ValueKind::Vec3s,
            ffi::GRIN_VDB_TYPE_VEC3D => ValueKind::Vec3d,
            _ => ValueKind::Other,
        };
        let value_range = (r.value_min.is_finite() && r.value_max.is_finite())
            .then_some((r.value_min, r.value_max));
        Ok(GridInfo {
            name,
            value_type,
            kind,
            grid_class,
            map_type,
            is_linear: r.is_linear != 0,
            half_float: r.save_float_as_half != 0,
            voxel_size: r.voxel_size,
            transform: Transform::from_flat(&r.world_from_index),
            active_bbox: (r.is_empty == 0).then_some(IndexBox {
                min: r.bbox_min,
                max: r.bbox_max,
            }),
            active_voxel_count: r.active_voxel_count,
            data_bbox: (r.data_voxel_count > 0).then_some(IndexBox {
                min: r.data_min,
                max: r.data_max,
            }),
            data_voxel_count: r.data_voxel_count,
            non_finite_count: r.non_finite_count,
            value_range,
            background: r.background,
            metadata: self.read_meta(grid)?,
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The grids, in file order.
    pub fn grids(&self) -> &[GridInfo] {
        &self.grids
    }

    /// File-level metadata.
    pub fn metadata(&self) -> &[Meta] {
        &self.metadata
    }

    /// The grid called `name`; the error lists the available grids.
    pub fn grid(&self, name: &str) -> Result<&GridInfo, VdbError> {
        self.grid_index(name).map(|i| &self.grids[i])
    }

    fn grid_index(&self, name: &str) -> Result<usize, VdbError> {
        self.grids
            .iter()
            .position(|g| g.name == name)
            .ok_or_else(|| VdbError::GridNotFound {
                path: self.path.display().to_string(),
                grid: name.to_owned(),
                available: if self.grids.is_empty() {
                    "(none)".into()
                } else {
                    self.grids
                        .iter()
                        .map(|g| format!("{} ({})", g.name, g.value_type))
                        .collect::<Vec<_>>()
                        .join(", ")
                },
            })
    }

    /// Check a dense read of `bbox` with `components` f32 per voxel against `max_bytes`,
    /// returning the float count to allocate.
    fn dense_len(
        &self,
        grid: &GridInfo,
        bbox: IndexBox,
        components: u64,
        max_bytes: u64,
    ) -> Result<usize, VdbError> {
        let voxels = bbox.voxel_count();
        if voxels == 0 {
            return Err(VdbError::Grid {
                path: self.path.display().to_string(),
                grid: grid.name.clone(),
                message: format!("empty index box {:?}..={:?}", bbox.min, bbox.max),
            });
        }
        let bytes = voxels * u128::from(components * BYTES_PER_SCALAR_VOXEL);
        let too_large = || VdbError::TooLarge {
            path: self.path.display().to_string(),
            grid: grid.name.clone(),
            min: bbox.min,
            max: bbox.max,
            bytes,
            cap: max_bytes,
        };
        if bytes > u128::from(max_bytes) {
            return Err(too_large());
        }
        usize::try_from(voxels * u128::from(components)).map_err(|_| too_large())
    }

    /// Read the index box `bbox` of the float (or double) grid `name` into a dense array,
    /// refusing boxes larger than `max_bytes`.
    pub fn read_scalar(
        &self,
        name: &str,
        bbox: IndexBox,
        max_bytes: u64,
    ) -> Result<DenseGrid<f32>, VdbError> {
        self.read_dense(name, bbox, max_bytes)
    }

    /// Read the index box `bbox` of the vec3 grid `name` into a dense array.
    pub fn read_vec3(
        &self,
        name: &str,
        bbox: IndexBox,
        max_bytes: u64,
    ) -> Result<DenseGrid<[f32; 3]>, VdbError> {
        self.read_dense(name, bbox, max_bytes)
    }

    /// Read the index box `bbox` of grid `name`, of the kind `V` reads, into a dense array
    /// of `V`, refusing boxes larger than `max_bytes`.
    fn read_dense<V: DenseValue>(
        &self,
        name: &str,
        bbox: IndexBox,
        max_bytes: u64,
    ) -> Result<DenseGrid<V>, VdbError> {
        let gi = self.grid_index(name)?;
        let grid = &self.grids[gi];
        if !V::reads(grid.kind) {
            return Err(VdbError::WrongType {
                path: self.path.display().to_string(),
                grid: name.to_owned(),
                found: grid.value_type.clone(),
                expected: V::EXPECTED,
            });
        }
        let len = self.dense_len(grid, bbox, V::COMPONENTS, max_bytes)?;
        let mut flat = try_zeros(len, &self.path, name)?;
        let mut err = [0 as c_char; ERR_LEN];
        // SAFETY: live handle; bbox arrays of 3; `flat` has exactly `len` floats, the
        // `V::COMPONENTS` floats of each voxel of `bbox` that `V::SHIM_READ` writes.
        let status = unsafe {
            (V::SHIM_READ)(
                self.raw.as_ptr(),
                gi,
                bbox.min.as_ptr(),
                bbox.max.as_ptr(),
                flat.as_mut_ptr(),
                len,
                err.as_mut_ptr(),
                ERR_LEN,
            )
        };
        if status != ffi::GRIN_VDB_OK {
            return Err(VdbError::Grid {
                path: self.path.display().to_string(),
                grid: name.to_owned(),
                message: err_text(&err),
            });
        }
        Ok(DenseGrid {
            bbox,
            world_from_index: grid.transform,
            values: V::from_floats(flat),
        })
    }
}

/// The shim's dense read of one grid kind (`grin_vdb_read_scalar`, `grin_vdb_read_vec3`).
type ShimRead = unsafe fn(
    *const ffi::GrinVdbFile,
    usize,
    *const i32,
    *const i32,
    *mut f32,
    usize,
    *mut c_char,
    usize,
) -> i32;

/// A voxel of a dense read: `f32` from a scalar grid, `[f32; 3]` from a vec3 grid.
trait DenseValue: Sized {
    /// The f32 components of one voxel.
    const COMPONENTS: u64;
    /// The grids this reads, for the error on another kind.
    const EXPECTED: &'static str;
    /// The shim call that reads it.
    const SHIM_READ: ShimRead;
    /// Whether a grid of `kind` reads as this voxel.
    fn reads(kind: ValueKind) -> bool;
    /// The voxels of the shim's floats (`COMPONENTS` a voxel, x fastest).
    fn from_floats(floats: Vec<f32>) -> Vec<Self>;
}

impl DenseValue for f32 {
    const COMPONENTS: u64 = 1;
    const EXPECTED: &'static str = "a scalar grid (float or double)";
    const SHIM_READ: ShimRead = ffi::grin_vdb_read_scalar;
    fn reads(kind: ValueKind) -> bool {
        kind.is_scalar()
    }
    fn from_floats(floats: Vec<f32>) -> Vec<f32> {
        floats
    }
}

impl DenseValue for [f32; 3] {
    const COMPONENTS: u64 = 3;
    const EXPECTED: &'static str = "a vec3 grid (vec3s or vec3d)";
    const SHIM_READ: ShimRead = ffi::grin_vdb_read_vec3;
    fn reads(kind: ValueKind) -> bool {
        kind.is_vec3()
    }
    fn from_floats(floats: Vec<f32>) -> Vec<[f32; 3]> {
        floats.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect()
    }
}
