//! End-to-end tests of `grin trace`: ray table in, ray table out, through the real
//! scene loader and field profiles.
//!
//! One concept, one file: a test per promise of `grin trace`, through the binary.

use common::{TestDir as Dir, assert_err, assert_failed, assert_ok, json, stderr};
use grin_testkit as common;
use std::path::Path;
use std::process::Output;

const HEADER: &str = "ox,oy,oz,dx,dy,dz,status,px,py,pz,qx,qy,qz,opl,length,steps,evals";

/// A Luneburg lens of radius 1.5 centred at (0.5, 0, 0).
const LUNEBURG_SCENE: &str = r#"
[camera]
position = [0.0, 0.0, -6.0]
look_at = [0.0, 0.0, 0.0]

[medium]
bounds = { sphere = { center = [0.5, 0.0, 0.0], radius = 1.5 } }
field = { kind = "luneburg" }

[render]
integrator = "sharma"
step = { fixed = 0.004 }
"#;

fn run(args: &[&Path], extra: &[&str]) -> Output {
    common::trace_cmd(args[0], args[1], args[2])
        .args(extra)
        .output()
        .expect("run grin")
}

/// Parse an output CSV into (status, numbers) per row after checking the header.
fn read_output(path: &Path) -> Vec<(String, Vec<f64>)> {
    let text = std::fs::read_to_string(path).expect("output written");
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some(HEADER));
    lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            assert_eq!(f.len(), 17, "row `{l}`");
            let nums = f
                .iter()
                .enumerate()
                .filter(|(i, _)| *i != 6)
                .map(|(_, v)| v.parse::<f64>().expect("number"))
                .collect();
            (f[6].to_owned(), nums)
        })
        .collect()
}

#[test]
fn luneburg_table_focuses_on_the_antipode() {
    let d = Dir::new();
    let scene = d.write("lens.toml", LUNEBURG_SCENE);
    // A parallel beam along +x (any length d), a miss, and rays starting inside.
    let mut rays = String::from("ox,oy,oz,dx,dy,dz\n");
    let beam: Vec<(f64, f64)> = vec![(0.0, 0.0), (0.5, 0.2), (-0.9, 0.7), (1.2, -0.6), (0.0, 1.4)];
    for (y, z) in &beam {
        rays.push_str(&format!("-3,{y},{z},2,0,0\n"));
    }
    rays.push_str("-3,5,0,1,0,0\n");
    rays.push_str("0.5,0.1,0.2,0,0,1\n");
    let rays = d.write("rays.csv", &rays);
    let out = d.path("out.csv");
    let o = run(&[&scene, &rays, &out], &[]);
    assert_ok(&o);
    assert!(stderr(&o).contains("traced 7 rays"), "{}", stderr(&o));
    let rows = read_output(&out);
    assert_eq!(rows.len(), 7);
    // Focus of a beam along +x: the far surface point c + R x = (2, 0, 0).
    for (status, v) in &rows[..5] {
        assert_eq!(status, "exited");
        let err = ((v[6] - 2.0).powi(2) + v[7].powi(2) + v[8].powi(2)).sqrt();
        assert!(err < 1e-7, "focus error {err:e} in row {v:?}");
        assert!(v[14] > 100.0, "steps {}", v[14]);
    }
    // The miss keeps its origin and reports the unit direction.
    assert_eq!(rows[5].0, "missed");
    assert_eq!(&rows[5].1[6..12], &[-3.0, 5.0, 0.0, 1.0, 0.0, 0.0]);
    // A ray starting inside leaves through the surface.
    assert_eq!(rows[6].0, "exited");
    let p = &rows[6].1[6..9];
    let r = ((p[0] - 0.5).powi(2) + p[1].powi(2) + p[2].powi(2)).sqrt();
    assert!((r - 1.5).abs() < 1e-9, "exit radius {r}");
}

