//! One way from a scene to its image: the medium's field, the render description,
//! `step = { auto = ... }`'s pilot rays, the GPU bake (through the user's bake cache) and
//! the renderer of either backend, to the output's named channels (the EXR's) and
//! previews with a report of how it went. `grin render` writes what [`Renderer::render`]
//! returns to files; the Python package hands the same channels out as arrays.
//! [`build_field`] and [`prepare_scene`] (the render description and `auto`'s choice)
//! are its first steps on their own: `grin bench speed` renders its own bake of the
//! field, prepared the same way, and `grin view`'s session prepares each scene it shows
//! through them, keeping what they make between frames.
//!
//! Over 600 lines: one concept, the render path from a scene to its output, its steps in order.

pub mod dataset;
pub mod optics;
pub mod trace;

use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use anyhow::Context;
use grin_field::IndexField;
use grin_gpu::channels::{Channels, FrameTotals};
use grin_render::image::Frame;
use grin_render::scene::RenderScene;
use grin_scene::{OpticsMode, Scene};

/// Which renderer runs the frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "lowercase")]
#[derive(strum::IntoStaticStr, strum::VariantNames)]
#[strum(serialize_all = "lowercase")]
pub enum Backend {
    /// The GPU marcher where wgpu finds a GPU, else the CPU tracer: on a CPU adapter
    /// (Mesa's lavapipe where a machine has no GPU) the marcher, built for GPUs, renders
    /// the same frame on the same cores several times slower.
    Auto,
    /// The WGSL marcher through wgpu (lavapipe without a GPU).
    Gpu,
    /// The CPU reference (rayon).
    Cpu,
}

impl Backend {
    pub fn name(self) -> &'static str {
        self.into()
    }
}

impl std::str::FromStr for Backend {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        <Self as clap::ValueEnum>::from_str(s, false).map_err(|_| {
            let names = one_of(<Self as strum::VariantNames>::VARIANTS);
            format!("unknown backend `{s}` ({names})")
        })
    }
}

/// `a, b or c`: the allowed names, as the error messages list them.
pub fn one_of(names: &[&str]) -> String {
    match names.split_last() {
        Some((last, rest)) if !rest.is_empty() => format!("{} or {last}", rest.join(", ")),
        _ => names.join(""),
    }
}

/// What a render reports as it goes: rows done (for a progress bar) and warnings the
/// moment they arise. Every method does nothing by default.
pub trait Progress: Sync {
    /// A pass of `rows` rows starts.
    fn begin(&self, _rows: u64) {}
    /// `rows` more rows are done.
    fn advance(&self, _rows: u32) {}
    /// The passes are done.
    fn finish(&self) {}
    /// A warning (also kept in [`Report::warnings`]).
    fn warn(&self, _message: &str) {}
}

/// Reports nothing as it goes.
#[derive(Debug)]
pub struct Quiet;
impl Progress for Quiet {}

/// Warnings as they arise: told to the progress at once, and kept.
struct Warnings<'a> {
    list: Vec<String>,
    progress: &'a dyn Progress,
}

impl<'a> Warnings<'a> {
    fn new(progress: &'a dyn Progress) -> Self {
        Self {
            list: Vec::new(),
            progress,
        }
    }

    fn push(&mut self, message: String) {
        self.progress.warn(&message);
        self.list.push(message);
    }
}

/// One preview image: 8-bit sRGB of the output's size, row 0 at the top.
#[derive(Debug, Clone)]
pub struct Preview {
    /// `None` for the output's own preview; else what the image is (`reference`: the BOS
    /// reference image), written beside it as `<name>-<suffix>.png`.
    pub suffix: Option<&'static str>,
    pub rgb8: Vec<u8>,
}

/// A rendered output: named f32 channels of one size, row 0 at the top, as the EXR holds
/// them, and its previews.
#[derive(Debug, Clone)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub channels: Vec<(String, Vec<f32>)>,
    pub previews: Vec<Preview>,
}

impl Image {
    pub fn new(width: u32, height: u32) -> Self {
        Self {
            width,
            height,
            channels: Vec::new(),
            previews: Vec::new(),
        }
    }

    pub fn push(&mut self, name: &str, data: Vec<f32>) {
        self.channels.push((name.to_owned(), data));
    }

    /// The channel names, in order.
    pub fn names(&self) -> Vec<&str> {
        self.channels.iter().map(|(n, _)| n.as_str()).collect()
    }

    /// The channel `name`.
    pub fn channel(&self, name: &str) -> Option<&[f32]> {
        self.channels
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, d)| d.as_slice())
    }
}

/// The field grid on the device.
#[derive(Debug, Clone, serde::Serialize)]
pub struct GpuField {
    pub dims: [u32; 3],
    pub bytes: u64,
}

