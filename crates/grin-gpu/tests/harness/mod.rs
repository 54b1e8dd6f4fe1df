//! The GPU test harness: adapter acquisition that is loud when it fails, CPU reference
//! renders on the same baked field, and image comparison that writes `*-actual.png`,
//! `*-expected.png` and `*-difference.png` when it fails.

#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use grin_field::IndexField;
use grin_field::baked::BakedField;
use grin_gpu::{GpuContext, GpuRenderer, field::bake_for_gpu};
use grin_render::image::{Frame, diff_frames};
use grin_render::scene::RenderScene;
use grin_scene::Scene;
use grin_trace::render::render_cpu;

/// The workspace's GPU-presence policy (grin-testkit's `skip`, included by path: that
/// crate depends on this one).
#[path = "../../../grin-testkit/src/skip.rs"]
mod skip;

/// The shared scene text (grin-testkit's `scenes`, included by path as `skip` is).
#[path = "../../../grin-testkit/src/scenes.rs"]
pub mod scenes;

/// The device, or `None` when no adapter exists and `GRIN_ALLOW_NO_GPU=1` is set (after
/// printing a prominent `SKIPPED (no GPU adapter): <test>` line). Without that variable a
/// missing adapter fails the test: GPU tests must never pass silently.
pub fn context(test: &str) -> Option<GpuContext> {
    skip::require_gpu(test, GpuContext::new_headless())
}

/// Where failing comparisons write their images.
pub fn output_dir() -> PathBuf {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../target/gpu-test-output");
    std::fs::create_dir_all(&dir).expect("create target/gpu-test-output");
    dir
}

/// A scene's medium field, built the way `grin render` builds it.
pub fn build_field(scene: &Scene, scene_dir: &Path) -> Option<Arc<dyn IndexField>> {
    let medium = scene.medium.as_ref()?;
    Some(grin_field::build_field(medium, scene_dir).expect("scene field builds"))
}

/// The scene's field baked for the GPU at `resolution`, as a field the CPU can march too.
pub fn baked(scene: &Scene, scene_dir: &Path, resolution: usize) -> Option<Arc<BakedField>> {
    let field = build_field(scene, scene_dir)?;
    let t = std::time::Instant::now();
    let baked = bake_for_gpu(field.as_ref(), resolution).expect("bake for GPU");
    eprintln!("bake {resolution}: {:.2} s", t.elapsed().as_secs_f64());
    Some(Arc::new(baked))
}

/// CPU and GPU frames of `scene` marching the same baked field.
pub fn render_both(
    ctx: &GpuContext,
    scene: &Scene,
    scene_dir: &Path,
    baked: Option<Arc<BakedField>>,
) -> (Frame, Frame) {
    let (_, cpu, gpu) = render_both_of(ctx, scene, scene_dir, baked);
    (cpu, gpu)
}

/// [`render_both`], with the render description the frames were made of (its camera's
/// rays, for a test that traces them again).
pub fn render_both_of(
    ctx: &GpuContext,
    scene: &Scene,
    scene_dir: &Path,
    baked: Option<Arc<BakedField>>,
) -> (RenderScene, Frame, Frame) {
    let field = baked.clone().map(|b| b as Arc<dyn IndexField>);
    let rs = RenderScene::new(scene, scene_dir, field).expect("render scene");
    let t = std::time::Instant::now();
    let cpu = render_cpu(&rs, &|_| {}, &AtomicBool::new(false)).expect("CPU render");
    let t_cpu = t.elapsed().as_secs_f64();
    let t = std::time::Instant::now();
    let renderer = GpuRenderer::new(ctx, &rs, baked.as_deref()).expect("GPU renderer");
    let t_setup = t.elapsed().as_secs_f64();
    let t = std::time::Instant::now();
    let gpu = renderer
        .render(&|_| {}, &AtomicBool::new(false))
        .expect("GPU render");
    eprintln!(
        "CPU render {t_cpu:.2} s; GPU setup {t_setup:.2} s, render {:.2} s",
        t.elapsed().as_secs_f64()
    );
    (rs, cpu, gpu)
}

