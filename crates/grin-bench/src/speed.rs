//! `grin bench speed`: the GPU marcher (wgpu, lavapipe without a GPU) and the CPU
//! reference on the same baked fields, in one run: rays/s and ms/frame for the paper's
//! scene (a) (analytic sphere), (c) (Perlin noise) and the heat-haze scene; the
//! noise/analytic frame-time ratio (the paper had 2.0); and the marcher's field-sample
//! rate as a fraction of the adapter's raw trilinear 3D-texture sample rate measured by
//! a microbenchmark (shaders/texture_bench.wgsl). Each of the three scenes is also baked
//! sparsely (grin_field::sparse), trilinear and Catmull-Rom, the coarsest sparse bake
//! measuring the dense one's error or less (within 1%: `cases::sparse_matching`), and
//! timed the same way: the field's bytes and frame time, sparse against dense.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::Instant;

use anyhow::{Context, bail};
use grin_field::IndexField;
use grin_field::baked::Interp;
use grin_gpu::field::{bake_for_gpu_with_report, bake_warning};
use grin_gpu::{GpuContext, GpuRenderer};
use grin_render::image::Frame;
use grin_trace::render::render_cpu;
use serde::Serialize;

/// The benchmarked scenes (files in the scene directory) and their labels.
const SCENES: [(&str, &str); 3] = [
    ("paper-a.toml", "paper (a) analytic"),
    ("paper-c.toml", "paper (c) noise"),
    ("heat-haze.toml", "heat haze"),
];

/// Label of the close-up of paper (c) where every ray marches the medium (sharma, as
/// the scene), and of the same close-up marched with verlet.
const MARCH_ONLY: &str = "(c) medium only";
const MARCH_ONLY_VERLET: &str = "(c) medium, verlet";

/// The close-up's frame corners at this fraction of the medium's angular radius.
const CLOSEUP_FILL: f64 = 0.95;

/// Image size of the full run (the 640x360) and of `--quick`.
const FULL_SIZE: (u32, u32) = (640, 360);
const QUICK_SIZE: (u32, u32) = (160, 90);
/// Bake resolution (nodes along the longest axis) for both backends: the bake helper's
/// default, so analytic and noise media cost the same to sample.
const FULL_BAKE: usize = 128;
const QUICK_BAKE: usize = 48;
/// Timed frames per backend and scene (after one untimed warm-up frame on the GPU).
const FULL_FRAMES: u32 = 3;
const QUICK_FRAMES: u32 = 1;

/// What `grin bench speed` measures.
#[derive(Debug, Clone)]
pub struct Options {
    /// Smaller images, coarser bakes and one timed frame (for CI and smoke tests).
    pub quick: bool,
    /// Directory holding paper-a.toml, paper-c.toml and heat-haze.toml.
    pub scenes: PathBuf,
    /// Skip the CPU backend.
    pub gpu_only: bool,
    /// Image size instead of 640x360 (160x90 with `quick`).
    pub size: Option<(u32, u32)>,
    /// Timed frames per backend and scene instead of 3 (1 with `quick`).
    pub frames: Option<u32>,
}

/// What [`run`] reports as it goes (for a progress bar). Every method does nothing by
/// default.
pub trait Progress {
    /// The frames start: `len` steps in all.
    fn begin(&self, _len: u64) {}
    /// What is rendered now (`<scene> (gpu)`).
    fn phase(&self, _what: &str) {}
    /// One more step done (a frame, or the warm-up frame of a scene).
    fn advance(&self) {}
    /// The frames are done.
    fn finish(&self) {}
    /// A warning, the moment it arises (a run whose frame times spread widely).
    fn warn(&self, _message: &str) {}
}

/// One backend on one scene.
#[derive(Debug, Clone, Serialize)]
pub struct Run {
    pub scene: String,
    pub backend: &'static str,
    pub width: u32,
    pub height: u32,
    /// The fastest frame, wall clock (the rates below are of it).
    pub ms_per_frame: f64,
    /// GPU runs on an adapter with timestamps: the device's time in the render passes
    /// of the fastest-on-the-device frame (no uploads, waits or read-back).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub device_ms_min: Option<f64>,
    /// Frame times over all timed frames: fastest, median, slowest.
    pub ms_min: f64,
    pub ms_median: f64,
    pub ms_max: f64,
    pub rays_per_second: f64,
    pub steps_per_ray: f64,
    pub evals_per_ray: f64,
    /// Integration steps (and straight flights) per second over all rays.
    pub ray_steps_per_second: f64,
    /// Field evaluations per second over all rays.
    pub field_evals_per_second: f64,
    /// The same two rates over the device's time (GPU runs with timestamps).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub device_ray_steps_per_second: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub device_field_evals_per_second: Option<f64>,
    /// The field's bytes as the backend holds it: the GPU's upload (f32 texels), the CPU's
    /// grid (its storage).
    pub field_bytes: u64,
}

