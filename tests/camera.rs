//! The measurement camera through `grin render`: a lens in mm (focal length with the
//! sensor height or the pixel pitch) is the field of view it implies; a thin-lens
//! aperture blurs an edge out of focus by the circle of confusion (and not in focus), on
//! both backends; `[sensor]` noise has the variance of its shot and read noise and its
//! bit depth; contradictory settings are errors naming the key.

use common::{assert_err, assert_ok as ok, gpu_or_skip, render};
use grin_testkit as common;
use std::path::Path;

use grin_render::image::Frame;

/// A checker wall at z = `wall_z` (squares of 10 m: one vertical edge at x = 0 in view),
/// lit evenly from behind the camera, seen from z = -4 with the camera table `lens`.
fn edge_scene(
    dir: &Path,
    name: &str,
    lens: &str,
    wall_z: f64,
    size: (u32, u32),
    spp: u32,
) -> std::path::PathBuf {
    let text = format!(
        "[camera]\nposition = [0.0, 5.0, -4.0]\nlook_at = [0.0, 5.0, 0.0]\n{lens}\n\
         [[object]]\nshape = {{ plane = {{ point = [0.0, 0.0, {wall_z}], normal = [0.0, 0.0, -1.0] }} }}\n\
         material = {{ checker = {{ color_a = [1.0, 1.0, 1.0], color_b = [0.0, 0.0, 0.0], scale = 10.0 }} }}\n\
         [[light]]\ndirectional = {{ direction = [0.0, 0.0, 1.0], intensity = [3.0, 3.0, 3.0] }}\n\
         [sky]\ngradient = {{ horizon = [0.0, 0.0, 0.0], zenith = [0.0, 0.0, 0.0], ground = [0.0, 0.0, 0.0] }}\n\
         [render]\nwidth = {}\nheight = {}\nspp = {spp}\n",
        size.0, size.1
    );
    let p = dir.join(name);
    std::fs::write(&p, text).expect("scene");
    p
}

/// focal_length_mm = 50 with a 24 mm sensor, or a 500 um pitch x 48 rows, is the
/// 2 atan(12 / 50) = 26.99 degree view: the same image.
#[test]
fn lens_in_mm_is_its_field_of_view() {
    let dir = tempfile::tempdir().expect("tmp");
    let d = dir.path();
    let fov = 2.0 * (12.0f64 / 50.0).atan().to_degrees();
    let lenses = [
        format!("fov_y_deg = {fov}"),
        "focal_length_mm = 50.0\nsensor_height_mm = 24.0".to_owned(),
        "focal_length_mm = 50.0\npixel_pitch_um = 500.0".to_owned(),
    ];
    let frames: Vec<Frame> = lenses
        .iter()
        .enumerate()
        .map(|(i, lens)| {
            let scene = edge_scene(d, &format!("l{i}.toml"), lens, 0.0, (64, 48), 1);
            let out = d.join(format!("l{i}.exr"));
            ok(&render(&scene, &out, "cpu"));
            Frame::read_exr(&out).expect("exr")
        })
        .collect();
    for f in &frames[1..] {
        let worst = f
            .pixels
            .iter()
            .zip(&frames[0].pixels)
            .map(|(a, b)| {
                (0..3)
                    .map(|c| (a.rgb[c] - b.rgb[c]).abs())
                    .fold(0.0f32, f32::max)
            })
            .fold(0.0f32, f32::max);
        assert!(worst < 1e-6, "{worst}");
    }
}

/// Second moment (px^2) of the line spread function: the edge's row-averaged profile,
/// differenced.
fn lsf_variance(frame: &Frame) -> f64 {
    let w = frame.width as usize;
    let esf: Vec<f64> = (0..w)
        .map(|x| {
            (0..frame.height as usize)
                .map(|y| f64::from(frame.pixels[y * w + x].rgb[0]))
                .sum::<f64>()
                / f64::from(frame.height)
        })
        .collect();
    let lsf: Vec<f64> = esf.windows(2).map(|p| (p[1] - p[0]).abs()).collect();
    let total: f64 = lsf.iter().sum();
    let mean = lsf
        .iter()
        .enumerate()
        .map(|(k, v)| k as f64 * v)
        .sum::<f64>()
        / total;
    lsf.iter()
        .enumerate()
        .map(|(k, v)| (k as f64 - mean).powi(2) * v)
        .sum::<f64>()
        / total
}

