//! Renderer tests against exact answers: a uniform medium equal to ambient is invisible,
//! a constant-n ball refracts by Snell's law at its two surfaces, a lit Lambertian plane
//! has radiance albedo / pi * I cos / d^2, a mirror shows the reflected sky.

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use glam::DVec3;
use grin_field::{Bounds, IndexField};
use grin_scene::{BoundsSpec, FieldSpec, MediumSpec, Scene, StepSpec, parse_scene};

use super::materials::refract_dir;
use super::primitives::intersect_sphere;
use super::shade::status_code;
use super::{RenderScene, render_cpu};
use crate::trace::RayStatus;
use grin_render::image::Frame;

/// n = `n` inside `bounds`, 1 outside.
fn constant(bounds: Bounds, n: f64) -> Arc<dyn IndexField> {
    Arc::new(grin_field::analytic::Uniform::new(bounds, 1.0, n).expect("n > 0"))
}

const PAPER_LIKE: &str = r#"
[camera]
position = [0.0, 1.0, -4.0]
look_at = [0.0, 0.5, 0.0]
fov_y_deg = 40.0

[[object]]
shape = { plane = { point = [0.0, 0.0, 0.0], normal = [0.0, 1.0, 0.0] } }
material = { checker = { scale = 0.5 } }

[[object]]
shape = { sphere = { center = [0.8, 0.5, 1.0], radius = 0.5 } }
material = "glass"

[[object]]
shape = { sphere = { center = [-0.8, 0.5, 1.0], radius = 0.5 } }
material = "metal"

[[light]]
point = { position = [2.0, 4.0, -2.0], intensity = [40.0, 40.0, 40.0] }

[render]
width = 48
height = 27
spp = 2
step = { fixed = 0.02 }
"#;

fn scene(text: &str) -> Scene {
    parse_scene(text, Path::new("test.toml")).expect("test scene parses")
}

fn render(scene: &Scene, field: Option<Arc<dyn IndexField>>) -> Frame {
    let rs = RenderScene::new(scene, Path::new("."), field).expect("scene resolves");
    render_cpu(&rs, &|_| {}, &AtomicBool::new(false)).expect("render")
}

fn max_beauty_diff(a: &Frame, b: &Frame) -> f32 {
    a.pixels
        .iter()
        .zip(&b.pixels)
        .flat_map(|(p, q)| (0..3).map(move |c| (p.rgb[c] - q.rgb[c]).abs()))
        .fold(0.0, f32::max)
}

#[test]
fn uniform_medium_at_ambient_index_is_invisible() {
    let plain = scene(PAPER_LIKE);
    let without = render(&plain, None);
    // A box medium that the ground plane and the metal ball cut through: objects inside
    // it are found by the per-step chord test, and rays cross its faces many ways.
    for (bounds, spec) in [
        (
            Bounds::Box {
                min: DVec3::new(-1.5, -0.3, -0.5),
                max: DVec3::new(0.3, 1.2, 1.6),
            },
            BoundsSpec::Box {
                min: [-1.5, -0.3, -0.5],
                max: [0.3, 1.2, 1.6],
            },
        ),
        (
            Bounds::Sphere {
                center: DVec3::new(0.0, 0.5, 0.0),
                radius: 0.6,
            },
            BoundsSpec::Sphere {
                center: [0.0, 0.5, 0.0],
                radius: 0.6,
            },
        ),
    ] {
        let mut with_medium = plain.clone();
        with_medium.medium = Some(MediumSpec {
            bounds: spec,
            ambient_index: 1.0.into(),
            field: FieldSpec::Uniform { n: 1.0 },
        });
        let field: Arc<dyn IndexField> = constant(bounds, 1.0);
        let with = render(&with_medium, Some(field));
        let d = max_beauty_diff(&with, &without);
        // Identical up to the f64 rounding of the stepped straight line (then f32 output).
        assert!(d < 1e-5, "uniform medium changed the image by {d}");
        let entered = with.pixels.iter().filter(|p| p.status != 0.0).count();
        assert!(entered > 50, "only {entered} pixels entered the medium");
        assert!(
            with.pixels
                .iter()
                .all(|p| p.deflection_deg.abs() < 1e-5 && p.opd.abs() < 1e-6)
        );
        // Hits on objects inside the medium are reported as absorbed there.
        if matches!(bounds, Bounds::Box { .. }) {
            assert!(
                with.pixels
                    .iter()
                    .any(|p| p.status == f32::from(status_code(RayStatus::Absorbed)))
            );
        }
    }
}