/// How a render went, for the summary.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Report {
    /// The backend that rendered (`gpu` or `cpu`; what `auto` chose).
    pub backend: &'static str,
    /// `--backend auto`: which backend it chose and why.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub backend_note: Option<String>,
    pub adapter: String,
    pub width: u32,
    pub height: u32,
    pub spp: u32,
    /// Frame time (the render itself).
    pub seconds: f64,
    /// Device setup, field bake and upload, pipeline creation (GPU; ~0 on the CPU).
    pub setup_seconds: f64,
    /// GPU: the device's own time in the render passes (timestamps; absent where the
    /// adapter has none). `seconds` adds dispatching and reading the pixels back.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub device_seconds: Option<f64>,
    pub rays_per_second: f64,
    pub steps_per_ray: f64,
    pub evals_per_ray: f64,
    /// Pixels by the camera ray's status in the medium (sample 0): missed, exited,
    /// absorbed (stopped on an object inside), max_steps, error.
    pub status_counts: std::collections::BTreeMap<&'static str, usize>,
    /// Warnings also told to the progress: an under-resolved GPU bake, pixels stopped in
    /// the medium.
    pub warnings: Vec<String>,
    /// GPU: whether the field grid came from the bake cache (`hit`), was baked and stored
    /// (`stored`) or baked without it (`off`); absent for a baked file or no medium.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bake_cache: Option<grin_gpu::cache::CacheUse>,
    /// GPU: the baked grid the marcher sampled (a `.grinf` file as it is, else the
    /// coarsest bake meeting the error budget, at most 128 nodes per axis).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gpu_field: Option<GpuField>,
    /// GPU: bytes read back from the device for the output: the channels of each pixel
    /// it is made of ([`output_channels`]), the frame's counts, the passes' timestamps.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub read_back_bytes: Option<u64>,
    /// `[optics]`: the mode's output (channels, ranges).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub optics: Option<serde_json::Value>,
    /// `step = { auto = ... }`: what the pilot rays chose (and every candidate tried).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub auto: Option<grin_trace::auto::AutoChoice>,
    /// `step = { auto = ... }` resolved without pilots (a render too small for them): why.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub auto_note: Option<String>,
}

/// A scene's rendered output.
#[derive(Debug)]
pub struct Rendered {
    /// The output's channels: the beauty and AOVs, or the `[optics]` mode's.
    pub image: Image,
    /// The frame the output came from: the beauty and AOVs of each pixel (for an
    /// `[optics]` output, of its centre ray; none for a shadowgraph, which traces a beam).
    /// On the GPU backend it holds the channels the output is made of
    /// ([`output_channels`]), the others NaN, unless the renderer reads every channel
    /// ([`Renderer::reading_every_channel`]).
    pub frame: Option<Frame>,
    /// The camera the frame was rendered through.
    pub camera: grin_render::camera::PinholeCamera,
    /// The medium's field (none without a medium).
    pub field: Option<std::sync::Arc<dyn grin_field::IndexField>>,
    pub report: Report,
}

/// The field of `scene`'s medium (read from `scene_dir`; `label` names it in errors),
/// `None` without a medium.
pub fn build_field(
    scene: &Scene,
    scene_dir: &Path,
    label: &str,
) -> anyhow::Result<Option<Arc<dyn IndexField>>> {
    scene
        .medium
        .as_ref()
        .map(|m| grin_field::build_field(m, scene_dir))
        .transpose()
        .with_context(|| format!("{label}: [medium]"))
}

/// `scene` (read from `scene_dir`; `label` names it in errors) ready to render: its
/// [`RenderScene`] on `field` (the medium's, from [`build_field`], or a bake of it),
/// with `step = { auto = ... }` resolved by [`resolve_auto`]. `on_gpu`: the GPU marcher
/// renders it (its pilots trace in f32), else the CPU tracer (f64).
pub fn prepare_scene(
    scene: &Scene,
    scene_dir: &Path,
    label: &str,
    field: Option<Arc<dyn IndexField>>,
    on_gpu: bool,
) -> anyhow::Result<Prepared> {
    let mut rs = RenderScene::new(scene, scene_dir, field).with_context(|| label.to_owned())?;
    let (auto, auto_note) = resolve_auto(&mut rs, scene, on_gpu);
    Ok(Prepared {
        render_scene: rs,
        auto,
        auto_note,
    })
}

