//! The window: winit + a wgpu surface + egui, on the device the render thread renders
//! with. The render thread's image is a texture on that device, drawn by egui beside the
//! panel (no pixel crosses to the CPU); mouse and keys move the orbit camera; the scene
//! file is watched and reloaded. With `--frames N` the same window runs N rendered frames, writes
//! the last one and reports frame rates (Xvfb in CI); `--offscreen` runs them without a
//! window.
//!
//! The panel and the camera's input are in [`panel`].
//!
//! Over 600 lines: one concept, the window's frame loop (requests to the render thread,
//! its replies, drawing), in the window and offscreen.

use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime};

use grin_gpu::GpuContext;
use grin_gpu::cache::BakeCache;
use grin_gpu::view::DisplayTexture;
use winit::application::ApplicationHandler;
use winit::dpi::PhysicalSize;
use winit::event::WindowEvent;
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop};
use winit::window::{Window, WindowId};

use crate::settings::ViewSettings;
use crate::worker::{FrameReply, Reply, Request, Worker};
use crate::{ViewOptions, ViewSummary};

mod layer;
mod panel;

/// Width of the panel (points).
const PANEL_WIDTH: f32 = 300.0;
/// How often the scene file's modification time is checked.
const WATCH_PERIOD: Duration = Duration::from_millis(250);
/// The camera counts as moving this long after its last change.
const MOVING_FOR: Duration = Duration::from_millis(150);
/// Shortest time between two window redraws on a CPU adapter: on lavapipe the window's
/// own drawing runs on the cores that render, so it redraws only for a new frame, input or
/// playing time, at most this often. A GPU redraws for each new frame.
const MIN_REDRAW: Duration = Duration::from_millis(16);

/// How long a headless run waits for its screenshot's pixels.
const CAPTURE_TIMEOUT: Duration = Duration::from_secs(120);

struct Gfx {
    window: Arc<Window>,
    surface: wgpu::Surface<'static>,
    device: wgpu::Device,
    queue: wgpu::Queue,
    config: wgpu::SurfaceConfiguration,
    egui: egui_winit::State,
    renderer: egui_wgpu::Renderer,
    /// On a CPU adapter whose surface takes copies: the panel kept in a texture
    /// ([`layer`]), made on the first frame.
    layered: bool,
    layer: Option<layer::UiLayer>,
}

/// Statistics of the frames shown.
#[derive(Debug, Default)]
struct Stats {
    /// Wall-clock instants at which new rendered frames were shown.
    shown: Vec<Instant>,
    wall_ms: Vec<f64>,
    device_ms: Vec<f64>,
    read_back_bytes: Vec<f64>,
    ui_frames: u64,
    ui_start: Option<Instant>,
    rays_per_second: Vec<f64>,
}

pub(crate) struct App {
    opts: ViewOptions,
    /// The render thread, started with the window (it renders on the window's device).
    worker: Option<Worker>,
    cache: Option<BakeCache>,
    gfx: Option<Gfx>,
    start: Instant,
    pub(crate) fatal: Option<String>,
    adapter: Option<String>,
    display_adapter: String,
    setup_seconds: Option<f64>,
    device_seconds: Option<f64>,
    first_frame_seconds: Option<f64>,
    first_full_frame_seconds: Option<f64>,
    settings: ViewSettings,
    /// The scene file's own settings (to rebase the user's edits on reload).
    file_settings: ViewSettings,
    animated: bool,
    /// The scene's [animation] when its medium is a file sequence.
    animation: Option<grin_scene::Animation>,
    last_sent: Option<(ViewSettings, u32, u32, bool)>,
    last_move: Option<Instant>,
    frame: Option<Box<FrameReply>>,
    /// The texture on screen, as egui knows it, and its generation.
    texture: Option<(egui::TextureId, u64)>,
    /// The render thread's texture to show (replaced by each frame and AOV switch).
    display: Option<DisplayTexture>,
    /// The frame last counted as shown.
    shown_frame: u32,
    aov_scale: f32,
    frame_error: Option<String>,
    reload_error: Option<String>,
    watched: Option<SystemTime>,
    last_watch: Instant,
    last_tick: Instant,
    stats: Stats,
    converged_after: Option<f64>,
    still_since: Instant,
    pub(crate) summary: Option<ViewSummary>,
    frames_seen: u32,
    image_px: (u32, u32),
    /// Headless with a screenshot after an orbit: the orbit's frames were previews at the
    /// moving resolution, so one more, still, at the size asked for, is the screenshot's.
    final_still: bool,
    /// Something to show: a reply from the render thread, input, an egui animation.
    dirty: bool,
    /// The run is over (closed, done, or a fatal error).
    exit: bool,
    /// The device is a CPU adapter (lavapipe).
    cpu_adapter: bool,
    /// Wakes the event loop when the render thread replies.
    proxy: Option<winit::event_loop::EventLoopProxy<()>>,
    last_redraw: Instant,
}

