//! End-to-end tests of `grin render`: the files it writes, the Luneburg lens focusing as
//! the exact solution says (through the render's AOVs and through `grin trace`), scene
//! errors before any work, and no broken output when a render is interrupted.

use common::{
    assert_err, assert_failed, assert_ok, grin, json, read_table, render_with, run_ok, scenes,
    stderr, vec3,
};
use grin_testkit as common;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

use glam::DVec3;
use grin_render::camera::PinholeCamera;
use grin_render::image::Frame;

fn scene_path(name: &str) -> PathBuf {
    scenes().join(name)
}

/// Width and height from a PNG's IHDR chunk.
fn png_size(path: &Path) -> (u32, u32) {
    let bytes = std::fs::read(path).expect("png exists");
    assert_eq!(
        &bytes[..8],
        b"\x89PNG\r\n\x1a\n",
        "{} is a PNG",
        path.display()
    );
    let be = |i: usize| u32::from_be_bytes([bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]]);
    (be(16), be(20))
}

/// `grin render SCENE -o OUT --backend cpu EXTRA`.
fn run_render(scene: &Path, out: &Path, extra: &[&str]) -> std::process::Output {
    render_with(scene, out, &[&["--backend", "cpu"], extra].concat())
}

#[test]
fn cpu_render_writes_exr_with_aovs_and_png_preview() {
    let dir = tempfile::tempdir().expect("tmp");
    let out = dir.path().join("paper-a.exr");
    let o = run_render(
        &scene_path("paper-a.toml"),
        &out,
        &["--size", "64x36", "--spp", "1", "--json"],
    );
    let summary = json(&o);
    assert_eq!(summary["backend"], "cpu");
    assert_eq!(summary["width"], 64);
    assert_eq!(summary["height"], 36);
    assert!(summary["rays_per_second"].as_f64().is_some_and(|r| r > 0.0));
    assert!(summary["steps_per_ray"].as_f64().is_some_and(|s| s > 0.0));
    let frame = Frame::read_exr(&out).expect("exr readable");
    assert_eq!((frame.width, frame.height), (64, 36));
    assert!(
        frame
            .pixels
            .iter()
            .all(|p| p.rgb.iter().all(|c| c.is_finite() && *c >= 0.0))
    );
    // The GRIN sphere of paper (a) converges: rays through it are bent, by up to tens of
    // degrees near the rim, and their optical path is longer than the straight one (n > 1).
    let through: Vec<_> = frame.pixels.iter().filter(|p| p.status == 1.0).collect();
    assert!(
        through.len() > 100,
        "{} pixels through the medium",
        through.len()
    );
    assert!(through.iter().any(|p| p.deflection_deg > 5.0));
    assert!(
        through
            .iter()
            .all(|p| p.opd > 0.0 && p.steps > 0.0 && p.evals >= p.steps)
    );
    assert_eq!(png_size(&dir.path().join("paper-a.png")), (64, 36));
    let leftovers: Vec<_> = std::fs::read_dir(dir.path())
        .expect("ls")
        .map(|e| e.expect("entry").file_name())
        .filter(|n| n.to_string_lossy().starts_with('.'))
        .collect();
    assert!(leftovers.is_empty(), "temporary files left: {leftovers:?}");
}

