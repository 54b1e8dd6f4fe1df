//! The viewer without a window: every panel setting, edited through the same
//! `ViewSettings` the panel edits, changes the next frame of one running session (no
//! restart); accumulation and hot reload behave as the window relies on. On lavapipe.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

use grin_gpu::GpuContext;
use grin_render::image::Frame;
use grin_scene::{IntegratorKind, Interpolation, StepSpec};
use grin_view::session::{Rendered, Session};
use grin_view::settings::StepKind;
use grin_view::worker::{Request, internal_size};
use grin_view::{Aov, ViewSettings};

const W: u32 = 48;
const H: u32 = 32;

/// A noise ball drifting upwards in front of a checker wall.
static SCENE: std::sync::LazyLock<String> = std::sync::LazyLock::new(|| {
    let rest = r#"
[medium]
bounds = { sphere = { center = [0.0, 0.0, 0.0], radius = 1.0 } }
field = { kind = "noise", noise = "fbm", octaves = 2, frequency = 1.5, amplitude = 0.03, seed = 3, envelope = 0.3, drift = [0.0, 0.5, 0.0] }

[render]
width = 48
height = 32
spp = 1
integrator = "rk4"
step = { fixed = 0.02 }
jitter = false
"#;
    format!("{}{rest}", grin_testkit::scenes::WALL_SET)
});

fn scene_file(dir: &Path, text: &str) -> PathBuf {
    let p = dir.join("scene.toml");
    std::fs::write(&p, text).expect("write scene");
    p
}

/// A frame rendered and the accumulated image read back (as a screenshot reads it).
struct Shot {
    rendered: Rendered,
    frame: Frame,
}

impl std::ops::Deref for Shot {
    type Target = Rendered;
    fn deref(&self) -> &Rendered {
        &self.rendered
    }
}

fn render_only(s: &mut Session, v: &ViewSettings, w: u32, h: u32) -> Rendered {
    match s.render(v, w, h, false, &AtomicBool::new(false)) {
        Ok(r) => r,
        Err(grin_view::session::RenderFailure::Error(e)) => panic!("{e:#}"),
        Err(grin_view::session::RenderFailure::Cancelled) => panic!("cancelled"),
    }
}

fn render(s: &mut Session, v: &ViewSettings) -> Shot {
    let rendered = render_only(s, v, W, H);
    let frame = s.frame().expect("the image read back");
    Shot { rendered, frame }
}

/// Mean absolute beauty difference.
fn beauty_diff(a: &Shot, b: &Shot) -> f64 {
    assert_eq!(a.frame.pixels.len(), b.frame.pixels.len());
    a.frame
        .pixels
        .iter()
        .zip(&b.frame.pixels)
        .map(|(p, q)| {
            (0..3)
                .map(|c| f64::from((p.rgb[c] - q.rgb[c]).abs()))
                .sum::<f64>()
        })
        .sum::<f64>()
        / a.frame.pixels.len() as f64
}

fn max_deflection(r: &Shot) -> f32 {
    r.frame
        .pixels
        .iter()
        .map(|p| p.deflection_deg)
        .fold(0.0, f32::max)
}

