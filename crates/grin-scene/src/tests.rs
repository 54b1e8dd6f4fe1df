//! Scene parsing and validation errors: one test per kind of error, asserting on the
//! message text (file:line:column: key: reason).
//!
//! One concept, one file: a test per kind of scene error, each a few lines.

use std::path::Path;

use crate::{FieldSpec, Material, Scene, SceneError, Shape, UpAxis, parse_scene};

/// A valid scene; tests replace one line to break it.
const BASE: &str = r#"[camera]
position = [0.0, 1.0, -4.0]
look_at = [0.0, 0.5, 0.0]
fov_y_deg = 40.0

[[object]]
shape = { plane = { point = [0.0, 0.0, 0.0], normal = [0.0, 2.0, 0.0] } }
material = { checker = { scale = 0.5 } }

[[object]]
shape = { sphere = { center = [0.8, 0.5, 1.0], radius = 0.5 } }
material = "glass"

[medium]
bounds = { sphere = { center = [0.0, 0.5, 0.0], radius = 0.6 } }
ambient_index = 1.0
field = { kind = "luneburg" }

[[light]]
point = { position = [2.0, 4.0, -2.0], intensity = [40.0, 40.0, 40.0] }

[render]
width = 64
height = 36
step = { heuristic = { min = 0.002, max = 0.05 } }
"#;

/// BASE with the first occurrence of `from` replaced by `to`; the error message.
fn error_of(from: &str, to: &str) -> String {
    assert!(BASE.contains(from), "test bug: `{from}` not in BASE");
    let text = BASE.replacen(from, to, 1);
    match parse_scene(&text, Path::new("scene.toml")) {
        Ok(_) => panic!("`{to}` was accepted"),
        Err(e @ SceneError::Invalid { .. }) => {
            assert_points_at_key(&text, &e.to_string());
            e.to_string()
        }
        Err(e) => e.to_string(),
    }
}

/// The line:column of a validation error is where its key (last path segment) is written.
fn assert_points_at_key(text: &str, message: &str) {
    let mut parts = message.splitn(4, ':');
    let (_, line, col, rest) = (
        parts.next(),
        parts.next(),
        parts.next(),
        parts.next().unwrap_or(""),
    );
    let line: usize = line
        .and_then(|l| l.parse().ok())
        .unwrap_or_else(|| panic!("no line in {message}"));
    let col: usize = col
        .and_then(|c| c.parse().ok())
        .unwrap_or_else(|| panic!("no column in {message}"));
    let key = rest.trim_start().split(':').next().unwrap_or("");
    let last = key
        .rsplit('.')
        .next()
        .unwrap_or("")
        .split('[')
        .next()
        .unwrap_or("");
    let at: String = text
        .lines()
        .nth(line - 1)
        .unwrap_or("")
        .chars()
        .skip(col - 1)
        .collect();
    assert!(
        at.starts_with(last),
        "{message}: column points at `{at}`, not at `{last}`"
    );
}

#[test]
fn base_scene_is_valid_and_plane_normal_is_normalised() {
    let s = parse_scene(BASE, Path::new("scene.toml")).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(s.objects.len(), 2);
    assert_eq!(
        s.objects[0].shape,
        Shape::Plane {
            point: [0.0; 3],
            normal: [0.0, 1.0, 0.0]
        }
    );
    assert_eq!(
        s.objects[1].material,
        Material::Glass {
            ior: 1.5,
            color: [1.0; 3]
        }
    );
    assert_eq!(
        s.medium.as_ref().map(|m| &m.field),
        Some(&FieldSpec::Luneburg { radius: None })
    );
}

#[test]
fn malformed_toml_has_line_and_column() {
    let m = error_of("[render]", "[render");
    assert!(m.starts_with("scene.toml:22:8: "), "{m}");
    let m = error_of("width = 64", "width = = 64");
    assert!(m.starts_with("scene.toml:23:"), "{m}");
}

