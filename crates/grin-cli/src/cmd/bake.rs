//! `grin bake`: bake a scene's medium into a `.grinf` file, at a resolution chosen from an
//! error budget (or given), cropped to the active region, under a memory cap.

use std::path::{Path, PathBuf};
use std::sync::Mutex;

use anyhow::Context;
use grin_field::bake::{self, BakeOptions, BakeReport, GradientMode};
use grin_field::baked::{Interp, Storage};

/// Arguments of `grin bake`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scene file whose [medium] is baked.
    pub scene: PathBuf,
    /// Output .grinf file (written to a temporary file, then renamed).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Nodes along the longest axis of the baked region (default: the coarsest that meets --error).
    #[arg(long)]
    pub resolution: Option<usize>,
    /// Error budget: max |n error| relative to the field's delta_n range, on random points.
    #[arg(long, default_value_t = bake::DEFAULT_ERROR_BUDGET)]
    pub error: f64,
    /// Memory cap in bytes for the baked grid (default 1G) and, when given, for what a VDB
    /// grid keeps in memory (bricks of voxels that change the index; its data box at one
    /// voxel a byte; default 2G there); suffixes k, M, G allowed: 512M.
    #[arg(long, value_parser = parse_bytes)]
    pub max_memory: Option<u64>,
    /// Interpolation stored as the file's default (and used to measure the error).
    /// Default: trilinear, and for a VDB grid whose own voxel size misses the budget,
    /// tricubic at it and on grids 2x and 4x finer (within --max-memory). With --sparse:
    /// trilinear (the default), or tricubic Catmull-Rom (bricks hold one more layer of
    /// nodes beyond each face; third order, so smooth fields need far fewer nodes).
    #[arg(long, value_enum)]
    pub interp: Option<InterpArg>,
    /// Storage (default: i16 when its rounding fits the budget, else f32).
    #[arg(long, value_enum)]
    pub storage: Option<StorageArg>,
    /// Bake the whole bounds instead of cropping to where n differs from ambient.
    #[arg(long)]
    pub no_crop: bool,
    /// Bake sparsely: bricks only where the index differs from ambient, each at the
    /// coarsest of its levels that meets --error (a version-2 .grinf, trilinear or with
    /// --interp tricubic Catmull-Rom; both backends render it).
    #[arg(long, conflicts_with_all = ["resolution", "no_crop"])]
    pub sparse: bool,
    /// With --sparse: bricks along the medium's longest axis (default: chosen, bricks of
    /// 1, 2, 4 or 8 32ths of it, whichever the probes predict holds the budget in the
    /// fewest voxels).
    #[arg(long, requires = "sparse")]
    pub bricks: Option<usize>,
    /// Print a machine-readable summary (JSON) on stdout.
    #[arg(long)]
    pub json: bool,
    /// Bake frames A..B (inclusive) of the scene's sequence, one file each: the output
    /// needs a frame token (`-o field.####.grinf`).
    #[arg(long, value_name = "A..B", value_parser = grin_scene::frames::parse_frame_range)]
    pub frames: Option<(i64, i64)>,
    /// Frames per second of the sequence (default: the scene's [animation] fps, else 24).
    #[arg(long)]
    pub fps: Option<f64>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum InterpArg {
    Trilinear,
    Tricubic,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum StorageArg {
    F32,
    I16,
}

/// Parse a byte count with an optional k/M/G suffix (powers of 1024).
pub fn parse_bytes(s: &str) -> Result<u64, String> {
    let t = s.trim();
    let (num, mult) = match t.chars().last() {
        Some('k' | 'K') => (&t[..t.len() - 1], 1u64 << 10),
        Some('m' | 'M') => (&t[..t.len() - 1], 1 << 20),
        Some('g' | 'G') => (&t[..t.len() - 1], 1 << 30),
        _ => (t, 1),
    };
    let v: f64 = num
        .trim()
        .parse()
        .map_err(|_| format!("`{s}` is not a byte count (e.g. 512M)"))?;
    if !(v.is_finite() && v > 0.0) {
        return Err(format!("`{s}` must be a positive byte count"));
    }
    Ok((v * mult as f64) as u64)
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let scene = grin_scene::load_scene(&args.scene)?;
    let fps = args.fps.unwrap_or_else(|| scene.fps());
    if !(fps.is_finite() && fps > 0.0) {
        anyhow::bail!("--fps must be a positive number of frames per second, got {fps}");
    }
    let pattern = args.output.to_string_lossy().into_owned();
    let token = grin_scene::frames::has_frame_token(&pattern);
    let Some((first, last)) = args.frames else {
        if token {
            anyhow::bail!(
                "{}: the output holds a frame token but no --frames A..B was given",
                args.output.display()
            );
        }
        let scene = match scene.animation {
            Some(a) => scene.at_frame(a.frames[0], fps),
            None => scene,
        };
        return bake_one(&args, &scene, &args.output, args.json).map(|_| ());
    };
    if !token {
        anyhow::bail!(
            "{}: with --frames the output needs a frame token, e.g. field.####.grinf",
            args.output.display()
        );
    }
    let scene_dir = args.scene.parent().unwrap_or(Path::new("."));
    let missing = grin_scene::frames::missing_frames(&scene, scene_dir, first, last);
    if !missing.is_empty() {
        anyhow::bail!(
            "{}: {} of frames {first}..{last} missing: {}",
            args.scene.display(),
            missing.len(),
            grin_scene::frames::summarize(&missing)
        );
    }
    grin_field::vdb::check_sequence(&scene, scene_dir, first, last)
        .with_context(|| format!("{}", args.scene.display()))?;
    let mut all = Vec::new();
    for f in first..=last {
        let out = PathBuf::from(
            grin_scene::frames::substitute_frame(&pattern, f).unwrap_or_else(|| pattern.clone()),
        );
        if !args.json {
            outln!("frame     {f}");
        }
        bake_one(&args, &scene.at_frame(f, fps), &out, false)
            .with_context(|| format!("frame {f}"))
            .map(|j| all.push(j))?;
    }
    if args.json {
        outln!("{}", serde_json::to_string_pretty(&all)?);
    }
    Ok(())
}

/// Bake `scene`'s medium to `output`; prints the summary (JSON when `json`) unless a
/// sequence collects it, and returns it as JSON.
fn bake_one(
    args: &Args,
    scene: &grin_scene::Scene,
    output: &Path,
    json: bool,
) -> anyhow::Result<serde_json::Value> {
    let _inputs = super::protect_scene(&args.scene, scene);
    let medium = scene.medium.as_ref().with_context(|| {
        format!(
            "{}: the scene has no [medium] to bake",
            args.scene.display()
        )
    })?;
    if let Some(dir) = output.parent()
        && !dir.as_os_str().is_empty()
        && !dir.is_dir()
    {
        anyhow::bail!("{}: output directory does not exist", dir.display());
    }
    let scene_dir = args.scene.parent().unwrap_or(Path::new("."));
    // An explicit --max-memory caps what a VDB grid keeps in memory too (its bricks of
    // voxels that change the index, and its data box at a voxel a byte), not only the bake.
    let vdb_cap = args
        .max_memory
        .unwrap_or(grin_field::vdb::DEFAULT_MAX_DENSE_BYTES);
    let field = grin_field::build_field_capped(medium, scene_dir, vdb_cap)
        .with_context(|| format!("{}: [medium]", args.scene.display()))?;
    for w in field.warnings() {
        eprintln!("grin: warning: {w}");
    }
    if args.sparse {
        return bake_sparse(args, field.as_ref(), &medium.field, output, json);
    }
    let opts = BakeOptions {
        resolution: args.resolution,
        error_budget: args.error,
        max_memory: args.max_memory.unwrap_or(bake::DEFAULT_MAX_MEMORY),
        interp: interp_of(args),
        cubic_past_source: args.interp.is_none(),
        storage: args.storage.map(|s| match s {
            StorageArg::F32 => Storage::F32,
            StorageArg::I16 => Storage::I16,
        }),
        crop: !args.no_crop,
        gradient: GradientMode::for_field(&medium.field),
        ..Default::default()
    };
    let (bar, progress) = stage_bar();
    let result = bake::bake(field.as_ref(), &opts, &progress);
    bar.finish_and_clear();
    let (baked, report) =
        result.with_context(|| format!("{}: bake failed", args.scene.display()))?;
    grin_field::grinf::save(&baked, output)?;
    if report.source_limited {
        // What would reduce the error: the search stops at 4x the source's voxel density
        // (a finer grid resolves only the interpolation between the same voxels), or at
        // the memory cap.
        let less = if report.memory_capped {
            format!(
                "--max-memory above {} bytes for a finer tricubic grid, or --resolution N",
                opts.max_memory
            )
        } else {
            format!(
                "the search stops 4x finer than the source's voxels; --resolution N for a \
                 finer grid (2x: {})",
                2 * (report.resolution - 1) + 1
            )
        };
        eprintln!(
            "grin: warning: {}: the budget {:.1e} is not met by the grids tried at and past \
             the source's own voxel size (best: relative error {:.2e}, {} nodes on the \
             longest axis, {}): what is left is that interpolation against grin's \
             Catmull-Rom between the same voxels, not missing data; the bake is kept. Less: \
             {less}",
            args.scene.display(),
            report.budget,
            report.relative_error,
            report.resolution,
            report.interp.name(),
        );
    }
    if !report.meets_budget && !report.source_limited && !json_on_stderr(args, output) {
        eprintln!(
            "grin: warning: {}: the budget {:.1e} is not met (relative error {:.2e} at {} nodes on the longest axis); the bake is kept: without --resolution grin chooses the grid that meets it",
            args.scene.display(),
            report.budget,
            report.relative_error,
            report.resolution,
        );
    }
    let summary = summary_json(output, &field.describe(), &report);
    // `-o -`: the binary is stdout's; the summary goes to stderr.
    let to_stream = crate::is_stream(output);
    if json {
        crate::report(to_stream, serde_json::to_string_pretty(&summary)?);
    } else if !args.json {
        crate::report(to_stream, summary_text(output, &field.describe(), &report));
    }
    Ok(summary)
}

/// The summary of a bake, a line per aspect.
fn summary_text(out: &Path, source: &str, r: &BakeReport) -> String {
    let [nx, ny, nz] = r.dims;
    let mut lines = Vec::new();
    lines.push(format!("baked     {source}"));
    lines.push(format!("to        {}", out.display()));
    lines.push(format!(
        "grid      {nx}x{ny}x{nz} ({} nodes on the longest axis, {} choice), {} {}",
        r.resolution,
        if r.trials.len() > 1 {
            "automatic"
        } else {
            "fixed"
        },
        r.interp.name(),
        r.storage.name()
    ));
    lines.push(format!(
        "region    {:?} .. {:?}{}",
        r.grid_min.to_array(),
        r.grid_max.to_array(),
        if r.cropped { " (cropped)" } else { "" }
    ));
    lines.push(format!("bytes     {}", r.bytes));
    lines.push(format!(
        "error     n: max {:.3e} rms {:.3e} ({:.3e} of the delta_n range {:.3e}; budget {:.1e}{})",
        r.errors.max_err_n,
        r.errors.rms_err_n,
        r.relative_error,
        r.delta_n_range,
        r.budget,
        if r.meets_budget {
            ", met"
        } else if r.source_limited {
            ", not met at or past the source's voxel size"
        } else {
            ", NOT met"
        }
    ));
    lines.push(format!(
        "          grad n: max {:.3e} rms {:.3e} ({} random points)",
        r.errors.max_err_grad, r.errors.rms_err_grad, r.errors.points
    ));
    lines.push(format!(
        "macro     {:.1}% of cells homogeneous",
        100.0 * r.homogeneous_cells
    ));
    lines.push(format!(
        "time      {:.2} s ({} source evaluations)",
        r.seconds, r.source_evals
    ));
    lines.join("\n")
}

/// Add a bake's measured errors against the budget to the JSON object `v`, as both bake
/// summaries list them: the error statistics `e`, the range of delta n, the error
/// relative to it, the budget, and (met, source-limited).
fn add_errors(
    v: &mut serde_json::Value,
    e: &grin_field::bake::ErrorStats,
    delta_n_range: f64,
    relative_error: f64,
    budget: f64,
    met: (bool, bool),
) {
    let errors = serde_json::json!({
        "max_err_n": e.max_err_n,
        "rms_err_n": e.rms_err_n,
        "max_err_grad": e.max_err_grad,
        "rms_err_grad": e.rms_err_grad,
        "error_points": e.points,
        "delta_n_range": delta_n_range,
        "relative_error": relative_error,
        "budget": budget,
        "meets_budget": met.0,
        "source_limited": met.1,
    });
    if let (Some(o), serde_json::Value::Object(errors)) = (v.as_object_mut(), errors) {
        o.extend(errors);
    }
}

fn summary_json(out: &Path, source: &str, r: &BakeReport) -> serde_json::Value {
    let mut v = serde_json::json!({
        "output": out.display().to_string(),
        "source": source,
        "resolution": r.resolution,
        "dims": r.dims,
        "grid_min": r.grid_min.to_array(),
        "grid_max": r.grid_max.to_array(),
        "cropped": r.cropped,
        "storage": r.storage.name(),
        "interp": r.interp.name(),
        "bytes": r.bytes,
        "memory_capped": r.memory_capped,
        "trials": r.trials.iter().map(|t| serde_json::json!({
            "resolution": t.resolution,
            "dims": t.dims,
            "storage": t.storage.name(),
            "interp": t.interp.name(),
            "relative_error": t.relative_error,
        })).collect::<Vec<_>>(),
        "seconds": r.seconds,
        "source_evals": r.source_evals,
        "homogeneous_cells": r.homogeneous_cells,
    });
    let met = (r.meets_budget, r.source_limited);
    add_errors(
        &mut v,
        &r.errors,
        r.delta_n_range,
        r.relative_error,
        r.budget,
        met,
    );
    v
}

/// A progress bar for a bake's stages and the callback that drives it (a stage's name,
/// done, total).
fn stage_bar() -> (indicatif::ProgressBar, impl Fn(&str, u64, u64) + Sync) {
    let bar = super::styled_bar(1, "{msg:>24} [{bar:40}] {pos}/{len} {elapsed}");
    let stage = Mutex::new(String::new());
    let driven = bar.clone();
    let progress = move |name: &str, done: u64, total: u64| {
        if let Ok(mut s) = stage.lock()
            && *s != name
        {
            *s = name.to_string();
            driven.set_message(name.to_string());
            driven.set_length(total);
        }
        driven.set_position(done);
    };
    (bar, progress)
}

/// The interpolation `--interp` asks for (trilinear where it is not given).
fn interp_of(args: &Args) -> Interp {
    match args.interp {
        None | Some(InterpArg::Trilinear) => Interp::Trilinear,
        Some(InterpArg::Tricubic) => Interp::Tricubic,
    }
}

/// `grin bake --sparse`: bake `field` into a sparse .grinf at `output`.
fn bake_sparse(
    args: &Args,
    field: &dyn grin_field::IndexField,
    spec: &grin_scene::FieldSpec,
    output: &Path,
    json: bool,
) -> anyhow::Result<serde_json::Value> {
    use grin_field::sparse::bake::{SparseOptions, bake_sparse};
    let opts = SparseOptions {
        error_budget: args.error,
        max_memory: args.max_memory.unwrap_or(bake::DEFAULT_MAX_MEMORY),
        storage: args.storage.map(|s| match s {
            StorageArg::F32 => Storage::F32,
            StorageArg::I16 => Storage::I16,
        }),
        top_bricks: args.bricks,
        gradient: GradientMode::for_field(spec),
        interp: interp_of(args),
        ..Default::default()
    };
    let (bar, progress) = stage_bar();
    let result = bake_sparse(field, &opts, &progress);
    bar.finish_and_clear();
    let (sparse, r) = result.with_context(|| format!("{}: bake failed", args.scene.display()))?;
    grin_field::sparse::file::save(&sparse, output)?;
    if r.source_limited {
        eprintln!(
            "grin: warning: {}: the budget {:.1e} is not met (relative error {:.2e}): {} bricks \
             reached half the source's voxel size, where what is left is the source's own \
             interpolation, not missing data; the bake is kept",
            args.scene.display(),
            r.budget,
            r.relative_error,
            r.limited_bricks
        );
    } else if !r.meets_budget && !json_on_stderr(args, output) {
        eprintln!(
            "grin: warning: {}: the budget {:.1e} is not met (relative error {:.2e}); the bake is kept",
            args.scene.display(),
            r.budget,
            r.relative_error,
        );
    }
    let mut summary = serde_json::json!({
        "output": output.display().to_string(),
        "source": field.describe(),
        "sparse": true,
        "bricks_per_axis": r.top.dims,
        "brick_edge": r.top.edge,
        "active_bricks": r.active_bricks,
        "total_bricks": r.total_bricks,
        "levels": r.levels,
        "finest_spacing": r.finest_spacing,
        "storage": r.storage.name(),
        "interp": sparse.interp().name(),
        "gradient_of_n": sparse.gradient_of_n(),
        "bytes": r.bytes,
        "memory_bytes": r.memory_bytes,
        "dense_bytes": r.dense_bytes,
        "limited_bricks": r.limited_bricks,
        "proven_empty": r.proven_empty,
        "seconds": r.seconds,
        "source_evals": r.source_evals,
    });
    let met = (r.meets_budget, r.source_limited);
    add_errors(
        &mut summary,
        &r.errors,
        r.delta_n_range,
        r.relative_error,
        r.budget,
        met,
    );
    let to_stream = crate::is_stream(output);
    if json {
        crate::report(to_stream, serde_json::to_string_pretty(&summary)?);
    } else if !args.json {
        let levels: Vec<String> = r
            .levels
            .iter()
            .enumerate()
            .filter(|(_, n)| **n > 0)
            .map(|(l, n)| {
                let cells = grin_field::sparse::cells_of(l as u8);
                format!(
                    "{n} x {}^3",
                    grin_field::sparse::nodes_of(cells, sparse.apron())
                )
            })
            .collect();
        let text = [
            format!("baked     {} (sparse)", field.describe()),
            format!("to        {}", output.display()),
            format!(
                "bricks    {} of {} active ({}x{}x{} of edge {:.4}), nodes {}",
                r.active_bricks,
                r.total_bricks,
                r.top.dims[0],
                r.top.dims[1],
                r.top.dims[2],
                r.top.edge,
                if levels.is_empty() { "none".to_string() } else { levels.join(", ") }
            ),
            format!(
                "bytes     {} ({} {}; a dense grid at the finest spacing {:.4} over the active bricks: {})",
                r.bytes,
                r.storage.name(),
                sparse.interp().name(),
                r.finest_spacing,
                r.dense_bytes
            ),
            format!(
                "error     n: max {:.3e} rms {:.3e} ({:.3e} of the delta_n range {:.3e}; budget {:.1e}{})",
                r.errors.max_err_n,
                r.errors.rms_err_n,
                r.relative_error,
                r.delta_n_range,
                r.budget,
                if r.meets_budget {
                    ", met"
                } else {
                    ", not met at half the source's voxel size"
                }
            ),
            format!(
                "          grad n: max {:.3e} rms {:.3e} ({} random points)",
                r.errors.max_err_grad, r.errors.rms_err_grad, r.errors.points
            ),
            format!(
                "time      {:.2} s ({} source evaluations)",
                r.seconds, r.source_evals
            ),
        ]
        .join("\n");
        crate::report(to_stream, text);
    }
    Ok(summary)
}

/// With `-o - --json` stderr carries the JSON summary alone (its `meets_budget` says what
/// a warning would).
fn json_on_stderr(args: &Args, output: &Path) -> bool {
    args.json && crate::is_stream(output)
}