#[test]
fn every_panel_setting_changes_the_next_frame_of_one_session() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = scene_file(dir.path(), &SCENE);
    let ctx = GpuContext::new_headless().expect("a wgpu adapter (lavapipe)");
    let mut s = Session::new(&ctx, &path, None).expect("session");
    let mut base = ViewSettings::from_scene(s.scene());
    base.max_spp = 1;
    // The renderer's own counts of what a frame reads back from the device: no pixel
    // (the image stays on the device, coloured into the window's texture). The first
    // frame of a method reads the 32 bytes of statistics and the passes' timestamps (16
    // bytes a pass, where the adapter writes them); the frames after it read nothing
    // until STATS_PERIOD has passed, and the next read counts them all. Frames of one
    // view accumulate (no jitter: each the same rays) towards a far `max_spp`.
    let period = grin_view::session::STATS_PERIOD;
    let mut long = base.clone();
    long.max_spp = 10_000;
    let first = render_only(&mut s, &long, W, H);
    assert!(
        (32..=32 + 32).contains(&first.read_back_bytes),
        "{} bytes read back for {W}x{H} pixels",
        first.read_back_bytes
    );
    let since = std::time::Instant::now();
    let mut quiet = 0;
    while since.elapsed() < period / 2 {
        let r = render_only(&mut s, &long, W, H);
        if since.elapsed() >= period {
            break; // this frame may have read
        }
        assert_eq!(r.read_back_bytes, 0, "frame {quiet} after the read");
        assert_eq!(r.device_seconds, None, "no timestamps read");
        assert_eq!(
            r.steps_per_ray, first.steps_per_ray,
            "the last read's means"
        );
        quiet += 1;
    }
    assert!(
        quiet > 0,
        "no {W}x{H} frame within {period:?} of the last: too slow to test"
    );
    std::thread::sleep(period);
    let r = render_only(&mut s, &long, W, H);
    assert!(
        (32..=32 + 32).contains(&r.read_back_bytes),
        "{}",
        r.read_back_bytes
    );
    assert_eq!(r.samples, quiet + 2, "one image, every frame added");
    assert_eq!(s.pixel_bytes_read_back(), 0, "no pixel crossed to the CPU");
    // The read's means are over every frame since the first's read: with the first's,
    // they make the accumulated image's mean steps a ray.
    let n = f64::from(r.samples);
    let image = s.frame().expect("the image read back");
    let all = image.pixels.iter().map(|p| f64::from(p.steps)).sum::<f64>() / f64::from(W * H);
    let since_first = (n * all - first.steps_per_ray) / (n - 1.0);
    let off = (r.steps_per_ray - since_first).abs() / since_first;
    assert!(
        off < 1e-5,
        "{} against {since_first} ({n} frames)",
        r.steps_per_ray
    );
    // The frame that completes a still image reads, however soon after the last read.
    let mut two = base.clone();
    two.max_spp = 2;
    let a = render_only(&mut s, &two, W, H);
    assert!(!a.converged, "one of two samples");
    let b = render_only(&mut s, &two, W, H);
    assert!(b.converged, "two frames of one sample");
    assert!(b.read_back_bytes > 0, "the completing frame reads");
    let r0 = render(&mut s, &base);
    assert_eq!(
        s.pixel_bytes_read_back(),
        2 * u64::from(W * H) * 64,
        "read on request: twice"
    );
    assert!(max_deflection(&r0) > 0.05, "{}", max_deflection(&r0));

    // Integrator: rk4 spends 4 field evaluations a step, euler 1.
    let mut v = base.clone();
    v.integrator = Some(IntegratorKind::Euler);
    let r = render(&mut s, &v);
    assert!(
        r.evals_per_ray < 0.5 * r0.evals_per_ray,
        "euler {} vs rk4 {} evals/ray",
        r.evals_per_ray,
        r0.evals_per_ray
    );

    // Step size: a quarter of the step, about 4x the steps in the medium.
    let mut v = base.clone();
    v.step = StepSpec::Fixed(0.005);
    let r = render(&mut s, &v);
    assert!(
        r.steps_per_ray > 2.0 * r0.steps_per_ray,
        "{} vs {}",
        r.steps_per_ray,
        r0.steps_per_ray
    );

    // Step policy: the accuracy knob renders, with other steps.
    let mut v = base.clone();
    v.step = StepKind::Auto.with_value(1e-3);
    let r = render(&mut s, &v);
    assert!(
        (r.steps_per_ray - r0.steps_per_ray).abs() > 0.5,
        "{}",
        r.steps_per_ray
    );
    assert!(beauty_diff(&r, &r0) < 0.05, "same picture, other steps");
    // The panel shows what was traced: the file's method, and with `auto` what the pilot
    // rays chose among the named integrator's steps.
    assert_eq!(r0.method, "rk4, fixed ds 0.0200");
    assert!(r.method.starts_with("rk4, "), "{}", r.method);
    assert_ne!(r.method, r0.method);

    // Interpolation: the tricubic B-spline of the same grid bends rays differently from
    // its trilinear interpolation.
    let mut v = base.clone();
    v.interpolation = Some(Interpolation::Trilinear);
    let lin = render(&mut s, &v);
    v.interpolation = Some(Interpolation::Tricubic);
    let r = render(&mut s, &v);
    let d = r
        .frame
        .pixels
        .iter()
        .zip(&lin.frame.pixels)
        .map(|(p, q)| (p.deflection_deg - q.deflection_deg).abs())
        .fold(0.0f32, f32::max);
    assert!(d > 1e-4, "tricubic deflection differs by {d}");

    // Medium off: no deflection, no steps; on again: back.
    let mut v = base.clone();
    v.medium = false;
    let r = render(&mut s, &v);
    assert_eq!(max_deflection(&r), 0.0);
    assert_eq!(r.steps_per_ray, 0.0);
    let r = render(&mut s, &base);
    assert!(max_deflection(&r) > 0.05);

    // Time: the noise drifts.
    let mut v = base.clone();
    v.time = 1.0;
    let r = render(&mut s, &v);
    assert!(beauty_diff(&r, &r0) > 1e-3, "{}", beauty_diff(&r, &r0));

    // Camera: another view, and the accumulation starts again.
    let mut v = base.clone();
    v.camera.orbit_degrees(20.0);
    let r = render(&mut s, &v);
    assert_eq!(r.samples, 1);
    assert!(beauty_diff(&r, &r0) > 1e-2);

    // spp: each frame adds its samples.
    let mut v = base.clone();
    v.spp = 3;
    v.max_spp = 9;
    let samples: Vec<u32> = (0..3).map(|_| render(&mut s, &v).samples).collect();
    assert_eq!(samples, [3, 6, 9]);
    assert!(!s.needs_frame(&v, W, H), "converged: nothing to add");

    // The AOV shown is display only: no new frame, another picture, coloured on the
    // device as the screenshot's PNG colours it (display::rgba), to within a level.
    let mut shown = v.clone();
    shown.aov = Aov::Deflection;
    assert!(!s.needs_frame(&shown, W, H));
    let last = render(&mut s, &base);
    for aov in Aov::ALL {
        let (want, scale) = grin_view::display::rgba(&last.frame, aov);
        let (_, device_scale) = s.show(aov).expect("show");
        assert_eq!(s.shown_aov(), Some(aov));
        assert_eq!(device_scale, scale, "{aov:?}'s colour scale");
        let texels = s.displayed().expect("texture read back");
        assert_eq!(texels.len(), (W * H) as usize);
        let worst = texels
            .iter()
            .zip(want.chunks(4))
            .flat_map(|(t, w)| {
                (0..3).map(move |c| {
                    (i32::from(grin_render::image::linear_to_srgb8(t[c])) - i32::from(w[c])).abs()
                })
            })
            .max();
        assert!(worst <= Some(1), "{aov:?}: off by {worst:?} of 255");
    }
    let (beauty, _) = grin_view::display::rgba(&last.frame, Aov::Beauty);
    let (defl, scale) = grin_view::display::rgba(&last.frame, Aov::Deflection);
    assert_ne!(beauty, defl);
    assert!((scale - max_deflection(&last)).abs() < 1e-6);

    // Resolution scale: the internal image is the scaled one.
    let mut v = base.clone();
    v.resolution_scale = 0.5;
    let req = Request {
        settings: v.clone(),
        width: W,
        height: H,
        moving: false,
        reload: false,
        capture: None,
    };
    let (w, h, _) = internal_size(&req, None);
    assert_eq!((w, h), (W / 2, H / 2));
    s.set_display_size(W, H);
    let r = render_only(&mut s, &v, w, h);
    assert_eq!((r.width, r.height), (W / 2, H / 2));
    // Shown scaled to the window's image area.
    assert_eq!(r.display.size, [W, H]);
    assert_eq!(s.frame().expect("frame").width, W / 2);
}