/// `--aovs` picks the AOVs the EXR holds beside R, G, B: on both backends the channels
/// written are the whole render's, bit for bit, with the same summary; on the GPU only
/// they are read back (12 bytes a pixel for `none`); an unknown name is refused with the
/// list.
#[test]
fn aovs_write_only_the_channels_asked_for() {
    use common::exr_channels;
    let dir = tempfile::tempdir().expect("tempdir");
    let scene = scene_path("paper-a.toml");
    let mut backends = vec!["cpu"];
    if common::gpu_or_skip() {
        backends.push("gpu");
    }
    let pixels = 96 * 54;
    for backend in backends {
        let render = |aovs: &str| {
            let out = dir
                .path()
                .join(format!("{backend}-{}.exr", aovs.replace(',', "-")));
            let args = [
                "--backend",
                backend,
                "--size",
                "96x54",
                "--json",
                "--aovs",
                aovs,
            ];
            let v = json(&render_with(&scene, &out, &args));
            (v, exr_channels(&out).1)
        };
        let (all, all_exr) = render("all");
        assert_eq!(all_exr.len(), 15, "{backend}: every channel by default");
        for (aovs, names) in [
            ("none", vec!["B", "G", "R"]),
            (
                "steps,status",
                vec!["B", "G", "R", "aov.status", "aov.steps"],
            ),
            (
                "exit_dir,opd_plane",
                vec![
                    "B",
                    "G",
                    "R",
                    "aov.exit_dir.X",
                    "aov.exit_dir.Y",
                    "aov.exit_dir.Z",
                    "aov.opd_plane",
                ],
            ),
        ] {
            let (v, exr) = render(aovs);
            let mut got: Vec<&str> = exr.keys().map(String::as_str).collect();
            got.sort_unstable();
            assert_eq!(got, names, "{backend} --aovs {aovs}");
            for (name, data) in &exr {
                let same = data
                    .iter()
                    .zip(&all_exr[name])
                    .all(|(a, b)| a.to_bits() == b.to_bits());
                assert!(
                    same,
                    "{backend} --aovs {aovs}: {name} differs from the whole render's"
                );
            }
            assert_eq!(
                v["status_counts"], all["status_counts"],
                "{backend} --aovs {aovs}"
            );
            for key in ["steps_per_ray", "evals_per_ray"] {
                let (a, b) = (v[key].as_f64().expect(key), all[key].as_f64().expect(key));
                assert!(
                    a > 1.0 && (a - b).abs() <= 1e-12 * b,
                    "{backend} --aovs {aovs}: {key} {a} against {b}"
                );
            }
            if backend == "gpu" {
                let bytes = |v: &serde_json::Value| v["read_back_bytes"].as_u64().expect("bytes");
                let per_pixel = 4 * (names.len() as u64);
                // The channels and 64 bytes of counts in place of 64 bytes a pixel.
                assert_eq!(
                    bytes(&v) + pixels * (64 - per_pixel),
                    bytes(&all) + 64,
                    "{backend} --aovs {aovs}: bytes read back"
                );
            }
        }
    }
    let o = run_render(
        &scene,
        &dir.path().join("x.exr"),
        &["--aovs", "steps,bogus"],
    );
    assert_failed(&o);
    let err = stderr(&o);
    assert!(
        err.contains("unknown AOV `bogus`") && err.contains("exit_dir") && err.contains("`none`"),
        "{err}"
    );
    assert!(!dir.path().join("x.exr").exists());
}

/// The exact Luneburg ray (docs/physics.md, Luneburg lens): entering the unit-radius lens
/// at p (relative to the centre) along unit d, it leaves at R d travelling along -p / R.
fn luneburg_exit(c: DVec3, r: f64, o: DVec3, d: DVec3) -> Option<(DVec3, DVec3)> {
    let oc = o - c;
    let b = oc.dot(d);
    let disc = b * b - (oc.length_squared() - r * r);
    if disc <= 0.0 {
        return None;
    }
    let p = oc + d * (-b - disc.sqrt());
    Some((c + d * r, -p / r))
}

