//! `[optics]` outputs of `grin render` against closed forms: a weak Gaussian plume's
//! displacement and schlieren signal against the straight-line integral of grad n (both
//! backends), its interferogram against the line integral of n - n_ambient, a Luneburg
//! lens's displacement against `grin trace` of the same rays, the shadowgraph's energy and
//! the lens's caustic, and a BOS round trip through a cross-correlation in numpy.
//!
//! Over 600 lines: one concept, each `[optics]` output against its closed form.

use common::{
    assert_err, assert_failed, assert_ok as ok, bos_plume_scene, exr_channels as channels,
    gpu_or_skip, grin, grin_args as run, read_table, render, render_json, render_with, scenes,
    stderr, stdout, vec3,
};
use grin_testkit as common;
use std::path::{Path, PathBuf};
use std::process::Command;

use glam::DVec3;
use grin_render::camera::PinholeCamera;
use grin_render::optics::{Plane, camera_angles, project_dir};

const A_WEAK: f64 = 1e-4;
const S: f64 = 0.25;
const WIDTH: u32 = 48;
const HEIGHT: u32 = 36;

/// A pinhole camera at `position` looking at `look_at` (up +y), WIDTH x HEIGHT.
fn pinhole(position: [f64; 3], look_at: [f64; 3], fov_y_deg: f64) -> PinholeCamera {
    let c = grin_scene::Camera {
        position,
        look_at,
        up: [0.0, 1.0, 0.0],
        fov_y_deg,
        focal_length_mm: None,
        sensor_height_mm: None,
        pixel_pitch_um: None,
        f_number: None,
        focus_distance: None,
    };
    PinholeCamera::new(&c, WIDTH, HEIGHT).expect("camera")
}

fn camera() -> PinholeCamera {
    pinhole([0.05, 0.03, -6.0], [0.05, 0.03, 0.0], 9.0)
}

/// A scene with one Gaussian plume (n = 1 - a exp(-r^2 / s^2)) at the origin, seen by
/// [`camera`], with the `[optics]` table `optics`, traced with rk4 at a fixed `step`, or
/// with grin's defaults (no integrator, no step) where `step` is 0.
fn plume_scene(dir: &Path, name: &str, a: f64, step: f64, optics: &str) -> PathBuf {
    let text = format!(
        r#"
[camera]
position = [0.05, 0.03, -6.0]
look_at = [0.05, 0.03, 0.0]
fov_y_deg = 9.0

[medium]
bounds = {{ box = {{ min = [-1.3, -1.3, -1.3], max = [1.3, 1.3, 1.3] }} }}
ambient_index = 1.0
field = {{ kind = "plume", plumes = [ {{ a = {a:e}, center = [0.0, 0.0, 0.0], s = {S} }} ] }}

[render]
width = {WIDTH}
height = {HEIGHT}
integrator = "rk4"
step = {{ fixed = {step} }}

[optics]
{optics}
"#
    );
    let text = if step == 0.0 {
        text.replace("integrator = \"rk4\"\nstep = { fixed = 0 }\n", "")
    } else {
        text
    };
    let p = dir.join(name);
    std::fs::write(&p, text).expect("scene");
    p
}

/// The straight-line prediction for pixel (i, j): the deflection vector (perpendicular to
/// the camera ray, radians) and the closest approach point on the ray, where a thin
/// symmetric lens bends it. For n = 1 - a exp(-|p|^2/s^2) along p = o + t d:
/// integral of grad n dt = (2a/s^2) b exp(-b^2/s^2) s sqrt(pi), b the closest-approach
/// vector; integral of (n - 1) dt = -a s sqrt(pi) exp(-b^2/s^2).
fn line_integrals(cam: &PinholeCamera, i: u32, j: u32, a: f64) -> (DVec3, DVec3, f64) {
    let d = cam.primary_ray(i, j, 0.5, 0.5);
    let t0 = -cam.origin.dot(d);
    let near = cam.origin + d * t0;
    let b2 = near.length_squared();
    let g = (-b2 / (S * S)).exp() * S * std::f64::consts::PI.sqrt();
    (near * (2.0 * a / (S * S)) * g, near, -a * g)
}

/// Displacement on a plane at z = 4 and the schlieren deflection of a weak plume match
/// the straight-line integral of grad n within 1 % (pixels whose prediction is over a
/// fifth of the largest), on the CPU and the GPU.
#[test]
fn weak_plume_displacement_and_schlieren_match_the_line_integral() {
    for step in [0.01, 0.0] {
        weak_plume_displacement_and_schlieren(step);
    }
}