fn mtime(p: &std::path::Path) -> Option<SystemTime> {
    std::fs::metadata(p).and_then(|m| m.modified()).ok()
}

impl App {
    pub(crate) fn new(
        opts: ViewOptions,
        scene: &grin_scene::Scene,
        cache: Option<BakeCache>,
    ) -> Self {
        let mut settings = ViewSettings::from_scene(scene);
        if let Some(spp) = opts.spp {
            settings.spp = spp.max(1);
        }
        settings.max_spp = match (opts.max_spp, opts.frames) {
            (Some(m), _) => m.max(settings.spp),
            // A headless still: exactly the frames asked for.
            (None, Some(n)) if opts.orbit_deg == 0.0 => n.max(1) * settings.spp,
            _ => settings.max_spp.max(settings.spp),
        };
        let image_px = opts
            .size
            .unwrap_or((scene.render.width, scene.render.height));
        App {
            worker: None,
            cache,
            gfx: None,
            start: Instant::now(),
            fatal: None,
            adapter: None,
            display_adapter: String::new(),
            setup_seconds: None,
            device_seconds: None,
            first_frame_seconds: None,
            first_full_frame_seconds: None,
            file_settings: ViewSettings::from_scene(scene),
            animated: ViewSettings::animated(scene),
            animation: scene.animation.filter(|_| scene.is_sequence()),
            settings,
            last_sent: None,
            last_move: None,
            frame: None,
            texture: None,
            display: None,
            shown_frame: 0,
            aov_scale: 1.0,
            frame_error: None,
            reload_error: None,
            watched: mtime(&opts.scene),
            last_watch: Instant::now(),
            last_tick: Instant::now(),
            stats: Stats::default(),
            converged_after: None,
            still_since: Instant::now(),
            summary: None,
            frames_seen: 0,
            image_px,
            final_still: false,
            dirty: true,
            exit: false,
            cpu_adapter: false,
            proxy: None,
            last_redraw: Instant::now(),
            opts,
        }
    }

    fn headless(&self) -> bool {
        self.opts.frames.is_some()
    }

