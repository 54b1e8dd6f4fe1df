//! `grin render` driven by a render farm or a Slurm array: `--frames` frame lists
//! (`1-3,5,7-9:2`), `--shard I/N`, `--skip-existing` and the per-frame `--seed`. Each test
//! renders a tiny animated scene (an `expr` medium whose time is t + frame / fps) on the
//! CPU.

use common::{
    TestDir, assert_err, assert_failed, assert_ok, grin, json, run_ok, scenes, stderr, stdout,
};
use grin_testkit as common;
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::process::Output;

/// A checker plane seen through a GRIN ball whose index swells with time (`time`: true)
/// or stays put, at 2 spp (the sub-pixel positions draw from the render's seed), with a
/// `[sensor]` (shot and read noise from the sensor's seed) when `sensor`.
fn scene_text(time: bool, sensor: bool) -> String {
    let swell = if time { "*(1 + 0.5*sin(3*t))" } else { "" };
    let sensor = if sensor {
        "[sensor]\nfull_well = 200.0\nread_noise = 2.0\nseed = 3\n"
    } else {
        ""
    };
    format!(
        r#"
[camera]
position = [0.0, 1.1, -4.0]
look_at = [0.0, 0.55, 0.0]
fov_y_deg = 40.0

[[object]]
shape = {{ plane = {{ point = [0.0, 0.0, 0.0], normal = [0.0, 1.0, 0.0] }} }}
material = {{ checker = {{ color_a = [0.85, 0.85, 0.85], color_b = [0.15, 0.15, 0.18], scale = 0.5 }} }}

[[light]]
directional = {{ direction = [0.3, -1.0, 0.5], intensity = [1.0, 1.0, 0.9] }}

[medium]
bounds = {{ sphere = {{ center = [0.0, 0.6, -0.6], radius = 0.6 }} }}
ambient_index = 1.0
field = {{ kind = "expr", n = "1 + 0.1*(1 - (x*x + (y - 0.6)*(y - 0.6) + (z + 0.6)*(z + 0.6))/0.36){swell}" }}

[render]
spp = 2
integrator = "rk4"
step = {{ fixed = 0.02 }}
{sensor}"#
    )
}

/// A temporary directory holding `scene.toml`.
struct Dir(TestDir);

impl std::ops::Deref for Dir {
    type Target = TestDir;
    fn deref(&self) -> &TestDir {
        &self.0
    }
}

impl Dir {
    fn new(scene: &str) -> Self {
        let dir = TestDir::new();
        dir.write("scene.toml", scene);
        Dir(dir)
    }

    fn scene(&self) -> PathBuf {
        self.path("scene.toml")
    }

    /// Every file but the scene, by name, with its bytes.
    fn outputs(&self) -> BTreeMap<String, Vec<u8>> {
        self.names()
            .into_iter()
            .filter(|n| n != "scene.toml")
            .map(|n| {
                let bytes = std::fs::read(self.path(&n)).expect("read output");
                (n, bytes)
            })
            .collect()
    }
}

/// `grin render scene.toml -o DIR/out.####.exr --backend cpu --size 32x18 EXTRA`, with
/// the bake cache in the directory.
fn render(dir: &Dir, extra: &[&str]) -> Output {
    grin()
        .env("GRIN_CACHE_DIR", dir.path("cache"))
        .arg("render")
        .arg(dir.scene())
        .arg("-o")
        .arg(dir.path("out.####.exr"))
        .args(["--backend", "cpu", "--size", "32x18"])
        .args(extra)
        .output()
        .expect("grin runs")
}

/// The EXR and PNG names of `frames`.
fn names_of(frames: &[i64]) -> Vec<String> {
    let mut v: Vec<String> = frames
        .iter()
        .flat_map(|f| [format!("out.{f:04}.exr"), format!("out.{f:04}.png")])
        .collect();
    v.sort();
    v
}

/// The command failed with a one-line `grin: error:` containing `needle`.
fn fails_with(o: &Output, needle: &str) {
    let err = assert_failed(o);
    let lines: Vec<&str> = err.lines().filter(|l| !l.trim().is_empty()).collect();
    assert_eq!(lines.len(), 1, "one line: {err}");
    assert!(lines[0].contains(needle), "`{needle}` in: {err}");
}

