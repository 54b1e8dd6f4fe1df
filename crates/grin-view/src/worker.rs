//! The render thread: a [`Session`] on the window's wgpu device, fed the newest view the
//! window asks for, so the window never waits on a GPU frame. Its frames stay on the
//! device: each reply names the texture the window draws (no pixel crosses to the CPU).
//! While the camera moves it renders at the internal resolution that keeps the frame
//! budget; when it stops it refines the full-resolution image progressively until
//! `max_spp`.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, Sender, TryRecvError};
use std::thread::JoinHandle;

use grin_gpu::GpuContext;
use grin_gpu::cache::BakeCache;
use grin_gpu::view::DisplayTexture;
use grin_render::image::Frame;

use crate::display::Aov;
use crate::session::{RenderFailure, Rendered, Session};
use crate::settings::ViewSettings;

/// Smallest internal resolution while moving, as a fraction of each side.
pub const MIN_MOVING_SCALE: f64 = 0.125;

/// The resolution of a still view's preview when the cost of a frame is not measured
/// yet (the first frame), as a fraction of each side.
pub const FIRST_PREVIEW_SCALE: f64 = 0.25;

/// What the window asks for.
#[derive(Debug, Clone)]
pub struct Request {
    pub settings: ViewSettings,
    /// The image's size in the window (pixels), before the resolution scale.
    pub width: u32,
    pub height: u32,
    /// The camera is moving: render at the reduced resolution that keeps the budget.
    pub moving: bool,
    /// Read the scene file again first.
    pub reload: bool,
    /// Read the image shown back to the CPU and send it here (a screenshot) before
    /// anything else; the request's view is not taken.
    pub capture: Option<Sender<Result<Frame, String>>>,
}

/// What the render thread reports.
#[derive(Debug)]
pub enum Reply {
    /// The scene's field is ready on the device.
    Started {
        adapter: String,
        setup_seconds: f64,
    },
    /// The device or the scene could not be set up: the viewer ends with this error.
    Fatal(String),
    Frame(Box<FrameReply>),
    /// The scene file was read again: the new file's settings, or why it was not taken.
    Reloaded(Result<ViewSettings, String>),
    /// The image was coloured in another AOV (no new frame): the texture and the value
    /// its full colour scale stands for.
    Shown {
        aov: Aov,
        display: DisplayTexture,
        scale: f32,
    },
    /// A frame failed (shown in the panel; the last good frame stays).
    Error(String),
}

/// A finished frame and what the panel shows about it.
#[derive(Debug)]
pub struct FrameReply {
    pub rendered: Rendered,
    /// The settings it was rendered with (for AOV display and screenshots).
    pub settings: ViewSettings,
    pub scale: f64,
    /// A still view's preview, shown while its full frame renders (not one of the
    /// frames a headless run counts).
    pub preview: bool,
    pub warnings: Vec<String>,
    pub cache: Option<grin_gpu::cache::CacheUse>,
    pub field_grid: Option<([u32; 3], u64)>,
}

/// The render thread's handle.
#[derive(Debug)]
pub struct Worker {
    requests: Sender<Request>,
    pub replies: Receiver<Reply>,
    cancel: Arc<AtomicBool>,
    handle: Option<JoinHandle<()>>,
}

impl Worker {
    /// Start the thread on `ctx` (the window's device): it loads `scene` (the bake
    /// through `cache`), then answers [`Request`]s.
    /// `wake` is called after each reply (to wake the window's event loop).
    pub fn start(
        ctx: Arc<GpuContext>,
        scene: PathBuf,
        cache: Option<BakeCache>,
        wake: Option<Box<dyn Fn() + Send>>,
    ) -> Self {
        let (requests, rx) = std::sync::mpsc::channel::<Request>();
        let (tx, replies) = std::sync::mpsc::channel::<Reply>();
        let cancel = Arc::new(AtomicBool::new(false));
        let c = cancel.clone();
        let handle = std::thread::Builder::new()
            .name("grin-view render".into())
            .spawn(move || run(&ctx, scene, cache, rx, Replies { tx, wake }, c))
            .ok();
        Worker {
            requests,
            replies,
            cancel,
            handle,
        }
    }

