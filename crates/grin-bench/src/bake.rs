//! `grin bench bake`: the paper's procedural noise (fBm with a central-difference gradient
//! at every Runge-Kutta stage) against the same medium baked, traced on the CPU; and bake
//! time and bytes per resolution.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use anyhow::Context;
use glam::DVec3;
use grin_field::IndexField;
use grin_field::bake::{BakeOptions, bake};
use grin_field::baked::{Interp, Storage};
use grin_render::settings::TraceSettings;
use grin_trace::trace_ray;
use serde::Serialize;

/// Resolutions baked (nodes along the longest axis).
const RESOLUTIONS: [usize; 4] = [32, 64, 128, 192];
const QUICK_RESOLUTIONS: [usize; 2] = [32, 64];
/// Rays per frame by default (quick).
const DEFAULT_RAYS: usize = 1024;
const QUICK_RAYS: usize = 256;

/// Frames traced per row; the fastest is reported (the others absorb cache warm-up and
/// the noise of a shared machine).
const REPEATS: usize = 3;

/// What `grin bench bake` measures.
#[derive(Debug, Clone)]
pub struct Options {
    /// Scene whose medium is benchmarked.
    pub scene: PathBuf,
    /// Fewer resolutions and rays.
    pub quick: bool,
    /// Rays per frame (a square grid of parallel rays across the medium) instead of
    /// 1024 (256 with `quick`).
    pub rays: Option<u64>,
}

/// A frame of rays traced: the fastest of [`REPEATS`].
#[derive(Debug, Clone, Copy)]
pub struct Timing {
    pub seconds: f64,
    /// Field evaluations over the frame.
    pub evals: u64,
}

/// The medium baked at one resolution and interpolation, traced.
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    pub resolution: usize,
    pub dims: [usize; 3],
    pub interp: &'static str,
    pub storage: &'static str,
    pub frame_ms: f64,
    pub evals: u64,
    /// The procedural frame's time over this one's.
    pub speedup: f64,
    pub bake_seconds: f64,
    pub bytes: u64,
    pub max_err_n: f64,
    pub rms_err_n: f64,
    /// The frame (`frame_ms` in seconds).
    #[serde(skip)]
    pub seconds: f64,
}

/// The JSON summary (`bench-bake.json`, `--json`).
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    pub scene: String,
    pub source: String,
    pub rays: usize,
    pub procedural_frame_ms: f64,
    pub procedural_evals: u64,
    pub baked: Vec<Row>,
}

/// A scene's medium, procedural, and the frame of rays traced through it and its bakes.
#[derive(Debug)]
pub struct Bench {
    scene: PathBuf,
    source: Arc<dyn IndexField>,
    /// How the rays are traced (the scene's `[render]` settings).
    pub settings: TraceSettings,
    /// Rays per frame.
    pub rays: usize,
    quick: bool,
}

impl Bench {
    /// The medium of `options.scene`, checked against its trace settings.
    pub fn new(options: &Options) -> anyhow::Result<Self> {
        let scene = grin_scene::load_scene(&options.scene)?;
        let medium = scene
            .medium
            .as_ref()
            .with_context(|| format!("{}: the scene has no [medium]", options.scene.display()))?;
        let scene_dir = options.scene.parent().unwrap_or(Path::new("."));
        let source = grin_field::build_field(medium, scene_dir)?;
        let settings = TraceSettings::from_render(&scene.render);
        settings.validate_for(&source.bounds())?;
        let rays = options.rays.map_or(
            if options.quick {
                QUICK_RAYS
            } else {
                DEFAULT_RAYS
            },
            |r| r as usize,
        );
        Ok(Self {
            scene: options.scene.clone(),
            source,
            settings,
            rays,
            quick: options.quick,
        })
    }

    /// What the procedural medium is.
    pub fn describe(&self) -> String {
        self.source.describe()
    }

    /// The bakes measured, in order: each resolution (nodes along the longest axis),
    /// trilinear then tricubic.
    pub fn variants(&self) -> Vec<(usize, Interp)> {
        let resolutions: &[usize] = if self.quick {
            &QUICK_RESOLUTIONS
        } else {
            &RESOLUTIONS
        };
        resolutions
            .iter()
            .flat_map(|&res| [Interp::Trilinear, Interp::Tricubic].map(|interp| (res, interp)))
            .collect()
    }

    /// The frame through the procedural medium.
    pub fn procedural(&self) -> Timing {
        frame(self.source.as_ref(), &self.settings, self.rays)
    }

    /// The medium baked at `resolution` with `interp` (i16 storage), and the frame
    /// through the bake, against the `procedural` frame.
    pub fn baked(
        &self,
        resolution: usize,
        interp: Interp,
        procedural: Timing,
    ) -> anyhow::Result<Row> {
        let opts = BakeOptions {
            resolution: Some(resolution),
            interp,
            storage: Some(Storage::I16),
            error_points: 2000,
            ..Default::default()
        };
        let (baked, report) = bake(self.source.as_ref(), &opts, &|_: &str, _: u64, _: u64| {})?;
        let Timing { seconds: t, evals } = frame(&baked, &self.settings, self.rays);
        Ok(Row {
            resolution,
            dims: report.dims,
            interp: interp.name(),
            storage: "i16",
            frame_ms: 1e3 * t,
            evals,
            speedup: procedural.seconds / t,
            bake_seconds: report.seconds,
            bytes: report.bytes,
            max_err_n: report.errors.max_err_n,
            rms_err_n: report.errors.rms_err_n,
            seconds: t,
        })
    }

    /// The summary of the `procedural` frame and the `baked` rows.
    pub fn summary(&self, procedural: Timing, baked: Vec<Row>) -> Summary {
        Summary {
            scene: self.scene.display().to_string(),
            source: self.source.describe(),
            rays: self.rays,
            procedural_frame_ms: 1e3 * procedural.seconds,
            procedural_evals: procedural.evals,
            baked,
        }
    }
}

/// Write `summary` as `dir/bench-bake.json` (making `dir`); the file's path.
pub fn write_summary(summary: &Summary, dir: &Path) -> anyhow::Result<PathBuf> {
    std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create", dir.display()))?;
    let path = dir.join("bench-bake.json");
    let text = serde_json::to_string_pretty(summary)?;
    grin_output::write_file(&path, |w| w.write_all(text.as_bytes()))?;
    Ok(path)
}

/// [`frame_once`] `REPEATS` times: the best seconds, and the evaluations.
fn frame(field: &dyn IndexField, settings: &TraceSettings, rays: usize) -> Timing {
    let (seconds, evals) = (0..REPEATS)
        .map(|_| frame_once(field, settings, rays))
        .fold((f64::INFINITY, 0), |(best, _), (t, e)| (best.min(t), e));
    Timing { seconds, evals }
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
