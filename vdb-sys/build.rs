//! Compiles the C++17 OpenVDB shim (shim/grin_vdb.cpp) and links OpenVDB, TBB and Imath.

use std::path::Path;

/// Debian packages that provide the headers and libraries the shim needs.
const APT_PACKAGES: &str = "libopenvdb-dev libboost-dev libtbb-dev";

/// Where OpenVDB's headers live unless `OPENVDB_INCLUDE_DIR` says otherwise.
const DEFAULT_INCLUDE_DIRS: &[&str] = &["/usr/include", "/usr/local/include"];

/// Where the OpenVDB, TBB and Imath shared libraries are looked for after what the system
/// publishes (pkg-config, then the dynamic linker's cache `ldconfig -p`), unless
/// `OPENVDB_LIB_DIR` says otherwise: Debian's multiarch paths, then the usual ones.
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
    let published = Published::find();
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
        "openvdb".to_owned(),
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

    let mut build = cc::Build::new();
    for d in &published.include_dirs {
        build.include(d);
    }
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
    build_checker(&build, lib_dir.as_deref(), &libs);

    if let Ok(dir) = std::env::var("OPENVDB_LIB_DIR") {
        println!("cargo:rustc-link-search=native={dir}");
    }
    for dir in &published.lib_dirs {
        println!("cargo:rustc-link-search=native={dir}");
    }
    for lib in &libs {
        println!("cargo:rustc-link-lib=dylib={lib}");
    }
    println!("cargo:rustc-link-lib=dylib=stdc++");
}

/// What the system says about TBB and Imath (pkg-config) and where the dynamic linker
/// finds OpenVDB (`ldconfig -p`; Debian ships no OpenVDB.pc).
#[derive(Debug)]
struct Published {
    /// TBB's library name (`tbb`).
    tbb: String,
    /// Imath's versioned library name (`Imath-3_1` on Debian 12).
    imath: String,
    lib_dirs: Vec<String>,
    include_dirs: Vec<String>,
}

impl Published {
    fn find() -> Self {
        println!("cargo:rerun-if-env-changed=PKG_CONFIG_PATH");
        let mut found = Published {
            tbb: "tbb".to_owned(),
            imath: "Imath-3_1".to_owned(),
            lib_dirs: Vec::new(),
            include_dirs: Vec::new(),
        };
        for (package, prefix) in [("tbb", "tbb"), ("Imath", "Imath")] {
            let Some(flags) = pkg_config(package) else {
                continue;
            };
            for flag in flags.split_whitespace() {
                if let Some(lib) = flag.strip_prefix("-l")
                    && lib.starts_with(prefix)
                {
                    if package == "tbb" {
                        found.tbb = lib.to_owned();
                    } else {
                        found.imath = lib.to_owned();
                    }
                } else if let Some(dir) = flag.strip_prefix("-L") {
                    found.lib_dirs.push(dir.to_owned());
                } else if let Some(dir) = flag.strip_prefix("-I") {
                    found.include_dirs.push(dir.to_owned());
                }
            }
        }
        if let Some(cache) = command_output("ldconfig", &["-p"]) {
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

/// `pkg-config --cflags --libs PACKAGE`, or `None` where pkg-config or the package is absent.
fn pkg_config(package: &str) -> Option<String> {
    command_output("pkg-config", &["--cflags", "--libs", package])
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

/// Link shim/grin_vdb_check.cpp against the shim into `$OUT_DIR/grin-vdb-check`, the child
/// process vdb-sys uses to try a file before reading it in-process (see `VdbFile::open`).
/// Its path reaches the crate as `GRIN_VDB_CHECK`.
fn build_checker(build: &cc::Build, lib_dir: Option<&str>, libs: &[String]) {
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
    cmd.args(libs.iter().map(|l| format!("-l{l}")));
    cmd.arg("-lstdc++");
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
