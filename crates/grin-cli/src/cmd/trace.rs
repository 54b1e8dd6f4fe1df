//! `grin trace`: ray table in, ray table out. Reads `ox,oy,oz,dx,dy,dz` rows, traces each
//! ray through the scene's medium with the CPU reference (f64, or f32 like the GPU) and
//! writes the input columns plus `status,px,py,pz,qx,qy,qz,opl,length,steps,evals`.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::bail;
use grin_pipeline::trace::{TraceOverrides, TracePlan};
use grin_scene::{ExitMethod, IntegratorKind, StepSpec};
use grin_trace::table::{self, TableFormat, TableSummary};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// Tables at least this long get a progress bar.
const PROGRESS_MIN_RAYS: usize = 10_000;

/// Output format of the ray table.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    Csv,
    Json,
}

/// How the exit point is found (overrides the scene's `exit`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Exit {
    Hermite,
    Bisection,
}

/// Arguments of `grin trace`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The scene file (TOML) whose [medium] the rays cross.
    pub scene: PathBuf,
    /// Input ray table (CSV with header `ox,oy,oz,dx,dy,dz`).
    #[arg(long)]
    pub rays: PathBuf,
    /// Output ray table.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Integrator, overriding the scene's: euler | symplectic-euler | verlet | sharma | rk4 | adaptive.
    #[arg(long, value_parser = grin_pipeline::trace::parse_integrator)]
    pub integrator: Option<IntegratorKind>,
    /// Step policy, overriding the scene's: fixed=DS | heuristic=MIN,MAX[,AMPLITUDE] |
    /// adaptive=TOL | auto=RAD (an exit-direction error of RAD radians, and an optical-path
    /// error of RAD times the bounds' radius, as measured on the pilot rays).
    #[arg(long, value_parser = grin_pipeline::trace::parse_step)]
    pub step: Option<StepSpec>,
    /// Per-ray step cap, overriding the scene's max_steps.
    #[arg(long)]
    pub max_steps: Option<u32>,
    /// Exit-point method, overriding the scene's.
    #[arg(long, value_enum)]
    pub exit: Option<Exit>,
    /// Integrate in f32 (what the GPU does) instead of f64.
    #[arg(long)]
    pub f32: bool,
    /// Output format (default: json if the output name ends in .json, else csv).
    #[arg(long, value_enum)]
    pub format: Option<Format>,
    /// Print a machine-readable summary (JSON) on stdout.
    #[arg(long)]
    pub json: bool,
}