#[test]
fn a_frame_list_renders_exactly_its_frames() {
    let d = Dir::new(&scene_text(true, false));
    let o = render(&d, &["--frames", "1-3,5,7-9:2", "--json"]);
    let summaries = json(&o);
    let frames: Vec<i64> = summaries
        .as_array()
        .expect("array")
        .iter()
        .map(|s| s["frame"].as_i64().expect("frame"))
        .collect();
    assert_eq!(frames, [1, 2, 3, 5, 7, 9]);
    let mut expected = names_of(&[1, 2, 3, 5, 7, 9]);
    expected.push("scene.toml".into());
    expected.sort();
    let names: Vec<String> = d.names().into_iter().filter(|n| n != "cache").collect();
    assert_eq!(names, expected);
    // The medium moves: frames differ.
    let out = d.outputs();
    assert_ne!(out["out.0001.exr"], out["out.0002.exr"]);

    // `A..B` still reads as before, and a bad list is named.
    let d = Dir::new(&scene_text(true, false));
    assert_ok(&render(&d, &["--frames", "2..3"]));
    assert_eq!(
        d.outputs().into_keys().collect::<Vec<_>>(),
        names_of(&[2, 3])
    );
    let d = Dir::new(&scene_text(true, false));
    let o = render(&d, &["--frames", "1-3,,5"]);
    assert_err(&o, "empty item in `1-3,,5`");
    assert_eq!(d.names(), ["scene.toml"]);
}

#[test]
fn shards_together_render_what_one_run_renders_bit_for_bit() {
    let whole = Dir::new(&scene_text(true, true));
    assert_ok(&render(&whole, &["--frames", "1-5"]));
    let whole_out = whole.outputs();
    assert_eq!(
        whole_out.keys().cloned().collect::<Vec<_>>(),
        names_of(&[1, 2, 3, 4, 5])
    );

    // Two array tasks at once, into one directory.
    let sharded = Dir::new(&scene_text(true, true));
    let task = |shard: &str| {
        grin()
            .env("GRIN_CACHE_DIR", sharded.path("cache"))
            .arg("render")
            .arg(sharded.scene())
            .arg("-o")
            .arg(sharded.path("out.####.exr"))
            .args(["--backend", "cpu", "--size", "32x18", "--frames", "1-5"])
            .args(["--shard", shard, "--json"])
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .expect("grin starts")
    };
    let (a, b) = (task("0/2"), task("1/2"));
    let (a, b) = (
        a.wait_with_output().expect("task 0"),
        b.wait_with_output().expect("task 1"),
    );
    assert_ok(&a);
    assert_ok(&b);
    let frames = |o: &Output| -> Vec<i64> {
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("json");
        v.as_array()
            .expect("array")
            .iter()
            .map(|s| s["frame"].as_i64().expect("frame"))
            .collect()
    };
    // Contiguous pieces, the first one taking the extra frame.
    assert_eq!((frames(&a), frames(&b)), (vec![1, 2, 3], vec![4, 5]));
    let _ = std::fs::remove_dir_all(sharded.path("cache"));
    let sharded_out = sharded.outputs();
    assert_eq!(
        sharded_out.keys().collect::<Vec<_>>(),
        whole_out.keys().collect::<Vec<_>>()
    );
    for (name, bytes) in &whole_out {
        assert!(sharded_out[name] == *bytes, "{name} differs");
    }
}

#[test]
fn skip_existing_renders_only_what_is_missing() {
    let d = Dir::new(&scene_text(true, false));
    assert_ok(&render(&d, &["--frames", "1-4"]));
    let _ = std::fs::remove_dir_all(d.path("cache"));
    let before = d.outputs();
    let mtime = |name: &str| {
        std::fs::metadata(d.path(name))
            .and_then(|m| m.modified())
            .expect("mtime")
    };
    let mtimes: BTreeMap<String, std::time::SystemTime> =
        before.keys().map(|n| (n.clone(), mtime(n))).collect();
    std::fs::remove_file(d.path("out.0003.exr")).expect("rm");
    // Coarse file-system clocks: a rewrite must show in the mtime.
    std::thread::sleep(std::time::Duration::from_millis(50));

    let o = render(&d, &["--frames", "1-4", "--skip-existing"]);
    assert_ok(&o);
    let err = stderr(&o);
    for f in [1, 2, 4] {
        let line = format!(
            "skipped frame {f}: {} exists",
            d.path(&format!("out.{f:04}.exr")).display()
        );
        assert!(err.lines().any(|l| l == line), "`{line}` in: {err}");
    }
    assert!(!err.contains("skipped frame 3"), "{err}");
    let out = stdout(&o);
    assert!(out.contains("out.0003.exr"), "frame 3 rendered: {out}");
    assert!(
        out.contains("1 of 4 frames rendered, 3 skipped"),
        "the tally: {out}"
    );
    let _ = std::fs::remove_dir_all(d.path("cache"));
    let after = d.outputs();
    assert_eq!(after, before, "frame 3 rendered as it was the first time");
    for f in [1, 2, 4] {
        for ext in ["exr", "png"] {
            let name = format!("out.{f:04}.{ext}");
            assert_eq!(mtime(&name), mtimes[&name], "{name} was rewritten");
        }
    }
    assert_ne!(mtime("out.0003.exr"), mtimes["out.0003.exr"]);

    // Everything there: nothing rendered; --json lists the skipped frames.
    let o = render(&d, &["--frames", "1-4", "--skip-existing", "--json"]);
    let v = json(&o);
    let entries = v.as_array().expect("array");
    assert_eq!(entries.len(), 4, "{v}");
    for (entry, f) in entries.iter().zip(1..) {
        assert_eq!(entry["frame"], f, "{v}");
        assert_eq!(entry["skipped"], true, "{v}");
        let exr = d.path(&format!("out.{f:04}.exr"));
        assert_eq!(entry["exr"].as_str(), exr.to_str(), "{v}");
    }
    assert!(stderr(&o).contains("0 of 4 frames rendered, 4 skipped"));
    assert_eq!(d.outputs(), before);
}