    fn create_gfx(&mut self, el: &ActiveEventLoop) -> Result<Gfx, String> {
        let (w, h) = self.image_px;
        let size = if self.headless() || self.opts.size.is_some() {
            PhysicalSize::new(w + PANEL_WIDTH as u32 + 16, h.max(480) + 16)
        } else {
            PhysicalSize::new(w.max(480) + PANEL_WIDTH as u32, h.max(480))
        };
        let title = format!("grin view — {}", self.opts.scene.display());
        let window = Arc::new(
            el.create_window(
                Window::default_attributes()
                    .with_title(title)
                    .with_inner_size(size),
            )
            .map_err(|e| format!("cannot open a window: {e}"))?,
        );
        let surface = grin_gpu::device::instance()
            .create_surface(window.clone())
            .map_err(|e| format!("cannot draw into the window: {e}"))?;
        // One device for the window and the renderer: frames stay in GPU memory. The
        // driver's pipeline cache sits beside the bake cache (and is off with it).
        let started = Instant::now();
        let pipeline_dir = self.cache.as_ref().map(BakeCache::pipeline_dir);
        let ctx = GpuContext::new_for_surface(&surface, pipeline_dir.as_deref())
            .map_err(|e| format!("no GPU device for the viewer: {e}"))?;
        self.device_seconds = Some(started.elapsed().as_secs_f64());
        let gpu = Arc::new(ctx);
        self.display_adapter = gpu.adapter_name();
        let (device, queue) = (gpu.device.clone(), gpu.queue.clone());
        let caps = surface.get_capabilities(&gpu.adapter);
        let format = egui_wgpu::preferred_framebuffer_format(&caps.formats)
            .map_err(|e| format!("the window's surface: {e}"))?;
        let inner = window.inner_size();
        // On a CPU adapter the panel is drawn once and copied into each frame.
        let layered = gpu.is_cpu_adapter() && caps.usages.contains(wgpu::TextureUsages::COPY_DST);
        let mut usage = wgpu::TextureUsages::RENDER_ATTACHMENT;
        if layered {
            usage |= wgpu::TextureUsages::COPY_DST;
        }
        let config = wgpu::SurfaceConfiguration {
            usage,
            format,
            color_space: wgpu::SurfaceColorSpace::Auto,
            width: inner.width.max(1),
            height: inner.height.max(1),
            present_mode: wgpu::PresentMode::AutoNoVsync,
            desired_maximum_frame_latency: 2,
            alpha_mode: caps.alpha_modes.first().copied().unwrap_or_default(),
            view_formats: vec![],
        };
        surface.configure(&device, &config);
        let ctx = egui::Context::default();
        let egui = egui_winit::State::new(
            ctx,
            egui::ViewportId::ROOT,
            &*window,
            Some(window.scale_factor() as f32),
            window.theme(),
            Some(device.limits().max_texture_dimension_2d as usize),
        );
        // On a CPU adapter every fragment of the window is the render thread's time (one
        // queue): no dithering there.
        let options = egui_wgpu::RendererOptions {
            dithering: !gpu.is_cpu_adapter(),
            ..Default::default()
        };
        let renderer = egui_wgpu::Renderer::new(&device, format, options);
        self.cpu_adapter = gpu.is_cpu_adapter();
        let wake = self.proxy.take().map(|p| {
            Box::new(move || {
                let _ = p.send_event(());
            }) as Box<dyn Fn() + Send>
        });
        self.worker = Some(Worker::start(
            gpu,
            self.opts.scene.clone(),
            self.cache.take(),
            wake,
        ));
        Ok(Gfx {
            window,
            surface,
            device,
            queue,
            config,
            egui,
            renderer,
            layered,
            layer: None,
        })
    }