/// Resolve `rs`'s `step = { auto = ... }` (from its own render settings, so a scene
/// re-aimed after an earlier choice starts afresh) by pilot rays in the backend's
/// precision (f32 for the GPU, but f64 for an OPD in waves), for an `[optics]` output of
/// `scene` to the accuracy it asks in its own unit: the choice, and why no pilots ran
/// where none could (a render too small for them). Nothing for other steps.
pub fn resolve_auto(
    rs: &mut RenderScene,
    scene: &Scene,
    on_gpu: bool,
) -> (Option<grin_trace::auto::AutoChoice>, Option<String>) {
    if let Some(m) = &mut rs.medium {
        m.trace = grin_render::settings::TraceSettings::from_render(&rs.settings);
    }
    if !matches!(rs.settings.step, grin_scene::StepSpec::Auto(_)) {
        return (None, None);
    }
    let metric = output_metric(scene, rs);
    // The GPU's pilots trace in f32 as it does, but for an OPD in waves: a CPU f32
    // trace holds n itself in f32 (1e-7 of ~1.0003: a fifth of a wave over a metre),
    // where the GPU sums n - n_amb, so its OPD is as good as f64's.
    let waves = matches!(metric, Some((grin_trace::auto::Metric::Waves { .. }, _)));
    // The shadowgraph's pilots are its beam's rays: resolved on a scene whose camera
    // is the beam's, then applied to this one.
    let beam_camera = match &metric {
        Some((grin_trace::auto::Metric::Screen(beam), _)) => Some(beam.camera()),
        _ => None,
    };
    let mut pilot_rs = beam_camera.map(|cam| {
        let mut p = rs.clone();
        p.camera = cam;
        (p.settings.width, p.settings.height) = (cam.width, cam.height);
        p
    });
    let target = pilot_rs.as_mut().unwrap_or(rs);
    let auto = if on_gpu && !waves {
        grin_trace::auto::resolve_scene_in::<f32>(target, metric)
    } else {
        grin_trace::auto::resolve_scene_in::<f64>(target, metric)
    };
    if let (Some(_), Some(a)) = (&pilot_rs, &auto) {
        grin_trace::auto::apply(rs, &a.settings);
    }
    let auto_note = grin_trace::auto::render_pilot_note(pilot_rs.as_ref().unwrap_or(rs));
    (auto, auto_note)
}

/// A scene ready for a backend to render: [`prepare_scene`]'s result.
#[derive(Debug, Clone)]
pub struct Prepared {
    /// The render description, with `auto`'s choice applied.
    pub render_scene: RenderScene,
    /// `step = { auto = ... }`: what the pilot rays chose (and every candidate tried).
    pub auto: Option<grin_trace::auto::AutoChoice>,
    /// `step = { auto = ... }` resolved without pilots (a render too small for them): why.
    pub auto_note: Option<String>,
}

/// Renders scenes on one backend, keeping the GPU device and its compiled pipelines from
/// one scene to the next (a sequence's frames, a dataset's samples).
#[derive(Debug)]
pub struct Renderer {
    backend: Backend,
    use_cache: bool,
    gpu: Mutex<Option<std::sync::Arc<grin_gpu::GpuContext>>>,
    /// What `Backend::Auto` chose, and why (made on first use).
    chosen: std::sync::OnceLock<(Backend, Option<String>)>,
    /// Read every channel of a GPU frame back, whatever the output is made of
    /// ([`Renderer::reading_every_channel`]).
    every_channel: bool,
    /// The AOVs a beauty output writes beside R, G, B ([`Renderer::with_aovs`]).
    aovs: Channels,
}

impl Renderer {
    /// A renderer on `backend`; `use_cache`: read and fill the user's bake cache and the
    /// driver's pipeline cache beside it.
    pub fn new(backend: Backend, use_cache: bool) -> Self {
        Self {
            backend,
            use_cache,
            gpu: Mutex::new(None),
            chosen: std::sync::OnceLock::new(),
            every_channel: false,
            aovs: Channels::ALL,
        }
    }

    /// Write only `aovs` ([`parse_aovs`]) beside R, G, B in a beauty output (one without
    /// `[optics]`; default every AOV). On the GPU only those channels are read back.
    pub fn with_aovs(mut self, aovs: Channels) -> Self {
        self.aovs = aovs;
        self
    }

    /// Keep every channel of [`Rendered::frame`] on the GPU backend too (for a caller
    /// that wants more of an `[optics]` render's pixels than its output): by default a
    /// GPU frame reads back only the channels its output is made of ([`output_channels`]).
    pub fn reading_every_channel(mut self) -> Self {
        self.every_channel = true;
        self
    }

    /// The backend asked for (`Auto` stays `Auto`: [`Renderer::chosen`] says what runs).
    pub fn backend(&self) -> Backend {
        self.backend
    }

    /// The backend that renders (`Gpu` or `Cpu`) and, for `Auto`, why: the GPU marcher
    /// where wgpu's adapter is a GPU, else the CPU tracer (a CPU adapter, or none).
    pub fn chosen(&self) -> (Backend, Option<String>) {
        self.chosen
            .get_or_init(|| match self.backend {
                Backend::Auto => match self.gpu() {
                    Ok(ctx) if !ctx.is_cpu_adapter() => (
                        Backend::Gpu,
                        Some(format!("backend auto: gpu ({})", ctx.adapter_name())),
                    ),
                    Ok(ctx) => {
                        // The CPU renders: the device is not kept.
                        *self.gpu.lock().unwrap_or_else(|e| e.into_inner()) = None;
                        (
                            Backend::Cpu,
                            Some(format!(
                                "backend auto: cpu: wgpu's only adapter is a CPU one ({}), where \
                             the CPU tracer is faster than the GPU marcher (--backend gpu \
                             runs the marcher there anyway)",
                                ctx.adapter_name()
                            )),
                        )
                    }
                    Err(e) => (
                        Backend::Cpu,
                        Some(format!(
                            "backend auto: cpu: wgpu finds no GPU adapter ({})",
                            first_line(&e)
                        )),
                    ),
                },
                b => (b, None),
            })
            .clone()
    }

