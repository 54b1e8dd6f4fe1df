//! Scene text the tests share, as TOML tables to which a test appends its own (a medium,
//! objects, `[render]`). Dependency-free, so that grin-gpu's tests (which this crate
//! depends on) can include it by path.

/// The paper's set: the camera above a checker floor, looking down at it, and a point
/// light (append spheres, a medium and `[render]`).
pub const PAPER_SET: &str = r#"
[camera]
position = [0.0, 1.0, -4.0]
look_at = [0.0, 0.6, 0.0]
fov_y_deg = 40.0

[[object]]
shape = { plane = { point = [0.0, 0.0, 0.0], normal = [0.0, 1.0, 0.0] } }
material = { checker = { scale = 0.5 } }

[[light]]
point = { position = [2.0, 4.0, -2.0], intensity = [30.0, 30.0, 30.0] }
"#;

/// A checker wall at z = 1.5 seen from z = -4 (append a medium about the origin and
/// `[render]`): the viewer's tests.
pub const WALL_SET: &str = r#"
[camera]
position = [0.0, 0.0, -4.0]
look_at = [0.0, 0.0, 0.0]
fov_y_deg = 32.0

[[object]]
shape = { plane = { point = [0.0, 0.0, 1.5], normal = [0.0, 0.0, -1.0] } }
material = { checker = { color_a = [0.9, 0.9, 0.85], color_b = [0.1, 0.1, 0.15], scale = 0.2 } }
"#;

/// [`WALL_SET`] with an fBm noise ball of radius 1 about the origin, `width` x `height`,
/// `spp` samples a pixel, rk4 at fixed steps of 0.02, and `extra` lines in `[render]`.
pub fn noise_ball(width: u32, height: u32, spp: u32, extra: &str) -> String {
    format!(
        r#"{WALL_SET}
[medium]
bounds = {{ sphere = {{ center = [0.0, 0.0, 0.0], radius = 1.0 }} }}
field = {{ kind = "noise", noise = "fbm", octaves = 2, frequency = 1.5, amplitude = 0.03, seed = 3 }}

[render]
width = {width}
height = {height}
spp = {spp}
integrator = "rk4"
step = {{ fixed = 0.02 }}
{extra}
"#
    )
}