#[test]
fn unknown_keys_are_named_with_their_line() {
    let m = error_of("fov_y_deg = 40.0", "fov_y_deg = 40.0\nzoom = 2.0");
    assert!(
        m.starts_with("scene.toml:5:1: camera.zoom: unknown field `zoom`"),
        "{m}"
    );
    let m = error_of("width = 64", "widht = 64");
    assert!(
        m.starts_with("scene.toml:23:1: render.widht: unknown field `widht`"),
        "{m}"
    );
    let m = error_of("[medium]", "[mediun]");
    assert!(
        m.starts_with("scene.toml:14:2: mediun: unknown field `mediun`"),
        "{m}"
    );
}

#[test]
fn unknown_field_kind_is_named() {
    let m = error_of("kind = \"luneburg\"", "kind = \"lunebrug\"");
    assert!(m.starts_with("scene.toml:17:"), "{m}");
    assert!(m.contains("medium.field"), "{m}");
    assert!(m.contains("unknown variant `lunebrug`"), "{m}");
}

#[test]
fn unknown_material_and_material_keys() {
    let m = error_of("material = \"glass\"", "material = \"glas\"");
    assert!(m.starts_with("scene.toml:12:"), "{m}");
    assert!(m.contains("object[1].material: unknown material `glas`, expected one of diffuse, checker, mirror, metal, glass"), "{m}");
    let m = error_of(
        "{ checker = { scale = 0.5 } }",
        "{ checker = { scael = 0.5 } }",
    );
    assert!(m.starts_with("scene.toml:8:"), "{m}");
    assert!(m.contains("unknown field `scael`"), "{m}");
}

#[test]
fn camera_errors() {
    let m = error_of("look_at = [0.0, 0.5, 0.0]", "look_at = [0.0, 1.0, -4.0]");
    assert_eq!(
        m,
        "scene.toml:3:1: camera.look_at: must differ from camera.position, both are [0.0, 1.0, -4.0]"
    );
    let m = error_of("fov_y_deg = 40.0", "fov_y_deg = 180.0");
    assert_eq!(
        m,
        "scene.toml:4:1: camera.fov_y_deg: must be in (0, 180) degrees, got 180"
    );
    let m = error_of("fov_y_deg = 40.0", "fov_y_deg = 0.0");
    assert_eq!(
        m,
        "scene.toml:4:1: camera.fov_y_deg: must be in (0, 180) degrees, got 0"
    );
    let m = error_of("fov_y_deg = 40.0", "up = [0.0, 0.0, 0.0]");
    assert_eq!(m, "scene.toml:4:1: camera.up: must be a non-zero vector");
    let m = error_of("position = [0.0, 1.0, -4.0]", "position = [0.0, nan, -4.0]");
    assert_eq!(
        m,
        "scene.toml:2:1: camera.position: all components must be finite, got [0.0, NaN, -4.0]"
    );
}

#[test]
fn shape_errors() {
    let m = error_of("radius = 0.5 }", "radius = -1.0 }");
    assert_eq!(
        m,
        "scene.toml:11:48: object[1].shape.sphere.radius: must be > 0, got -1"
    );
    let m = error_of("normal = [0.0, 2.0, 0.0]", "normal = [0.0, 0.0, 0.0]");
    assert_eq!(
        m,
        "scene.toml:7:46: object[0].shape.plane.normal: must be a non-zero vector"
    );
    let m = error_of(
        "shape = { sphere = { center = [0.8, 0.5, 1.0], radius = 0.5 } }",
        "shape = { box = { min = [0.0, 0.0, 0.0], max = [1.0, 0.0, 1.0] } }",
    );
    assert_eq!(
        m,
        "scene.toml:11:42: object[1].shape.box.max: must be > min in every component, got min [0.0, 0.0, 0.0], max [1.0, 0.0, 1.0]"
    );
}

#[test]
fn material_errors() {
    let m = error_of(
        "material = \"glass\"",
        "material = { glass = { ior = 0.0 } }",
    );
    assert_eq!(
        m,
        "scene.toml:12:24: object[1].material.glass.ior: must be > 0, got 0"
    );
    let m = error_of(
        "material = \"glass\"",
        "material = { diffuse = { color = [0.5, -0.1, 0.5] } }",
    );
    assert_eq!(
        m,
        "scene.toml:12:26: object[1].material.diffuse.color: colour components must be finite and >= 0, got [0.5, -0.1, 0.5]"
    );
    let m = error_of(
        "{ checker = { scale = 0.5 } }",
        "{ checker = { scale = 0.0 } }",
    );
    assert_eq!(
        m,
        "scene.toml:8:26: object[0].material.checker.scale: must be > 0, got 0"
    );
}

