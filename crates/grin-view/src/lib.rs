//! `grin view`: the real-time renderer. A window (winit, a wgpu surface, egui) shows what
//! a render thread marches with grin-gpu's kernel, frame after frame: an orbit camera,
//! a panel of statistics and controls applied without a restart, a reduced internal
//! resolution while the camera moves and progressive refinement when it stops, and the
//! scene file reloaded when it changes.
//!
//! - [`settings::ViewSettings`]: what the panel edits, applied to the scene file's scene.
//! - [`session::Session`]: the scene on the GPU (fields, bakes, renderer, accumulation),
//!   without a window; tests drive it directly.
//! - [`worker`]: the render thread around a session.
//! - `app`: the window.

mod app;
pub mod display;
pub mod orbit;
pub mod session;
pub mod settings;
pub mod worker;

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use grin_render::image::Frame;

pub use display::Aov;
pub use settings::ViewSettings;

/// How `grin view` runs.
#[derive(Debug, Clone, Default)]
pub struct ViewOptions {
    pub scene: PathBuf,
    /// The image's size in pixels (default: the window's image area; headless: the
    /// scene's [render] size).
    pub size: Option<(u32, u32)>,
    /// Samples per pixel of each frame.
    pub spp: Option<u32>,
    /// Samples per pixel at which a still view is converged.
    pub max_spp: Option<u32>,
    /// Headless run: stop after this many rendered frames.
    pub frames: Option<u32>,
    /// Where the last frame goes (.png: as shown; .exr: every channel, PNG beside).
    pub screenshot: Option<PathBuf>,
    /// Degrees the camera orbits per frame (headless).
    pub orbit_deg: f64,
    /// Bake without the disk cache.
    pub no_cache: bool,
    /// Headless without a window or display: each frame is drawn into an offscreen
    /// texture (needs `frames`).
    pub offscreen: bool,
}

/// Min, median and max of some per-frame figure.
#[derive(Debug, Clone, Copy, Default, serde::Serialize)]
pub struct MinMedMax {
    pub min: f64,
    pub median: f64,
    pub max: f64,
}

impl MinMedMax {
    pub fn of(values: &[f64]) -> Self {
        let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
        if v.is_empty() {
            return MinMedMax::default();
        }
        v.sort_by(f64::total_cmp);
        MinMedMax {
            min: v[0],
            median: v[v.len() / 2],
            max: v[v.len() - 1],
        }
    }
}

/// What a headless run measured.
#[derive(Debug, Clone, serde::Serialize)]
pub struct ViewSummary {
    pub scene: PathBuf,
    /// The render thread's adapter.
    pub adapter: String,
    /// The window's adapter.
    pub display_adapter: String,
    pub frames: u32,
    pub width: u32,
    pub height: u32,
    /// Internal resolution of the last frame.
    pub last_internal: [u32; 2],
    pub orbit_deg_per_frame: f64,
    /// New rendered frames shown per second (between consecutive frames).
    pub fps: MinMedMax,
    /// Wall-clock milliseconds per frame on the render thread (the dispatches to the
    /// last byte read back).
    pub wall_ms: MinMedMax,
    /// The device's milliseconds per frame in the render passes (its timestamps; absent
    /// where the adapter writes none).
    pub device_ms: Option<MinMedMax>,
    /// Bytes read back from the device per frame (pixels and timestamps).
    pub read_back_bytes: MinMedMax,
    pub rays_per_second: f64,
    /// Window redraws per second (the UI's own rate).
    pub ui_fps: f64,
    /// Device, scene, field bake and pipelines of the render thread.
    pub setup_seconds: f64,
    /// The part of `setup_seconds` spent creating the GPU device (adapter, device, the
    /// pipeline cache read).
    pub device_seconds: f64,
    /// From the start to the first frame shown (a still view's low-resolution preview
    /// where its full frame takes longer than the frame budget).
    pub first_frame_seconds: f64,
    /// From the start to the first full frame (the first counted in `frames`).
    pub first_full_frame_seconds: f64,
    pub samples: u32,
    pub converged: bool,
    /// From the last change of the view to the converged image.
    pub converged_seconds: Option<f64>,
    pub steps_per_ray: f64,
    pub evals_per_ray: f64,
    /// The integrator and step traced (with `auto`, the pilot rays' choice).
    pub method: String,
    pub bake_cache: Option<grin_gpu::cache::CacheUse>,
    pub field_grid: Option<[u32; 3]>,
    pub warnings: Vec<String>,
    pub screenshot: Option<PathBuf>,
}

/// Check a screenshot path before any work: `.png` or `.exr`, in a directory that exists.
pub fn check_screenshot(path: &Path) -> anyhow::Result<()> {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    if !matches!(ext.as_deref(), Some("png" | "exr")) {
        bail!(
            "{}: the screenshot must be a .png (the image as shown) or an .exr (every channel)",
            path.display()
        );
    }
    let dir = path.parent().filter(|d| !d.as_os_str().is_empty());
    if let Some(d) = dir
        && !d.is_dir()
    {
        bail!("{}: no such directory {}", path.display(), d.display());
    }
    Ok(())
}

/// Write `frame` as shown (`aov`) to a .png, or every channel to an .exr with the beauty
/// PNG beside it; staged, so a failure leaves no partial file.
pub fn write_screenshot(path: &Path, frame: &Frame, aov: Aov) -> anyhow::Result<()> {
    let is_exr = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("exr"));
    let staged = if is_exr {
        vec![
            frame.stage_exr(path)?,
            frame.stage_png(&path.with_extension("png"))?,
        ]
    } else {
        let (rgba, _) = display::rgba(frame, aov);
        vec![grin_output::stage_path(path, |tmp| {
            image::save_buffer_with_format(
                tmp,
                &rgba,
                frame.width,
                frame.height,
                image::ColorType::Rgba8,
                image::ImageFormat::Png,
            )
            .map_err(|e| e.to_string())
        })?]
    };
    grin_output::commit(staged).with_context(|| format!("{}", path.display()))?;
    Ok(())
}

/// Run the viewer. Errors before the window opens (no display, a broken scene) and
/// after (no adapter, a failed headless frame) are one line each. Headless runs
/// (`frames`) return their summary.
pub fn run(opts: ViewOptions) -> anyhow::Result<Option<ViewSummary>> {
    if let Some(p) = &opts.screenshot {
        check_screenshot(p)?;
    }
    if opts.screenshot.is_some() && opts.frames.is_none() {
        bail!("--screenshot needs --frames N (the frame to write is the N-th)");
    }
    if opts.offscreen && opts.frames.is_none() {
        bail!("--offscreen needs --frames N (there is no window to close)");
    }
    // The user's input first, then the machine.
    let scene = session::load(&opts.scene)?;
    let cache = (!opts.no_cache)
        .then(grin_gpu::cache::BakeCache::user_default)
        .flatten();
    if opts.offscreen {
        let app = app::run_offscreen(app::App::new(opts, &scene, cache))?;
        if let Some(e) = app.fatal {
            bail!("{e}");
        }
        return Ok(app.summary);
    }
    let display = std::env::var_os("DISPLAY").filter(|d| !d.is_empty());
    if display.is_none() {
        bail!(
            "grin view needs an X11 display and DISPLAY is not set (on a machine without one, run it under Xvfb: xvfb-run -a grin view ..., or headless with --frames N --offscreen)"
        );
    }
    let app = app::App::new(opts, &scene, cache);
    let app = app::run_window(app)?;
    if let Some(e) = app.fatal {
        bail!("{e}");
    }
    Ok(app.summary)
}
