//! Compiles the C++17 OpenVDB shim (shim/grin_vdb.cpp) into a shared library linked
//! against OpenVDB, TBB and Imath, which the crate embeds and loads at run time (see
//! src/ffi.rs): binaries that use vdb-sys do not link OpenVDB themselves. Also links the
//! checker executable (shim/grin_vdb_check.cpp).

use std::path::{Path, PathBuf};

/// The shared library build.rs links into `OUT_DIR`; src/ffi.rs embeds it by this name.
const SHIM_FILE: &str = "libgrin_vdb_shim.so";

/// Debian packages that provide the headers and libraries the shim needs.
const APT_PACKAGES: &str = "libopenvdb-dev libboost-dev libtbb-dev";

/// Where OpenVDB's headers live unless `OPENVDB_INCLUDE_DIR` says otherwise (the include
/// directories of the pkg-config files found are looked in too).
const DEFAULT_INCLUDE_DIRS: &[&str] = &["/usr/include", "/usr/local/include"];

/// Where the OpenVDB, TBB and Imath shared libraries are looked for after what the system
/// publishes (pkg-config files, else for OpenVDB the dynamic linker's cache `ldconfig -p`),
/// unless `OPENVDB_LIB_DIR` says otherwise: Debian's multiarch paths, then the usual ones.
const FALLBACK_LIB_DIRS: &[&str] = &[
    "/usr/lib/x86_64-linux-gnu",
    "/usr/lib/aarch64-linux-gnu",
    "/usr/lib",
    "/usr/local/lib",
];

fn main() {
    println!("cargo:rerun-if-changed=shim/grin_vdb.cpp");
    println!("cargo:rerun-if-changed=shim/grin_vdb.h");
    println!("cargo:rerun-if-changed=shim/grin_vdb_check.cpp");
    println!("cargo:rerun-if-env-changed=OPENVDB_INCLUDE_DIR");
    println!("cargo:rerun-if-env-changed=OPENVDB_LIB_DIR");

    let include_dirs: Vec<String> = match std::env::var("OPENVDB_INCLUDE_DIR") {
        Ok(dir) => vec![dir],
        Err(_) => DEFAULT_INCLUDE_DIRS
            .iter()
            .map(|s| (*s).to_owned())
            .collect(),
    };
    let published = Published::find();
    let has = |rel: &str| {
        include_dirs
            .iter()
            .chain(&published.include_dirs)
            .any(|d| Path::new(d).join(rel).exists())
    };
    let mut missing = Vec::new();
    if !has("openvdb/openvdb.h") {
        missing.push("OpenVDB headers (openvdb/openvdb.h)");
    }
    if !has("boost/version.hpp") {
        missing.push("Boost headers (boost/version.hpp)");
    }
    if !has("tbb/tbb.h") && !has("oneapi/tbb.h") {
        missing.push("TBB headers (tbb/tbb.h)");
    }
    let lib_dirs: Vec<String> = match std::env::var("OPENVDB_LIB_DIR") {
        Ok(dir) => vec![dir],
        Err(_) => {
            let mut dirs = published.lib_dirs.clone();
            dirs.extend(FALLBACK_LIB_DIRS.iter().map(|s| (*s).to_owned()));
            dirs.dedup();
            dirs
        }
    };
    let libs = [
        published.openvdb.clone(),
        published.tbb.clone(),
        published.imath.clone(),
    ];
    let lib_files: Vec<String> = libs.iter().map(|l| format!("lib{l}.so")).collect();
    for lib in &lib_files {
        if !lib_dirs.iter().any(|d| Path::new(d).join(lib).exists()) {
            missing.push(lib.as_str());
        }
    }
    if !missing.is_empty() {
        panic!(
            "vdb-sys: cannot build the OpenVDB shim: missing {} (looked in {:?} and {:?}). \
             Install them with `sudo apt-get install {APT_PACKAGES}` (or run scripts/setup.sh), \
             or set OPENVDB_INCLUDE_DIR / OPENVDB_LIB_DIR.",
            missing.join(", "),
            include_dirs,
            lib_dirs
        );
    }

    let out_dir = PathBuf::from(std::env::var("OUT_DIR").expect("cargo sets OUT_DIR"));
    let mut link_dirs: Vec<String> = std::env::var("OPENVDB_LIB_DIR").into_iter().collect();
    link_dirs.extend(published.lib_dirs.iter().cloned());

    // One position-independent object, linked twice: into the shared library the crate
    // embeds, and into the checker executable.
    let mut build = cc::Build::new();
    for d in &published.include_dirs {
        build.include(d);
    }
    build
        .cpp(true)
        .std("c++17")
        .pic(true)
        .file("shim/grin_vdb.cpp")
        .include("shim")
        .warnings(false)
        // OpenVDB headers are heavy: optimise the shim even in dev builds.
        .opt_level(2);
    for d in &include_dirs {
        build.include(d);
    }
    let objects = build.compile_intermediates();
    let compiler = build.get_compiler();
    let link = |cmd: &mut std::process::Command| {
        cmd.args(link_dirs.iter().map(|d| format!("-L{d}")))
            .args(libs.iter().map(|l| format!("-l{l}")))
            .arg("-lstdc++");
    };
    build_shared(&compiler, &objects, &out_dir, &link);
    build_checker(&compiler, &objects, &out_dir, &link);
    println!(
        "cargo:rustc-env=GRIN_VDB_OPENVDB={}",
        openvdb_soname(&lib_dirs)
    );
    // Nothing is linked into the crate's users: the shim and OpenVDB behind it are
    // loaded at run time by the first VDB call (src/ffi.rs), so a grin command that
    // reads no VDB file never pays for binding OpenVDB's symbols.
}