/// The check above with rk4 at a fixed `step`, or with grin's defaults (`step` 0: `auto`
/// in the output's unit, 0.01 px, pilots choosing the method).
fn weak_plume_displacement_and_schlieren(step: f64) {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let disp_scene = plume_scene(
        d,
        "disp.toml",
        A_WEAK,
        step,
        "mode = \"displacement\"\nplane = { point = [0.0, 0.0, 4.0], normal = [0.0, 0.0, -1.0] }",
    );
    if step == 0.0 {
        let text = std::fs::read_to_string(&disp_scene).expect("scene");
        assert!(
            !text.contains("step =") && !text.contains("integrator"),
            "{text}"
        );
    }
    let sch_scene = plume_scene(
        d,
        "sch.toml",
        A_WEAK,
        0.01,
        "mode = \"schlieren\"\nknife = { angle_deg = 30.0, cutoff = 0.5, source_size_rad = 1e-3 }",
    );
    let cam = camera();
    let plane = Plane::new(
        &grin_scene::PlaneSpec {
            point: [0.0, 0.0, 4.0],
            normal: [0.0, 0.0, -1.0],
        },
        &cam,
    )
    .expect("plane");
    let backends: &[&str] = if gpu_or_skip() {
        &["cpu", "gpu"]
    } else {
        &["cpu"]
    };
    for backend in backends {
        let env_cache = d.join("cache");
        let out = d.join(format!("disp-{backend}.exr"));
        let o = grin()
            .env("GRIN_CACHE_DIR", &env_cache)
            .args(["render", "--backend", backend, "--json", "-o"])
            .arg(&out)
            .arg(&disp_scene)
            .output()
            .expect("grin");
        ok(&o);
        let (w, ch) = channels(&out);
        let (mut checked, mut worst_px, mut worst_w) = (0, 0.0f64, 0.0f64);
        let mut preds = Vec::new();
        for j in 0..HEIGHT {
            for i in 0..WIDTH {
                let (eps, near, _) = line_integrals(&cam, i, j, A_WEAK);
                let d0 = cam.primary_ray(i, j, 0.5, 0.5);
                let with = plane.hit(near, (d0 + eps).normalize()).expect("hit");
                let without = plane.hit(cam.origin, d0).expect("hit");
                let (cw, c0) = (plane.coords(with), plane.coords(without));
                let seen = project_dir(&cam, with - cam.origin).expect("front");
                preds.push((
                    [seen[0] - f64::from(i) - 0.5, seen[1] - f64::from(j) - 0.5],
                    [cw[0] - c0[0], cw[1] - c0[1]],
                ));
            }
        }
        let max_px = preds
            .iter()
            .fold(0.0f64, |m, p| m.max(p.0[0].hypot(p.0[1])));
        // Heat haze: a hundredth of a pixel here; 1 % of it is what is checked.
        assert!(
            max_px > 0.01,
            "the plume moves the background by {max_px} px"
        );
        for (idx, (px, world)) in preds.iter().enumerate() {
            let size = px[0].hypot(px[1]);
            if size < 0.2 * max_px {
                continue;
            }
            let got_px = [ch["displacement_px.X"][idx], ch["displacement_px.Y"][idx]];
            let got_w = [ch["displacement.U"][idx], ch["displacement.V"][idx]];
            let e_px = (got_px[0] - px[0]).hypot(got_px[1] - px[1]) / size;
            let e_w = (got_w[0] - world[0]).hypot(got_w[1] - world[1]) / world[0].hypot(world[1]);
            worst_px = worst_px.max(e_px);
            worst_w = worst_w.max(e_w);
            checked += 1;
            // The ST map reads the plate where the displacement points.
            let x = (idx % w) as f64 + 0.5 + got_px[0];
            assert!((ch["st.S"][idx] - x / f64::from(WIDTH)).abs() < 1e-6);
        }
        assert!(checked > 100, "{checked} pixels checked");
        assert!(
            worst_px < 0.01 && worst_w < 0.01,
            "{backend}: displacement off the line integral by {worst_px:.2e} (pixels), {worst_w:.2e} (plane)"
        );
        eprintln!(
            "{backend}: displacement vs line integral: worst {worst_px:.2e} (px), {worst_w:.2e} (plane), {checked} pixels, max {max_px:.2} px"
        );

        let out = d.join(format!("sch-{backend}.exr"));
        let o = grin()
            .env("GRIN_CACHE_DIR", &env_cache)
            .args(["render", "--backend", backend, "-o"])
            .arg(&out)
            .arg(&sch_scene)
            .output()
            .expect("grin");
        ok(&o);
        let (_, ch) = channels(&out);
        let (s30, c30) = 30f64.to_radians().sin_cos();
        let mut preds = Vec::new();
        for j in 0..HEIGHT {
            for i in 0..WIDTH {
                let (eps, _, _) = line_integrals(&cam, i, j, A_WEAK);
                let d0 = cam.primary_ray(i, j, 0.5, 0.5);
                let (a1, a0) = (
                    camera_angles(&cam, (d0 + eps).normalize()),
                    camera_angles(&cam, d0),
                );
                preds.push([a1[0] - a0[0], a1[1] - a0[1]]);
            }
        }
        let max_k = preds
            .iter()
            .fold(0.0f64, |m, p| m.max((p[0] * c30 + p[1] * s30).abs()));
        let mut worst = 0.0f64;
        for (idx, p) in preds.iter().enumerate() {
            let ek = p[0] * c30 + p[1] * s30;
            if ek.abs() < 0.2 * max_k {
                continue;
            }
            // Linear range: I - 1 = e.k / (2 a (1 - c)) = e.k / 1e-3.
            let want = 1.0 + ek / 1e-3;
            let got = ch["schlieren"][idx];
            worst = worst.max(((got - 1.0) - (want - 1.0)).abs() / (want - 1.0).abs());
        }
        assert!(
            worst < 0.01,
            "{backend}: schlieren signal off by {worst:.2e}"
        );
        eprintln!("{backend}: schlieren vs line integral: worst {worst:.2e}");
    }
}