#[test]
fn bad_rows_become_error_rows_and_json_summary() {
    let d = Dir::new();
    let scene = d.write("lens.toml", LUNEBURG_SCENE);
    let rays = d.write(
        "rays.csv",
        "ox,oy,oz,dx,dy,dz\n-3,0,0,0,0,0\n-3,0,0,NaN,0,0\n-3,0.1,0,1,0,0\n",
    );
    let out = d.path("out.csv");
    let o = run(
        &[&scene, &rays, &out],
        &["--json", "--integrator", "rk4", "--step", "adaptive=1e-9"],
    );
    assert_ok(&o);
    let rows = read_output(&out);
    let statuses: Vec<&str> = rows.iter().map(|r| r.0.as_str()).collect();
    assert_eq!(statuses, ["error", "error", "exited"]);
    let summary: serde_json::Value =
        serde_json::from_slice(&o.stdout).expect("json summary on stdout");
    assert_eq!(summary["rays"], 3);
    assert_eq!(summary["error"], 2);
    assert_eq!(summary["exited"], 1);
    assert_eq!(summary["integrator"], "rk4");
    assert_eq!(summary["precision"], "f64");
}

#[test]
fn json_format_and_f32_agree_with_f64() {
    let d = Dir::new();
    let scene = d.write("lens.toml", LUNEBURG_SCENE);
    let rays = d.write(
        "rays.csv",
        "ox,oy,oz,dx,dy,dz\n-3,0.3,0.4,1,0,0\n-3,-0.6,0.1,1,0,0\n",
    );
    let out64 = d.path("out.json");
    let out32 = d.path("out32.json");
    let o = run(&[&scene, &rays, &out64], &[]);
    assert_ok(&o);
    let o = run(&[&scene, &rays, &out32], &["--f32", "--format", "json"]);
    assert_ok(&o);
    let a: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out64).expect("json")).expect("valid JSON");
    let b: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out32).expect("json")).expect("valid JSON");
    let (a, b) = (a.as_array().expect("array"), b.as_array().expect("array"));
    assert_eq!((a.len(), b.len()), (2, 2));
    for (x, y) in a.iter().zip(b) {
        assert_eq!(x["status"], "exited");
        for k in ["px", "py", "pz", "qx", "qy", "qz", "opl"] {
            let (u, v) = (x[k].as_f64().expect("num"), y[k].as_f64().expect("num"));
            assert!((u - v).abs() < 1e-4, "{k}: f64 {u} vs f32 {v}");
        }
    }
}

#[test]
fn malformed_scene_fails_naming_file_and_line() {
    let d = Dir::new();
    let scene = d.write("bad.toml", "[camera]\nposition = [0.0, 0.0, -6.0]\nlook_at = [0.0, 0.0, 0.0]\n\n[medium]\nbounds = 7\n");
    let rays = d.write("rays.csv", "ox,oy,oz,dx,dy,dz\n0,0,-3,0,0,1\n");
    let out = d.path("out.csv");
    let o = run(&[&scene, &rays, &out], &[]);
    assert_err(&o, "bad.toml:6");
    let e = stderr(&o);
    assert_eq!(e.trim().lines().count(), 1, "one-line reason: {e}");
    assert!(!out.exists(), "no output on failure");
}

#[test]
fn missing_or_malformed_ray_tables_fail_without_output() {
    let d = Dir::new();
    let scene = d.write("lens.toml", LUNEBURG_SCENE);
    let out = d.path("out.csv");
    let o = run(&[&scene, &d.path("nope.csv"), &out], &[]);
    assert_err(&o, "nope.csv");
    assert!(!out.exists());

    let cases = [
        ("noheader.csv", "0,0,-3,0,0,1\n", "noheader.csv:1: header"),
        (
            "cols.csv",
            "ox,oy,oz,dx,dy,dz\n0,0,-3,0,0,1\n0,0,-3,0,1\n",
            "cols.csv:3: expected 6 columns",
        ),
        (
            "text.csv",
            "ox,oy,oz,dx,dy,dz\n0,0,-3,0,zero,1\n",
            "text.csv:2: column `dy`",
        ),
        ("empty.csv", "", "empty ray table"),
    ];
    for (name, text, msg) in cases {
        let rays = d.write(name, text);
        let o = run(&[&scene, &rays, &out], &[]);
        assert_err(&o, msg);
        assert!(!out.exists(), "{name}: output created");
    }
    // A bad --step never gets to write either.
    let rays = d.write("ok.csv", "ox,oy,oz,dx,dy,dz\n0,0,-3,0,0,1\n");
    let o = run(&[&scene, &rays, &out], &["--step", "fixed=-1"]);
    assert_err(&o, "not a positive number");
    assert!(!out.exists());
}

