//! `grin render`: scene file -> linear HDR EXR (beauty + AOV channels) and a PNG preview
//! beside it, on the GPU (wgpu) or the CPU reference.
//!
//! Over 600 lines: one concept, `grin render`'s arguments, jobs, outputs and summary (a sequence's
//! frame checks are in [`frames`]).

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use grin_pipeline::{Backend, Rendered, Renderer};
use grin_render::image::{Frame, diff_frames, stage_channels_exr, stage_rgb8_png};
use grin_scene::frames::FrameList;
use indicatif::ProgressBar;

mod frames;
use frames::{check_frames, seeded};

/// Arguments of `grin render`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The scene file (TOML).
    pub scene: PathBuf,
    /// Output EXR; the PNG preview is written beside it with the extension `.png`.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Renderer.
    #[arg(long, value_enum, default_value_t = Backend::Auto)]
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
    /// Render these frames of the scene's sequence: `A..B` (inclusive) or a render farm's
    /// frame list (OpenJD / Deadline: `1-3,5,7-20:2`, frames `A`, ranges `A-B`, stepped
    /// ranges `A-B:S`, in the order given, repeats dropped). The medium's path may hold a
    /// frame token (`####`, `%04d`, `$F4`) and noise / expr time is t + frame / fps. The
    /// output must hold a frame token too (`-o out.####.exr`). The GPU device and its
    /// compiled pipelines are kept from frame to frame.
    #[arg(long, value_name = "LIST", value_parser = grin_scene::frames::parse_frame_list)]
    pub frames: Option<FrameList>,
    /// Render only shard I of N (0-based) of the --frames list: the list cut into N
    /// contiguous pieces whose sizes differ by at most one, the earlier pieces taking the
    /// extra frames (a Slurm array task:
    /// `--shard $SLURM_ARRAY_TASK_ID/$SLURM_ARRAY_TASK_COUNT` with `--array=0-(N-1)`).
    /// A shard with no frames renders nothing and succeeds.
    #[arg(long, value_name = "I/N", value_parser = grin_scene::frames::parse_shard)]
    pub shard: Option<(u32, u32)>,
    /// Skip what is rendered already: a frame whose EXR (and --beauty EXR) exists is not
    /// rendered again (a retried farm task renders only what is missing). Outputs are put
    /// in place whole, so an existing file is a complete one.
    #[arg(long)]
    pub skip_existing: bool,
    /// Seed each frame's randomness from S and the frame number: the [render] seed
    /// (sub-pixel positions, step jitter, lens and path sampling) and the [sensor] noise
    /// seed, each frame its own. A frame renders the same whichever shard or task renders
    /// it, and different frames get unrelated noise. The [optics] BOS dot pattern keeps
    /// its seed (the background does not change between frames). Without --seed the
    /// scene's seeds are used (the sensor's mixed with the frame number).
    #[arg(long, value_name = "S")]
    pub seed: Option<u64>,
    /// Frames per second of the sequence (default: the scene's [animation] fps, else 24).
    #[arg(long)]
    pub fps: Option<f64>,
    /// With a scene that has an [optics] output: also render its beauty image (the scene
    /// without [optics], at its spp) to this EXR (and its PNG), in the same run: a plate
    /// and its ST map from one scene file. With --frames it holds a frame token too.
    #[arg(long, value_name = "BEAUTY.exr")]
    pub beauty: Option<PathBuf>,
    /// The AOVs the EXR holds beside R, G, B: `all` (default), `none`, or a comma list of
    /// deflection, exit_dir, opd, steps, evals, status, exit_pos, opd_plane. On the GPU
    /// only those channels are read back (12 bytes a pixel for `none`, against 64). The
    /// summary's steps, evaluations and statuses are counted either way. An [optics]
    /// output writes its own channels.
    #[arg(long, value_name = "LIST", value_parser = grin_pipeline::parse_aovs)]
    pub aovs: Option<grin_gpu::channels::Channels>,
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
    /// The frame, with --frames.
    #[serde(skip_serializing_if = "Option::is_none")]
    frame: Option<i64>,
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
    let png = path.with_extension("png");
    // The preview may not replace an input either (a plate `bg.png` for `-o bg.exr`).
    grin_output::Destination::resolve(&png)?;
    Ok(Some(png))
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
        let bar = super::styled_bar(rows, "{prefix} [{bar:40}] {pos}/{len} rows {elapsed}<{eta}");
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
    if let (Some((index, count)), None) = (args.shard, &args.frames) {
        bail!(
            "--shard {index}/{count} renders a shard of a frame list: give the list with --frames \
             (e.g. --frames 1-100 --shard {index}/{count})"
        );
    }
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
    let Some(list) = &args.frames else {
        if grin_scene::frames::has_frame_token(&args.output.to_string_lossy()) {
            bail!(
                "{}: the output holds a frame token but no --frames A..B was given",
                args.output.display()
            );
        }
        // A scene with an [animation] renders its first frame.
        let first = scene.animation.as_ref().map(|a| a.frames[0]);
        let scene = match first {
            Some(f) => scene.at_frame(f, fps),
            None => scene,
        };
        let scene = seeded(scene, first.unwrap_or(0), args.seed);
        if args.skip_existing && complete(&args.output)? {
            if let Some(beauty) = &args.beauty {
                if complete(beauty)? {
                    return report_skipped(&args, None, &args.output, Some(beauty));
                }
            } else {
                return report_skipped(&args, None, &args.output, None);
            }
        }
        let Some(beauty) = &args.beauty else {
            let renderer = Renderer::new(args.backend, !args.no_cache)
                .with_aovs(args.aovs.unwrap_or(grin_gpu::channels::Channels::ALL));
            let (summary, to_stream) = render_one(&args, &renderer, scene, &args.output)?;
            return print_summary(&summary, args.json, to_stream);
        };
        // The [optics] output and the beauty image, on one device.
        let jobs = [
            Job::render(scene.clone(), args.output.clone(), String::new(), None),
            Job::render(without_optics(scene), beauty.clone(), "beauty".into(), None),
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
    let frames = match args.shard {
        Some((index, count)) => list.shard(index, count),
        None => list.frames().to_vec(),
    };
    if let (true, Some((index, count))) = (frames.is_empty(), args.shard) {
        eprintln!(
            "grin: note: shard {index}/{count} of the {} frames {list} holds no frame: nothing to render",
            list.len()
        );
        if args.json {
            outln!("[]");
        }
        return Ok(());
    }
    // Each frame's outputs, and whether they are there already (--skip-existing).
    let at = |path: &Path, f: i64| {
        let p = path.to_string_lossy();
        PathBuf::from(grin_scene::frames::substitute_frame(&p, f).unwrap_or_else(|| p.into()))
    };
    let mut done = std::collections::HashSet::new();
    if args.skip_existing {
        for &f in &frames {
            let beauty = args.beauty.as_ref().map(|b| at(b, f));
            if complete(&at(&args.output, f))? && beauty.as_deref().map_or(Ok(true), complete)? {
                done.insert(f);
            }
        }
    }
    let todo: Vec<i64> = frames
        .iter()
        .copied()
        .filter(|f| !done.contains(f))
        .collect();
    // Every file of a frame to render must be there before any frame is rendered.
    let scene_dir = args.scene.parent().unwrap_or(Path::new("."));
    check_frames(&args.scene, &scene, scene_dir, &todo)?;
    // Each frame, and its beauty image beside it with --beauty; or what is there already.
    let jobs = frames.iter().flat_map(|&f| {
        let out = at(&args.output, f);
        let beauty_out = args.beauty.as_ref().map(|b| at(b, f));
        if done.contains(&f) {
            return vec![Job::Skipped {
                frame: Some(f),
                exr: out,
                beauty: beauty_out,
            }];
        }
        let frame = seeded(scene.at_frame(f, fps), f, args.seed);
        let beauty = beauty_out.map(|b| {
            Job::render(
                without_optics(frame.clone()),
                b,
                format!("frame {f} (beauty)"),
                Some(f),
            )
        });
        std::iter::once(Job::render(frame, out, format!("frame {f}"), Some(f)))
            .chain(beauty)
            .collect()
    });
    render_all(&args, jobs)?;
    if args.skip_existing {
        let text = format!(
            "{} of {} frames rendered, {} skipped (their outputs exist)",
            todo.len(),
            frames.len(),
            done.len()
        );
        // With --json stdout holds the JSON array alone.
        crate::report(args.json, text);
    }
    Ok(())
}

/// Whether `path` is a rendered output already (`--skip-existing`): a file, not a stream.
/// Outputs are staged and renamed into place, so a file there is a whole one.
fn complete(path: &Path) -> anyhow::Result<bool> {
    Ok(check_output(path)?.is_some() && path.is_file())
}

/// One thing `render_all` does: render a scene to an output, or report an output that
/// is there already (`--skip-existing`).
enum Job {
    Render {
        scene: Box<grin_scene::Scene>,
        out: PathBuf,
        /// What it is, for error messages (empty: the render itself).
        what: String,
        frame: Option<i64>,
    },
    Skipped {
        frame: Option<i64>,
        exr: PathBuf,
        beauty: Option<PathBuf>,
    },
}

impl Job {
    fn render(scene: grin_scene::Scene, out: PathBuf, what: String, frame: Option<i64>) -> Self {
        Job::Render {
            scene: Box::new(scene),
            out,
            what,
            frame,
        }
    }
}

/// `--skip-existing`: the line on stderr, and the summary entry.
fn skipped_entry(frame: Option<i64>, exr: &Path, beauty: Option<&Path>) -> serde_json::Value {
    let outputs = match beauty {
        Some(b) => format!("{} and {} exist", exr.display(), b.display()),
        None => format!("{} exists", exr.display()),
    };
    match frame {
        Some(f) => eprintln!("skipped frame {f}: {outputs}"),
        None => eprintln!("skipped: {outputs}"),
    }
    let mut entry = serde_json::Map::new();
    if let Some(f) = frame {
        entry.insert("frame".into(), f.into());
    }
    entry.insert("skipped".into(), true.into());
    entry.insert("exr".into(), serde_json::json!(exr));
    if let Some(b) = beauty {
        entry.insert("beauty".into(), serde_json::json!(b));
    }
    entry.into()
}

/// A render without --frames that `--skip-existing` skips.
fn report_skipped(
    args: &Args,
    frame: Option<i64>,
    exr: &Path,
    beauty: Option<&PathBuf>,
) -> anyhow::Result<()> {
    let entry = skipped_entry(frame, exr, beauty.map(PathBuf::as_path));
    if args.json {
        outln!("{}", serde_json::to_string_pretty(&entry)?);
    }
    Ok(())
}

/// Run each job on one device, printing each summary (a skipped output: a line on
/// stderr), or with `--json` all of them as one array at the end.
fn render_all(args: &Args, jobs: impl Iterator<Item = Job>) -> anyhow::Result<()> {
    let renderer = Renderer::new(args.backend, !args.no_cache)
        .with_aovs(args.aovs.unwrap_or(grin_gpu::channels::Channels::ALL));
    let mut summaries = Vec::new();
    for job in jobs {
        let (scene, out, what, frame) = match job {
            Job::Render {
                scene,
                out,
                what,
                frame,
            } => (scene, out, what, frame),
            Job::Skipped { frame, exr, beauty } => {
                summaries.push(skipped_entry(frame, &exr, beauty.as_deref()));
                continue;
            }
        };
        let rendered = render_one(args, &renderer, *scene, &out);
        let (mut summary, to_stream) = if what.is_empty() {
            rendered?
        } else {
            rendered.with_context(|| what)?
        };
        summary.frame = frame;
        if !args.json {
            print_summary(&summary, false, to_stream)?;
        }
        summaries.push(serde_json::to_value(&summary)?);
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
    let _inputs = (
        super::protect_scene(&args.scene, &scene),
        grin_output::protect_inputs(args.compare.iter()),
    );
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
        ..
    } = renderer.render(scene, scene_dir, &label, &Bar::new())?;

    // The EXR, its PNG previews and the --compare difference image are staged, then put
    // in place together: a failure or a signal leaves the previous set as it was.
    let exr_to_stream = png.is_none();
    let size = (image.width as usize, image.height as usize);
    let mut staged = vec![stage_channels_exr(output, size, image.channels)?];
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
        frame: None,
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
        if let Some(note) = &summary.report.backend_note {
            report(note.clone());
        }
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