/// The interferogram's phase is the line integral of n - n_ambient over the wavelength
/// within 1e-3 waves on the CPU (a plume weak enough that the bending's second-order path
/// change is 1e-4 waves), and the GPU's phase is the CPU's within 0.01 waves, for that
/// plume and for one of 100 waves (the GPU summed the ~1 m optical path in f32 and read a
/// 100-wave plume as 96.8 waves, 1.5 waves rms off the CPU).
#[test]
fn interferogram_phase_is_the_line_integral_of_the_index() {
    let dir = tempfile::tempdir().expect("tempdir");
    let cam = camera();
    // a s sqrt(pi) / 532 nm = 100 waves at the plume's centre.
    let a100 = 100.0 * 532e-9 / (S * std::f64::consts::PI.sqrt());
    // rk4 at a fixed step; then grin's defaults (`auto` in waves, 0.01).
    for (a, deepest_min, step) in [(1e-5, 5.0, 0.005), (a100, 99.0, 0.005), (1e-5, 5.0, 0.0)] {
        let scene = plume_scene(
            dir.path(),
            "fringes.toml",
            a,
            step,
            "mode = \"interferogram\"\nwavelength_nm = 532.0",
        );
        let mut phases = Vec::new();
        for backend in ["cpu", "gpu"] {
            if backend == "gpu" && !gpu_or_skip() {
                continue;
            }
            let out = dir.path().join(format!("fringes-{backend}.exr"));
            let o = render(&scene, &out, backend);
            ok(&o);
            let (_, ch) = channels(&out);
            let (mut worst, mut deepest, mut centre) = (0.0f64, 0.0f64, 0.0f64);
            for j in 0..HEIGHT {
                for i in 0..WIDTH {
                    let (_, _, opd) = line_integrals(&cam, i, j, a);
                    let want = opd / 532e-9;
                    let idx = (j * WIDTH + i) as usize;
                    let got = ch["phase_waves"][idx];
                    worst = worst.max((got - want).abs());
                    if want.abs() > deepest {
                        (deepest, centre) = (want.abs(), got);
                    }
                    let fringe = 0.5 * (1.0 + (std::f64::consts::TAU * got).cos());
                    assert!((ch["intensity"][idx] - fringe).abs() < 1e-4);
                }
            }
            assert!(deepest > deepest_min, "only {deepest} waves");
            eprintln!(
                "{backend}, a = {a:.3e}, step {step}: interferogram vs line integral: worst \
                 {worst:.2e} waves of {deepest:.4} (reads {centre:.4} there); {}",
                stderr(&o)
                    .lines()
                    .find(|l| l.starts_with("auto "))
                    .unwrap_or("")
            );
            // The line integral is the weak plume's answer. The strong one bends its rays
            // (a second-order change of the path: 0.044 waves on its flank, 1e-3 at its
            // centre, where the bending is least).
            let limit = match (a < 1e-4, step == 0.0) {
                // The default asks 0.01 waves of the output.
                (true, true) => 0.01,
                (true, false) => 1e-3,
                (false, _) => 0.05,
            };
            assert!(
                worst < limit,
                "{backend}: phase off by {worst:.2e} waves (of {deepest:.1})"
            );
            assert!(
                (centre.abs() - deepest).abs() < 2e-3,
                "{backend}: the centre reads {centre} waves, the line integral {deepest}"
            );
            phases.push(ch["phase_waves"].clone());
        }
        if let [cpu, gpu] = &phases[..] {
            let worst = cpu
                .iter()
                .zip(gpu)
                .map(|(c, g)| (c - g).abs())
                .fold(0.0, f64::max);
            eprintln!("a = {a:.3e}: GPU vs CPU phase: worst {worst:.2e} waves");
            assert!(
                worst < 0.01,
                "the GPU's phase is {worst:.3} waves off the CPU's"
            );
        }
    }
}

/// The example interferogram (data/scenes/optics) with its own settings: the GPU's phase
/// is the CPU's within 0.01 waves.
#[test]
fn example_interferogram_agrees_across_backends() {
    if !gpu_or_skip() {
        return;
    }
    let dir = tempfile::tempdir().expect("tempdir");
    let scene = scenes().join("optics/interferogram.toml");
    let phase = |backend: &str| {
        let out = dir.path().join(format!("{backend}.exr"));
        let o = render_with(&scene, &out, &["--backend", backend, "--size", "64x64"]);
        ok(&o);
        channels(&out).1["phase_waves"].clone()
    };
    let (cpu, gpu) = (phase("cpu"), phase("gpu"));
    let deepest = cpu.iter().fold(0.0f64, |m, p| m.max(p.abs()));
    let worst = cpu
        .iter()
        .zip(&gpu)
        .map(|(c, g)| (c - g).abs())
        .fold(0.0, f64::max);
    eprintln!("example interferogram: GPU vs CPU worst {worst:.2e} waves of {deepest:.2}");
    assert!(deepest > 5.0, "only {deepest} waves");
    assert!(worst < 0.01, "GPU off the CPU by {worst:.3} waves");
}