#[test]
fn scene_without_medium_is_an_error() {
    let d = Dir::new();
    let scene = d.write(
        "empty.toml",
        "[camera]\nposition = [0.0, 0.0, -6.0]\nlook_at = [0.0, 0.0, 0.0]\n",
    );
    let rays = d.write("rays.csv", "ox,oy,oz,dx,dy,dz\n0,0,-3,0,0,1\n");
    let out = d.path("out.csv");
    let o = run(&[&scene, &rays, &out], &[]);
    assert_err(&o, "no [medium]");
    assert!(!out.exists());
}

#[test]
fn step_cap_reports_max_steps() {
    let d = Dir::new();
    let scene = d.write("lens.toml", LUNEBURG_SCENE);
    let rays = d.write("rays.csv", "ox,oy,oz,dx,dy,dz\n-3,0.2,0,1,0,0\n");
    let out = d.path("out.csv");
    let o = run(
        &[&scene, &rays, &out],
        &["--max-steps", "10", "--exit", "bisection"],
    );
    assert_ok(&o);
    let rows = read_output(&out);
    assert_eq!(rows[0].0, "max_steps");
    assert_eq!(rows[0].1[14], 10.0, "steps column");
    // Stopped inside the lens, 10 steps of 0.004 past the entry point.
    let p = &rows[0].1[6..9];
    let r = ((p[0] - 0.5).powi(2) + p[1].powi(2) + p[2].powi(2)).sqrt();
    assert!(r < 1.5, "stopped at radius {r}");
    // Each step is ds = 0.004 long at its start; n grows inwards, so a little longer.
    let (opl, length) = (rows[0].1[12], rows[0].1[13]);
    assert!(length > 0.04 && length < 0.0401, "length {length}");
    assert!(opl > length && opl < 2f64.sqrt() * length, "opl {opl}");
}

/// Rays through the lens of `LUNEBURG_SCENE` at impacts 0.1 .. 1.4 (radius 1.5), along +x.
fn beam_rows(count: usize) -> String {
    let mut s = String::from("ox,oy,oz,dx,dy,dz\n");
    for i in 0..count {
        let y = 0.1 + 1.3 * i as f64 / (count - 1) as f64;
        s.push_str(&format!("-3,{y},0.05,1,0,0\n"));
    }
    s
}

/// The default method: a scene without `integrator` or `step` traces with `auto` 1e-4.
/// A table large enough to pay for them gets pilot rays (some of its own) that choose a
/// method meeting it, for at most ~20 % of the table's evaluations; a small one (pilots
/// cost 10-60x such a table) gets error control per length, and the summary says why.
/// Either way every ray ends `exited` within the asked error of the exact Luneburg exit
/// direction (through the focus on the far side: the exit direction makes the angle
/// asin(p / R) with the axis, p the impact).
#[test]
fn the_default_method_is_auto_and_meets_its_error() {
    let d = Dir::new();
    let scene_text =
        LUNEBURG_SCENE.replace("integrator = \"sharma\"\nstep = { fixed = 0.004 }\n", "");
    assert!(!scene_text.contains("step ="));
    let scene = d.write("lens.toml", &scene_text);
    for count in [24, 3200] {
        let rays = d.write("rays.csv", &beam_rows(count));
        let out = d.path("out.csv");
        let o = run(&[&scene, &rays, &out], &["--json"]);
        let summary = json(&o);
        let auto = &summary["auto"];
        if count < 1600 {
            assert!(auto.is_null(), "{summary}");
            let note = summary["auto_note"].as_str().expect("auto_note");
            assert!(
                note.starts_with("auto 1e-4 rad: error control per length, no pilot rays"),
                "{note}"
            );
            assert!(stderr(&o).contains(note), "{}", stderr(&o));
        } else {
            assert_eq!(auto["asked"], 1e-4, "{summary}");
            assert_eq!(auto["met"], true, "{summary}");
            assert_eq!(auto["pilot_rays"], count / 200, "{summary}");
            assert!(
                auto["chosen"]["error"].as_f64().expect("error") <= 0.7e-4,
                "{summary}"
            );
            assert!(
                stderr(&o).contains("chosen by pilot rays"),
                "{}",
                stderr(&o)
            );
            let table = summary["mean_evals"].as_f64().expect("evals") * count as f64;
            let pilots = auto["spent_evals"].as_f64().expect("spent");
            eprintln!("{count} rays: pilots {pilots} evals, table {table}");
            assert!(
                pilots <= 0.2 * table,
                "pilots {pilots} evals, table {table}"
            );
        }
        assert_eq!(summary["exited"], count, "{summary}");
        for (i, (status, v)) in read_output(&out).iter().enumerate() {
            assert_eq!(status, "exited");
            let (p, q) = (&v[6..9], &v[9..12]);
            let impact = 0.1 + 1.3 * i as f64 / (count - 1) as f64;
            let b = (impact * impact + 0.05 * 0.05).sqrt() / 1.5;
            // Leaves through the focus (2, 0, 0) at angle asin(b) off the axis.
            assert!(
                (p[0] - 2.0).abs() < 1e-3 && p[1].abs() < 1e-3,
                "ray {i} leaves at {p:?}"
            );
            let angle = (q[0].clamp(-1.0, 1.0)).acos();
            assert!(
                (angle - b.asin()).abs() < 3e-4,
                "ray {i}: {angle} vs {}",
                b.asin()
            );
        }
    }
}