    fn bake_cache(&self) -> Option<grin_gpu::cache::BakeCache> {
        self.use_cache
            .then(grin_gpu::cache::BakeCache::user_default)
            .flatten()
    }

    /// The GPU device, made on first use.
    fn gpu(&self) -> anyhow::Result<std::sync::Arc<grin_gpu::GpuContext>> {
        let mut slot = self.gpu.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(ctx) = slot.as_ref() {
            return Ok(ctx.clone());
        }
        let dir = self.bake_cache().map(|c| c.pipeline_dir());
        let ctx = std::sync::Arc::new(grin_gpu::GpuContext::new_headless_in(dir.as_deref())?);
        *slot = Some(ctx.clone());
        Ok(ctx)
    }

    /// `scene` (read from `scene_dir`; `label` names it in errors) as this renderer's
    /// backend renders it: [`prepare_scene`] with pilots in the backend's precision.
    pub fn prepare(
        &self,
        scene: &Scene,
        scene_dir: &Path,
        label: &str,
        field: Option<Arc<dyn IndexField>>,
    ) -> anyhow::Result<Prepared> {
        let on_gpu = self.chosen().0 == Backend::Gpu;
        prepare_scene(scene, scene_dir, label, field, on_gpu)
    }

    /// Render `scene` (read from `scene_dir`; `label` names it in errors, usually its
    /// file): its `[optics]` output when it has one, else its beauty and AOVs.
    pub fn render(
        &self,
        scene: Scene,
        scene_dir: &Path,
        label: &str,
        progress: &dyn Progress,
    ) -> anyhow::Result<Rendered> {
        self.render_aovs(scene, scene_dir, label, progress, self.aovs)
    }

    /// [`Renderer::render`] of a beauty image alone (R, G, B: no AOV read back or
    /// written), whatever AOVs the renderer writes otherwise.
    pub fn render_beauty(
        &self,
        scene: Scene,
        scene_dir: &Path,
        label: &str,
        progress: &dyn Progress,
    ) -> anyhow::Result<Rendered> {
        self.render_aovs(scene, scene_dir, label, progress, Channels::NONE)
    }

