//! Bounded fuzz loops over every parser of user text and files: the scene parser, the
//! expression parser, the ray-table reader, the .grinf reader, frame ranges and tokens,
//! and image headers (PNG, EXR). Inputs are mutations
//! of valid ones (bit flips, truncations, spliced tokens, duplicated spans); each outcome
//! must be `Ok` or a typed error with a message. A panic fails the test (and the case is
//! printed), a crash (stack overflow, abort) kills it.
//!
//! Each loop runs for [`DEFAULT_SECONDS`] in `cargo test`; `GRIN_FUZZ_SECONDS` sets a
//! longer campaign.

use std::path::Path;
use std::time::{Duration, Instant};

use glam::DVec3;
use grin_field::Bounds;
use grin_field::expr::ExprField;

const DEFAULT_SECONDS: f64 = 1.5;

fn budget() -> Duration {
    let s = std::env::var("GRIN_FUZZ_SECONDS")
        .ok()
        .and_then(|s| s.parse::<f64>().ok())
        .unwrap_or(DEFAULT_SECONDS);
    Duration::from_secs_f64(s)
}

use grin_testkit::rng::Rng;

/// One mutation of `seed` using `tokens` for splices.
fn mutate(rng: &mut Rng, seed: &[u8], tokens: &[&str]) -> Vec<u8> {
    let mut b = seed.to_vec();
    for _ in 0..1 + rng.below(4) {
        if b.is_empty() {
            b.extend_from_slice(tokens[rng.below(tokens.len())].as_bytes());
            continue;
        }
        match rng.below(5) {
            0 => {
                let i = rng.below(b.len());
                b[i] ^= 1 << rng.below(8);
            }
            1 => b.truncate(rng.below(b.len())),
            2 => {
                let i = rng.below(b.len() + 1);
                let t = tokens[rng.below(tokens.len())].as_bytes();
                b.splice(i..i, t.iter().copied());
            }
            3 => {
                let i = rng.below(b.len());
                let j = (i + 1 + rng.below(16)).min(b.len());
                let span = b[i..j].to_vec();
                b.splice(i..i, span);
            }
            _ => {
                let i = rng.below(b.len());
                let j = (i + 1 + rng.below(8)).min(b.len());
                b.drain(i..j);
            }
        }
    }
    b
}

/// Run `check` on mutations of `seeds` until the budget is spent; panics name the case.
fn fuzz(name: &str, seeds: &[&[u8]], tokens: &[&str], check: impl Fn(&[u8]) -> bool) {
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15 ^ name.len() as u64);
    let start = Instant::now();
    let (mut runs, mut accepted) = (0usize, 0usize);
    while start.elapsed() < budget() {
        let seed = seeds[rng.below(seeds.len())];
        let case = mutate(&mut rng, seed, tokens);
        let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| check(&case)));
        match outcome {
            Ok(ok) => accepted += usize::from(ok),
            Err(_) => panic!(
                "{name}: panicked on case {runs}: {:?}",
                String::from_utf8_lossy(&case)
            ),
        }
        runs += 1;
    }
    eprintln!("{name}: {runs} cases, {accepted} accepted, 0 panics");
    assert!(runs > 50, "{name}: only {runs} cases");
}

const SCENE: &str = r#"[camera]
position = [0.0, 1.0, -4.0]
look_at = [0.0, 0.5, 0.0]
fov_y_deg = 40.0
[[object]]
shape = { sphere = { center = [0.8, 0.5, 1.0], radius = 0.5 } }
material = "glass"
[medium]
bounds = { box = { min = [-1.0, 0.0, -1.0], max = [1.0, 1.0, 1.0] } }
ambient_index = 1.0
field = { kind = "noise", octaves = 4, frequency = 3.0, amplitude = 0.02, seed = 7 }
[[light]]
point = { position = [2.0, 4.0, -2.0], intensity = [40.0, 40.0, 40.0] }
[render]
width = 64
height = 36
step = { adaptive = { tolerance = 1e-5 } }
"#;

