//! `grin bench bake`: the paper's procedural noise (fBm with a central-difference gradient
//! at every Runge-Kutta stage) against the same medium baked, traced on the CPU; and bake
//! time and bytes per resolution.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use glam::DVec3;
use grin_field::IndexField;
use grin_field::bake::{BakeOptions, bake};
use grin_field::baked::{Interp, Storage};
use grin_render::settings::TraceSettings;
use grin_trace::trace_ray;

/// Arguments of `grin bench bake`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scene whose medium is benchmarked (default: the noise example).
    #[arg(long, default_value = "data/scenes/noise-sphere.toml")]
    pub scene: PathBuf,
    /// Fewer resolutions and rays.
    #[arg(long)]
    pub quick: bool,
    /// Rays per frame (a square grid of parallel rays across the medium), at least 1.
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..=(1u64 << 24)))]
    pub rays: Option<u64>,
    /// Directory for bench-bake.json.
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Print the JSON summary on stdout.
    #[arg(long)]
    pub json: bool,
}

/// Resolutions baked (nodes along the longest axis).
const RESOLUTIONS: [usize; 4] = [32, 64, 128, 192];
const QUICK_RESOLUTIONS: [usize; 2] = [32, 64];
/// Rays per frame by default (quick).
const DEFAULT_RAYS: usize = 1024;
const QUICK_RAYS: usize = 256;

/// Frames traced per row; the fastest is reported (the others absorb cache warm-up and
/// the noise of a shared machine).
const REPEATS: usize = 3;

/// [`frame_once`] `REPEATS` times: (best seconds, evaluations).
fn frame(field: &dyn IndexField, settings: &TraceSettings, rays: usize) -> (f64, u64) {
    (0..REPEATS)
        .map(|_| frame_once(field, settings, rays))
        .fold((f64::INFINITY, 0), |(best, _), (t, e)| (best.min(t), e))
}

/// Trace a frame of parallel rays along +z through `field`; (seconds, evaluations).
fn frame_once(field: &dyn IndexField, settings: &TraceSettings, rays: usize) -> (f64, u64) {
    let (lo, hi) = field.bounds().aabb();
    let side = (rays as f64).sqrt().ceil() as usize;
    let start = Instant::now();
    let mut evals = 0;
    for j in 0..side {
        for i in 0..side {
            let u = (i as f64 + 0.5) / side as f64;
            let v = (j as f64 + 0.5) / side as f64;
            let o = DVec3::new(
                lo.x + (hi.x - lo.x) * u,
                lo.y + (hi.y - lo.y) * v,
                lo.z - 1.0,
            );
            evals += trace_ray::<f64>(field, settings, o, DVec3::Z).evals;
        }
    }
    (start.elapsed().as_secs_f64(), evals)
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let scene = grin_scene::load_scene(&args.scene)?;
    let medium = scene
        .medium
        .as_ref()
        .with_context(|| format!("{}: the scene has no [medium]", args.scene.display()))?;
    let scene_dir = args.scene.parent().unwrap_or(Path::new("."));
    let source = grin_field::build_field(medium, scene_dir)?;
    let settings = TraceSettings::from_render(&scene.render);
    settings.validate_for(&source.bounds())?;
    let rays = args
        .rays
        .map_or(if args.quick { QUICK_RAYS } else { DEFAULT_RAYS }, |r| {
            r as usize
        });
    let resolutions: &[usize] = if args.quick {
        &QUICK_RESOLUTIONS
    } else {
        &RESOLUTIONS
    };

    eprintln!(
        "procedural: {} ({rays} rays, {:?} / {:?})",
        source.describe(),
        settings.integrator,
        settings.step
    );
    let (t_proc, e_proc) = frame(source.as_ref(), &settings, rays);
    outln!(
        "{:<34} {:>10.1} ms/frame {:>12} evals {:>8.0} ns/eval",
        "procedural (paper)",
        1e3 * t_proc,
        e_proc,
        1e9 * t_proc / e_proc.max(1) as f64
    );
    let mut rows = Vec::new();
    for &res in resolutions {
        for interp in [Interp::Trilinear, Interp::Tricubic] {
            let opts = BakeOptions {
                resolution: Some(res),
                interp,
                storage: Some(Storage::I16),
                error_points: 2000,
                ..Default::default()
            };
            let (baked, report) = bake(source.as_ref(), &opts, &|_: &str, _: u64, _: u64| {})?;
            let (t, e) = frame(&baked, &settings, rays);
            let label = format!("baked {res} {} i16", interp.name());
            outln!(
                "{label:<34} {:>10.1} ms/frame {:>12} evals {:>8.0} ns/eval  speedup {:>6.1}x  bake {:.2} s  {} bytes  max|dn err| {:.2e}",
                1e3 * t,
                e,
                1e9 * t / e.max(1) as f64,
                t_proc / t,
                report.seconds,
                report.bytes,
                report.errors.max_err_n
            );
            rows.push(serde_json::json!({
                "resolution": res,
                "dims": report.dims,
                "interp": interp.name(),
                "storage": "i16",
                "frame_ms": 1e3 * t,
                "evals": e,
                "speedup": t_proc / t,
                "bake_seconds": report.seconds,
                "bytes": report.bytes,
                "max_err_n": report.errors.max_err_n,
                "rms_err_n": report.errors.rms_err_n,
            }));
        }
    }
    let summary = serde_json::json!({
        "scene": args.scene.display().to_string(),
        "source": source.describe(),
        "rays": rays,
        "procedural_frame_ms": 1e3 * t_proc,
        "procedural_evals": e_proc,
        "baked": rows,
    });
    if let Some(dir) = &args.output {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("{}: cannot create", dir.display()))?;
        let path = dir.join("bench-bake.json");
        let text = serde_json::to_string_pretty(&summary)?;
        grin_output::write_file(&path, |w| w.write_all(text.as_bytes()))?;
        eprintln!("wrote {}", path.display());
    }
    if args.json {
        outln!("{}", serde_json::to_string_pretty(&summary)?);
    }
    Ok(())
}
