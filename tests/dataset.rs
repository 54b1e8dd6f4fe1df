//! `grin dataset bos`: deterministic by seed and index, shards that add up to the single
//! run, and runs that resume after an interruption without duplicates or half-written
//! samples.

use common::{assert_ok, grin, json, run_err, run_ok};
use grin_testkit as common;
use std::collections::BTreeMap;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Samples of the tests' dataset, and its (small) image size.
const COUNT: u64 = 200;
const SIZE: &str = "48x32";

/// `grin dataset bos -o DIR --count COUNT --seed 11 --size SIZE`: the tests' dataset.
fn dataset(dir: &Path) -> Command {
    let mut c = grin();
    c.args(["dataset", "bos", "-o"]).arg(dir).args([
        "--count",
        &COUNT.to_string(),
        "--seed",
        "11",
        "--size",
        SIZE,
    ]);
    c
}

/// [`dataset`] with `extra`, which must succeed.
fn run(dir: &Path, extra: &[&str]) -> std::process::Output {
    run_ok(dataset(dir).args(extra))
}

/// Every file of the folder by name, with its bytes.
/// Every entry's name and bytes (a directory, such as a staging one, has none).
fn files(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    std::fs::read_dir(dir)
        .expect("read dir")
        .map(|e| {
            let e = e.expect("dir entry");
            let bytes = if e.path().is_dir() {
                Vec::new()
            } else {
                std::fs::read(e.path()).expect("read file")
            };
            (e.file_name().to_string_lossy().into_owned(), bytes)
        })
        .collect()
}

/// The dataset is complete: 5 files a sample, no temporary files, a manifest with one
/// line per sample in index order.
fn assert_complete(dir: &Path) {
    let f = files(dir);
    assert_eq!(
        f.len() as u64,
        5 * COUNT + 1,
        "files: {:?}",
        f.keys().take(8).collect::<Vec<_>>()
    );
    assert!(
        f.keys().all(|n| !n.starts_with(".grin-")),
        "temporary files left"
    );
    let manifest = String::from_utf8(f["manifest.jsonl"].clone()).expect("test step");
    let indices: Vec<u64> = manifest
        .lines()
        .map(|l| {
            serde_json::from_str::<serde_json::Value>(l).expect("test step")["index"]
                .as_u64()
                .expect("test step")
        })
        .collect();
    assert_eq!(indices, (0..COUNT).collect::<Vec<_>>());
}

#[test]
fn the_same_seed_gives_the_same_dataset_and_shards_add_up_to_it() {
    let tmp = tempfile::tempdir().expect("test step");
    let (a, b, s) = (
        tmp.path().join("a"),
        tmp.path().join("b"),
        tmp.path().join("s"),
    );
    let out = run(&a, &["--json"]);
    let summary = json(&out);
    assert_eq!(summary["rendered"], COUNT);
    assert!(summary["samples_per_second"].as_f64().expect("test step") > 0.0);
    assert_complete(&a);
    run(&b, &[]);
    assert_eq!(files(&a), files(&b), "two runs of one seed differ");
    // Two processes at once, one shard each: the same files, byte for byte.
    let shard = |i: u32| {
        dataset(&s)
            .args(["--shard", &format!("{i}/2")])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("test step")
    };
    let (p0, p1) = (shard(0), shard(1));
    assert_ok(&p0.wait_with_output().expect("test step"));
    assert_ok(&p1.wait_with_output().expect("test step"));
    // The shard that ends last sees every sample and writes the manifest.
    assert_complete(&s);
    assert_eq!(
        files(&a),
        files(&s),
        "two shards differ from the single run"
    );
    // Another seed is another dataset.
    let c = tmp.path().join("c");
    run_ok(
        grin()
            .args(["dataset", "bos", "-o"])
            .arg(&c)
            .args(["--count", "2", "--seed", "12", "--size", SIZE]),
    );
    assert_ne!(
        std::fs::read(c.join("bos_000000.exr")).expect("test step"),
        files(&a)["bos_000000.exr"]
    );
}

