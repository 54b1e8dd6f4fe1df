//! Safe access to OpenVDB files through grin's C++ shim (shim/grin_vdb.cpp): open a file,
//! list its grids and metadata, read scalar and vec3 grids into dense arrays with their
//! `world_from_index` transform, and write float/vec3 grids with metadata.
//!
//! This crate holds grin's FFI `unsafe` code, all of it in this file and in [`ffi`], which
//! loads the shim (the other `unsafe` in grin: grin-gpu's pipeline-cache load and
//! grin-field's compiled formulas, `expr_jit`). Every shim call returns a status code and message (the
//! shim catches every C++ exception), so errors come back as [`VdbError`].
//!
//! OpenVDB is not linked into the program: build.rs links the shim as a shared library
//! against it, the crate embeds that library, and [`ffi`] loads it (and OpenVDB with it) at
//! the first [`VdbFile::open`] or [`VdbWriter::new`]. Programs start without binding
//! OpenVDB's symbols, and a machine without OpenVDB gets [`VdbError::Unavailable`] from
//! those two calls rather than a program that cannot start.
//!
//! One concept, one file: every FFI call and its safety argument, reviewed together.

#![expect(
    unsafe_code,
    reason = "the FFI boundary to the OpenVDB shim lives here"
)]

pub mod ffi;

use std::ffi::{CStr, CString, c_char};
use std::path::{Path, PathBuf};
use std::ptr::NonNull;

/// Size of the buffer the shim writes error messages into.
const ERR_LEN: usize = 1024;

/// Bytes per voxel of a dense scalar read (f32).
pub const BYTES_PER_SCALAR_VOXEL: u64 = 4;

/// The checker executable build.rs links beside the shim (shim/grin_vdb_check.cpp): the
/// fallback for library users and tests, which have no checker entry of their own.
const BUILD_TREE_CHECKER: &str = env!("GRIN_VDB_CHECK");
/// The checker's dense reads are capped here (bigger grids are only opened, not copied).
const CHECK_DENSE_CAP_BYTES: u64 = 256 << 20;
/// First argument that turns a program calling [`checker_entry`] into the checker.
pub const CHECK_ARG: &str = "__grin-vdb-check";

/// The executable that checks files in a child process, registered by a binary with
/// [`use_current_exe_as_checker`]; else [`BUILD_TREE_CHECKER`].
static CHECKER: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();

/// Make this program its own VDB checker: files are tried by re-running it as
/// `<exe> __grin-vdb-check FILE CAP`. The binary must call [`checker_entry`] first thing
/// in `main`. An installed grin, moved away from its build tree, keeps its isolation.
pub fn use_current_exe_as_checker() -> Result<(), VdbError> {
    let exe = std::env::current_exe().map_err(|e| VdbError::Open {
        path: String::new(),
        message: format!("cannot find grin's own executable to check VDB files with: {e}"),
    })?;
    let _ = CHECKER.set(exe);
    Ok(())
}

/// Where this process was started as the checker (`args[1] == CHECK_ARG`): run the check
/// and return the exit status (0 readable, 1 a reported error on stderr, 2 usage). A
/// crash while reading is what the parent sees as a signal.
pub fn checker_entry() -> Option<i32> {
    let args: Vec<std::ffi::OsString> = std::env::args_os().collect();
    if args.get(1).is_none_or(|a| a != CHECK_ARG) {
        return None;
    }
    let (Some(path), Some(cap)) = (
        args.get(2),
        args.get(3).and_then(|c| c.to_str()?.parse().ok()),
    ) else {
        eprintln!("usage: {CHECK_ARG} FILE MAX_DENSE_BYTES");
        return Some(2);
    };
    Some(match check_here(Path::new(path), cap) {
        Ok(()) => 0,
        Err(e) => {
            eprintln!("{}", e.reason());
            1
        }
    })
}

/// Open `path` in this process and read every grid up to `cap` bytes: what the checker
/// does (the same reads as shim/grin_vdb_check.cpp).
fn check_here(path: &Path, cap: u64) -> Result<(), VdbError> {
    let file = VdbFile::open_in_process(path)?;
    for grid in file.grids() {
        let Some(bbox) = grid.active_bbox else {
            continue;
        };
        let components = if grid.kind.is_vec3() { 3 } else { 1 };
        let bytes = bbox.voxel_count() * components * u128::from(BYTES_PER_SCALAR_VOXEL);
        if bytes > u128::from(cap) {
            continue;
        }
        if grid.kind.is_scalar() {
            file.read_scalar(&grid.name, bbox, cap)?;
        } else if grid.kind.is_vec3() {
            file.read_vec3(&grid.name, bbox, cap)?;
        }
    }
    Ok(())
}