/// Thin lens f = 50 mm at f/1 (a 50 mm aperture) focused at 1.5 m: an edge 4 m away is
/// blurred by a disc of b = A (D - s) / s = 83.3 mm on the wall, 4.17 px here; its line
/// spread function (a projected disc, variance (b/2)^2 / 4) convolved with the pixel and
/// the differencing (1/12 px^2 each) has variance 1.25 px^2. Measured within 10 %, on
/// both backends; focused on the wall, the edge is as sharp as the pinhole's.
#[test]
fn defocus_blurs_an_edge_by_the_circle_of_confusion() {
    let dir = tempfile::tempdir().expect("tmp");
    let d = dir.path();
    let (w, h) = (48u32, 24u32);
    // A 6 mm sensor behind 50 mm: tan(half view) = 3 / 50, so at 4 m the 24 rows span
    // 2 * 4 * 0.06 = 0.48 m, 0.02 m a pixel.
    let lens =
        "focal_length_mm = 50.0\nsensor_height_mm = 6.0\nf_number = 1.0\nfocus_distance = 1.5";
    let px = 2.0 * 4.0 * (3.0 / 50.0) / f64::from(h);
    let b = 0.05 * (4.0 - 1.5) / 1.5 / px;
    let expected = (b / 2.0).powi(2) / 4.0 + 2.0 / 12.0;
    let mut backends = vec!["cpu"];
    if gpu_or_skip() {
        backends.push("gpu");
    }
    for backend in backends {
        let blurred = edge_scene(d, "blur.toml", lens, 0.0, (w, h), 512);
        let out = d.join(format!("blur-{backend}.exr"));
        ok(&render(&blurred, &out, backend));
        let var = lsf_variance(&Frame::read_exr(&out).expect("exr"));
        eprintln!(
            "{backend}: defocused edge, LSF variance {var:.3} px^2 (thin lens: {expected:.3}; blur {b:.2} px)"
        );
        assert!(
            (var / expected - 1.0).abs() < 0.1,
            "{backend}: {var} vs {expected}"
        );
        // In focus: the wall at the focus distance (z = -2.5) is sharp again.
        let focused = edge_scene(d, "focus.toml", lens, -2.5, (w, h), 512);
        let out = d.join(format!("focus-{backend}.exr"));
        ok(&render(&focused, &out, backend));
        let var = lsf_variance(&Frame::read_exr(&out).expect("exr"));
        eprintln!("{backend}: focused edge, LSF variance {var:.3} px^2");
        assert!(var < 0.3, "{backend}: {var}");
    }
}

/// `[sensor]` on a flat plate of value 0.25: shot noise of a 400 e- well (sd
/// sqrt(100) / 400 = 0.025) plus 2 e- read noise, 10 bits: the recorded image has that
/// mean and spread, and only 1/1023 steps.
#[test]
fn sensor_noise_and_bit_depth() {
    let dir = tempfile::tempdir().expect("tmp");
    let d = dir.path();
    exr::prelude::write_rgb_file(d.join("flat.exr"), 4, 4, |_, _| (0.25f32, 0.25f32, 0.25f32))
        .expect("exr");
    let scene = d.join("flat.toml");
    std::fs::write(
        &scene,
        "[camera]\nposition = [0.0, 0.0, 0.0]\nlook_at = [0.0, 0.0, 1.0]\n\
         [sky]\nplate = { path = \"flat.exr\" }\n\
         [sensor]\nfull_well = 400.0\nread_noise = 2.0\nbits = 10\nseed = 7\n\
         [render]\nwidth = 96\nheight = 64\n",
    )
    .expect("scene");
    let out = d.join("flat.exr.out.exr");
    ok(&render(&scene, &out, "cpu"));
    let frame = Frame::read_exr(&out).expect("exr");
    let v: Vec<f64> = frame
        .pixels
        .iter()
        .flat_map(|p| p.rgb.map(f64::from))
        .collect();
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let sd = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    let want = (100.0f64 + 4.0).sqrt() / 400.0;
    eprintln!("sensor: mean {mean:.4}, sd {sd:.5} (expected 0.25, {want:.5})");
    assert!((mean - 0.25).abs() < 1.5e-3, "{mean}");
    assert!((sd / want - 1.0).abs() < 0.06, "{sd} vs {want}");
    assert!(
        v.iter()
            .all(|x| (x * 1023.0 - (x * 1023.0).round()).abs() < 1e-4)
    );
}

/// Contradictory or incomplete lens settings name their key.
#[test]
fn lens_errors_name_the_key() {
    let dir = tempfile::tempdir().expect("tmp");
    let d = dir.path();
    let cases = [
        (
            "fov_y_deg = 30.0\nfocal_length_mm = 50.0\nsensor_height_mm = 24.0",
            "camera.focal_length_mm",
        ),
        ("focal_length_mm = 50.0", "camera.focal_length_mm"),
        ("sensor_height_mm = 24.0", "camera.sensor_height_mm"),
        (
            "focal_length_mm = 50.0\nsensor_height_mm = 24.0\npixel_pitch_um = 5.0",
            "camera.pixel_pitch_um",
        ),
        ("f_number = 2.0", "camera.f_number"),
        (
            "focal_length_mm = 50.0\nsensor_height_mm = 24.0\nf_number = 0.0",
            "camera.f_number",
        ),
        (
            "focal_length_mm = 50.0\nsensor_height_mm = 24.0\nfocus_distance = 2.0",
            "camera.focus_distance",
        ),
    ];
    for (i, (lens, key)) in cases.iter().enumerate() {
        let scene = edge_scene(d, &format!("bad{i}.toml"), lens, 0.0, (8, 8), 1);
        let out = d.join(format!("bad{i}.exr"));
        let o = render(&scene, &out, "cpu");
        assert_err(&o, key);
        assert!(!out.exists());
    }
    // Sensor: read noise without a full well.
    let scene = d.join("sensor.toml");
    std::fs::write(
        &scene,
        "[camera]\nposition = [0.0, 0.0, 0.0]\nlook_at = [0.0, 0.0, 1.0]\n[sensor]\nread_noise = 3.0\n",
    )
    .expect("scene");
    let o = render(&scene, &d.join("s.exr"), "cpu");
    assert_err(&o, "sensor.read_noise");
}
