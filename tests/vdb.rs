//! End-to-end tests of the VDB pipeline: `grin info file.vdb`, `grin bake` of a
//! `kind = "vdb"` scene (and its clear refusals of bad input), and a ray traced through a
//! VDB-sourced field against the analytic field the VDB sampled.
//!
//! Over 600 lines: one concept, the VDB pipeline end to end, through the binary.

use common::rng::Rng;
use common::{
    Row, assert_failed, assert_ok, bake_with, exr_channels, gpu_or_skip, grin, grin_args as run,
    json, num, read_table, run_ok, stderr, stdout,
};
use grin_testkit as common;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use glam::DVec3;
use grin_field::vdb::{DEFAULT_MAX_DENSE_BYTES, Mapping, VdbField, VdbFieldParams};
use grin_field::{Bounds, FieldSample, IndexField};
use grin_render::settings::TraceSettings;
use grin_scene::{ExitMethod, IntegratorKind, NonFinitePolicy, StepSpec};
use grin_trace::{RayStatus, trace_ray};

fn data(rel: &str) -> PathBuf {
    common::data(&format!("vdb/{rel}"))
}

/// Write the OpenVDB python `script` to `dir/make.py` and run it with `arg` as its one
/// argument (where it writes): how these tests make VDB files with another tool than
/// grin's own writer. The script has `sys`, `numpy as np` and `pyopenvdb as vdb`
/// imported. Fails the test with python's stderr when the script fails.
fn run_openvdb_python(dir: &Path, script: &str, arg: &Path) {
    let path = dir.join("make.py");
    let script = format!("import sys\nimport numpy as np\nimport pyopenvdb as vdb\n{script}");
    std::fs::write(&path, script).expect("script");
    let made = Command::new("/usr/bin/python3")
        .arg(&path)
        .arg(arg)
        .output()
        .expect("python3-openvdb (installed by scripts/setup.sh)");
    assert_ok(&made);
}

/// `dir/file`: one float grid `name` of voxel size `voxel`, its voxels set by the
/// OpenVDB python `lines` (on the grid `g`), written with [`run_openvdb_python`].
fn float_grid_file(dir: &Path, file: &str, name: &str, voxel: f64, lines: &[&str]) -> PathBuf {
    let path = dir.join(file);
    let body = lines.join("\n");
    let script = format!(
        "g = vdb.FloatGrid()\ng.name = \"{name}\"\n{body}\n\
         g.transform = vdb.createLinearTransform(voxelSize={voxel})\n\
         vdb.write(sys.argv[1], grids=[g])\n"
    );
    run_openvdb_python(dir, &script, &path);
    path
}

/// The command failed with one clear stderr line containing `needle`, and wrote nothing.
fn fails_cleanly(out: &Output, needle: &str, output_file: Option<&Path>) {
    let stderr = assert_failed(out);
    assert!(out.status.code().is_some(), "killed by a signal: {stderr}");
    let lines: Vec<&str> = stderr.lines().filter(|l| !l.trim().is_empty()).collect();
    let last = lines.last().copied().unwrap_or("");
    assert!(last.starts_with("grin: error:"), "stderr: {stderr}");
    assert!(last.contains(needle), "expected `{needle}` in: {last}");
    if let Some(p) = output_file {
        assert!(!p.exists(), "{} must not be written", p.display());
        let dir = p.parent().expect("parent");
        let leftovers: Vec<_> = std::fs::read_dir(dir)
            .expect("dir")
            .filter_map(Result::ok)
            .filter(|e| {
                e.path()
                    .extension()
                    .is_some_and(|x| x != "toml" && x != "vdb")
            })
            .collect();
        assert!(leftovers.is_empty(), "temporary files left: {leftovers:?}");
    }
}

#[test]
fn info_lists_grids_with_transform_and_half_flag() {
    let out = run(&[
        "info",
        data("blender_fire.vdb").to_str().expect("utf8"),
        "--json",
    ]);
    let v = json(&out);
    assert_eq!(v["metadata"]["creator"], "Blender (grin example)");
    let grids = v["grids"].as_array().expect("grids");
    let mut names: Vec<&str> = grids.iter().filter_map(|g| g["name"].as_str()).collect();
    names.sort_unstable();
    assert_eq!(names, ["density", "flame", "temperature"]);
    for g in grids {
        assert_eq!(g["half_float"], true);
        assert_eq!(g["value_type"], "float");
        assert_eq!(g["class"], "fog volume");
        let h = g["voxel_size"][0].as_f64().expect("voxel size");
        assert!((h - 0.05).abs() < 1e-12);
        // world = 0.05 * ijk + (-0.6, -0.1, -0.6)
        let m = &g["world_from_index"];
        assert!((m[0][3].as_f64().expect("t") + 0.6).abs() < 1e-12);
        assert!((m[1][3].as_f64().expect("t") + 0.1).abs() < 1e-12);
        let bmin = g["active_bbox"]["min"][1].as_f64().expect("bbox");
        let wmin = g["world_bbox"]["min"][1].as_f64().expect("world bbox");
        assert!((wmin - (-0.1 + 0.05 * bmin)).abs() < 1e-9);
        assert!(g["active_voxel_count"].as_u64().expect("count") > 0);
    }

    // The text form names each grid and flags half floats.
    let out = run(&["info", data("houdini_pyro.vdb").to_str().expect("utf8")]);
    assert_ok(&out);
    let text = stdout(&out);
    assert!(text.contains("grid `vel`: vec3s"), "{text}");
    assert!(text.contains("grid `temperature`: float"), "{text}");

    let out = run(&["info", data("test/nonfinite.vdb").to_str().expect("utf8")]);
    assert!(stdout(&out).contains("NaN/Inf voxels: 4"));
}

#[test]
fn info_refuses_bad_files_clearly() {
    let dir = tempfile::tempdir().expect("tempdir");
    let good = std::fs::read(data("houdini_pyro.vdb")).expect("fixture");
    let cases: [(&str, Vec<u8>, &str); 3] = [
        ("empty.vdb", Vec::new(), "the file is empty"),
        (
            "truncated.vdb",
            good[..good.len() / 3].to_vec(),
            "truncated or corrupt",
        ),
        (
            "random.vdb",
            (0u32..8192)
                .map(|i| (i.wrapping_mul(2_654_435_761) >> 11) as u8)
                .collect(),
            "not a readable OpenVDB file",
        ),
    ];
    for (name, bytes, needle) in cases {
        let p = dir.path().join(name);
        std::fs::write(&p, bytes).expect("write");
        fails_cleanly(&run(&["info", p.to_str().expect("utf8")]), needle, None);
    }
    let missing = dir.path().join("missing.vdb");
    fails_cleanly(
        &run(&["info", missing.to_str().expect("utf8")]),
        "No such file",
        None,
    );
}

/// A scene over `vdb` (absolute path) with the given field options.
fn vdb_scene(dir: &Path, vdb: &Path, grid: &str, map: &str, extra: &str, ambient: f64) -> PathBuf {
    let text = format!(
        r#"
[camera]
position = [0.0, 0.5, -3.0]
look_at = [0.0, 0.5, 0.0]
fov_y_deg = 40.0

[medium]
bounds = {{ box = {{ min = [-0.6, -0.1, -0.6], max = [0.6, 1.0, 0.6] }} }}
ambient_index = {ambient}
field = {{ kind = "vdb", path = "{}", grid = "{grid}", map = {map} {extra} }}

[render]
width = 8
height = 8
"#,
        vdb.display()
    );
    let p = dir.join(format!("scene-{grid}-{}.toml", std::process::id()));
    std::fs::write(&p, text).expect("scene");
    p
}