/// The exact path of a ray through a constant-index ball: Snell in, straight, Snell out.
fn snell_through_ball(c: DVec3, r: f64, n: f64, o: DVec3, d: DVec3) -> Option<DVec3> {
    let (t_in, nrm) = intersect_sphere(c, r, o, d, 0.0, f64::INFINITY)?;
    let p = o + d * t_in;
    let inside = refract_dir(d, nrm, 1.0, n)?;
    let (_, nrm_out) = intersect_sphere(c, r, p, inside, 1e-9, f64::INFINITY)?;
    refract_dir(inside, -nrm_out, n, 1.0)
}

#[test]
fn constant_n_ball_matches_snell() {
    let mut s = scene(PAPER_LIKE);
    s.objects.clear();
    s.render.spp = 1;
    (s.render.width, s.render.height) = (64, 36);
    let (c, r, n) = (DVec3::new(0.0, 0.5, 0.0), 0.6, 1.33);
    s.medium = Some(MediumSpec {
        bounds: BoundsSpec::Sphere {
            center: c.to_array(),
            radius: r,
        },
        ambient_index: 1.0.into(),
        field: FieldSpec::Uniform { n },
    });
    let field: Arc<dyn IndexField> = constant(
        Bounds::Sphere {
            center: c,
            radius: r,
        },
        n,
    );
    let rs = RenderScene::new(&s, Path::new("."), Some(field)).expect("scene");
    let frame = render_cpu(&rs, &|_| {}, &AtomicBool::new(false)).expect("render");
    let mut checked = 0;
    let mut max_err: f64 = 0.0;
    for py in 0..s.render.height {
        for px in 0..s.render.width {
            let p = frame.pixels[(py * s.render.width + px) as usize];
            let d = rs.camera.primary_ray(px, py, 0.5, 0.5);
            match snell_through_ball(c, r, n, rs.camera.origin, d) {
                Some(expected) if p.status == 1.0 => {
                    let got = DVec3::from(p.exit_dir.map(f64::from));
                    max_err = max_err.max((got - expected).length());
                    let defl = d.angle_between(expected).to_degrees();
                    assert!((f64::from(p.deflection_deg) - defl).abs() < 1e-3);
                    checked += 1;
                }
                Some(_) => panic!(
                    "pixel ({px}, {py}) should pass the ball, status {}",
                    p.status
                ),
                None => assert_eq!(p.status, 0.0, "pixel ({px}, {py}) misses the ball"),
            }
        }
    }
    assert!(checked > 100, "only {checked} pixels through the ball");
    // f32 output of the direction: ~1e-7; the geometry itself is exact to ~1e-12.
    assert!(max_err < 1e-6, "exit direction off Snell by {max_err}");
}

#[test]
fn lambertian_plane_under_a_point_light_has_the_exact_radiance() {
    let text = r#"
[camera]
position = [0.0, 3.0, 0.0]
look_at = [0.0, 0.0, 0.0]
up = [0.0, 0.0, 1.0]
fov_y_deg = 10.0
[[object]]
shape = { plane = { point = [0.0, 0.0, 0.0], normal = [0.0, 1.0, 0.0] } }
material = { diffuse = { color = [0.5, 0.25, 1.0] } }
[[light]]
point = { position = [0.0, 2.0, 0.0], intensity = [8.0, 8.0, 8.0] }
[sky]
gradient = { horizon = [0.0, 0.0, 0.0], zenith = [0.0, 0.0, 0.0], ground = [0.0, 0.0, 0.0] }
[render]
width = 3
height = 3
"#;
    let f = render(&scene(text), None);
    let centre = f.pixels[4].rgb;
    // L = albedo / pi * I / d^2 with d = 2, normal incidence.
    for (c, albedo) in [0.5, 0.25, 1.0].into_iter().enumerate() {
        let expected = albedo / std::f32::consts::PI * 8.0 / 4.0;
        assert!(
            (centre[c] - expected).abs() < 1e-5,
            "channel {c}: {} vs {expected}",
            centre[c]
        );
    }
}