/// A frame cancelled part-way may have added some bands to the image on the device: the
/// next frame of the same view starts the image again instead of adding to it.
#[test]
fn a_cancelled_frame_restarts_the_image() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = scene_file(dir.path(), &SCENE);
    let ctx = GpuContext::new_headless().expect("a wgpu adapter (lavapipe)");
    let mut s = Session::new(&ctx, &path, None).expect("session");
    let mut v = ViewSettings::from_scene(s.scene());
    v.spp = 2;
    v.max_spp = 8;
    assert_eq!(render_only(&mut s, &v, W, H).samples, 2);
    assert_eq!(render_only(&mut s, &v, W, H).samples, 4);
    let cancelled = s.render(&v, W, H, false, &AtomicBool::new(true));
    assert!(matches!(
        cancelled,
        Err(grin_view::session::RenderFailure::Cancelled)
    ));
    assert!(s.needs_frame(&v, W, H));
    let again = render_only(&mut s, &v, W, H);
    assert_eq!(again.samples, 2, "started again, not 6 samples");
    let fresh = {
        let mut t = Session::new(&ctx, &path, None).expect("session");
        render_only(&mut t, &v, W, H);
        t.frame().expect("frame")
    };
    let restarted = s.frame().expect("frame");
    // The same two samples as a fresh session's first frame.
    for (a, b) in restarted.pixels.iter().zip(&fresh.pixels) {
        assert_eq!(a.rgb, b.rgb);
    }
}

