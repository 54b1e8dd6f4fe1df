//! grin measures itself: `grin bench accuracy` (error against cost for every integrator,
//! step policy, exit method and precision on reference fields, with the Pareto front and
//! measured convergence orders), `grin bench stability` (hard cases x methods, each
//! cell converged, degraded or failed, and whether grin said so), `grin bench speed`
//! (the GPU marcher and the CPU reference on the same bakes) and `grin bench bake`
//! (procedural noise against its bakes on the CPU). The `grin` binary parses their
//! arguments and prints what they return.

pub mod accuracy;
pub mod bake;
pub mod cases;
pub mod chart;
pub mod methods;
pub mod report;
pub mod speed;
pub mod stability;
