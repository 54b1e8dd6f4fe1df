//! `grin bench bake`: the paper's procedural noise (fBm with a central-difference gradient
//! at every Runge-Kutta stage) against the same medium baked, traced on the CPU
//! (grin-bench's `bake`); a row per bake as it is measured, and the JSON summary.

use std::path::PathBuf;

use grin_bench::bake::{self, Bench, Options};

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

pub fn run(args: Args) -> anyhow::Result<()> {
    let bench = Bench::new(&Options {
        scene: args.scene,
        quick: args.quick,
        rays: args.rays,
    })?;
    eprintln!(
        "procedural: {} ({} rays, {:?} / {:?})",
        bench.describe(),
        bench.rays,
        bench.settings.integrator,
        bench.settings.step
    );
    let procedural = bench.procedural();
    let (t_proc, e_proc) = (procedural.seconds, procedural.evals);
    outln!(
        "{:<34} {:>10.1} ms/frame {:>12} evals {:>8.0} ns/eval",
        "procedural (paper)",
        1e3 * t_proc,
        e_proc,
        1e9 * t_proc / e_proc.max(1) as f64
    );
    let mut rows = Vec::new();
    for (res, interp) in bench.variants() {
        let row = bench.baked(res, interp, procedural)?;
        let (t, e) = (row.seconds, row.evals);
        let label = format!("baked {res} {} i16", row.interp);
        outln!(
            "{label:<34} {:>10.1} ms/frame {:>12} evals {:>8.0} ns/eval  speedup {:>6.1}x  bake {:.2} s  {} bytes  max|dn err| {:.2e}",
            1e3 * t,
            e,
            1e9 * t / e.max(1) as f64,
            row.speedup,
            row.bake_seconds,
            row.bytes,
            row.max_err_n
        );
        rows.push(row);
    }
    let summary = bench.summary(procedural, rows);
    if let Some(dir) = &args.output {
        let path = bake::write_summary(&summary, dir)?;
        eprintln!("wrote {}", path.display());
    }
    if args.json {
        outln!("{}", serde_json::to_string_pretty(&summary)?);
    }
    Ok(())
}