/// Euler at a coarse step through the lens: rays whose own error estimate is above the
/// accuracy asked for (1e-4 rad for a fixed step) end `degraded` (counted in the
/// summary), not `exited` with a wrong answer.
#[test]
fn a_low_order_method_says_degraded_where_it_cannot_vouch() {
    let d = Dir::new();
    let scene = d.write("lens.toml", LUNEBURG_SCENE);
    let rays = d.write("rays.csv", &beam_rows(12));
    let out = d.path("out.csv");
    let o = run(
        &[&scene, &rays, &out],
        &["--json", "--integrator", "euler", "--step", "fixed=0.05"],
    );
    let summary = json(&o);
    assert_eq!(summary["degraded"], 12, "{summary}");
    assert!(summary.get("auto").is_none(), "{summary}");
    assert_eq!(summary["accuracy"], 1e-4, "{summary}");
    // The summary says how many and why.
    assert!(
        stderr(&o).contains(
            "12 rays ended `degraded`: their own error estimate is above the 1.0e-4 rad they are held to (asked 1.0e-4)"
        ),
        "{}",
        stderr(&o)
    );
    let rows = read_output(&out);
    assert!(rows.iter().all(|r| r.0 == "degraded"));
    // rk4 at a quarter of the radius vouches for the same rays (its third-order
    // companion's estimate is under 1e-4): every one exited, and the largest estimate is
    // reported.
    let o = run(
        &[&scene, &rays, &out],
        &["--json", "--integrator", "rk4", "--step", "fixed=0.25"],
    );
    let summary = json(&o);
    assert_eq!(summary["exited"], 12, "{summary}");
    let worst = summary["worst_estimate"].as_f64().expect("worst_estimate");
    assert!(worst > 0.0 && worst <= 1e-4, "{summary}");
    assert!(stderr(&o).contains("exited rays' own error estimates: at most"));
}

/// A table longer than a batch streams: every row comes back in order (the output is
/// written a batch at a time), and a bad row far down is named by its file line, with no
/// output left behind. (The reader was quadratic: 200k rows took 220 s to read.)
#[test]
fn a_long_table_streams_and_a_bad_row_is_named_by_its_line() {
    let d = Dir::new();
    let scene = d.write("lens.toml", LUNEBURG_SCENE);
    let rows = 150_000;
    // Rays that miss the lens: the test is the table's reading and writing.
    let mut text = String::from("# far from the lens\nid,ox,oy,oz,dx,dy,dz\n");
    for i in 0..rows {
        text.push_str(&format!("{i},-3,{},0,1,0,0\n", 5.0 + i as f64 * 1e-5));
    }
    let rays = d.write("rays.csv", &text);
    let out = d.path("out.csv");
    let o = run(&[&scene, &rays, &out], &["--json"]);
    let summary = json(&o);
    assert_eq!(summary["rays"], rows);
    assert_eq!(summary["missed"], rows);
    assert!(summary["total_seconds"].as_f64().expect("total") >= 0.0);
    let written = std::fs::read_to_string(&out).expect("output");
    let lines: Vec<&str> = written.lines().collect();
    assert_eq!(lines.len(), rows + 1);
    assert!(
        lines[0].starts_with("ox,oy,oz,dx,dy,dz,id,status"),
        "{}",
        lines[0]
    );
    for (k, line) in lines[1..].iter().enumerate().step_by(9973) {
        assert_eq!(
            line.split(',').nth(6),
            Some(k.to_string().as_str()),
            "{line}"
        );
    }
    // One bad row after them all: file line 2 + rows + 1; nothing is written.
    text.push_str("x,-3,0,zero,1,0,0\n");
    let rays = d.write("bad.csv", &text);
    let out = d.path("bad-out.csv");
    let o = run(&[&scene, &rays, &out], &[]);
    assert_eq!(
        assert_failed(&o).trim(),
        format!(
            "grin: error: {}:{}: column `oz`: `zero` is not a number",
            rays.display(),
            rows + 3
        )
    );
    assert!(!out.exists(), "a failed trace leaves no output");
}