impl Run {
    /// (ray-steps/s, field evaluations/s) over the device's time where measured, else
    /// over the wall clock: what the raw sample rate (timed the same way) compares with.
    fn marcher_rates(&self) -> (f64, f64) {
        match (
            self.device_ray_steps_per_second,
            self.device_field_evals_per_second,
        ) {
            (Some(steps), Some(evals)) => (steps, evals),
            _ => (self.ray_steps_per_second, self.field_evals_per_second),
        }
    }
}

/// What `grin bench speed` measured (its `--json`).
#[derive(Debug, Serialize)]
pub struct Report {
    pub adapter: String,
    pub cpu_threads: usize,
    pub bake_resolution: usize,
    pub runs: Vec<Run>,
    /// Per scene: the sparse bake against the dense one at the dense bake's error.
    pub sparse: Vec<SparseRow>,
    /// Frame time of paper (c) over paper (a), both baked (the paper: 2.0).
    pub noise_over_analytic_gpu: f64,
    pub noise_over_analytic_cpu: Option<f64>,
    /// Raw trilinear field samples per second on the adapter (microbenchmark).
    pub raw_field_samples_per_second: f64,
    /// The marcher's ray-steps/s (close-up of paper c's medium) over the raw sample rate.
    pub ray_steps_fraction_of_raw: f64,
    /// The marcher's field evaluations/s (same close-up) over the raw sample rate.
    pub field_evals_fraction_of_raw: f64,
    /// Ray-steps/s of the close-up marched with verlet (one evaluation per step) over
    /// the raw sample rate.
    pub verlet_ray_steps_fraction_of_raw: f64,
    /// Whether the raw rate and the marcher's rates in the fractions are over the
    /// device's own time (timestamps) rather than the wall clock.
    pub timed_on_device: bool,
}

fn mean(frame: &Frame, f: fn(&grin_render::image::PixelOut) -> f32) -> f64 {
    frame.pixels.iter().map(|p| f64::from(f(p))).sum::<f64>() / frame.pixels.len().max(1) as f64
}

/// Spread (slowest - fastest) / fastest above which the machine was busy during a run.
const BUSY_SPREAD: f64 = 0.25;

/// (min, median, max) of frame times in seconds.
fn min_median_max(times: &[f64]) -> (f64, f64, f64) {
    let mut t = times.to_vec();
    t.sort_by(f64::total_cmp);
    let n = t.len();
    if n == 0 {
        return (f64::NAN, f64::NAN, f64::NAN);
    }
    let median = if n % 2 == 1 {
        t[n / 2]
    } else {
        0.5 * (t[n / 2 - 1] + t[n / 2])
    };
    (t[0], median, t[n - 1])
}

/// `frames` frames from `render`, each timed (wall clock) and counted on `progress`: the
/// fastest frame and every frame's seconds.
fn timed_frames(
    frames: u32,
    progress: &dyn Progress,
    mut render: impl FnMut() -> anyhow::Result<Frame>,
) -> anyhow::Result<(Option<Frame>, Vec<f64>)> {
    let mut best: Option<(Frame, f64)> = None;
    let mut times = Vec::new();
    for _ in 0..frames {
        let start = Instant::now();
        let frame = render()?;
        let t = start.elapsed().as_secs_f64();
        times.push(t);
        if best.as_ref().is_none_or(|(_, b)| t < *b) {
            best = Some((frame, t));
        }
        progress.advance();
    }
    Ok((best.map(|(frame, _)| frame), times))
}