/// Link the shim into `$OUT_DIR/libgrin_vdb_shim.so` (stripped), the library src/ffi.rs
/// embeds and loads on first use; its id (length and FNV-1a hash of its bytes) reaches the
/// crate as `GRIN_VDB_SHIM_ID`, for the name of the copy written where memfd is refused.
fn build_shared(
    compiler: &cc::Tool,
    objects: &[PathBuf],
    out_dir: &Path,
    link: &dyn Fn(&mut std::process::Command),
) {
    let lib = out_dir.join(SHIM_FILE);
    let mut cmd = compiler.to_command();
    cmd.arg("-shared")
        .arg("-s")
        .arg("-Wl,--no-undefined")
        .arg("-o")
        .arg(&lib)
        .args(objects);
    link(&mut cmd);
    match cmd.status() {
        Ok(s) if s.success() => {}
        other => panic!(
            "vdb-sys: linking the OpenVDB shim {} failed ({other:?}); install \
             `{APT_PACKAGES}` (or run scripts/setup.sh)",
            lib.display()
        ),
    }
    let bytes = std::fs::read(&lib).expect("vdb-sys: the shim just linked is readable");
    let hash = bytes.iter().fold(0xcbf2_9ce4_8422_2325_u64, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    });
    println!(
        "cargo:rustc-env=GRIN_VDB_SHIM_ID={}-{hash:016x}",
        bytes.len()
    );
}

/// The name the dynamic linker looks OpenVDB up by (`libopenvdb.so.10.0` on Debian 12,
/// where `libopenvdb.so` links to it), for the message shown where it cannot be loaded.
fn openvdb_soname(lib_dirs: &[String]) -> String {
    lib_dirs
        .iter()
        .filter_map(|d| std::fs::read_link(Path::new(d).join("libopenvdb.so")).ok())
        .filter_map(|target| Some(target.file_name()?.to_str()?.to_owned()))
        .find(|name| name.starts_with("libopenvdb.so."))
        .unwrap_or_else(|| "libopenvdb.so".to_owned())
}

/// What the system publishes about OpenVDB, TBB and Imath: their pkg-config files where
/// it has them (OpenVDB's as `OpenVDB` or `openvdb`; Debian ships tbb.pc and Imath.pc,
/// none for OpenVDB), and without an OpenVDB one, where the dynamic linker finds OpenVDB
/// (`ldconfig -p`).
#[derive(Debug)]
struct Published {
    /// OpenVDB's library name (`openvdb`).
    openvdb: String,
    /// TBB's library name (`tbb`).
    tbb: String,
    /// Imath's versioned library name (`Imath-3_1` on Debian 12).
    imath: String,
    lib_dirs: Vec<String>,
    include_dirs: Vec<String>,
}

