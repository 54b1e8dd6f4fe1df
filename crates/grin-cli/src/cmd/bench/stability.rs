//! `grin bench stability`: the matrix of hard cases x methods (grin-bench), each cell
//! converged / degraded / failed, and silent where grin reported a wrong answer as
//! `exited`.

use std::path::PathBuf;

use grin_bench::report;
use grin_bench::stability::{self, Outcome};

/// Arguments of `grin bench stability`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Fewer methods per case (CI's smoke test).
    #[arg(long)]
    pub quick: bool,
    /// Directory for stability.md and stability.csv.
    #[arg(short, long, default_value = "out/bench-stability")]
    pub output: PathBuf,
    /// Print every cell as JSON on stdout.
    #[arg(long)]
    pub json: bool,
    /// No GPU rows (by default the full matrix adds the render kernel's march of each
    /// case as `grin render --backend gpu` bakes it; without an adapter they are skipped
    /// with a warning).
    #[arg(long)]
    pub no_gpu: bool,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let bar = crate::cmd::styled_bar(1, "cells [{bar:40}] {pos}/{len} {elapsed}");
    let progress = |done: u64, total: u64| {
        bar.set_length(total);
        bar.set_position(done);
    };
    let m = stability::run(args.quick, !args.no_gpu, &progress)?;
    bar.finish_and_clear();
    let command = match (args.quick, args.no_gpu) {
        (true, _) => "grin bench stability --quick",
        (false, true) => "grin bench stability --no-gpu",
        (false, false) => "grin bench stability",
    };
    if let Some(note) = m.gpu.as_deref().filter(|n| n.starts_with("no GPU")) {
        eprintln!("grin: warning: {note}");
    }
    let files = report::write_stability(&m, &args.output, command)?;
    let count = |o: Outcome| m.cells.iter().filter(|c| c.outcome == o).count();
    let silent = m.cells.iter().filter(|c| c.silent).count();
    if args.json {
        let summary = serde_json::json!({
            "seconds": m.seconds,
            "cells": m.cells,
            "converged": count(Outcome::Converged),
            "degraded": count(Outcome::Degraded),
            "failed": count(Outcome::Failed),
            "silent": silent,
            "gpu": m.gpu,
            "gpu_warnings": m.gpu_warnings,
            "output": args.output.display().to_string(),
            "files": files,
        });
        outln!("{}", serde_json::to_string_pretty(&summary)?);
        return Ok(());
    }
    for (case, _, _) in &m.cases {
        let cells: Vec<_> = m.cells.iter().filter(|c| c.case == *case).collect();
        let n = |o: Outcome| cells.iter().filter(|c| c.outcome == o).count();
        let s = cells.iter().filter(|c| c.silent).count();
        outln!(
            "{case:<28} converged {:>3}  degraded {:>3}  failed {:>3}  silent {:>3}",
            n(Outcome::Converged),
            n(Outcome::Degraded),
            n(Outcome::Failed),
            s
        );
    }
    outln!(
        "{} cells in {:.1} s: {} converged, {} degraded, {} failed; {silent} silent wrong answers; wrote {}",
        m.cells.len(),
        m.seconds,
        count(Outcome::Converged),
        count(Outcome::Degraded),
        count(Outcome::Failed),
        args.output.join("stability.md").display()
    );
    Ok(())
}
