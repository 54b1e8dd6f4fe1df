//! Images in scenes through `grin render`: a background plate comes back pixel for pixel
//! without a medium, a texture reads upright and unmirrored with its PNG decoded from
//! sRGB, the `dots` material is the BOS background (a render through the medium equals
//! `[optics] mode = "bos"`'s distorted image), and bad image files are clear errors
//! naming them. Both backends agreeing on textures, dots and plates is tested in
//! crates/grin-gpu/tests/gpu_vs_cpu.rs.

use common::{
    assert_err, assert_ok as ok, bos_plume_scene, exr_channels, gpu_or_skip, render, stderr,
};
use grin_testkit as common;

use grin_render::image::Frame;
use grin_render::surface::srgb_to_linear;

/// A plate at infinity, rendered at its own size without a medium, is the plate: each
/// pixel-centre ray projects back to its texel's centre (CPU exactly, to f32 rounding;
/// the GPU within 2e-5, its f32 projection).
#[test]
fn background_plate_without_a_medium_is_the_plate() {
    let dir = tempfile::tempdir().expect("tmp");
    let d = dir.path();
    let (w, h) = (40u32, 30u32);
    let plate = image::RgbImage::from_fn(w, h, |x, y| {
        image::Rgb([(x * 6) as u8, (y * 8) as u8, ((x * 7 + y * 13) % 256) as u8])
    });
    plate.save(d.join("plate.png")).expect("png");
    let scene = d.join("plate.toml");
    std::fs::write(
        &scene,
        format!(
            "[camera]\nposition = [1.0, 2.0, 3.0]\nlook_at = [2.0, 2.5, 9.0]\nfov_y_deg = 50.0\n\
             [sky]\nplate = {{ path = \"plate.png\", intensity = 2.0 }}\n\
             [render]\nwidth = {w}\nheight = {h}\n"
        ),
    )
    .expect("scene");
    let mut backends = vec![("cpu", 1e-6)];
    if gpu_or_skip() {
        backends.push(("gpu", 2e-5));
    }
    for (backend, tol) in backends {
        let out = d.join(format!("{backend}.exr"));
        ok(&render(&scene, &out, backend));
        let frame = Frame::read_exr(&out).expect("exr");
        let mut worst = 0.0f64;
        for y in 0..h {
            for x in 0..w {
                let want = plate
                    .get_pixel(x, y)
                    .0
                    .map(|c| 2.0 * srgb_to_linear(f32::from(c) / 255.0));
                let got = frame.pixels[(y * w + x) as usize].rgb;
                for c in 0..3 {
                    worst = worst.max(f64::from((got[c] - want[c]).abs()));
                }
            }
        }
        eprintln!("{backend}: plate round trip, largest difference {worst:e}");
        assert!(worst <= tol, "{backend}: {worst:e}");
    }
}

/// A 2x2 PNG on a wall facing the camera (emissive: shown as it is) reads upright and
/// unmirrored, decoded from sRGB: its top-left texel at the top left of the wall. The
/// camera looks along +z, so the wall's u axis is -x (the camera's right).
#[test]
fn texture_reads_upright_and_is_decoded_from_srgb() {
    let dir = tempfile::tempdir().expect("tmp");
    let d = dir.path();
    let texels = [[255u8, 0, 0], [0, 128, 0], [0, 0, 64], [200, 200, 200]];
    let img = image::RgbImage::from_fn(2, 2, |x, y| image::Rgb(texels[(y * 2 + x) as usize]));
    img.save(d.join("quad.png")).expect("png");
    // The wall (2 x 2 at z = 0) exactly fills a 28.07-degree view from z = -4.
    let fov = 2.0 * 0.25f64.atan().to_degrees();
    let scene = d.join("wall.toml");
    std::fs::write(
        &scene,
        format!(
            "[camera]\nposition = [0.0, 0.0, -4.0]\nlook_at = [0.0, 0.0, 0.0]\nfov_y_deg = {fov}\n\
             [[object]]\nshape = {{ plane = {{ point = [0.0, 0.0, 0.0], normal = [0.0, 0.0, -1.0] }} }}\n\
             material = {{ texture = {{ path = \"quad.png\", size = [2.0, 2.0], emissive = true }} }}\n\
             [render]\nwidth = 64\nheight = 64\n"
        ),
    )
    .expect("scene");
    let out = d.join("wall.exr");
    ok(&render(&scene, &out, "cpu"));
    let frame = Frame::read_exr(&out).expect("exr");
    // Pixel (16, 16)'s centre is 1.6 % of a texel from the top-left texel's centre on
    // each axis: 97 % of its value.
    for (px, py, k) in [
        (16u32, 16u32, 0usize),
        (47, 16, 1),
        (16, 47, 2),
        (47, 47, 3),
    ] {
        let got = frame.pixels[(py * 64 + px) as usize].rgb;
        let want = texels[k].map(|c| srgb_to_linear(f32::from(c) / 255.0));
        for c in 0..3 {
            assert!(
                (got[c] - want[c]).abs() < 0.04,
                "pixel ({px}, {py}): {got:?}, texel {k} is {want:?}"
            );
        }
    }
}