#[test]
fn bad_shards_fail_clearly_and_write_nothing() {
    let d = Dir::new(&scene_text(true, false));
    let o = render(&d, &["--frames", "1-4", "--shard", "2/2"]);
    assert_err(&o, "`2/2`: shard index 2 must be below the shard count 2");
    let o = render(&d, &["--shard", "0/2"]);
    fails_with(
        &o,
        "--shard 0/2 renders a shard of a frame list: give the list with --frames",
    );
    let o = render(&d, &["--frames", "1-4", "--shard", "0/0"]);
    assert_err(&o, "the shard count must be at least 1");
    let o = render(&d, &["--frames", "1-4", "--shard", "x"]);
    assert_err(&o, "is not a shard (I/N, e.g. 0/4)");
    assert_eq!(d.names(), ["scene.toml"]);

    // More tasks than frames: the spare tasks succeed and render nothing.
    let o = render(&d, &["--frames", "1-2", "--shard", "3/4", "--json"]);
    assert_ok(&o);
    assert!(stderr(&o).contains("holds no frame"), "{}", stderr(&o));
    assert_eq!(stdout(&o).trim(), "[]");
    assert_eq!(d.names(), ["scene.toml"]);
}

#[test]
fn a_seeded_frame_renders_the_same_alone_or_in_a_list() {
    let alone = Dir::new(&scene_text(true, true));
    assert_ok(&render(&alone, &["--frames", "3", "--seed", "42"]));
    let listed = Dir::new(&scene_text(true, true));
    assert_ok(&render(&listed, &["--frames", "7,1-4", "--seed", "42"]));
    let (alone, listed) = (alone.outputs(), listed.outputs());
    assert!(alone["out.0003.exr"] == listed["out.0003.exr"]);
    assert!(alone["out.0003.png"] == listed["out.0003.png"]);

    // The seed is what made it: another seed, or none, is other noise.
    let other = Dir::new(&scene_text(true, true));
    assert_ok(&render(&other, &["--frames", "3", "--seed", "43"]));
    let unseeded = Dir::new(&scene_text(true, true));
    assert_ok(&render(&unseeded, &["--frames", "3"]));
    assert!(other.outputs()["out.0003.exr"] != alone["out.0003.exr"]);
    assert!(unseeded.outputs()["out.0003.exr"] != alone["out.0003.exr"]);

    // A still medium: frames differ by their noise alone, each its own.
    let still = Dir::new(&scene_text(false, true));
    assert_ok(&render(&still, &["--frames", "1-2", "--seed", "42"]));
    let out = still.outputs();
    let (_, one) = common::exr_channels(&still.path("out.0001.exr"));
    let (_, two) = common::exr_channels(&still.path("out.0002.exr"));
    assert_ne!(out["out.0001.exr"], out["out.0002.exr"]);
    let differing = one["R"].iter().zip(&two["R"]).filter(|(a, b)| a != b);
    assert!(
        differing.count() > one["R"].len() / 2,
        "noise in most pixels"
    );

    // Without [sensor] the seed still moves the sub-pixel samples.
    let a = Dir::new(&scene_text(false, false));
    assert_ok(&render(&a, &["--frames", "1", "--seed", "1"]));
    let b = Dir::new(&scene_text(false, false));
    assert_ok(&render(&b, &["--frames", "1", "--seed", "2"]));
    assert!(a.outputs()["out.0001.exr"] != b.outputs()["out.0001.exr"]);
}

