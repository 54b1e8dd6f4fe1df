//! OpenVDB is loaded at run time, by the first VDB call, not linked: a program that uses
//! vdb-sys starts without it. One test in its own binary, so that no other test has
//! loaded the shim first.

use std::path::Path;

/// Whether a library whose file name contains `name` is mapped into this process.
fn mapped(name: &str) -> bool {
    let maps = std::fs::read_to_string("/proc/self/maps").expect("read /proc/self/maps");
    maps.lines().any(|line| line.contains(name))
}

#[test]
fn openvdb_is_loaded_on_first_use_not_at_start() {
    // Every library a binary names as NEEDED is mapped before main runs.
    for lib in ["libopenvdb", "libtbb", "libImath", "grin_vdb_shim"] {
        assert!(!mapped(lib), "{lib} is mapped before any VDB call");
    }
    vdb_sys::ffi::load().expect("the shim and OpenVDB load in-process");
    assert!(
        mapped("libopenvdb"),
        "OpenVDB is mapped after loading the shim"
    );
    assert!(
        mapped("grin_vdb_shim"),
        "the shim is mapped after loading it"
    );
    // Loading again is free and gives the same answer.
    vdb_sys::ffi::load().expect("a second load");

    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/vdb/houdini_pyro.vdb");
    let file = vdb_sys::VdbFile::open(&path).expect("a VDB file opens through the loaded shim");
    let names: Vec<&str> = file.grids().iter().map(|g| g.name.as_str()).collect();
    assert_eq!(names, ["temperature", "vel"]);
}