    /// Take the render thread's replies, waiting up to `wait` for the first.
    fn poll_worker(&mut self, wait: Duration) {
        let mut first = self
            .worker
            .as_ref()
            .and_then(|w| w.replies.recv_timeout(wait).ok());
        while let Some(reply) = first
            .take()
            .or_else(|| self.worker.as_ref().and_then(|w| w.replies.try_recv().ok()))
        {
            self.dirty = true;
            match reply {
                Reply::Started {
                    adapter,
                    setup_seconds,
                } => {
                    self.adapter = Some(adapter);
                    self.setup_seconds = Some(setup_seconds);
                }
                Reply::Shown {
                    aov,
                    display,
                    scale,
                } => {
                    if aov == self.settings.aov {
                        self.display = Some(display);
                        self.aov_scale = scale;
                    }
                }
                Reply::Fatal(e) => {
                    self.fatal = Some(e);
                    self.exit = true;
                }
                Reply::Error(e) => {
                    self.frame_error = Some(e.clone());
                    if self.headless() {
                        self.fatal = Some(e);
                        self.exit = true;
                    }
                }
                Reply::Reloaded(Ok(new_file)) => {
                    eprintln!(
                        "grin view: reloaded {} (frame {})",
                        self.opts.scene.display(),
                        self.frames_seen
                    );
                    self.settings.rebase(&self.file_settings, &new_file);
                    self.file_settings = new_file;
                    self.reload_error = None;
                    self.last_sent = None;
                }
                Reply::Reloaded(Err(e)) => {
                    eprintln!(
                        "grin view: {} not reloaded, the last good scene stays (frame {}): {e}",
                        self.opts.scene.display(),
                        self.frames_seen
                    );
                    self.reload_error = Some(e);
                    self.last_sent = None;
                }
                Reply::Frame(f) => {
                    let now = Instant::now();
                    if self.first_frame_seconds.is_none() {
                        let t = self.start.elapsed().as_secs_f64();
                        self.first_frame_seconds = Some(t);
                        eprintln!("grin view: first frame after {t:.2} s");
                    }
                    self.display = Some(f.rendered.display.clone());
                    self.aov_scale = f.rendered.aov_scale;
                    if f.preview {
                        // A still view's preview: shown until its full frame comes, not
                        // one of the frames counted.
                        self.frame_error = None;
                        self.frame = Some(f);
                        continue;
                    }
                    if self.first_full_frame_seconds.is_none() {
                        self.first_full_frame_seconds = Some(self.start.elapsed().as_secs_f64());
                    }
                    self.stats.wall_ms.push(f.rendered.gpu_seconds * 1e3);
                    if let Some(d) = f.rendered.device_seconds {
                        self.stats.device_ms.push(d * 1e3);
                    }
                    self.stats
                        .read_back_bytes
                        .push(f.rendered.read_back_bytes as f64);
                    self.stats.rays_per_second.push(f.rendered.rays_per_second);
                    if f.rendered.converged && self.converged_after.is_none() {
                        self.converged_after = Some(self.still_since.elapsed().as_secs_f64());
                    }
                    self.frame_error = None;
                    self.frames_seen += 1;
                    self.frame = Some(f);
                    if let Some(n) = self.opts.frames {
                        let done = self.frames_seen >= n
                            || self.frame.as_ref().is_some_and(|f| f.rendered.converged);
                        // A screenshot is of the size asked for: after an orbit's preview
                        // frames, one more still frame at that size.
                        let preview = self.frame.as_ref().is_some_and(|f| {
                            (f.rendered.width, f.rendered.height) != self.image_px
                        });
                        if done && preview && self.opts.screenshot.is_some() && !self.final_still {
                            self.final_still = true;
                            self.last_move = None;
                            self.request_view(self.image_px);
                            return;
                        }
                        if done {
                            self.finish();
                            return;
                        }
                        if self.opts.orbit_deg != 0.0 {
                            self.settings.camera.orbit_degrees(self.opts.orbit_deg);
                            self.last_move = Some(now);
                            // The next view goes out now, so the render thread works
                            // while this frame is drawn (the headless size is fixed).
                            self.request_view(self.image_px);
                        }
                    }
                }
            }
        }
    }

    /// Headless end: the screenshot and the summary.
    fn finish(&mut self) {
        self.exit = true;
        let Some(f) = &self.frame else {
            self.fatal = Some("no frame was rendered".into());
            return;
        };
        if let Some(path) = &self.opts.screenshot {
            // The only pixels read back: the image shown, once, for the file.
            let written = self.capture().and_then(|frame| {
                crate::write_screenshot(path, &frame, f.settings.aov).map_err(|e| format!("{e:#}"))
            });
            if let Err(e) = written {
                self.fatal = Some(e);
                return;
            }
        }
        let intervals: Vec<f64> = self
            .stats
            .shown
            .windows(2)
            .map(|w| (w[1] - w[0]).as_secs_f64())
            .collect();
        let fps: Vec<f64> = intervals.iter().map(|s| 1.0 / s.max(1e-9)).collect();
        let ui_secs = self
            .stats
            .ui_start
            .map_or(0.0, |s| s.elapsed().as_secs_f64());
        self.summary = Some(ViewSummary {
            scene: self.opts.scene.clone(),
            adapter: self.adapter.clone().unwrap_or_default(),
            display_adapter: self.display_adapter.clone(),
            frames: self.frames_seen,
            width: self.image_px.0,
            height: self.image_px.1,
            last_internal: [f.rendered.width, f.rendered.height],
            orbit_deg_per_frame: self.opts.orbit_deg,
            fps: crate::MinMedMax::of(&fps),
            wall_ms: crate::MinMedMax::of(&self.stats.wall_ms),
            device_ms: (!self.stats.device_ms.is_empty())
                .then(|| crate::MinMedMax::of(&self.stats.device_ms)),
            read_back_bytes: crate::MinMedMax::of(&self.stats.read_back_bytes),
            rays_per_second: crate::MinMedMax::of(&self.stats.rays_per_second).median,
            ui_fps: self.stats.ui_frames as f64 / ui_secs.max(1e-9),
            setup_seconds: self.setup_seconds.unwrap_or(0.0),
            device_seconds: self.device_seconds.unwrap_or(0.0),
            first_frame_seconds: self.first_frame_seconds.unwrap_or(0.0),
            first_full_frame_seconds: self.first_full_frame_seconds.unwrap_or(0.0),
            samples: f.rendered.samples,
            converged: f.rendered.converged,
            converged_seconds: self.converged_after,
            steps_per_ray: f.rendered.steps_per_ray,
            evals_per_ray: f.rendered.evals_per_ray,
            method: f.rendered.method.clone(),
            bake_cache: f.cache,
            field_grid: f.field_grid.map(|g| g.0),
            warnings: f.warnings.clone(),
            screenshot: self.opts.screenshot.clone(),
        });
    }

