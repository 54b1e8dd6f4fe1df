//! Compiles the C++17 OpenVDB shim (shim/grin_vdb.cpp) and links OpenVDB, TBB and Imath.

use std::path::Path;

/// Debian packages that provide the headers and libraries the shim needs.
const APT_PACKAGES: &str = "libopenvdb-dev libboost-dev libtbb-dev";

/// Where OpenVDB's headers live unless `OPENVDB_INCLUDE_DIR` says otherwise.
const DEFAULT_INCLUDE_DIRS: &[&str] = &["/usr/include", "/usr/local/include"];

/// Where the OpenVDB, TBB and Imath shared libraries live unless `OPENVDB_LIB_DIR` says
/// otherwise (Debian multiarch first).
const DEFAULT_LIB_DIRS: &[&str] = &[
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
    let has = |rel: &str| include_dirs.iter().any(|d| Path::new(d).join(rel).exists());
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
        Err(_) => DEFAULT_LIB_DIRS.iter().map(|s| (*s).to_owned()).collect(),
    };
    for lib in ["libopenvdb.so", "libtbb.so", "libImath-3_1.so"] {
        if !lib_dirs.iter().any(|d| Path::new(d).join(lib).exists()) {
            missing.push(lib);
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

    let mut build = cc::Build::new();
    build
        .cpp(true)
        .std("c++17")
        .file("shim/grin_vdb.cpp")
        .include("shim")
        .warnings(false)
        // OpenVDB headers are heavy: optimise the shim even in dev builds.
        .opt_level(2);
    for d in &include_dirs {
        build.include(d);
    }
    build.compile("grin_vdb_shim");
    let lib_dir = std::env::var("OPENVDB_LIB_DIR").ok();
    build_checker(&build, lib_dir.as_deref());

    if let Ok(dir) = std::env::var("OPENVDB_LIB_DIR") {
        println!("cargo:rustc-link-search=native={dir}");
    }
    println!("cargo:rustc-link-lib=dylib=openvdb");
    println!("cargo:rustc-link-lib=dylib=tbb");
    println!("cargo:rustc-link-lib=dylib=Imath-3_1");
    println!("cargo:rustc-link-lib=dylib=stdc++");
}

/// Link shim/grin_vdb_check.cpp against the shim into `$OUT_DIR/grin-vdb-check`, the child
/// process vdb-sys uses to try a file before reading it in-process (see `VdbFile::open`).
/// Its path reaches the crate as `GRIN_VDB_CHECK`.
fn build_checker(build: &cc::Build, lib_dir: Option<&str>) {
    let out_dir = std::env::var("OUT_DIR").expect("cargo sets OUT_DIR");
    let exe = Path::new(&out_dir).join("grin-vdb-check");
    let compiler = build.get_compiler();
    let mut cmd = compiler.to_command();
    cmd.arg("-std=c++17")
        .arg("-O1")
        .arg("-Ishim")
        .arg("shim/grin_vdb_check.cpp")
        .arg("-o")
        .arg(&exe)
        .arg(format!("-L{out_dir}"))
        .arg("-lgrin_vdb_shim");
    if let Some(dir) = lib_dir {
        cmd.arg(format!("-L{dir}"));
    }
    cmd.args(["-lopenvdb", "-ltbb", "-lImath-3_1", "-lstdc++"]);
    let status = cmd.status();
    match status {
        Ok(s) if s.success() => {
            println!("cargo:rustc-env=GRIN_VDB_CHECK={}", exe.display());
        }
        other => panic!(
            "vdb-sys: linking the OpenVDB checker failed ({other:?}); install \
             `{APT_PACKAGES}` (or run scripts/setup.sh)"
        ),
    }
}
