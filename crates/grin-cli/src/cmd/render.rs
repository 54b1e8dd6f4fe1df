//! `grin render`: scene file -> linear HDR EXR (beauty + AOV channels) and a PNG preview
//! beside it, on the GPU (wgpu) or the CPU reference.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use grin_pipeline::{Backend, Rendered, Renderer};
use grin_render::image::{Frame, diff_frames, stage_channels_exr, stage_rgb8_png};
use indicatif::{ProgressBar, ProgressStyle};

/// Arguments of `grin render`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The scene file (TOML).
    pub scene: PathBuf,
    /// Output EXR; the PNG preview is written beside it with the extension `.png`.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Renderer.
    #[arg(long, value_enum, default_value_t = Backend::Gpu)]
    pub backend: Backend,
    /// Image size, overriding the scene's [render] width and height.
    #[arg(long, value_name = "WxH", value_parser = parse_size)]
    pub size: Option<(u32, u32)>,
    /// Samples per pixel, overriding the scene's [render] spp.
    #[arg(long)]
    pub spp: Option<u32>,
    /// Compare the beauty pass with a reference EXR (e.g. the other backend's): print the
    /// mean, 99th percentile and max per-pixel difference and write `<out>-difference.png`.
    #[arg(long, value_name = "REF.exr")]
    pub compare: Option<PathBuf>,
    /// Print a machine-readable summary (JSON) on stdout.
    #[arg(long)]
    pub json: bool,
    /// Bake the GPU's field grid anew instead of reading it from the user's bake cache
    /// (and do not store it there); the driver's pipeline cache is not used either.
    #[arg(long)]
    pub no_cache: bool,
    /// Render frames A..B (inclusive) of the scene's sequence: the medium's path may hold a
    /// frame token (`####`, `%04d`, `$F4`) and noise / expr time is t + frame / fps. The
    /// output must hold a frame token too (`-o out.####.exr`). The GPU device and its
    /// compiled pipelines are kept from frame to frame.
    #[arg(long, value_name = "A..B", value_parser = grin_scene::frames::parse_frame_range)]
    pub frames: Option<(i64, i64)>,
    /// Frames per second of the sequence (default: the scene's [animation] fps, else 24).
    #[arg(long)]
    pub fps: Option<f64>,
    /// With a scene that has an [optics] output: also render its beauty image (the scene
    /// without [optics], at its spp) to this EXR (and its PNG), in the same run: a plate
    /// and its ST map from one scene file. With --frames it holds a frame token too.
    #[arg(long, value_name = "BEAUTY.exr")]
    pub beauty: Option<PathBuf>,
}

/// Largest accepted image side: keeps `width * height * spp` and the frame buffer sane.
const MAX_SIDE: u32 = 16_384;

pub(crate) fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("`{s}` is not WxH (e.g. 640x360)"))?;
    let parse = |v: &str| {
        v.trim()
            .parse::<u32>()
            .map_err(|_| format!("`{s}` is not WxH (e.g. 640x360)"))
    };
    let (w, h) = (parse(w)?, parse(h)?);
    if w == 0 || h == 0 || w > MAX_SIDE || h > MAX_SIDE {
        return Err(format!(
            "size {w}x{h} must be between 1 and {MAX_SIDE} on each side"
        ));
    }
    Ok((w, h))
}

/// What a render produced, for the summary: the pipeline's report and the files.
#[derive(Debug, serde::Serialize)]
struct Summary {
    #[serde(flatten)]
    report: grin_pipeline::Report,
    exr: PathBuf,
    /// The PNG preview; none where the EXR went to a stream (`-`, a device).
    png: Option<PathBuf>,
    /// `--compare`: per-pixel beauty difference against the reference (largest channel).
    #[serde(skip_serializing_if = "Option::is_none")]
    comparison: Option<Comparison>,
}

/// The `--compare` result.
#[derive(Debug, serde::Serialize)]
struct Comparison {
    mean: f64,
    p99: f64,
    max: f64,
    /// Pixels whose difference is infinite (NaN or an unmatched infinity).
    nonfinite: usize,
    difference_png: Option<PathBuf>,
}

