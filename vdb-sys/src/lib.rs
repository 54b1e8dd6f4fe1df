//! Safe access to OpenVDB files through grin's C++ shim (shim/grin_vdb.cpp): open a file,
//! list its grids and metadata, read scalar and vec3 grids into dense arrays with their
//! `world_from_index` transform, and write float/vec3 grids with metadata.
//!
//! This crate holds grin's FFI `unsafe` code: [`ffi`] loads the shim, and the safe
//! wrappers that call it are `read` ([`VdbFile`]), `write` ([`VdbWriter`]) and the C
//! string helpers here (the other `unsafe` in grin: grin-gpu's pipeline-cache load and
//! grin-field's compiled formulas, `expr_jit`). Every shim call returns a status code and
//! message (the shim catches every C++ exception), so errors come back as [`VdbError`].
//!
//! OpenVDB is not linked into the program: build.rs links the shim as a shared library
//! against it, the crate embeds that library, and [`ffi`] loads it (and OpenVDB with it) at
//! the first [`VdbFile::open`] or [`VdbWriter::new`]. Programs start without binding
//! OpenVDB's symbols, and a machine without OpenVDB gets [`VdbError::Unavailable`] from
//! those two calls rather than a program that cannot start. Files are first read by a
//! checker in a child process (`checker`), where a crash of OpenVDB is an exit status.
//!
//! One concept a file: the checker process, the error type, the grid types, the
//! transform, reading and writing; this file keeps the crate's shared C helpers.

#![expect(
    unsafe_code,
    reason = "the FFI boundary to the OpenVDB shim lives here"
)]

mod checker;
mod error;
pub mod ffi;
mod read;
mod transform;
mod types;
mod write;

use std::ffi::{CStr, CString, c_char};
use std::path::Path;

pub use checker::{CHECK_ARG, checker_entry, use_current_exe_as_checker};
pub use error::VdbError;
pub use read::VdbFile;
pub use transform::Transform;
pub use types::{DenseGrid, GridInfo, IndexBox, Meta, MetaValue, ValueKind};
pub use write::{VdbWriter, WriteOptions};

/// Size of the buffer the shim writes error messages into.
const ERR_LEN: usize = 1024;

/// Bytes per voxel of a dense scalar read (f32).
pub const BYTES_PER_SCALAR_VOXEL: u64 = 4;

/// Load the shim and OpenVDB (once per process; see [`ffi`]).
fn loaded() -> Result<(), VdbError> {
    ffi::load().map_err(|message| VdbError::Unavailable { message })
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
