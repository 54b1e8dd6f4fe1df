//! The child-process check of a file before this process reads it: OpenVDB can abort on
//! some malformed files, which in a child is only an exit status.

use std::path::{Path, PathBuf};

use crate::{BYTES_PER_SCALAR_VOXEL, VdbError, VdbFile};

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
pub(crate) fn check_in_child(path: &Path) -> Result<(), VdbError> {
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