/// The scene's beauty image: the scene without its [optics] output.
fn without_optics(mut scene: grin_scene::Scene) -> grin_scene::Scene {
    scene.optics = None;
    scene
}

/// Where the EXR goes and the PNG preview beside it (`None` when the EXR goes to a
/// stream: `-`, a device or a FIFO). Checked before any rendering.
fn check_output(path: &Path) -> anyhow::Result<Option<PathBuf>> {
    if grin_output::Destination::resolve(path)?.is_stream() {
        return Ok(None);
    }
    if !path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("exr"))
    {
        bail!("{}: the output must be an .exr file", path.display());
    }
    Ok(Some(path.with_extension("png")))
}

/// A progress bar on stderr per pass, with the warnings printed above it.
struct Bar(std::sync::Mutex<Option<ProgressBar>>);

impl Bar {
    fn new() -> Self {
        Self(std::sync::Mutex::new(None))
    }

    fn with(&self, f: impl FnOnce(&mut Option<ProgressBar>)) {
        f(&mut self.0.lock().unwrap_or_else(|e| e.into_inner()));
    }
}

impl grin_pipeline::Progress for Bar {
    fn begin(&self, rows: u64) {
        let bar = ProgressBar::new(rows);
        if let Ok(style) =
            ProgressStyle::with_template("{prefix} [{bar:40}] {pos}/{len} rows {elapsed}<{eta}")
        {
            bar.set_style(style.progress_chars("=> "));
        }
        bar.set_prefix("rendering");
        self.with(|b| *b = Some(bar));
    }

    fn advance(&self, rows: u32) {
        self.with(|b| {
            if let Some(b) = b {
                b.inc(u64::from(rows));
            }
        });
    }

    fn finish(&self) {
        self.with(|b| {
            if let Some(b) = b.take() {
                b.finish_and_clear();
            }
        });
    }

