//! wgpu's pipeline cache on disk: a device that compiled pipelines leaves a file the next
//! device starts from, images are the same with and without it, and a damaged file is an
//! empty cache (rewritten), never an error.

mod harness;

use std::path::Path;
use std::sync::atomic::AtomicBool;

use grin_gpu::{GpuContext, GpuRenderer};
use grin_render::scene::RenderScene;
use grin_scene::parse_scene;

/// The paper's set, nothing else.
fn scene_text() -> String {
    format!(
        "{}\n[render]\nwidth = 48\nheight = 27\n",
        harness::scenes::PAPER_SET
    )
}

fn frame(ctx: &GpuContext) -> Vec<[f32; 3]> {
    let scene = parse_scene(&scene_text(), Path::new("inline.toml")).expect("scene");
    let rs = RenderScene::new(&scene, Path::new("."), None).expect("render scene");
    let f = GpuRenderer::new(ctx, &rs, None)
        .expect("renderer")
        .render(&|_| {}, &AtomicBool::new(false))
        .expect("render");
    f.pixels.iter().map(|p| p.rgb).collect()
}

#[test]
fn the_pipeline_cache_is_kept_between_devices_and_survives_damage() {
    // The adapter must exist (the harness fails loudly otherwise).
    if harness::context("the_pipeline_cache_is_kept_between_devices_and_survives_damage").is_none()
    {
        return;
    }
    let dir = tempfile::tempdir().expect("temp dir");
    let first = GpuContext::new_headless_in(Some(dir.path())).expect("device");
    let Some((path, loaded)) = first.pipeline_cache_file() else {
        // Only adapters with Features::PIPELINE_CACHE keep one (lavapipe does).
        let uncached = GpuContext::new_headless_in(None).expect("device");
        assert!(uncached.pipeline_cache_file().is_none());
        eprintln!("SKIPPED: {} has no pipeline cache", first.adapter_name());
        return;
    };
    let path = path.to_owned();
    assert_eq!(loaded, 0, "a new directory holds no cache");
    assert!(path.starts_with(dir.path()));
    let image = frame(&first);
    let written = std::fs::read(&path).expect("the compile wrote the cache file");
    assert!(written.starts_with(b"GRINPLC1"), "grin's envelope");
    drop(first);

    let second = GpuContext::new_headless_in(Some(dir.path())).expect("device");
    let (_, loaded) = second.pipeline_cache_file().expect("cache");
    assert_eq!(
        loaded,
        written.len() - 40,
        "the second device starts from the first one's data"
    );
    assert_eq!(
        frame(&second),
        image,
        "same image from the cached pipelines"
    );
    drop(second);

    // A flipped byte in the data: not handed to wgpu, the cache starts empty and the
    // next compile writes an intact file again.
    let mut damaged = written.clone();
    let last = damaged.len() - 1;
    damaged[last] ^= 0x5a;
    std::fs::write(&path, &damaged).expect("write");
    let third = GpuContext::new_headless_in(Some(dir.path())).expect("device");
    assert_eq!(third.pipeline_cache_file().expect("cache").1, 0);
    assert_eq!(frame(&third), image);
    drop(third);
    let rewritten = std::fs::read(&path).expect("rewritten");
    assert_ne!(rewritten, damaged);
    let fourth = GpuContext::new_headless_in(Some(dir.path())).expect("device");
    assert_eq!(
        fourth.pipeline_cache_file().expect("cache").1,
        rewritten.len() - 40,
        "the rewritten file is whole again"
    );
    drop(fourth);

    // No directory: no pipeline cache.
    let uncached = GpuContext::new_headless_in(None).expect("device");
    assert!(uncached.pipeline_cache_file().is_none());
    assert_eq!(frame(&uncached), image);
}