impl Published {
    fn find() -> Self {
        let mut found = Published {
            openvdb: "openvdb".to_owned(),
            tbb: "tbb".to_owned(),
            imath: "Imath-3_1".to_owned(),
            lib_dirs: Vec::new(),
            include_dirs: Vec::new(),
        };
        let mut openvdb_pc = false;
        for (package, prefix) in [
            ("OpenVDB", "openvdb"),
            ("openvdb", "openvdb"),
            ("tbb", "tbb"),
            ("Imath", "Imath"),
        ] {
            if prefix == "openvdb" && openvdb_pc {
                continue;
            }
            let Some(library) = pkg_config_probe(package) else {
                continue;
            };
            for lib in library.libs.iter().filter(|l| l.starts_with(prefix)) {
                match prefix {
                    "openvdb" => found.openvdb = lib.clone(),
                    "tbb" => found.tbb = lib.clone(),
                    _ => found.imath = lib.clone(),
                }
            }
            let shown = |dirs: &[PathBuf]| {
                dirs.iter()
                    .map(|d| d.display().to_string())
                    .collect::<Vec<_>>()
            };
            found.lib_dirs.extend(shown(&library.link_paths));
            found.include_dirs.extend(shown(&library.include_paths));
            openvdb_pc |= prefix == "openvdb";
        }
        if !openvdb_pc && let Some(cache) = command_output("ldconfig", &["-p"]) {
            for line in cache.lines() {
                if let Some((name, path)) = line.trim().split_once(" => ")
                    && name.starts_with("libopenvdb.so ")
                    && let Some(dir) = Path::new(path.trim()).parent()
                {
                    found.lib_dirs.push(dir.display().to_string());
                }
            }
        }
        found
    }
}

/// The `-l`, `-L` and `-I` flags of `package`'s pkg-config file, as
/// `pkg-config --cflags --libs PACKAGE` gives them (system directories left out), or `None`
/// where pkg-config or the file is absent. Nothing is linked into the crate from them: the
/// shim and the checker link these libraries themselves.
fn pkg_config_probe(package: &str) -> Option<pkg_config::Library> {
    pkg_config::Config::new()
        .cargo_metadata(false)
        .print_system_libs(false)
        .print_system_cflags(false)
        .statik(false)
        .probe(package)
        .ok()
}

fn command_output(program: &str, args: &[&str]) -> Option<String> {
    let out = std::process::Command::new(program)
        .args(args)
        .output()
        .ok()?;
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).into_owned())
}

/// Link shim/grin_vdb_check.cpp with the shim's object into `$OUT_DIR/grin-vdb-check`, the
/// child process vdb-sys uses to try a file before reading it in-process (see
/// `VdbFile::open`). It links OpenVDB directly (it runs from the build tree, where the
/// libraries were found). Its path reaches the crate as `GRIN_VDB_CHECK`.
fn build_checker(
    compiler: &cc::Tool,
    objects: &[PathBuf],
    out_dir: &Path,
    link: &dyn Fn(&mut std::process::Command),
) {
    let exe = out_dir.join("grin-vdb-check");
    let mut cmd = compiler.to_command();
    cmd.arg("-std=c++17")
        .arg("-O1")
        .arg("-Ishim")
        .arg("shim/grin_vdb_check.cpp")
        .args(objects)
        .arg("-o")
        .arg(&exe);
    link(&mut cmd);
    match cmd.status() {
        Ok(s) if s.success() => {
            println!("cargo:rustc-env=GRIN_VDB_CHECK={}", exe.display());
        }
        other => panic!(
            "vdb-sys: linking the OpenVDB checker failed ({other:?}); install \
             `{APT_PACKAGES}` (or run scripts/setup.sh)"
        ),
    }
}