/// Assert the beauty passes agree: mean and 99th-percentile per-pixel difference (the
/// largest channel difference of each pixel, linear radiance) within the tolerances.
/// On failure writes `<name>-actual.png` (GPU), `<name>-expected.png` (CPU) and
/// `<name>-difference.png` (x10) to target/gpu-test-output/.
pub fn assert_images_agree(
    name: &str,
    expected: &Frame,
    actual: &Frame,
    mean_tol: f64,
    p99_tol: f64,
) {
    let (stats, mut diff) = diff_frames(expected, actual).expect("same size");
    eprintln!(
        "{name}: GPU vs CPU per-pixel difference mean {:.2e} p99 {:.2e} max {:.2e} (tolerances {mean_tol:e}, {p99_tol:e})",
        stats.mean, stats.p99, stats.max
    );
    if stats.mean <= mean_tol && stats.p99 <= p99_tol {
        return;
    }
    // The pixels that differ most, with what each backend's ray did (for a failure seen
    // on a machine whose images do not come back).
    let mut worst: Vec<(usize, f32)> = diff
        .pixels
        .iter()
        .enumerate()
        .map(|(i, p)| (i, p.rgb[0]))
        .collect();
    worst.sort_by(|a, b| b.1.total_cmp(&a.1));
    let width = expected.width as usize;
    for &(i, d) in worst.iter().take(8) {
        let (c, g) = (&expected.pixels[i], &actual.pixels[i]);
        eprintln!(
            "  ({}, {}) differs by {d:.3}: cpu rgb {:?} status {} steps {} exit {:?} at {:?}; gpu rgb {:?} status {} steps {} exit {:?} at {:?}",
            i % width,
            i / width,
            c.rgb,
            c.status,
            c.steps,
            c.exit_dir,
            c.exit_pos,
            g.rgb,
            g.status,
            g.steps,
            g.exit_dir,
            g.exit_pos
        );
    }
    let dir = output_dir();
    for p in &mut diff.pixels {
        p.rgb = p.rgb.map(|x| x * 10.0);
    }
    actual
        .write_png(&dir.join(format!("{name}-actual.png")))
        .expect("write actual");
    expected
        .write_png(&dir.join(format!("{name}-expected.png")))
        .expect("write expected");
    diff.write_png(&dir.join(format!("{name}-difference.png")))
        .expect("write difference");
    panic!(
        "{name}: GPU and CPU images differ: mean {:.3e} (tol {mean_tol:e}), p99 {:.3e} (tol {p99_tol:e}); images in {}",
        stats.mean,
        stats.p99,
        dir.display()
    );
}

/// The AOVs of two frames compared pixel by pixel: the fraction of pixels whose status
/// differs, and over the pixels that left the medium on both backends (`exited` or
/// `degraded`: how sure each is, not where it went), the 99th percentile and
/// the max of the exit-direction angle (rad) and of |OPD difference| (world units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AovDiff {
    pub status_mismatch: f64,
    pub left: usize,
    pub dir_p99: f64,
    pub dir_max: f64,
    pub opd_p99: f64,
    pub opd_max: f64,
}

pub fn aov_diff(expected: &Frame, actual: &Frame) -> AovDiff {
    assert_eq!(
        (expected.width, expected.height),
        (actual.width, actual.height)
    );
    let n = expected.pixels.len().max(1);
    let mismatched = expected
        .pixels
        .iter()
        .zip(&actual.pixels)
        .filter(|(p, q)| p.status != q.status)
        .count();
    let (mut dirs, mut opds) = (Vec::new(), Vec::new());
    for (p, q) in expected.pixels.iter().zip(&actual.pixels) {
        let left = |s: f32| s == 1.0 || s == 5.0;
        if left(p.status) && left(q.status) {
            let a = glam::Vec3::from(p.exit_dir).as_dvec3();
            let b = glam::Vec3::from(q.exit_dir).as_dvec3();
            // NaN compares as the largest difference.
            dirs.push(if a.is_finite() && b.is_finite() {
                a.angle_between(b)
            } else {
                f64::INFINITY
            });
            let d = f64::from(p.opd - q.opd).abs();
            opds.push(if d.is_nan() { f64::INFINITY } else { d });
        }
    }
    let p99 = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        let p = v
            .get((v.len() as f64 * 0.99) as usize)
            .or(v.last())
            .copied()
            .unwrap_or(0.0);
        (p, v.last().copied().unwrap_or(0.0))
    };
    let left = dirs.len();
    let (dir_p99, dir_max) = p99(&mut dirs);
    let (opd_p99, opd_max) = p99(&mut opds);
    AovDiff {
        status_mismatch: mismatched as f64 / n as f64,
        left,
        dir_p99,
        dir_max,
        opd_p99,
        opd_max,
    }
}