/// Input echoed in an error keeps its control characters escaped: a NUL or a terminal
/// escape in a ray table reaches the terminal as `\u{0}`, `\u{1b}`.
#[test]
fn control_characters_in_inputs_are_escaped_in_errors() {
    let d = Dir::new();
    let scene = d.write("lens.toml", LUNEBURG_SCENE);
    let rays = d.write("rays.csv", "ox,oy,oz,dx,dy,dz\n0,0,\0\u{1b}[2J,1,0,0\n");
    let out = d.path("out.csv");
    let o = run(&[&scene, &rays, &out], &[]);
    let err = assert_failed(&o);
    assert!(!err.contains('\0') && !err.contains('\u{1b}'), "{err:?}");
    assert!(
        err.contains("column `oz`: `\\u{0}\\u{1b}[2J` is not a number"),
        "{err}"
    );
}

/// n = 1 + A exp(-|p - c|^2 / w^2): a tall bump 1/100 of the bounds wide, off the axis.
fn bump_n(p: [f64; 3], a: f64, w: f64, c: [f64; 3]) -> (f64, [f64; 3]) {
    let d = [p[0] - c[0], p[1] - c[1], p[2] - c[2]];
    let e = a * (-(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) / (w * w)).exp();
    let k = -2.0 * e / (w * w);
    (1.0 + e, [k * d[0], k * d[1], k * d[2]])
}

/// An independent reference: classical RK4 on r'' = n grad n (t-form, r' = T) with a
/// fixed t-step far below the bump's width, written here and not grin's; the exit is
/// where the segment leaving the box [-1, 1]^3 crosses it (n = 1 there: no refraction).
fn bump_reference(o: [f64; 3], d: [f64; 3], a: f64, w: f64, c: [f64; 3]) -> [f64; 3] {
    let h = 2e-5;
    let inside = |r: &[f64; 3]| r.iter().all(|x| x.abs() <= 1.0);
    // Start on the box's face along d.
    let s = (-1.0 - o[2]) / d[2];
    let mut r = [o[0] + s * d[0], o[1] + s * d[1], o[2] + s * d[2]];
    let (n0, _) = bump_n(r, a, w, c);
    let mut t = [d[0] * n0, d[1] * n0, d[2] * n0];
    let f = |r: &[f64; 3]| {
        let (n, g) = bump_n(*r, a, w, c);
        [n * g[0], n * g[1], n * g[2]]
    };
    let add =
        |x: &[f64; 3], y: &[f64; 3], k: f64| [x[0] + k * y[0], x[1] + k * y[1], x[2] + k * y[2]];
    for _ in 0..10_000_000 {
        let k1r = t;
        let k1t = f(&r);
        let k2r = add(&t, &k1t, h / 2.0);
        let k2t = f(&add(&r, &k1r, h / 2.0));
        let k3r = add(&t, &k2t, h / 2.0);
        let k3t = f(&add(&r, &k2r, h / 2.0));
        let k4r = add(&t, &k3t, h);
        let k4t = f(&add(&r, &k3r, h));
        for i in 0..3 {
            r[i] += h / 6.0 * (k1r[i] + 2.0 * k2r[i] + 2.0 * k3r[i] + k4r[i]);
            t[i] += h / 6.0 * (k1t[i] + 2.0 * k2t[i] + 2.0 * k3t[i] + k4t[i]);
        }
        if !inside(&r) {
            let l = (t[0] * t[0] + t[1] * t[1] + t[2] * t[2]).sqrt();
            return [t[0] / l, t[1] / l, t[2] / l];
        }
    }
    panic!("the reference ray never left");
}

