//! `grin bench accuracy`: error against cost for every integrator x step policy x exit
//! method x precision on the reference cases (grin-bench), written as CSV, Markdown and
//! charts; the summary names the cheapest method per error decade.

use std::path::PathBuf;

use grin_bench::accuracy;
use grin_bench::cases::{self, Suite};
use grin_bench::report;
use indicatif::{ProgressBar, ProgressStyle};

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
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let suite = if args.quick {
        Suite::Quick
    } else {
        Suite::Full
    };
    eprintln!("building the reference cases ...");
    let cases = cases::suite(suite)?;
    let bar = ProgressBar::new(1);
    if let Ok(style) =
        ProgressStyle::with_template("runs [{bar:40}] {pos}/{len} {elapsed} (eta {eta})")
    {
        bar.set_style(style.progress_chars("=> "));
    }
    let progress = |done: u64, total: u64| {
        bar.set_length(total);
        bar.set_position(done);
    };
    let run = accuracy::run(cases, args.quick, &progress)?;
    bar.finish_and_clear();
    let command = if args.quick {
        "grin bench accuracy --quick"
    } else {
        "grin bench accuracy"
    };
    let files = report::write_accuracy(&run, &args.output, command)?;
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
            })).collect::<Vec<_>>(),
            "decades": rows,
            "orders": run.orders,
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
    outln!("wrote {} files to {}", files.len(), args.output.display());
    Ok(())
}