    fn render_aovs(
        &self,
        mut scene: Scene,
        scene_dir: &Path,
        label: &str,
        progress: &dyn Progress,
        aovs: Channels,
    ) -> anyhow::Result<Rendered> {
        let field = build_field(&scene, scene_dir, label)?;
        // BOS images through the camera's lens or anti-aliased: rendered as beauty images
        // of the dots on the plane, with and without the medium, at the scene's spp.
        let bos_scene = bos_image_scene(&scene)?;
        if scene.optics.is_some() {
            scene.render.spp = 1;
            scene.render.jitter = false;
        }
        let Prepared {
            render_scene: rs,
            auto,
            auto_note,
        } = self.prepare(&scene, scene_dir, label, field.clone())?;
        let (backend, backend_note) = self.chosen();
        let mut warnings = Warnings::new(progress);
        for w in field.iter().flat_map(|f| f.warnings()) {
            warnings.push(w);
        }
        if let Some(w) = auto.as_ref().and_then(|a| a.unmet_warning("rendering")) {
            warnings.push(w);
        }
        let bos_scenes = match &bos_scene {
            Some(s) => {
                let mut with = RenderScene::new(s, scene_dir, field.clone())
                    .with_context(|| label.to_owned())?;
                if let Some(a) = &auto {
                    grin_trace::auto::apply(&mut with, &a.settings);
                }
                let mut bare = s.clone();
                bare.medium = None;
                let without =
                    RenderScene::new(&bare, scene_dir, None).with_context(|| label.to_owned())?;
                Some((with, without))
            }
            None => None,
        };
        let job = Job {
            scene: &scene,
            scene_dir,
            label,
            progress,
        };

        if let Some(spec) = scene
            .optics
            .as_ref()
            .filter(|o| o.mode == OpticsMode::Shadowgraph)
        {
            let start = Instant::now();
            let (image, optics, frame_report) = self.shadowgraph(&job, &rs, spec, &mut warnings)?;
            let seconds = start.elapsed().as_secs_f64();
            let rays = optics["rays_launched"].as_f64().unwrap_or(0.0);
            let report = Report {
                backend: backend.name(),
                backend_note,
                adapter: frame_report.adapter,
                width: scene.render.width,
                height: scene.render.height,
                spp: 1,
                seconds,
                setup_seconds: 0.0,
                device_seconds: None,
                rays_per_second: rays / seconds.max(1e-9),
                steps_per_ray: 0.0,
                evals_per_ray: 0.0,
                status_counts: std::collections::BTreeMap::new(),
                warnings: warnings.list,
                bake_cache: frame_report.bake_cache,
                gpu_field: frame_report.gpu_field,
                read_back_bytes: frame_report.read_back_bytes,
                optics: Some(optics),
                auto,
                auto_note,
            };
            return Ok(Rendered {
                image,
                frame: None,
                camera: rs.camera,
                field,
                report,
            });
        }

        let passes = if bos_scenes.is_some() { 3 } else { 1 };
        progress.begin(u64::from(scene.render.height) * passes);
        let setup_start = Instant::now();
        let channels = match &scene.optics {
            Some(o) => output_channels(Some(o.mode)),
            None => Channels::RGB.and(aovs),
        };
        let (mut frame, fr) =
            self.frame(&job, &rs, scene.medium.as_ref(), channels, &mut warnings)?;
        let mut read_back_bytes = fr.read_back_bytes;
        let bos_images = match &bos_scenes {
            Some((with, without)) => {
                let mut quiet = Warnings::new(progress);
                let red = Channels::RED;
                let (distorted, d) =
                    self.frame(&job, with, scene.medium.as_ref(), red, &mut quiet)?;
                let (reference, r) = self.frame(&job, without, None, red, &mut quiet)?;
                for bytes in [d.read_back_bytes, r.read_back_bytes] {
                    read_back_bytes = read_back_bytes.zip(bytes).map(|(a, b)| a + b);
                }
                let red = |f: &Frame| f.pixels.iter().map(|p| f64::from(p.rgb[0])).collect();
                Some((red(&reference), red(&distorted)))
            }
            None => None,
        };
        let setup_seconds = setup_start.elapsed().as_secs_f64() - fr.seconds;
        progress.finish();
        if let Some(sensor) = &scene.sensor {
            match scene.optics.as_ref().map(|o| o.mode) {
                None => grin_render::sensor::record_frame(sensor, &mut frame),
                Some(OpticsMode::Bos | OpticsMode::Interferogram) => {}
                Some(mode) => warnings.push(format!(
                    "[sensor] records the beauty, BOS and interferogram images; the {} \
                     output is written without sensor noise",
                    optics::mode_name(mode)
                )),
            }
        }
        if scene.optics.is_some() && scene.camera.f_number.is_some() && bos_images.is_none() {
            warnings.push(
                "[optics] outputs trace one pinhole ray per pixel centre: camera.f_number \
                 (defocus) is not applied to them"
                    .to_owned(),
            );
        }
        let (image, optics_summary) = match &scene.optics {
            Some(spec) => {
                let (image, summary) =
                    optics::from_frame(spec, scene.sensor.as_ref(), bos_images, &rs, &frame)?;
                (image, Some(summary))
            }
            None => {
                let mut image = Image::new(frame.width, frame.height);
                image.channels = frame
                    .channels()?
                    .into_iter()
                    .filter(|(n, _)| aov_written(aovs, n))
                    .map(|(n, d)| (n.to_owned(), d))
                    .collect();
                image.previews.push(Preview {
                    suffix: None,
                    rgb8: frame.preview_rgb8(),
                });
                (image, None)
            }
        };

        let n_pixels = f64::from(frame.width) * f64::from(frame.height);
        let rays = n_pixels * f64::from(scene.render.spp);
        let mean = |f: fn(&grin_render::image::PixelOut) -> f32| {
            frame.pixels.iter().map(|p| f64::from(f(p))).sum::<f64>() / n_pixels.max(1.0)
        };
        // Counted on the device where the frame holds only the output's channels.
        let (steps_per_ray, evals_per_ray, status_counts) = match &fr.totals {
            Some(t) => (
                t.steps as f64 / rays.max(1.0),
                t.evals as f64 / rays.max(1.0),
                status_counts(&t.status),
            ),
            None => (
                mean(|p| p.steps),
                mean(|p| p.evals),
                status_counts(&FrameTotals::of(&frame, 1).status),
            ),
        };
        let stuck = status_counts["max_steps"] + status_counts["error"];
        if stuck > 0 {
            warnings.push(format!(
                "{stuck} pixels stopped in the medium (max_steps {}, error {}): see the aov.status channel",
                status_counts["max_steps"], status_counts["error"]
            ));
        }
        let degraded = status_counts["degraded"];
        if degraded > 0 {
            warnings.push(format!(
                "{degraded} pixels left the medium `degraded`: their error estimate is above the {:.1e} rad they are held to (asked {:.1e}; aov.status 5): the integrator's own at these steps (shorter steps, or step = {{ auto = ... }} without an integrator, resolve it), or a baked field's n error amplified at a grazing crossing of the bounds (a finer or tricubic bake resolves it)",
                rs.settings.estimate_limit(),
                rs.settings.accuracy()
            ));
        }
        let report = Report {
            backend: backend.name(),
            backend_note,
            adapter: fr.adapter,
            width: frame.width,
            height: frame.height,
            spp: scene.render.spp,
            seconds: fr.seconds,
            setup_seconds,
            device_seconds: fr.device_seconds,
            rays_per_second: rays / fr.seconds.max(1e-9),
            steps_per_ray,
            evals_per_ray,
            status_counts,
            warnings: warnings.list,
            bake_cache: fr.bake_cache,
            gpu_field: fr.gpu_field,
            read_back_bytes,
            optics: optics_summary,
            auto,
            auto_note,
        };
        Ok(Rendered {
            frame: Some(frame),
            camera: rs.camera,
            field,
            image,
            report,
        })
    }