/// A VDB field's parameters: `mapping` of the grid's values in world units, non-finite
/// values refused, ambient 1, within `bounds` and under `max_bytes`, placed as the file
/// says.
fn field_params(mapping: Mapping, bounds: Bounds, max_bytes: u64) -> VdbFieldParams {
    VdbFieldParams {
        mapping,
        units: 1.0,
        non_finite: NonFinitePolicy::Reject,
        bounds,
        ambient: Some(1.0),
        max_bytes,
        placement: grin_field::vdb::IDENTITY,
    }
}

const GD: &str = "{ gladstone-dale = {} }";
/// n of air at 293.15 K, 101325 Pa (what GD maps the background to).
const N_AIR_20C: f64 = 1.000_272_131;

/// A quick bake: `--resolution 24 --error 0.5`.
fn bake(scene: &Path, out: &Path) -> Output {
    bake_with(scene, out, &["--resolution", "24", "--error", "0.5"])
}

#[test]
fn bake_of_the_example_vdb_scene_succeeds() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out_file = dir.path().join("fire.grinf");
    let out = bake_with(
        &data("fire-haze.toml"),
        &out_file,
        &["--resolution", "32", "--error", "0.2", "--json"],
    );
    assert_ok(&out);
    assert!(out_file.exists());
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("json summary");
    assert!(v.is_object(), "{v}");

    // --max-memory also caps what is read of the VDB grid (its data box, a voxel a byte of
    // the cap): refused before reading, with the cap named, and no output file.
    let sub = dir.path().join("capped");
    std::fs::create_dir(&sub).expect("subdir");
    let capped = sub.join("capped.grinf");
    let out = bake_with(&data("fire-haze.toml"), &capped, &["--max-memory", "1k"]);
    fails_cleanly(&out, "data box", Some(&capped));
    assert!(
        stderr(&out).contains("memory cap of 1024 bytes"),
        "{}",
        stderr(&out)
    );
}

#[test]
fn bake_refuses_bad_vdb_input_with_clear_errors() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let out = d.join("out.grinf");
    let blender = data("blender_fire.vdb");

    // A scene over `vdb`'s `grid` (Gladstone-Dale, air's ambient) whose bake is refused
    // with `needle`, writing nothing.
    let refused = |vdb: &Path, grid: &str, needle: &str| {
        let s = vdb_scene(d, vdb, grid, GD, "", N_AIR_20C);
        let o = bake(&s, &out);
        fails_cleanly(&o, needle, Some(&out));
        o
    };
    let e = refused(
        &blender,
        "smoke",
        "grid `smoke` not found; available grids:",
    );
    assert!(stderr(&e).contains("temperature (float)"));
    refused(&data("houdini_pyro.vdb"), "vel", "has value type `vec3s`");

    let nf = data("test/nonfinite.vdb");
    refused(&nf, "temperature", "4 NaN/Inf voxel(s)");
    let s = vdb_scene(
        d,
        &nf,
        "temperature",
        GD,
        r#", non_finite = "ambient""#,
        N_AIR_20C,
    );
    let ok = bake(&s, &out);
    assert_ok(&ok);
    let report = stdout(&ok);
    assert!(
        report.contains("4 NaN/Inf voxels replaced by ambient"),
        "{report}"
    );
    std::fs::remove_file(&out).expect("remove");

    for (file, needle) in [
        ("test/empty_grid.vdb", "the grid is empty"),
        ("test/huge_bbox.vdb", "more than the memory cap"),
        ("test/frustum.vdb", "non-linear transform"),
    ] {
        refused(&data(file), "temperature", needle);
    }
    refused(&d.join("nope.vdb"), "temperature", "no such file");

    let truncated = d.join("truncated.vdb");
    let bytes = std::fs::read(&blender).expect("fixture");
    std::fs::write(&truncated, &bytes[..bytes.len() - 1000]).expect("write");
    refused(&truncated, "temperature", "truncated or corrupt");

    let empty = d.join("empty.vdb");
    std::fs::write(&empty, b"").expect("write");
    refused(&empty, "temperature", "the file is empty");

    let random = d.join("random.vdb");
    let junk: Vec<u8> = (0u32..4096)
        .map(|i| (i.wrapping_mul(2_246_822_519) >> 9) as u8)
        .collect();
    std::fs::write(&random, junk).expect("write");
    refused(&random, "temperature", "not a readable OpenVDB file");

    // Gladstone-Dale background (air at 20 C) against a vacuum ambient index.
    let s = vdb_scene(d, &blender, "temperature", GD, "", 1.0);
    fails_cleanly(
        &bake(&s, &out),
        "set [medium] ambient_index = 1.000272",
        Some(&out),
    );
}

/// delta_n = A exp(-|p - c|^2 / s^2): the field scripts/make_vdb_data.py sampled into
/// data/vdb/test/gaussian.vdb (parameters read from data/vdb/manifest.json).
#[derive(Debug)]
struct Gaussian {
    a: f64,
    s: f64,
    c: DVec3,
    bounds: Bounds,
}

impl IndexField for Gaussian {
    fn sample(&self, p: DVec3) -> FieldSample<f64> {
        let r = p - self.c;
        let e = self.a * (-r.length_squared() / (self.s * self.s)).exp();
        FieldSample {
            n: 1.0 + e,
            grad_n: r * (-2.0 * e / (self.s * self.s)),
        }
    }
    fn bounds(&self) -> Bounds {
        self.bounds
    }
    fn ambient_index(&self) -> f64 {
        1.0
    }
    fn n_range(&self) -> (f64, f64) {
        (1.0, 1.0 + self.a)
    }
    fn max_grad_n(&self) -> f64 {
        self.a * (2.0f64).sqrt() / self.s * (-0.5f64).exp()
    }
    fn describe(&self) -> String {
        "gaussian".into()
    }
}

/// Max interpolation error of the VDB field against the analytic one, relative to A:
/// tricubic Catmull-Rom at 10 voxels per Gaussian width s (measured 1.2e-4 of A in n and
/// 6.6e-3 of max |grad n| in grad n; see the vdb module docs), plus the f32 storage.
const N_ERR_REL: f64 = 5e-4;
const GRAD_ERR_REL: f64 = 2e-2;
/// Ray exit direction agreement, relative to the ray's total bend: the direction error is
/// the gradient error integrated along the path, so it is of the order of GRAD_ERR_REL
/// times the bend (measured 0.25 %).
const RAY_DIR_REL: f64 = 1e-2;
/// Exit position agreement relative to (bend x path length in the medium).
const RAY_POS_REL: f64 = 1e-2;