#[test]
fn medium_errors() {
    let m = error_of("radius = 0.6 }", "radius = -1 }");
    assert_eq!(
        m,
        "scene.toml:15:49: medium.bounds.sphere.radius: must be > 0, got -1"
    );
    let m = error_of(
        "bounds = { sphere = { center = [0.0, 0.5, 0.0], radius = 0.6 } }",
        "bounds = { box = { min = [0.0, 0.0, 0.0], max = [-1.0, 1.0, 1.0] } }",
    );
    assert!(
        m.starts_with("scene.toml:15:43: medium.bounds.box.max: must be > min in every component"),
        "{m}"
    );
    let m = error_of("ambient_index = 1.0", "ambient_index = 0.0");
    assert_eq!(
        m,
        "scene.toml:16:1: medium.ambient_index: must be > 0, got 0"
    );
    let m = error_of("ambient_index = 1.0", "ambient_index = inf");
    assert_eq!(
        m,
        "scene.toml:16:1: medium.ambient_index: must be > 0, got inf"
    );
    let m = error_of("ambient_index = 1.0", "ambient_index = 1e300");
    assert_eq!(
        m,
        "scene.toml:16:1: medium.ambient_index: must be at most 1e3, got 1e300"
    );
    // Absurdly small media: a sphere of 1e-300 and a box 2e-12 thin.
    let m = error_of("radius = 0.6 }", "radius = 1e-300 }");
    assert_eq!(
        m,
        "scene.toml:15:49: medium.bounds.sphere.radius: must be at least 1e-9 world units, got 1e-300"
    );
    let m = error_of(
        "bounds = { sphere = { center = [0.0, 0.5, 0.0], radius = 0.6 } }",
        "bounds = { box = { min = [0.0, 0.0, -1e-12], max = [1.0, 1.0, 1e-12] } }",
    );
    assert!(
        m.starts_with(
            "scene.toml:15:46: medium.bounds.box.max: must be at least 1e-9 world units beyond min"
        ),
        "{m}"
    );
    // "auto" is the index of a VDB grid's background: refused for a formula field.
    let m = error_of("ambient_index = 1.0", "ambient_index = \"auto\"");
    assert!(
        m.starts_with("scene.toml:16:1: medium.ambient_index: \"auto\" takes the index a VDB"),
        "{m}"
    );
    let m = error_of("ambient_index = 1.0", "ambient_index = \"warm\"");
    assert!(m.contains("a number or \"auto\""), "{m}");
}

/// `ambient_index`: a number, "auto", or left out (1.0; "auto" for VDB media); the VDB
/// placement keys parse and are checked.
#[test]
fn ambient_index_and_vdb_placement() {
    let vdb = "field = { kind = \"vdb\", path = \"a.vdb\", grid = \"t\", map = { index = {} } }";
    let with = |ambient: &str, field: &str| -> Result<Scene, SceneError> {
        let text = BASE
            .replacen("ambient_index = 1.0", ambient, 1)
            .lines()
            .map(|l| if l.starts_with("field = ") { field } else { l })
            .collect::<Vec<_>>()
            .join("\n");
        parse_scene(&text, Path::new("scene.toml"))
    };
    let medium = |s: Result<Scene, SceneError>| s.expect("valid").medium.expect("medium");
    assert_eq!(medium(with("", vdb)).ambient(), None);
    assert_eq!(
        medium(with("ambient_index = \"auto\"", vdb)).ambient(),
        None
    );
    assert_eq!(
        medium(with("ambient_index = 1.0003", vdb)).ambient(),
        Some(1.0003)
    );
    assert_eq!(medium(with("ambient_index = 2", vdb)).ambient(), Some(2.0));
    let plain = BASE
        .lines()
        .find(|l| l.starts_with("field = "))
        .expect("field line");
    assert_eq!(medium(with("", plain)).ambient(), Some(1.0));

    let placed = "field = { kind = \"vdb\", path = \"a.vdb\", grid = \"t\", map = { index = {} }, up = \"z\", scale = 0.01, rotate_deg = [0.0, 90.0, 0.0], translate = [1.0, 2.0, 3.0] }";
    match medium(with("", placed)).field {
        FieldSpec::Vdb(v) => {
            assert_eq!(v.up, UpAxis::Z);
            assert_eq!(
                (v.scale, v.rotate_deg, v.translate),
                (0.01, [0.0, 90.0, 0.0], [1.0, 2.0, 3.0])
            );
        }
        f => panic!("{f:?}"),
    }
    let bad = placed.replace("scale = 0.01", "scale = 0.0");
    let e = with("", &bad).expect_err("scale 0").to_string();
    assert!(e.contains("medium.field.scale: must be > 0"), "{e}");
    let bad = placed.replace("up = \"z\"", "up = \"x\"");
    let e = with("", &bad).expect_err("up x").to_string();
    assert!(
        e.contains("unknown variant `x`, expected `y` or `z`"),
        "{e}"
    );
}