/// The render thread (no window): a still view's frames, the image coloured again in
/// another AOV without a new frame, and the image read back on request, once.
#[test]
fn the_render_thread_recolours_and_captures_without_new_frames() {
    use grin_view::worker::{Reply, Worker};
    use std::time::Duration;
    let dir = tempfile::tempdir().expect("tempdir");
    let path = scene_file(dir.path(), &SCENE);
    let ctx = std::sync::Arc::new(GpuContext::new_headless().expect("a wgpu adapter"));
    let worker = Worker::start(ctx, path.clone(), None, None);
    let mut v = ViewSettings::from_scene(&grin_view::session::load(&path).expect("scene"));
    v.max_spp = 1;
    let request = |settings: &ViewSettings| Request {
        settings: settings.clone(),
        width: W,
        height: H,
        moving: false,
        reload: false,
        capture: None,
    };
    let next = || {
        worker
            .replies
            .recv_timeout(Duration::from_secs(120))
            .expect("a reply from the render thread")
    };
    worker.send(request(&v), false);
    // Started, a preview maybe, then the full frame.
    loop {
        match next() {
            Reply::Frame(f) if !f.preview => {
                assert_eq!((f.rendered.width, f.rendered.height), (W, H));
                assert_eq!(f.rendered.samples, 1);
                break;
            }
            Reply::Started { .. } | Reply::Frame(_) => {}
            other => panic!("unexpected {other:?}"),
        }
    }
    let mut shown = v.clone();
    shown.aov = Aov::Deflection;
    worker.send(request(&shown), false);
    let scale = match next() {
        Reply::Shown {
            aov,
            scale,
            display,
        } => {
            assert_eq!(aov, Aov::Deflection);
            assert_eq!(display.size, [W, H]);
            scale
        }
        other => panic!("expected the image coloured again, got {other:?}"),
    };
    let (tx, rx) = std::sync::mpsc::channel();
    worker.send(
        Request {
            capture: Some(tx),
            ..request(&shown)
        },
        false,
    );
    let frame = rx
        .recv_timeout(Duration::from_secs(60))
        .expect("captured")
        .expect("the image read back");
    assert_eq!((frame.width, frame.height), (W, H));
    let largest = frame
        .pixels
        .iter()
        .map(|p| p.deflection_deg.abs())
        .fold(0.0, f32::max);
    assert_eq!(
        scale, largest,
        "the colour scale is the image's largest deflection"
    );
    // Converged and shown: nothing more comes.
    assert!(
        worker
            .replies
            .recv_timeout(Duration::from_millis(300))
            .is_err()
    );
}