#[test]
fn ray_through_vdb_field_matches_the_analytic_field_it_sampled() {
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(data("manifest.json")).expect("manifest"))
            .expect("json");
    let g = &manifest["test/gaussian.vdb"];
    let c = DVec3::new(
        g["center"][0].as_f64().expect("c"),
        g["center"][1].as_f64().expect("c"),
        g["center"][2].as_f64().expect("c"),
    );
    let h = g["voxel_size"].as_f64().expect("h");
    let half_cells = g["half_cells"].as_f64().expect("cells");
    let bounds = Bounds::Sphere {
        center: c,
        radius: h * (half_cells - 2.0),
    };
    let exact = Gaussian {
        a: g["a"].as_f64().expect("a"),
        s: g["s"].as_f64().expect("s"),
        c,
        bounds,
    };
    let params = field_params(
        Mapping::Index { delta: true },
        bounds,
        DEFAULT_MAX_DENSE_BYTES,
    );
    let vdb = VdbField::load(&data("test/gaussian.vdb"), "delta_n", &params).expect("load");

    // Point samples: n and grad n (deterministic pseudo-random points in the ball).
    let mut rng = Rng(0x1234_5678_9abc_def0);
    let mut rnd = || rng.range_f64(-1.0, 1.0);
    let (mut max_dn, mut max_dg) = (0.0f64, 0.0f64);
    for _ in 0..2000 {
        let p = c + DVec3::new(rnd(), rnd(), rnd()) * 0.4;
        let (a, b) = (vdb.sample(p), exact.sample(p));
        max_dn = max_dn.max((a.n - b.n).abs());
        max_dg = max_dg.max((a.grad_n - b.grad_n).length());
    }
    eprintln!(
        "gaussian.vdb: max |n error| = {max_dn:.3e} ({:.2e} of A), max |grad n error| = {max_dg:.3e} ({:.2e} of max |grad n|)",
        max_dn / exact.a,
        max_dg / exact.max_grad_n()
    );
    assert!(max_dn < N_ERR_REL * exact.a, "n error {max_dn}");
    assert!(
        max_dg < GRAD_ERR_REL * exact.max_grad_n(),
        "grad n error {max_dg}"
    );

    let settings = TraceSettings {
        integrator: IntegratorKind::Rk4,
        step: StepSpec::Fixed(0.005),
        max_steps: 100_000,
        exit: ExitMethod::Hermite,
        macro_cells: false,
        accuracy: grin_scene::DEFAULT_AUTO_ACCURACY,
        estimate_limit: grin_scene::DEFAULT_AUTO_ACCURACY,
        opl_control: false,
    };
    let (mut max_dp, mut max_dd, mut max_bend) = (0.0f64, 0.0f64, 0.0f64);
    for k in 0..7 {
        let offset = -0.3 + 0.1 * f64::from(k);
        let origin = c + DVec3::new(offset, 0.5 * offset, -2.0);
        let dir = DVec3::new(0.05, -0.02, 1.0);
        let a = trace_ray::<f64>(&vdb, &settings, origin, dir);
        let b = trace_ray::<f64>(&exact, &settings, origin, dir);
        assert_eq!((a.status, b.status), (RayStatus::Exited, RayStatus::Exited));
        max_dp = max_dp.max((a.position - b.position).length());
        max_dd = max_dd.max((a.direction - b.direction).length());
        max_bend = max_bend.max(b.direction.angle_between(dir.normalize()));
    }
    eprintln!(
        "rays: max exit position difference {max_dp:.3e} m, direction {max_dd:.3e} rad; max bend {max_bend:.3e} rad"
    );
    // The comparison means something: the rays bend by several degrees.
    assert!(max_bend > 0.05, "bend {max_bend}");
    assert!(
        max_dd < RAY_DIR_REL * max_bend,
        "exit direction differs by {max_dd}"
    );
    let path_len = 2.0 * bounds.radius();
    assert!(
        max_dp < RAY_POS_REL * max_bend * path_len,
        "exit position differs by {max_dp}"
    );
}

#[test]
fn export_writes_delta_n_and_grad_n_that_read_back_exactly() {
    let dir = tempfile::tempdir().expect("tempdir");
    let baked = dir.path().join("fire.grinf");
    let out = bake_with(
        &data("fire-haze.toml"),
        &baked,
        &["--resolution", "20", "--error", "0.5"],
    );
    assert_ok(&out);
    let vdb_path = dir.path().join("fire.vdb");
    let out = run(&[
        "export",
        baked.to_str().expect("utf8"),
        "-o",
        vdb_path.to_str().expect("utf8"),
        "--json",
    ]);
    let summary = json(&out);
    assert_eq!(summary["grids"][0], "delta_n");

    let field = grin_field::grinf::load(&baked).expect("load baked");
    let geo = *field.geometry();
    let file = vdb_sys::VdbFile::open(&vdb_path).expect("open export");
    let bbox = vdb_sys::IndexBox {
        min: [0, 0, 0],
        max: geo.dims.map(|d| d as i32 - 1),
    };
    let dn = file.read_scalar("delta_n", bbox, 1 << 28).expect("delta_n");
    let gn = file.read_vec3("grad_n", bbox, 1 << 28).expect("grad_n");
    let info = file.grid("delta_n").expect("grid");
    let ambient = info
        .metadata
        .iter()
        .find(|m| m.key == "n_ambient")
        .expect("n_ambient metadata");
    assert_eq!(
        ambient.value,
        vdb_sys::MetaValue::Number(field.ambient_index())
    );
    let mut nonzero = 0;
    for k in 0..geo.dims[2] {
        for j in 0..geo.dims[1] {
            for i in 0..geo.dims[0] {
                let v = field.voxels().get(geo.index(i, j, k));
                let ijk = [i as i32, j as i32, k as i32];
                assert_eq!(dn.get(ijk), Some(v[0]), "delta_n at {ijk:?}");
                assert_eq!(gn.get(ijk), Some([v[1], v[2], v[3]]), "grad_n at {ijk:?}");
                nonzero += usize::from(v[0] != 0.0);
                // Voxel centres sit where the baked nodes are.
                let w = info
                    .transform
                    .index_to_world([i as f64, j as f64, k as f64]);
                let node = geo.node_world(i, j, k);
                assert!((DVec3::from_array(w) - node).length() < 1e-12);
            }
        }
    }
    assert!(
        nonzero > 100,
        "the plume must be in the export ({nonzero} voxels)"
    );

    // Bad input: no output file.
    let missing = dir.path().join("missing.grinf");
    let bad_out = dir.path().join("bad.vdb");
    let out = run(&[
        "export",
        missing.to_str().expect("utf8"),
        "-o",
        bad_out.to_str().expect("utf8"),
    ]);
    fails_cleanly(&out, "missing.grinf", None);
    assert!(!bad_out.exists());
    let no_dir = dir.path().join("no/such/dir/out.vdb");
    let out = run(&[
        "export",
        baked.to_str().expect("utf8"),
        "-o",
        no_dir.to_str().expect("utf8"),
    ]);
    fails_cleanly(&out, "cannot write", None);
}

