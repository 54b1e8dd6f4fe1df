//! `grin bench`: one module per mode (`grin bench <mode>`).

mod accuracy;
mod bake;
mod speed;
mod stability;

/// Arguments of `grin bench`.
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(subcommand)]
    pub mode: Mode,
}

/// The benchmark modes.
#[derive(Debug, clap::Subcommand)]
pub enum Mode {
    /// GPU (wgpu; lavapipe without a GPU) vs CPU: rays/s and ms/frame for the paper's
    /// scenes (a), (c) and heat haze, the noise/analytic frame-time ratio, and the
    /// marcher's field-sample rate as a fraction of the adapter's raw rate.
    Speed(speed::Args),
    /// Procedural noise (the paper: fBm + gradient at every stage) vs the baked field on
    /// the CPU: frame cost and speedup; bake time and bytes per resolution.
    Bake(bake::Args),
    /// Error against cost for every integrator, step policy, exit method and precision
    /// on reference fields (exact solutions where known): CSV, charts, the Pareto front,
    /// measured convergence orders.
    Accuracy(accuracy::Args),
    /// Hard cases x methods (steep features, index jumps, grazing and tangent rays,
    /// tunnelling, trapped orbits, n -> 0, invalid spikes): converged, degraded or
    /// failed per cell, and which wrong answers grin reported as `exited`.
    Stability(stability::Args),
}

pub fn run(args: Args) -> anyhow::Result<()> {
    match args.mode {
        Mode::Speed(a) => speed::run(a),
        Mode::Bake(a) => bake::run(a),
        Mode::Accuracy(a) => accuracy::run(a),
        Mode::Stability(a) => stability::run(a),
    }
}