/// A scene baked sparsely at its dense bake's error.
#[derive(Debug, Clone, Serialize)]
pub struct SparseRow {
    pub scene: String,
    /// `trilinear` or `tricubic` (Catmull-Rom).
    pub interp: &'static str,
    /// The dense bake's measured relative error: what the sparse bake's may not exceed
    /// (by more than 1%, `cases::SAME_ERROR`).
    pub error: f64,
    /// The sparse bake's own measured relative error (the bake of fewest bytes among the
    /// budgets tried that measured within 1% of `error`: `cases::sparse_matching`).
    pub sparse_error: f64,
    pub dense_bytes: u64,
    pub sparse_bytes: u64,
    pub active_bricks: usize,
    pub total_bricks: usize,
    /// Sparse over dense frame time on the GPU (and the CPU when it ran).
    pub gpu_time_ratio: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cpu_time_ratio: Option<f64>,
}

/// The label of a scene's sparse bake's runs.
fn sparse_label(scene: &str, interp: Interp) -> String {
    match interp {
        Interp::Trilinear => format!("{scene} sparse"),
        Interp::Tricubic => format!("{scene} sparse catmull-rom"),
    }
}

#[allow(clippy::too_many_arguments)]
fn run_of(
    scene: &str,
    backend: &'static str,
    frame: &Frame,
    spp: u32,
    times: &[f64],
    device_times: &[f64],
    field_bytes: u64,
    progress: &dyn Progress,
) -> Run {
    let (min, median, max) = min_median_max(times);
    let seconds = min;
    let rays = f64::from(frame.width) * f64::from(frame.height) * f64::from(spp);
    let steps = mean(frame, |p| p.steps);
    let evals = mean(frame, |p| p.evals);
    let s = seconds.max(1e-9);
    let device_s = device_times
        .iter()
        .copied()
        .min_by(f64::total_cmp)
        .map(|t| t.max(1e-9));
    if times.len() > 1 && (max - min) / min.max(1e-12) > BUSY_SPREAD {
        progress.warn(&format!(
            "{scene} ({backend}): frame times {:.1} / {:.1} / {:.1} ms (min / median / max) spread by more than {:.0}%: the machine was busy; rerun for figures to quote",
            min * 1e3,
            median * 1e3,
            max * 1e3,
            BUSY_SPREAD * 100.0
        ));
    }
    Run {
        scene: scene.to_owned(),
        backend,
        width: frame.width,
        height: frame.height,
        ms_per_frame: seconds * 1e3,
        device_ms_min: device_s.map(|t| t * 1e3),
        ms_min: min * 1e3,
        ms_median: median * 1e3,
        ms_max: max * 1e3,
        rays_per_second: rays / s,
        steps_per_ray: steps,
        evals_per_ray: evals,
        ray_steps_per_second: steps * rays / s,
        field_evals_per_second: evals * rays / s,
        device_ray_steps_per_second: device_s.map(|d| steps * rays / d),
        device_field_evals_per_second: device_s.map(|d| evals * rays / d),
        field_bytes,
    }
}