    /// The shadowgraph of `spec`: its beam traced on the CPU, or as one GPU frame whose
    /// exit AOVs are binned on the screen.
    fn shadowgraph(
        &self,
        job: &Job,
        rs: &RenderScene,
        spec: &grin_scene::OpticsSpec,
        warnings: &mut Warnings,
    ) -> anyhow::Result<(Image, serde_json::Value, FrameReport)> {
        let medium = rs
            .medium
            .as_ref()
            .with_context(|| format!("{}: [optics] a shadowgraph needs a [medium]", job.label))?;
        let (sg, report) = match self.chosen().0 {
            Backend::Auto | Backend::Cpu => {
                let sg = grin_trace::shadowgraph::shadowgraph(
                    medium.field.as_ref(),
                    &medium.trace,
                    &rs.camera,
                    &spec.screen,
                );
                let report = FrameReport {
                    adapter: cpu_adapter(),
                    ..FrameReport::default()
                };
                (sg, report)
            }
            Backend::Gpu => {
                // The beam's rays are an orthographic camera's pixel centres.
                let beam =
                    grin_trace::shadowgraph::Beam::new(&medium.bounds, &rs.camera, &spec.screen);
                let mut beam_rs = rs.clone();
                beam_rs.camera = beam.camera();
                beam_rs.settings.width = beam_rs.camera.width;
                beam_rs.settings.height = beam_rs.camera.height;
                beam_rs.objects.clear();
                beam_rs.materials.clear();
                beam_rs.object_images.clear();
                let pixels = u64::from(beam_rs.camera.width) * u64::from(beam_rs.camera.height);
                if pixels > grin_render::scene::MAX_PIXELS {
                    anyhow::bail!(
                        "{}: [optics] the shadowgraph's beam is {pixels} rays (bins x \
                         rays_per_pixel); at most {} fit one GPU frame: fewer bins or \
                         rays_per_pixel",
                        job.label,
                        grin_render::scene::MAX_PIXELS
                    );
                }
                job.progress.begin(u64::from(beam_rs.settings.height));
                let channels = output_channels(Some(OpticsMode::Shadowgraph));
                let (frame, report) =
                    self.frame(job, &beam_rs, job.scene.medium.as_ref(), channels, warnings)?;
                job.progress.finish();
                let v = |a: [f32; 3]| glam::DVec3::from_array(a.map(f64::from));
                // status 0 missed (exit_pos = the ray's start), 1 exited, 5 degraded;
                // else stopped.
                let ends = frame.pixels.iter().map(|p| {
                    (p.status <= 1.0 || p.status == 5.0)
                        .then(|| (v(p.exit_pos), v(p.exit_dir).normalize()))
                });
                (beam.collect(ends), report)
            }
        };
        let (image, summary) = optics::from_shadowgraph(&sg);
        Ok((image, summary, report))
    }