#[test]
fn luneburg_scene_focuses_as_the_exact_solution_predicts() {
    let scene_file = scene_path("luneburg.toml");
    let scene = grin_scene::load_scene(&scene_file).expect("scene");
    let Some(grin_scene::BoundsSpec::Sphere { center, radius }) =
        scene.medium.as_ref().map(|m| m.bounds.clone())
    else {
        panic!("luneburg.toml has a spherical medium")
    };
    let c = DVec3::from_array(center);
    let (w, h) = (48u32, 27u32);
    let cam = PinholeCamera::new(&scene.camera, w, h).expect("camera");

    // 1. The render's exit-direction AOV, every pixel through the lens (spp 1: the
    //    pixel-centre ray).
    let dir = tempfile::tempdir().expect("tmp");
    let out = dir.path().join("lune.exr");
    let o = run_render(&scene_file, &out, &["--size", "48x27", "--spp", "1"]);
    assert_ok(&o);
    let frame = Frame::read_exr(&out).expect("exr");
    let mut through = 0;
    let mut worst: f64 = 0.0;
    let mut worst_opd: f64 = 0.0;
    for py in 0..h {
        for px in 0..w {
            let d = cam.primary_ray(px, py, 0.5, 0.5);
            let p = frame.pixels[(py * w + px) as usize];
            match luneburg_exit(c, radius, cam.origin, d) {
                // Rays within 2% of grazing spend few steps inside; skip their exits.
                Some((_, q)) if p.status == 1.0 => {
                    let got = DVec3::from(p.exit_dir.map(f64::from));
                    worst = worst.max(got.angle_between(q));
                    through += 1;
                    // Exact optical path: with r(t) = p cos(t/R) + R d sin(t/R) (unit d,
                    // entry p relative to the centre, |p| = R), n^2 = 1 - (p.d/R)
                    // sin(2t/R), so OPL = integral of n^2 dt over t in [0, pi R / 2] =
                    // pi R / 2 - p.d; the straight chord is -2 p.d (ambient n = 1), so
                    // OPD = pi R / 2 + p.d.
                    let oc = cam.origin - c;
                    let b = oc.dot(d);
                    let entry =
                        oc + d * (-b - (b * b - oc.length_squared() + radius * radius).sqrt());
                    let opd_exact = std::f64::consts::FRAC_PI_2 * radius + entry.dot(d);
                    worst_opd = worst_opd.max((f64::from(p.opd) - opd_exact).abs());
                }
                Some(_) => panic!(
                    "pixel ({px}, {py}) should pass through the lens, status {}",
                    p.status
                ),
                None => assert_eq!(p.status, 0.0, "pixel ({px}, {py}) misses the lens"),
            }
        }
    }
    assert!(through > 100, "{through} pixels through the lens");
    // Sharma at ds = 0.01 with the Hermite exit: direction error ~1e-4 rad at worst (the
    // gradient jump at the surface limits the order), far below the ~0.3 rad spread.
    assert!(
        worst < 2e-3,
        "exit direction off the exact solution by {worst} rad"
    );
    // The OPD AOV (f32 in the EXR) against the exact optical path difference (measured
    // worst 5.7e-8 R); the OPD itself ranges from pi/2 - 1 = 0.57 (axis) to pi/2 (rim).
    assert!(
        worst_opd < 1e-6 * radius,
        "OPD off the exact solution by {worst_opd}"
    );

    // 2. A few of the same pixel rays through `grin trace`: exit point and direction.
    let pixels = [(24u32, 13u32), (20, 10), (30, 16), (18, 14), (27, 7)];
    let mut csv = String::from("ox,oy,oz,dx,dy,dz\n");
    for &(px, py) in &pixels {
        let d = cam.primary_ray(px, py, 0.5, 0.5);
        let o = cam.origin;
        csv += &format!("{},{},{},{},{},{}\n", o.x, o.y, o.z, d.x, d.y, d.z);
    }
    let rays = dir.path().join("rays.csv");
    let traced = dir.path().join("out.csv");
    std::fs::write(&rays, csv).expect("write rays");
    run_ok(&mut common::trace_cmd(&scene_file, &rays, &traced));
    for (row, &(px, py)) in read_table(&traced).iter().zip(&pixels) {
        let (p, q) = (vec3(row, ["px", "py", "pz"]), vec3(row, ["qx", "qy", "qz"]));
        assert_eq!(row["status"], "exited", "pixel ({px}, {py})");
        let d = cam.primary_ray(px, py, 0.5, 0.5);
        let (p_exact, q_exact) = luneburg_exit(c, radius, cam.origin, d).expect("hits the lens");
        assert!(
            (p - p_exact).length() < 1e-3,
            "pixel ({px}, {py}): exit {p} vs {p_exact}"
        );
        assert!(
            q.angle_between(q_exact) < 2e-3,
            "pixel ({px}, {py}): direction {q} vs {q_exact}"
        );
        // The render agrees with the trace for the same ray.
        let aov = frame.pixels[(py * w + px) as usize].exit_dir.map(f64::from);
        assert!(DVec3::from(aov).angle_between(q) < 1e-5);
    }
}

