//! Raw bindings to the C shim (shim/grin_vdb.h). Keep in sync with that header.

use std::ffi::c_char;

pub const GRIN_VDB_OK: i32 = 0;
pub const GRIN_VDB_ERR_IO: i32 = 1;
pub const GRIN_VDB_ERR_ARG: i32 = 2;
pub const GRIN_VDB_ERR_MEMORY: i32 = 3;

pub const GRIN_VDB_TYPE_FLOAT: i32 = 1;
pub const GRIN_VDB_TYPE_DOUBLE: i32 = 2;
pub const GRIN_VDB_TYPE_VEC3S: i32 = 3;
pub const GRIN_VDB_TYPE_VEC3D: i32 = 4;

pub const GRIN_VDB_META_STRING: i32 = 1;
pub const GRIN_VDB_META_NUMBER: i32 = 2;

/// Opaque file handle.
#[repr(C)]
#[derive(Debug)]
pub struct GrinVdbFile {
    _private: [u8; 0],
}

/// Opaque writer handle.
#[repr(C)]
#[derive(Debug)]
pub struct GrinVdbWriter {
    _private: [u8; 0],
}

/// Mirrors `GrinVdbGridInfo` in grin_vdb.h.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct GrinVdbGridInfo {
    pub name: *const c_char,
    pub value_type: *const c_char,
    pub grid_class: *const c_char,
    pub map_type: *const c_char,
    pub type_code: i32,
    pub is_linear: i32,
    pub save_float_as_half: i32,
    pub is_empty: i32,
    pub voxel_size: [f64; 3],
    pub world_from_index: [f64; 12],
    pub bbox_min: [i32; 3],
    pub bbox_max: [i32; 3],
    pub active_voxel_count: u64,
    pub non_finite_count: u64,
    pub value_min: f64,
    pub value_max: f64,
    pub background: f64,
    pub meta_count: usize,
    pub data_min: [i32; 3],
    pub data_max: [i32; 3],
    pub data_voxel_count: u64,
}

unsafe extern "C" {
    pub fn grin_vdb_open(
        path: *const c_char,
        out: *mut *mut GrinVdbFile,
        err: *mut c_char,
        err_len: usize,
    ) -> i32;
    pub fn grin_vdb_close(file: *mut GrinVdbFile);
    pub fn grin_vdb_grid_count(file: *const GrinVdbFile) -> usize;
    pub fn grin_vdb_grid_info(
        file: *const GrinVdbFile,
        grid: usize,
        out: *mut GrinVdbGridInfo,
        err: *mut c_char,
        err_len: usize,
    ) -> i32;
    pub fn grin_vdb_file_meta_count(file: *const GrinVdbFile) -> usize;
    pub fn grin_vdb_meta(
        file: *const GrinVdbFile,
        grid: usize,
        i: usize,
        key: *mut *const c_char,
        type_name: *mut *const c_char,
        kind: *mut i32,
        text: *mut *const c_char,
        number: *mut f64,
        err: *mut c_char,
        err_len: usize,
    ) -> i32;
    pub fn grin_vdb_read_scalar(
        file: *const GrinVdbFile,
        grid: usize,
        bmin: *const i32,
        bmax: *const i32,
        out: *mut f32,
        out_len: usize,
        err: *mut c_char,
        err_len: usize,
    ) -> i32;
    pub fn grin_vdb_read_vec3(
        file: *const GrinVdbFile,
        grid: usize,
        bmin: *const i32,
        bmax: *const i32,
        out: *mut f32,
        out_len: usize,
        err: *mut c_char,
        err_len: usize,
    ) -> i32;
    pub fn grin_vdb_writer_new() -> *mut GrinVdbWriter;
    pub fn grin_vdb_writer_free(writer: *mut GrinVdbWriter);
    pub fn grin_vdb_writer_add_grid(
        writer: *mut GrinVdbWriter,
        name: *const c_char,
        components: i32,
        origin: *const i32,
        dims: *const u64,
        data: *const f32,
        data_len: usize,
        world_from_index: *const f64,
        background: f32,
        tolerance: f32,
        save_as_half: i32,
        meta_keys: *const *const c_char,
        meta_values: *const *const c_char,
        n_meta: usize,
        num_keys: *const *const c_char,
        num_values: *const f64,
        n_num: usize,
        err: *mut c_char,
        err_len: usize,
    ) -> i32;
    pub fn grin_vdb_writer_add_file_meta(
        writer: *mut GrinVdbWriter,
        key: *const c_char,
        value: *const c_char,
        err: *mut c_char,
        err_len: usize,
    ) -> i32;
    pub fn grin_vdb_writer_write(
        writer: *mut GrinVdbWriter,
        path: *const c_char,
        err: *mut c_char,
        err_len: usize,
    ) -> i32;
}