/// The mapped field puts each voxel's value at the world position the file's transform
/// (non-uniform voxel size, negative index origin) and `units` give it.
#[test]
fn vdb_field_places_voxels_at_their_world_positions() {
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(data("manifest.json")).expect("manifest"))
            .expect("json");
    let rec = &manifest["test/aniso.vdb"][0];
    let f3 = |v: &serde_json::Value| -> [f64; 3] {
        std::array::from_fn(|a| v[a].as_f64().expect("number"))
    };
    let (h, origin) = (f3(&rec["voxel_size"]), f3(&rec["origin"]));
    let lo = f3(&rec["dense_min"]);
    let dims = f3(&rec["dense_dims"]);
    let bytes = std::fs::read(data("test/aniso.vdb.value.f32")).expect("sidecar");
    let values: Vec<f32> = bytes
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    let (k, units) = (1e-3, 3.0);
    let params = VdbFieldParams {
        units,
        ..field_params(
            Mapping::Linear { k },
            Bounds::Sphere {
                center: DVec3::ZERO,
                radius: 10.0,
            },
            DEFAULT_MAX_DENSE_BYTES,
        )
    };
    let field = VdbField::load(&data("test/aniso.vdb"), "value", &params).expect("load");
    let nx = dims[0] as usize;
    let ny = dims[1] as usize;
    for (off, &v) in values.iter().enumerate() {
        let ijk = [
            (off % nx) as f64 + lo[0],
            ((off / nx) % ny) as f64 + lo[1],
            (off / (nx * ny)) as f64 + lo[2],
        ];
        let world = DVec3::from_array(std::array::from_fn(|a| units * (origin[a] + h[a] * ijk[a])));
        let n = field.sample(world).n;
        assert!(
            (n - (1.0 + k * f64::from(v))).abs() < 1e-12,
            "voxel {ijk:?} at {world}: n = {n}, value {v}"
        );
    }
    // Half a voxel off along x the value is no longer the voxel's (the placement matters).
    let world = DVec3::from_array(std::array::from_fn(|a| {
        units * (origin[a] + h[a] * (lo[a] + 1.0) + if a == 0 { 0.5 * h[0] } else { 0.0 })
    }));
    let at_node = 1.0 + k * f64::from(values[1 + nx * (1 + ny)]);
    assert!((field.sample(world).n - at_node).abs() > 1e-6);
}

/// File -> Gladstone-Dale map -> tracer: a ray through a uniform 1000 K block of a VDB
/// temperature grid has optical path / length = n(1000 K), and n - 1 matches the
/// table in docs/physics.md, Air (0.80e-4 at 1000 K).
#[test]
fn trace_through_a_uniform_hot_block_reads_the_gladstone_dale_index() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (t_amb, scale) = (293.15, 300.0);
    let value = ((1000.0 - t_amb) / scale) as f32;
    let half = 10;
    let bbox = vdb_sys::IndexBox {
        min: [-half; 3],
        max: [half; 3],
    };
    let count = (2 * half + 1).pow(3) as usize;
    let grid = vdb_sys::DenseGrid {
        bbox,
        world_from_index: vdb_sys::Transform::uniform(0.05, [0.0; 3]),
        values: vec![value; count],
    };
    let vdb_path = dir.path().join("block.vdb");
    let mut w = vdb_sys::VdbWriter::new().expect("writer");
    w.add_float("temperature", &grid, &vdb_sys::WriteOptions::default())
        .expect("add");
    w.write(&vdb_path).expect("write");

    // Medium: a box 4 voxels inside the data, where the interpolant is exactly uniform.
    let scene = dir.path().join("block.toml");
    std::fs::write(
        &scene,
        format!(
            r#"
[camera]
position = [0.0, 0.0, -3.0]
look_at = [0.0, 0.0, 0.0]
fov_y_deg = 40.0

[medium]
bounds = {{ box = {{ min = [-0.3, -0.3, -0.3], max = [0.3, 0.3, 0.3] }} }}
ambient_index = {N_AIR_20C}
field = {{ kind = "vdb", path = "block.vdb", grid = "temperature", map = {{ gladstone-dale = {{ ambient_temperature_k = {t_amb}, scale_k = {scale} }} }} }}

[render]
width = 8
height = 8
integrator = "rk4"
step = {{ fixed = 0.01 }}
"#
        ),
    )
    .expect("scene");
    let rays = dir.path().join("rays.csv");
    std::fs::write(&rays, "ox,oy,oz,dx,dy,dz\n0.05,-0.1,-2,0,0,1\n").expect("rays");
    let traced = dir.path().join("out.csv");
    let out = run(&[
        "trace",
        scene.to_str().expect("utf8"),
        "--rays",
        rays.to_str().expect("utf8"),
        "-o",
        traced.to_str().expect("utf8"),
    ]);
    assert_ok(&out);
    let rows = read_table(&traced);
    let row = &rows[0];
    let col = |name: &str| num(row, name);
    assert_eq!(row["status"], "exited");
    let (opl, length) = (col("opl"), col("length"));
    assert!((length - 0.6).abs() < 1e-9, "length {length}");
    let n = opl / length;
    // The grid stores the value as f32; the exact map of that value:
    let t_k = t_amb + scale * f64::from(value);
    // The scene's ambient (9 digits) is taken as the background's index: the data moves
    // by the difference (data/vdb/README.md, "Ambient").
    let n_background = 1.0 + 2.26e-4 * 101_325.0 / (287.05 * t_amb);
    let n_exact = 1.0 + 2.26e-4 * 101_325.0 / (287.05 * t_k) + (N_AIR_20C - n_background);
    assert!((n - n_exact).abs() < 1e-12, "n {n} vs {n_exact}");
    assert!(
        (n - 1.0 - 0.80e-4).abs() < 0.005e-4,
        "n - 1 = {:e}",
        n - 1.0
    );
}

/// A file that makes OpenVDB abort (a bit flip found by fuzzing, data/vdb/test/
/// crash_abort.vdb) is read in a child process: grin itself re-run as the checker. A copy
/// of grin outside its build tree (an installed grin) keeps that isolation.
#[test]
fn an_installed_grin_still_isolates_a_crashing_vdb() {
    let crash = data("test/crash_abort.vdb");
    // The file really aborts OpenVDB in-process: the checker entry dies by a signal.
    let out = grin()
        .args([
            vdb_sys::CHECK_ARG,
            crash.to_str().expect("utf-8"),
            "268435456",
        ])
        .output()
        .expect("run the checker");
    assert_eq!(
        out.status.code(),
        None,
        "the fixture no longer crashes OpenVDB"
    );
    let dir = tempfile::tempdir().expect("tmp");
    let installed = dir.path().join("grin");
    std::fs::copy(env!("CARGO_BIN_EXE_grin"), &installed).expect("install");
    for args in [vec!["info"], vec!["info", "--json"]] {
        let out = Command::new(&installed)
            .args(&args)
            .arg(&crash)
            .output()
            .expect("run installed grin");
        fails_cleanly(&out, "OpenVDB crashed while reading it (signal 6)", None);
    }
    let out = Command::new(&installed)
        .args(["info"])
        .arg(data("test/aniso.vdb"))
        .output()
        .expect("run installed grin");
    assert_ok(&out);
}