    /// A request for the current settings at the image size.
    fn request(&self, moving: bool, reload: bool) -> Request {
        Request {
            settings: self.settings.clone(),
            width: self.image_px.0,
            height: self.image_px.1,
            moving,
            reload,
            capture: None,
        }
    }

    /// The image shown, read back by the render thread (a screenshot).
    fn capture(&self) -> Result<grin_render::image::Frame, String> {
        let worker = self.worker.as_ref().ok_or("no render thread")?;
        let (tx, rx) = std::sync::mpsc::channel();
        worker.send(
            Request {
                capture: Some(tx),
                ..self.request(false, false)
            },
            false,
        );
        rx.recv_timeout(CAPTURE_TIMEOUT)
            .map_err(|e| format!("the screenshot's pixels did not come back: {e}"))?
    }

    /// The camera moved within MOVING_FOR (a headless orbit moves it every frame).
    fn moving(&self) -> bool {
        !self.final_still
            && ((self.headless() && self.opts.orbit_deg != 0.0)
                || self.last_move.is_some_and(|t| t.elapsed() < MOVING_FOR))
    }

    /// The image size in pixels: fixed (`--size`, headless) or the central area.
    fn request_view(&mut self, avail_px: (u32, u32)) {
        let (w, h) = if self.headless() || self.opts.size.is_some() {
            self.image_px
        } else {
            avail_px
        };
        if w == 0 || h == 0 {
            return;
        }
        self.image_px = (w, h);
        let moving = self.moving();
        let key = (self.settings.clone(), w, h, moving);
        if self.last_sent.as_ref() == Some(&key) {
            return;
        }
        let view_changed = self.last_sent.as_ref().is_none_or(|(s, lw, lh, _)| {
            (s.clone().without_display(), *lw, *lh)
                != (self.settings.clone().without_display(), w, h)
        });
        if view_changed && !moving {
            self.still_since = Instant::now();
            self.converged_after = None;
        }
        let Some(worker) = &self.worker else { return };
        worker.send(self.request(moving, false), view_changed);
        self.last_sent = Some(key);
    }

    fn watch_scene(&mut self) {
        if self.last_watch.elapsed() < WATCH_PERIOD {
            return;
        }
        self.last_watch = Instant::now();
        let now = mtime(&self.opts.scene);
        if now != self.watched {
            self.watched = now;
            let Some(worker) = &self.worker else { return };
            worker.send(self.request(false, true), true);
        }
    }