#[test]
fn field_parameter_errors() {
    let cases = [
        (
            "{ kind = \"luneburg\", radius = -1.0 }",
            "scene.toml:17:30: medium.field.radius: must be > 0, got -1",
        ),
        (
            "{ kind = \"uniform\", n = 0.0 }",
            "scene.toml:17:29: medium.field.n: must be > 0, got 0",
        ),
        (
            "{ kind = \"uniform\", n = 1e300 }",
            "scene.toml:17:29: medium.field.n: must be at most 1e3, got 1e300",
        ),
        (
            "{ kind = \"grin-rod\", n0 = 2e3, a = 0.1 }",
            "scene.toml:17:30: medium.field.n0: must be at most 1e3, got 2e3",
        ),
        (
            "{ kind = \"grin-rod\", n0 = 1.5, a = -0.1 }",
            "scene.toml:17:40: medium.field.a: must be > 0, got -0.1",
        ),
        (
            "{ kind = \"eaton\", core = 1.5 }",
            "scene.toml:17:27: medium.field.core: must be in (0, 1) (a fraction of the radius), got 1.5",
        ),
        (
            "{ kind = \"plume\", plumes = [{ a = 1e-5, center = [0.0, 0.0, 0.0], s = 0.0 }] }",
            "scene.toml:17:75: medium.field.plumes[0].s: must be > 0, got 0",
        ),
        (
            "{ kind = \"plume\", plumes = [] }",
            "scene.toml:17:27: medium.field.plumes: must list at least one plume",
        ),
        (
            "{ kind = \"noise\", amplitude = 0.01, octaves = 17 }",
            "scene.toml:17:45: medium.field.octaves: must be in 1..=16, got 17",
        ),
        (
            "{ kind = \"noise\", amplitude = 0.01, octaves = 0 }",
            "scene.toml:17:45: medium.field.octaves: must be in 1..=16, got 0",
        ),
        (
            "{ kind = \"exponential-atmosphere\", e = -5e-5, scale_height = 0.0 }",
            "scene.toml:17:55: medium.field.scale_height: must be > 0, got 0",
        ),
        (
            "{ kind = \"expr\", n = \" \" }",
            "scene.toml:17:26: medium.field.n: must not be empty",
        ),
        (
            "{ kind = \"baked\", path = \"\" }",
            "scene.toml:17:27: medium.field.path: must not be empty",
        ),
    ];
    for (field, want) in cases {
        let m = error_of("{ kind = \"luneburg\" }", field);
        assert_eq!(m, want);
    }
}