#[test]
fn mirror_shows_the_sky_and_max_depth_ends_paths() {
    let text = r#"
[camera]
position = [0.0, 1.0, -3.0]
look_at = [0.0, 0.0, 0.0]
[[object]]
shape = { plane = { point = [0.0, 0.0, 0.0], normal = [0.0, 1.0, 0.0] } }
material = { mirror = { color = [0.5, 0.5, 0.5] } }
[render]
width = 5
height = 5
"#;
    let s = scene(text);
    let f = render(&s, None);
    let rs = RenderScene::new(&s, Path::new("."), None).expect("scene");
    let d = rs.camera.primary_ray(2, 4, 0.5, 0.5);
    let reflected = DVec3::new(d.x, -d.y, d.z);
    let expected = rs.sky.sky_radiance(reflected) * 0.5;
    let got = DVec3::from(f.pixels[22].rgb.map(f64::from));
    assert!((got - expected).length() < 1e-6, "{got} vs {expected}");
    // With max_depth 0 the mirror cannot bounce: the pixel is black.
    let mut s0 = s.clone();
    s0.render.max_depth = 0;
    assert_eq!(render(&s0, None).pixels[22].rgb, [0.0; 3]);
}

#[test]
fn step_cap_gives_max_steps_status_and_bad_settings_are_rejected() {
    let mut s = scene(PAPER_LIKE);
    s.render.max_steps = 2;
    s.render.spp = 1;
    s.render.step = StepSpec::Fixed(0.001);
    let bounds = Bounds::Sphere {
        center: DVec3::new(0.0, 0.5, 0.0),
        radius: 0.6,
    };
    let field: Arc<dyn IndexField> = constant(bounds, 1.2);
    let f = render(&s, Some(field.clone()));
    let capped = f.pixels.iter().filter(|p| p.status == 3.0).count();
    assert!(capped > 20);
    assert!(
        f.pixels
            .iter()
            .filter(|p| p.status == 3.0)
            .all(|p| p.rgb == [0.0; 3])
    );
    s.render.step = StepSpec::Fixed(-1.0);
    let e = RenderScene::new(&s, Path::new("."), Some(field)).expect_err("negative step");
    assert!(e.to_string().contains("step"), "{e}");
    let mut huge = scene(PAPER_LIKE);
    (huge.render.width, huge.render.height) = (100_000, 100_000);
    let e = RenderScene::new(&huge, Path::new("."), None).expect_err("too big");
    assert!(e.to_string().contains("exceeds"), "{e}");
    let mut bad = scene(PAPER_LIKE);
    bad.camera.look_at = bad.camera.position;
    let e = RenderScene::new(&bad, Path::new("."), None).expect_err("degenerate camera");
    assert!(e.to_string().starts_with("camera:"), "{e}");
}

#[test]
fn cancel_stops_the_render() {
    let s = scene(PAPER_LIKE);
    let rs = RenderScene::new(&s, Path::new("."), None).expect("scene");
    let e = render_cpu(&rs, &|_| {}, &AtomicBool::new(true)).expect_err("cancelled");
    assert!(matches!(e, super::RenderError::Cancelled));
}

#[test]
fn bent_shadow_ray_through_a_ball_lens_carries_its_fresnel_transmittance() {
    // A ground point straight below a constant-n ball, the light straight above it: the
    // shadow ray crosses both surfaces at normal incidence and is not deviated, so bending
    // it multiplies the direct light by (1 - R)^2, R = ((n - 1)/(n + 1))^2.
    let text = r#"
[camera]
position = [2.0, 0.5, 0.0]
look_at = [0.0, 0.0, 0.0]
[[object]]
shape = { plane = { point = [0.0, 0.0, 0.0], normal = [0.0, 1.0, 0.0] } }
material = { diffuse = { color = [1.0, 1.0, 1.0] } }
[[light]]
point = { position = [0.0, 3.0, 0.0], intensity = [9.0, 9.0, 9.0] }
[sky]
gradient = { horizon = [0.0, 0.0, 0.0], zenith = [0.0, 0.0, 0.0], ground = [0.0, 0.0, 0.0] }
[medium]
bounds = { sphere = { center = [0.0, 1.5, 0.0], radius = 0.5 } }
field = { kind = "uniform", n = 1.5 }
[render]
width = 3
height = 3
"#;
    let n = 1.5;
    let field: Arc<dyn IndexField> = constant(
        Bounds::Sphere {
            center: DVec3::new(0.0, 1.5, 0.0),
            radius: 0.5,
        },
        n,
    );
    let mut s = scene(text);
    let straight = render(&s, Some(field.clone())).pixels[4].rgb[0];
    s.render.bend_shadow_rays = true;
    let bent = render(&s, Some(field)).pixels[4].rgb[0];
    // Straight shadow rays ignore the medium (the paper): I / d^2 / pi.
    assert!(
        (straight - 1.0 / std::f32::consts::PI).abs() < 1e-6,
        "{straight}"
    );
    let r = ((n - 1.0) / (n + 1.0)).powi(2);
    let expected = (1.0 - r) * (1.0 - r);
    assert!(
        (f64::from(bent / straight) - expected).abs() < 1e-6,
        "ratio {} vs {expected}",
        bent / straight
    );
}

