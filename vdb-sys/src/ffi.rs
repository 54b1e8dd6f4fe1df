//! Raw bindings to the C shim (shim/grin_vdb.h), loaded at run time. Keep in sync with
//! that header.
//!
//! build.rs links the shim into a shared library against OpenVDB, TBB and Imath; its bytes
//! are embedded here and nothing of OpenVDB is linked into the program. The first call
//! ([`load`], or any function below) writes the bytes into an anonymous file
//! (`memfd_create`) and `dlopen`s it through `/proc/self/fd`; where that is refused, into
//! a file in the temporary directory named by the library's length and hash. The
//! dynamic linker then loads and binds OpenVDB, which costs tens of milliseconds: only
//! programs that read or write VDB files pay it, once. The library stays loaded for the
//! life of the process.
//!
//! Each function below has the name and signature of the C function it calls, and loads
//! the library first if no call has. Where it cannot be loaded, those that return a status
//! write the reason into `err` and return [`GRIN_VDB_ERR_OTHER`]; the others return null,
//! 0 or nothing. The safe wrapper calls [`load`] where it starts (opening a file, creating
//! a writer) and reports a failure there as `VdbError::Unavailable`.

use std::ffi::c_char;
use std::path::Path;
use std::sync::OnceLock;

use libloading::Library;

pub const GRIN_VDB_OK: i32 = 0;
pub const GRIN_VDB_ERR_IO: i32 = 1;
pub const GRIN_VDB_ERR_ARG: i32 = 2;
pub const GRIN_VDB_ERR_MEMORY: i32 = 3;
pub const GRIN_VDB_ERR_OTHER: i32 = 4;

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

/// The shim linked by build.rs.
const SHIM: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/libgrin_vdb_shim.so"));
/// The shim's length and hash (build.rs): the name of its copy in the temporary directory.
const SHIM_ID: &str = env!("GRIN_VDB_SHIM_ID");
/// The OpenVDB library the shim needs, as the dynamic linker names it (build.rs).
const OPENVDB: &str = env!("GRIN_VDB_OPENVDB");
/// What to do where OpenVDB's libraries are missing (Debian's package pulls in OpenVDB,
/// TBB and Imath).
const INSTALL_HINT: &str =
    "install them with `sudo apt-get install libopenvdb-dev` (or run scripts/setup.sh)";

static TABLE: OnceLock<Result<Table, String>> = OnceLock::new();

/// Load the shim, and OpenVDB with it, if no call has yet: `Ok` once it is loaded, else
/// why it cannot be (the same answer for the rest of the process).
pub fn load() -> Result<(), String> {
    table().map(|_| ()).map_err(str::to_owned)
}

fn table() -> Result<&'static Table, &'static str> {
    TABLE
        .get_or_init(|| open_shim().and_then(Table::resolve))
        .as_ref()
        .map_err(String::as_str)
}

/// Write why the shim is not loaded into the caller's error buffer (truncated and
/// NUL-terminated) and return [`GRIN_VDB_ERR_OTHER`].
///
/// Safety: `err` is null or valid for writes of `err_len` bytes.
unsafe fn unloaded(err: *mut c_char, err_len: usize) -> i32 {
    let message = table().err().unwrap_or("grin's OpenVDB shim is not loaded");
    if !err.is_null() && err_len > 0 {
        let n = message.len().min(err_len - 1);
        // SAFETY: `n + 1 <= err_len` bytes, which the caller guarantees are writable; the
        // message is a separate allocation.
        unsafe {
            std::ptr::copy_nonoverlapping(message.as_ptr().cast::<c_char>(), err, n);
            *err.add(n) = 0;
        }
    }
    GRIN_VDB_ERR_OTHER
}

/// How one way of loading the shim failed.
#[derive(Debug)]
enum Failure {
    /// The shim's bytes could not be placed or mapped this way: another way may work.
    Retry(String),
    /// The dynamic linker refused for a reason that is not the shim's file (OpenVDB or a
    /// library it needs is missing or broken, most often): every way would fail alike.
    Final(String),
}