#[test]
fn an_interrupted_run_resumes_without_duplicates_or_half_written_samples() {
    let tmp = tempfile::tempdir().expect("test step");
    let dir = tmp.path().join("d");
    let reference = tmp.path().join("r");
    run(&reference, &[]);
    for signal in ["TERM", "KILL"] {
        let _ = std::fs::remove_dir_all(&dir);
        // Each commit waits a little, so the run is stopped in the middle of writing.
        let mut child = dataset(&dir)
            .env("GRIN_TEST_PAUSE_BEFORE_COMMIT_MS", "20")
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("test step");
        let start = Instant::now();
        while files_named(&dir, ".json") < 5 && start.elapsed() < Duration::from_secs(60) {
            std::thread::sleep(Duration::from_millis(20));
        }
        let status = std::process::Command::new("kill")
            .args([&format!("-{signal}"), &child.id().to_string()])
            .status()
            .expect("test step");
        assert!(status.success());
        assert!(
            !child.wait().expect("test step").success(),
            "the run was not stopped"
        );
        let done = files_named(&dir, ".json");
        assert!(
            done > 0 && (done as u64) < COUNT,
            "{done} samples before the {signal}"
        );
        // A sample is complete exactly when its JSON is there: every one with a JSON has
        // its four other files.
        let f = files(&dir);
        for name in f.keys().filter(|n| n.ends_with(".json")) {
            let stem = name.trim_end_matches(".json");
            for ext in [".exr", "-slice.exr", ".png", "-reference.png"] {
                assert!(
                    f.contains_key(&format!("{stem}{ext}")),
                    "{stem}{ext} missing"
                );
            }
        }
        assert!(!f.contains_key("manifest.jsonl"));
        let out = run(&dir, &["--json"]);
        let summary = json(&out);
        assert_eq!(
            summary["skipped"].as_u64().expect("test step"),
            done as u64,
            "{signal}"
        );
        assert_eq!(
            summary["rendered"].as_u64().expect("test step"),
            COUNT - done as u64
        );
        // SIGKILL leaves its staging directory behind (nothing can remove it); SIGTERM
        // does not.
        let leftovers: Vec<String> = files(&dir)
            .into_keys()
            .filter(|n| n.starts_with(".grin-"))
            .collect();
        if signal == "TERM" {
            assert!(leftovers.is_empty(), "{leftovers:?}");
        }
        for l in leftovers {
            std::fs::remove_dir_all(dir.join(l)).expect("test step");
        }
        assert_complete(&dir);
        assert_eq!(files(&dir), files(&reference), "resumed after {signal}");
    }
}

fn files_named(dir: &Path, suffix: &str) -> usize {
    std::fs::read_dir(dir).map_or(0, |d| {
        d.filter(|e| {
            e.as_ref()
                .is_ok_and(|e| e.file_name().to_string_lossy().ends_with(suffix))
        })
        .count()
    })
}

#[test]
fn bad_dataset_arguments_fail_clearly() {
    let tmp = tempfile::tempdir().expect("test step");
    run_err(
        grin()
            .args(["dataset", "bos", "-o"])
            .arg(tmp.path().join("x"))
            .args(["--count", "0"]),
        "--count 0: a dataset holds 1 to",
    );
    run_err(
        grin()
            .args(["dataset", "bos", "-o"])
            .arg(tmp.path().join("x"))
            .args(["--count", "4", "--shard", "4/4"]),
        "shard index 4 must be below",
    );
    assert!(!tmp.path().join("x").exists());
}

