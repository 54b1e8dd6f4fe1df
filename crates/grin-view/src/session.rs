//! The viewer's renderer without a window: the scene file, its fields and GPU bakes, the
//! GPU renderer and the progressive accumulation. The window's worker thread drives one;
//! tests drive one directly, through the same [`ViewSettings`] the panel edits.
//!
//! Each [`Session::render`] renders the scene file with the settings applied and, when
//! the view is the one of the last frame, adds the frame's samples to the image so far:
//! frame k renders samples k spp .. (k+1) spp of `max_spp`, so the accumulated image is
//! one render of that many samples (`grin render --spp max_spp`, to rounding). The image
//! stays on the device ([`ViewImage`]): each frame is added there and coloured into the
//! texture the window draws, and only 32 bytes of statistics (and the passes' timestamps)
//! are read back; [`Session::frame`] reads the pixels for a screenshot. What a
//! change costs is decided by comparing scenes: the camera, the image size, spp and the
//! step's value only re-aim the renderer ([`GpuRenderer::retarget`]); the integrator,
//! the step policy or the medium switched on or off build new pipelines; another field
//! (time, interpolation, an edited medium) bakes its grid (memory, then the disk cache).
//!
//! Over 600 lines: one concept, the session's scene, fields, renderers and image kept
//! between frames.

use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, OnceLock};
use std::time::Instant;

use anyhow::Context;
use grin_field::IndexField;
use grin_field::baked::{BakedField, Interp};
use grin_gpu::cache::{BakeCache, CacheUse};
use grin_gpu::field::GpuGrid;
use grin_gpu::view::DisplayTexture;
use grin_gpu::{GpuContext, GpuRenderer, ViewImage};
use grin_render::camera::PinholeCamera;
use grin_render::image::Frame;
use grin_render::scene::RenderScene;
use grin_render::settings::TraceSettings;
use grin_scene::{FieldSpec, Interpolation, Scene};

use crate::display::Aov;
use crate::settings::ViewSettings;

/// Seconds of work a band of a frame is cut to on a CPU adapter (lavapipe), at the cost
/// the renderer last measured: the window's submissions wait behind the band in flight on
/// its one queue, so this is the longest it waits to draw (32 Ki-pixel bands, `grin
/// render`'s there, held a heat-haze window 3.1 s), and each band costs a submission and a
/// wait (~15 ms), so bands are no shorter than they need to be.
pub const CPU_BAND_SECONDS: f64 = 0.25;
/// The fewest pixels a band has on a CPU adapter (and its size before a cost is measured).
pub const CPU_BAND_PIXELS: u32 = 4096;

/// Fields kept in memory (time steps of an animation, interpolations).
const FIELDS_KEPT: usize = 4;

/// How often a frame reads back the device's statistics (steps, evaluations and loop-limit
/// suspects counted since the last read, 32 bytes, with the passes' timestamps) for the
/// panel, while the method stays the same: the frames between read nothing back.
pub const STATS_PERIOD: std::time::Duration = std::time::Duration::from_millis(500);
/// Nodes along the longest axis of the bakes made while time plays (a full bake per
/// frame would stall playback; the paused frame is baked to the error budget).
pub const PLAYBACK_BAKE_RESOLUTION: usize = 48;

/// A field and the grid the GPU marches for it.
#[derive(Debug)]
struct FieldEntry {
    key: String,
    field: Arc<dyn IndexField>,
    /// `None`: the field is a baked file the renderer marches as it is.
    grid: Option<Arc<BakedField>>,
    /// The trilinear twin of a tricubic `grid`, built when the camera first moves.
    preview: OnceLock<Arc<BakedField>>,
    warnings: Vec<String>,
    cache: Option<CacheUse>,
}

impl FieldEntry {
    /// The grid marched while the camera moves: the same nodes trilinear where `grid` is
    /// tricubic (8 texel reads a sample instead of 64), else `grid` itself.
    fn preview_grid(&self) -> Option<Arc<BakedField>> {
        let grid = self.grid.as_ref()?;
        Some(match grid.interp() {
            Interp::Tricubic => self
                .preview
                .get_or_init(|| Arc::new(grid.to_interp(Interp::Trilinear)))
                .clone(),
            Interp::Trilinear => grid.clone(),
        })
    }
}