#[test]
fn scene_errors_fail_before_any_work_and_write_nothing() {
    let dir = tempfile::tempdir().expect("tmp");
    let bad = dir.path().join("bad.toml");
    std::fs::write(
        &bad,
        "[camera]\nposition = [0.0, 1.0, -4.0]\nlook_at = [0.0, 0.5, 0.0]\n\n[[object]]\nshape = { sphere = { center = [0.0, 0.0, 0.0], radius = 1.0 } }\nmaterial = \"velvet\"\n",
    )
    .expect("write");
    let out = dir.path().join("out.exr");
    // The default backend is the GPU: the scene error must come first regardless.
    let o = grin()
        .arg("render")
        .arg(&bad)
        .arg("-o")
        .arg(&out)
        .output()
        .expect("runs");
    let err = assert_failed(&o);
    assert_eq!(err.trim().lines().count(), 1, "one-line error: {err}");
    assert!(err.contains("bad.toml") && err.contains("velvet"), "{err}");
    assert!(!out.exists() && !dir.path().join("out.png").exists());

    // Degenerate camera: caught when the scene is resolved.
    std::fs::write(
        &bad,
        "[camera]\nposition = [0.0, 1.0, 0.0]\nlook_at = [0.0, 1.0, 0.0]\n",
    )
    .expect("write");
    let o = run_render(&bad, &out, &[]);
    assert_err(&o, "camera");

    // Bad flags and outputs.
    let good = scene_path("paper-b.toml");
    for (extra, needle) in [
        (&["--size", "0x10"][..], "size"),
        (&["--size", "big"][..], "WxH"),
        (&["--spp", "0"][..], "spp"),
    ] {
        let o = run_render(&good, &out, extra);
        assert_err(&o, needle);
    }
    let o = run_render(&good, &dir.path().join("out.png"), &[]);
    assert_err(&o, ".exr");
    let o = run_render(&good, &dir.path().join("missing/out.exr"), &[]);
    assert_err(&o, "does not exist");
    assert!(
        std::fs::read_dir(dir.path()).expect("ls").count() == 1,
        "only bad.toml remains"
    );
}