/// The summary printed with `--json`.
#[derive(Debug, serde::Serialize)]
struct Summary<'a> {
    output: &'a Path,
    field: String,
    integrator: &'static str,
    /// As in the scene file: `{"fixed": 0.01}`, `{"adaptive": {"tolerance": 1e-8, ...}}`.
    step: grin_scene::StepSpec,
    precision: &'static str,
    rays: usize,
    exited: usize,
    /// Left the medium with an error estimate above `estimate_limit`.
    degraded: usize,
    /// The exit-direction error asked for (rad).
    accuracy: f64,
    /// A ray whose own error estimate is above this (rad) is `degraded`: `accuracy`, or
    /// 10x it where the pilots measured their choice within it.
    estimate_limit: f64,
    /// The largest error estimate of an `exited` ray (rad).
    worst_estimate: f64,
    missed: usize,
    absorbed: usize,
    max_steps: usize,
    error: usize,
    mean_steps: f64,
    mean_evals: f64,
    /// Tracing alone.
    seconds: f64,
    /// Reading, tracing and writing the table (the pilots before it not counted).
    total_seconds: f64,
    rays_per_second: f64,
    /// `step = { auto = ... }`: what the pilot rays chose.
    #[serde(skip_serializing_if = "Option::is_none")]
    auto: Option<grin_trace::auto::AutoChoice>,
    /// `step = { auto = ... }` resolved without pilots (a table too small for them): why.
    #[serde(skip_serializing_if = "Option::is_none")]
    auto_note: Option<String>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let scene = grin_scene::load_scene(&args.scene)?;
    let scene_dir = args.scene.parent().unwrap_or_else(|| Path::new("."));
    let label = args.scene.display().to_string();
    if scene.medium.is_none() {
        bail!("{label}: the scene has no [medium] to trace rays through");
    }
    let _inputs = (
        super::protect_scene(&args.scene, &scene),
        grin_output::protect_inputs([&args.rays]),
    );
    // The table streams: the first batch is read now (its rays are the pilots'), the rest
    // while the output is written, a batch at a time.
    let mut reader = table::RayReader::open(&args.rays)?;
    let mut rows = Vec::new();
    reader.next_batch(table::BATCH_ROWS, &mut rows)?;
    let overrides = TraceOverrides {
        integrator: args.integrator,
        step: args.step,
        max_steps: args.max_steps,
        exit: args.exit.map(|e| match e {
            Exit::Hermite => ExitMethod::Hermite,
            Exit::Bisection => ExitMethod::Bisection,
        }),
        f32: args.f32,
    };
    let plan = TracePlan::new(&scene, scene_dir, &label, &overrides, &rows)?;
    for w in plan.field.warnings() {
        eprintln!("grin: warning: {w}");
    }
    if let Some(w) = plan.auto.as_ref().and_then(|a| a.unmet_warning("tracing")) {
        eprintln!("grin: warning: {w}");
    }
    let (field, settings) = (&plan.field, plan.settings);
    let (auto, auto_note) = (plan.auto.clone(), plan.auto_note.clone());
    let format = match args.format {
        Some(Format::Json) => TableFormat::Json,
        Some(Format::Csv) => TableFormat::Csv,
        None if args
            .output
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("json")) =>
        {
            TableFormat::Json
        }
        None => TableFormat::Csv,
    };

    // Progress in bytes of the input where its size is known, else in rays.
    let input_bytes = std::fs::metadata(&args.rays)
        .ok()
        .filter(|m| m.is_file())
        .map(|m| m.len());
    let bar = match input_bytes {
        _ if rows.len() < PROGRESS_MIN_RAYS => ProgressBar::hidden(),
        Some(len) => {
            let bar = ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::stderr());
            bar.set_style(super::bar_style(
                "tracing {bar:40} {percent}% of the table, {msg} rays ({elapsed}, eta {eta})",
            ));
            bar
        }
        None => {
            let bar = ProgressBar::with_draw_target(None, ProgressDrawTarget::stderr());
            bar.set_style(
                ProgressStyle::with_template("tracing {msg} rays ({elapsed})")
                    .unwrap_or_else(|_| ProgressStyle::default_spinner()),
            );
            bar
        }
    };
    let wall = Instant::now();
    let mut seconds = 0.0;
    let mut s = TableSummary::default();
    let mut failed: Option<table::TableError> = None;
    // The input lines of the first few rays that ended `error` (the summary counts them).
    let mut error_lines = Vec::new();
    let written = grin_output::write_file(&args.output, |w| {
        let mut out = table::TableWriter::new(format, reader.extra_columns());
        let mut results = Vec::new();
        loop {
            let start = Instant::now();
            plan.trace_into(&rows, &mut results);
            seconds += start.elapsed().as_secs_f64();
            s.add(&results);
            let errors = rows.iter().zip(&results);
            let errors = errors.filter(|(_, r)| r.status == grin_trace::RayStatus::Error);
            let room = table::LINES_NAMED - error_lines.len();
            error_lines.extend(errors.take(room).map(|(row, _)| row.line));
            out.rows(w, &rows, &results)?;
            bar.set_message(s.rays.to_string());
            bar.set_position(reader.bytes_read());
            rows.clear();
            match reader.next_batch(table::BATCH_ROWS, &mut rows) {
                Ok(0) => break,
                Ok(_) => {}
                Err(e) => {
                    let text = e.to_string();
                    failed = Some(e);
                    return Err(std::io::Error::other(text));
                }
            }
        }
        out.finish(w)
    });
    bar.finish_and_clear();
    if let Some(e) = failed {
        return Err(e.into());
    }
    written?;
    let total_seconds = wall.elapsed().as_secs_f64();

    let precision = if args.f32 { "f32" } else { "f64" };
    eprintln!(
        "traced {} rays ({}, {}, {precision}) in {seconds:.3} s ({total_seconds:.3} s with reading and writing): {} exited, {} degraded, {} missed, {} max_steps, {} absorbed, {} error; mean {:.1} steps, {:.1} evals per ray -> {}",
        s.rays,
        field.describe(),
        settings.integrator.name(),
        s.exited,
        s.degraded,
        s.missed,
        s.max_steps,
        s.absorbed,
        s.error,
        s.mean_steps,
        s.mean_evals,
        args.output.display()
    );
    if let Some(a) = &auto {
        eprintln!("{}", a.summary_line());
    }
    if let Some(note) = &auto_note {
        eprintln!("{note}");
    }
    eprintln!(
        "exited rays' own error estimates: at most {:.1e} rad (asked {:.1e})",
        s.worst_estimate, settings.accuracy
    );
    if !reader.replaced_columns().is_empty() {
        eprintln!(
            "grin: warning: {}: input columns named as results ({}) are replaced by this trace's, not passed through",
            args.rays.display(),
            reader.replaced_columns().join(", ")
        );
    }
    let (comments, comment_lines) = reader.comments_after_header();
    if comments > 0 {
        eprintln!(
            "grin: warning: {}: `#` comment lines after the header skipped: {comments} ({}); a row whose first value starts with `#` must quote it",
            args.rays.display(),
            name_lines(comment_lines, comments)
        );
    }
    if s.error > 0 {
        eprintln!(
            "grin: warning: {}: rays that ended `error`: {} ({}): a NaN or infinite value or a zero direction in the row, or the ray met n <= 0 or a non-finite field",
            args.rays.display(),
            s.error,
            name_lines(&error_lines, s.error)
        );
    }
    if s.degraded > 0 {
        eprintln!(
            "grin: warning: {} rays ended `degraded`: their own error estimate is above the {:.1e} rad they are held to (asked {:.1e}) (steps too coarse for the field there, a grazing exit or near miss of the surface, or a bake's n error amplified at a grazing crossing); shorter steps or step = {{ auto = ... }} without an integrator resolve the first",
            s.degraded, settings.estimate_limit, settings.accuracy
        );
    }
    if args.json {
        let summary = Summary {
            output: &args.output,
            field: field.describe(),
            integrator: settings.integrator.name(),
            step: settings.step,
            precision,
            rays: s.rays,
            exited: s.exited,
            degraded: s.degraded,
            accuracy: settings.accuracy,
            estimate_limit: settings.estimate_limit,
            worst_estimate: s.worst_estimate,
            missed: s.missed,
            absorbed: s.absorbed,
            max_steps: s.max_steps,
            error: s.error,
            mean_steps: s.mean_steps,
            mean_evals: s.mean_evals,
            seconds,
            total_seconds,
            rays_per_second: if seconds > 0.0 {
                s.rays as f64 / seconds
            } else {
                0.0
            },
            auto,
            auto_note,
        };
        // Where the table itself went to a stream (`-o -`, a device: it may be stdout), the
        // summary goes to stderr, as `grin render` does.
        crate::report(
            crate::is_stream(&args.output),
            serde_json::to_string(&summary)?,
        );
    }
    Ok(())
}

/// `line 4`, `lines 4, 7 and 9`, `lines 4, 7, 9, 12, 15 and 3 more`: the first `lines` of
/// `count`.
fn name_lines(lines: &[usize], count: usize) -> String {
    let listed: Vec<String> = lines.iter().map(usize::to_string).collect();
    let more = count.saturating_sub(lines.len());
    match (listed.as_slice(), more) {
        ([one], 0) => format!("line {one}"),
        (_, 0) if listed.len() > 1 => {
            let (last, rest) = listed.split_last().expect("two or more");
            format!("lines {} and {last}", rest.join(", "))
        }
        _ => format!("lines {} and {more} more", listed.join(", ")),
    }
}
