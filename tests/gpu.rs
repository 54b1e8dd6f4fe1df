//! End-to-end tests of `grin` on the GPU backend (lavapipe in CI): `grin render
//! --backend gpu`, the no-adapter error, the default backend's choice, scene errors
//! before GPU work, and
//! `grin bench speed`. A missing adapter fails these tests unless GRIN_ALLOW_NO_GPU=1,
//! which turns them into a loud SKIPPED line.

use common::{assert_failed, gpu_required, grin, json, render_with, run_ok, scenes, stderr};
use grin_testkit as common;

#[test]
fn render_gpu_writes_exr_png_and_summary() {
    if !gpu_required() {
        return;
    }
    let dir = tempfile::tempdir().expect("tmp");
    let out = dir.path().join("lens.exr");
    let summary = json(&render_with(
        &scenes().join("luneburg.toml"),
        &out,
        &[
            "--backend",
            "gpu",
            "--size",
            "64x36",
            "--spp",
            "1",
            "--json",
        ],
    ));
    assert_eq!(summary["backend"], "gpu", "{summary}");
    assert!(
        !summary["adapter"].as_str().unwrap_or("").is_empty(),
        "{summary}"
    );
    assert!(
        summary["rays_per_second"].as_f64().is_some_and(|r| r > 0.0),
        "{summary}"
    );
    assert!(
        summary["steps_per_ray"].as_f64().is_some_and(|s| s > 0.0),
        "the lens is marched: {summary}"
    );
    // lavapipe writes timestamps too: the device's time is there, and within the frame's.
    let (device, wall) = (
        summary["device_seconds"].as_f64().unwrap_or(f64::NAN),
        summary["seconds"].as_f64().unwrap_or(f64::NAN),
    );
    assert!(device > 0.0 && device <= wall, "{summary}");
    let frame = grin_render::image::Frame::read_exr(&out).expect("EXR readable");
    assert_eq!((frame.width, frame.height), (64, 36));
    assert!(
        frame.pixels.iter().any(|p| p.status == 1.0),
        "some rays exit the lens"
    );
    assert!(
        out.with_extension("png").is_file(),
        "PNG preview beside the EXR"
    );
}

/// The frame is dispatched in bands of rows (32 Ki pixels on lavapipe, 2 Mi / spp on a
/// GPU); their size (`GRIN_BAND_PIXELS`) must not change a pixel: bands of 700 pixels
/// (7 rows of 96, the last band partial) give the same EXR as one band for the frame. A
/// value that is not a positive number is said and the default band used.
#[test]
fn band_size_does_not_change_the_image() {
    if !gpu_required() {
        return;
    }
    let dir = tempfile::tempdir().expect("tmp");
    let render = |band: &str, name: &str| {
        let out = dir.path().join(name);
        let o = run_ok(
            grin()
                .env("GRIN_BAND_PIXELS", band)
                .args(["render", "--backend", "gpu", "--size", "96x54", "-o"])
                .arg(&out)
                .arg(scenes().join("paper-c.toml")),
        );
        (
            grin_render::image::Frame::read_exr(&out).expect("EXR readable"),
            stderr(&o),
        )
    };
    let (whole, _) = render("100000", "whole.exr");
    let (banded, _) = render("700", "banded.exr");
    let (default, err) = render("-3", "default.exr");
    assert!(
        err.contains("GRIN_BAND_PIXELS=\"-3\" is not a positive number"),
        "{err}"
    );
    assert!(
        whole.pixels == default.pixels,
        "the default band changes pixels"
    );
    assert!(
        whole.pixels.iter().any(|p| p.steps > 0.0),
        "the medium is marched"
    );
    let differ = whole
        .pixels
        .iter()
        .zip(&banded.pixels)
        .filter(|(a, b)| a != b)
        .count();
    assert_eq!(differ, 0, "pixels differ between band sizes");
}

/// Rays too long for lavapipe's loop limit (65,535 loop iterations an invocation in all,
/// ~21,800 steps; these take ~200,000) leave on every adapter: `grin render`'s medium pass
/// runs in rounds of 1,024 steps, a pixel's state kept on the device between them. (Marched
/// whole, they ended `error` on lavapipe, with a warning naming the limit.)
#[test]
fn rays_past_lavapipes_loop_limit_leave_on_every_adapter() {
    if !gpu_required() {
        return;
    }
    let dir = tempfile::tempdir().expect("tmp");
    let path = common::long_luneburg_scene(dir.path());
    let v = json(&render_with(
        &path,
        &dir.path().join("long.exr"),
        &["--backend", "gpu", "--size", "6x4", "--json"],
    ));
    let counts = &v["status_counts"];
    let count = |s: &str| counts[s].as_u64().expect("status count");
    assert_eq!(count("error"), 0, "{v}");
    assert_eq!(count("max_steps"), 0, "{v}");
    assert!(count("exited") + count("degraded") >= 6, "{v}");
    let steps = v["steps_per_ray"].as_f64().expect("steps per ray");
    assert!(steps > 20_000.0, "{steps} steps a pixel: not long rays");
    let warned = v["warnings"]
        .as_array()
        .expect("warnings")
        .iter()
        .filter_map(|w| w.as_str())
        .any(|w| w.contains("on a CPU adapter (lavapipe)"));
    assert!(!warned, "{v}");
}