/// The `dots` material on a plane is the BOS background: rendered through a plume, the
/// beauty image equals `[optics] mode = "bos"`'s distorted image on the same plane, and
/// without the plume its reference image (same dots, same axes, same hash).
#[test]
fn dots_material_is_the_bos_background() {
    let dir = tempfile::tempdir().expect("tmp");
    let d = dir.path();
    let head = bos_plume_scene("fov_y_deg = 12.0", 64, 48, 0.01, "");
    let bos = d.join("bos.toml");
    std::fs::write(
        &bos,
        format!(
            "{head}[optics]\nmode = \"bos\"\nplane = {{ point = [0.0, 0.0, 6.0], normal = [0.0, 0.0, -1.0] }}\n\
             dots = {{ diameter = 0.05, density = 0.4, seed = 3 }}\n"
        ),
    )
    .expect("scene");
    let beauty = d.join("beauty.toml");
    std::fs::write(
        &beauty,
        format!(
            "[[object]]\nshape = {{ plane = {{ point = [0.0, 0.0, 6.0], normal = [0.0, 0.0, -1.0] }} }}\n\
             material = {{ dots = {{ diameter = 0.05, density = 0.4, seed = 3, emissive = true }} }}\n{head}"
        ),
    )
    .expect("scene");
    ok(&render(&bos, &d.join("bos.exr"), "cpu"));
    ok(&render(&beauty, &d.join("beauty.exr"), "cpu"));
    let (_, b) = exr_channels(&d.join("bos.exr"));
    let (_, r) = exr_channels(&d.join("beauty.exr"));
    let (distorted, reference, red) = (&b["distorted"], &b["reference"], &r["R"]);
    let worst = distorted
        .iter()
        .zip(red)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f64, f64::max);
    let changed = distorted
        .iter()
        .zip(reference)
        .filter(|(a, b)| (*a - *b).abs() > 0.05)
        .count();
    eprintln!("dots vs BOS: largest difference {worst:e}; {changed} pixels moved by the plume");
    assert!(worst < 1e-4, "{worst}");
    // The test would not notice a plume that does nothing.
    assert!(changed > 100, "{changed}");
}

/// A missing or corrupt texture or plate, or a texture on a sphere: a clear error
/// naming the file (or the key), a non-zero exit, and no output written.
#[test]
fn bad_images_are_errors_naming_the_file() {
    let dir = tempfile::tempdir().expect("tmp");
    let d = dir.path();
    std::fs::write(d.join("broken.png"), b"\x89PNG\r\n\x1a\nnot really").expect("file");
    // An image bomb: a 4x4 EXR whose header is patched to declare 60000x60000 (it aborted
    // with "memory allocation of 43200000000 bytes failed" before its size was checked).
    let pixels = exr::prelude::SpecificChannels::rgb(|_: exr::prelude::Vec2<usize>| {
        (0.5f32, 0.5f32, 0.5f32)
    });
    use exr::prelude::WritableImage as _;
    exr::prelude::Image::from_channels((4, 4), pixels)
        .write()
        .to_file(d.join("bomb.exr"))
        .expect("exr");
    let mut bytes = std::fs::read(d.join("bomb.exr")).expect("read");
    for name in [&b"dataWindow\0box2i\0"[..], &b"displayWindow\0box2i\0"[..]] {
        let at = bytes
            .windows(name.len())
            .position(|w| w == name)
            .expect("window attribute")
            + name.len()
            + 4;
        bytes[at + 8..at + 16].copy_from_slice(&[59_999i32.to_le_bytes(); 2].concat());
    }
    std::fs::write(d.join("bomb.exr"), bytes).expect("write");
    let cam = "[camera]\nposition = [0.0, 1.0, -4.0]\nlook_at = [0.0, 0.0, 0.0]\n[render]\nwidth = 8\nheight = 8\n";
    let wall = "shape = { plane = { point = [0.0, 0.0, 2.0], normal = [0.0, 0.0, -1.0] } }";
    let cases = [
        (
            format!(
                "[[object]]\n{wall}\nmaterial = {{ texture = {{ path = \"missing.png\", size = [1.0, 1.0] }} }}\n"
            ),
            "missing.png",
        ),
        (
            format!(
                "[[object]]\n{wall}\nmaterial = {{ texture = {{ path = \"broken.png\", size = [1.0, 1.0] }} }}\n"
            ),
            "broken.png",
        ),
        (
            format!(
                "[[object]]\n{wall}\nmaterial = {{ texture = {{ path = \"notes.txt\", size = [1.0, 1.0] }} }}\n"
            ),
            "must be a .png, .exr or .hdr file",
        ),
        (
            "[sky]\nplate = { path = \"nowhere.exr\" }\n".to_string(),
            "background plate",
        ),
        (
            "[sky]\nplate = { path = \"bomb.exr\" }\n".to_string(),
            "bomb.exr",
        ),
        (
            format!(
                "[[object]]\n{wall}\nmaterial = {{ texture = {{ path = \"bomb.exr\", size = [1.0, 1.0] }} }}\n"
            ),
            "60000x60000 exceeds 16384 texels a side",
        ),
        (
            "[[object]]\nshape = { sphere = { center = [0.0, 0.0, 0.0], radius = 1.0 } }\n\
             material = { texture = { path = \"broken.png\" } }\n"
                .to_string(),
            "maps onto planes and boxes",
        ),
        (
            format!("[[object]]\n{wall}\nmaterial = {{ texture = {{ path = \"broken.png\" }} }}\n"),
            "needs its size",
        ),
    ];
    for (i, (body, needle)) in cases.iter().enumerate() {
        let scene = d.join(format!("bad{i}.toml"));
        std::fs::write(&scene, format!("{body}{cam}")).expect("scene");
        let out = d.join(format!("bad{i}.exr"));
        let o = render(&scene, &out, "cpu");
        assert_err(&o, needle);
        let err = stderr(&o);
        assert!(!err.contains("panicked"), "case {i}: {err}");
        assert!(!out.exists(), "case {i} wrote {}", out.display());
    }
}
