//! GPU (lavapipe in CI) vs the CPU reference on the same scenes and the same baked field.

mod harness;

use std::path::Path;

use grin_scene::parse_scene;

/// The paper's test scene: ground plane, glass and steel balls, a GRIN sphere in front.
fn paper_scene(field: &str) -> String {
    format!(
        r#"
[camera]
position = [0.0, 1.0, -4.0]
look_at = [0.0, 0.6, 0.0]
fov_y_deg = 40.0

[[object]]
shape = {{ plane = {{ point = [0.0, 0.0, 0.0], normal = [0.0, 1.0, 0.0] }} }}
material = {{ checker = {{ scale = 0.5 }} }}

[[object]]
shape = {{ sphere = {{ center = [-0.7, 0.5, 1.2], radius = 0.5 }} }}
material = "glass"

[[object]]
shape = {{ sphere = {{ center = [0.8, 0.5, 1.4], radius = 0.5 }} }}
material = "metal"

[medium]
bounds = {{ sphere = {{ center = [0.0, 0.7, -0.6], radius = 0.6 }} }}
field = {field}

[[light]]
point = {{ position = [2.0, 4.0, -2.0], intensity = [30.0, 30.0, 30.0] }}

[render]
width = 96
height = 54
step = {{ fixed = 0.02 }}
jitter = false
"#
    )
}

#[test]
fn luneburg_paper_scene_matches_cpu() {
    let Some(ctx) = harness::context("luneburg_paper_scene_matches_cpu") else {
        return;
    };
    let scene = parse_scene(
        &paper_scene(r#"{ kind = "luneburg" }"#),
        Path::new("inline.toml"),
    )
    .expect("scene");
    let baked = harness::baked(&scene, Path::new("."), 48);
    let (cpu, gpu) = harness::render_both(&ctx, &scene, Path::new("."), baked);
    harness::assert_images_agree("luneburg-paper", &cpu, &gpu, 2e-3, 5e-2);
}