#[test]
fn light_errors() {
    let m = error_of(
        "intensity = [40.0, 40.0, 40.0]",
        "intensity = [40.0, -1.0, 40.0]",
    );
    assert_eq!(
        m,
        "scene.toml:20:40: light[0].point.intensity: colour components must be finite and >= 0, got [40.0, -1.0, 40.0]"
    );
    let m = error_of(
        "point = { position = [2.0, 4.0, -2.0], intensity = [40.0, 40.0, 40.0] }",
        "directional = { direction = [0.0, 0.0, 0.0], intensity = [1.0, 1.0, 1.0] }",
    );
    assert_eq!(
        m,
        "scene.toml:20:17: light[0].directional.direction: must be a non-zero vector"
    );
}

#[test]
fn render_errors() {
    let cases = [
        (
            "width = 64",
            "width = 0",
            "scene.toml:23:1: render.width: must be in 1..=16384, got 0",
        ),
        (
            "height = 36",
            "height = 20000",
            "scene.toml:24:1: render.height: must be in 1..=16384, got 20000",
        ),
        (
            "height = 36",
            "height = 36\nspp = 0",
            "scene.toml:25:1: render.spp: must be >= 1, got 0",
        ),
        (
            "height = 36",
            "height = 36\nmax_steps = 0",
            "scene.toml:25:1: render.max_steps: must be in 1..=1073741824 (2^30), got 0",
        ),
        (
            "height = 36",
            "height = 36\npilot_rays = 1000000000",
            "scene.toml:25:1: render.pilot_rays: must be in 0..=4096 (0: no pilots), got 1000000000",
        ),
        (
            "step = { heuristic = { min = 0.002, max = 0.05 } }",
            "step = { fixed = 0.0 }",
            "scene.toml:25:10: render.step.fixed: must be > 0, got 0",
        ),
        (
            "min = 0.002, max = 0.05",
            "min = 0.1, max = 0.05",
            "scene.toml:25:24: render.step.heuristic.min: must be <= max (0.05), got 0.1",
        ),
        (
            "step = { heuristic = { min = 0.002, max = 0.05 } }",
            "step = { adaptive = { tolerance = -1e-5 } }",
            "scene.toml:25:23: render.step.adaptive.tolerance: must be > 0, got -0.00001",
        ),
        (
            "step = { heuristic = { min = 0.002, max = 0.05 } }",
            "step = { auto = 2.0 }",
            "scene.toml:25:10: render.step.auto: is an exit-direction error in radians and must be < 1, got 2",
        ),
    ];
    for (from, to, want) in cases {
        assert_eq!(error_of(from, to), want);
    }
}

#[test]
fn wrong_types_and_negative_integers_are_parse_errors() {
    let m = error_of("width = 64", "width = -64");
    assert!(m.starts_with("scene.toml:23:9: render.width: "), "{m}");
    let m = error_of("width = 64", "width = \"wide\"");
    assert!(m.starts_with("scene.toml:23:9: render.width: "), "{m}");
}

#[test]
fn io_error_names_the_file() {
    let e = crate::load_scene(Path::new("/nonexistent/scene.toml")).expect_err("missing");
    assert!(
        e.to_string()
            .starts_with("/nonexistent/scene.toml: cannot read scene file: "),
        "{e}"
    );
}
#[test]
fn unknown_keys_inside_field_kinds_point_at_the_key() {
    let m = error_of("kind = \"luneburg\"", "kind = \"luneburg\", radiuss = 1.0");
    assert_eq!(
        m,
        "scene.toml:17:30: medium.field.radiuss: unknown field `radiuss`, expected `radius`"
    );
    let m = error_of(
        "kind = \"luneburg\"",
        "kind = \"noise\", amplitude = 0.1, octavs = 3",
    );
    assert!(
        m.starts_with(
            "scene.toml:17:44: medium.field.octavs: unknown field `octavs`, expected one of"
        ),
        "{m}"
    );
    let m = error_of(
        "kind = \"luneburg\"",
        "kind = \"plume\", plumes = [{ a = 1.0, center = [0.0, 0.0, 0.0] }]",
    );
    assert_eq!(m, "scene.toml:17:9: medium.field: missing field `s`");
    let m = error_of("field = { kind = \"luneburg\" }", "");
    assert_eq!(m, "scene.toml:14:1: medium: missing field `field`");
    let m = error_of(
        "step = { heuristic = { min = 0.002, max = 0.05 } }",
        "integrator = \"rk5\"",
    );
    assert!(
        m.starts_with(
            "scene.toml:25:14: render.integrator: unknown variant `rk5`, expected one of"
        ),
        "{m}"
    );
}