    /// One frame of `rs` on this renderer's backend, and what the report says of it;
    /// warnings are pushed as they arise. The GPU reads back `channels` of it (the
    /// others NaN; every channel where the renderer [reads every
    /// channel](Renderer::reading_every_channel)).
    fn frame(
        &self,
        job: &Job,
        rs: &RenderScene,
        medium: Option<&grin_scene::MediumSpec>,
        channels: Channels,
        warnings: &mut Warnings,
    ) -> anyhow::Result<(Frame, FrameReport)> {
        let cancel = AtomicBool::new(false);
        let tick = |rows: u32| job.progress.advance(rows);
        match self.chosen().0 {
            Backend::Auto | Backend::Cpu => {
                let start = Instant::now();
                let frame = grin_trace::render::render_cpu(rs, &tick, &cancel)?;
                let report = FrameReport {
                    adapter: cpu_adapter(),
                    seconds: start.elapsed().as_secs_f64(),
                    ..FrameReport::default()
                };
                Ok((frame, report))
            }
            Backend::Gpu => {
                let ctx = self.gpu()?;
                if let Some(w) = cpu_adapter_warning(&ctx)
                    && !warnings.list.contains(&w)
                {
                    // Told once a process (a sequence renders many frames on one device).
                    static TOLD: std::sync::Once = std::sync::Once::new();
                    TOLD.call_once(|| job.progress.warn(&w));
                    warnings.list.push(w);
                }
                let cache = self.bake_cache();
                let field = match (&rs.medium, medium) {
                    (Some(m), Some(spec)) => grin_gpu::cache::medium_gpu_grid(
                        m.field.as_ref(),
                        spec,
                        job.scene_dir,
                        cache.as_ref(),
                    )
                    .with_context(|| format!("{}: [medium]", job.label))?,
                    _ => None,
                };
                let renderer =
                    grin_gpu::GpuRenderer::new_with(&ctx, rs, field.as_ref().map(|f| f.0.device()))
                        .with_context(|| job.label.to_owned())?;
                let mut report = FrameReport::default();
                if let Some((_, field_warnings, used)) = &field {
                    report.bake_cache = Some(*used);
                    for w in field_warnings {
                        warnings.push(w.clone());
                    }
                }
                for w in renderer.warnings() {
                    warnings.push(w.clone());
                }
                if medium.is_some() {
                    report.gpu_field = Some(GpuField {
                        dims: renderer.field_dims(),
                        bytes: renderer.field_bytes(),
                    });
                }
                report.adapter = renderer.adapter_info();
                let start = Instant::now();
                let channels = if self.every_channel {
                    Channels::ALL
                } else {
                    channels
                };
                let (frame, totals) = renderer.render_channels(channels, &tick, &cancel)?;
                report.device_seconds = renderer.last_device_seconds();
                if let Some(w) = renderer.loop_limit_warning_of(totals.loop_limit_suspects) {
                    warnings.push(w);
                }
                report.totals = (channels != Channels::ALL).then_some(totals);
                report.read_back_bytes = Some(renderer.bytes_read_back());
                report.seconds = start.elapsed().as_secs_f64();
                Ok((frame, report))
            }
        }
    }
}

/// What one render call works on.
struct Job<'a> {
    scene: &'a Scene,
    scene_dir: &'a Path,
    label: &'a str,
    progress: &'a dyn Progress,
}

/// What the report says of one frame.
#[derive(Default)]
struct FrameReport {
    adapter: String,
    seconds: f64,
    device_seconds: Option<f64>,
    gpu_field: Option<GpuField>,
    bake_cache: Option<grin_gpu::cache::CacheUse>,
    /// The frame's counts from the device, where it read back only some channels.
    totals: Option<FrameTotals>,
    /// Bytes the frame read back from the device (GPU).
    read_back_bytes: Option<u64>,
}

fn cpu_adapter() -> String {
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    format!("cpu ({threads} threads)")
}

/// The GPU backend on a CPU adapter (lavapipe where a machine has no GPU): the marcher is
/// built for GPUs (short dispatches of many threads), and the CPU tracer renders the same
/// frame on the same cores faster; say so.
fn cpu_adapter_warning(ctx: &grin_gpu::GpuContext) -> Option<String> {
    ctx.is_cpu_adapter().then(|| {
        format!(
            "the GPU backend runs on a CPU adapter ({}): wgpu finds no GPU on this machine, \
             and `--backend cpu` is usually faster without one (docs/render.md)",
            ctx.adapter_name()
        )
    })
}

/// The accuracy an `[optics]` output asks in its own unit (`[optics] accuracy`: pixels of
/// landing point, waves of OPD, a fraction of the knife's range), as the pilots' metric.
fn output_metric(scene: &Scene, rs: &RenderScene) -> Option<(grin_trace::auto::Metric, f64)> {
    let o = scene.optics.as_ref()?;
    let asked = o.output_accuracy()?;
    let metric = match o.accuracy_unit() {
        // The shadowgraph's pixels are its screen's bins, its rays the beam's.
        grin_scene::AccuracyUnit::Pixels if o.mode == OpticsMode::Shadowgraph => {
            let medium = rs.medium.as_ref()?;
            grin_trace::auto::Metric::Screen(Box::new(grin_trace::shadowgraph::Beam::new(
                &medium.bounds,
                &rs.camera,
                &o.screen,
            )))
        }
        grin_scene::AccuracyUnit::Pixels => grin_trace::auto::Metric::Pixels {
            cam: Box::new(rs.camera),
            plane: o
                .plane
                .as_ref()
                .and_then(|p| grin_render::optics::Plane::new(p, &rs.camera)),
        },
        grin_scene::AccuracyUnit::Waves => grin_trace::auto::Metric::Waves {
            wavelength: o.wavelength_nm * 1e-9,
        },
        // Schlieren: the exit direction, to a fraction of the knife's range.
        grin_scene::AccuracyUnit::Radians => grin_trace::auto::Metric::Direction,
    };
    Some((metric, asked))
}