    fn warn(&self, message: &str) {
        self.with(|b| match b {
            Some(b) => b.suspend(|| eprintln!("grin: warning: {message}")),
            None => eprintln!("grin: warning: {message}"),
        });
    }
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let mut scene = grin_scene::load_scene(&args.scene)?;
    if let Some((w, h)) = args.size {
        scene.render.width = w;
        scene.render.height = h;
    }
    if let Some(spp) = args.spp {
        scene.render.spp = spp;
    }
    if let Some(o) = &scene.optics {
        // Optical outputs follow each pixel's centre ray, once: the AOVs of that ray
        // (render_one sets that up). BOS images are rendered at the scene's spp.
        if scene.render.spp > 1 && o.mode != grin_scene::OpticsMode::Bos {
            eprintln!(
                "grin: note: [optics] {} traces one ray through each pixel's centre (spp {} ignored)",
                grin_pipeline::optics::mode_name(o.mode),
                scene.render.spp
            );
        }
        if args.compare.is_some() {
            bail!("--compare compares beauty renders; this scene has an [optics] output");
        }
    }
    if let Some(b) = &args.beauty {
        if scene.optics.is_none() {
            bail!(
                "--beauty: {} has no [optics] output: its render is the beauty image already",
                args.scene.display()
            );
        }
        check_output(b).with_context(|| "--beauty")?;
        if b == &args.output || b.with_extension("png") == args.output.with_extension("png") {
            bail!(
                "--beauty {}: the beauty image needs a name of its own (not the output's)",
                b.display()
            );
        }
        if grin_scene::frames::has_frame_token(&b.to_string_lossy()) != args.frames.is_some() {
            bail!(
                "--beauty {}: holds a frame token exactly when --frames is given, as -o does",
                b.display()
            );
        }
    }
    let fps = args.fps.unwrap_or_else(|| scene.fps());
    if !(fps.is_finite() && fps > 0.0) {
        bail!("--fps must be a positive number of frames per second, got {fps}");
    }
    let Some((first, last)) = args.frames else {
        if grin_scene::frames::has_frame_token(&args.output.to_string_lossy()) {
            bail!(
                "{}: the output holds a frame token but no --frames A..B was given",
                args.output.display()
            );
        }
        // A scene with an [animation] renders its first frame.
        let scene = match scene.animation {
            Some(a) => scene.at_frame(a.frames[0], fps),
            None => scene,
        };
        let Some(beauty) = &args.beauty else {
            let renderer = Renderer::new(args.backend, !args.no_cache);
            let (summary, to_stream) = render_one(&args, &renderer, scene, &args.output)?;
            return print_summary(&summary, args.json, to_stream);
        };
        // The [optics] output and the beauty image, on one device.
        let jobs = [
            (scene.clone(), args.output.clone(), String::new()),
            (without_optics(scene), beauty.clone(), "beauty".into()),
        ];
        return render_all(&args, jobs.into_iter());
    };
    let pattern = args.output.to_string_lossy().into_owned();
    if !grin_scene::frames::has_frame_token(&pattern) {
        bail!(
            "{}: with --frames the output needs a frame token, e.g. out.####.exr",
            args.output.display()
        );
    }
    if args.compare.is_some() {
        bail!("--compare compares one frame: render the frame alone to compare it");
    }
    // Every frame's file must be there before any frame is rendered.
    let scene_dir = args.scene.parent().unwrap_or(Path::new("."));
    let missing = grin_scene::frames::missing_frames(&scene, scene_dir, first, last);
    if !missing.is_empty() {
        bail!(
            "{}: {} of frames {first}..{last} missing: {}",
            args.scene.display(),
            missing.len(),
            grin_scene::frames::summarize(&missing)
        );
    }
    grin_field::vdb::check_sequence(&scene, scene_dir, first, last)
        .with_context(|| format!("{}", args.scene.display()))?;
    // Each frame, and its beauty image beside it with --beauty.
    let at = |path: &Path, f: i64| {
        let p = path.to_string_lossy();
        PathBuf::from(grin_scene::frames::substitute_frame(&p, f).unwrap_or_else(|| p.into()))
    };
    let jobs = (first..=last).flat_map(|f| {
        let frame = scene.at_frame(f, fps);
        let beauty = args.beauty.as_ref().map(|b| {
            (
                without_optics(frame.clone()),
                at(b, f),
                format!("frame {f} (beauty)"),
            )
        });
        std::iter::once((frame, at(&args.output, f), format!("frame {f}"))).chain(beauty)
    });
    render_all(&args, jobs)
}

/// Render each (scene, output, what it is for error messages, or empty) on one device, printing
/// each summary, or with `--json` all of them as one array at the end.
fn render_all(
    args: &Args,
    jobs: impl Iterator<Item = (grin_scene::Scene, PathBuf, String)>,
) -> anyhow::Result<()> {
    let renderer = Renderer::new(args.backend, !args.no_cache);
    let mut summaries = Vec::new();
    for (scene, out, what) in jobs {
        let rendered = render_one(args, &renderer, scene, &out);
        let (summary, to_stream) = if what.is_empty() {
            rendered?
        } else {
            rendered.with_context(|| what)?
        };
        if !args.json {
            print_summary(&summary, false, to_stream)?;
        }
        summaries.push(summary);
    }
    if args.json {
        outln!("{}", serde_json::to_string_pretty(&summaries)?);
    }
    Ok(())
}