/// Try the file in a child process first: OpenVDB can corrupt its heap and abort on some
/// malformed files (found by tests/fuzz.rs), which no exception handler can catch. In a
/// child that is an exit status. Without a checker the file is not read at all: the
/// isolation cannot switch itself off.
fn check_in_child(path: &Path) -> Result<(), VdbError> {
    let shown = path.display().to_string();
    let (exe, self_exec) = match CHECKER.get() {
        Some(exe) => (exe.clone(), true),
        None => (PathBuf::from(BUILD_TREE_CHECKER), false),
    };
    let mut command = std::process::Command::new(&exe);
    if self_exec {
        command.arg(CHECK_ARG);
    }
    let output = command
        .arg(path)
        .arg(CHECK_DENSE_CAP_BYTES.to_string())
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .output()
        .map_err(|e| VdbError::Open {
            path: shown.clone(),
            message: format!(
                "cannot start the VDB checker {} to read the file safely ({e}); the file \
                 was not read",
                exe.display()
            ),
        })?;
    if output.status.success() {
        return Ok(());
    }
    let stderr = String::from_utf8_lossy(&output.stderr).trim().to_string();
    let message = match output.status.code() {
        Some(1) if !stderr.is_empty() => stderr,
        Some(code) => format!("the OpenVDB reader failed (exit status {code})"),
        None => {
            use std::os::unix::process::ExitStatusExt;
            format!(
                "the file is corrupt: OpenVDB crashed while reading it (signal {})",
                output.status.signal().unwrap_or(0)
            )
        }
    };
    Err(VdbError::Open {
        path: shown,
        message,
    })
}

/// Why a VDB file could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum VdbError {
    #[error("{path}: no such file")]
    Missing { path: String },
    #[error("{path}: not a readable OpenVDB file: {message}")]
    Open { path: String, message: String },
    #[error("{path}: grid `{grid}` not found; available grids: {available}")]
    GridNotFound {
        path: String,
        grid: String,
        available: String,
    },
    #[error("{path}: grid `{grid}` has value type `{found}`, expected {expected}")]
    WrongType {
        path: String,
        grid: String,
        found: String,
        expected: &'static str,
    },
    #[error(
        "{path}: grid `{grid}`: a dense copy of the index box {min:?}..={max:?} needs {bytes} bytes, more than the memory cap of {cap} bytes"
    )]
    TooLarge {
        path: String,
        grid: String,
        min: [i32; 3],
        max: [i32; 3],
        bytes: u128,
        cap: u64,
    },
    #[error("{path}: grid `{grid}`: {message}")]
    Grid {
        path: String,
        grid: String,
        message: String,
    },
    #[error("{path}: cannot write: {message}")]
    Write { path: String, message: String },
    /// The shim or OpenVDB could not be loaded (the message says why and what to install).
    #[error("{message}")]
    Unavailable { message: String },
    #[error(
        "{path}: not enough memory to read grid `{grid}`: {bytes} bytes could not be allocated"
    )]
    Memory {
        path: String,
        grid: String,
        bytes: u64,
    },
}

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

/// Load the shim and OpenVDB (once per process; see [`ffi`]).
fn loaded() -> Result<(), VdbError> {
    ffi::load().map_err(|message| VdbError::Unavailable { message })
}

impl VdbError {
    /// The message without the file's path (the checker's parent adds it back).
    fn reason(&self) -> String {
        match self {
            VdbError::Open { message, .. } => message.clone(),
            other => other.to_string(),
        }
    }
}

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

/// An affine index-to-world transform: world = A * ijk + t.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Transform {
    /// Row-major 3x4 `[A | t]`.
    pub world_from_index: [[f64; 4]; 3],
}