    /// Ask for a view; `interrupt` stops the frame in progress (the view changed).
    pub fn send(&self, request: Request, interrupt: bool) {
        if interrupt {
            self.cancel.store(true, Ordering::Relaxed);
        }
        let _ = self.requests.send(request);
    }
}

impl Drop for Worker {
    fn drop(&mut self) {
        self.cancel.store(true, Ordering::Relaxed);
        // Closing the channel ends the thread's loop.
        let (dead, _) = std::sync::mpsc::channel();
        self.requests = dead;
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

fn run(
    ctx: &GpuContext,
    scene: PathBuf,
    cache: Option<BakeCache>,
    rx: Receiver<Request>,
    tx: Replies,
    cancel: Arc<AtomicBool>,
) {
    let start = std::time::Instant::now();
    let mut session = match Session::new(ctx, &scene, cache) {
        Ok(s) => s,
        Err(e) => {
            let _ = tx.send(Reply::Fatal(format!("{e:#}")));
            return;
        }
    };
    let _ = tx.send(Reply::Started {
        adapter: ctx.adapter_name(),
        setup_seconds: start.elapsed().as_secs_f64(),
    });
    let mut current: Option<Request> = None;
    // Seconds per pixel-sample of the last frames (for the moving resolution).
    let mut cost: Option<f64> = None;
    let mut failed = false;
    // A moving request gets one preview frame: the next view comes with the next request
    // (its internal size follows the cost measured meanwhile, which would otherwise ask
    // for another frame of the same view).
    let mut previewed = false;
    // The current still request had its preview.
    let mut still_previewed = false;
    loop {
        // The newest request; block when there is nothing left to refine.
        let rendered = match &current {
            Some(r) if r.moving => previewed,
            Some(r) => {
                let (w, h, _) = internal_size(r, cost);
                !session.needs_frame(&r.settings, w, h)
            }
            None => true,
        };
        // Nothing to render, but the image is wanted in another AOV: colour it again.
        if rendered
            && !failed
            && let Some(r) = &current
            && session.shown_aov().is_some_and(|a| a != r.settings.aov)
        {
            let aov = r.settings.aov;
            let reply = match session.show(aov) {
                Ok((display, scale)) => Reply::Shown {
                    aov,
                    display,
                    scale,
                },
                Err(e) => {
                    // Shown once; the next request tries again.
                    failed = true;
                    Reply::Error(format!("{e:#}"))
                }
            };
            if tx.send(reply).is_err() {
                return;
            }
            continue;
        }
        if failed || rendered {
            match rx.recv() {
                Ok(r) if r.capture.is_some() => {
                    capture(&session, r);
                    continue;
                }
                Ok(r) => {
                    current = Some(r);
                    previewed = false;
                    still_previewed = false;
                }
                Err(_) => return,
            }
        }
        loop {
            match rx.try_recv() {
                Ok(r) if r.capture.is_some() => capture(&session, r),
                Ok(r) => {
                    let reload = r.reload || current.as_ref().is_some_and(|c| c.reload);
                    current = Some(Request { reload, ..r });
                    previewed = false;
                    still_previewed = false;
                }
                Err(TryRecvError::Empty) => break,
                Err(TryRecvError::Disconnected) => return,
            }
        }
        let Some(req) = &mut current else { continue };
        failed = false;
        if req.reload {
            req.reload = false;
            let reply = session.reload().map_err(|e| format!("{e:#}"));
            if tx.send(Reply::Reloaded(reply)).is_err() {
                return;
            }
            // The window answers with the rebased settings.
            continue;
        }
        let (mut w, mut h, mut scale) = internal_size(req, cost);
        // A still view whose image is complete (another AOV shown, the same view asked
        // again): nothing to render; the loop's top colours it again where needed.
        if !req.moving && !session.needs_frame(&req.settings, w, h) {
            continue;
        }
        // A new still view whose frame would take longer than the frame budget (or whose
        // cost is not known yet): a preview first, as a moving view gets, refined after.
        let preview = !req.moving
            && !still_previewed
            && !session.has_image_of(&req.settings, w, h)
            && cost.is_none_or(|c| {
                let samples = f64::from(w) * f64::from(h) * f64::from(req.settings.spp.max(1));
                c * samples > 1.0 / req.settings.target_fps.max(1.0)
            });
        if preview {
            still_previewed = true;
            let moving = Request {
                moving: true,
                ..req.clone()
            };
            (w, h, scale) = match cost {
                Some(_) => internal_size(&moving, cost),
                None => scaled(req, scale.min(FIRST_PREVIEW_SCALE)),
            };
        }
        cancel.store(false, Ordering::Relaxed);
        session.set_display_size(req.width, req.height);
        let settings = req.settings.clone();
        match session.render(&settings, w, h, req.moving || preview, &cancel) {
            Ok(rendered) => {
                let samples = f64::from(w) * f64::from(h) * f64::from(settings.spp.max(1));
                let c = rendered.gpu_seconds / samples.max(1.0);
                cost = Some(cost.map_or(c, |old| 0.5 * old + 0.5 * c));
                let reply = FrameReply {
                    rendered,
                    settings,
                    scale,
                    preview,
                    warnings: session
                        .warnings
                        .iter()
                        .chain(&session.frame_warning)
                        .cloned()
                        .collect(),
                    cache: session.cache_use,
                    field_grid: session.field_grid,
                };
                if tx.send(Reply::Frame(Box::new(reply))).is_err() {
                    return;
                }
                previewed = req.moving;
            }
            Err(RenderFailure::Cancelled) => {}
            Err(RenderFailure::Error(e)) => {
                failed = true;
                if tx.send(Reply::Error(format!("{e:#}"))).is_err() {
                    return;
                }
            }
        }
    }
}

/// The reply channel, and what wakes the window when a reply is sent.
struct Replies {
    tx: Sender<Reply>,
    wake: Option<Box<dyn Fn() + Send>>,
}

impl Replies {
    /// Send `reply`; `Err` when the window is gone.
    fn send(&self, reply: Reply) -> Result<(), ()> {
        self.tx.send(reply).map_err(|_| ())?;
        if let Some(wake) = &self.wake {
            wake();
        }
        Ok(())
    }
}

/// Answer a capture request: the image shown, read back from the device.
fn capture(session: &Session, r: Request) {
    if let Some(to) = r.capture {
        let _ = to.send(session.frame().map_err(|e| format!("{e:#}")));
    }
}

/// The internal resolution of `req`: the resolution scale, or while moving the largest
/// one whose frame fits the frame budget at the measured cost.
pub fn internal_size(req: &Request, cost: Option<f64>) -> (u32, u32, f64) {
    let s = &req.settings;
    let mut scale = s.resolution_scale.clamp(MIN_MOVING_SCALE, 1.0);
    if req.moving {
        scale = match cost {
            Some(c) => {
                let budget = 1.0 / s.target_fps.max(1.0);
                let full = f64::from(req.width) * f64::from(req.height) * f64::from(s.spp.max(1));
                let fit = (budget / (c * full).max(1e-12)).sqrt();
                scale.min(fit).max(MIN_MOVING_SCALE)
            }
            // The first frame, its cost unknown: the preview's size.
            None => scale.min(FIRST_PREVIEW_SCALE),
        };
    }
    scaled(req, scale)
}

/// `req`'s image size at `scale` of each side.
fn scaled(req: &Request, scale: f64) -> (u32, u32, f64) {
    let w = ((f64::from(req.width) * scale).round() as u32).max(1);
    let h = ((f64::from(req.height) * scale).round() as u32).max(1);
    (w, h, scale)
}