#[test]
fn no_adapter_is_a_clear_error_and_writes_nothing() {
    let dir = tempfile::tempdir().expect("tmp");
    let out = dir.path().join("x.exr");
    let o = grin()
        .env("WGPU_ADAPTER_NAME", "no-such-adapter-anywhere")
        .args(["render", "--backend", "gpu", "--size", "32x18", "-o"])
        .arg(&out)
        .arg(scenes().join("luneburg.toml"))
        .output()
        .expect("run grin");
    let err = assert_failed(&o);
    assert!(
        err.contains("no GPU adapter") && err.contains("WGPU_ADAPTER_NAME"),
        "{err}"
    );
    // (Mesa's Vulkan loader may add its own lines about the environment.)
    let ours: Vec<&str> = err.lines().filter(|l| l.starts_with("grin:")).collect();
    assert_eq!(ours.len(), 1, "one-line reason: {err}");
    assert_eq!(
        std::fs::read_dir(dir.path()).expect("ls").count(),
        0,
        "no output on failure"
    );
}

/// `grin render` without `--backend` renders on the GPU marcher only where wgpu's adapter
/// is a GPU: with no adapter, or a CPU one (lavapipe), the CPU tracer renders (faster
/// there), and the summary says which backend and why.
#[test]
fn the_default_backend_is_the_gpu_marcher_only_on_a_gpu() {
    let dir = tempfile::tempdir().expect("tmp");
    let scene = scenes().join("luneburg.toml");
    let args = ["--size", "32x18", "--spp", "1", "--json"];
    let none = json(&run_ok(
        grin()
            .env("WGPU_ADAPTER_NAME", "no-such-adapter-anywhere")
            .arg("render")
            .arg(&scene)
            .arg("-o")
            .arg(dir.path().join("none.exr"))
            .args(args),
    ));
    assert_eq!(none["backend"], "cpu", "{none}");
    let note = none["backend_note"].as_str().expect("a backend note");
    assert!(
        note.starts_with("backend auto: cpu: wgpu finds no GPU adapter"),
        "{note}"
    );
    if !gpu_required() {
        return;
    }
    let chosen = json(&render_with(&scene, &dir.path().join("auto.exr"), &args));
    let gpu = json(&render_with(
        &scene,
        &dir.path().join("gpu.exr"),
        &[
            "--backend",
            "gpu",
            "--size",
            "32x18",
            "--spp",
            "1",
            "--json",
        ],
    ));
    let adapter = gpu["adapter"].as_str().expect("adapter");
    let note = chosen["backend_note"].as_str().expect("a backend note");
    if adapter.ends_with(", Cpu)") {
        assert_eq!(chosen["backend"], "cpu", "{chosen}");
        assert!(note.contains("only adapter is a CPU one"), "{note}");
    } else {
        assert_eq!(chosen["backend"], "gpu", "{chosen}");
        assert!(note.starts_with("backend auto: gpu"), "{note}");
    }
    // The backend named is the one that ran: no note where it was asked for.
    assert!(gpu.get("backend_note").is_none(), "{gpu}");
}

#[test]
fn scene_errors_come_before_any_gpu_work() {
    let dir = tempfile::tempdir().expect("tmp");
    let scene = dir.path().join("bad.toml");
    std::fs::write(
        &scene,
        "[camera]\nposition = [0.0, 1.0, -4.0]\nlook_at = [0.0, 1.0, -4.0]\n\n[render]\nwidth = 32\nheight = 18\n",
    )
    .expect("write scene");
    // Even with no usable adapter, the scene's own error is what is reported.
    let o = grin()
        .env("WGPU_ADAPTER_NAME", "no-such-adapter-anywhere")
        .args(["render", "--backend", "gpu", "-o"])
        .arg(dir.path().join("x.exr"))
        .arg(&scene)
        .output()
        .expect("run grin");
    let err = assert_failed(&o);
    assert!(err.contains("camera") && !err.contains("adapter"), "{err}");
}