impl Transform {
    /// Uniform voxel size `h` with index (0,0,0) at world `origin`.
    pub fn uniform(h: f64, origin: [f64; 3]) -> Self {
        Transform {
            world_from_index: [
                [h, 0.0, 0.0, origin[0]],
                [0.0, h, 0.0, origin[1]],
                [0.0, 0.0, h, origin[2]],
            ],
        }
    }

    fn from_flat(m: &[f64; 12]) -> Self {
        Transform {
            world_from_index: std::array::from_fn(|r| std::array::from_fn(|c| m[r * 4 + c])),
        }
    }

    fn to_flat(self) -> [f64; 12] {
        std::array::from_fn(|i| self.world_from_index[i / 4][i % 4])
    }

    /// World position of (fractional) index coordinates.
    pub fn index_to_world(&self, ijk: [f64; 3]) -> [f64; 3] {
        let m = &self.world_from_index;
        std::array::from_fn(|r| m[r][0] * ijk[0] + m[r][1] * ijk[1] + m[r][2] * ijk[2] + m[r][3])
    }

    /// The inverse transform (index from world), `None` if A is singular.
    pub fn inverse(&self) -> Option<Transform> {
        let m = &self.world_from_index;
        let a = |r: usize, c: usize| m[r][c];
        let det = a(0, 0) * (a(1, 1) * a(2, 2) - a(1, 2) * a(2, 1))
            - a(0, 1) * (a(1, 0) * a(2, 2) - a(1, 2) * a(2, 0))
            + a(0, 2) * (a(1, 0) * a(2, 1) - a(1, 1) * a(2, 0));
        if !det.is_finite() || det.abs() < f64::MIN_POSITIVE {
            return None;
        }
        let inv_det = 1.0 / det;
        let cof = |r: usize, c: usize| {
            // Inverse entry (r, c) = cofactor(c, r) / det.
            let (r0, r1) = ((c + 1) % 3, (c + 2) % 3);
            let (c0, c1) = ((r + 1) % 3, (r + 2) % 3);
            (a(r0, c0) * a(r1, c1) - a(r0, c1) * a(r1, c0)) * inv_det
        };
        let inv: [[f64; 3]; 3] = std::array::from_fn(|r| std::array::from_fn(|c| cof(r, c)));
        let t = [m[0][3], m[1][3], m[2][3]];
        let mut out = [[0.0; 4]; 3];
        for r in 0..3 {
            out[r][..3].copy_from_slice(&inv[r]);
            out[r][3] = -(inv[r][0] * t[0] + inv[r][1] * t[1] + inv[r][2] * t[2]);
        }
        Some(Transform {
            world_from_index: out,
        })
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

fn c_path(path: &Path) -> Result<CString, VdbError> {
    CString::new(path.as_os_str().as_encoded_bytes()).map_err(|_| VdbError::Open {
        path: path.display().to_string(),
        message: "path contains a NUL byte".into(),
    })
}

fn err_text(buf: &[c_char]) -> String {
    let bytes: Vec<u8> = buf
        .iter()
        .take_while(|&&c| c != 0)
        .map(|&c| c as u8)
        .collect();
    let s = String::from_utf8_lossy(&bytes).trim().to_string();
    if s.is_empty() {
        "unknown error".into()
    } else {
        s
    }
}

/// Copy a C string owned by the shim. Safety: `p` is null or a valid NUL-terminated string.
unsafe fn owned(p: *const c_char) -> String {
    if p.is_null() {
        return String::new();
    }
    // SAFETY: the caller guarantees `p` points to a live NUL-terminated string.
    unsafe { CStr::from_ptr(p) }.to_string_lossy().into_owned()
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
    fn open_in_process(path: &Path) -> Result<Self, VdbError> {
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
            unsafe { info.assume_init() }.meta_count
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

    fn read_info(&self, grid: usize) -> Result<GridInfo, VdbError> {
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
        let r = unsafe { info.assume_init() };
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
        if bytes > u128::from(max_bytes) {
            return Err(VdbError::TooLarge {
                path: self.path.display().to_string(),
                grid: grid.name.clone(),
                min: bbox.min,
                max: bbox.max,
                bytes,
                cap: max_bytes,
            });
        }
        usize::try_from(voxels * u128::from(components)).map_err(|_| VdbError::TooLarge {
            path: self.path.display().to_string(),
            grid: grid.name.clone(),
            min: bbox.min,
            max: bbox.max,
            bytes,
            cap: max_bytes,
        })
    }

    /// Read the index box `bbox` of the float (or double) grid `name` into a dense array,
    /// refusing boxes larger than `max_bytes`.
    pub fn read_scalar(
        &self,
        name: &str,
        bbox: IndexBox,
        max_bytes: u64,
    ) -> Result<DenseGrid<f32>, VdbError> {
        let gi = self.grid_index(name)?;
        let grid = &self.grids[gi];
        if !grid.kind.is_scalar() {
            return Err(VdbError::WrongType {
                path: self.path.display().to_string(),
                grid: name.to_owned(),
                found: grid.value_type.clone(),
                expected: "a scalar grid (float or double)",
            });
        }
        let len = self.dense_len(grid, bbox, 1, max_bytes)?;
        let mut values = try_zeros(len, &self.path, name)?;
        let mut err = [0 as c_char; ERR_LEN];
        // SAFETY: live handle; bbox arrays of 3; `values` has exactly `len` floats.
        let status = unsafe {
            ffi::grin_vdb_read_scalar(
                self.raw.as_ptr(),
                gi,
                bbox.min.as_ptr(),
                bbox.max.as_ptr(),
                values.as_mut_ptr(),
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
            values,
        })
    }

    /// Read the index box `bbox` of the vec3 grid `name` into a dense array.
    pub fn read_vec3(
        &self,
        name: &str,
        bbox: IndexBox,
        max_bytes: u64,
    ) -> Result<DenseGrid<[f32; 3]>, VdbError> {
        let gi = self.grid_index(name)?;
        let grid = &self.grids[gi];
        if !grid.kind.is_vec3() {
            return Err(VdbError::WrongType {
                path: self.path.display().to_string(),
                grid: name.to_owned(),
                found: grid.value_type.clone(),
                expected: "a vec3 grid (vec3s or vec3d)",
            });
        }
        let len = self.dense_len(grid, bbox, 3, max_bytes)?;
        let mut flat = try_zeros(len, &self.path, name)?;
        let mut err = [0 as c_char; ERR_LEN];
        // SAFETY: live handle; bbox arrays of 3; `flat` has exactly `len` floats.
        let status = unsafe {
            ffi::grin_vdb_read_vec3(
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
        let values = flat.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
        Ok(DenseGrid {
            bbox,
            world_from_index: grid.transform,
            values,
        })
    }
}

/// How a grid is written.
#[derive(Debug, Clone, PartialEq)]
pub struct WriteOptions {
    /// Background value (inactive voxels); also each component's background for vec3.
    pub background: f32,
    /// Voxels within this of the background become inactive.
    pub tolerance: f32,
    /// Store as 16-bit floats.
    pub half_float: bool,
    /// Grid metadata.
    pub metadata: Vec<(String, MetaValue)>,
}

impl Default for WriteOptions {
    fn default() -> Self {
        WriteOptions {
            background: 0.0,
            tolerance: 0.0,
            half_float: false,
            metadata: Vec::new(),
        }
    }
}

/// Collects grids and file metadata, then writes one `.vdb` file.
#[derive(Debug)]
pub struct VdbWriter {
    raw: NonNull<ffi::GrinVdbWriter>,
}

// SAFETY: the writer owns its grids exclusively.
unsafe impl Send for VdbWriter {}

impl Drop for VdbWriter {
    fn drop(&mut self) {
        // SAFETY: `raw` came from grin_vdb_writer_new and is freed exactly once.
        unsafe { ffi::grin_vdb_writer_free(self.raw.as_ptr()) };
    }
}

fn cstring(s: &str, what: &str) -> Result<CString, VdbError> {
    CString::new(s).map_err(|_| VdbError::Write {
        path: String::new(),
        message: format!("{what} `{s}` contains a NUL byte"),
    })
}

impl VdbWriter {
    pub fn new() -> Result<Self, VdbError> {
        loaded()?;
        // SAFETY: no arguments; null means the shim could not allocate.
        let raw = unsafe { ffi::grin_vdb_writer_new() };
        NonNull::new(raw)
            .map(|raw| VdbWriter { raw })
            .ok_or_else(|| VdbError::Write {
                path: String::new(),
                message: "cannot create an OpenVDB writer".into(),
            })
    }

    fn add(
        &mut self,
        name: &str,
        components: i32,
        bbox: IndexBox,
        world_from_index: Transform,
        data: &[f32],
        opts: &WriteOptions,
    ) -> Result<(), VdbError> {
        let cname = cstring(name, "grid name")?;
        let mut str_keys = Vec::new();
        let mut str_vals = Vec::new();
        let mut num_keys = Vec::new();
        let mut num_vals = Vec::new();
        for (k, v) in &opts.metadata {
            match v {
                MetaValue::Number(x) => {
                    num_keys.push(cstring(k, "metadata key")?);
                    num_vals.push(*x);
                }
                MetaValue::Text(s) | MetaValue::Other(s) => {
                    str_keys.push(cstring(k, "metadata key")?);
                    str_vals.push(cstring(s, "metadata value")?);
                }
            }
        }
        let str_key_ptrs: Vec<*const c_char> = str_keys.iter().map(|c| c.as_ptr()).collect();
        let str_val_ptrs: Vec<*const c_char> = str_vals.iter().map(|c| c.as_ptr()).collect();
        let num_key_ptrs: Vec<*const c_char> = num_keys.iter().map(|c| c.as_ptr()).collect();
        let dims = bbox.dims();
        let flat = world_from_index.to_flat();
        let mut err = [0 as c_char; ERR_LEN];
        // SAFETY: every pointer refers to a live local of the stated length; the shim
        // checks `data.len()` against `dims` and `components`.
        let status = unsafe {
            ffi::grin_vdb_writer_add_grid(
                self.raw.as_ptr(),
                cname.as_ptr(),
                components,
                bbox.min.as_ptr(),
                dims.as_ptr(),
                data.as_ptr(),
                data.len(),
                flat.as_ptr(),
                opts.background,
                opts.tolerance,
                i32::from(opts.half_float),
                str_key_ptrs.as_ptr(),
                str_val_ptrs.as_ptr(),
                str_key_ptrs.len(),
                num_key_ptrs.as_ptr(),
                num_vals.as_ptr(),
                num_key_ptrs.len(),
                err.as_mut_ptr(),
                ERR_LEN,
            )
        };
        if status != ffi::GRIN_VDB_OK {
            return Err(VdbError::Write {
                path: String::new(),
                message: format!("grid `{name}`: {}", err_text(&err)),
            });
        }
        Ok(())
    }

    /// Add a float grid from a dense array.
    pub fn add_float(
        &mut self,
        name: &str,
        grid: &DenseGrid<f32>,
        opts: &WriteOptions,
    ) -> Result<(), VdbError> {
        self.add(
            name,
            1,
            grid.bbox,
            grid.world_from_index,
            &grid.values,
            opts,
        )
    }

    /// Add a vec3s grid (vector type covariant, as gradients are) from a dense array.
    pub fn add_vec3(
        &mut self,
        name: &str,
        grid: &DenseGrid<[f32; 3]>,
        opts: &WriteOptions,
    ) -> Result<(), VdbError> {
        let flat: Vec<f32> = grid.values.iter().flat_map(|v| v.iter().copied()).collect();
        self.add(name, 3, grid.bbox, grid.world_from_index, &flat, opts)
    }

    /// Add a string entry to the file metadata.
    pub fn add_file_meta(&mut self, key: &str, value: &str) -> Result<(), VdbError> {
        let (k, v) = (
            cstring(key, "metadata key")?,
            cstring(value, "metadata value")?,
        );
        let mut err = [0 as c_char; ERR_LEN];
        // SAFETY: live writer, valid C strings and buffer.
        let status = unsafe {
            ffi::grin_vdb_writer_add_file_meta(
                self.raw.as_ptr(),
                k.as_ptr(),
                v.as_ptr(),
                err.as_mut_ptr(),
                ERR_LEN,
            )
        };
        if status != ffi::GRIN_VDB_OK {
            return Err(VdbError::Write {
                path: String::new(),
                message: err_text(&err),
            });
        }
        Ok(())
    }

    /// Write all grids to `path` (overwriting it). Callers that must not leave a partial
    /// file write to a temporary path and rename.
    pub fn write(&mut self, path: impl AsRef<Path>) -> Result<(), VdbError> {
        let path = path.as_ref();
        let shown = path.display().to_string();
        let c = c_path(path).map_err(|e| VdbError::Write {
            path: shown.clone(),
            message: e.to_string(),
        })?;
        let mut err = [0 as c_char; ERR_LEN];
        // SAFETY: live writer, valid C string and buffer.
        let status = unsafe {
            ffi::grin_vdb_writer_write(self.raw.as_ptr(), c.as_ptr(), err.as_mut_ptr(), ERR_LEN)
        };
        if status != ffi::GRIN_VDB_OK {
            return Err(VdbError::Write {
                path: shown,
                message: err_text(&err),
            });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn transform_inverse_roundtrips() {
        let t = Transform {
            world_from_index: [
                [0.05, 0.01, 0.0, -1.2],
                [0.0, 0.04, 0.02, 0.3],
                [0.01, 0.0, 0.06, 2.5],
            ],
        };
        let inv = t.inverse().expect("invertible");
        let p = [3.0, -7.5, 11.25];
        let w = t.index_to_world(p);
        let back = inv.index_to_world(w);
        for a in 0..3 {
            assert!((back[a] - p[a]).abs() < 1e-12, "{back:?} vs {p:?}");
        }
    }

    #[test]
    fn write_then_read_roundtrips_values_and_transform() {
        let dir = std::env::temp_dir().join(format!("vdb-sys-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let path = dir.join("roundtrip.vdb");
        let bbox = IndexBox {
            min: [-3, 2, -1],
            max: [1, 4, 2],
        };
        let dims = bbox.dims();
        let n = dims.iter().product::<u64>() as usize;
        let xf = Transform::uniform(0.25, [1.0, -2.0, 0.5]);
        let scalar = DenseGrid {
            bbox,
            world_from_index: xf,
            values: (0..n).map(|i| 1.0 + i as f32 * 0.5).collect(),
        };
        let vec = DenseGrid {
            bbox,
            world_from_index: xf,
            values: (0..n).map(|i| [i as f32, -(i as f32), 0.5]).collect(),
        };
        let mut w = VdbWriter::new().expect("writer");
        let opts = WriteOptions {
            metadata: vec![
                ("units".into(), MetaValue::Text("m".into())),
                ("n_ambient".into(), MetaValue::Number(1.000_272)),
            ],
            ..WriteOptions::default()
        };
        w.add_float("delta_n", &scalar, &opts).expect("add float");
        w.add_vec3("grad_n", &vec, &WriteOptions::default())
            .expect("add vec3");
        w.add_file_meta("creator", "grin test").expect("meta");
        w.write(&path).expect("write");

        let f = VdbFile::open(&path).expect("open");
        assert_eq!(f.grids().len(), 2);
        assert!(
            f.metadata()
                .iter()
                .any(|m| m.key == "creator" && m.value == MetaValue::Text("grin test".into()))
        );
        let g = f.grid("delta_n").expect("grid");
        assert_eq!(g.kind, ValueKind::Float);
        assert_eq!(g.active_bbox, Some(bbox));
        assert_eq!(g.active_voxel_count, n as u64);
        assert_eq!(g.voxel_size, [0.25; 3]);
        assert!(
            g.metadata
                .iter()
                .any(|m| m.key == "n_ambient" && m.value == MetaValue::Number(1.000_272))
        );
        let back = f.read_scalar("delta_n", bbox, 1 << 20).expect("read");
        assert_eq!(back.values, scalar.values);
        assert_eq!(back.world_from_index, xf);
        let vback = f.read_vec3("grad_n", bbox, 1 << 20).expect("read vec3");
        assert_eq!(vback.values, vec.values);
        assert_eq!(f.grid("grad_n").expect("grid").kind, ValueKind::Vec3s);

        // Wrong type, missing grid and the memory cap give typed errors.
        assert!(matches!(
            f.read_scalar("grad_n", bbox, 1 << 20),
            Err(VdbError::WrongType { .. })
        ));
        let e = f
            .read_scalar("nope", bbox, 1 << 20)
            .expect_err("missing grid");
        assert!(
            e.to_string().contains("delta_n (float), grad_n (vec3s)"),
            "{e}"
        );
        assert!(matches!(
            f.read_scalar("delta_n", bbox, 16),
            Err(VdbError::TooLarge { .. })
        ));
        std::fs::remove_dir_all(&dir).ok();
    }
}