#[test]
fn while_moving_the_resolution_drops_to_the_frame_budget() {
    let mut v = ViewSettings::from_scene(
        &grin_scene::parse_scene(&SCENE, Path::new("s.toml")).expect("scene"),
    );
    v.target_fps = 20.0;
    let req = |moving| Request {
        settings: v.clone(),
        width: 800,
        height: 400,
        moving,
        reload: false,
        capture: None,
    };
    // 1 us per pixel-sample: the full frame takes 0.32 s, the budget is 0.05 s.
    let (w, h, scale) = internal_size(&req(true), Some(1e-6));
    assert!((scale - (0.05f64 / 0.32).sqrt()).abs() < 1e-9, "{scale}");
    assert_eq!(
        (w, h),
        (
            (800.0 * scale).round() as u32,
            (400.0 * scale).round() as u32
        )
    );
    // Still: the full resolution, whatever it costs.
    assert_eq!(internal_size(&req(false), Some(1e-6)).2, 1.0);
    // Moving before any frame's cost is known: the first preview's size.
    assert_eq!(
        internal_size(&req(true), None).2,
        grin_view::worker::FIRST_PREVIEW_SCALE
    );
}

#[test]
fn reload_follows_the_file_and_keeps_the_last_good_scene() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = scene_file(dir.path(), &SCENE);
    let ctx = GpuContext::new_headless().expect("a wgpu adapter (lavapipe)");
    let mut s = Session::new(&ctx, &path, None).expect("session");
    // One sample a frame, no accumulation: equal views render equal frames.
    let mut v = ViewSettings::from_scene(s.scene());
    v.max_spp = 1;
    let r0 = render(&mut s, &v);

    // Broken: an unknown key in the wall's material. The error names file, line and key; the last
    // good scene still renders the same image.
    let broken = SCENE.replace("scale = 0.2 }", "scale = 0.2, shine = 1 }");
    std::fs::write(&path, &broken).expect("write");
    let line = broken
        .lines()
        .position(|l| l.contains("shine"))
        .expect("line")
        + 1;
    let e = format!("{:#}", s.reload().expect_err("a broken scene is refused"));
    assert!(
        e.contains(&format!("scene.toml:{line}:")) && e.contains("shine"),
        "{e}"
    );
    let r = render(&mut s, &v);
    assert!(beauty_diff(&r, &r0) < 1e-6);

    // Valid again, with another wall colour: taken, and the picture follows; the user's
    // own edits of settings the file did not change are kept.
    let fixed = SCENE.replace("color_a = [0.9, 0.9, 0.85]", "color_a = [0.9, 0.2, 0.1]");
    std::fs::write(&path, &fixed).expect("write");
    let mut new_file = s.reload().expect("valid again");
    new_file.max_spp = 1;
    let mut edited = v.clone();
    edited.aov = Aov::Steps;
    edited.integrator = Some(IntegratorKind::Sharma);
    edited.rebase(&v, &new_file);
    assert_eq!(edited.integrator, Some(IntegratorKind::Sharma));
    assert_eq!(edited.aov, Aov::Steps);
    let r = render(&mut s, &v);
    assert!(beauty_diff(&r, &r0) > 1e-2, "{}", beauty_diff(&r, &r0));

    // A file change to the step is taken over the user's unchanged setting.
    let stepped = fixed.replace("step = { fixed = 0.02 }", "step = { fixed = 0.05 }");
    std::fs::write(&path, &stepped).expect("write");
    let newer = s.reload().expect("valid");
    let mut mine = new_file.clone();
    mine.rebase(&new_file, &newer);
    assert_eq!(mine.step, StepSpec::Fixed(0.05));
}