    fn redraw(&mut self, el: &ActiveEventLoop) {
        self.poll_worker(Duration::ZERO);
        if self.exit {
            el.exit();
            return;
        }
        self.dirty = false;
        self.last_redraw = Instant::now();
        // Time plays in scene seconds.
        let dt = self.last_tick.elapsed().as_secs_f64();
        self.last_tick = Instant::now();
        if self.settings.playing {
            self.settings.time += dt * self.settings.speed;
            // A sequence plays in a loop.
            if let Some(a) = self.animation
                && self.settings.time * a.fps > a.frames[1] as f64 + 0.5
            {
                self.settings.time = a.frames[0] as f64 / a.fps;
            }
        }
        let Some(mut g) = self.gfx.take() else { return };
        self.stats.ui_start.get_or_insert_with(Instant::now);
        self.stats.ui_frames += 1;
        let raw = g.egui.take_egui_input(&g.window);
        let ctx = g.egui.egui_ctx().clone();
        self.update_texture(&mut g);
        let mut avail = (0u32, 0u32);
        let mut out = ctx.run_ui(raw, |ui| {
            avail = self.ui(ui);
        });
        g.egui
            .handle_platform_output(&g.window, std::mem::take(&mut out.platform_output));
        if out
            .viewport_output
            .get(&egui::ViewportId::ROOT)
            .is_some_and(|v| v.repaint_delay.is_zero())
        {
            self.dirty = true;
        }
        self.request_view(avail);
        let prims = ctx.tessellate(std::mem::take(&mut out.shapes), out.pixels_per_point);
        let sd = egui_wgpu::ScreenDescriptor {
            size_in_pixels: [g.config.width, g.config.height],
            pixels_per_point: out.pixels_per_point,
        };
        let frame = match g.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(f)
            | wgpu::CurrentSurfaceTexture::Suboptimal(f) => Some(f),
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                g.surface.configure(&g.device, &g.config);
                None
            }
            _ => None,
        };
        let textures_changed = !out.textures_delta.set.is_empty();
        for (id, deltas) in out.textures_delta.set.drain() {
            for d in deltas {
                g.renderer.update_texture(&g.device, &g.queue, id, &d);
            }
        }
        match frame {
            Some(f) if g.layered => self.draw_layered(&mut g, f, prims, &sd, textures_changed),
            None => {}
            Some(frame) => {
                let view = frame
                    .texture
                    .create_view(&wgpu::TextureViewDescriptor::default());
                let clear = wgpu::LoadOp::Clear(wgpu::Color::BLACK);
                draw_egui(&mut g, &view, &prims, &sd, clear, |_| {});
                g.window.pre_present_notify();
                g.queue.present(frame);
            }
        }
        for id in out.textures_delta.free.drain() {
            g.renderer.free_texture(&id);
        }
        self.gfx = Some(g);
    }

    /// Draw `prims` into `frame` over the panel's layer ([`layer`]): the shapes under the
    /// image into the layer when they look different (at most every
    /// [`layer::LAYER_PERIOD`] while moving), the layer copied in, the image and what
    /// is painted after it on top.
    fn draw_layered(
        &self,
        g: &mut Gfx,
        frame: wgpu::SurfaceTexture,
        prims: Vec<egui::epaint::ClippedPrimitive>,
        sd: &egui_wgpu::ScreenDescriptor,
        textures_changed: bool,
    ) {
        let (under, over) = layer::split_at_image(prims, self.texture.map(|(id, _)| id));
        let look = layer::look(&under);
        if g.layer.as_ref().is_none_or(|l| !l.fits(&g.config)) {
            g.layer = Some(layer::UiLayer::new(&g.device, &g.config));
        }
        // Out of `g` while `g` draws (put back below).
        let Some(mut ui_layer) = g.layer.take() else {
            return;
        };
        if textures_changed || ui_layer.stale(look, self.moving()) {
            let clear = wgpu::LoadOp::Clear(wgpu::Color::BLACK);
            draw_egui(g, ui_layer.view(), &under, sd, clear, |_| {});
            ui_layer.drawn(look);
        }
        let view = frame
            .texture
            .create_view(&wgpu::TextureViewDescriptor::default());
        draw_egui(g, &view, &over, sd, wgpu::LoadOp::Load, |enc| {
            enc.copy_texture_to_texture(
                ui_layer.texture().as_image_copy(),
                frame.texture.as_image_copy(),
                ui_layer.texture().size(),
            );
        });
        g.layer = Some(ui_layer);
        g.window.pre_present_notify();
        g.queue.present(frame);
    }

    /// The render thread's texture, registered with egui when it is a new one (the
    /// texture is drawn where it is, on the device).
    fn update_texture(&mut self, g: &mut Gfx) {
        let Some(d) = &self.display else { return };
        if self.shown_frame != self.frames_seen {
            // A new rendered frame reaches the screen (not an AOV switch).
            self.shown_frame = self.frames_seen;
            self.stats.shown.push(Instant::now());
        }
        match self.texture {
            Some((_, generation)) if generation == d.generation => {}
            Some((id, _)) => {
                g.renderer.update_egui_texture_from_wgpu_texture(
                    &g.device,
                    &d.view,
                    wgpu::FilterMode::Linear,
                    id,
                );
                self.texture = Some((id, d.generation));
            }
            None => {
                let id = g.renderer.register_native_texture(
                    &g.device,
                    &d.view,
                    wgpu::FilterMode::Linear,
                );
                self.texture = Some((id, d.generation));
            }
        }
    }

    /// Offscreen: copy a new frame's texture into `target`, as a window would draw it.
    fn draw_offscreen(&mut self, gpu: &GpuContext, target: &mut Option<wgpu::Texture>) {
        let Some(d) = &self.display else { return };
        if self.shown_frame == self.frames_seen && self.stats.ui_start.is_some() {
            return;
        }
        self.shown_frame = self.frames_seen;
        self.stats.shown.push(Instant::now());
        self.stats.ui_start.get_or_insert_with(Instant::now);
        self.stats.ui_frames += 1;
        let size = d.texture.size();
        if target.as_ref().is_none_or(|t| t.size() != size) {
            *target = Some(gpu.device.create_texture(&wgpu::TextureDescriptor {
                label: Some("offscreen window"),
                size,
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: d.texture.format(),
                usage: wgpu::TextureUsages::COPY_DST | wgpu::TextureUsages::RENDER_ATTACHMENT,
                view_formats: &[],
            }));
        }
        let Some(t) = target else { return };
        let mut enc = gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("offscreen draw"),
            });
        enc.copy_texture_to_texture(d.texture.as_image_copy(), t.as_image_copy(), size);
        gpu.queue.submit([enc.finish()]);
    }
}