/// What one [`Session::render`] produced.
#[derive(Debug, Clone)]
pub struct Rendered {
    /// The image's size (the internal resolution).
    pub width: u32,
    pub height: u32,
    /// The texture showing the accumulated image in the AOV asked for (on the device).
    pub display: DisplayTexture,
    /// The value the full colour scale of that AOV stands for.
    pub aov_scale: f32,
    /// Samples per pixel accumulated.
    pub samples: u32,
    /// Seconds the GPU frame took on the wall clock (its dispatches to its end on the
    /// device, after the colour pass).
    pub gpu_seconds: f64,
    /// Seconds the device spent in the frame's render passes (its timestamps; `None`
    /// where the adapter writes none, or the frame read nothing back).
    pub device_seconds: Option<f64>,
    /// Bytes the frame read back from the device: none, or every [`STATS_PERIOD`] and
    /// when the method changes, the statistics and the passes' timestamps (never pixels).
    pub read_back_bytes: u64,
    /// Seconds spent on baking, building fields and pipelines before it (0 when the
    /// renderer was only re-aimed).
    pub setup_seconds: f64,
    pub rays_per_second: f64,
    /// Means over the frames counted at the last read of the statistics (this frame's
    /// method).
    pub steps_per_ray: f64,
    pub evals_per_ray: f64,
    /// The accumulation reached `max_spp`.
    pub converged: bool,
    /// The integrator and step traced (what `auto` resolved to).
    pub method: String,
}

/// `sharma, fixed ds 0.2500`: the integrator and step of `s`.
pub fn method_name(s: &grin_scene::RenderSettings) -> String {
    let k = s.integrator().name();
    match s.step {
        grin_scene::StepSpec::Fixed(ds) => format!("{k}, fixed ds {ds:.4}"),
        grin_scene::StepSpec::Heuristic { min, max, .. } => {
            format!("{k}, heuristic ds {min:.4} .. {max:.4}")
        }
        grin_scene::StepSpec::Adaptive { tolerance, .. } => {
            format!("{k}, error control {tolerance:.0e} per step")
        }
        grin_scene::StepSpec::Auto(rad) => format!("{k}, error control per length {rad:.0e} rad"),
    }
}

/// Why nothing was rendered: cancelled (a newer view is waiting), or an error to show.
#[derive(Debug)]
pub enum RenderFailure {
    Cancelled,
    Error(anyhow::Error),
}

impl<E: Into<anyhow::Error>> From<E> for RenderFailure {
    fn from(e: E) -> Self {
        RenderFailure::Error(e.into())
    }
}

struct Gpu<'a> {
    renderer: GpuRenderer<'a>,
    scene: RenderScene,
    /// The grid it marches (`None`: the scene's own baked file, or no medium).
    grid: Option<Arc<BakedField>>,
    /// The scene's objects, lights, sky and medium as JSON: what the renderer holds.
    static_key: String,
    /// `step = { auto = ... }` as the pilot rays resolved it: the settings asked (as
    /// JSON) and the tracer settings chosen, kept while only the camera moves.
    auto: Option<(String, TraceSettings)>,
}

/// What an `auto` choice depends on besides the view: the step, integrator and pilot
/// count asked.
fn auto_key(s: &grin_scene::RenderSettings) -> String {
    json(&(s.step, s.integrator, s.pilot_rays))
}

/// Resolve `scene`'s `auto` step (`applied`: the scene file as viewed) as `grin render
/// --backend gpu` does ([`grin_pipeline::resolve_auto`]), or reuse `cached` when the step,
/// integrator and pilot count asked are the same (only the camera or the image moved).
fn resolve_auto(
    scene: &mut RenderScene,
    applied: &Scene,
    cached: &mut Option<(String, TraceSettings)>,
) {
    let key = auto_key(&scene.settings);
    if matches!(scene.settings.step, grin_scene::StepSpec::Auto(_))
        && let Some((k, t)) = cached.as_ref()
        && *k == key
    {
        grin_trace::auto::apply(scene, t);
        return;
    }
    let (choice, _) = grin_pipeline::resolve_auto(scene, applied, true);
    *cached = choice.map(|c| (key, c.settings));
}