#[test]
fn interrupted_render_leaves_no_output_file() {
    let dir = tempfile::tempdir().expect("tmp");
    let out = dir.path().join("big.exr");
    let mut child = grin()
        .arg("render")
        .arg(scene_path("paper-a.toml"))
        .arg("-o")
        .arg(&out)
        .args(["--backend", "cpu", "--size", "1500x1500", "--spp", "32"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("spawn");
    std::thread::sleep(Duration::from_millis(1500));
    assert!(
        child.try_wait().expect("status").is_none(),
        "render finished too soon to interrupt"
    );
    // SIGTERM mid-render: grin's handler exits 130 having written nothing (the write
    // phase itself is interrupted in tests/output.rs).
    let killed = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .expect("kill");
    assert!(killed.success());
    let status = child.wait().expect("reaped");
    assert_eq!(status.code(), Some(130), "{status:?}");
    let left: Vec<_> = std::fs::read_dir(dir.path())
        .expect("ls")
        .map(|e| e.expect("entry").file_name())
        .collect();
    assert!(left.is_empty(), "files left behind: {left:?}");
}

#[test]
fn gpu_backend_renders_the_same_scene_as_the_cpu() {
    let dir = tempfile::tempdir().expect("tmp");
    let scene = scene_path("luneburg.toml");
    let args = ["--size", "48x28", "--spp", "1", "--json"];
    let cpu_out = dir.path().join("cpu.exr");
    let o = run_render(&scene, &cpu_out, &args);
    assert_ok(&o);
    let gpu_out = dir.path().join("gpu.exr");
    let o = grin()
        .arg("render")
        .arg(&scene)
        .arg("-o")
        .arg(&gpu_out)
        .args(["--backend", "gpu"])
        .args(args)
        .arg("--compare")
        .arg(&cpu_out)
        .output()
        .expect("grin runs");
    // CI installs lavapipe (mesa-vulkan-drivers): no adapter is a failure, said loudly.
    let summary = json(&o);
    assert_eq!(summary["backend"], "gpu");
    assert!(summary["adapter"].as_str().is_some_and(|a| !a.is_empty()));
    // The smooth lens meets the error budget on a coarser grid than 128 nodes (96 plus
    // margins), so the GPU bakes that and the bake has nothing to warn about. But its n
    // error (~1.5e-4) is more than the scene's fixed sharma steps are asked for (the
    // default 1e-4 rad): rays through the outer lens leave 1e-4..4e-4 rad off and their
    // own estimates say so (the drift of |T| from the bake's n), so those pixels end
    // `degraded` (116 of the 392 in the medium, measured), and that is the one warning
    // about the image (on lavapipe another says that `--backend cpu` is faster there).
    let warnings: Vec<&str> = summary["warnings"]
        .as_array()
        .expect("warnings")
        .iter()
        .filter_map(|w| w.as_str())
        .filter(|w| !w.contains("runs on a CPU adapter"))
        .collect();
    assert!(
        warnings.len() <= 1
            && warnings
                .iter()
                .all(|w| w.contains("left the medium `degraded`")),
        "{summary}"
    );
    let count = |k: &str| summary["status_counts"][k].as_u64().expect("status count");
    assert!(
        count("degraded") * 100 <= (count("exited") + count("degraded")) * 50,
        "{summary}"
    );
    let dims = summary["gpu_field"]["dims"]
        .as_array()
        .expect("gpu_field.dims");
    assert!(
        dims.iter().all(|d| d.as_u64().is_some_and(|d| d < 128)),
        "{summary}"
    );
    let cpu = Frame::read_exr(&cpu_out).expect("cpu exr");
    let gpu = Frame::read_exr(&gpu_out).expect("gpu exr");
    let (stats, _) = grin_render::image::diff_frames(&cpu, &gpu).expect("same size");
    eprintln!(
        "cpu vs gpu (luneburg 48x28): mean {:.2e}, p99 {:.2e}, max {:.2e}",
        stats.mean, stats.p99, stats.max
    );
    // The GPU marches a baked f32 copy of the analytic lens: the images agree except
    // for a few pixels along the lens rim and checker edges (tests/gpu.rs holds the
    // strict comparisons with the same baked field on both sides). An even height keeps
    // pixel rows off y = 0, a checker edge straight ahead: at 48x27 the middle row's
    // rays land on it, and f32 vs f64 picks the colour (22 pixels differed by ~0.7 once
    // the GPU baked the lens at 96 nodes).
    // Measured at 48x28 with the 96-node GPU bake: mean 5.2e-6, p99 5.9e-5, max 2.8e-4.
    assert!(
        stats.mean < 0.01,
        "mean per-pixel difference {}",
        stats.mean
    );
    assert!(
        stats.p99 < 0.01,
        "99th percentile per-pixel difference {}",
        stats.p99
    );
    // `--compare` printed the same metric and wrote the difference image.
    let cmp = &summary["comparison"];
    assert!(
        (cmp["mean"].as_f64().expect("mean") - stats.mean).abs() < 1e-9,
        "{cmp}"
    );
    assert_eq!(png_size(&dir.path().join("gpu-difference.png")), (48, 28));
    // A reference of another size is refused before rendering.
    let o = run_render(
        &scene,
        &dir.path().join("x.exr"),
        &[
            "--size",
            "20x10",
            "--compare",
            cpu_out.to_str().expect("utf8"),
        ],
    );
    assert_err(&o, "48x28");
    assert!(!dir.path().join("x.exr").exists());
    // The same outcome (exited and degraded both left the medium: the CPU traces the
    // analytic lens, the GPU its bake, whose error it flags).
    let outcome = |s: f32| if s == 5.0 { 1.0 } else { s };
    let same_status = cpu
        .pixels
        .iter()
        .zip(&gpu.pixels)
        .filter(|(a, b)| outcome(a.status) == outcome(b.status))
        .count();
    assert!(
        same_status * 100 >= cpu.pixels.len() * 97,
        "{same_status} of {} statuses agree",
        cpu.pixels.len()
    );
}

/// A field no automatic GPU bake within its memory cap resolves (a hot layer 0.15 thick
/// over a box 120 long) is rendered, with the warning on stderr and in the `--json`
/// summary, not silently.
#[test]
fn gpu_render_reports_an_under_resolved_bake() {
    let dir = tempfile::tempdir().expect("tmp");
    let out = dir.path().join("layer.exr");
    let scene = dir.path().join("layer.toml");
    std::fs::write(
        &scene,
        r#"[camera]
position = [0.0, 0.5, -2.0]
look_at = [0.0, 0.3, 20.0]
[medium]
bounds = { box = { min = [-60.0, -0.1, 0.0], max = [60.0, 1.5, 120.0] } }
field = { kind = "exponential-atmosphere", e = -6e-4, scale_height = 0.15 }
"#,
    )
    .expect("write scene");
    let o = run_ok(
        grin()
            .env("GRIN_CACHE_DIR", dir.path())
            .arg("render")
            .arg(&scene)
            .arg("-o")
            .arg(&out)
            .args([
                "--backend",
                "gpu",
                "--size",
                "32x18",
                "--spp",
                "1",
                "--json",
            ]),
    );
    let stderr = stderr(&o);
    assert!(
        stderr.contains("grin: warning:") && stderr.contains("under-resolved"),
        "{stderr}"
    );
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).expect("json");
    let warnings = summary["warnings"].as_array().expect("warnings array");
    assert!(
        warnings
            .iter()
            .any(|w| w.as_str().is_some_and(|w| w.contains("under-resolved"))),
        "{summary}"
    );
    // On a CPU adapter (lavapipe) the render says that `--backend cpu` is the faster
    // way here; on a GPU it says nothing of the kind.
    let on_cpu = summary["adapter"]
        .as_str()
        .is_some_and(|a| a.contains("Cpu"));
    let says = |w: &str| w.contains("CPU adapter") && w.contains("--backend cpu");
    assert_eq!(
        warnings.iter().any(|w| w.as_str().is_some_and(says)),
        on_cpu,
        "{summary}"
    );
    assert_eq!(stderr.contains("CPU adapter"), on_cpu, "{stderr}");
    assert!(out.exists());
}

/// The default GPU bake of every example scene meets its error budget (trilinear, else
/// tricubic, else a finer grid within grin_field's GPU_BAKE_MAX_BYTES): no scene renders
/// with the under-resolved warning.
#[test]
fn every_example_scene_gets_a_resolved_gpu_bake() {
    let dir = tempfile::tempdir().expect("tmp");
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data");
    let mut scenes: Vec<PathBuf> = std::fs::read_dir(data.join("scenes"))
        .expect("data/scenes")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    scenes.push(data.join("vdb/fire-haze.toml"));
    scenes.sort();
    assert!(scenes.len() >= 12, "{scenes:?}");
    for scene in &scenes {
        let summary = json(&run_ok(
            grin()
                .arg("render")
                .arg(scene)
                .arg("-o")
                .arg(dir.path().join("s.exr"))
                .args(["--size", "16x9", "--spp", "1", "--json"]),
        ));
        let warnings = summary["warnings"].as_array().expect("warnings");
        assert!(
            !warnings
                .iter()
                .any(|w| w.as_str().is_some_and(|w| w.contains("under-resolved"))),
            "{}: {summary}",
            scene.display()
        );
    }
}