#[test]
fn locate_key_finds_field_parameters() {
    assert_eq!(crate::locate_key(BASE, "medium.field.kind"), Some((17, 11)));
    assert_eq!(crate::locate_key(BASE, "light[0].point"), Some((20, 1)));
    assert_eq!(crate::locate_key(BASE, "nothing.here"), None);
}

/// Numbers no backend can represent: coordinates past 1e7, max_steps past 2^30 (the GPU's
/// u32 loop bound), more objects than every-ray-tests-every-object allows.
#[test]
fn out_of_range_numbers_are_refused() {
    let e = error_of("radius = 0.6", "radius = 1e300");
    assert!(
        e.ends_with("medium.bounds.sphere.radius: must be at most 1e7 world units, got 1e300"),
        "{e}"
    );
    let e = error_of("center = [0.0, 0.5, 0.0]", "center = [0.0, 5e8, 0.0]");
    assert!(
        e.contains("medium.bounds.sphere.center: components must lie within ±1e7"),
        "{e}"
    );
    let e = error_of("position = [0.0, 1.0, -4.0]", "position = [0.0, 1.0, -4e9]");
    assert!(
        e.contains("camera.position: components must lie within ±1e7"),
        "{e}"
    );
    let e = error_of("height = 36", "height = 36\nmax_steps = 2147483647");
    assert!(
        e.ends_with("must be in 1..=1073741824 (2^30), got 2147483647"),
        "{e}"
    );
    let many = "[[object]]\nshape = { sphere = { center = [0.0, 0.0, 9.0], radius = 0.1 } }\nmaterial = \"glass\"\n"
        .repeat(crate::MAX_OBJECTS);
    let text = BASE.replacen("[medium]", &format!("{many}[medium]"), 1);
    let e = parse_scene(&text, Path::new("scene.toml"))
        .expect_err("1026 objects")
        .to_string();
    assert!(
        e.contains("the scene has 1026 objects; at most 1024 are supported"),
        "{e}"
    );
    let text = BASE.replacen(
        "[medium]",
        &format!("{}[medium]", &many[..many.len() / 1024 * 1022]),
        1,
    );
    parse_scene(&text, Path::new("scene.toml")).expect("1024 objects");
}

/// Unknown keys come from the deserializer as a typed error at their key path (in a
/// variant table, an array of tables, a nested step table), not read out of the text of
/// serde's message.
#[test]
fn unknown_keys_are_found_by_path_not_by_message_text() {
    let m = error_of("radius = 0.5 } }", "radius = 0.5, radiuss = 1.0 } }");
    assert_eq!(
        m,
        "scene.toml:11:62: object[1].shape.sphere.radiuss: unknown field `radiuss`, expected `center` or `radius`"
    );
    let m = error_of("max = 0.05 }", "max = 0.05, maxx = 1.0 }");
    assert!(
        m.starts_with("scene.toml:25:49: render.step.heuristic.maxx: unknown field `maxx`"),
        "{m}"
    );
    let de: Result<crate::Scene, _> = crate::de::from_table(
        "[camera]\nzoom = 1\n"
            .parse::<toml::Table>()
            .expect("toml parses"),
    );
    let e = de.expect_err("unknown key");
    assert_eq!(e.key(), "camera.zoom");
    assert!(
        matches!(&e.kind, crate::de::DeErrorKind::UnknownField { field, expected }
            if field == "zoom" && expected.contains(&"fov_y_deg")),
        "{e:?}"
    );
}

