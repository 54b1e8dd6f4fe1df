//! `grin bench speed`: the GPU marcher (wgpu, lavapipe without a GPU) and the CPU
//! reference on the same baked fields (grin-bench's `speed`), printed as a table or
//! JSON.

use std::cell::OnceCell;
use std::path::PathBuf;

use grin_bench::speed::{self, Options};
use indicatif::ProgressBar;

/// Arguments of `grin bench speed`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Smaller images, coarser bakes and one timed frame (for CI and smoke tests).
    #[arg(long)]
    pub quick: bool,
    /// Print the results as JSON on stdout.
    #[arg(long)]
    pub json: bool,
    /// Directory holding paper-a.toml, paper-c.toml and heat-haze.toml.
    #[arg(long, default_value = "data/scenes")]
    pub scenes: PathBuf,
    /// Skip the CPU backend.
    #[arg(long)]
    pub gpu_only: bool,
    /// Image size instead of 640x360 (160x90 with --quick), e.g. 1920x1080 on a real GPU.
    #[arg(long, value_name = "WxH", value_parser = crate::cmd::render::parse_size)]
    pub size: Option<(u32, u32)>,
    /// Timed frames per backend and scene instead of 3 (1 with --quick).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=1000))]
    pub frames: Option<u32>,
}

/// The progress bar, made when the frames start (after the scenes are loaded and baked).
struct Bar(OnceCell<ProgressBar>);

impl speed::Progress for Bar {
    fn begin(&self, len: u64) {
        let bar = crate::cmd::styled_bar(len, "{prefix} [{bar:30}] {pos}/{len} {msg} {elapsed}");
        bar.set_prefix("bench speed");
        let _ = self.0.set(bar);
    }

    fn phase(&self, what: &str) {
        if let Some(bar) = self.0.get() {
            bar.set_message(what.to_owned());
        }
    }

    fn advance(&self) {
        if let Some(bar) = self.0.get() {
            bar.inc(1);
        }
    }

    fn finish(&self) {
        if let Some(bar) = self.0.get() {
            bar.finish_and_clear();
        }
    }

    fn warn(&self, message: &str) {
        eprintln!("grin: warning: {message}");
    }
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let options = Options {
        quick: args.quick,
        scenes: args.scenes,
        gpu_only: args.gpu_only,
        size: args.size,
        frames: args.frames,
    };
    let report = speed::run(&options, &Bar(OnceCell::new()))?;
    if args.json {
        outln!("{}", serde_json::to_string_pretty(&report)?);
        return Ok(());
    }
    outln!(
        "adapter: {} | cpu: {} threads | bakes {}^3-class, both backends",
        report.adapter,
        report.cpu_threads,
        report.bake_resolution
    );
    outln!(
        "{:<24} {:<4} {:>9} {:>22} {:>10} {:>11} {:>9} {:>9} {:>12}",
        "scene",
        "",
        "size",
        "ms/frame min/med/max",
        "device ms",
        "Mrays/s",
        "steps/ray",
        "evals/ray",
        "Msteps/s"
    );
    for r in &report.runs {
        outln!(
            "{:<24} {:<4} {:>9} {:>22} {:>10} {:>11.3} {:>9.1} {:>9.1} {:>12.2}",
            r.scene,
            r.backend,
            format!("{}x{}", r.width, r.height),
            format!("{:.1}/{:.1}/{:.1}", r.ms_min, r.ms_median, r.ms_max),
            r.device_ms_min
                .map_or_else(|| "-".to_owned(), |d| format!("{d:.2}")),
            r.rays_per_second / 1e6,
            r.steps_per_ray,
            r.evals_per_ray,
            r.ray_steps_per_second / 1e6
        );
    }
    for s in &report.sparse {
        outln!(
            "sparse {:<18} {:<9} at error {:.2e} (sparse's {:.2e}): {} of {} bricks, {} bytes vs dense {} ({:.2}x), frame time gpu {:.2}x{} (aim: bytes <= 1x, time <= 1.3x)",
            s.scene,
            s.interp,
            s.error,
            s.sparse_error,
            s.active_bricks,
            s.total_bricks,
            s.sparse_bytes,
            s.dense_bytes,
            s.sparse_bytes as f64 / s.dense_bytes.max(1) as f64,
            s.gpu_time_ratio,
            s.cpu_time_ratio
                .map(|c| format!(", cpu {c:.2}x"))
                .unwrap_or_default()
        );
    }
    outln!(
        "noise / analytic frame time: gpu {:.2}{} (paper: 2.0; aim <= 1.2)",
        report.noise_over_analytic_gpu,
        report
            .noise_over_analytic_cpu
            .map(|c| format!(", cpu {c:.2}"))
            .unwrap_or_default()
    );
    outln!(
        "rates of the fractions below timed {}",
        if report.timed_on_device {
            "on the device (timestamps around the passes)"
        } else {
            "by the wall clock (no timestamps on this adapter)"
        }
    );
    outln!(
        "raw trilinear field samples: {:.1} M/s; marcher ((c) medium only, sharma: 3 evaluations per step): field evals {:.1}% and ray-steps {:.1}% of it; verlet (1 per step): ray-steps {:.1}% (aim >= 60%)",
        report.raw_field_samples_per_second / 1e6,
        report.field_evals_fraction_of_raw * 100.0,
        report.ray_steps_fraction_of_raw * 100.0,
        report.verlet_ray_steps_fraction_of_raw * 100.0
    );
    Ok(())
}
