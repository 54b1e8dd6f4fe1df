//! grin's test harness (as wgpu's tests/ harness): running the `grin` binary and asserting
//! its outcome with its streams, the one GPU-presence policy ([`skip`]), the one random
//! generator ([`rng`]), the shared scenes ([`scenes`]), temporary directories, the repository's data, an EXR's channels
//! and `grin trace`'s tables. The end-to-end tests (tests/, grin-cli's) import it as
//! `common`; the crates' own tests use what they need. grin-gpu's tests, which this crate
//! depends on, include its dependency-free modules by path.

pub mod rng;
pub mod scenes;
pub mod skip;

pub use skip::{require_gpu, skipped_no_gpu, test_name};

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The `grin` binary cargo built with the running tests: beside the directory of the test
/// executable (`target/<profile>/deps/<test>` -> `target/<profile>/grin`). Cargo builds a
/// package's binaries before its integration tests run.
pub fn grin_path() -> PathBuf {
    let exe = std::env::current_exe().expect("the test executable's path");
    let profile = exe
        .parent()
        .and_then(Path::parent)
        .expect("the test executable lies in target/<profile>/deps");
    let grin = profile.join(format!("grin{}", std::env::consts::EXE_SUFFIX));
    assert!(
        grin.is_file(),
        "{} is not built (the tests that run it are grin-cli's)",
        grin.display()
    );
    grin
}

/// The `grin` binary built with these tests.
pub fn grin() -> Command {
    Command::new(grin_path())
}

/// `grin ARGS`, run to its end.
pub fn grin_args<S: AsRef<std::ffi::OsStr>>(args: &[S]) -> Output {
    grin().args(args).output().expect("run grin")
}

/// A file under the repository's `data/`.
pub fn data(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../data")
        .join(rel)
}

/// The example scenes, `data/scenes`.
pub fn scenes() -> PathBuf {
    data("scenes")
}