/// The scene whose beauty renders are the BOS images when they need more than the pixel
/// centre's pinhole ray (a lens, or spp > 1): the dots as an emissive plane object (white
/// on black, the `[optics]` dots and plane), at the scene's spp; `None` otherwise.
fn bos_image_scene(scene: &Scene) -> anyhow::Result<Option<Scene>> {
    let Some(spec) = scene.optics.as_ref().filter(|o| o.mode == OpticsMode::Bos) else {
        return Ok(None);
    };
    if scene.render.spp <= 1 && scene.camera.f_number.is_none() {
        return Ok(None);
    }
    let plane = spec
        .plane
        .context("[optics] BOS needs a plane for its dots")?;
    let len = plane.normal.iter().map(|c| c * c).sum::<f64>().sqrt();
    let mut s = scene.clone();
    s.optics = None;
    s.objects.push(grin_scene::Object {
        shape: grin_scene::Shape::Plane {
            point: plane.point,
            normal: plane.normal.map(|c| c / len),
        },
        material: grin_scene::Material::Dots {
            diameter: spec.dots.diameter,
            density: spec.dots.density,
            seed: spec.dots.seed,
            color: [1.0; 3],
            background: [0.0; 3],
            center: Some(plane.point),
            emissive: true,
        },
    });
    Ok(Some(s))
}

/// The channels of a GPU frame an output is made of (`mode`: its `[optics]` mode, none
/// for the beauty and AOVs, every channel): the exit position and direction and the
/// status where rays are followed past the medium (displacement, BOS, schlieren, the
/// shadowgraph's beam), the optical path to the plane for an interferogram.
pub fn output_channels(mode: Option<OpticsMode>) -> Channels {
    match mode {
        None => Channels::ALL,
        Some(OpticsMode::Interferogram) => Channels::OPD_PLANE,
        Some(
            OpticsMode::Displacement
            | OpticsMode::Bos
            | OpticsMode::Schlieren
            | OpticsMode::Shadowgraph,
        ) => Channels::EXIT_DIR
            .and(Channels::EXIT_POS)
            .and(Channels::STATUS),
    }
}

/// The AOVs a beauty output may write (`--aovs`): each name, its channels in the frame,
/// and the EXR channels it writes.
pub const AOVS: [(&str, Channels, &[&str]); 8] = [
    ("deflection", Channels::DEFLECTION, &["aov.deflection_deg"]),
    (
        "exit_dir",
        Channels::EXIT_DIR,
        &["aov.exit_dir.X", "aov.exit_dir.Y", "aov.exit_dir.Z"],
    ),
    ("opd", Channels::OPD, &["aov.opd"]),
    ("steps", Channels::STEPS, &["aov.steps"]),
    ("evals", Channels::EVALS, &["aov.evals"]),
    ("status", Channels::STATUS, &["aov.status"]),
    (
        "exit_pos",
        Channels::EXIT_POS,
        &["aov.exit_pos.X", "aov.exit_pos.Y", "aov.exit_pos.Z"],
    ),
    ("opd_plane", Channels::OPD_PLANE, &["aov.opd_plane"]),
];

/// `--aovs`: `all`, `none`, or names of [`AOVS`] separated by commas.
pub fn parse_aovs(list: &str) -> Result<Channels, String> {
    let mut aovs = Channels::NONE;
    match list.trim() {
        "all" => return Ok(Channels::ALL),
        "none" => return Ok(aovs),
        _ => {}
    }
    for name in list.split(',').map(str::trim) {
        let (_, channels, _) = AOVS.iter().find(|(n, ..)| *n == name).ok_or_else(|| {
            let names: Vec<&str> = AOVS.iter().map(|(n, ..)| *n).collect();
            format!(
                "unknown AOV `{name}`: the AOVs are {}, or `all` or `none`",
                names.join(", ")
            )
        })?;
        aovs = aovs.and(*channels);
    }
    Ok(aovs)
}

/// Whether a beauty output with `aovs` writes the EXR channel `name` (R, G and B always).
fn aov_written(aovs: Channels, name: &str) -> bool {
    matches!(name, "R" | "G" | "B")
        || AOVS
            .iter()
            .any(|(_, c, names)| aovs.contains(*c) && names.contains(&name))
}

/// Pixels per `aov.status` value, by name, from their counts by value
/// ([`FrameTotals::status`]: the device's, or [`FrameTotals::of`] a frame).
fn status_counts(counts: &[u64; 8]) -> std::collections::BTreeMap<&'static str, usize> {
    grin_trace::RayStatus::ALL
        .iter()
        .enumerate()
        .map(|(i, s)| (s.name(), counts[i] as usize))
        .collect()
}

/// An error's first line (wgpu's adapter errors run on with advice for the GPU backend).
fn first_line(e: &anyhow::Error) -> String {
    e.to_string().lines().next().unwrap_or_default().to_owned()
}
