//! The CPU reference tracer: integrators (t-parameter form r'' = n grad n), step policies,
//! boundaries, the per-ray loop and ray tables.

pub mod auto;
pub mod boundary;
pub mod estimate;
mod exit_search;
pub mod integrate;
pub mod packet;
pub mod step;
pub mod table;
pub mod trace;

pub use boundary::{Interface, Segment, fresnel, refract};
pub use trace::{Control, RayResult, RayStatus, trace_ray, trace_ray_observed};

pub mod render;
pub mod shadowgraph;
