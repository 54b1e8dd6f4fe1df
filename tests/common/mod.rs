//! Helpers the end-to-end tests share: the `grin` binary, its outcome, the GPU's
//! presence and an EXR's channels.

#![allow(dead_code)]

use std::collections::HashMap;
use std::path::Path;
use std::process::{Command, Output};

/// The `grin` binary built with these tests.
pub fn grin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_grin"))
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

/// Whether a GPU adapter (lavapipe in CI) is there.
pub fn gpu_available() -> bool {
    grin_gpu::GpuContext::new_headless().is_ok()
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
    grin()
        .arg("render")
        .arg(scene)
        .arg("-o")
        .arg(out)
        .args(["--backend", backend])
        .output()
        .expect("grin runs")
}

/// [`render`] with `--json`, which must succeed: the summary.
pub fn render_json(scene: &Path, out: &Path, backend: &str) -> serde_json::Value {
    let o = grin()
        .arg("render")
        .arg(scene)
        .arg("-o")
        .arg(out)
        .args(["--backend", backend, "--json"])
        .output()
        .expect("grin runs");
    assert_ok(&o);
    serde_json::from_slice(&o.stdout).expect("json summary")
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
    let scenes = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/scenes");
    let scene = std::fs::read_to_string(scenes.join("luneburg.toml"))
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