/// A strong field: the displacement AOV of a Luneburg lens on the CPU agrees with `grin
/// trace` of the same pixel-centre rays to 1e-6 of the image width.
#[test]
fn luneburg_displacement_agrees_with_grin_trace() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let scene = d.join("lens.toml");
    std::fs::write(
        &scene,
        format!(
            r#"
[camera]
position = [0.1, 0.05, -5.0]
look_at = [0.0, 0.0, 0.0]
fov_y_deg = 25.0
[medium]
bounds = {{ sphere = {{ center = [0.0, 0.0, 0.0], radius = 1.0 }} }}
field = {{ kind = "luneburg" }}
[render]
width = {WIDTH}
height = {HEIGHT}
integrator = "rk4"
step = {{ fixed = 0.01 }}
[optics]
mode = "displacement"
plane = {{ point = [0.0, 0.0, 3.0], normal = [0.0, 0.2, -1.0] }}
"#
        ),
    )
    .expect("scene");
    let out = d.join("lens.exr");
    ok(&render(&scene, &out, "cpu"));
    let (_, ch) = channels(&out);
    let cam = pinhole([0.1, 0.05, -5.0], [0.0, 0.0, 0.0], 25.0);
    let plane = Plane::new(
        &grin_scene::PlaneSpec {
            point: [0.0, 0.0, 3.0],
            normal: [0.0, 0.2, -1.0],
        },
        &cam,
    )
    .expect("plane");
    let mut table = String::from("ox,oy,oz,dx,dy,dz\n");
    for j in 0..HEIGHT {
        for i in 0..WIDTH {
            let v = cam.primary_ray(i, j, 0.5, 0.5);
            let o = cam.origin;
            table += &format!("{},{},{},{},{},{}\n", o.x, o.y, o.z, v.x, v.y, v.z);
        }
    }
    let rays = d.join("rays.csv");
    std::fs::write(&rays, table).expect("rays");
    let traced = d.join("traced.csv");
    ok(&run(&[
        "trace",
        scene.to_str().expect("utf8"),
        "--rays",
        rays.to_str().expect("utf8"),
        "-o",
        traced.to_str().expect("utf8"),
    ]));
    let (mut worst, mut bent) = (0.0f64, 0);
    for (idx, row) in read_table(&traced).iter().enumerate() {
        let (i, j) = ((idx as u32) % WIDTH, (idx as u32) / WIDTH);
        let status = row["status"].as_str();
        let d0 = cam.primary_ray(i, j, 0.5, 0.5);
        let (p, q) = match status {
            "exited" => (vec3(row, ["px", "py", "pz"]), vec3(row, ["qx", "qy", "qz"])),
            "missed" => (cam.origin, d0),
            other => panic!("pixel {i},{j}: {other}"),
        };
        let Some(landed) = plane.hit(p, q) else {
            assert_eq!(ch["valid"][idx], 0.0);
            continue;
        };
        let seen = project_dir(&cam, landed - cam.origin).expect("front");
        let want = [seen[0] - f64::from(i) - 0.5, seen[1] - f64::from(j) - 0.5];
        let got = [ch["displacement_px.X"][idx], ch["displacement_px.Y"][idx]];
        if want[0].hypot(want[1]) > 1.0 {
            bent += 1;
        }
        worst = worst.max((got[0] - want[0]).hypot(got[1] - want[1]));
    }
    assert!(bent > 50, "only {bent} pixels moved by more than a pixel");
    let limit = 1e-6 * f64::from(WIDTH);
    assert!(worst < limit, "worst {worst:.3e} px (limit {limit:.1e})");
    eprintln!("luneburg displacement vs grin trace: worst {worst:.2e} px");
}

fn shadowgraph(
    dir: &Path,
    name: &str,
    field: &str,
    bounds: &str,
    distance: f64,
    backend: &str,
) -> (serde_json::Value, Vec<f64>) {
    let rk4 = "integrator = \"rk4\"\nstep = { fixed = 0.01 }";
    shadowgraph_with(dir, name, field, bounds, distance, backend, rk4)
}

/// [`shadowgraph`] with `method` as its `[render]` lines (empty: the defaults); returns
/// the whole `--json` summary.
fn shadowgraph_with(
    dir: &Path,
    name: &str,
    field: &str,
    bounds: &str,
    distance: f64,
    backend: &str,
    method: &str,
) -> (serde_json::Value, Vec<f64>) {
    let scene = dir.join(format!("{name}.toml"));
    std::fs::write(
        &scene,
        format!(
            r#"
[camera]
position = [0.0, 0.0, -5.0]
look_at = [0.0, 0.0, 0.0]
[medium]
bounds = {bounds}
field = {field}
[render]
width = 48
height = 48
{method}
[optics]
mode = "shadowgraph"
screen = {{ distance = {distance}, rays_per_pixel = 36 }}
"#
        ),
    )
    .expect("scene");
    let out = dir.join(format!("{name}.exr"));
    let v = render_json(&scene, &out, backend);
    assert_eq!(v["backend"], backend, "{v}");
    let (_, ch) = channels(&out);
    let total: f64 = ch["intensity"].iter().sum();
    let mut optics = v["optics"].clone();
    optics["mean_intensity"] = serde_json::json!(total / (48.0 * 48.0));
    optics["summary"] = v;
    (optics, ch["intensity"].clone())
}

