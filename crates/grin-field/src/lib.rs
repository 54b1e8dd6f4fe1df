//! Refractive index fields: the [`IndexField`] trait every tracer samples, the bounds of a
//! medium, and the scalar/vector abstraction ([`Real`]) that lets the integrators run in
//! f64 (the reference) and f32 (what the GPU does).

pub mod alloc;
pub mod analytic;
pub mod bake;
pub mod baked;
pub mod bounds;
pub mod build;
pub mod check;
pub mod export;
pub mod expr;
pub mod expr_jit;
pub mod expr_tape;
pub mod features;
pub mod field;
pub mod grinf;
pub mod interval;
pub mod noise;
pub mod real;
pub mod sparse;
pub mod vdb;

pub use bounds::Bounds;
pub use build::{build_field, build_field_capped};
pub use field::{FieldError, FieldSample, IndexField};
pub use real::{Real, Vec3Like};
