//! End-to-end tests of `grin view`: the real window under Xvfb (installed by
//! scripts/setup.sh) on lavapipe. The headless run's screenshot against `grin render` of
//! the same camera and settings, orbiting frames and their fps report, hot reload of the
//! scene file while the window renders, and the one-line errors without a display, with a
//! broken scene and without an adapter.

use common::{grin, json, run_ok, scenes, stderr};
use grin_testkit as common;
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};

/// An Xvfb server of this test's own, killed when dropped.
struct Xvfb {
    child: Child,
    display: String,
}

impl Drop for Xvfb {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

static NEXT: AtomicU32 = AtomicU32::new(0);

/// Start Xvfb on a free display (scripts/setup.sh installs it; its absence fails).
fn xvfb() -> Xvfb {
    let base = 300 + (std::process::id() % 200) * 8;
    for _ in 0..16 {
        let n = base + NEXT.fetch_add(1, Ordering::Relaxed);
        if Path::new(&format!("/tmp/.X11-unix/X{n}")).exists() {
            continue;
        }
        let child = Command::new("Xvfb")
            .args([
                format!(":{n}").as_str(),
                "-screen",
                "0",
                "1280x1024x24",
                "-nolisten",
                "tcp",
            ])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("Xvfb (package xvfb, installed by scripts/setup.sh)");
        let mut x = Xvfb {
            child,
            display: format!(":{n}"),
        };
        let start = Instant::now();
        while start.elapsed() < Duration::from_secs(10) {
            if Path::new(&format!("/tmp/.X11-unix/X{n}")).exists() {
                return x;
            }
            if let Ok(Some(_)) = x.child.try_wait() {
                break;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        drop(x);
    }
    panic!("could not start Xvfb");
}

/// `grin view` on `x`'s display with a bake cache of the test's own.
fn view(x: &Xvfb, cache: &Path) -> Command {
    let mut c = grin();
    c.env("DISPLAY", &x.display)
        .env_remove("WAYLAND_DISPLAY")
        .env("GRIN_CACHE_DIR", cache);
    c
}

/// The window's accumulated frames are one render of all their samples: 4 frames of the
/// paper's scene (a) at 4 spp each against `grin render --spp 16` of the same camera.
/// Tolerance: the same samples are drawn (frame k renders samples 4k..4k+3 of 16), so
/// pixels differ by float rounding (mean <= 1e-4, p99 <= 1e-5); a few isolated pixels
/// may differ where a rounding flips a discrete event (a Fresnel choice, an edge hit).
#[test]
fn view_screenshot_matches_render_of_the_same_camera() {
    let x = xvfb();
    let dir = tempfile::tempdir().expect("tempdir");
    let shot = dir.path().join("shot.exr");
    let scene = scenes().join("paper-a.toml");
    let o = view(&x, dir.path())
        .arg("view")
        .arg(&scene)
        .args([
            "--frames",
            "4",
            "--size",
            "160x90",
            "--json",
            "--screenshot",
        ])
        .arg(&shot)
        .output()
        .expect("run grin view");
    let s = json(&o);
    // Four full frames of 4 samples, after the low-resolution preview shown first (its
    // frame cost was not known): shown before the first full frame, not counted.
    assert_eq!(s["frames"], 4, "{s}");
    assert_eq!(s["samples"], 16, "{s}");
    let (first, full) = (
        s["first_frame_seconds"].as_f64().expect("first"),
        s["first_full_frame_seconds"].as_f64().expect("full"),
    );
    assert!(0.0 < first && first < full, "{s}");
    assert_eq!(s["converged"], true, "{s}");
    assert!(shot.is_file() && shot.with_extension("png").is_file());

    let reference = dir.path().join("ref.exr");
    let o = run_ok(
        grin()
            .env("GRIN_CACHE_DIR", dir.path())
            .arg("render")
            .arg(&scene)
            .args([
                "--backend",
                "gpu",
                "--size",
                "160x90",
                "--spp",
                "16",
                "--json",
                "-o",
            ])
            .arg(&reference)
            .arg("--compare")
            .arg(&shot),
    );
    let r = json(&o);
    // The render read the view's bake from the cache.
    assert_eq!(r["bake_cache"], "hit", "{r}");
    let c = &r["comparison"];
    assert_eq!(c["nonfinite"], 0, "{c}");
    assert!(c["mean"].as_f64().expect("mean") <= 1e-4, "{c}");
    assert!(c["p99"].as_f64().expect("p99") <= 1e-5, "{c}");
}

/// Orbiting: every frame a new view at the internal resolution of the frame budget,
/// with fps statistics in the summary; the screenshot is a last still frame at the size
/// asked for (it was the 185x104 preview of a 480x270 orbit).
#[test]
fn view_orbits_and_reports_frame_rates() {
    let x = xvfb();
    let dir = tempfile::tempdir().expect("tempdir");
    let shot = dir.path().join("orbit.png");
    let o = view(&x, dir.path())
        .arg("view")
        .arg(scenes().join("luneburg.toml"))
        .args([
            "--frames",
            "6",
            "--orbit",
            "5",
            "--size",
            "128x72",
            "--json",
            "--screenshot",
        ])
        .arg(&shot)
        .output()
        .expect("run grin view");
    let s = json(&o);
    // Six orbit frames, then the still one for the screenshot.
    assert_eq!(s["frames"], 7, "{s}");
    let fps = &s["fps"];
    let (min, med, max) = (
        fps["min"].as_f64().expect("min"),
        fps["median"].as_f64().expect("median"),
        fps["max"].as_f64().expect("max"),
    );
    assert!(0.0 < min && min <= med && med <= max, "{fps}");
    // Per frame: wall and (where the adapter writes timestamps) device milliseconds, and
    // the bytes read back: no pixel (the image stays on the window's device); the first
    // frame of a method, and one every half second, reads 32 bytes of statistics and the
    // passes' timestamps (16 bytes a pass), the others nothing (the session's tests hold
    // that exactly).
    let wall = s["wall_ms"]["median"].as_f64().expect("wall_ms");
    assert!(wall > 0.0, "{s}");
    if let Some(d) = s["device_ms"]["median"].as_f64() {
        assert!(
            d > 0.0 && d <= 1.5 * s["wall_ms"]["max"].as_f64().expect("max"),
            "{s}"
        );
    }
    let bytes = s["read_back_bytes"]["max"]
        .as_f64()
        .expect("read_back_bytes");
    // (a timestamp pair a pass and band: a few bands on lavapipe), far below a row of
    // the image's pixels (128 x 64 bytes).
    assert!((32.0..=512.0).contains(&bytes), "{s}");
    assert!(
        s["adapter"] == s["display_adapter"],
        "the window draws on the renderer's device: {s}"
    );
    let internal = s["last_internal"].as_array().expect("internal size");
    assert!(internal[0].as_u64().expect("w") <= 128 && internal[1].as_u64().expect("h") <= 72);
    let png = image::open(&shot).expect("the screenshot is a PNG");
    assert_eq!((png.width(), png.height()), (128, 72));
}

/// Hot reload while the window renders: a broken edit is reported with file:line and
/// the last good scene keeps rendering; the next valid edit is taken.
#[test]
fn view_follows_edits_of_the_scene_file() {
    let x = xvfb();
    let dir = tempfile::tempdir().expect("tempdir");
    let scene = dir.path().join("scene.toml");
    let text = std::fs::read_to_string(scenes().join("luneburg.toml")).expect("read scene");
    std::fs::write(&scene, &text).expect("write scene");
    let mut child = view(&x, dir.path())
        .arg("view")
        .arg(&scene)
        .args(["--frames", "1000000", "--orbit", "1", "--size", "40x24"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run grin view");
    let (tx, rx) = std::sync::mpsc::channel::<String>();
    let err = child.stderr.take().expect("stderr");
    std::thread::spawn(move || {
        for line in BufReader::new(err).lines().map_while(Result::ok) {
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    let mut seen = Vec::new();
    let wait_for = |what: &str, seen: &mut Vec<String>| -> Option<String> {
        let deadline = Instant::now() + Duration::from_secs(120);
        while let Some(left) = deadline.checked_duration_since(Instant::now()) {
            match rx.recv_timeout(left) {
                Ok(line) => {
                    seen.push(line.clone());
                    if line.contains(what) {
                        return Some(line);
                    }
                }
                Err(_) => break,
            }
        }
        None
    };
    let first = wait_for("first frame", &mut seen);
    let broken = text.replacen("[camera]", "[camera]\nzoom = 3", 1);
    std::fs::write(&scene, &broken).expect("write broken scene");
    let refused = wait_for("not reloaded", &mut seen);
    // Frames go on with the last good scene meanwhile.
    std::thread::sleep(Duration::from_millis(1500));
    let valid = text.replacen("[camera]", "[camera]\n# edited", 1);
    std::fs::write(&scene, &valid).expect("write valid scene");
    let taken = wait_for("grin view: reloaded", &mut seen);
    let _ = child.kill();
    let _ = child.wait();
    let all = seen.join("\n");
    assert!(first.is_some(), "{all}");
    let refused = refused.unwrap_or_else(|| panic!("no refusal:\n{all}"));
    let line = broken
        .lines()
        .position(|l| l.contains("zoom"))
        .expect("line")
        + 1;
    assert!(
        refused.contains(&format!("scene.toml:{line}:")) && refused.contains("zoom"),
        "{refused}"
    );
    let taken = taken.unwrap_or_else(|| panic!("no reload:\n{all}"));
    // Frames went on between the refusal and the reload.
    let frame = |l: &str| -> u64 {
        l.split("(frame ")
            .nth(1)
            .and_then(|r| r.split(')').next())
            .and_then(|n| n.parse().ok())
            .unwrap_or_else(|| panic!("no frame number in {l}"))
    };
    assert!(frame(&taken) > frame(&refused), "{refused}\n{taken}");
    assert!(!all.contains("panicked"), "{all}");
}

#[test]
fn view_without_a_display_is_one_clear_error() {
    let o = grin()
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .arg("view")
        .arg(scenes().join("luneburg.toml"))
        .output()
        .expect("run grin view");
    assert_eq!(o.status.code(), Some(1));
    let e = stderr(&o);
    assert_eq!(e.lines().count(), 1, "{e}");
    assert!(
        e.starts_with("grin: error: grin view needs an X11 display and DISPLAY is not set"),
        "{e}"
    );
}

/// Without a display, `--offscreen` runs the same headless frames: the render thread's
/// texture copied where a window would draw it, no pixel read back but the screenshot's.
#[test]
fn view_offscreen_needs_no_display() {
    let dir = tempfile::tempdir().expect("tempdir");
    let shot = dir.path().join("shot.png");
    let o = run_ok(
        grin()
            .env_remove("DISPLAY")
            .env_remove("WAYLAND_DISPLAY")
            .env("GRIN_CACHE_DIR", dir.path().join("cache"))
            .arg("view")
            .arg(scenes().join("paper-a.toml"))
            .args([
                "--size",
                "48x27",
                "--frames",
                "3",
                "--orbit",
                "2",
                "--offscreen",
            ])
            .arg("--screenshot")
            .arg(&shot)
            .arg("--json"),
    );
    let s = json(&o);
    // Three orbit frames, and a still one for the screenshot where the orbit's were
    // smaller than asked.
    let frames = s["frames"].as_u64().expect("frames");
    assert!((3..=4).contains(&frames), "{s}");
    assert!(
        s["display_adapter"]
            .as_str()
            .is_some_and(|a| a.ends_with("(offscreen)")),
        "{s}"
    );
    assert!(s["fps"]["median"].as_f64().expect("fps") > 0.0, "{s}");
    let bytes = s["read_back_bytes"]["max"].as_f64().expect("bytes");
    assert!((32.0..=512.0).contains(&bytes), "{s}");
    let png = image::open(&shot).expect("the screenshot is a PNG");
    assert_eq!((png.width(), png.height()), (48, 27));
    // --offscreen is for headless runs only.
    let o = grin()
        .env_remove("DISPLAY")
        .arg("view")
        .arg(scenes().join("paper-a.toml"))
        .arg("--offscreen")
        .output()
        .expect("run grin view");
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--frames"), "{}", stderr(&o));
}

#[test]
fn view_of_a_broken_scene_is_one_clear_error() {
    let dir = tempfile::tempdir().expect("tempdir");
    let scene = dir.path().join("broken.toml");
    std::fs::write(
        &scene,
        "[camera]\nposition = [0.0, 0.0]\nlook_at = [0.0, 0.0, 0.0]\n",
    )
    .expect("write");
    let o = grin()
        .env("DISPLAY", ":9999")
        .arg("view")
        .arg(&scene)
        .output()
        .expect("run grin view");
    assert_eq!(o.status.code(), Some(1));
    let e = stderr(&o);
    assert!(
        e.starts_with("grin: error: ") && e.contains("broken.toml:2:") && !e.contains("panicked"),
        "{e}"
    );
}

#[test]
fn view_without_an_adapter_is_one_clear_error() {
    let x = xvfb();
    let dir = tempfile::tempdir().expect("tempdir");
    let o = view(&x, dir.path())
        .env("WGPU_ADAPTER_NAME", "no-such-adapter")
        .arg("view")
        .arg(scenes().join("luneburg.toml"))
        .args(["--frames", "1"])
        .output()
        .expect("run grin view");
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let e = stderr(&o);
    let errors: Vec<&str> = e
        .lines()
        .filter(|l| l.starts_with("grin: error:"))
        .collect();
    assert_eq!(errors.len(), 1, "{e}");
    assert!(
        errors[0].contains("no GPU device for the viewer") && errors[0].contains("no-such-adapter"),
        "{e}"
    );
    assert!(!e.contains("panicked"), "{e}");
}

/// The viewer names lavapipe's loop limit as `grin render` does: the Luneburg scene at a
/// fixed step of 1e-5 (~200,000 steps a ray) has pixels cut short on a CPU adapter, and the
/// summary's warnings say so once (the last frame's count, not one line a frame); on a
/// GPU, which has no such limit, there is no such warning.
#[test]
fn view_names_lavapipes_loop_limit() {
    let x = xvfb();
    let dir = tempfile::tempdir().expect("tempdir");
    let path = common::long_luneburg_scene(dir.path());
    let o = view(&x, dir.path())
        .arg("view")
        .arg(&path)
        .args(["--frames", "2", "--size", "32x18", "--json"])
        .output()
        .expect("run grin view");
    let s = json(&o);
    let adapter = s["adapter"].as_str().expect("adapter");
    let named: Vec<&str> = s["warnings"]
        .as_array()
        .expect("warnings")
        .iter()
        .filter_map(|w| w.as_str())
        .filter(|w| w.contains("on a CPU adapter (lavapipe)"))
        .collect();
    if adapter.ends_with(", Cpu)") {
        assert_eq!(named.len(), 1, "{s}");
        assert!(
            named[0].contains("pixels ended `error` after 2000+ steps"),
            "{s}"
        );
    } else {
        assert!(named.is_empty(), "{adapter}: {s}");
    }
}