/// Run headless without a window (`--offscreen`): the render thread on a device of its
/// own, each new frame's texture copied into an offscreen target where a window would
/// draw it, until the frames are done.
pub(crate) fn run_offscreen(mut app: App) -> anyhow::Result<App> {
    let started = Instant::now();
    let pipeline_dir = app.cache.as_ref().map(BakeCache::pipeline_dir);
    let gpu = GpuContext::new_headless_in(pipeline_dir.as_deref())
        .map_err(|e| anyhow::anyhow!("no GPU device for the viewer: {e}"))?;
    app.device_seconds = Some(started.elapsed().as_secs_f64());
    let gpu = Arc::new(gpu);
    app.display_adapter = format!("{} (offscreen)", gpu.adapter_name());
    app.cpu_adapter = gpu.is_cpu_adapter();
    app.worker = Some(Worker::start(
        gpu.clone(),
        app.opts.scene.clone(),
        app.cache.take(),
        None,
    ));
    let mut target: Option<wgpu::Texture> = None;
    while !app.exit {
        app.poll_worker(Duration::from_millis(5));
        if app.exit {
            break;
        }
        app.watch_scene();
        app.request_view(app.image_px);
        app.draw_offscreen(&gpu, &mut target);
    }
    Ok(app)
}

/// winit's event loop, or why there is none: its X11 backend panics where the display
/// lacks an extension it needs (XKB), and that is an error to report, not a crash.
fn open_event_loop() -> anyhow::Result<EventLoop<()>> {
    let hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    let opened = std::panic::catch_unwind(EventLoop::new);
    std::panic::set_hook(hook);
    match opened {
        Ok(Ok(el)) => Ok(el),
        Ok(Err(e)) => Err(anyhow::anyhow!("grin view cannot open a window: {e}")),
        Err(panic) => {
            let why = panic
                .downcast_ref::<String>()
                .map(String::as_str)
                .or_else(|| panic.downcast_ref::<&str>().copied())
                .unwrap_or("no reason given");
            Err(anyhow::anyhow!(
                "grin view cannot open a window on this display ({why}); without a usable display, run it with --offscreen"
            ))
        }
    }
}