/// Four frames of a hot blob rising, written by OpenVDB's own Python API (half floats,
/// voxel size 0.04, two grids), rendered as a sequence with `--frames` (on the CPU, which
/// samples the VDB field itself: the GPU would bake each frame): each frame equals a
/// single render of that frame's scene, a missing frame is named before anything is
/// rendered, and a frame pattern without --frames is a clear error.
#[test]
fn a_vdb_sequence_renders_frame_by_frame() {
    let dir = tempfile::tempdir().expect("tempdir");
    run_openvdb_python(
        dir.path(),
        r#"
out = sys.argv[1]
n = 24
ax = (np.arange(n) - n / 2 + 0.5) * 0.04
x, y, z = np.meshgrid(ax, ax, ax, indexing="ij")
for frame in range(1, 5):
    cy = -0.2 + 0.1 * frame
    hot = -0.01 * np.exp(-(x**2 + (y - cy) ** 2 + z**2) / 0.12**2)
    t = vdb.FloatGrid()
    t.name = "delta_n"
    t.copyFromArray(hot.astype(np.float32), ijk=(-12, -12, -12), tolerance=1e-4)
    t.transform = vdb.createLinearTransform(voxelSize=0.04)
    t.saveFloatAsHalf = True
    d = vdb.FloatGrid()
    d.name = "density"
    d.copyFromArray((hot < -0.005).astype(np.float32), ijk=(-12, -12, -12), tolerance=0)
    d.transform = vdb.createLinearTransform(voxelSize=0.04)
    vdb.write(f"{out}/blob_{frame:04d}.vdb", grids=[d, t])
"#,
        dir.path(),
    );
    let scene = |path: &str, name: &str| {
        let text = format!(
            r#"
[camera]
position = [0.0, 0.0, -2.0]
look_at = [0.0, 0.0, 0.0]
fov_y_deg = 30.0
[[object]]
shape = {{ plane = {{ point = [0.0, 0.0, 1.0], normal = [0.0, 0.0, -1.0] }} }}
material = {{ checker = {{ color_a = [0.9, 0.9, 0.9], color_b = [0.1, 0.1, 0.1], scale = 0.05 }} }}
[medium]
bounds = {{ box = {{ min = [-0.45, -0.45, -0.45], max = [0.45, 0.45, 0.45] }} }}
ambient_index = 1.0
field = {{ kind = "vdb", path = "{path}", grid = "delta_n", map = {{ index = {{ delta = true }} }} }}
[render]
width = 40
height = 30
integrator = "rk4"
step = {{ fixed = 0.01 }}
jitter = false
"#
        );
        let p = dir.path().join(name);
        std::fs::write(&p, text).expect("scene");
        p
    };
    let seq = scene("blob_####.vdb", "seq.toml");
    let out = dir.path().join("out.####.exr");
    let o = run_ok(
        grin()
            .env("GRIN_CACHE_DIR", dir.path())
            .args([
                "render",
                "--backend",
                "cpu",
                "--frames",
                "1..4",
                "--json",
                "-o",
            ])
            .arg(&out)
            .arg(&seq),
    );
    let summaries = json(&o);
    assert_eq!(summaries.as_array().map(Vec::len), Some(4), "{summaries}");
    for f in 1..=4 {
        assert!(dir.path().join(format!("out.{f:04}.exr")).is_file());
    }
    // Frame 3 alone, from a scene naming its file: the same image.
    let single = scene("blob_0003.vdb", "frame3.toml");
    let o = run_ok(
        grin()
            .env("GRIN_CACHE_DIR", dir.path())
            .args(["render", "--backend", "cpu", "--json", "-o"])
            .arg(dir.path().join("single3.exr"))
            .arg("--compare")
            .arg(dir.path().join("out.0003.exr"))
            .arg(&single),
    );
    let s = json(&o);
    assert_eq!(s["comparison"]["max"].as_f64(), Some(0.0), "{s}");
    // The blob moved: frames 1 and 4 differ.
    let o = grin()
        .env("GRIN_CACHE_DIR", dir.path())
        .args(["render", "--backend", "cpu", "--json", "-o"])
        .arg(dir.path().join("single3b.exr"))
        .arg("--compare")
        .arg(dir.path().join("out.0001.exr"))
        .arg(&single)
        .output()
        .expect("grin");
    let s: serde_json::Value = serde_json::from_slice(&o.stdout).expect("json");
    assert!(s["comparison"]["max"].as_f64().expect("max") > 1e-3, "{s}");

    // On the GPU every frame is baked once: a second render of the sequence bakes
    // nothing, each frame's grid read from the bake cache (`bake_cache` per frame), and
    // the images are the first render's.
    if gpu_or_skip() {
        let cache = dir.path().join("bakes");
        let render_gpu = |pattern: &str| {
            let o = run_ok(
                grin()
                    .env("GRIN_CACHE_DIR", &cache)
                    .args([
                        "render",
                        "--backend",
                        "gpu",
                        "--frames",
                        "1..4",
                        "--json",
                        "-o",
                    ])
                    .arg(dir.path().join(pattern))
                    .arg(&seq),
            );
            let frames = json(&o);
            let used: Vec<String> = frames
                .as_array()
                .expect("one summary a frame")
                .iter()
                .map(|f| f["bake_cache"].as_str().unwrap_or("none").to_owned())
                .collect();
            used
        };
        assert_eq!(render_gpu("gpu1.####.exr"), ["stored"; 4]);
        assert_eq!(render_gpu("gpu2.####.exr"), ["hit"; 4]);
        for f in 1..=4 {
            let read = |name: &str| exr_channels(&dir.path().join(format!("{name}.{f:04}.exr")));
            assert!(read("gpu1") == read("gpu2"), "frame {f} differs");
        }
    }

    // `grin bake` of the sequence: one file a frame, each the frame's field.
    let o = run_ok(
        grin()
            .args([
                "bake",
                "--frames",
                "2..3",
                "--resolution",
                "24",
                "--error",
                "0.5",
                "--json",
                "-o",
            ])
            .arg(dir.path().join("field.####.grinf"))
            .arg(&seq),
    );
    let baked = json(&o);
    assert_eq!(baked.as_array().map(Vec::len), Some(2), "{baked}");
    let bytes = |f: &str| std::fs::read(dir.path().join(f)).expect("baked file");
    assert_ne!(bytes("field.0002.grinf"), bytes("field.0003.grinf"));

    // A missing frame is named before anything is written.
    std::fs::remove_file(dir.path().join("blob_0002.vdb")).expect("rm");
    let o = grin()
        .args(["bake", "--frames", "1..3", "-o"])
        .arg(dir.path().join("again.####.grinf"))
        .arg(&seq)
        .output()
        .expect("grin");
    fails_cleanly(&o, "frame 2:", None);
    assert!(!dir.path().join("again.0001.grinf").exists());
    let out2 = dir.path().join("again.####.exr");
    let o = grin()
        .args(["render", "--backend", "cpu", "--frames", "1..4", "-o"])
        .arg(&out2)
        .arg(&seq)
        .output()
        .expect("grin");
    fails_cleanly(&o, "frame 2:", None);
    assert!(stderr(&o).contains("blob_0002.vdb"));
    assert!(!dir.path().join("again.0001.exr").exists());

    // The pattern without --frames: what to do, not "no such file".
    let o = grin()
        .args(["render", "--backend", "cpu", "-o"])
        .arg(dir.path().join("x.exr"))
        .arg(&seq)
        .output()
        .expect("grin");
    fails_cleanly(&o, "is a frame sequence", None);
}