/// Every kind with every source of media: the channels the kind promises, a sample's own
/// scene TOML renders to the same channels with `grin render`, and the index slice of a
/// plume sample is the plume formula.
#[test]
fn every_kind_and_media_give_their_channels_and_ground_truth() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let pool = format!(
        "scene:{}",
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../data/vdb/fire-haze.toml")
            .display()
    );
    for kind in ["bos", "schlieren", "haze"] {
        for media in ["plumes", "noise", "expr", pool.as_str()] {
            let dir = tmp.path().join(format!("{kind}-{}", media.len()));
            run_ok(grin().args(["dataset", kind, "-o"]).arg(&dir).args([
                "--count", "1", "--seed", "2", "--size", "24x16", "--media", media,
            ]));
            let (width, ch) = common::exr_channels(&dir.join(format!("{kind}_000000.exr")));
            assert_eq!(width, 24);
            let want: &[&str] = match kind {
                "bos" => &[
                    "reference",
                    "distorted",
                    "displacement_px.X",
                    "deflection_rad.X",
                ],
                "schlieren" => &["schlieren", "deflection_rad.X", "grad_n_line.Y"],
                _ => &[
                    "reference.R",
                    "distorted.B",
                    "st.S",
                    "valid",
                    "grad_n_line.X",
                ],
            };
            for w in want {
                assert!(ch.contains_key(*w), "{kind} {media}: no channel {w}");
            }
            // The medium bends the rays: some pixel's deflection is not zero, and for the
            // generated media, weak and at ambient on their box's faces, it is the
            // projected gradient over n (small angles). The fire cache's box cuts its hot
            // gas (n is 1.3e-4 off ambient on the top face, 6e-5 on the others, of 2.1e-4
            // at most): the jump there refracts rays, which no integral inside holds.
            let defl = &ch["deflection_rad.X"];
            assert!(
                defl.iter().any(|d| d.abs() > 1e-7),
                "{kind} {media}: no deflection"
            );
            for axis in ["X", "Y"].iter().filter(|_| media != pool) {
                let d = &ch[&format!("deflection_rad.{axis}")];
                let g = &ch[&format!("grad_n_line.{axis}")];
                let peak = d.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                let worst = d
                    .iter()
                    .zip(g)
                    .filter(|(d, _)| d.is_finite())
                    .fold(0.0f64, |m, (d, g)| m.max((d - g / 1.000272).abs()));
                assert!(
                    worst <= 0.03 * peak,
                    "{kind} {media} {axis}: deflection vs projected gradient {worst:e} of {peak:e}"
                );
            }
            let json: serde_json::Value = serde_json::from_slice(
                &std::fs::read(dir.join(format!("{kind}_000000.json"))).expect("json"),
            )
            .expect("parse json");
            // The sample's scene renders alone to its channels (the beauty pair of haze
            // is rendered beside the ST map; the scene file holds the [optics] part).
            let scene = dir.join("again.toml");
            std::fs::write(&scene, json["scene_toml"].as_str().expect("toml")).expect("write");
            let again = dir.join("again.exr");
            run_ok(
                grin()
                    .args(["render"])
                    .arg(&scene)
                    .arg("-o")
                    .arg(&again)
                    .args(["--backend", "cpu"]),
            );
            let (_, rendered) = common::exr_channels(&again);
            for (name, values) in &rendered {
                let same = values
                    .iter()
                    .zip(&ch[name])
                    .all(|(a, b)| a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()));
                assert!(
                    same,
                    "{kind} {media}: {name} differs from the scene's own render"
                );
            }
            if media == "plumes" {
                let (_, slice) =
                    common::exr_channels(&dir.join(format!("{kind}_000000-slice.exr")));
                let s = &json["slice"];
                let (x, y, z) = (&s["x"], &s["y"], s["plane_z"].as_f64().expect("z"));
                let at = |a: &serde_json::Value, i: usize, n: usize| {
                    let (lo, hi) = (a[0].as_f64().expect("lo"), a[1].as_f64().expect("hi"));
                    lo + (hi - lo) * i as f64 / (n - 1) as f64
                };
                for (row, col) in [(0, 0), (20, 31), (40, 10), (63, 63), (32, 32)] {
                    let p = [at(x, col, 64), at(y, 63 - row, 64), z];
                    let mut n = 1.000272;
                    for pl in json["medium"]["plumes"].as_array().expect("plumes") {
                        let c: Vec<f64> = (0..3)
                            .map(|k| pl["center"][k].as_f64().expect("c"))
                            .collect();
                        let r2: f64 = (0..3).map(|k| (p[k] - c[k]).powi(2)).sum();
                        let s = pl["s"].as_f64().expect("s");
                        n -= pl["a"].as_f64().expect("a") * (-r2 / (s * s)).exp();
                    }
                    let got = slice["n"][row * 64 + col];
                    assert!((got - n).abs() < 2e-7, "slice ({row}, {col}): {got} vs {n}");
                }
            }
        }
    }
}