/// Render `scene` (the scene file's, sized, at its frame) to `output` with `renderer`.
/// Returns the summary and whether the EXR went to a stream.
fn render_one(
    args: &Args,
    renderer: &Renderer,
    scene: grin_scene::Scene,
    output: &Path,
) -> anyhow::Result<(Summary, bool)> {
    // Everything that can be wrong with the input fails here, before any GPU work.
    let png = check_output(output)?;
    let scene_dir = args.scene.parent().unwrap_or(Path::new("."));
    let reference = args
        .compare
        .as_deref()
        .map(Frame::read_exr)
        .transpose()
        .context("--compare")?;
    if let Some(r) = &reference
        && (r.width, r.height) != (scene.render.width, scene.render.height)
    {
        bail!(
            "--compare: reference is {}x{}, the render is {}x{}",
            r.width,
            r.height,
            scene.render.width,
            scene.render.height
        );
    }
    let label = args.scene.display().to_string();
    let Rendered {
        image,
        frame,
        mut report,
    } = renderer.render(scene, scene_dir, &label, &Bar::new())?;

    // The EXR, its PNG previews and the --compare difference image are staged, then put
    // in place together: a failure or a signal leaves the previous set as it was.
    let exr_to_stream = png.is_none();
    let size = (image.width as usize, image.height as usize);
    let named = image
        .channels
        .iter()
        .map(|(n, d)| (n.as_str(), d.clone()))
        .collect();
    let mut staged = vec![stage_channels_exr(output, size, named)?];
    let mut pngs = Vec::new();
    if let Some(png) = &png {
        for preview in &image.previews {
            let path = match preview.suffix {
                None => png.clone(),
                Some(suffix) => sibling(png, suffix),
            };
            staged.push(stage_rgb8_png(
                &path,
                image.width,
                image.height,
                &preview.rgb8,
            )?);
            pngs.push(path);
        }
    } else {
        eprintln!(
            "grin: note: {} is not a file: the EXR goes there, no PNG preview is written",
            args.output.display()
        );
    }
    if let Some(optics) = &mut report.optics {
        optics["pngs"] = serde_json::json!(pngs);
    }
    let comparison = match (&reference, &frame) {
        (Some(r), Some(frame)) => {
            let (stats, diff) = diff_frames(frame, r).context("--compare: sizes differ")?;
            let diff_png = sibling(output, "difference");
            if !exr_to_stream {
                staged.push(diff.stage_png(&diff_png)?);
            }
            Some(Comparison {
                mean: stats.mean,
                p99: stats.p99,
                max: stats.max,
                nonfinite: stats.nonfinite,
                difference_png: (!exr_to_stream).then_some(diff_png),
            })
        }
        _ => None,
    };
    grin_output::commit(staged)?;
    let summary = Summary {
        report,
        exr: output.to_owned(),
        png,
        comparison,
    };
    Ok((summary, exr_to_stream))
}

/// The PNG beside `path` with `-suffix` after its stem.
fn sibling(path: &Path, suffix: &str) -> PathBuf {
    let stem = path
        .file_stem()
        .map_or_else(|| "out".into(), |s| s.to_string_lossy().into_owned());
    path.with_file_name(format!("{stem}-{suffix}.png"))
}

/// Print a frame's summary (JSON or a few lines).
fn print_summary(summary: &Summary, json: bool, exr_to_stream: bool) -> anyhow::Result<()> {
    // Where the EXR itself went to a stream (it may be stdout), the summary goes to stderr.
    let report = |text: String| crate::report(exr_to_stream, text);
    if json {
        report(serde_json::to_string_pretty(summary)?);
    } else {
        let wrote = match &summary.png {
            Some(png) => format!("{} and {}", summary.exr.display(), png.display()),
            None => summary.exr.display().to_string(),
        };
        report(format!(
            "rendered {}x{} x {} spp on {} ({}) in {:.3} s{} (+ {:.3} s setup): {:.3} Mrays/s, {:.1} steps/ray, {:.1} field evals/ray\nwrote {}",
            summary.report.width,
            summary.report.height,
            summary.report.spp,
            summary.report.backend,
            summary.report.adapter,
            summary.report.seconds,
            summary
                .report
                .device_seconds
                .map(|d| format!(", {d:.3} s of it on the device"))
                .unwrap_or_default(),
            summary.report.setup_seconds,
            summary.report.rays_per_second * 1e-6,
            summary.report.steps_per_ray,
            summary.report.evals_per_ray,
            wrote,
        ));
        if let Some(a) = &summary.report.auto {
            report(a.summary_line());
        }
        if let Some(note) = &summary.report.auto_note {
            report(note.clone());
        }
        if let Some(c) = &summary.comparison {
            let wrote = c
                .difference_png
                .as_ref()
                .map_or_else(String::new, |p| format!("; wrote {}", p.display()));
            report(format!(
                "difference vs reference: mean {:.3e}, p99 {:.3e}, max {:.3e}, {} non-finite pixels{wrote}",
                c.mean, c.p99, c.max, c.nonfinite
            ));
        }
    }
    Ok(())
}
