//! The viewer's image on the device: frames added in GPU memory are the frames read back
//! and averaged on the CPU, the device counts their steps and evaluations exactly, the
//! texture shows the accumulation as the viewer colours it, and no pixel is read back
//! until one is asked for.

mod harness;

use std::path::Path;
use std::sync::atomic::AtomicBool;

use grin_gpu::{GpuRenderer, ViewImage};
use grin_render::image::Frame;
use grin_render::scene::RenderScene;
use grin_scene::parse_scene;

const W: u32 = 40;
const H: u32 = 24;
const SPP: u32 = 2;
const FRAMES: u32 = 3;

/// A noise ball in front of a checker wall, jittered samples (frames differ).
fn scene_text() -> String {
    harness::scenes::noise_ball(W, H, SPP, "")
}

/// Whole steps (or evaluations) of a frame's rays: each pixel's mean times its samples.
fn count(f: &Frame, of: fn(&grin_render::image::PixelOut) -> f32) -> u64 {
    f.pixels
        .iter()
        .map(|p| (of(p) * SPP as f32).round() as u64)
        .sum()
}

#[test]
fn frames_added_on_the_device_are_the_frames_read_back_and_averaged() {
    let Some(ctx) =
        harness::context("frames_added_on_the_device_are_the_frames_read_back_and_averaged")
    else {
        return;
    };
    let scene = parse_scene(&scene_text(), Path::new("inline.toml")).expect("scene");
    let field = harness::build_field(&scene, Path::new("."));
    let rs = RenderScene::new(&scene, Path::new("."), field).expect("render scene");
    let mut gpu = GpuRenderer::new(&ctx, &rs, None).expect("renderer");
    let mut image = ViewImage::new(&ctx, W, H).expect("view image");
    let no = AtomicBool::new(false);
    let mut frames = Vec::new();
    // The statistics are read with the first frame and the last: the frames between
    // read nothing back, and the last read counts every frame since the first.
    let mut unread = (0, 0);
    let mut reads = 0;
    for k in 0..FRAMES {
        assert!(gpu.retarget(&rs, k * SPP, FRAMES * SPP).expect("retarget"));
        // Bands of 5 rows: the accumulation is written band by band.
        gpu.limit_band_rows(5);
        let f = gpu.render(&|_| {}, &no).expect("render read back");
        let before = (gpu.bytes_read_back(), image.stats_bytes_read_back());
        let read = k == 0 || k == FRAMES - 1;
        let stats = gpu
            .render_to_view(&mut image, k == 0, 0, read, &no)
            .expect("render to view");
        let crossed = gpu.bytes_read_back() - before.0;
        let stats_crossed = image.stats_bytes_read_back() - before.1;
        unread = (
            unread.0 + count(&f, |p| p.steps),
            unread.1 + count(&f, |p| p.evals),
        );
        reads += 1;
        frames.push(f);
        let Some(stats) = stats else {
            assert!(!read);
            assert_eq!((crossed, stats_crossed), (0, 0), "frame {k} read back");
            continue;
        };
        assert!(read);
        // The statistics, and the passes' timestamps (16 bytes a pass and band), where
        // the adapter writes them.
        assert_eq!(stats_crossed, grin_gpu::view::STATS_BYTES);
        assert!(crossed <= 32 * u64::from(H.div_ceil(5)), "{crossed} bytes");
        assert_eq!(stats.frames, reads, "frame {k}: frames counted");
        assert_eq!((stats.steps, stats.evals), unread, "frame {k} steps, evals");
        assert_eq!(stats.scale, 1.0);
        (unread, reads) = ((0, 0), 0);
    }
    assert_eq!(image.samples(), FRAMES * SPP);
    assert_eq!(
        image.pixel_bytes_read_back(),
        0,
        "no pixel read back per frame"
    );
    assert_eq!(
        image.stats_bytes_read_back(),
        2 * grin_gpu::view::STATS_BYTES
    );
    assert!(
        frames[0]
            .pixels
            .iter()
            .zip(&frames[1].pixels)
            .any(|(a, b)| a.rgb != b.rgb),
        "jittered frames differ"
    );

    let got = image.read_frame(&ctx).expect("read frame");
    assert_eq!(
        image.pixel_bytes_read_back(),
        u64::from(W * H) * 64,
        "an export reads every pixel once"
    );
    assert_eq!((got.width, got.height), (W, H));
    let mut worst = 0.0f32;
    for (i, p) in got.pixels.iter().enumerate() {
        for c in 0..3 {
            let mean = frames.iter().map(|f| f.pixels[i].rgb[c]).sum::<f32>() / FRAMES as f32;
            worst = worst.max((p.rgb[c] - mean).abs() / mean.abs().max(1e-3));
        }
        let steps = frames.iter().map(|f| f.pixels[i].steps).sum::<f32>() / FRAMES as f32;
        assert!((p.steps - steps).abs() <= 1e-4 * steps.max(1.0), "{i}");
        // The other AOVs are the first frame's.
        assert_eq!(p.deflection_deg, frames[0].pixels[i].deflection_deg);
        assert_eq!(p.status, frames[0].pixels[i].status);
    }
    assert!(
        worst < 1e-5,
        "accumulated radiance off by {worst:e} (relative)"
    );

    // The texture: beauty is the mean radiance clamped to [0, 1] (linear, f16).
    let texels = image.read_display(&ctx).expect("read display");
    assert_eq!(texels.len(), (W * H) as usize);
    for (t, p) in texels.iter().zip(&got.pixels) {
        for c in 0..3 {
            let want = p.rgb[c].clamp(0.0, 1.0);
            assert!(
                (t[c] - want).abs() <= 1e-3 * want + 1e-6,
                "{t:?} vs {:?}",
                p.rgb
            );
        }
        assert_eq!(t[3], 1.0);
    }
    // Deflection: grey over the largest deflection of the image.
    let stats = image.show(&ctx, 1).expect("show deflection");
    let largest = got
        .pixels
        .iter()
        .map(|p| p.deflection_deg.abs())
        .fold(0.0, f32::max);
    assert!(largest > 0.05, "the medium deflects: {largest}");
    assert_eq!(stats.scale, largest);
    let texels = image.read_display(&ctx).expect("read display");
    for (t, p) in texels.iter().zip(&got.pixels) {
        let want = (p.deflection_deg / largest).clamp(0.0, 1.0);
        assert!((t[0] - want).abs() <= 1e-3 * want + 1e-6 && t[0] == t[2]);
    }

    // Shown at twice the size: the image scaled to fill the texture, no new frame.
    image.reserve(&ctx, W, H, [2 * W, 2 * H]).expect("reserve");
    image.show(&ctx, 0).expect("show scaled");
    let big = image.read_display(&ctx).expect("read display");
    assert_eq!(big.len(), (4 * W * H) as usize);
    let mean = |t: &[[f32; 4]]| t.iter().map(|x| f64::from(x[1])).sum::<f64>() / t.len() as f64;
    let beauty: Vec<[f32; 4]> = got
        .pixels
        .iter()
        .map(|p| {
            let g = p.rgb[1].clamp(0.0, 1.0);
            [g, g, g, 1.0]
        })
        .collect();
    let (a, b) = (mean(&beauty), mean(&big));
    assert!((a - b).abs() < 0.02 * a, "scaled mean {b} vs {a}");
    assert_eq!(image.samples(), FRAMES * SPP, "the accumulation is kept");
}