/// The expr scene baked to one file, copied to the frames `present`, and a scene that
/// reads `field.####.grinf`: a sequence with gaps.
fn baked_sequence(present: &[i64]) -> Dir {
    let d = Dir::new(&scene_text(false, false));
    run_ok(
        grin()
            .args(["bake", "--resolution", "16", "-o"])
            .arg(d.path("field.grinf"))
            .arg(d.scene()),
    );
    for f in present {
        std::fs::copy(
            d.path("field.grinf"),
            d.path(&format!("field.{f:04}.grinf")),
        )
        .expect("cp");
    }
    let text = scene_text(false, false);
    let (head, tail) = text.split_once("field = {").expect("field line");
    let tail = &tail[tail.find('\n').expect("line end")..];
    let seq = format!("{head}field = {{ kind = \"baked\", path = \"field.####.grinf\" }}{tail}");
    std::fs::write(d.scene(), seq).expect("scene");
    d
}

#[test]
fn only_the_frames_rendered_need_their_files() {
    let d = baked_sequence(&[1, 2, 5]);
    let frames_written = |d: &Dir| -> Vec<String> {
        d.names()
            .into_iter()
            .filter(|n| n.starts_with("out."))
            .collect()
    };
    // Frames 3 and 4 have no file: a list around them renders.
    assert_ok(&render(&d, &["--frames", "1-2,5"]));
    assert_eq!(frames_written(&d), names_of(&[1, 2, 5]));
    // A range over them names them before anything is written.
    let o = grin()
        .arg("render")
        .arg(d.scene())
        .arg("-o")
        .arg(d.path("again.####.exr"))
        .args(["--backend", "cpu", "--size", "32x18", "--frames", "1-5"])
        .output()
        .expect("grin");
    fails_with(&o, "2 of frames 1..5 missing: frame 3: ");
    assert!(stderr(&o).contains("field.0004.grinf"), "{}", stderr(&o));
    let o = render(&d, &["--frames", "1,3-5"]);
    fails_with(&o, "2 of frames 1,3-5 missing: frame 3: ");
    assert_eq!(frames_written(&d), names_of(&[1, 2, 5]));
    // Their outputs there, --skip-existing does not ask for frames it does not render.
    for f in [3, 4] {
        for ext in ["exr", "png"] {
            std::fs::copy(
                d.path(&format!("out.0001.{ext}")),
                d.path(&format!("out.{f:04}.{ext}")),
            )
            .expect("cp");
        }
    }
    std::fs::remove_file(d.path("out.0005.exr")).expect("rm");
    let o = render(&d, &["--frames", "1-5", "--skip-existing"]);
    assert_ok(&o);
    assert!(stderr(&o).contains("skipped frame 4: "), "{}", stderr(&o));
    assert!(d.path("out.0005.exr").is_file());
}

#[test]
fn skip_existing_asks_for_the_beauty_image_too() {
    let scene = scenes().join("optics/displacement.toml");
    let d = tempfile::tempdir().expect("temp dir");
    let run = || {
        grin()
            .arg("render")
            .arg(&scene)
            .arg("-o")
            .arg(d.path().join("st.####.exr"))
            .arg("--beauty")
            .arg(d.path().join("plate.####.exr"))
            .args(["--frames", "0-1", "--backend", "cpu", "--size", "16x16"])
            .args(["--skip-existing", "--json"])
            .output()
            .expect("grin runs")
    };
    let o = run();
    let v = json(&o);
    assert_eq!(v.as_array().map(Vec::len), Some(4), "{v}");
    // Frame 1's plate is gone: frame 1 renders again, both its images.
    std::fs::remove_file(d.path().join("plate.0001.exr")).expect("rm");
    let o = run();
    assert_ok(&o);
    let line = format!(
        "skipped frame 0: {} and {} exist",
        d.path().join("st.0000.exr").display(),
        d.path().join("plate.0000.exr").display()
    );
    assert!(stderr(&o).lines().any(|l| l == line), "{}", stderr(&o));
    assert!(!stderr(&o).contains("skipped frame 1"), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("json");
    let entries = v.as_array().expect("array");
    assert_eq!(entries.len(), 3, "{v}");
    assert_eq!(entries[0]["skipped"], true, "{v}");
    assert_eq!(
        entries[0]["beauty"].as_str(),
        d.path().join("plate.0000.exr").to_str()
    );
    assert_eq!(
        (&entries[1]["frame"], &entries[2]["frame"]),
        (&1.into(), &1.into())
    );
    assert!(entries[1]["skipped"].is_null() && entries[2]["skipped"].is_null());
    assert!(d.path().join("plate.0001.exr").is_file());
}