/// The shim, from an anonymous file or else from the temporary directory.
fn open_shim() -> Result<Library, String> {
    let in_memory = match from_memfd() {
        Ok(library) => return Ok(library),
        Err(Failure::Final(e)) => return Err(cannot_load(&e)),
        Err(Failure::Retry(e)) => e,
    };
    match from_temp_file() {
        Ok(library) => Ok(library),
        Err(Failure::Final(e)) => Err(cannot_load(&e)),
        Err(Failure::Retry(e)) => Err(format!(
            "cannot load OpenVDB ({OPENVDB}): grin's OpenVDB shim could be placed neither in \
             an anonymous file ({in_memory}) nor in the temporary directory ({e})"
        )),
    }
}

fn cannot_load(dlerror: &str) -> String {
    format!(
        "cannot load OpenVDB ({OPENVDB}): {dlerror}; VDB files need the OpenVDB, TBB and \
         Imath runtime libraries: {INSTALL_HINT}"
    )
}

/// `dlopen` the shim at `path`. A refusal that names `path` is about the file there (no
/// /proc, a mount that forbids mapping code): another place may work.
fn open_at(path: &Path) -> Result<Library, Failure> {
    // SAFETY: loading runs the static initialisers of the shim, OpenVDB, TBB and Imath,
    // which need nothing from the caller; the file holds exactly the shim build.rs linked.
    unsafe { Library::new(path) }.map_err(|e| {
        let message = e.to_string();
        if message.contains(&*path.to_string_lossy()) {
            Failure::Retry(message)
        } else {
            Failure::Final(message)
        }
    })
}

/// Write the shim into a `memfd_create` file and load it through `/proc/self/fd/N`.
#[cfg(target_os = "linux")]
fn from_memfd() -> Result<Library, Failure> {
    use std::io::Write as _;
    use std::os::fd::{FromRawFd as _, OwnedFd};

    let name = c"grin_vdb_shim";
    // SAFETY: a NUL-terminated name and valid flags; the result is a new descriptor or -1.
    let mut fd = unsafe { libc::memfd_create(name.as_ptr(), libc::MFD_CLOEXEC | libc::MFD_EXEC) };
    if fd < 0 && std::io::Error::last_os_error().raw_os_error() == Some(libc::EINVAL) {
        // Kernels before 6.3 know no MFD_EXEC; their anonymous files can be mapped as code.
        // SAFETY: as above.
        fd = unsafe { libc::memfd_create(name.as_ptr(), libc::MFD_CLOEXEC) };
    }
    if fd < 0 {
        return Err(Failure::Retry(format!(
            "memfd_create: {}",
            std::io::Error::last_os_error()
        )));
    }
    // SAFETY: `fd` is a new descriptor that nothing else owns.
    let mut file = std::fs::File::from(unsafe { OwnedFd::from_raw_fd(fd) });
    file.write_all(SHIM)
        .map_err(|e| Failure::Retry(format!("writing it: {e}")))?;
    // The descriptor stays open until the library is mapped; the mapping then keeps the
    // anonymous file alive.
    open_at(Path::new(&format!("/proc/self/fd/{fd}")))
}

#[cfg(not(target_os = "linux"))]
fn from_memfd() -> Result<Library, Failure> {
    Err(Failure::Retry("memfd_create is Linux-only".into()))
}

/// Load the shim from `grin-vdb-shim-<uid>-<length>-<hash>.so` in the temporary directory,
/// written there (under a temporary name, then renamed) unless this user's copy already is.
/// The copy is left there for the next process.
fn from_temp_file() -> Result<Library, Failure> {
    from_dir(&std::env::temp_dir())
}

fn from_dir(dir: &Path) -> Result<Library, Failure> {
    // SAFETY: geteuid has no preconditions and cannot fail.
    let uid = unsafe { libc::geteuid() };
    let path = dir.join(format!("grin-vdb-shim-{uid}-{SHIM_ID}.so"));
    if !holds_shim(&path, uid) {
        let staged = dir.join(format!(
            "grin-vdb-shim-{uid}-{SHIM_ID}.{}.tmp",
            std::process::id()
        ));
        write_new(&staged)
            .and_then(|()| std::fs::rename(&staged, &path))
            .map_err(|e| {
                let _ = std::fs::remove_file(&staged);
                Failure::Retry(format!("{}: {e}", path.display()))
            })?;
    }
    open_at(&path)
}