/// The shadowgraph's accuracy is asked in its own unit, the screen's bins (0.01 by
/// default): with no integrator or step the pilots are the beam's rays, measured where
/// they land on the screen, and the image matches rk4 at 0.01 R (mean |difference| under
/// 0.2 % of the undisturbed intensity; measured: the same image) at a fraction of its
/// cost (measured: sharma at 0.5, 30 evaluations a ray, where rk4 at 0.01 pays ~800).
#[test]
fn shadowgraph_default_is_held_in_screen_bins() {
    let dir = tempfile::tempdir().expect("tempdir");
    let plume = format!(
        "{{ kind = \"plume\", plumes = [ {{ a = 5e-3, center = [0.0, 0.0, 0.0], s = {S} }} ] }}"
    );
    let cube = "{ box = { min = [-1.0, -1.0, -1.0], max = [1.0, 1.0, 1.0] } }";
    let (reference, ri) = shadowgraph(dir.path(), "rk4", &plume, cube, 2.0, "cpu");
    let (default, di) = shadowgraph_with(dir.path(), "auto", &plume, cube, 2.0, "cpu", "");
    let auto = &default["summary"]["auto"];
    assert_eq!(auto["unit"], "px", "{auto}");
    assert!(auto["asked"].as_f64().expect("asked") <= 0.01, "{auto}");
    let diff = ri.iter().zip(&di).map(|(a, b)| (a - b).abs()).sum::<f64>() / ri.len() as f64;
    eprintln!(
        "shadowgraph default: {}; mean |difference| to rk4 at 0.01: {diff:.2e}",
        auto["chosen"]
    );
    assert!(diff < 2e-3, "{diff}");
    let evals = auto["chosen"]["evals_per_ray"].as_f64().expect("evals");
    assert!(evals < 100.0, "{auto}");
    assert_eq!(reference["rays_on_screen"], default["rays_on_screen"]);
}

/// Shadowgraph: a plume's screen keeps the beam's energy within 1 %; a Luneburg
/// lens's caustic is brightest on the screen at its exact focus, the far side of the
/// sphere (distance = radius).
#[test]
fn shadowgraph_conserves_energy_and_focuses_where_the_lens_does() {
    let dir = tempfile::tempdir().expect("tempdir");
    let plume = format!(
        "{{ kind = \"plume\", plumes = [ {{ a = 5e-3, center = [0.0, 0.0, 0.0], s = {S} }} ] }}"
    );
    let (weak, _) = shadowgraph(
        dir.path(),
        "weak",
        &plume,
        "{ box = { min = [-1.0, -1.0, -1.0], max = [1.0, 1.0, 1.0] } }",
        2.0,
        "cpu",
    );
    let mean = weak["mean_intensity"].as_f64().expect("mean");
    assert!((mean - 1.0).abs() < 0.01, "{weak}");
    let peak = weak["peak_intensity"].as_f64().expect("peak");
    assert!(peak > 1.05, "the plume shows: {weak}");

    let lens = "{ kind = \"luneburg\" }";
    let ball = "{ sphere = { center = [0.0, 0.0, 0.0], radius = 1.0 } }";
    let peaks: Vec<(f64, f64)> = [0.6, 0.8, 1.0, 1.2, 1.5]
        .iter()
        .map(|&z| {
            let (v, _) = shadowgraph(dir.path(), &format!("lens{z}"), lens, ball, z, "cpu");
            (z, v["peak_intensity"].as_f64().expect("peak"))
        })
        .collect();
    let brightest = peaks
        .iter()
        .fold((0.0, 0.0), |b, &p| if p.1 > b.1 { p } else { b });
    assert_eq!(brightest.0, 1.0, "{peaks:?}");
    assert!(brightest.1 > 50.0, "{peaks:?}");
}

/// The shadowgraph on the GPU: the beam as an orthographic camera's pixel centres, one
/// frame of the marcher (its baked field, f32), binned like the CPU's f64 beam. The
/// plume's screen keeps the energy and matches the CPU's image (mean |difference| under
/// 2 % of the mean intensity); the Luneburg lens focuses on the screen at its radius.
#[test]
fn shadowgraph_on_the_gpu_matches_the_cpu() {
    if !gpu_or_skip() {
        return;
    }
    let dir = tempfile::tempdir().expect("tempdir");
    let plume = format!(
        "{{ kind = \"plume\", plumes = [ {{ a = 5e-3, center = [0.0, 0.0, 0.0], s = {S} }} ] }}"
    );
    let cube = "{ box = { min = [-1.0, -1.0, -1.0], max = [1.0, 1.0, 1.0] } }";
    let (cpu, ci) = shadowgraph(dir.path(), "c", &plume, cube, 2.0, "cpu");
    let (gpu, gi) = shadowgraph(dir.path(), "g", &plume, cube, 2.0, "gpu");
    let mean = gpu["mean_intensity"].as_f64().expect("mean");
    assert!((mean - 1.0).abs() < 0.01, "{gpu}");
    let diff = ci.iter().zip(&gi).map(|(a, b)| (a - b).abs()).sum::<f64>() / ci.len() as f64;
    eprintln!(
        "shadowgraph GPU vs CPU: mean |difference| {diff:.4}; peaks {} / {}",
        cpu["peak_intensity"], gpu["peak_intensity"]
    );
    assert!(diff < 0.02, "{diff}");
    let lens = "{ kind = \"luneburg\" }";
    let ball = "{ sphere = { center = [0.0, 0.0, 0.0], radius = 1.0 } }";
    let peak = |z: f64| {
        let (v, _) = shadowgraph(dir.path(), &format!("gl{z}"), lens, ball, z, "gpu");
        v["peak_intensity"].as_f64().expect("peak")
    };
    let (near, focus) = (peak(0.6), peak(1.0));
    eprintln!("GPU Luneburg caustic: peak {near} at 0.6 R, {focus} at R");
    assert!(focus > 50.0 && focus > 2.0 * near, "{near} {focus}");
}

