//! `grin bench accuracy`: error against cost for every integrator x step policy x exit
//! method x precision on the reference cases (grin-bench), written as CSV, Markdown and
//! charts; the summary names the cheapest method per error decade.

use std::path::PathBuf;

use grin_bench::accuracy;
use grin_bench::cases::{self, Suite};
use grin_bench::report;

/// Arguments of `grin bench accuracy`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Three cases, three steps or tolerances per method, the Hermite exit only (CI's
    /// smoke test).
    #[arg(long)]
    pub quick: bool,
    /// Directory for accuracy.csv, orders.csv, summary.md and the charts.
    #[arg(short, long, default_value = "out/bench-accuracy")]
    pub output: PathBuf,
    /// Print the summary (decade table and orders) as JSON on stdout.
    #[arg(long)]
    pub json: bool,
    /// Only the case of this name, else the cases whose name contains it (e.g.
    /// `baked`): the full suite is long, and one case at a time fits a CI step.
    #[arg(long, value_name = "NAME")]
    pub case: Option<String>,
    /// No GPU column (by default the cases with a baked field are traced on the GPU
    /// too, by the render kernel's own march; without an adapter the column is skipped
    /// with a warning).
    #[arg(long)]
    pub no_gpu: bool,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let suite = if args.quick {
        Suite::Quick
    } else {
        Suite::Full
    };
    // The charts need a font: a missing one is said now, not after minutes of runs
    // whose results would then not be written (they are written all or nothing).
    grin_bench::chart::ensure_font()?;
    eprintln!("building the reference cases ...");
    let mut cases = cases::suite(suite)?;
    if let Some(want) = &args.case {
        cases = cases::select(cases, want)?;
    }
    let bar = crate::cmd::styled_bar(1, "runs [{bar:40}] {pos}/{len} {elapsed} (eta {eta})");
    // Where stderr is not a terminal (a CI log) the bar is hidden: a line per 10% instead.
    let log_lines = !std::io::IsTerminal::is_terminal(&std::io::stderr());
    let logged = std::sync::atomic::AtomicU64::new(0);
    let started = std::time::Instant::now();
    let progress = |done: u64, total: u64| {
        bar.set_length(total);
        bar.set_position(done);
        let tenth = done * 10 / total.max(1);
        if log_lines && logged.fetch_max(tenth, std::sync::atomic::Ordering::Relaxed) < tenth {
            eprintln!(
                "runs: {done}/{total} ({}%) after {:.0} s",
                tenth * 10,
                started.elapsed().as_secs_f64()
            );
        }
    };
    let run = accuracy::run(cases, args.quick, !args.no_gpu, &progress)?;
    bar.finish_and_clear();
    let mut command = String::from("grin bench accuracy");
    if args.quick {
        command.push_str(" --quick");
    }
    if let Some(want) = &args.case {
        command.push_str(&format!(" --case {want}"));
    }
    if args.no_gpu {
        command.push_str(" --no-gpu");
    }
    if !args.no_gpu
        && let Some(why) = &run.gpu.skipped
    {
        eprintln!("grin: warning: no GPU column: {why}");
    }
    let files = report::write_accuracy(&run, &args.output, &command)?;
    let rows = report::decade_rows(&run);
    if args.json {
        let summary = serde_json::json!({
            "seconds": run.seconds,
            "runs": run.points.len(),
            "failed_runs": run.points.iter().filter(|p| p.failed()).count(),
            "cases": run.cases.iter().zip(&run.references).map(|(c, r)| serde_json::json!({
                "name": c.name,
                "rays": c.rays.len(),
                "exact": c.exact.is_some(),
                "numeric_vs_exact": r.numeric_vs_exact,
                "bake_error": c.bake_error,
                "grid_bytes": c.grid.as_ref().map(|g| g.data_bytes()),
            })).collect::<Vec<_>>(),
            "decades": rows,
            "orders": run.orders,
            "gpu": serde_json::json!({
                "column": run.gpu,
                "cases": report::gpu_rows(&run),
            }),
            "output": args.output.display().to_string(),
            "files": files,
        });
        outln!("{}", serde_json::to_string_pretty(&summary)?);
        return Ok(());
    }
    outln!(
        "{} runs over {} cases in {:.1} s ({} lost rays)",
        run.points.len(),
        run.cases.len(),
        run.seconds,
        run.points.iter().filter(|p| p.failed()).count()
    );
    for r in rows.iter().filter(|r| r.precision == "f64") {
        outln!(
            "{:<34} <= {:.0e} rad: {:<48} {:>8} evals/ray   paper {}",
            r.case,
            r.target,
            r.best.clone().unwrap_or_else(|| "none reaches it".into()),
            r.best_evals.map_or("-".into(), |x| format!("{x:.0}")),
            r.paper_ratio
                .map_or("-".into(), |x| format!("{x:.1}x the evals"))
        );
    }
    if let Some(adapter) = &run.gpu.adapter {
        outln!(
            "GPU column on {adapter}: {} pipelines, {:.1} s",
            run.gpu.pipelines,
            run.gpu.seconds
        );
        for r in report::gpu_rows(&run) {
            outln!(
                "{:<34} gpu: {}/{} runs agree with the cpu f32 twin; {:.0} ns/ray (cpu f32 one thread {:.0})",
                r.case,
                r.agree,
                r.runs,
                r.gpu_ns_per_ray,
                r.cpu_f32_ns_per_ray
            );
        }
    }
    outln!("wrote {} files to {}", files.len(), args.output.display());
    Ok(())
}