/// One cache written twice by OpenVDB's python API (half-float temperature, a second grid,
/// voxel size 0.04, a Gaussian plume and a sharp-edged hot block): Y-up, and Z-up as
/// Blender writes it (the same voxels, turned). Placed with `up = "z"`, the Z-up file
/// traces exactly as the Y-up one; placed with `rotate_deg` and `translate`, the Y-up one
/// traces as the same rays moved by that transform. `ambient_index` is left out: "auto",
/// the index of the background (air at 20 C). `grin info --up z` finds the data where the
/// Y-up file has it, and its `[medium]` block is a scene that traces.
#[test]
fn a_z_up_cache_placed_with_up_z_traces_as_the_y_up_one() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    run_openvdb_python(
        d,
        r#"
out = sys.argv[1]
h, n = 0.04, 26
ax = np.arange(n) * h
x, y, z = np.meshgrid(ax - 0.5, ax, ax - 0.5, indexing="ij")
plume = 1.5 * np.exp(-((x - 0.05) ** 2 + (y - 0.35) ** 2 + (z + 0.1) ** 2) / 0.12 ** 2)
block = 0.8 * ((abs(x + 0.2) < 0.1) & (abs(y - 0.7) < 0.08) & (abs(z - 0.15) < 0.1))
yup = (plume + block).astype(np.float32)
# Z-up (Blender): voxel (i, j, k) at (x, y, z) = h (i, j, k) + (-0.5, -0.5, 0) holds what
# the Y-up file has at scene (x, z, -y).
zup = np.ascontiguousarray(yup[:, :, ::-1].transpose(0, 2, 1))
def write(path, values, origin):
    m = [[h, 0, 0, 0], [0, h, 0, 0], [0, 0, h, 0], [origin[0], origin[1], origin[2], 1]]
    t = vdb.FloatGrid()
    t.name = "temperature"
    t.copyFromArray(values, ijk=(0, 0, 0), tolerance=0)
    t.transform = vdb.createLinearTransform(m)
    t.saveFloatAsHalf = True
    d = vdb.FloatGrid()
    d.name = "density"
    d.copyFromArray((values > 0.5).astype(np.float32), ijk=(0, 0, 0), tolerance=0)
    d.transform = vdb.createLinearTransform(m)
    vdb.write(path, grids=[d, t])
write(f"{out}/yup.vdb", yup, (-0.5, 0.0, -0.5))
write(f"{out}/zup.vdb", zup, (-0.5, -0.5, 0.0))
"#,
        d,
    );

    let scene = |name: &str, file: &str, bounds: &str, place: &str| {
        let text = format!(
            r#"
[camera]
position = [0.0, 0.5, -3.0]
look_at = [0.0, 0.5, 0.0]
[medium]
bounds = {{ box = {bounds} }}
field = {{ kind = "vdb", path = "{file}", grid = "temperature", map = {{ gladstone-dale = {{ scale_k = 300.0 }} }}{place} }}
[render]
integrator = "rk4"
step = {{ fixed = 0.004 }}
"#
        );
        let p = d.join(name);
        std::fs::write(&p, text).expect("scene");
        p
    };
    let held = "{ min = [-0.52, -0.02, -0.52], max = [0.52, 1.02, 0.52] }";
    let y_up = scene("yup.toml", "yup.vdb", held, "");
    let z_up = scene("zup.toml", "zup.vdb", held, ", up = \"z\"");
    let moved = scene(
        "moved.toml",
        "yup.vdb",
        "{ min = [1.48, -0.02, -0.52], max = [2.52, 1.02, 0.52] }",
        ", rotate_deg = [0.0, 90.0, 0.0], translate = [2.0, 0.0, 0.0]",
    );

    // Rays along +z and along +x through the plume and the block.
    let mut rays = vec![];
    for &x in &[-0.25, -0.15, 0.0, 0.05, 0.12] {
        for &y in &[0.3, 0.35, 0.45, 0.68, 0.75] {
            rays.push(([x, y, -1.0], [0.0, 0.0, 1.0]));
            rays.push(([-1.0, y, x], [1.0, 0.0, 0.0]));
        }
    }
    // The move: rotation by 90 degrees about +y ((x, y, z) -> (z, y, -x)), then +2 in x.
    let turn = |v: [f64; 3]| [v[2], v[1], -v[0]];
    let shift = |p: [f64; 3]| {
        let t = turn(p);
        [t[0] + 2.0, t[1], t[2]]
    };
    let table = |name: &str, rays: &[([f64; 3], [f64; 3])]| {
        let mut text = String::from("ox,oy,oz,dx,dy,dz\n");
        for (o, v) in rays {
            text += &format!("{},{},{},{},{},{}\n", o[0], o[1], o[2], v[0], v[1], v[2]);
        }
        let p = d.join(name);
        std::fs::write(&p, text).expect("rays");
        p
    };
    let plain = table("rays.csv", &rays);
    let moved_rays: Vec<_> = rays.iter().map(|(o, v)| (shift(*o), turn(*v))).collect();
    let moved_table = table("moved-rays.csv", &moved_rays);
    let trace = |scene: &Path, rays: &Path| -> Vec<Row> {
        let out_csv = d.join(format!(
            "{}.out.csv",
            scene.file_stem().expect("stem").to_string_lossy()
        ));
        let out = run(&[
            "trace",
            scene.to_str().expect("utf8"),
            "--rays",
            rays.to_str().expect("utf8"),
            "-o",
            out_csv.to_str().expect("utf8"),
        ]);
        assert_ok(&out);
        read_table(&out_csv)
    };
    let a = trace(&y_up, &plain);
    let b = trace(&z_up, &plain);
    let c = trace(&moved, &moved_table);
    assert_eq!(a.len(), rays.len());
    let mut bent = 0;
    for ((ra, rb), rc) in a.iter().zip(&b).zip(&c) {
        assert_eq!(ra["status"], "exited", "{ra:?}");
        assert_eq!(rb["status"], "exited", "{rb:?}");
        assert_eq!(rc["status"], "exited", "{rc:?}");
        let p = ["px", "py", "pz"].map(|k| num(ra, k));
        let q = ["qx", "qy", "qz"].map(|k| num(ra, k));
        for (k, v) in ["px", "py", "pz", "qx", "qy", "qz", "opl"].iter().zip(0..) {
            let _ = v;
            assert!(
                (num(ra, k) - num(rb, k)).abs() < 1e-9,
                "Z-up vs Y-up {k}: {} vs {}",
                num(ra, k),
                num(rb, k)
            );
        }
        let (pm, qm) = (shift(p), turn(q));
        for (i, k) in ["px", "py", "pz"].iter().enumerate() {
            assert!(
                (num(rc, k) - pm[i]).abs() < 1e-9,
                "moved {k}: {rc:?} vs {pm:?}"
            );
        }
        for (i, k) in ["qx", "qy", "qz"].iter().enumerate() {
            assert!(
                (num(rc, k) - qm[i]).abs() < 1e-9,
                "moved {k}: {rc:?} vs {qm:?}"
            );
        }
        let d_in = if num(ra, "dz") > 0.5 {
            [0.0, 0.0, 1.0]
        } else {
            [1.0, 0.0, 0.0]
        };
        let turned = (0..3).map(|i| (q[i] - d_in[i]).powi(2)).sum::<f64>().sqrt();
        if turned > 1e-5 {
            bent += 1;
        }
    }
    assert!(
        bent >= rays.len() / 2,
        "only {bent} of {} rays bent",
        rays.len()
    );

    // grin info --up z locates the Z-up data where the Y-up file's is, and its [medium]
    // block (ambient "auto") is a scene that traces.
    let info = |file: &str, up: &str| -> serde_json::Value {
        let out = run(&[
            "info",
            d.join(file).to_str().expect("utf8"),
            "--up",
            up,
            "--json",
        ]);
        let v = json(&out);
        v["grids"]
            .as_array()
            .expect("grids")
            .iter()
            .find(|g| g["name"] == "temperature")
            .expect("temperature")
            .clone()
    };
    let (gy, gz) = (info("yup.vdb", "y"), info("zup.vdb", "z"));
    for side in ["min", "max"] {
        for i in 0..3 {
            let (u, v) = (
                gy["data_world_box"][side][i].as_f64().expect("box"),
                gz["data_world_box"][side][i].as_f64().expect("box"),
            );
            assert!((u - v).abs() < 1e-9, "{side}[{i}]: {u} vs {v}");
        }
    }
    let block = gz["medium_toml"].as_str().expect("medium block");
    assert!(
        block.contains("up = \"z\"") && block.contains("ambient_index = \"auto\""),
        "{block}"
    );
    let pasted = d.join("pasted.toml");
    std::fs::write(
        &pasted,
        format!("[camera]\nposition = [0.0, 0.5, -3.0]\nlook_at = [0.0, 0.5, 0.0]\n{block}\n"),
    )
    .expect("scene");
    let p = trace(&pasted, &plain);
    assert!(p.iter().all(|r| r["status"] == "exited"), "{p:?}");
}