/// Whether `path` is a regular file of this user's, writable by no one else, holding
/// exactly the shim's bytes (so that a file planted in a shared directory is never loaded).
fn holds_shim(path: &Path, uid: u32) -> bool {
    use std::os::unix::fs::MetadataExt as _;
    std::fs::symlink_metadata(path).is_ok_and(|m| {
        m.is_file() && m.uid() == uid && m.mode() & 0o022 == 0 && m.len() == SHIM.len() as u64
    }) && std::fs::read(path).is_ok_and(|bytes| bytes == SHIM)
}

/// Create `path` afresh (never through an existing file or link) and write the shim.
fn write_new(path: &Path) -> std::io::Result<()> {
    use std::io::Write as _;
    use std::os::unix::fs::OpenOptionsExt as _;
    let create = || {
        std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .mode(0o600)
            .open(path)
    };
    let mut file = match create() {
        // A leftover of an earlier process with the same id.
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
            std::fs::remove_file(path)?;
            create()?
        }
        other => other?,
    };
    file.write_all(SHIM)?;
    file.sync_all()
}

/// Declares the shim's functions once: the table's fields, their resolution by name, and
/// the wrappers of the same name and signature that call through the table (after `=>`:
/// what a wrapper returns where the shim is not loaded).
macro_rules! shim {
    ($(
        fn $name:ident($($arg:ident: $ty:ty),* $(,)?) $(-> $ret:ty)? => $unloaded:expr;
    )*) => {
        /// The shim's functions, resolved from the loaded library.
        struct Table {
            /// Keeps the shim, and OpenVDB behind it, mapped for the life of the process.
            _library: Library,
            $($name: unsafe extern "C" fn($($ty),*) $(-> $ret)?,)*
        }

        impl Table {
            fn resolve(library: Library) -> Result<Table, String> {
                $(
                    let $name = {
                        // SAFETY: the shim defines this symbol as the `extern "C"` function
                        // of this signature (grin_vdb.h); the pointer is only called while
                        // `library`, kept in the table, stays loaded.
                        let symbol = unsafe {
                            library.get::<unsafe extern "C" fn($($ty),*) $(-> $ret)?>(
                                concat!(stringify!($name), "\0").as_bytes(),
                            )
                        }
                        .map_err(|e| format!(
                            "grin's OpenVDB shim has no `{}`: {e}",
                            stringify!($name)
                        ))?;
                        *symbol
                    };
                )*
                Ok(Table { _library: library, $($name,)* })
            }
        }

        $(
            #[doc = concat!("`", stringify!($name), "` of grin_vdb.h, through the loaded shim.")]
            ///
            /// # Safety
            ///
            /// The arguments must meet grin_vdb.h's contract for this function: handles
            /// from the shim and still open, pointers valid for the lengths given.
            #[allow(
                clippy::too_many_arguments,
                reason = "the C function's signature, argument for argument"
            )]
            pub unsafe fn $name($($arg: $ty),*) $(-> $ret)? {
                match table() {
                    // SAFETY: the caller meets the C function's contract; the table's
                    // library stays loaded.
                    Ok(table) => unsafe { (table.$name)($($arg),*) },
                    Err(_) => $unloaded,
                }
            }
        )*
    };
}