#[test]
fn scene_parser_never_panics() {
    let plume = SCENE.replace(
        r#"field = { kind = "noise", octaves = 4, frequency = 3.0, amplitude = 0.02, seed = 7 }"#,
        r#"field = { kind = "plume", plumes = [{ a = 6.0e-3, center = [0.0, 0.0, 0.5], s = 0.6 }] }"#,
    );
    let seeds: [&[u8]; 2] = [SCENE.as_bytes(), plume.as_bytes()];
    let tokens = [
        "1e300",
        "-0.0",
        "nan",
        "inf",
        "[",
        "]",
        "{",
        "}",
        "=",
        "\"",
        "\n",
        "[[object]]",
        "kind = \"expr\"",
        "radius = -1",
        "width = 0",
        "max_steps = 4294967295",
        "#",
        "\u{feff}",
        "\\u0000",
        "'''",
        "0x10",
        "[render]",
    ];
    fuzz("scene", &seeds, &tokens, |b| {
        let text = String::from_utf8_lossy(b);
        match grin_scene::parse_scene(&text, Path::new("fuzz.toml")) {
            Ok(_) => true,
            Err(e) => {
                assert!(e.to_string().starts_with("fuzz.toml"), "{e}");
                false
            }
        }
    });
}

#[test]
fn expression_parser_never_panics() {
    let ball = Bounds::Sphere {
        center: DVec3::ZERO,
        radius: 1.0,
    };
    let seeds: [&[u8]; 3] = [
        b"1 + 0.05*exp(-(x*x + y*y + z*z)/0.1)",
        b"sqrt(2 - (x^2 + y^2 + z^2))",
        b"1.000293 - 5e-5*sin(3*x + t)*cos(y)",
    ];
    let tokens = [
        "(", ")", "^", "*", "/", "-", "+", "sin(", "exp(", "log(", "1e308", "1e-308", "x", "t",
        "w", ",", "..", "e", "E+", "tan(", "atan2(", "0/0", "()", "  ",
    ];
    fuzz("expr", &seeds, &tokens, |b| {
        let text = String::from_utf8_lossy(b);
        match ExprField::new(&text, ball, 1.0, 0.0) {
            Ok(_) => true,
            Err(e) => {
                assert!(!e.to_string().is_empty());
                false
            }
        }
    });
}

#[test]
fn ray_table_reader_never_panics() {
    let seeds: [&[u8]; 2] = [
        b"ox,oy,oz,dx,dy,dz\n0,0.2,-3,0,0,1\n# c\n\n1e-3,2,3,nan,0,1\n",
        b"id,dz,dy,dx,oz,oy,ox\n\"a,b\",1,0,0,-3,0,0\n",
    ];
    let tokens = [
        ",", "\"", "\n", "\r\n", "#", "nan", "-inf", "1e999", "\u{feff}", "ox", "",
    ];
    fuzz("ray table", &seeds, &tokens, |b| {
        let text = String::from_utf8_lossy(b);
        match grin_trace::table::parse_rays(&text, Path::new("fuzz.csv")) {
            Ok(_) => true,
            Err(e) => {
                assert!(e.to_string().starts_with("fuzz.csv"), "{e}");
                false
            }
        }
    });
}

#[test]
fn grinf_reader_never_panics() {
    let lens = grin_field::analytic::Luneburg::new(
        Bounds::Sphere {
            center: DVec3::ZERO,
            radius: 1.0,
        },
        1.0,
        None,
    )
    .expect("lens");
    let opts = grin_field::bake::BakeOptions {
        resolution: Some(12),
        error_points: 100,
        ..Default::default()
    };
    let (baked, _) =
        grin_field::bake::bake(&lens, &opts, &|_: &str, _: u64, _: u64| {}).expect("bake");
    let good = grin_field::grinf::to_bytes(&baked);
    let seeds: [&[u8]; 1] = [&good];
    let tokens = ["\0\0\0\0", "\u{7f}\u{7f}\u{7f}\u{7f}", "GRINF\0\0\0"];
    fuzz("grinf", &seeds, &tokens, |b| {
        // Re-seal the checksum half the time so mutations reach the header checks.
        let mut b = b.to_vec();
        if b.len() > 4 && b.len() % 2 == 0 {
            let n = b.len() - 4;
            let crc = crc32fast::hash(&b[..n]);
            b[n..].copy_from_slice(&crc.to_le_bytes());
        }
        match grin_field::grinf::from_bytes(&b, "fuzz.grinf") {
            Ok(_) => true,
            Err(e) => {
                assert!(e.to_string().starts_with("fuzz.grinf"), "{e}");
                false
            }
        }
    });
}