/// The default bake of the example fire cache meets the default budget: the search stops
/// at the cache's own voxel size (40 nodes) for trilinear, then goes on with tricubic at
/// it and 2x and 4x finer. Under a memory cap that stops it earlier, the most accurate
/// grid it reached is written and a warning says why the budget is missed and what to
/// change.
#[test]
fn the_default_bake_of_the_fire_example_meets_its_budget() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out_file = dir.path().join("fire.grinf");
    let scene = data("fire-haze.toml");
    let out = bake_with(&scene, &out_file, &["--json"]);
    let v = json(&out);
    assert_eq!(v["meets_budget"], true, "{v}");
    assert_eq!(v["source_limited"], false, "{v}");
    let trials = v["trials"].as_array().expect("trials");
    let finest_trilinear = trials
        .iter()
        .filter(|t| t["interp"] == "trilinear")
        .filter_map(|t| t["resolution"].as_u64())
        .max()
        .expect("a trilinear trial");
    // 1.95 m tall at 0.05 m voxels: 40 nodes reach the voxel size; no trilinear grid past it.
    assert_eq!(finest_trilinear, 40, "{v}");
    assert!(v["resolution"].as_u64().expect("res") <= 157, "{v}");

    let capped = dir.path().join("capped.grinf");
    let out = bake_with(&scene, &capped, &["--max-memory", "4M", "--json"]);
    let v = json(&out);
    assert_eq!(v["meets_budget"], false, "{v}");
    assert_eq!(v["source_limited"], true, "{v}");
    assert!(capped.exists());
    assert_eq!(v["memory_capped"], true, "{v}");
    let err = stderr(&out);
    assert!(
        err.contains("not met by the grids tried at and past the source's own voxel size")
            && err.contains("--max-memory above"),
        "{err}"
    );
}

/// A scene of a 4^3-voxel `density` grid (voxel 0.05, at index (-2, 8, -2)) whose values
/// the python lines `fill` set in the zero array `a`, mapped by n = 1 + 1e-4 value:
/// `dir/NAME.vdb` and the scene reading it.
fn density_cube(dir: &Path, name: &str, fill: &str) -> PathBuf {
    let file = float_grid_file(
        dir,
        &format!("{name}.vdb"),
        "density",
        0.05,
        &[
            "a = np.zeros((4, 4, 4), dtype=np.float32)",
            fill,
            "g.copyFromArray(a, ijk=(-2, 8, -2), tolerance=0)",
        ],
    );
    vdb_scene(dir, &file, "density", "{ linear = { k = 1e-4 } }", "", 1.0)
}

/// A blob a few voxels across with sharp edges (as a coarse smoke cache has): no grid up
/// to 4x finer than its voxels reproduces the source's interpolation within the budget.
/// The bake keeps the best grid, and the warning says the search ended 4x past the voxel
/// size (not at the memory cap) and which `--resolution` goes finer.
#[test]
fn a_sharp_blob_the_budget_cannot_resolve_says_how_to_go_finer() {
    let dir = tempfile::tempdir().expect("tempdir");
    let scene = density_cube(
        dir.path(),
        "blob",
        "a[1:3, 1:3, 1:3] = 1.0\na[1, 1, 1] = 0.5",
    );
    let out_file = dir.path().join("blob.grinf");
    let out = bake_with(&scene, &out_file, &["--json"]);
    let v = json(&out);
    assert_eq!(v["meets_budget"], false, "{v}");
    assert_eq!(v["source_limited"], true, "{v}");
    assert_eq!(v["memory_capped"], false, "{v}");
    assert!(out_file.exists());
    let res = v["resolution"].as_u64().expect("resolution");
    let err = stderr(&out);
    assert!(
        err.contains("the search stops 4x finer than the source's voxels")
            && err.contains(&format!("(2x: {})", 2 * (res - 1) + 1))
            && !err.contains("--max-memory"),
        "{err}"
    );
}

/// n = 1 + 1e-4 * value in the box [lo, hi]^3 (world), ambient 1, under `max_bytes`.
fn temperature_in_box(lo: f64, hi: f64, max_bytes: u64) -> VdbFieldParams {
    field_params(
        Mapping::Linear { k: 1e-4 },
        Bounds::Box {
            min: DVec3::splat(lo),
            max: DVec3::splat(hi),
        },
        max_bytes,
    )
}

/// A cache whose active box is its whole domain (a 200^3 fill of background-valued active
/// voxels, as fluid caches are written) with a 10^3 hot block: only the block (and 2
/// voxels of padding) is read into memory, found from OpenVDB's tree without a dense copy
/// of the domain.
#[test]
fn a_cache_active_over_its_whole_domain_is_read_where_the_data_is() {
    let dir = tempfile::tempdir().expect("tempdir");
    let file = float_grid_file(
        dir.path(),
        "domain.vdb",
        "temperature",
        0.01,
        &[
            "g.fill((0, 0, 0), (199, 199, 199), 0.0, active=True)",
            "g.copyFromArray(np.ones((10, 10, 10), dtype=np.float32), ijk=(90, 100, 80), tolerance=0)",
        ],
    );
    let vdb = vdb_sys::VdbFile::open(&file).expect("open");
    let info = vdb.grid("temperature").expect("grid");
    let active = info.active_bbox.expect("active");
    assert_eq!((active.min, active.max), ([0, 0, 0], [199, 199, 199]));
    let data = info.data_bbox.expect("data");
    assert_eq!((data.min, data.max), ([90, 100, 80], [99, 109, 89]));
    assert_eq!(info.data_voxel_count, 1000);

    // A dense copy of the domain (8e6 voxels, 96 MB) would not fit under this cap.
    let params = temperature_in_box(-0.01, 2.0, 1 << 20);
    let field = VdbField::load(&file, "temperature", &params).expect("load");
    let b = field.index_box();
    assert_eq!((b.min, b.max), ([88, 98, 78], [101, 111, 91]));
    assert!((field.n(DVec3::new(0.945, 1.045, 0.845)) - 1.0001).abs() < 1e-12);
}