/// Bake and time the scenes of `options.scenes` on both backends (the GPU only with
/// `gpu_only`), telling `progress` as it goes.
pub fn run(options: &Options, progress: &dyn Progress) -> anyhow::Result<Report> {
    let (size, bake_res, frames) = if options.quick {
        (QUICK_SIZE, QUICK_BAKE, QUICK_FRAMES)
    } else {
        (FULL_SIZE, FULL_BAKE, FULL_FRAMES)
    };
    let size = options.size.unwrap_or(size);
    let frames = options.frames.unwrap_or(frames);
    // Both backends render the GPU's bake of each scene, prepared (auto's pilots in f32)
    // as `grin render --backend gpu` prepares a scene; its bake cache is not used.
    let pipeline = grin_pipeline::Renderer::new(grin_pipeline::Backend::Gpu, false);
    // Load and bake every scene first: input errors stop the run before any GPU work.
    let mut prepared = Vec::new();
    let mut sparse_prepared = Vec::new();
    let mut sparse_bakes = Vec::new();
    for (file, label) in SCENES {
        let path = options.scenes.join(file);
        if !path.is_file() {
            bail!(
                "{}: not found (pass --scenes DIR with paper-a.toml, paper-c.toml, heat-haze.toml)",
                path.display()
            );
        }
        let mut scene = grin_scene::load_scene(&path)?;
        scene.render.width = size.0;
        scene.render.height = size.1;
        scene.render.spp = 1;
        let dir = path.parent().unwrap_or(Path::new("."));
        let name = path.display().to_string();
        let field = grin_pipeline::build_field(&scene, dir, &name)?
            .with_context(|| format!("{name}: no [medium]"))?;
        let (baked, bake) = bake_for_gpu_with_report(field.as_ref(), bake_res)
            .with_context(|| format!("{name}: baking"))?;
        for w in field.warnings().into_iter().chain(bake_warning(&bake)) {
            progress.warn(&w);
        }
        // The render scene marching `grid` in place of the scene's own field.
        let prepare = |grid: Arc<dyn IndexField>| {
            anyhow::Ok(
                pipeline
                    .prepare(&scene, dir, &name, Some(grid))?
                    .render_scene,
            )
        };
        let baked = Arc::new(baked);
        let rs = prepare(baked.clone())?;
        prepared.push((label.to_owned(), rs, Some(baked.clone())));
        // The same field sparsely, at the error the dense grid has: the coarsest sparse
        // bake measuring no more than it, trilinear and Catmull-Rom.
        let error = bake.relative_error.max(1e-6);
        for interp in [Interp::Trilinear, Interp::Tricubic] {
            let (sparse, report) =
                crate::cases::sparse_matching(field.as_ref(), error, interp, &name)?;
            let sparse = Arc::new(sparse);
            let rs = prepare(sparse.clone())?;
            sparse_prepared.push((sparse_label(label, interp), rs, None));
            sparse_bakes.push((label, interp, error, report, baked.data_bytes() as u64));
        }
    }

    // The marcher alone: paper (c)'s medium filling the whole frame (its silhouette
    // reaches past the corners), no objects or lights, so every ray marches and its
    // cost is the march (for the fraction of the raw sample rate).
    let closeup = {
        let (_, rs, baked) = &prepared[1];
        let baked: Option<Arc<grin_field::baked::BakedField>> = baked.clone();
        let mut rs = rs.clone();
        let m = rs.medium.as_ref().context("paper (c) has a medium")?;
        let (centre, radius) = (m.bounds.center(), m.bounds.radius());
        let distance = 3.0 * radius;
        let eye = centre - glam::DVec3::Z * distance;
        // The frame's half-diagonal at 95% of the silhouette's angular radius.
        let tan_silhouette = radius / (distance * distance - radius * radius).sqrt();
        let aspect = f64::from(size.0) / f64::from(size.1);
        let tan_half_y = CLOSEUP_FILL * tan_silhouette / (1.0 + aspect * aspect).sqrt();
        let cam = grin_scene::Camera {
            position: eye.to_array(),
            look_at: centre.to_array(),
            up: [0.0, 1.0, 0.0],
            fov_y_deg: 2.0 * tan_half_y.atan().to_degrees(),
            focal_length_mm: None,
            sensor_height_mm: None,
            pixel_pitch_um: None,
            f_number: None,
            focus_distance: None,
        };
        rs.camera = grin_render::camera::PinholeCamera::new(&cam, size.0, size.1)
            .context("close-up camera")?;
        rs.objects.clear();
        rs.materials.clear();
        rs.lights.clear();
        (MARCH_ONLY.to_owned(), rs, baked)
    };
    // The same close-up marched with verlet: one new field evaluation per step (sharma
    // makes three), so its ray-steps/s is directly comparable with the raw sample rate.
    let closeup_verlet = {
        let mut rs = closeup.1.clone();
        rs.settings.integrator = Some(grin_scene::IntegratorKind::Verlet);
        if let Some(m) = rs.medium.as_mut() {
            m.trace.integrator = grin_scene::IntegratorKind::Verlet;
        }
        (MARCH_ONLY_VERLET.to_owned(), rs, closeup.2.clone())
    };
    prepared.push(closeup);
    prepared.push(closeup_verlet);
    prepared.extend(sparse_prepared);

    let ctx = GpuContext::new_headless()?;
    let adapter = ctx.adapter_name();
    let cpu_threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let per_scene = u64::from(frames) * if options.gpu_only { 1 } else { 2 } + 1;
    progress.begin(per_scene * prepared.len() as u64 + 1);
    let cancel = AtomicBool::new(false);
    let mut runs = Vec::new();
    let mut raw_rate = 0.0;
    for (label, rs, baked) in &prepared {
        progress.phase(&format!("{label} (gpu)"));
        let renderer = GpuRenderer::new(&ctx, rs, baked.as_deref())?;
        renderer.render(&|_| {}, &cancel)?; // warm-up: lavapipe compiles lazily
        progress.advance();
        let mut device_times = Vec::new();
        let (best, times) = timed_frames(frames, progress, || {
            let frame = renderer.render(&|_| {}, &cancel)?;
            device_times.extend(renderer.last_device_seconds());
            Ok(frame)
        })?;
        if let Some(frame) = best {
            runs.push(run_of(
                label,
                "gpu",
                &frame,
                rs.settings.spp,
                &times,
                &device_times,
                renderer.field_bytes(),
                progress,
            ));
        }
        if label == MARCH_ONLY {
            raw_rate = renderer.field_sample_rate(3)?;
        }
        if !options.gpu_only {
            progress.phase(&format!("{label} (cpu)"));
            let (best, times) =
                timed_frames(frames, progress, || Ok(render_cpu(rs, &|_| {}, &cancel)?))?;
            if let Some(frame) = best {
                let field_bytes = match baked {
                    Some(b) => b.data_bytes() as u64,
                    None => rs
                        .medium
                        .as_ref()
                        .and_then(|m| m.field.as_sparse())
                        .map_or(0, |s| s.memory_bytes() as u64),
                };
                runs.push(run_of(
                    label,
                    "cpu",
                    &frame,
                    rs.settings.spp,
                    &times,
                    &[],
                    field_bytes,
                    progress,
                ));
            }
        }
    }
    progress.finish();

    let find = |scene: &str, backend: &str| {
        runs.iter()
            .find(|r| r.scene.contains(scene) && r.backend == backend)
    };
    let ratio = |backend: &str| match (find("(c)", backend), find("(a)", backend)) {
        (Some(c), Some(a)) => Some(c.ms_per_frame / a.ms_per_frame),
        _ => None,
    };
    let exact = |scene: &str, backend: &str| {
        runs.iter()
            .find(|r| r.scene == scene && r.backend == backend)
    };
    let sparse = sparse_bakes
        .iter()
        .map(|(label, interp, error, report, dense_bytes)| {
            let with = sparse_label(label, *interp);
            let ratio = |backend: &str| match (exact(&with, backend), exact(label, backend)) {
                (Some(s), Some(d)) => Some(s.ms_per_frame / d.ms_per_frame),
                _ => None,
            };
            SparseRow {
                scene: (*label).to_owned(),
                interp: interp.name(),
                error: *error,
                sparse_error: report.relative_error,
                dense_bytes: *dense_bytes,
                sparse_bytes: report.memory_bytes,
                active_bricks: report.active_bricks,
                total_bricks: report.total_bricks,
                gpu_time_ratio: ratio("gpu").unwrap_or(f64::NAN),
                cpu_time_ratio: ratio("cpu"),
            }
        })
        .collect();
    let noise_gpu = find(MARCH_ONLY, "gpu");
    let verlet_gpu = find(MARCH_ONLY_VERLET, "gpu");
    Ok(Report {
        adapter,
        cpu_threads,
        bake_resolution: bake_res,
        noise_over_analytic_gpu: ratio("gpu").unwrap_or(f64::NAN),
        noise_over_analytic_cpu: ratio("cpu"),
        raw_field_samples_per_second: raw_rate,
        ray_steps_fraction_of_raw: noise_gpu.map_or(f64::NAN, |r| r.marcher_rates().0 / raw_rate),
        field_evals_fraction_of_raw: noise_gpu.map_or(f64::NAN, |r| r.marcher_rates().1 / raw_rate),
        verlet_ray_steps_fraction_of_raw: verlet_gpu
            .map_or(f64::NAN, |r| r.marcher_rates().0 / raw_rate),
        timed_on_device: ctx.has_timestamps(),
        runs,
        sparse,
    })
}

#[cfg(test)]
mod tests {
    use super::min_median_max;

    #[test]
    fn frame_time_spread_is_min_median_max() {
        assert_eq!(min_median_max(&[3.0, 1.0, 2.0]), (1.0, 2.0, 3.0));
        assert_eq!(min_median_max(&[4.0, 1.0, 2.0, 3.0]), (1.0, 2.5, 4.0));
        assert_eq!(min_median_max(&[5.0]), (5.0, 5.0, 5.0));
        assert!(min_median_max(&[]).0.is_nan());
    }
}
