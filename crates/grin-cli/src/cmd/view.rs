//! `grin view`: the real-time window (grin-view), and its headless frame runs.

use std::path::PathBuf;

/// Arguments of `grin view`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The scene file (TOML); it is watched and reloaded when it changes.
    pub scene: PathBuf,
    /// Image size in pixels (default: the window's image area; with --frames, the
    /// scene's [render] size).
    #[arg(long, value_name = "WxH", value_parser = super::render::parse_size)]
    pub size: Option<(u32, u32)>,
    /// Samples per pixel of each frame (default: the scene's spp).
    #[arg(long)]
    pub spp: Option<u32>,
    /// Samples per pixel at which a still view is converged (default: 16x spp, at least
    /// 64; with --frames and no --orbit, frames x spp).
    #[arg(long, value_name = "N")]
    pub max_spp: Option<u32>,
    /// Render N frames through the window, then write --screenshot and print fps
    /// statistics (min/median/max) and the summary.
    #[arg(long, value_name = "N")]
    pub frames: Option<u32>,
    /// Where the last frame goes: .png (the image as shown) or .exr (every channel, with
    /// the beauty PNG beside it).
    #[arg(long, value_name = "PATH")]
    pub screenshot: Option<PathBuf>,
    /// Degrees the camera orbits about the scene's up axis after each frame (--frames).
    #[arg(
        long,
        value_name = "DEG",
        default_value_t = 0.0,
        allow_hyphen_values = true
    )]
    pub orbit: f64,
    /// Bake the field anew instead of reading the user's bake cache (the driver's
    /// pipeline cache is not used either).
    #[arg(long)]
    pub no_cache: bool,
    /// With --frames: no window and no display needed; each frame is drawn into an
    /// offscreen texture on the render device (servers, benchmarks).
    #[arg(long, requires = "frames")]
    pub offscreen: bool,
    /// Print the summary as JSON.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    if args.frames == Some(0) {
        anyhow::bail!("--frames must be at least 1");
    }
    if args.spp == Some(0) || args.max_spp == Some(0) {
        anyhow::bail!("--spp and --max-spp must be at least 1");
    }
    if !args.orbit.is_finite() {
        anyhow::bail!("--orbit must be a finite number of degrees");
    }
    // A screenshot may not replace the scene or a file it reads (a reload reads them
    // again; a scene that does not load fails in the viewer, which names it).
    let _inputs = grin_scene::load_scene(&args.scene)
        .ok()
        .map(|scene| super::protect_scene(&args.scene, &scene));
    let opts = grin_view::ViewOptions {
        scene: args.scene,
        size: args.size,
        spp: args.spp,
        max_spp: args.max_spp,
        frames: args.frames,
        screenshot: args.screenshot,
        orbit_deg: args.orbit,
        no_cache: args.no_cache,
        offscreen: args.offscreen,
    };
    let Some(s) = grin_view::run(opts)? else {
        return Ok(());
    };
    if args.json {
        outln!("{}", serde_json::to_string_pretty(&s)?);
        return Ok(());
    }
    for w in &s.warnings {
        eprintln!("grin: warning: {w}");
    }
    outln!(
        "viewed {} frames of {}x{} (last at {}x{}) on {}: {:.1} fps min / {:.1} median / {:.1} max, frame {:.1} ms median on the wall{}, {:.2} Mrays/s, {:.0} kB read back a frame",
        s.frames,
        s.width,
        s.height,
        s.last_internal[0],
        s.last_internal[1],
        s.adapter,
        s.fps.min,
        s.fps.median,
        s.fps.max,
        s.wall_ms.median,
        s.device_ms.map_or(String::new(), |d| format!(
            " ({:.1} ms on the device)",
            d.median
        )),
        s.rays_per_second * 1e-6,
        s.read_back_bytes.median * 1e-3
    );
    outln!(
        "setup {:.2} s (device {:.2} s, bake cache: {}), first frame at {:.2} s; {} spp{}",
        s.setup_seconds,
        s.device_seconds,
        s.bake_cache.map_or("none", <&str>::from),
        s.first_frame_seconds,
        s.samples,
        match s.converged_seconds {
            Some(c) if s.converged => format!(", converged {c:.2} s after the view settled"),
            _ => String::new(),
        }
    );
    if let Some(p) = &s.screenshot {
        outln!("wrote {}", p.display());
    }
    Ok(())
}
