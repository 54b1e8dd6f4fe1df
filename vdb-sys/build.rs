//! Compiles the C++17 OpenVDB shim (shim/grin_vdb.cpp) and links OpenVDB, TBB and Imath.

use std::path::Path;

/// Debian packages that provide the headers and libraries the shim needs.
const APT_PACKAGES: &str = "libopenvdb-dev libboost-dev libtbb-dev";

/// Where OpenVDB's headers live unless `OPENVDB_INCLUDE_DIR` says otherwise.
const DEFAULT_INCLUDE_DIRS: &[&str] = &["/usr/include", "/usr/local/include"];

fn main() {
    println!("cargo:rerun-if-changed=shim/grin_vdb.cpp");
    println!("cargo:rerun-if-changed=shim/grin_vdb.h");
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
    if !missing.is_empty() {
        panic!(
            "vdb-sys: cannot build the OpenVDB shim: missing {} in {:?}. \
             Install them with `sudo apt-get install {APT_PACKAGES}` (or run scripts/setup.sh), \
             or set OPENVDB_INCLUDE_DIR / OPENVDB_LIB_DIR.",
            missing.join(", "),
            include_dirs
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

    if let Ok(dir) = std::env::var("OPENVDB_LIB_DIR") {
        println!("cargo:rustc-link-search=native={dir}");
    }
    println!("cargo:rustc-link-lib=dylib=openvdb");
    println!("cargo:rustc-link-lib=dylib=tbb");
    println!("cargo:rustc-link-lib=dylib=Imath-3_1");
    println!("cargo:rustc-link-lib=dylib=stdc++");
}
