//! `grin render`: scene file -> linear HDR EXR (beauty + AOV channels) and a PNG preview
//! beside it, on the GPU (wgpu) or the CPU reference.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::time::Instant;

use anyhow::{Context, bail};
use grin_render::image::{Frame, diff_frames};
use grin_render::scene::RenderScene;
use grin_trace::render::render_cpu;
use indicatif::{ProgressBar, ProgressStyle};

/// Which renderer runs the frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Backend {
    /// The WGSL marcher through wgpu (lavapipe without a GPU).
    Gpu,
    /// The CPU reference (rayon).
    Cpu,
}

impl Backend {
    fn name(self) -> &'static str {
        match self {
            Backend::Gpu => "gpu",
            Backend::Cpu => "cpu",
        }
    }
}

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

/// What a render produced, for the summary.
#[derive(Debug, serde::Serialize)]
struct Summary {
    backend: &'static str,
    adapter: String,
    width: u32,
    height: u32,
    spp: u32,
    /// Frame time (the render itself).
    seconds: f64,
    /// Device setup, field bake and upload, pipeline creation (GPU; ~0 on the CPU).
    setup_seconds: f64,
    /// GPU: the device's own time in the render passes (timestamps; absent where the
    /// adapter has none). `seconds` adds dispatching and reading the pixels back.
    #[serde(skip_serializing_if = "Option::is_none")]
    device_seconds: Option<f64>,
    rays_per_second: f64,
    steps_per_ray: f64,
    evals_per_ray: f64,
    /// Pixels by the camera ray's status in the medium (sample 0): missed, exited,
    /// absorbed (stopped on an object inside), max_steps, error.
    status_counts: std::collections::BTreeMap<&'static str, usize>,
    exr: PathBuf,
    /// The PNG preview; none where the EXR went to a stream (`-`, a device).
    png: Option<PathBuf>,
    /// Warnings also printed on stderr: an under-resolved GPU bake, pixels stopped in
    /// the medium.
    warnings: Vec<String>,
    /// GPU: whether the field grid came from the bake cache (`hit`), was baked and stored
    /// (`stored`) or baked without it (`off`); absent for a baked file or no medium.
    #[serde(skip_serializing_if = "Option::is_none")]
    bake_cache: Option<grin_gpu::cache::CacheUse>,
    /// GPU: the baked grid the marcher sampled (a `.grinf` file as it is, else the
    /// coarsest bake meeting the error budget, at most 128 nodes per axis).
    #[serde(skip_serializing_if = "Option::is_none")]
    gpu_field: Option<GpuField>,
    /// `--compare`: per-pixel beauty difference against the reference (largest channel).
    #[serde(skip_serializing_if = "Option::is_none")]
    comparison: Option<Comparison>,
    /// `[optics]`: the mode's output (channels written, ranges, PNGs).
    #[serde(skip_serializing_if = "Option::is_none")]
    optics: Option<serde_json::Value>,
    /// `step = { auto = ... }`: what the pilot rays chose (and every candidate tried).
    #[serde(skip_serializing_if = "Option::is_none")]
    auto: Option<grin_trace::auto::AutoChoice>,
    /// `step = { auto = ... }` resolved without pilots (a render too small for them): why.
    #[serde(skip_serializing_if = "Option::is_none")]
    auto_note: Option<String>,
}