/// The viewer's scene on the GPU.
pub struct Session<'a> {
    ctx: &'a GpuContext,
    path: PathBuf,
    dir: PathBuf,
    scene: Scene,
    cache: Option<BakeCache>,
    fields: VecDeque<FieldEntry>,
    /// The renderers of still frames and of preview frames (while the camera moves).
    gpus: [Option<Gpu<'a>>; 2],
    /// Each renderer's seconds per pixel-sample in its last frame (for band sizes on a CPU
    /// adapter).
    sample_seconds: [Option<f64>; 2],
    /// The view whose samples the image on the device holds (its key).
    accum: Option<String>,
    /// The accumulated image and the texture the window draws.
    image: Option<ViewImage>,
    /// The texture's size (the window's image area); `None`: the image's own size.
    display_size: Option<[u32; 2]>,
    /// The AOV the texture shows.
    shown_aov: Option<Aov>,
    /// Warnings about the current field (an under-resolved bake), for the panel.
    pub warnings: Vec<String>,
    /// What the last frame itself warns of (pixels cut short by lavapipe's loop limit):
    /// replaced every frame, shown after `warnings`.
    pub frame_warning: Option<String>,
    /// Whether the current field's GPU grid came from the disk cache.
    pub cache_use: Option<CacheUse>,
    /// The current field's GPU grid: node counts and bytes.
    pub field_grid: Option<([u32; 3], u64)>,
    /// The statistics as last read: when, for which method (integrator, step,
    /// interpolation, samples, preview, AOV, medium on or off), and their means a ray.
    stats: Option<StatsRead>,
    /// Rays of the frames added since the statistics were last read.
    rays_uncounted: f64,
}

/// The device's statistics as a [`Session`] last read them.
#[derive(Debug, Clone)]
struct StatsRead {
    at: Instant,
    method: String,
    steps_per_ray: f64,
    evals_per_ray: f64,
    aov_scale: f32,
}

impl std::fmt::Debug for Session<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Session")
            .field("path", &self.path)
            .field("samples", &self.image.as_ref().map(ViewImage::samples))
            .finish_non_exhaustive()
    }
}

/// Scene file -> scene, with the file named in the error.
pub fn load(path: &Path) -> anyhow::Result<Scene> {
    Ok(grin_scene::load_scene(path)?)
}

fn json<T: serde::Serialize>(v: &T) -> String {
    serde_json::to_string(v).unwrap_or_default()
}

impl<'a> Session<'a> {
    /// Load the scene file (errors name it). `cache`: the disk cache of GPU bakes.
    pub fn new(ctx: &'a GpuContext, path: &Path, cache: Option<BakeCache>) -> anyhow::Result<Self> {
        let scene = load(path)?;
        let dir = path.parent().unwrap_or(Path::new(".")).to_owned();
        let mut s = Session {
            ctx,
            path: path.to_owned(),
            dir,
            scene,
            cache,
            fields: VecDeque::new(),
            gpus: [None, None],
            sample_seconds: [None, None],
            accum: None,
            image: None,
            display_size: None,
            shown_aov: None,
            warnings: Vec::new(),
            frame_warning: None,
            cache_use: None,
            field_grid: None,
            stats: None,
            rays_uncounted: 0.0,
        };
        // Build the field now, so a scene whose medium cannot be built fails here.
        let applied = ViewSettings::from_scene(&s.scene).apply(&s.scene, 1, 1);
        s.field_for(&applied, false, None)?;
        Ok(s)
    }