/// Two small hot blocks 300 voxels apart (as two plumes in one cache): their data box is
/// 306^3 = 2.9e7 voxels, whose dense copy (f32 read + f64 index, 344 MB) the 32 MiB cap
/// refuses; read a brick at a time, only the bricks that change the index are kept
/// (under 1 MB), and both blocks are in the field with their mapped values.
#[test]
fn a_sparse_cache_is_kept_in_bricks_not_as_its_dense_box() {
    let dir = tempfile::tempdir().expect("tempdir");
    let file = float_grid_file(
        dir.path(),
        "two.vdb",
        "temperature",
        0.01,
        &[
            "g.copyFromArray(np.ones((6, 6, 6), dtype=np.float32), ijk=(0, 0, 0), tolerance=0)",
            "g.copyFromArray(2.0 * np.ones((6, 6, 6), dtype=np.float32), ijk=(300, 300, 300), tolerance=0)",
        ],
    );
    let params = temperature_in_box(-0.1, 3.2, 32 << 20);
    let t = std::time::Instant::now();
    let field = VdbField::load(&file, "temperature", &params).expect("load");
    eprintln!(
        "two blocks: loaded in {:.2} s, {} bytes of voxels kept",
        t.elapsed().as_secs_f64(),
        field.voxel_bytes()
    );
    assert!(
        field.voxel_bytes() < 1 << 20,
        "{} bytes",
        field.voxel_bytes()
    );
    // Voxel centres inside each block, and the background between them.
    assert!((field.n(DVec3::splat(0.025)) - 1.0001).abs() < 1e-12);
    assert!((field.n(DVec3::splat(3.025)) - 1.0002).abs() < 1e-12);
    assert_eq!(field.n(DVec3::splat(1.5)), 1.0);
    let b = field.index_box();
    assert_eq!((b.min, b.max), ([-2, -2, -2], [307, 307, 307]));
}

/// `grin info` on a cache active over a 700^3 domain (a dense read of it, 1.4 GB, was
/// refused: "data: not located") with two small blocks near opposite corners: it reads
/// the blocks' box a brick at a time and reports exactly where the data is.
#[test]
fn info_locates_the_data_of_a_large_cache() {
    let dir = tempfile::tempdir().expect("tempdir");
    let file = float_grid_file(
        dir.path(),
        "large.vdb",
        "temperature",
        0.02,
        &[
            "g.fill((0, 0, 0), (699, 699, 699), 0.0, active=True)",
            "g.copyFromArray(np.ones((4, 5, 6), dtype=np.float32), ijk=(20, 30, 40), tolerance=0)",
            "g.copyFromArray(np.ones((3, 3, 3), dtype=np.float32), ijk=(650, 640, 630), tolerance=0)",
        ],
    );
    let out = run(&["info", file.to_str().expect("utf8"), "--json"]);
    let v = json(&out);
    let g = &v["grids"][0];
    assert_eq!(
        g["data_index_box"]["min"],
        serde_json::json!([20, 30, 40]),
        "{g}"
    );
    assert_eq!(
        g["data_index_box"]["max"],
        serde_json::json!([652, 642, 632]),
        "{g}"
    );
}

/// A sequence whose grid is renamed in one frame or changes type in another is refused
/// before anything is rendered, naming the frame, its file and what differs.
#[test]
fn a_sequence_whose_grid_changes_is_refused_naming_the_frame() {
    let dir = tempfile::tempdir().expect("tempdir");
    let tools = tempfile::tempdir().expect("tempdir");
    run_openvdb_python(
        tools.path(),
        r#"
out = sys.argv[1]
v = -1e-3 * np.ones((6, 6, 6), dtype=np.float32)
for frame, name, kind in [(1, "delta_n", "f"), (2, "dn", "f"), (3, "delta_n", "v")]:
    if kind == "f":
        g = vdb.FloatGrid()
        g.copyFromArray(v, ijk=(-3, -3, -3), tolerance=0)
    else:
        g = vdb.Vec3SGrid()
        g.copyFromArray(np.stack([v, v, v], axis=-1), ijk=(-3, -3, -3), tolerance=(0, 0, 0))
    g.name = name
    g.transform = vdb.createLinearTransform(voxelSize=0.05)
    vdb.write(f"{out}/s_{frame:04d}.vdb", grids=[g])
"#,
        dir.path(),
    );
    let scene = dir.path().join("seq.toml");
    std::fs::write(
        &scene,
        r#"
[camera]
position = [0.0, 0.0, -2.0]
look_at = [0.0, 0.0, 0.0]
[medium]
bounds = { box = { min = [-0.3, -0.3, -0.3], max = [0.3, 0.3, 0.3] } }
field = { kind = "vdb", path = "s_####.vdb", grid = "delta_n", map = { index = { delta = true } } }
[render]
width = 8
height = 8
"#,
    )
    .expect("scene");
    let render = |frames: &str| {
        let out = dir.path().join("out.####.exr");
        let o = grin()
            .args(["render", "--backend", "cpu", "--frames", frames, "-o"])
            .arg(&out)
            .arg(&scene)
            .output()
            .expect("grin");
        (o, dir.path().join("out.0001.exr"))
    };
    let (o, first) = render("1..3");
    fails_cleanly(&o, "frame 2: ", Some(&first));
    let err = stderr(&o);
    assert!(
        err.contains("s_0002.vdb: grid `delta_n` not found; available grids: dn"),
        "{err}"
    );
    let (o, _) = render("3..3");
    fails_cleanly(&o, "frame 3: ", None);
    let err = stderr(&o);
    assert!(
        err.contains("s_0003.vdb: grid `delta_n` has value type `vec3s`"),
        "{err}"
    );
    let (o, first) = render("1..1");
    assert_ok(&o);
    assert!(first.exists());
}

/// A cache whose values overflow what a bake and the GPU carry (1e32 mapped to n): refused
/// with the limit named and the voxel's place, no output (the CPU rendered OPD -inf and
/// rays left after a few steps).
#[test]
fn values_no_bake_can_carry_are_refused_with_the_limit() {
    let dir = tempfile::tempdir().expect("tempdir");
    let scene = density_cube(dir.path(), "huge", "a[1:3, 1:3, 1:3] = 1e32");
    let out_dir = dir.path().join("out");
    std::fs::create_dir(&out_dir).expect("out dir");
    let out_file = out_dir.join("huge.grinf");
    fails_cleanly(
        &bake(&scene, &out_file),
        "|n - ambient| must be at most 1000 (what a bake and the GPU can carry)",
        Some(&out_file),
    );
}

/// Bounds that cut a grid's data load it with a warning (library code returns it), and
/// every way in tells the user: `grin render` (stderr and `--json`), `grin trace` and
/// `grin bake`.
#[test]
fn bounds_that_cut_the_data_warn_on_every_command() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let scene = density_cube(d, "cut", "a[:, :, :] = 1.0");
    // The cube spans x -0.1 .. 0.05: bounds ending at x = 0 cut it.
    let text = std::fs::read_to_string(&scene).expect("scene");
    let cut = text.replace("max = [0.6, 1.0, 0.6]", "max = [0.0, 1.0, 0.6]");
    assert_ne!(cut, text, "the scene's bounds line moved");
    std::fs::write(&scene, cut).expect("scene");
    let warned = |o: &Output| {
        let err = stderr(o);
        assert!(
            err.lines().any(|l| l.starts_with("grin: warning: ")
                && l.contains("the [medium] bounds cut the grid's data")),
            "{err}"
        );
    };

    let render = run_ok(
        grin()
            .arg("render")
            .arg(&scene)
            .arg("-o")
            .arg(d.join("cut.exr"))
            .args(["--backend", "cpu", "--size", "8x8", "--json"]),
    );
    warned(&render);
    let v = json(&render);
    assert!(
        v["warnings"].as_array().expect("warnings").iter().any(|w| w
            .as_str()
            .is_some_and(|w| w.contains("cut the grid's data"))),
        "{v}"
    );

    let rays = d.join("rays.csv");
    std::fs::write(&rays, "ox,oy,oz,dx,dy,dz\n-0.05,0.5,-2,0,0,1\n").expect("rays");
    warned(&run_ok(&mut common::trace_cmd(
        &scene,
        &rays,
        &d.join("out.csv"),
    )));

    warned(&bake(&scene, &d.join("cut.grinf")));
}