/// A renderer made for a small image (a viewer's first preview) re-aimed at a bigger one
/// renders it in one band while it is at most twice as tall, and asks for a new renderer
/// beyond, rather than splitting every frame into bands of its first image's size.
#[test]
fn a_renderer_renders_a_grown_image_in_one_band_or_asks_to_be_rebuilt() {
    let Some(ctx) =
        harness::context("a_renderer_renders_a_grown_image_in_one_band_or_asks_to_be_rebuilt")
    else {
        return;
    };
    let scene = parse_scene(&scene_text(), Path::new("inline.toml")).expect("scene");
    let field = harness::build_field(&scene, Path::new("."));
    let sized = |w: u32, h: u32| {
        let mut s = scene.clone();
        (s.render.width, s.render.height) = (w, h);
        RenderScene::new(&s, Path::new("."), field.clone()).expect("render scene")
    };
    let mut gpu = GpuRenderer::new(&ctx, &sized(W, H), None).expect("renderer");
    assert_eq!(gpu.rows_per_band(), H);
    assert!(gpu.retarget(&sized(W, 2 * H), 0, SPP).expect("retarget"));
    assert_eq!(gpu.rows_per_band(), 2 * H, "one band for twice the rows");
    let frame = gpu.render(&|_| {}, &AtomicBool::new(false)).expect("frame");
    assert_eq!((frame.width, frame.height), (W, 2 * H));
    assert!(!gpu.retarget(&sized(W, 3 * H), 0, SPP).expect("retarget"));
    assert_eq!(gpu.rows_per_band(), 2 * H, "nothing changed");
}