/// The field grid on the device.
#[derive(Debug, serde::Serialize)]
struct GpuField {
    dims: [u32; 3],
    bytes: u64,
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

/// The GPU device of a render: the driver's pipeline cache beside the user's bake cache,
/// neither with `--no-cache`.
fn gpu_context(no_cache: bool) -> anyhow::Result<grin_gpu::GpuContext> {
    let dir = (!no_cache)
        .then(grin_gpu::cache::BakeCache::user_default)
        .flatten()
        .map(|c| c.pipeline_dir());
    Ok(grin_gpu::GpuContext::new_headless_in(dir.as_deref())?)
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

fn progress_bar(rows: u32) -> ProgressBar {
    let bar = ProgressBar::new(u64::from(rows));
    if let Ok(style) =
        ProgressStyle::with_template("{prefix} [{bar:40}] {pos}/{len} rows {elapsed}<{eta}")
    {
        bar.set_style(style.progress_chars("=> "));
    }
    bar.set_prefix("rendering");
    bar
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
                crate::cmd::optics::mode_name(o.mode),
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
            let (summary, to_stream) = render_one(&args, scene, &args.output, None)?;
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
    let ctx = match args.backend {
        Backend::Gpu => Some(gpu_context(args.no_cache)?),
        Backend::Cpu => None,
    };
    let mut summaries = Vec::new();
    for (scene, out, what) in jobs {
        let rendered = render_one(args, scene, &out, ctx.as_ref());
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

/// Render `scene` (the scene file's, sized, at its frame) to `output`; `gpu`: a device
/// to reuse (sequences), else one is made. Returns the summary and whether the EXR went
/// to a stream.
fn render_one(
    args: &Args,
    mut scene: grin_scene::Scene,
    output: &Path,
    gpu: Option<&grin_gpu::GpuContext>,
) -> anyhow::Result<(Summary, bool)> {
    // Everything that can be wrong with the input fails here, before any GPU work.
    let png = check_output(output)?;
    let scene_dir = args.scene.parent().unwrap_or(Path::new("."));
    let field = scene
        .medium
        .as_ref()
        .map(|m| grin_field::build_field(m, scene_dir))
        .transpose()
        .with_context(|| format!("{}: [medium]", args.scene.display()))?;
    // BOS images through the camera's lens or anti-aliased: rendered as beauty images
    // of the dots on the plane, with and without the medium, at the scene's spp.
    let bos_scene = bos_image_scene(&scene)?;
    if scene.optics.is_some() {
        scene.render.spp = 1;
        scene.render.jitter = false;
    }
    let mut rs = RenderScene::new(&scene, scene_dir, field.clone())
        .with_context(|| format!("{}", args.scene.display()))?;
    // `step = { auto = ... }`: pilot rays choose the integrator and step, in the
    // backend's precision, before anything is traced.
    // An optical output asks its accuracy in its own unit: pixels of landing point,
    // waves of OPD (`[optics] accuracy`, default 0.01).
    let metric = scene.optics.as_ref().and_then(|o| {
        let asked = o.output_accuracy()?;
        let metric = match o.accuracy_unit() {
            // The shadowgraph's pixels are its screen's bins, its rays the beam's.
            grin_scene::AccuracyUnit::Pixels if o.mode == grin_scene::OpticsMode::Shadowgraph => {
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
    });
    // The GPU's pilots trace in f32 as it does, but for an OPD in waves: a CPU f32 trace
    // holds n itself in f32 (1e-7 of ~1.0003: a fifth of a wave over a metre), where the
    // GPU sums n - n_amb, so its OPD is as good as f64's.
    let waves = matches!(metric, Some((grin_trace::auto::Metric::Waves { .. }, _)));
    // The shadowgraph's pilots are its beam's rays: resolved on a scene whose camera is
    // the beam's, then applied to this one.
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
    let target = pilot_rs.as_mut().unwrap_or(&mut rs);
    let auto = match args.backend {
        Backend::Gpu if !waves => grin_trace::auto::resolve_scene_in::<f32>(target, metric),
        _ => grin_trace::auto::resolve_scene_in::<f64>(target, metric),
    };
    if let (Some(_), Some(a)) = (&pilot_rs, &auto) {
        grin_trace::auto::apply(&mut rs, &a.settings);
    }
    let auto_note = grin_trace::auto::render_pilot_note(pilot_rs.as_ref().unwrap_or(&rs));
    let auto_warning = auto.as_ref().and_then(|a| a.unmet_warning("rendering"));
    if let Some(w) = &auto_warning {
        eprintln!("grin: warning: {w}");
    }
    let bos_scenes = match &bos_scene {
        Some(s) => {
            let mut with = RenderScene::new(s, scene_dir, field.clone())
                .with_context(|| format!("{}", args.scene.display()))?;
            if let Some(a) = &auto {
                grin_trace::auto::apply(&mut with, &a.settings);
            }
            let mut bare = s.clone();
            bare.medium = None;
            let without = RenderScene::new(&bare, scene_dir, None)
                .with_context(|| format!("{}", args.scene.display()))?;
            Some((with, without))
        }
        None => None,
    };

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

    if let Some(spec) = scene
        .optics
        .as_ref()
        .filter(|o| o.mode == grin_scene::OpticsMode::Shadowgraph)
    {
        let start = Instant::now();
        let to_stream = png.is_none();
        let medium = rs.medium.as_ref().with_context(|| {
            format!(
                "{}: [optics] a shadowgraph needs a [medium]",
                args.scene.display()
            )
        })?;
        let mut warnings: Vec<String> = auto_warning.iter().cloned().collect();
        let (sg, adapter, gpu_field, bake_cache) = match args.backend {
            Backend::Cpu => {
                let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
                let sg = grin_trace::shadowgraph::shadowgraph(
                    medium.field.as_ref(),
                    &medium.trace,
                    &rs.camera,
                    &spec.screen,
                );
                (sg, format!("cpu ({threads} threads)"), None, None)
            }
            Backend::Gpu => {
                // The beam's rays are an orthographic camera's pixel centres: one GPU
                // frame, its exit AOVs binned on the screen.
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
                    bail!(
                        "{}: [optics] the shadowgraph's beam is {pixels} rays (bins x \
                         rays_per_pixel); at most {} fit one GPU frame: fewer bins or \
                         rays_per_pixel",
                        args.scene.display(),
                        grin_render::scene::MAX_PIXELS
                    );
                }
                let bar = progress_bar(beam_rs.settings.height);
                let Rendered {
                    frame,
                    adapter,
                    gpu_field,
                    bake_cache,
                    ..
                } = render_frame(
                    args,
                    &beam_rs,
                    scene.medium.as_ref(),
                    scene_dir,
                    gpu,
                    &bar,
                    &mut warnings,
                )?;
                bar.finish_and_clear();
                let v = |a: [f32; 3]| glam::DVec3::from_array(a.map(f64::from));
                // status 0 missed (exit_pos = the ray's start), 1 exited, 5 degraded;
                // else stopped.
                let ends = frame.pixels.iter().map(|p| {
                    (p.status <= 1.0 || p.status == 5.0)
                        .then(|| (v(p.exit_pos), v(p.exit_dir).normalize()))
                });
                (beam.collect(ends), adapter, gpu_field, bake_cache)
            }
        };
        let (staged, optics) = crate::cmd::optics::stage_shadowgraph(&sg, output, png.as_deref())?;
        grin_output::commit(staged)?;
        let seconds = start.elapsed().as_secs_f64();
        let rays = optics["rays_launched"].as_f64().unwrap_or(0.0);
        let summary = Summary {
            backend: args.backend.name(),
            adapter,
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
            exr: output.to_owned(),
            png,
            warnings,
            bake_cache,
            gpu_field,
            comparison: None,
            optics: Some(optics),
            auto,
            auto_note,
        };
        return Ok((summary, to_stream));
    }

    // Three renders share one device (and its compiled pipelines).
    let owned_ctx;
    let gpu = match (gpu, &bos_scenes, args.backend) {
        (None, Some(_), Backend::Gpu) => {
            owned_ctx = gpu_context(args.no_cache)?;
            Some(&owned_ctx)
        }
        _ => gpu,
    };
    let passes = if bos_scenes.is_some() { 3 } else { 1 };
    let bar = progress_bar(scene.render.height * passes);
    let setup_start = Instant::now();
    let mut warnings: Vec<String> = auto_warning.into_iter().collect();
    let Rendered {
        frame,
        adapter,
        seconds,
        device_seconds,
        gpu_field,
        bake_cache,
    } = render_frame(
        args,
        &rs,
        scene.medium.as_ref(),
        scene_dir,
        gpu,
        &bar,
        &mut warnings,
    )?;
    let bos_images = match &bos_scenes {
        Some((with, without)) => {
            let mut quiet = Vec::new();
            let Rendered {
                frame: distorted, ..
            } = render_frame(
                args,
                with,
                scene.medium.as_ref(),
                scene_dir,
                gpu,
                &bar,
                &mut quiet,
            )?;
            let Rendered {
                frame: reference, ..
            } = render_frame(args, without, None, scene_dir, gpu, &bar, &mut quiet)?;
            let red = |f: &Frame| f.pixels.iter().map(|p| f64::from(p.rgb[0])).collect();
            Some((red(&reference), red(&distorted)))
        }
        None => None,
    };
    let setup_seconds = setup_start.elapsed().as_secs_f64() - seconds;
    bar.finish_and_clear();
    let mut frame = frame;
    if let Some(sensor) = &scene.sensor {
        match scene.optics.as_ref().map(|o| o.mode) {
            None => grin_render::sensor::record_frame(sensor, &mut frame),
            Some(grin_scene::OpticsMode::Bos | grin_scene::OpticsMode::Interferogram) => {}
            Some(mode) => {
                let w = format!(
                    "[sensor] records the beauty, BOS and interferogram images; the {} \
                     output is written without sensor noise",
                    crate::cmd::optics::mode_name(mode)
                );
                eprintln!("grin: warning: {w}");
                warnings.push(w);
            }
        }
    }
    if scene.optics.is_some() && scene.camera.f_number.is_some() && bos_images.is_none() {
        let w = "[optics] outputs trace one pinhole ray per pixel centre: camera.f_number \
                 (defocus) is not applied to them"
            .to_owned();
        eprintln!("grin: warning: {w}");
        warnings.push(w);
    }

    // The EXR, its PNG preview and the --compare difference image are staged, then put
    // in place together: a failure or a signal leaves the previous set as it was.
    let exr_to_stream = png.is_none();
    let mut optics = None;
    let mut staged = match &scene.optics {
        Some(spec) => {
            let (staged, summary) = crate::cmd::optics::stage_from_frame(
                spec,
                scene.sensor.as_ref(),
                bos_images,
                &rs,
                &frame,
                output,
                png.as_deref(),
            )?;
            optics = Some(summary);
            staged
        }
        None => {
            let mut v = vec![frame.stage_exr(output)?];
            if let Some(png) = &png {
                v.push(frame.stage_png(png)?);
            }
            v
        }
    };
    match &png {
        Some(_) => {}
        None => eprintln!(
            "grin: note: {} is not a file: the EXR goes there, no PNG preview is written",
            args.output.display()
        ),
    }
    let comparison = match &reference {
        Some(r) => {
            let (stats, diff) = diff_frames(&frame, r).context("--compare: sizes differ")?;
            let diff_png = output.with_file_name(format!(
                "{}-difference.png",
                output
                    .file_stem()
                    .map_or_else(|| "out".into(), |s| s.to_string_lossy())
            ));
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
        None => None,
    };
    grin_output::commit(staged)?;

    let n_pixels = f64::from(frame.width) * f64::from(frame.height);
    let rays = n_pixels * f64::from(scene.render.spp);
    let mean = |f: fn(&grin_render::image::PixelOut) -> f32| {
        frame.pixels.iter().map(|p| f64::from(f(p))).sum::<f64>() / n_pixels.max(1.0)
    };
    let mut summary = Summary {
        backend: args.backend.name(),
        adapter,
        width: frame.width,
        height: frame.height,
        spp: scene.render.spp,
        seconds,
        setup_seconds,
        device_seconds,
        rays_per_second: rays / seconds.max(1e-9),
        steps_per_ray: mean(|p| p.steps),
        evals_per_ray: mean(|p| p.evals),
        status_counts: status_counts(&frame),
        comparison,
        exr: output.to_owned(),
        png,
        warnings,
        bake_cache,
        gpu_field,
        optics,
        auto,
        auto_note,
    };
    let stuck = summary.status_counts["max_steps"] + summary.status_counts["error"];
    if stuck > 0 {
        let w = format!(
            "{stuck} pixels stopped in the medium (max_steps {}, error {}): see the aov.status channel",
            summary.status_counts["max_steps"], summary.status_counts["error"]
        );
        eprintln!("grin: warning: {w}");
        summary.warnings.push(w);
    }
    let degraded = summary.status_counts["degraded"];
    if degraded > 0 {
        let w = format!(
            "{degraded} pixels left the medium `degraded`: their error estimate is above the {:.1e} rad they are held to (asked {:.1e}; aov.status 5): the integrator's own at these steps (shorter steps, or step = {{ auto = ... }} without an integrator, resolve it), or a baked field's n error amplified at a grazing crossing of the bounds (a finer or tricubic bake resolves it)",
            rs.settings.estimate_limit(),
            rs.settings.accuracy()
        );
        eprintln!("grin: warning: {w}");
        summary.warnings.push(w);
    }
    Ok((summary, exr_to_stream))
}

/// One frame of `rs` on the backend `args` asks for (`gpu`: a device to reuse): the
/// frame, the adapter, the render time, and on the GPU the field's size and how the bake
/// cache served it; warnings are printed above `bar` and collected.
#[allow(clippy::type_complexity)]
/// One frame of [`render_frame`] and what the summary says of it.
struct Rendered {
    frame: Frame,
    adapter: String,
    seconds: f64,
    /// The GPU's own time in the render passes, where the adapter writes timestamps.
    device_seconds: Option<f64>,
    gpu_field: Option<GpuField>,
    bake_cache: Option<grin_gpu::cache::CacheUse>,
}

fn render_frame(
    args: &Args,
    rs: &RenderScene,
    medium: Option<&grin_scene::MediumSpec>,
    scene_dir: &Path,
    gpu: Option<&grin_gpu::GpuContext>,
    bar: &ProgressBar,
    warnings: &mut Vec<String>,
) -> anyhow::Result<Rendered> {
    let cancel = AtomicBool::new(false);
    let tick = |rows: u32| bar.inc(u64::from(rows));
    let mut gpu_field = None;
    let mut bake_cache = None;
    let mut device_seconds = None;
    let (frame, adapter, seconds): (Frame, String, f64) = match args.backend {
        Backend::Cpu => {
            let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
            let start = Instant::now();
            let frame = render_cpu(rs, &tick, &cancel)?;
            let adapter = format!("cpu ({threads} threads)");
            (frame, adapter, start.elapsed().as_secs_f64())
        }
        Backend::Gpu => {
            let owned;
            let ctx = match gpu {
                Some(c) => c,
                None => {
                    owned = gpu_context(args.no_cache)?;
                    &owned
                }
            };
            if let Some(w) = cpu_adapter_warning(ctx)
                && !warnings.contains(&w)
            {
                // Printed once a process (a sequence renders many frames on one device).
                static PRINTED: std::sync::Once = std::sync::Once::new();
                PRINTED.call_once(|| bar.suspend(|| eprintln!("grin: warning: {w}")));
                warnings.push(w);
            }
            let cache = (!args.no_cache)
                .then(grin_gpu::cache::BakeCache::user_default)
                .flatten();
            let field = grin_gpu::cache::scene_gpu_field(rs, medium, scene_dir, cache.as_ref())
                .with_context(|| format!("{}: [medium]", args.scene.display()))?;
            let renderer = grin_gpu::GpuRenderer::new(ctx, rs, field.as_ref().map(|f| &f.0))
                .with_context(|| format!("{}", args.scene.display()))?;
            if let Some((_, field_warnings, used)) = &field {
                bake_cache = Some(*used);
                for w in field_warnings {
                    bar.suspend(|| eprintln!("grin: warning: {w}"));
                    warnings.push(w.clone());
                }
            }
            for w in renderer.warnings() {
                bar.suspend(|| eprintln!("grin: warning: {w}"));
                warnings.push(w.clone());
            }
            if medium.is_some() {
                gpu_field = Some(GpuField {
                    dims: renderer.field_dims(),
                    bytes: renderer.field_bytes(),
                });
            }
            let adapter = renderer.adapter_info();
            let start = Instant::now();
            let frame = renderer.render(&tick, &cancel)?;
            device_seconds = renderer.last_device_seconds();
            if let Some(w) = renderer.loop_limit_warning(&frame) {
                bar.suspend(|| eprintln!("grin: warning: {w}"));
                warnings.push(w);
            }
            (frame, adapter, start.elapsed().as_secs_f64())
        }
    };
    Ok(Rendered {
        frame,
        adapter,
        seconds,
        device_seconds,
        gpu_field,
        bake_cache,
    })
}

/// The scene whose beauty renders are the BOS images when they need more than the pixel
/// centre's pinhole ray (a lens, or spp > 1): the dots as an emissive plane object (white
/// on black, the `[optics]` dots and plane), at the scene's spp; `None` otherwise.
fn bos_image_scene(scene: &grin_scene::Scene) -> anyhow::Result<Option<grin_scene::Scene>> {
    let Some(spec) = scene
        .optics
        .as_ref()
        .filter(|o| o.mode == grin_scene::OpticsMode::Bos)
    else {
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
            summary.width,
            summary.height,
            summary.spp,
            summary.backend,
            summary.adapter,
            summary.seconds,
            summary
                .device_seconds
                .map(|d| format!(", {d:.3} s of it on the device"))
                .unwrap_or_default(),
            summary.setup_seconds,
            summary.rays_per_second * 1e-6,
            summary.steps_per_ray,
            summary.evals_per_ray,
            wrote,
        ));
        if let Some(a) = &summary.auto {
            report(a.summary_line());
        }
        if let Some(note) = &summary.auto_note {
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

/// Pixels per `aov.status` value, by name.
fn status_counts(frame: &Frame) -> std::collections::BTreeMap<&'static str, usize> {
    let names = grin_trace::RayStatus::ALL.map(|s| s.name());
    let mut counts: std::collections::BTreeMap<_, _> = names.iter().map(|&n| (n, 0)).collect();
    for p in &frame.pixels {
        if let Some(name) = names.get(p.status as usize)
            && let Some(c) = counts.get_mut(name)
        {
            *c += 1;
        }
    }
    counts
}
