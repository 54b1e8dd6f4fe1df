//! `grin dataset`: training data for learning, rendered in batches that resume and shard.

use std::path::PathBuf;

use grin_pipeline::dataset::{Dataset, Kind, Media};
use grin_pipeline::{Backend, Renderer};

/// Arguments of `grin dataset`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// What a sample shows: bos (a dot plate without and with the medium), schlieren (a
    /// knife-edge image) or haze (a background without and with the medium, and its ST map).
    #[arg(value_enum)]
    pub kind: Kind,
    /// Output folder (made if missing).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Samples in the dataset (indices 0..COUNT).
    #[arg(long)]
    pub count: u64,
    /// Dataset seed: sample i is drawn from (seed, i) alone.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Media: plumes (Gaussian hot-air plumes), noise (fBm or turbulence), expr (a hot
    /// layer with waves) or scene:PATH (the [medium] of a scene file at a random frame of
    /// its [animation]: a pool of VDB frames).
    #[arg(long, default_value = "plumes", value_parser = Media::parse)]
    pub media: Media,
    /// haze: a background plate image (PNG, EXR or HDR), one drawn per sample; repeat for
    /// a pool. Without it, a checker wall of random scale and contrast.
    #[arg(long, value_name = "IMAGE")]
    pub plate: Vec<PathBuf>,
    /// haze: a texture image on the wall behind the medium (filling the view), one drawn
    /// per sample with the plates; repeat for a pool.
    #[arg(long, value_name = "IMAGE")]
    pub texture: Vec<PathBuf>,
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
    if !(args.plate.is_empty() && args.texture.is_empty()) && args.kind != Kind::Haze {
        anyhow::bail!("--plate, --texture: only haze samples have a background image");
    }
    for (flag, p) in args
        .plate
        .iter()
        .map(|p| ("--plate", p))
        .chain(args.texture.iter().map(|p| ("--texture", p)))
    {
        if !p.is_file() {
            anyhow::bail!("{flag} {}: no such image file", p.display());
        }
    }
    let mut dataset = Dataset::new(args.kind, args.media, args.seed, args.size.0, args.size.1);
    dataset.plates = args.plate;
    dataset.textures = args.texture;
    let renderer = Renderer::new(args.backend, true);
    let bar = super::styled_bar(
        indices.len() as u64,
        "samples [{bar:40}] {pos}/{len} {elapsed}<{eta}",
    );
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