shim! {
    fn grin_vdb_open(
        path: *const c_char,
        out: *mut *mut GrinVdbFile,
        err: *mut c_char,
        err_len: usize,
    ) -> i32 => unsafe { unloaded(err, err_len) };
    fn grin_vdb_close(file: *mut GrinVdbFile) => ();
    fn grin_vdb_grid_count(file: *const GrinVdbFile) -> usize => 0;
    fn grin_vdb_grid_info(
        file: *const GrinVdbFile,
        grid: usize,
        out: *mut GrinVdbGridInfo,
        err: *mut c_char,
        err_len: usize,
    ) -> i32 => unsafe { unloaded(err, err_len) };
    fn grin_vdb_file_meta_count(file: *const GrinVdbFile) -> usize => 0;
    fn grin_vdb_meta(
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
    ) -> i32 => unsafe { unloaded(err, err_len) };
    fn grin_vdb_read_scalar(
        file: *const GrinVdbFile,
        grid: usize,
        bmin: *const i32,
        bmax: *const i32,
        out: *mut f32,
        out_len: usize,
        err: *mut c_char,
        err_len: usize,
    ) -> i32 => unsafe { unloaded(err, err_len) };
    fn grin_vdb_read_vec3(
        file: *const GrinVdbFile,
        grid: usize,
        bmin: *const i32,
        bmax: *const i32,
        out: *mut f32,
        out_len: usize,
        err: *mut c_char,
        err_len: usize,
    ) -> i32 => unsafe { unloaded(err, err_len) };
    fn grin_vdb_writer_new() -> *mut GrinVdbWriter => std::ptr::null_mut();
    fn grin_vdb_writer_free(writer: *mut GrinVdbWriter) => ();
    fn grin_vdb_writer_add_grid(
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
    ) -> i32 => unsafe { unloaded(err, err_len) };
    fn grin_vdb_writer_add_box(
        writer: *mut GrinVdbWriter,
        origin: *const i32,
        dims: *const u64,
        data: *const f32,
        data_len: usize,
        tolerance: f32,
        err: *mut c_char,
        err_len: usize,
    ) -> i32 => unsafe { unloaded(err, err_len) };
    fn grin_vdb_writer_add_file_meta(
        writer: *mut GrinVdbWriter,
        key: *const c_char,
        value: *const c_char,
        err: *mut c_char,
        err_len: usize,
    ) -> i32 => unsafe { unloaded(err, err_len) };
    fn grin_vdb_writer_write(
        writer: *mut GrinVdbWriter,
        path: *const c_char,
        err: *mut c_char,
        err_len: usize,
    ) -> i32 => unsafe { unloaded(err, err_len) };
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The fallback where memfd is refused: the copy is written once, then reused; a file
    /// of that name that is not the shim is replaced, never loaded.
    #[test]
    fn the_temp_file_fallback_writes_reuses_and_replaces() {
        let dir = std::env::temp_dir().join(format!("vdb-sys-fallback-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("create the test directory");
        // SAFETY: no preconditions.
        let uid = unsafe { libc::geteuid() };
        let path = dir.join(format!("grin-vdb-shim-{uid}-{SHIM_ID}.so"));
        std::fs::write(&path, b"not the shim").expect("plant a file");
        assert!(!holds_shim(&path, uid));

        let table = from_dir(&dir)
            .map_err(|e| format!("{e:?}"))
            .and_then(Table::resolve);
        let table = table.expect("the shim loads from the directory");
        assert!(
            holds_shim(&path, uid),
            "the planted file was replaced by the shim"
        );
        // SAFETY: a writer from this library, freed once by it.
        unsafe {
            let writer = (table.grin_vdb_writer_new)();
            assert!(!writer.is_null());
            (table.grin_vdb_writer_free)(writer);
        }
        let modified = std::fs::metadata(&path).and_then(|m| m.modified()).ok();
        from_dir(&dir)
            .map_err(|e| format!("{e:?}"))
            .expect("loads again");
        let again = std::fs::metadata(&path).and_then(|m| m.modified()).ok();
        assert_eq!(modified, again, "the copy is reused, not rewritten");
        let leftovers = std::fs::read_dir(&dir).expect("list").count();
        assert_eq!(leftovers, 1, "no staged file is left behind");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn an_unloaded_shim_writes_a_truncated_terminated_message() {
        let mut err = [1 as c_char; 8];
        // SAFETY: a buffer of the stated length.
        let status = unsafe { unloaded(err.as_mut_ptr(), err.len()) };
        assert_eq!(status, GRIN_VDB_ERR_OTHER);
        assert_eq!(err[7], 0, "the message is NUL-terminated within the buffer");
        // SAFETY: null with length 0 writes nothing.
        assert_eq!(
            unsafe { unloaded(std::ptr::null_mut(), 0) },
            GRIN_VDB_ERR_OTHER
        );
    }
}