#[test]
fn jitter_moves_steps_but_not_the_refracted_rays() {
    let mut s = scene(PAPER_LIKE);
    s.render.spp = 1;
    s.render.step = StepSpec::Fixed(0.05);
    let bounds = Bounds::Sphere {
        center: DVec3::new(0.0, 0.5, 0.0),
        radius: 0.6,
    };
    let field: Arc<dyn IndexField> = constant(bounds, 1.2);
    s.render.jitter = false;
    let plain = render(&s, Some(field.clone()));
    s.render.jitter = true;
    let jittered = render(&s, Some(field));
    let mut moved = 0;
    for (a, b) in plain.pixels.iter().zip(&jittered.pixels) {
        assert_eq!(a.status, b.status);
        let da = DVec3::from(a.exit_dir.map(f64::from));
        let db = DVec3::from(b.exit_dir.map(f64::from));
        assert!(
            (da - db).length() < 1e-6,
            "constant n: jitter must not change the path"
        );
        if a.steps != b.steps {
            moved += 1;
        }
    }
    // A shorter first step shifts the step grid: some rays need one step more.
    assert!(moved > 10, "{moved} pixels changed their step count");
}

#[test]
fn environment_maps_from_exr_and_hdr_light_the_background() {
    let dir = std::env::temp_dir().join(format!("grin-envmap-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("tmp dir");
    // A uniform map: every direction sees the same radiance, so the pixel value is exact.
    let value = [0.25f32, 0.5, 2.0];
    exr::prelude::write_rgb_file(dir.join("sky.exr"), 16, 8, |_, _| {
        (value[0], value[1], value[2])
    })
    .expect("exr");
    let hdr = std::fs::File::create(dir.join("sky.hdr")).expect("hdr file");
    let texels = vec![image::Rgb(value); 16 * 8];
    image::codecs::hdr::HdrEncoder::new(std::io::BufWriter::new(hdr))
        .encode(&texels, 16, 8)
        .expect("hdr");
    for name in ["sky.exr", "sky.hdr"] {
        let text = format!(
            "[camera]\nposition = [0.0, 0.0, 0.0]\nlook_at = [0.0, 0.0, 1.0]\n[sky]\nmap = {{ path = \"{name}\", intensity = 3.0 }}\n[render]\nwidth = 4\nheight = 2\n"
        );
        let s = scene(&text);
        let rs = RenderScene::new(&s, &dir, None).expect("scene with a map");
        let f = render_cpu(&rs, &|_| {}, &AtomicBool::new(false)).expect("render");
        for p in &f.pixels {
            for (&got, &v) in p.rgb.iter().zip(&value) {
                // Radiance HDR stores 8-bit mantissas: ~1% quantisation.
                let rel = (got - 3.0 * v).abs() / (3.0 * v);
                assert!(rel < 1e-2, "{name}: {:?}", p.rgb);
            }
        }
    }
    let s = scene(
        "[camera]\nposition = [0.0, 0.0, 0.0]\nlook_at = [0.0, 0.0, 1.0]\n[sky]\nmap = { path = \"nope.exr\" }\n",
    );
    let e = RenderScene::new(&s, &dir, None).expect_err("missing map");
    assert!(e.to_string().contains("nope.exr"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}
