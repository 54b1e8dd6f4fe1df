//! grin measures itself: `grin bench accuracy` (error against cost for every integrator,
//! step policy, exit method and precision on reference fields, with the Pareto front and
//! measured convergence orders) and `grin bench stability` (hard cases x methods, each
//! cell converged, degraded or failed, and whether grin said so).

pub mod accuracy;
pub mod cases;
pub mod chart;
pub mod methods;
pub mod report;
pub mod stability;
