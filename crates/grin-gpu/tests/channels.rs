//! `grin render` reads back only the channels an output is made of: the packed words are
//! exactly those of a whole read, the others NaN, the device's counts are the CPU's
//! counts of the whole frame, and the bytes read are the channels' and 64 more.

mod harness;

use std::path::Path;
use std::sync::atomic::AtomicBool;

use grin_gpu::GpuRenderer;
use grin_gpu::channels::{Channels, FrameTotals};
use grin_render::image::PixelOut;
use grin_render::scene::RenderScene;
use grin_scene::parse_scene;

/// A noise ball in front of a checker wall, 2 samples a pixel, steps short enough that
/// the rays through the ball's middle end `max_steps` (three statuses in one frame).
fn scene_text() -> String {
    harness::scenes::noise_ball(48, 30, 2, "max_steps = 80")
}

/// The 15 channels of a pixel as words, in the device's order.
fn words(p: &PixelOut) -> [f32; 15] {
    let mut w = [0.0; 15];
    w[0..3].copy_from_slice(&p.rgb);
    w[3] = p.deflection_deg;
    w[4..7].copy_from_slice(&p.exit_dir);
    w[7] = p.opd;
    w[8] = p.steps;
    w[9] = p.evals;
    w[10] = p.status;
    w[11..14].copy_from_slice(&p.exit_pos);
    w[14] = p.opd_plane;
    w
}

#[test]
fn a_render_reads_back_only_the_channels_asked_for_and_counts_the_rest_on_the_device() {
    let Some(ctx) = harness::context(
        "a_render_reads_back_only_the_channels_asked_for_and_counts_the_rest_on_the_device",
    ) else {
        return;
    };
    let scene = parse_scene(&scene_text(), Path::new("inline.toml")).expect("scene");
    let field = harness::build_field(&scene, Path::new("."));
    let rs = RenderScene::new(&scene, Path::new("."), field).expect("render scene");
    let mut gpu = GpuRenderer::new(&ctx, &rs, None).expect("renderer");
    // Several bands: each packs and reads its own rows, the totals run over all. Short
    // rounds: a band's marches take several submissions, its pixels packed after each
    // batch and counted once.
    gpu.limit_band_rows(7);
    gpu.set_round_steps(4);
    let no = AtomicBool::new(false);
    let before = gpu.bytes_read_back();
    let whole = gpu.render(&|_| {}, &no).expect("whole frame");
    let whole_bytes = gpu.bytes_read_back() - before;
    assert!(
        gpu.last_medium_rounds() > 9,
        "more than one submission of 8 rounds: {}",
        gpu.last_medium_rounds()
    );
    let expected = FrameTotals::of(&whole, 2);
    let statuses = expected.status.iter().filter(|&&n| n > 0).count();
    assert!(
        statuses >= 3 && expected.status[3] > 0,
        "the scene should end rays missed, exited and max_steps: {:?}",
        expected.status
    );
    let pixels = u64::from(whole.width) * u64::from(whole.height);
    assert_eq!(expected.status.iter().sum::<u64>(), pixels);

    let schlieren = Channels::EXIT_DIR
        .and(Channels::EXIT_POS)
        .and(Channels::STATUS);
    for (channels, kept) in [
        (schlieren, vec![4, 5, 6, 10, 11, 12, 13]),
        (Channels::OPD_PLANE, vec![14]),
        (Channels::RED, vec![0]),
    ] {
        let before = gpu.bytes_read_back();
        let (frame, totals) = gpu
            .render_channels(channels, &|_| {}, &no)
            .expect("packed frame");
        let bytes = gpu.bytes_read_back() - before;
        assert_eq!(channels.bytes_per_pixel(), 4 * kept.len() as u64);
        // The same passes and timestamps as the whole frame's; 64 bytes of totals more.
        assert_eq!(
            bytes,
            whole_bytes - pixels * 64 + pixels * channels.bytes_per_pixel() + 64,
            "{channels:?}: bytes read back"
        );
        assert_eq!(totals, expected, "{channels:?}: the device's counts");
        assert_eq!(frame.pixels.len(), whole.pixels.len());
        for (i, (p, q)) in frame.pixels.iter().zip(&whole.pixels).enumerate() {
            let (got, want) = (words(p), words(q));
            for w in 0..15 {
                if kept.contains(&w) {
                    assert_eq!(
                        got[w].to_bits(),
                        want[w].to_bits(),
                        "{channels:?}: pixel {i} word {w}"
                    );
                } else {
                    assert!(got[w].is_nan(), "{channels:?}: pixel {i} word {w} not read");
                }
            }
        }
    }

    // Every channel: the whole frame as it is, counted on the CPU.
    let (frame, totals) = gpu
        .render_channels(Channels::ALL, &|_| {}, &no)
        .expect("whole frame again");
    assert_eq!(totals, expected);
    assert_eq!(frame.pixels.len(), whole.pixels.len());
    assert!(
        frame
            .pixels
            .iter()
            .zip(&whole.pixels)
            .all(|(p, q)| words(p).map(f32::to_bits) == words(q).map(f32::to_bits))
    );
}