/// The command's stderr, as text.
pub fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// The command's stdout, as text.
pub fn stdout(out: &Output) -> String {
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Fail with both streams when `grin` did.
pub fn assert_ok(out: &Output) {
    assert!(
        out.status.success(),
        "stdout {}\nstderr {}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Fail unless the command failed (exited non-zero): its stderr.
pub fn assert_failed(out: &Output) -> String {
    let err = stderr(out);
    assert!(
        !out.status.success(),
        "expected a failure; it succeeded. stdout {}\nstderr {err}",
        stdout(out)
    );
    err
}

/// Fail unless the command failed (exited non-zero) with `needle` in its stderr.
pub fn assert_err(out: &Output, needle: &str) {
    let err = assert_failed(out);
    assert!(err.contains(needle), "expected `{needle}` in stderr: {err}");
}

/// Run `cmd` (a `grin()` built up), which must succeed: its output.
pub fn run_ok(cmd: &mut Command) -> Output {
    let out = cmd.output().expect("run grin");
    if !out.status.success() {
        eprintln!("failed: {cmd:?}");
    }
    assert_ok(&out);
    out
}

/// Run `cmd`, which must fail with `needle` in its stderr: its output.
pub fn run_err(cmd: &mut Command, needle: &str) -> Output {
    let out = cmd.output().expect("run grin");
    if out.status.success() || !stderr(&out).contains(needle) {
        eprintln!("ran: {cmd:?}");
    }
    assert_err(&out, needle);
    out
}

/// The JSON the command printed on stdout, which it must have printed successfully.
pub fn json(out: &Output) -> serde_json::Value {
    assert_ok(out);
    serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("bad JSON ({e}): {}", stdout(out)))
}

/// Whether a GPU adapter (lavapipe in CI) is there.
pub fn gpu_available() -> bool {
    grin_gpu::GpuContext::new_headless().is_ok()
}

/// For a test, or the GPU half of one, that runs where an adapter is: true if there is
/// one; otherwise prints `SKIPPED (no GPU adapter): <test name>` on stderr and gives false.
pub fn gpu_or_skip() -> bool {
    match grin_gpu::GpuContext::new_headless() {
        Ok(_) => true,
        Err(e) => {
            skipped_no_gpu(&test_name(), &e.to_string());
            false
        }
    }
}

/// For a test that CI runs on lavapipe: true if there is an adapter; without one it fails,
/// unless `GRIN_ALLOW_NO_GPU=1`, when it prints the SKIPPED line and gives false.
pub fn gpu_required() -> bool {
    require_gpu(&test_name(), grin_gpu::GpuContext::new_headless()).is_some()
}

/// A temporary directory the test writes its files in.
#[derive(Debug)]
pub struct TestDir {
    pub dir: tempfile::TempDir,
}

impl Default for TestDir {
    fn default() -> Self {
        Self::new()
    }
}

impl TestDir {
    pub fn new() -> Self {
        TestDir {
            dir: tempfile::tempdir().expect("temp dir"),
        }
    }

    /// The directory.
    pub fn root(&self) -> &Path {
        self.dir.path()
    }

    /// `name` in the directory.
    pub fn path(&self, name: &str) -> PathBuf {
        self.dir.path().join(name)
    }

    /// Write `text` to `name` in the directory: its path.
    pub fn write(&self, name: &str, text: &str) -> PathBuf {
        let p = self.path(name);
        std::fs::write(&p, text).expect("write test file");
        p
    }

    /// The names in the directory, sorted (to check no temporary or partial file is left).
    pub fn names(&self) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(self.dir.path())
            .expect("read dir")
            .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }
}

/// One row of a `grin trace` table: each field by its column's name.
pub type Row = HashMap<String, String>;

/// The rows of the CSV table `grin trace` wrote to `path`.
pub fn read_table(path: &Path) -> Vec<Row> {
    let text = std::fs::read_to_string(path).expect("trace output");
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    lines
        .map(|l| {
            header
                .iter()
                .map(|h| (*h).to_owned())
                .zip(l.split(',').map(str::to_owned))
                .collect()
        })
        .collect()
}

/// The number in `row`'s column `name`.
pub fn num(row: &Row, name: &str) -> f64 {
    row.get(name)
        .unwrap_or_else(|| panic!("no column {name}: {row:?}"))
        .parse()
        .unwrap_or_else(|e| panic!("column {name} ({e}): {row:?}"))
}

/// The vector in `row`'s columns `names`.
pub fn vec3(row: &Row, names: [&str; 3]) -> glam::DVec3 {
    glam::DVec3::from_array(names.map(|k| num(row, k)))
}

/// Every channel of an EXR's first layer by name, and the layer's width.
pub fn exr_channels(path: &Path) -> (usize, HashMap<String, Vec<f64>>) {
    use exr::prelude::*;
    let image = read_all_flat_layers_from_file(path).expect("read exr");
    let layer = &image.layer_data[0];
    let map = layer
        .channel_data
        .list
        .iter()
        .map(|c| {
            (
                c.name.to_string(),
                c.sample_data.values_as_f32().map(f64::from).collect(),
            )
        })
        .collect();
    (layer.size.width(), map)
}

/// `grin render SCENE -o OUT --backend BACKEND`.
pub fn render(scene: &Path, out: &Path, backend: &str) -> Output {
    render_with(scene, out, &["--backend", backend])
}

/// `grin render SCENE -o OUT EXTRA`.
pub fn render_with(scene: &Path, out: &Path, extra: &[&str]) -> Output {
    grin()
        .arg("render")
        .arg(scene)
        .arg("-o")
        .arg(out)
        .args(extra)
        .output()
        .expect("grin runs")
}

/// `grin trace SCENE --rays RAYS -o OUT`, to run (add options first).
pub fn trace_cmd(scene: &Path, rays: &Path, out: &Path) -> Command {
    let mut cmd = grin();
    cmd.arg("trace")
        .arg(scene)
        .arg("--rays")
        .arg(rays)
        .arg("-o")
        .arg(out);
    cmd
}

/// `grin bake SCENE -o OUT EXTRA`.
pub fn bake_with(scene: &Path, out: &Path, extra: &[&str]) -> Output {
    grin()
        .arg("bake")
        .arg(scene)
        .arg("-o")
        .arg(out)
        .args(extra)
        .output()
        .expect("run grin")
}

/// [`render`] with `--json`, which must succeed: the summary.
pub fn render_json(scene: &Path, out: &Path, backend: &str) -> serde_json::Value {
    json(&render_with(scene, out, &["--backend", backend, "--json"]))
}

/// The BOS tests' set-up as scene text: a Gaussian plume of hot air (a = 2e-3, s = 0.3)
/// in a 2 m box, seen from 6 m (`camera`: its lens lines, e.g. `fov_y_deg = 12.0`),
/// `width` x `height`, rk4 at fixed `step` (0: no integrator or step, grin's defaults);
/// `extra` is appended right after `[render]`'s lines (so it may set more of them, e.g.
/// `spp = 32`, before its own tables).
pub fn bos_plume_scene(camera: &str, width: u32, height: u32, step: f64, extra: &str) -> String {
    let method = if step == 0.0 {
        String::new()
    } else {
        format!("integrator = \"rk4\"\nstep = {{ fixed = {step} }}")
    };
    format!(
        r#"
[camera]
position = [0.0, 0.0, -6.0]
look_at = [0.0, 0.0, 0.0]
{camera}
[medium]
bounds = {{ box = {{ min = [-1.0, -1.0, -1.0], max = [1.0, 1.0, 1.0] }} }}
field = {{ kind = "plume", plumes = [ {{ a = 2e-3, center = [0.0, 0.0, 0.0], s = 0.3 }} ] }}
[render]
width = {width}
height = {height}
{method}
{extra}
"#
    )
}

/// The Luneburg example scene at a fixed step of 1e-5 (~200,000 steps a ray, max_steps
/// 10^6), written as `long.toml` into `dir`: rays past lavapipe's loop limit.
pub fn long_luneburg_scene(dir: &Path) -> std::path::PathBuf {
    let scene = std::fs::read_to_string(scenes().join("luneburg.toml"))
        .expect("scene")
        .replace(
            "step = { fixed = 0.01 }",
            "step = { fixed = 1e-5 }\nmax_steps = 1000000",
        );
    assert!(
        scene.contains("fixed = 1e-5"),
        "the scene's step was not replaced"
    );
    let path = dir.join("long.toml");
    std::fs::write(&path, scene).expect("write scene");
    path
}