/// A feature narrower than any default step, in an expression field (a formula has no
/// feature size): `grin trace` with the defaults (auto 1e-4) enters and resolves it. No
/// ray is `exited` more than 10x the asked accuracy off an independent reference (dopri
/// with per-length control stepped over it: most rays came out straight, up to 0.76 rad
/// off, while its pilots reported 0 rad).
#[test]
fn a_narrow_bump_in_an_expression_is_not_stepped_over() {
    let d = Dir::new();
    let (a, w, c) = (0.05, 0.01, [0.3, -0.2, 0.1]);
    let scene = d.write(
        "bump.toml",
        &format!(
            "[camera]\nposition = [0.0, 0.0, -6.0]\nlook_at = [0.0, 0.0, 0.0]\n\n[medium]\n\
             bounds = {{ box = {{ min = [-1.0, -1.0, -1.0], max = [1.0, 1.0, 1.0] }} }}\n\
             field = {{ kind = \"expr\", n = \"1 + {a}*exp(-((x-{})^2 + (y-({}))^2 + (z-{})^2)/{})\" }}\n",
            c[0],
            c[1],
            c[2],
            w * w
        ),
    );
    // A beam over the bump (3 widths either side) and a few rays far from it.
    let mut rays = String::from("ox,oy,oz,dx,dy,dz\n");
    let mut starts = Vec::new();
    for i in 0..9 {
        for j in 0..9 {
            let (x, y) = (
                c[0] - 0.03 + 0.0075 * i as f64,
                c[1] - 0.03 + 0.0075 * j as f64,
            );
            starts.push([x, y, -1.5]);
        }
    }
    starts.extend([[-0.5, 0.5, -1.5], [0.0, 0.0, -1.5], [0.7, -0.7, -1.5]]);
    for s in &starts {
        rays.push_str(&format!("{},{},{},0,0,1\n", s[0], s[1], s[2]));
    }
    let rays = d.write("rays.csv", &rays);
    let out = d.path("out.csv");
    let o = run(&[&scene, &rays, &out], &["--json"]);
    assert_ok(&o);
    let rows = read_output(&out);
    let (mut worst, mut exited, mut bent) = (0.0f64, 0, 0);
    for ((status, v), s) in rows.iter().zip(&starts) {
        let want = bump_reference(*s, [0.0, 0.0, 1.0], a, w, c);
        let got = [v[9], v[10], v[11]];
        let cos = (got[0] * want[0] + got[1] * want[1] + got[2] * want[2]).clamp(-1.0, 1.0);
        let err = cos.acos();
        bent += usize::from(want[2] < 1.0 - 5e-7);
        if status == "exited" {
            exited += 1;
            worst = worst.max(err);
            assert!(
                err <= 10.0 * 1e-4,
                "ray from {s:?} exited {err:.2e} rad off the reference ({got:?} vs {want:?})"
            );
        }
    }
    eprintln!(
        "narrow bump: {exited} of {} exited, worst {worst:.2e} rad; {bent} bent over 1 mrad; {}",
        rows.len(),
        stderr(&o).lines().last().unwrap_or("")
    );
    let statuses: Vec<&str> = rows.iter().map(|(s, _)| s.as_str()).collect();
    assert!(
        bent > 20,
        "the test needs rays the bump really bends: {bent}"
    );
    // The others are `degraded` (their own estimate is above its limit), none stopped.
    assert!(
        statuses.iter().all(|s| *s == "exited" || *s == "degraded") && exited >= 40,
        "{statuses:?}"
    );
}