/// `[optics]`: bad values are refused at their key, BOS needs a plane, and an optical
/// output needs a medium.
#[test]
fn optics_errors_name_the_key() {
    let with = |optics: &str| BASE.to_owned() + "\n[optics]\n" + optics + "\n";
    let err = |optics: &str| {
        parse_scene(&with(optics), Path::new("scene.toml"))
            .expect_err(optics)
            .to_string()
    };
    assert!(parse_scene(&with("mode = \"schlieren\""), Path::new("s.toml")).is_ok());
    let e = err("mode = \"interferogram\"\nwavelength_nm = -3.0");
    assert!(
        e.contains("optics.wavelength_nm: must be > 0, got -3"),
        "{e}"
    );
    // A wavelength whose phase (2 pi OPD / wavelength) would be infinite.
    let e = err("mode = \"interferogram\"\nwavelength_nm = 1e-300");
    assert!(
        e.contains("optics.wavelength_nm: must be in 10..=1e6 nm") && e.contains("got 1e-300"),
        "{e}"
    );
    // The accuracy is asked in the output's unit: pixels, waves, or (schlieren) radians.
    let ok = parse_scene(
        &with("mode = \"interferogram\"\naccuracy = 0.05"),
        Path::new("s.toml"),
    )
    .expect("waves");
    let o = ok.optics.expect("optics");
    assert_eq!(
        (o.accuracy_unit(), o.output_accuracy()),
        (crate::AccuracyUnit::Waves, Some(0.05))
    );
    let e = err("mode = \"displacement\"\naccuracy = -1.0");
    assert!(e.contains("optics.accuracy: must be > 0"), "{e}");
    let e = err("mode = \"schlieren\"\naccuracy = 2.0");
    assert!(
        e.contains("optics.accuracy: schlieren's is an exit-direction error in radians, below 1"),
        "{e}"
    );
    let ok = parse_scene(
        &with("mode = \"schlieren\"\nknife = { source_size_rad = 5e-4 }"),
        Path::new("s.toml"),
    )
    .expect("schlieren");
    let o = ok.optics.expect("optics");
    // A hundredth of the knife's range by default.
    assert_eq!(
        (o.accuracy_unit(), o.output_accuracy()),
        (crate::AccuracyUnit::Radians, Some(5e-6))
    );
    let e = err("mode = \"bos\"");
    assert!(e.contains("optics.plane: BOS needs the plane"), "{e}");
    let e = err("mode = \"schlieren\"\nknife = { cutoff = 1.0 }");
    assert!(e.contains("optics.knife.cutoff: must be in (0, 1)"), "{e}");
    let e = err("mode = \"bos\"\nplane = { point = [0.0, 0.0, 1.0], normal = [0.0, 0.0, 0.0] }");
    assert!(
        e.contains("optics.plane.normal: must be a non-zero vector"),
        "{e}"
    );
    let e = err("mode = \"shadowgraph\"\nscreen = { rays_per_pixel = 0 }");
    assert!(
        e.contains("optics.screen.rays_per_pixel: must be in 1..=1024"),
        "{e}"
    );
    let e = err("mode = \"x\"");
    assert!(e.contains("unknown variant `x`"), "{e}");
    let no_medium: String = BASE
        .split("[medium]")
        .next()
        .expect("before the medium")
        .to_owned()
        + "[optics]\nmode = \"schlieren\"\n";
    let e = parse_scene(&no_medium, Path::new("s.toml"))
        .expect_err("no medium")
        .to_string();
    assert!(e.contains("an optical output needs a [medium]"), "{e}");
}

/// Numbers that overflow downstream are refused with the limit named: an f-number of
/// 1e-300 (an aperture of 5e298 m, every GPU ray missed).
#[test]
fn lens_numbers_are_checked_for_what_they_imply() {
    let lens = |f_number: &str| {
        BASE.replace(
            "fov_y_deg = 40.0",
            &format!("focal_length_mm = 50.0\nsensor_height_mm = 24.0\nf_number = {f_number}"),
        )
    };
    let e = parse_scene(&lens("1e-300"), Path::new("scene.toml"))
        .expect_err("aperture")
        .to_string();
    assert!(
        e.contains("camera.f_number: must be at least 0.5 (the fastest a lens in air can be"),
        "{e}"
    );
    assert!(e.contains("got 1e-300"), "{e}");
    assert!(parse_scene(&lens("0.5"), Path::new("scene.toml")).is_ok());
    assert!(parse_scene(&lens("2.8"), Path::new("scene.toml")).is_ok());
}