/// The field's own warnings (here a VDB grid whose data the bounds cut) reach the list
/// the panel shows, before the bake's: library code returns them, the viewer shows them.
#[test]
fn the_fields_own_warnings_reach_the_panel() {
    let dir = tempfile::tempdir().expect("tempdir");
    let vdb = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/vdb/test/gaussian.vdb");
    // A Gaussian of width 0.25 about (0.1, -0.05, 0.2): a sphere of radius 0.3 cuts it.
    let text = format!(
        r#"
[camera]
position = [0.1, -0.05, -3.0]
look_at = [0.1, -0.05, 0.2]
fov_y_deg = 30.0

[medium]
bounds = {{ sphere = {{ center = [0.1, -0.05, 0.2], radius = 0.3 }} }}
field = {{ kind = "vdb", path = "{}", grid = "delta_n", map = {{ index = {{ delta = true }} }} }}

[render]
width = 48
height = 32
spp = 1
"#,
        vdb.display()
    );
    let path = scene_file(dir.path(), &text);
    let ctx = GpuContext::new_headless().expect("a wgpu adapter (lavapipe)");
    let mut s = Session::new(&ctx, &path, None).expect("session");
    let v = ViewSettings::from_scene(s.scene());
    render(&mut s, &v);
    assert!(
        s.warnings
            .first()
            .is_some_and(|w| w.contains("the [medium] bounds cut the grid's data")),
        "{:?}",
        s.warnings
    );
}

/// The viewer resolves `step = { auto }` as `grin render --backend gpu` does: the same
/// pilots in the same precision, held to an `[optics]` output's accuracy in its own unit
/// (here pixels of displacement), so both trace the frame with the same integrator and
/// step.
#[test]
fn the_auto_step_is_the_one_grin_render_chooses() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (w, h) = (64, 32);
    let auto = SCENE
        .replace(
            "width = 48\nheight = 32",
            &format!("width = {w}\nheight = {h}"),
        )
        .replace("integrator = \"rk4\"\nstep = { fixed = 0.02 }\n", "");
    let optics = "\n[optics]\nmode = \"displacement\"\nplane = { point = [0.0, 0.0, 1.5], \
                  normal = [0.0, 0.0, -1.0] }\naccuracy = 0.00001\n";
    let with_optics = scene_file(dir.path(), &format!("{auto}{optics}"));
    let ctx = GpuContext::new_headless().expect("a wgpu adapter (lavapipe)");
    let mut s = Session::new(&ctx, &with_optics, None).expect("session");
    let v = ViewSettings::from_scene(s.scene());
    let viewed = render_only(&mut s, &v, w, h).method;

    // grin render's choice for the same view of the same file, and for the file without
    // its [optics] table (the exit direction to 1e-4 rad, what the viewer chose before).
    let chosen = |scene: &grin_scene::Scene| {
        let applied = v.apply(scene, w, h);
        let field = grin_pipeline::build_field(&applied, dir.path(), "scene").expect("field");
        let renderer = grin_pipeline::Renderer::new(grin_pipeline::Backend::Gpu, false);
        let p = renderer
            .prepare(&applied, dir.path(), "scene", field)
            .expect("prepared");
        let unit = p.auto.as_ref().expect("pilots ran").unit;
        (
            grin_view::session::method_name(&p.render_scene.settings),
            unit,
        )
    };
    let scene = s.scene().clone();
    let (rendered, unit) = chosen(&scene);
    assert_eq!(unit, "px");
    assert_eq!(
        viewed, rendered,
        "the viewer traces what grin render traces"
    );
    let mut bare = scene;
    bare.optics = None;
    let (radians, unit) = chosen(&bare);
    assert_eq!(unit, "rad");
    assert_ne!(
        rendered, radians,
        "the [optics] accuracy changes the choice (else this test shows nothing)"
    );
}