/// `--step auto=RAD` holds a table's rays to RAD, as a scene asking `auto = RAD` does,
/// also where the table is too small for pilot rays: the limit above which a ray is
/// `degraded` is RAD, not the scene's own (it was the scene's, so `auto=1e-12` vouched for
/// f32 rays 1e5x less accurate, and `auto=1e-2` on a scene asking 1e-9 degraded them all).
#[test]
fn a_step_override_holds_the_rays_to_its_own_accuracy() {
    let d = Dir::new();
    let scene_text = LUNEBURG_SCENE.replace(
        "integrator = \"sharma\"\nstep = { fixed = 0.004 }\n",
        "step = { auto = 1e-9 }\n",
    );
    let scene = d.write("lens.toml", &scene_text);
    let rays = d.write("rays.csv", &beam_rows(24));
    let out = d.path("out.csv");
    let o = run(
        &[&scene, &rays, &out],
        &["--json", "--f32", "--step", "auto=1e-2"],
    );
    let summary = json(&o);
    assert_eq!(summary["estimate_limit"], 1e-2, "{summary}");
    assert_eq!(
        (summary["exited"].as_u64(), summary["degraded"].as_u64()),
        (Some(24), Some(0)),
        "{summary}"
    );
    let o = run(
        &[&scene, &rays, &out],
        &["--json", "--f32", "--step", "auto=1e-12"],
    );
    let summary = json(&o);
    assert_eq!(summary["estimate_limit"], 1e-12, "{summary}");
    assert_eq!(summary["degraded"], 24, "{summary}");
    assert!(
        stderr(&o).contains("24 rays ended `degraded`"),
        "{}",
        stderr(&o)
    );
}

/// Rows a table cannot trace are named: `#` lines after the header (read as comments, so
/// an unquoted value starting with `#` drops its row) and rays that end `error` get a
/// warning with their lines; an input column named as a result is replaced by the result
/// (it was written twice in CSV, and the input's lost in JSON), with a warning; directions whose squared length
/// overflows or underflows are traced as the unit direction they point along.
#[test]
fn a_tables_untraceable_rows_are_named() {
    let d = Dir::new();
    let scene = d.write("lens.toml", LUNEBURG_SCENE);
    let out = d.path("out.csv");
    let rays = d.write(
        "rays.csv",
        "id,ox,oy,oz,dx,dy,dz\n#1,0.0,0.3,-3,1,0,0\n\"#2\",0.0,0.3,0,1,0,0\n\
         3,nan,0.3,0,1,0,0\n4,-3,0.3,0,0,0,0\n5,-3,0.3,0,1e308,0,0\n6,-3,0.3,0,1e-320,0,0\n",
    );
    let o = run(&[&scene, &rays, &out], &[]);
    assert_ok(&o);
    let err = stderr(&o);
    assert!(
        err.contains("rays.csv: `#` comment lines after the header skipped: 1 (line 2)"),
        "{err}"
    );
    assert!(
        err.contains("rays.csv: rays that ended `error`: 2 (lines 4 and 5)"),
        "{err}"
    );
    let text = std::fs::read_to_string(&out).expect("output");
    let rows: Vec<&str> = text.lines().skip(1).collect();
    assert_eq!(rows.len(), 5, "{text}");
    assert!(rows[0].starts_with("0,0.3,0,1,0,0,#2,"), "{text}");
    // 1e308 and 1e-320 along +x: the same exit as a unit direction along +x.
    let unit = run(
        &[
            &scene,
            &d.write("unit.csv", "ox,oy,oz,dx,dy,dz\n-3,0.3,0,1,0,0\n"),
            &d.path("unit_out.csv"),
        ],
        &[],
    );
    assert_ok(&unit);
    let exit = std::fs::read_to_string(d.path("unit_out.csv")).expect("unit output");
    let want: Vec<&str> = exit
        .lines()
        .nth(1)
        .expect("row")
        .split(',')
        .skip(6)
        .collect();
    for row in &rows[3..5] {
        let got: Vec<&str> = row.split(',').skip(7).collect();
        assert_eq!(got, want, "{row}");
    }
    // An earlier trace's output traced again: its result columns are replaced, once each.
    let again = d.path("again.csv");
    let o = run(&[&scene, &out, &again], &[]);
    assert_ok(&o);
    assert!(
        stderr(&o).contains(
            "out.csv: input columns named as results (status, px, py, pz, qx, qy, qz, opl, length, steps, evals) are replaced by this trace's"
        ),
        "{}",
        stderr(&o)
    );
    let again = std::fs::read_to_string(&again).expect("again");
    assert_eq!(
        again.lines().next(),
        Some("ox,oy,oz,dx,dy,dz,id,status,px,py,pz,qx,qy,qz,opl,length,steps,evals")
    );
    assert_eq!(
        again.lines().nth(1),
        text.lines().nth(1),
        "the same ray, traced again"
    );
}
