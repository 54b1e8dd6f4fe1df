//! `grin dataset`: training data for learning, rendered in batches that resume and shard.

use std::path::PathBuf;

use grin_pipeline::dataset::Bos;
use grin_pipeline::{Backend, Renderer};
use indicatif::{ProgressBar, ProgressStyle};

/// Arguments of `grin dataset`.
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(subcommand)]
    pub kind: Kind,
}

#[derive(Debug, clap::Subcommand)]
pub enum Kind {
    /// Background-oriented schlieren pairs (reference and distorted dot images) of
    /// randomised hot-air plumes, with the true displacement, deflection, the index on a
    /// slice, and the camera as JSON (docs/scale.md).
    Bos(BosArgs),
}

#[derive(Debug, clap::Args)]
pub struct BosArgs {
    /// Output folder (made if missing).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Samples in the dataset (indices 0..COUNT).
    #[arg(long)]
    pub count: u64,
    /// Dataset seed: sample i is drawn from (seed, i) alone.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Image size.
    #[arg(long, value_name = "WxH", value_parser = crate::cmd::render::parse_size, default_value = "128x96")]
    pub size: (u32, u32),
    /// Render only shard I of N (0-based; contiguous index ranges): a Slurm array task
    /// passes $SLURM_ARRAY_TASK_ID/$SLURM_ARRAY_TASK_COUNT.
    #[arg(long, value_name = "I/N", value_parser = grin_scene::frames::parse_shard)]
    pub shard: Option<(u32, u32)>,
    /// Renderer.
    #[arg(long, value_enum, default_value_t = Backend::Cpu)]
    pub backend: Backend,
    /// Print the run's summary as JSON on stdout.
    #[arg(long)]
    pub json: bool,
}

/// Most samples one dataset may hold.
const MAX_COUNT: u64 = 100_000_000;

pub fn run(args: Args) -> anyhow::Result<()> {
    match args.kind {
        Kind::Bos(a) => bos(a),
    }
}

fn bos(args: BosArgs) -> anyhow::Result<()> {
    if args.count == 0 || args.count > MAX_COUNT {
        anyhow::bail!(
            "--count {}: a dataset holds 1 to {MAX_COUNT} samples",
            args.count
        );
    }
    let all = grin_scene::frames::FrameList::from_range(0, args.count as i64 - 1);
    let indices: Vec<u64> = match args.shard {
        Some((i, n)) => all.shard(i, n),
        None => all.frames().to_vec(),
    }
    .into_iter()
    .map(|i| i as u64)
    .collect();
    let dataset = Bos {
        seed: args.seed,
        width: args.size.0,
        height: args.size.1,
    };
    let renderer = Renderer::new(args.backend, true);
    let bar = ProgressBar::new(indices.len() as u64);
    if let Ok(style) =
        ProgressStyle::with_template("samples [{bar:40}] {pos}/{len} {elapsed}<{eta}")
    {
        bar.set_style(style.progress_chars("=> "));
    }
    let summary = dataset.write(&renderer, &args.output, args.count, &indices, &|done, _| {
        bar.set_position(done as u64)
    })?;
    bar.finish_and_clear();
    if args.json {
        outln!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        outln!(
            "{} samples rendered, {} skipped (complete already) in {:.2} s: {:.2} samples/s -> {}{}",
            summary.rendered,
            summary.skipped,
            summary.seconds,
            summary.samples_per_second,
            args.output.display(),
            if summary.manifest {
                " (manifest.jsonl written: every sample is there)"
            } else {
                " (manifest.jsonl waits for the other shards' samples)"
            }
        );
    }
    Ok(())
}