impl ApplicationHandler for App {
    fn user_event(&mut self, _el: &ActiveEventLoop, _wake: ()) {
        // A reply from the render thread: about_to_wait, next, takes it.
        self.dirty = true;
    }

    fn resumed(&mut self, el: &ActiveEventLoop) {
        if self.gfx.is_some() {
            return;
        }
        match self.create_gfx(el) {
            Ok(g) => self.gfx = Some(g),
            Err(e) => {
                self.fatal = Some(e);
                el.exit();
            }
        }
    }

    fn window_event(&mut self, el: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        let Some(g) = &mut self.gfx else { return };
        let resp = g.egui.on_window_event(&g.window, &event);
        // egui-winit asks for a repaint after every redraw; taken, that kept the window
        // redrawing ~30 times a second with nothing new to show, which on a CPU adapter
        // (lavapipe) took a core from the render thread (a heat-haze frame 10.3 -> 12.3 s
        // with an image on screen). The redraw's own output says whether egui wants
        // another.
        let repaint = resp.repaint && !matches!(event, WindowEvent::RedrawRequested);
        match event {
            WindowEvent::CloseRequested => {
                self.exit = true;
                el.exit();
            }
            WindowEvent::Resized(s) => {
                g.config.width = s.width.max(1);
                g.config.height = s.height.max(1);
                g.surface.configure(&g.device, &g.config);
            }
            WindowEvent::RedrawRequested => self.redraw(el),
            _ => {}
        }
        if repaint {
            self.dirty = true;
        }
    }

    fn about_to_wait(&mut self, el: &ActiveEventLoop) {
        // Frames from the render thread arrive on their own (and wake the loop): poll for
        // them, the scene file and the clock, and redraw when there is something to show.
        self.poll_worker(Duration::ZERO);
        if self.exit {
            el.exit();
            return;
        }
        self.watch_scene();
        // The camera stopped since the last (moving) request: one redraw sends the still
        // one.
        let stopped = self.last_sent.as_ref().is_some_and(|l| l.3) && !self.moving();
        // Only a CPU adapter spaces redraws out (its drawing takes the render's cores).
        let min_redraw = if self.cpu_adapter {
            MIN_REDRAW
        } else {
            Duration::ZERO
        };
        if (self.dirty || self.settings.playing || stopped)
            && self.last_redraw.elapsed() >= min_redraw
            && let Some(g) = &self.gfx
        {
            g.window.request_redraw();
        }
        el.set_control_flow(ControlFlow::WaitUntil(
            Instant::now() + Duration::from_millis(10),
        ));
    }
}

/// Draw `prims` into `view` (cleared or loaded as `load`) in one submission, after what
/// `before` encodes.
fn draw_egui(
    g: &mut Gfx,
    view: &wgpu::TextureView,
    prims: &[egui::epaint::ClippedPrimitive],
    sd: &egui_wgpu::ScreenDescriptor,
    load: wgpu::LoadOp<wgpu::Color>,
    before: impl FnOnce(&mut wgpu::CommandEncoder),
) {
    let mut enc = g
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("egui"),
        });
    before(&mut enc);
    let user = g
        .renderer
        .update_buffers(&g.device, &g.queue, &mut enc, prims, sd);
    let mut pass = enc
        .begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("egui"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load,
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: None,
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        })
        .forget_lifetime();
    g.renderer.render(&mut pass, prims, sd);
    drop(pass);
    g.queue.submit(user.into_iter().chain([enc.finish()]));
}

/// Open the window and run until it is closed (or, headless, until the frames are done).
pub(crate) fn run_window(mut app: App) -> anyhow::Result<App> {
    let el = open_event_loop()?;
    app.proxy = Some(el.create_proxy());
    el.set_control_flow(ControlFlow::Poll);
    el.run_app(&mut app)
        .map_err(|e| anyhow::anyhow!("the window's event loop failed: {e}"))?;
    Ok(app)
}