/// The BOS tests' `[optics]`: dots on a plane 6 m past the plume.
const BOS_OPTICS: &str = r#"[optics]
mode = "bos"
plane = { point = [0.0, 0.0, 6.0], normal = [0.0, 0.0, -1.0] }
dots = { diameter = 0.05, density = 0.4, seed = 3 }
"#;

/// The BOS tests' scene in `d`: the plume seen through a 12 degree view, `size` pixels
/// square, rk4 at `step` (0: grin's defaults), with [`BOS_OPTICS`].
fn bos_scene(d: &Path, size: u32, step: f64) -> PathBuf {
    let scene = d.join("bos.toml");
    std::fs::write(
        &scene,
        bos_plume_scene("fov_y_deg = 12.0", size, size, step, BOS_OPTICS),
    )
    .expect("scene");
    scene
}

/// BOS on both backends: the GPU's distorted dot image and true displacement (its rays
/// through the GPU's bake, f32) agree with the CPU's, both with the default accuracy (no
/// integrator named): displacement within 0.01 px at the 99th percentile, dot images
/// within 2 % of their range on average (measured: 4.5e-5 px of up to 0.70 px, 4.6e-6).
#[test]
fn bos_on_the_gpu_matches_the_cpu() {
    if !gpu_or_skip() {
        return;
    }
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let scene = bos_scene(d, 96, 0.0);
    let render_on = |backend: &str| {
        let out = d.join(format!("bos-{backend}.exr"));
        ok(&render(&scene, &out, backend));
        channels(&out).1
    };
    let (cpu, gpu) = (render_on("cpu"), render_on("gpu"));
    let mut diffs: Vec<f64> = cpu["displacement_px.X"]
        .iter()
        .zip(&gpu["displacement_px.X"])
        .chain(
            cpu["displacement_px.Y"]
                .iter()
                .zip(&gpu["displacement_px.Y"]),
        )
        .map(|(a, b)| (a - b).abs())
        .collect();
    diffs.sort_by(f64::total_cmp);
    let p99 = diffs[diffs.len() * 99 / 100];
    let largest = cpu["displacement_px.X"]
        .iter()
        .chain(&cpu["displacement_px.Y"])
        .fold(0.0f64, |m, v| m.max(v.abs()));
    let image = cpu["distorted"]
        .iter()
        .zip(&gpu["distorted"])
        .map(|(a, b)| (a - b).abs())
        .sum::<f64>()
        / cpu["distorted"].len() as f64;
    eprintln!(
        "BOS GPU vs CPU: displacement p99 {p99:.2e} px (largest {largest:.2} px), dot image mean |difference| {image:.2e}"
    );
    assert!(largest > 0.3, "the plume shows: {largest}");
    assert!(p99 < 0.01, "{p99}");
    assert!(image < 0.02, "{image}");
}

/// BOS round trip: the reference and distorted dot images, cross-correlated window by
/// window in numpy (normalized cross-correlation, parabolic sub-pixel peak), give back the
/// true displacement the render wrote, within 0.15 px RMS.
#[test]
fn bos_pair_round_trips_through_cross_correlation() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let scene = bos_scene(d, 160, 0.01);
    let out = d.join("bos.exr");
    ok(&render(&scene, &out, "cpu"));
    assert!(d.join("bos.png").exists() && d.join("bos-reference.png").exists());
    let (_, ch) = channels(&out);
    for name in [
        "reference",
        "distorted",
        "displacement_px.X",
        "displacement_px.Y",
    ] {
        let bytes: Vec<u8> = ch[name]
            .iter()
            .flat_map(|v| (*v as f32).to_le_bytes())
            .collect();
        std::fs::write(d.join(format!("{name}.f32")), bytes).expect("raw");
    }
    let script = d.join("xcorr.py");
    std::fs::write(
        &script,
        r#"
import sys
import numpy as np
d, n = sys.argv[1], 160
load = lambda name: np.fromfile(f"{d}/{name}.f32", dtype="<f4").reshape(n, n).astype(float)
ref, dis = load("reference"), load("distorted")
tx, ty = load("displacement_px.X"), load("displacement_px.Y")
win, search, errs, moved = 24, 4, [], 0
for y0 in range(search + 8, n - win - search - 8, 8):
    for x0 in range(search + 8, n - win - search - 8, 8):
        a = dis[y0:y0 + win, x0:x0 + win]
        a = (a - a.mean()) / (a.std() + 1e-12)
        score = np.full((2 * search + 1, 2 * search + 1), -np.inf)
        for dy in range(-search, search + 1):
            for dx in range(-search, search + 1):
                b = ref[y0 + dy:y0 + dy + win, x0 + dx:x0 + dx + win]
                b = (b - b.mean()) / (b.std() + 1e-12)
                score[dy + search, dx + search] = (a * b).mean()
        iy, ix = np.unravel_index(np.argmax(score), score.shape)
        if not (0 < iy < 2 * search and 0 < ix < 2 * search):
            continue
        def peak(m, c, p):
            den = m - 2 * c + p
            return 0.0 if den == 0 else 0.5 * (m - p) / den
        sx = ix - search + peak(score[iy, ix - 1], score[iy, ix], score[iy, ix + 1])
        sy = iy - search + peak(score[iy - 1, ix], score[iy, ix], score[iy + 1, ix])
        gx = tx[y0:y0 + win, x0:x0 + win].mean()
        gy = ty[y0:y0 + win, x0:x0 + win].mean()
        if np.hypot(gx, gy) > 0.5:
            moved += 1
        errs.append(np.hypot(sx - gx, sy - gy))
errs = np.array(errs)
print(f"{len(errs)} {moved} {np.sqrt((errs ** 2).mean()):.4f} {errs.max():.4f}")
"#,
    )
    .expect("script");
    let o = Command::new("/usr/bin/python3")
        .arg(&script)
        .arg(d)
        .output()
        .expect("numpy (python3-numpy, installed by scripts/setup.sh)");
    ok(&o);
    let text = stdout(&o);
    let v: Vec<f64> = text
        .split_whitespace()
        .map(|x| x.parse().expect("number"))
        .collect();
    let (windows, moved, rms, max) = (v[0], v[1], v[2], v[3]);
    eprintln!(
        "BOS round trip: {windows} windows, {moved} moved > 0.5 px, rms {rms} px, max {max} px"
    );
    assert!(windows > 100.0 && moved > 20.0, "{text}");
    assert!(rms < 0.15, "{text}");
}

