//! vdb-sys against the files scripts/make_vdb_data.py writes with python3-openvdb
//! (data/vdb/): values, half floats, negative origins, voxel sizes and transforms, and the
//! errors for bad files.

use std::path::{Path, PathBuf};

use serde_json::Value;
use vdb_sys::{IndexBox, ValueKind, VdbError, VdbFile};

/// Cap used for dense reads in these tests.
const TEST_CAP_BYTES: u64 = 256 << 20;

fn data_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/vdb")
}

fn manifest() -> Value {
    let text = std::fs::read_to_string(data_dir().join("manifest.json")).expect("manifest");
    serde_json::from_str(&text).expect("manifest json")
}

fn ints(v: &Value) -> [i64; 3] {
    std::array::from_fn(|a| v[a].as_i64().expect("int"))
}

fn floats(v: &Value) -> [f64; 3] {
    std::array::from_fn(|a| v[a].as_f64().expect("float"))
}

fn sidecar(file: &str, grid: &str) -> Vec<f32> {
    let bytes = std::fs::read(data_dir().join(format!("{file}.{grid}.f32"))).expect("sidecar");
    bytes
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect()
}

/// Every grid with a sidecar reads back the values python wrote: bit-exact for float
/// grids, and exactly the IEEE half rounding for half-float grids.
#[test]
fn values_match_what_python_openvdb_wrote() {
    let m = manifest();
    let mut checked_half = false;
    let mut checked_negative_origin = false;
    let mut checked_anisotropic = false;
    for file in ["blender_fire.vdb", "houdini_pyro.vdb", "test/aniso.vdb"] {
        let f = VdbFile::open(data_dir().join(file)).expect("open fixture");
        for rec in m[file].as_array().expect("records") {
            let name = rec["grid"].as_str().expect("grid name");
            let lo = ints(&rec["dense_min"]);
            let dims = ints(&rec["dense_dims"]);
            let bbox = IndexBox {
                min: lo.map(|v| v as i32),
                max: std::array::from_fn(|a| (lo[a] + dims[a] - 1) as i32),
            };
            let expected = sidecar(file, name);
            let info = f.grid(name).expect("grid listed").clone();
            let half = rec["half_float"].as_bool().expect("flag");
            assert_eq!(info.half_float, half, "{file}:{name} half flag");
            let got: Vec<f32> = if rec["components"].as_i64() == Some(3) {
                assert_eq!(info.kind, ValueKind::Vec3s);
                let v = f.read_vec3(name, bbox, TEST_CAP_BYTES).expect("read vec3");
                v.values.iter().flat_map(|x| x.iter().copied()).collect()
            } else {
                assert_eq!(info.kind, ValueKind::Float);
                f.read_scalar(name, bbox, TEST_CAP_BYTES)
                    .expect("read")
                    .values
            };
            assert_eq!(got.len(), expected.len(), "{file}:{name} length");
            let mut rounded = 0usize;
            for (i, (&g, &e)) in got.iter().zip(expected.iter()).enumerate() {
                let want = if half {
                    half::f16::from_f32(e).to_f32()
                } else {
                    e
                };
                // Exact (== also equates the -0.0 python wrote with the +0.0 background).
                assert!(g == want, "{file}:{name} value #{i}: {g} vs {want}");
                rounded += usize::from(g != e);
            }
            if half {
                assert!(
                    rounded > 0,
                    "{file}:{name}: half storage must round some values"
                );
                checked_half = true;
            }
            // Active voxels are exactly the non-background (non-zero) values python wrote.
            let comps = if rec["components"].as_i64() == Some(3) {
                3
            } else {
                1
            };
            let nonzero = expected
                .chunks_exact(comps)
                .filter(|c| c.iter().any(|&v| v != 0.0))
                .count() as u64;
            assert_eq!(
                info.active_voxel_count, nonzero,
                "{file}:{name} active count"
            );

            // World positions of voxels follow the file's transform.
            let h = floats(&rec["voxel_size"]);
            let origin = floats(&rec["origin"]);
            for (got, want) in info.voxel_size.iter().zip(h) {
                assert!((got - want).abs() < 1e-12, "{file}:{name} voxel size");
            }
            assert!(info.is_linear);
            for ijk in [bbox.min, bbox.max, [bbox.min[0], bbox.max[1], bbox.min[2]]] {
                let w = info.transform.index_to_world(ijk.map(f64::from));
                for a in 0..3 {
                    let want = origin[a] + h[a] * f64::from(ijk[a]);
                    assert!(
                        (w[a] - want).abs() < 1e-12,
                        "{file}:{name} world {w:?} at {ijk:?}"
                    );
                }
            }
            checked_negative_origin |= lo.iter().any(|&v| v < 0);
            checked_anisotropic |= h[0] != h[1];
        }
    }
    assert!(checked_half && checked_negative_origin && checked_anisotropic);
}