    /// The scene file as last loaded successfully.
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Read the scene file again. On success it replaces the scene (and `Ok` holds the
    /// new file's settings); on error the last good scene stays and the error names the
    /// file, line and key.
    pub fn reload(&mut self) -> anyhow::Result<ViewSettings> {
        let scene = load(&self.path)?;
        let applied = ViewSettings::from_scene(&scene).apply(&scene, 1, 1);
        // The medium must build (a VDB that exists, n > 0) before the scene is taken.
        let field = self.build_entry(&applied, false, None)?;
        RenderScene::new(&applied, &self.dir, field.as_ref().map(|f| f.field.clone()))
            .with_context(|| self.path.display().to_string())?;
        if let Some(f) = field {
            self.remember(f);
        }
        self.scene = scene;
        self.gpus = [None, None];
        self.accum = None;
        Ok(ViewSettings::from_scene(&self.scene))
    }

    /// Whether a frame of `settings` at `width` x `height` would add anything: the view
    /// changed, or its accumulation is short of `max_spp`.
    pub fn needs_frame(&self, settings: &ViewSettings, width: u32, height: u32) -> bool {
        self.accum_of(settings, width, height)
            .is_none_or(|samples| samples < settings.max_spp)
    }

    /// An image of this view (`settings` at `width` x `height`) is accumulated, at any
    /// number of samples.
    pub fn has_image_of(&self, settings: &ViewSettings, width: u32, height: u32) -> bool {
        self.accum_of(settings, width, height).is_some()
    }

    /// Show the image in the window's image area of `width` x `height` pixels (the
    /// texture's size; frames rendered smaller are scaled to fill it).
    pub fn set_display_size(&mut self, width: u32, height: u32) {
        self.display_size = Some([width.max(1), height.max(1)]);
    }

    /// The AOV the texture shows (`None` before the first frame).
    pub fn shown_aov(&self) -> Option<Aov> {
        self.shown_aov
    }

    /// Colour the accumulated image's `aov` into the texture (no new frame): the texture
    /// and the value its full colour scale stands for.
    pub fn show(&mut self, aov: Aov) -> anyhow::Result<(DisplayTexture, f32)> {
        let image = self
            .image
            .as_mut()
            .filter(|i| i.samples() > 0)
            .context("no image to show yet")?;
        if let Some(d) = self.display_size {
            let [w, h] = image.size();
            image.reserve(self.ctx, w, h, d)?;
        }
        let stats = image.show(self.ctx, aov_index(aov))?;
        // The read restarts the device's counts: the frames before it are not counted.
        self.rays_uncounted = 0.0;
        self.shown_aov = Some(aov);
        Ok((image.display_texture(), stats.scale))
    }

    /// The accumulated image read back from the device (mean radiance of all samples so
    /// far, steps and evaluations averaged, the other AOVs of its first frame): for a
    /// screenshot or an export, never per frame.
    pub fn frame(&self) -> anyhow::Result<Frame> {
        let image = self
            .image
            .as_ref()
            .filter(|i| i.samples() > 0)
            .context("no image to read yet")?;
        Ok(image.read_frame(self.ctx)?)
    }

    /// The texture as shown, read back (linear RGBA a texel; for tests).
    pub fn displayed(&self) -> anyhow::Result<Vec<[f32; 4]>> {
        let image = self.image.as_ref().context("no image shown yet")?;
        Ok(image.read_display(self.ctx)?)
    }

    /// Bytes of pixels read back so far (only by [`Self::frame`] and [`Self::displayed`]).
    pub fn pixel_bytes_read_back(&self) -> u64 {
        self.image
            .as_ref()
            .map_or(0, ViewImage::pixel_bytes_read_back)
    }

    /// The samples accumulated, where the image holds this view.
    fn accum_of(&self, settings: &ViewSettings, width: u32, height: u32) -> Option<u32> {
        let applied = settings.apply(&self.scene, width, height);
        self.samples_of(&view_key(&applied, settings))
    }

    /// The samples the image holds of the view keyed `view` (none: another view, or an
    /// image started again).
    fn samples_of(&self, view: &str) -> Option<u32> {
        let samples = self.image.as_ref().map_or(0, ViewImage::samples);
        (self.accum.as_deref() == Some(view) && samples > 0).then_some(samples)
    }

    /// Render one frame of `settings` at `width` x `height` (the internal resolution)
    /// and accumulate it; `cancel` stops between bands of rows. A `preview` frame (the
    /// camera is moving) has 1 sample a pixel and marches a tricubic grid's nodes
    /// trilinear, on a renderer of its own, so starting and stopping costs no rebuild.
    pub fn render(
        &mut self,
        settings: &ViewSettings,
        width: u32,
        height: u32,
        preview: bool,
        cancel: &AtomicBool,
    ) -> Result<Rendered, RenderFailure> {
        let setup = Instant::now();
        let mut settings = settings.clone();
        if preview {
            settings.spp = 1;
        }
        let settings = &settings;
        let applied = settings.apply(&self.scene, width, height);
        let view = view_key(&applied, settings);
        let display = self.display_size.unwrap_or([width, height]);
        match &mut self.image {
            Some(image) => image.reserve(self.ctx, width, height, display)?,
            None => {
                let mut image = ViewImage::new(self.ctx, width, height)?;
                image.reserve(self.ctx, width, height, display)?;
                self.image = Some(image);
            }
        }
        let first_sample = self
            .samples_of(&view)
            .filter(|&s| s < settings.max_spp)
            .unwrap_or(0);
        let continuing = first_sample > 0;
        let spp_total = settings.max_spp.max(applied.render.spp);

        let static_key = json(&(
            &applied.objects,
            &applied.lights,
            &applied.sky,
            &applied.medium,
            settings.interpolation,
            settings.playing,
        ));
        let slot = usize::from(preview);
        if self.gpus[slot]
            .as_ref()
            .is_some_and(|g| g.static_key != static_key)
        {
            self.gpus[slot] = None;
        }
        let mut rebuilt = false;
        if let Some(g) = &mut self.gpus[slot] {
            // Same objects and field: new camera and settings into the same renderer.
            let camera = PinholeCamera::new(&applied.camera, width, height)
                .context("camera: the view is degenerate")?;
            if let Some(m) = &g.scene.medium {
                TraceSettings::from_render(&applied.render)
                    .validate_for(&m.bounds)
                    .context("[render]")?;
            }
            g.scene.camera = camera;
            g.scene.settings = applied.render.clone();
            resolve_auto(&mut g.scene, &applied, &mut g.auto);
            if !g.renderer.retarget(&g.scene, first_sample, spp_total)? {
                // Other pipelines (integrator, step policy, flags) or a bigger image.
                let mut renderer = GpuRenderer::new(self.ctx, &g.scene, g.grid.as_deref())?;
                renderer.retarget(&g.scene, first_sample, spp_total)?;
                g.renderer = renderer;
                rebuilt = true;
            }
        } else {
            let entry = self.field_for(&applied, settings.playing, settings.interpolation)?;
            let (field, grid) = match entry {
                Some(e) if preview => (Some(e.field.clone()), e.preview_grid()),
                Some(e) => (Some(e.field.clone()), e.grid.clone()),
                None => (None, None),
            };
            let label = self.path.display().to_string();
            let prepared = grin_pipeline::prepare_scene(&applied, &self.dir, &label, field, true)?;
            let mut scene = prepared.render_scene;
            // A background plate stays where the scene file's camera sees it.
            scene.pin_plate_to(&self.scene.camera);
            let auto = prepared
                .auto
                .map(|c| (auto_key(&scene.settings), c.settings));
            let mut renderer = GpuRenderer::new(self.ctx, &scene, grid.as_deref())?;
            renderer.retarget(&scene, first_sample, spp_total)?;
            self.warnings.extend(renderer.warnings().iter().cloned());
            if !preview || self.field_grid.is_none() {
                self.field_grid = applied
                    .medium
                    .is_some()
                    .then(|| (renderer.field_dims(), renderer.field_bytes()));
            }
            self.gpus[slot] = Some(Gpu {
                renderer,
                scene,
                grid,
                static_key,
                auto,
            });
            rebuilt = true;
        }
        let setup_seconds = if rebuilt {
            setup.elapsed().as_secs_f64()
        } else {
            0.0
        };
        let Some(g) = &mut self.gpus[slot] else {
            return Err(RenderFailure::Error(anyhow::anyhow!("no renderer")));
        };
        let spp = applied.render.spp;
        if self.ctx.is_cpu_adapter() {
            // Bands of CPU_BAND_SECONDS keep the window drawing (and cancels prompt).
            let pixels = self.sample_seconds[slot].map_or(CPU_BAND_PIXELS, |c| {
                (CPU_BAND_SECONDS / (c * f64::from(spp.max(1))).max(1e-12))
                    .clamp(f64::from(CPU_BAND_PIXELS), f64::from(u32::MAX)) as u32
            });
            g.renderer.limit_band_rows((pixels / width.max(1)).max(1));
        }
        let method = method_name(&g.scene.settings);
        let Some(image) = self.image.as_mut() else {
            return Err(RenderFailure::Error(anyhow::anyhow!("no image")));
        };
        // The statistics are read when the method (or the AOV, whose colour scale they
        // hold) is not the one last read, and every STATS_PERIOD; the frames between
        // read nothing back.
        let counted = format!(
            "{method} {:?} spp {spp} preview {preview} {:?} medium {}",
            settings.interpolation, settings.aov, settings.medium
        );
        let same = self.stats.as_ref().is_some_and(|s| s.method == counted);
        if !same {
            // What was counted since the last read is of another method: dropped.
            image.discard_stats();
            self.rays_uncounted = 0.0;
        }
        // The frame that completes a still image reads too: no frame follows it, and the
        // panel keeps what it shows.
        let completes = !preview && first_sample + spp >= settings.max_spp;
        let read = !same
            || completes
            || self
                .stats
                .as_ref()
                .is_some_and(|s| s.at.elapsed() >= STATS_PERIOD);
        let read_before = g.renderer.bytes_read_back() + image.stats_bytes_read_back();
        let start = Instant::now();
        let stats = match g.renderer.render_to_view(
            image,
            !continuing,
            aov_index(settings.aov),
            read,
            cancel,
        ) {
            Ok(stats) => stats,
            Err(e) => {
                // Part of the image may be this frame's: the next starts it again,
                // and counts its statistics afresh.
                self.accum = None;
                image.discard_stats();
                self.rays_uncounted = 0.0;
                return Err(match e {
                    grin_gpu::GpuError::Cancelled => RenderFailure::Cancelled,
                    e => e.into(),
                });
            }
        };
        self.shown_aov = Some(settings.aov);
        let gpu_seconds = start.elapsed().as_secs_f64();
        let pixel_samples = f64::from(width) * f64::from(height) * f64::from(spp.max(1));
        self.sample_seconds[slot] = Some(gpu_seconds / pixel_samples.max(1.0));
        let device_seconds = g.renderer.last_device_seconds();
        let read_back_bytes =
            g.renderer.bytes_read_back() + image.stats_bytes_read_back() - read_before;
        let rays = f64::from(width) * f64::from(height) * f64::from(spp);
        self.rays_uncounted += rays;
        if let Some(stats) = stats {
            // Means over every frame counted since the last read.
            let counted_rays = std::mem::take(&mut self.rays_uncounted).max(1.0);
            // Pixels a frame: the suspects of every frame counted, over their number.
            let suspects = stats.loop_limit_suspects.div_ceil(stats.frames.max(1));
            self.frame_warning = g.renderer.loop_limit_warning_of(u64::from(suspects));
            self.stats = Some(StatsRead {
                at: Instant::now(),
                method: counted,
                steps_per_ray: stats.steps as f64 / counted_rays,
                evals_per_ray: stats.evals as f64 / counted_rays,
                aov_scale: stats.scale,
            });
        }
        let Some(stats) = self.stats.clone() else {
            return Err(RenderFailure::Error(anyhow::anyhow!(
                "the device's statistics were never read"
            )));
        };
        let samples = image.samples();
        self.accum = Some(view);
        Ok(Rendered {
            width,
            height,
            display: image.display_texture(),
            aov_scale: stats.aov_scale,
            samples,
            gpu_seconds,
            device_seconds,
            read_back_bytes,
            setup_seconds,
            rays_per_second: rays / gpu_seconds.max(1e-9),
            steps_per_ray: stats.steps_per_ray,
            evals_per_ray: stats.evals_per_ray,
            converged: samples >= settings.max_spp,
            method,
        })
    }

    fn remember(&mut self, entry: FieldEntry) {
        self.fields.retain(|f| f.key != entry.key);
        self.fields.push_back(entry);
        while self.fields.len() > FIELDS_KEPT {
            self.fields.pop_front();
        }
    }

    /// The field of `applied`'s medium and its GPU grid: from memory, else built (and
    /// baked through the disk cache, except for the coarse bakes made while playing).
    fn field_for(
        &mut self,
        applied: &Scene,
        playing: bool,
        interp: Option<Interpolation>,
    ) -> anyhow::Result<Option<&FieldEntry>> {
        let key = json(&(&applied.medium, interp, playing));
        if applied.medium.is_none() {
            self.warnings.clear();
            self.cache_use = None;
            return Ok(None);
        }
        if !self.fields.iter().any(|f| f.key == key) {
            let entry = self.build_entry(applied, playing, interp)?;
            if let Some(e) = entry {
                self.remember(e);
            }
        }
        // Most recently used last (the retarget path reads the back).
        if let Some(i) = self.fields.iter().position(|f| f.key == key)
            && let Some(e) = self.fields.remove(i)
        {
            self.fields.push_back(e);
        }
        let entry = self.fields.back();
        if let Some(e) = entry {
            self.warnings = e.warnings.clone();
            self.cache_use = e.cache;
        }
        Ok(entry)
    }

    fn build_entry(
        &self,
        applied: &Scene,
        playing: bool,
        interp: Option<Interpolation>,
    ) -> anyhow::Result<Option<FieldEntry>> {
        let label = self.path.display().to_string();
        let (Some(spec), Some(field)) = (
            &applied.medium,
            grin_pipeline::build_field(applied, &self.dir, &label)?,
        ) else {
            return Ok(None);
        };
        let key = json(&(&applied.medium, interp, playing));
        // The field's own warnings (a VDB grid its bounds cut, an unproven positivity)
        // come first in the panel, then the bake's.
        let mut warnings = field.warnings();
        let file = field.as_baked().is_some() || field.as_sparse().is_some();
        let (grid, cache) = if playing && !file {
            let (g, report) =
                grin_gpu::field::bake_for_gpu_with_report(field.as_ref(), PLAYBACK_BAKE_RESOLUTION)
                    .map_err(|e| anyhow::anyhow!("{label}: baking the field: {e}"))?;
            warnings.extend(grin_gpu::field::bake_warning(&report));
            warnings.push(format!(
                "playing: the field is baked at {PLAYBACK_BAKE_RESOLUTION} nodes per axis; pause for the full bake"
            ));
            (Some(GpuGrid::Dense(Arc::new(g))), None)
        } else {
            // The disk cache holds the scene file's own field (its own t); time steps of
            // an animation are baked in memory only.
            let file_t = crate::settings::scene_time(&self.scene);
            let own_time = match &spec.field {
                FieldSpec::Noise(n) => Some(n.t) == file_t,
                FieldSpec::Expr { t, .. } => Some(*t) == file_t,
                _ => true,
            };
            let cache = self.cache.as_ref().filter(|_| own_time);
            match grin_gpu::cache::medium_gpu_grid(field.as_ref(), spec, &self.dir, cache)? {
                Some((g, w, used)) => {
                    warnings.extend(w);
                    (Some(g), Some(used))
                }
                // A baked file, marched as it is.
                None => (None, None),
            }
        };
        let (field, grid) = match grid {
            None => (field, None),
            // A sparse grid (a mostly ambient medium no dense grid within the GPU's cap
            // resolves) is marched as the field itself: the renderer uploads it.
            Some(GpuGrid::Sparse(sparse)) => (sparse as Arc<dyn IndexField>, None),
            Some(GpuGrid::Dense(grid)) => {
                let grid = match interp {
                    None => grid,
                    Some(i) => Arc::new(Arc::unwrap_or_clone(grid).with_interp(i.into())),
                };
                (field, Some(grid))
            }
        };
        Ok(Some(FieldEntry {
            key,
            field,
            grid,
            preview: OnceLock::new(),
            warnings,
            cache,
        }))
    }
}

/// `aov`'s index in the colour pass (shaders/view.wgsl's AOV_*: [`Aov::ALL`]'s order).
fn aov_index(aov: Aov) -> u32 {
    Aov::ALL.iter().position(|a| *a == aov).unwrap_or(0) as u32
}

/// Everything that makes two frames' samples belong to one image.
fn view_key(applied: &Scene, settings: &ViewSettings) -> String {
    json(&(
        applied,
        settings.interpolation,
        settings.playing,
        settings.max_spp,
    ))
}