/// BOS images through a lens: with `f_number` (and spp > 1) the pair is rendered as
/// beauty images of the dots plane through the camera's aperture. Focused on the dots,
/// the reference is the point-sampled one, anti-aliased (correlation > 0.9); focused at
/// a quarter of the distance, the dots blur (the image's contrast drops by over a third), and the
/// plume still moves them (distorted differs from reference).
#[test]
fn bos_images_go_through_the_lens() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let scene = |name: &str, lens: &str, spp: u32| {
        let p = d.join(name);
        let extra = format!(
            "spp = {spp}\n[optics]\nmode = \"bos\"\n\
             plane = {{ point = [0.0, 0.0, 6.0], normal = [0.0, 0.0, -1.0] }}\n\
             dots = {{ diameter = 0.08, density = 0.4, seed = 3 }}\n"
        );
        std::fs::write(&p, bos_plume_scene(lens, 64, 64, 0.02, &extra)).expect("scene");
        let out = d.join(format!("{name}.exr"));
        let summary = render_json(&p, &out, "cpu");
        (channels(&out).1, summary)
    };
    // 12 degrees (2 atan(10.5 / 100)): a 21 mm sensor behind 100 mm; at f/1.4 a 71 mm aperture, which
    // focused at 3 m blurs the dots 12 m away by a 214 mm disc (2.7 dot diameters).
    let pinhole = format!("fov_y_deg = {}", 2.0 * 0.105f64.atan().to_degrees());
    let focused =
        "focal_length_mm = 100.0\nsensor_height_mm = 21.0\nf_number = 1.4\nfocus_distance = 12.0";
    let near =
        "focal_length_mm = 100.0\nsensor_height_mm = 21.0\nf_number = 1.4\nfocus_distance = 3.0";
    let (p, ps) = scene("pinhole.toml", &pinhole, 1);
    let (f, fs) = scene("focused.toml", focused, 32);
    let (n, _) = scene("near.toml", near, 32);
    assert_eq!(ps["optics"]["images"], "pixel centres", "{ps}");
    assert_eq!(fs["optics"]["images"], "rendered", "{fs}");
    let stats = |v: &[f64]| {
        let m = v.iter().sum::<f64>() / v.len() as f64;
        let sd = (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / v.len() as f64).sqrt();
        (m, sd)
    };
    let corr = |a: &[f64], b: &[f64]| {
        let ((ma, sa), (mb, sb)) = (stats(a), stats(b));
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - ma) * (y - mb))
            .sum::<f64>()
            / (a.len() as f64 * sa * sb)
    };
    let c = corr(&p["reference"], &f["reference"]);
    let (sd_focused, sd_near) = (stats(&f["reference"]).1, stats(&n["reference"]).1);
    let moved = corr(&f["reference"], &f["distorted"]);
    eprintln!(
        "BOS through a lens: in-focus reference vs pinhole correlation {c:.3}; contrast (sd) in focus {sd_focused:.3}, defocused {sd_near:.3}; reference vs distorted correlation {moved:.3}"
    );
    assert!(c > 0.9, "{c}");
    assert!(sd_near < 0.67 * sd_focused, "{sd_near} vs {sd_focused}");
    assert!(moved < 0.98, "{moved}");
    // The true displacement stays the pixel-centre rays': the same with and without the lens.
    let dx = |m: &std::collections::HashMap<String, Vec<f64>>| m["displacement_px.X"].clone();
    let worst = dx(&p)
        .iter()
        .zip(dx(&f))
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f64, f64::max);
    assert!(worst < 1e-9, "{worst}");
}