#[test]
fn file_and_grid_metadata_are_listed() {
    let f = VdbFile::open(data_dir().join("blender_fire.vdb")).expect("open");
    let mut names: Vec<&str> = f.grids().iter().map(|g| g.name.as_str()).collect();
    names.sort_unstable();
    assert_eq!(names, ["density", "flame", "temperature"]);
    let creator = f
        .metadata()
        .iter()
        .find(|m| m.key == "creator")
        .expect("creator");
    assert_eq!(creator.value.to_string(), "Blender (grin example)");
    let t = f.grid("temperature").expect("grid");
    assert_eq!(t.grid_class, "fog volume");
    assert!(t.metadata.iter().any(|m| m.key == "blender/source"));
    let (lo, hi) = t.value_range.expect("range");
    assert!(lo > 0.0 && hi <= 2.0 && hi > 1.5, "{lo}..{hi}");
}

#[test]
fn bad_files_give_clear_errors() {
    let dir = std::env::temp_dir().join(format!("vdb-sys-bad-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");

    let e = VdbFile::open(dir.join("missing.vdb")).expect_err("missing");
    assert!(matches!(e, VdbError::Missing { .. }), "{e}");
    assert!(e.to_string().ends_with("no such file"));

    let empty = dir.join("empty.vdb");
    std::fs::write(&empty, b"").expect("write");
    let e = VdbFile::open(&empty).expect_err("empty");
    assert!(matches!(e, VdbError::Open { .. }), "{e}");

    let good = std::fs::read(data_dir().join("houdini_pyro.vdb")).expect("fixture");
    let trunc = dir.join("trunc.vdb");
    std::fs::write(&trunc, &good[..good.len() / 2]).expect("write");
    let e = VdbFile::open(&trunc).expect_err("truncated");
    assert!(e.to_string().contains("trunc.vdb"), "{e}");

    let junk = dir.join("junk.vdb");
    let bytes: Vec<u8> = (0u32..4096)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
        .collect();
    std::fs::write(&junk, bytes).expect("write");
    let e = VdbFile::open(&junk).expect_err("random bytes");
    assert!(e.to_string().contains("not a readable OpenVDB file"), "{e}");
    std::fs::remove_dir_all(&dir).ok();

    let f = VdbFile::open(data_dir().join("houdini_pyro.vdb")).expect("open");
    let e = f.grid("density").expect_err("no such grid");
    assert!(
        e.to_string()
            .contains("available grids: temperature (float), vel (vec3s)"),
        "{e}"
    );
    let bbox = f.grid("vel").expect("vel").active_bbox.expect("bbox");
    let e = f
        .read_scalar("vel", bbox, TEST_CAP_BYTES)
        .expect_err("wrong type");
    assert!(matches!(e, VdbError::WrongType { .. }), "{e}");

    let f = VdbFile::open(data_dir().join("test/nonfinite.vdb")).expect("open");
    assert_eq!(f.grid("temperature").expect("grid").non_finite_count, 4);

    let f = VdbFile::open(data_dir().join("test/empty_grid.vdb")).expect("open");
    let g = f.grid("temperature").expect("grid");
    assert_eq!((g.active_bbox, g.active_voxel_count), (None, 0));

    let f = VdbFile::open(data_dir().join("test/huge_bbox.vdb")).expect("open");
    let g = f.grid("temperature").expect("grid");
    let e = f
        .read_scalar("temperature", g.active_bbox.expect("bbox"), TEST_CAP_BYTES)
        .expect_err("too large");
    assert!(matches!(e, VdbError::TooLarge { .. }), "{e}");
    assert!(e.to_string().contains("memory cap"), "{e}");

    let f = VdbFile::open(data_dir().join("test/frustum.vdb")).expect("open");
    let g = f.grid("temperature").expect("grid");
    assert!(!g.is_linear);
    assert!(g.map_type.contains("Frustum"), "{}", g.map_type);
}