/// Frame ranges (`A..B`, one frame) and frame tokens in paths: a range accepted holds at
/// most `MAX_FRAMES` frames, whatever its ends (the ends of i64 overflowed the check).
#[test]
fn frame_patterns_never_panic_or_overflow() {
    let seeds: [&[u8]; 6] = [
        b"1..24",
        b"-1..9223372036854775807",
        b"-9223372036854775808..=9223372036854775807",
        b"9223372036854775807",
        b"f.####.exr",
        b"a_%04d/b_$F4.vdb",
    ];
    let tokens = [
        "..",
        "..=",
        "-",
        "9223372036854775807",
        "-9223372036854775808",
        "#",
        "%d",
        "%09d",
        "$F",
        "$F9",
        "0",
        "99999",
        " ",
        "\0",
    ];
    fuzz("frames", &seeds, &tokens, |b| {
        let text = String::from_utf8_lossy(b);
        let _ = grin_scene::frames::substitute_frame(&text, i64::MIN);
        let _ = grin_scene::frames::substitute_frame(&text, i64::MAX);
        match grin_scene::frames::parse_frame_range(&text) {
            Ok((a, c)) => {
                let n = grin_scene::frames::frame_count(a, c);
                assert!(
                    (1..=grin_scene::frames::MAX_FRAMES as u64).contains(&n),
                    "{text}: {n} frames"
                );
                true
            }
            Err(e) => {
                assert!(!e.is_empty());
                false
            }
        }
    });
}

/// Image headers (PNG, EXR): mutated small images and bombs (a few hundred bytes that
/// declare gigapixels) load or fail with a message, never decode past the texel budget
/// (an allocation of that size would abort the test) and never panic.
#[test]
fn image_headers_never_panic_or_allocate_past_the_budget() {
    let dir = tempfile::tempdir().expect("tmp");
    let png_path = dir.path().join("seed.png");
    image::RgbImage::from_fn(3, 2, |x, y| image::Rgb([x as u8 * 60, y as u8 * 90, 7]))
        .save(&png_path)
        .expect("png");
    let exr_path = dir.path().join("seed.exr");
    use exr::prelude::WritableImage as _;
    let pixels = exr::prelude::SpecificChannels::rgb(|p: exr::prelude::Vec2<usize>| {
        (p.x() as f32, p.y() as f32, 0.5f32)
    });
    exr::prelude::Image::from_channels((4, 3), pixels)
        .write()
        .to_file(&exr_path)
        .expect("exr");
    let png = std::fs::read(&png_path).expect("png bytes");
    let exr = std::fs::read(&exr_path).expect("exr bytes");
    // The bombs: the seeds with their sizes patched to 60000 (EXR data window) and 20000
    // (PNG IHDR, its CRC left stale).
    let mut exr_bomb = exr.clone();
    let name = b"dataWindow\0box2i\0";
    if let Some(at) = exr_bomb.windows(name.len()).position(|w| w == name) {
        let at = at + name.len() + 4;
        exr_bomb[at + 8..at + 16].copy_from_slice(&[59_999i32.to_le_bytes(); 2].concat());
    }
    let mut png_bomb = png.clone();
    png_bomb[16..24].copy_from_slice(&[20_000u32.to_be_bytes(); 2].concat());
    let seeds: [&[u8]; 4] = [&png, &exr, &exr_bomb, &png_bomb];
    let tokens = [
        "\0\0\0\0",
        "\u{7f}\u{ff}\u{ff}\u{7f}",
        "IHDR",
        "IDAT",
        "box2i",
        "\u{1}",
    ];
    fuzz("image", &seeds, &tokens, |b| {
        let ext = if b.starts_with(b"\x89PNG") {
            "png"
        } else {
            "exr"
        };
        let path = dir.path().join(format!("case.{ext}"));
        std::fs::write(&path, b).expect("write case");
        match grin_render::surface::load_image(&path) {
            Ok(img) => {
                assert!(img.width * img.height <= grin_render::surface::MAX_IMAGE_TEXELS);
                true
            }
            Err(e) => {
                assert!(!e.is_empty());
                false
            }
        }
    });
}