/// One scene, two outputs: `--beauty` renders the [optics] output and the beauty image of
/// the same scene file in one run (a compositor kept two copies of a scene to get a plate
/// and its ST map). The beauty equals a render of the scene without [optics], bit for bit.
#[test]
fn one_scene_gives_its_optics_output_and_its_beauty() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let scene = scenes().join("optics/displacement.toml");
    let (out, beauty) = (d.join("disp.exr"), d.join("plate.exr"));
    let o = render_with(
        &scene,
        &out,
        &[
            "--beauty",
            beauty.to_str().expect("utf8"),
            "--backend",
            "cpu",
            "--size",
            "48x48",
            "--json",
        ],
    );
    ok(&o);
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("json");
    assert_eq!(v.as_array().map(Vec::len), Some(2), "{v}");
    assert!(d.join("disp.png").exists() && d.join("plate.png").exists());
    let (_, disp) = channels(&out);
    assert!(disp.contains_key("displacement_px.X"), "{:?}", disp.keys());
    let (_, plate) = channels(&beauty);
    // The same scene without its [optics] table, rendered alone.
    let text = std::fs::read_to_string(&scene).expect("scene");
    let bare = d.join("bare.toml");
    std::fs::write(
        &bare,
        text.split("[optics]").next().expect("before [optics]"),
    )
    .expect("write");
    let alone = d.join("alone.exr");
    ok(&render_with(
        &bare,
        &alone,
        &["--backend", "cpu", "--size", "48x48"],
    ));
    let (_, want) = channels(&alone);
    for ch in ["R", "G", "B", "aov.exit_dir.X", "aov.opd"] {
        assert_eq!(plate[ch], want[ch], "channel {ch}");
    }
    // A sequence: each frame's output and its beauty beside it.
    let o = render_with(
        &scene,
        &d.join("st.####.exr"),
        &[
            "--beauty",
            d.join("plate.####.exr").to_str().expect("utf8"),
            "--frames",
            "0..1",
            "--backend",
            "cpu",
            "--size",
            "16x16",
            "--json",
        ],
    );
    ok(&o);
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("json");
    assert_eq!(v.as_array().map(Vec::len), Some(4), "{v}");
    for name in [
        "st.0000.exr",
        "plate.0000.exr",
        "st.0001.exr",
        "plate.0001.exr",
    ] {
        assert!(d.join(name).exists(), "{name}");
    }
    // Refused: a scene with no [optics], and a beauty named as the output.
    let lens = scenes().join("luneburg.toml");
    let o = render_with(
        &lens,
        &d.join("l.exr"),
        &["--beauty", d.join("lb.exr").to_str().expect("utf8")],
    );
    assert_err(&o, "has no [optics] output");
    let o = render_with(&scene, &out, &["--beauty", out.to_str().expect("utf8")]);
    assert_err(&o, "needs a name of its own");
}

/// Errors of the optical outputs name the scene file, as every other error does: a
/// shadowgraph beam too large for one GPU frame (it was a bare `[optics] ...` line).
#[test]
fn optics_errors_name_the_scene() {
    let dir = tempfile::tempdir().expect("tempdir");
    let example = scenes().join("optics/shadowgraph.toml");
    let text = std::fs::read_to_string(example).expect("scene");
    let scene = dir.path().join("beam.toml");
    std::fs::write(
        &scene,
        text.replace("rays_per_pixel = 16", "rays_per_pixel = 1024"),
    )
    .expect("write");
    let out = dir.path().join("beam.exr");
    let o = render_with(&scene, &out, &["--backend", "gpu", "--size", "512x512"]);
    let err = assert_failed(&o);
    assert!(
        err.contains(&format!(
            "grin: error: {}: [optics] the shadowgraph's beam is",
            scene.display()
        )),
        "{err}"
    );
    assert!(!out.exists());
}

/// On the GPU an `[optics]` output reads back only the channels it is made of (28 bytes
/// a pixel for schlieren, 4 for an interferogram, against 64 for every channel), with
/// the same images and the same summary (steps, evaluations and statuses counted on the
/// device) as a renderer that reads every channel.
#[test]
fn a_gpu_optics_render_reads_back_only_its_channels() {
    if !gpu_or_skip() {
        return;
    }
    use grin_pipeline::{Backend, Quiet, Renderer};
    let narrow = Renderer::new(Backend::Gpu, false);
    let whole = Renderer::new(Backend::Gpu, false).reading_every_channel();
    let (width, height) = (64u32, 48u32);
    let pixels = u64::from(width * height);
    for (mode, bytes_per_pixel) in [("schlieren", 28), ("interferogram", 4)] {
        let path = scenes().join(format!("optics/{mode}.toml"));
        let mut scene = grin_scene::load_scene(&path).expect("scene");
        (scene.render.width, scene.render.height) = (width, height);
        let dir = path.parent().expect("scene dir");
        let render = |r: &Renderer| r.render(scene.clone(), dir, mode, &Quiet).expect("render");
        let (n, w) = (render(&narrow), render(&whole));
        let (nb, wb) = (
            n.report.read_back_bytes.expect("GPU bytes"),
            w.report.read_back_bytes.expect("GPU bytes"),
        );
        eprintln!("{mode}: {nb} bytes read back, {wb} reading every channel");
        // The channels, 64 bytes of counts, and the passes' timestamps as a whole read's.
        assert_eq!(wb + 64, nb + pixels * (64 - bytes_per_pixel), "{mode}");
        assert!(
            nb >= pixels * bytes_per_pixel + 64 && nb < pixels * bytes_per_pixel + 1024,
            "{mode}: {nb}"
        );
        assert_eq!(n.report.status_counts, w.report.status_counts, "{mode}");
        assert_eq!(n.report.status_counts["exited"], pixels as usize, "{mode}");
        for (a, b) in [
            (n.report.steps_per_ray, w.report.steps_per_ray),
            (n.report.evals_per_ray, w.report.evals_per_ray),
        ] {
            assert!(
                a > 1.0 && (a - b).abs() <= 1e-12 * b,
                "{mode}: {a} against {b}"
            );
        }
        assert_eq!(n.image.names(), w.image.names(), "{mode}");
        for ((name, a), (_, b)) in n.image.channels.iter().zip(&w.image.channels) {
            let same = a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits());
            assert!(same, "{mode}: channel {name} differs from a whole read's");
        }
    }
}