#[test]
fn bench_speed_quick_reports_both_backends() {
    if !gpu_required() {
        return;
    }
    let o = run_ok(
        grin()
            .args(["bench", "speed", "--quick", "--json", "--scenes"])
            .arg(scenes()),
    );
    let r = json(&o);
    let runs = r["runs"].as_array().expect("runs");
    for backend in ["gpu", "cpu"] {
        for scene in ["paper (a)", "paper (c)", "heat haze"] {
            let run = runs
                .iter()
                .find(|x| {
                    x["backend"] == backend
                        && x["scene"].as_str().is_some_and(|s| s.starts_with(scene))
                })
                .unwrap_or_else(|| panic!("no {backend} run of {scene}: {r}"));
            assert!(
                run["ms_per_frame"].as_f64().is_some_and(|t| t > 0.0),
                "{run}"
            );
            assert!(
                run["rays_per_second"].as_f64().is_some_and(|t| t > 0.0),
                "{run}"
            );
            // The spread over the timed frames: min <= median <= max, min is the rate's frame.
            let ms = |k: &str| run[k].as_f64().unwrap_or(f64::NAN);
            assert!(
                ms("ms_min") <= ms("ms_median") && ms("ms_median") <= ms("ms_max"),
                "{run}"
            );
            assert_eq!(ms("ms_min"), ms("ms_per_frame"), "{run}");
            // GPU runs timed on the device too (lavapipe writes timestamps): within the
            // wall clock's fastest frame.
            if backend == "gpu" && r["timed_on_device"] == true {
                let device = ms("device_ms_min");
                assert!(device > 0.0 && device <= ms("ms_min"), "{run}");
            }
        }
    }
    assert!(
        r["noise_over_analytic_gpu"]
            .as_f64()
            .is_some_and(|x| x.is_finite() && x > 0.0),
        "{r}"
    );
    // Each scene baked sparsely at its dense bake's error, trilinear and Catmull-Rom: the
    // sparse bake meets it, and its rows name both fields' bytes and the frame-time ratios.
    let sparse = r["sparse"].as_array().expect("sparse rows");
    assert_eq!(sparse.len(), 6, "{r}");
    for row in sparse {
        let f = |k: &str| row[k].as_f64().unwrap_or(f64::NAN);
        // The same error: within 1% (grin_bench::cases::SAME_ERROR).
        assert!(f("sparse_error") <= f("error") * 1.01, "{row}");
        assert!(f("sparse_bytes") > 0.0 && f("dense_bytes") > 0.0, "{row}");
        assert!(
            f("gpu_time_ratio") > 0.0 && f("cpu_time_ratio") > 0.0,
            "{row}"
        );
        let scene = row["scene"].as_str().expect("scene");
        let label = match row["interp"].as_str() {
            Some("trilinear") => format!("{scene} sparse"),
            Some("tricubic") => format!("{scene} sparse catmull-rom"),
            other => panic!("interp {other:?}: {row}"),
        };
        assert!(
            runs.iter().any(|x| x["scene"] == label.as_str()),
            "{label}: {r}"
        );
    }
    let frac = r["field_evals_fraction_of_raw"].as_f64().expect("fraction");
    assert!(
        frac > 0.0 && frac < 2.0,
        "marcher rate is a plausible fraction of the raw rate: {r}"
    );
    // Verlet makes one evaluation per step, sharma three: on the same steps it makes
    // fewer evaluations per ray (counted; the rates themselves are timings, which a busy
    // machine reorders: CI once measured 0.0767 vs 0.0779).
    let verlet = r["verlet_ray_steps_fraction_of_raw"]
        .as_f64()
        .expect("verlet fraction");
    assert!(verlet > 0.0 && verlet < 2.0, "{r}");
    let runs = r["runs"].as_array().expect("runs");
    let evals = |scene: &str| {
        runs.iter()
            .find(|x| x["scene"] == scene && x["backend"] == "gpu")
            .and_then(|x| Some((x["steps_per_ray"].as_f64()?, x["evals_per_ray"].as_f64()?)))
            .unwrap_or_else(|| panic!("no GPU run of {scene}: {r}"))
    };
    let (steps_v, evals_v) = evals("(c) medium, verlet");
    let (steps_s, evals_s) = evals("(c) medium only");
    assert!(
        (steps_v - steps_s).abs() <= 0.01 * steps_s && evals_v < 0.5 * evals_s,
        "verlet {steps_v} steps / {evals_v} evals vs sharma {steps_s} / {evals_s}: {r}"
    );
}
