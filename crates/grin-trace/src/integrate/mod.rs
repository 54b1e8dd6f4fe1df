//! One step of the ray equation in t-parameter form, dr/dt = T, dT/dt = D(r) = n grad n,
//! for every integrator. Each step function takes D at the step start (already sampled by
//! the caller, so it is not counted again) and returns the new state, the field
//! evaluations it made and, when it sampled the end point itself, that sample.

pub mod adaptive;
pub mod euler;
pub mod rk4;
pub mod sharma;
pub mod symplectic_euler;
pub mod verlet;

use grin_field::{FieldSample, IndexField, Real, Vec3Like};
use grin_scene::IntegratorKind;

pub use adaptive::dopri_step;
pub use euler::euler_step;
pub use rk4::rk4_step;
pub use sharma::sharma_step;
pub use symplectic_euler::symplectic_euler_step;
pub use verlet::verlet_step;

/// Position r and T = n dr/ds (|T| = n) of a ray.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RayState<R: Real> {
    pub r: R::V3,
    pub t: R::V3,
}

/// The result of one step.
#[derive(Debug, Clone, Copy)]
pub struct Step<R: Real> {
    pub state: RayState<R>,
    /// Field evaluations made by the step (the start sample is the caller's).
    pub evals: u32,
    /// The field at `state.r`, when the step evaluated it anyway (verlet, dopri: FSAL).
    pub end: Option<FieldSample<R>>,
    /// Embedded local error estimate (e_r, e_T) of the adaptive pair.
    pub error: Option<(R::V3, R::V3)>,
}

impl<R: Real> Step<R> {
    fn plain(r: R::V3, t: R::V3, evals: u32) -> Self {
        Step {
            state: RayState { r, t },
            evals,
            end: None,
            error: None,
        }
    }
}

/// D = n grad n at `p`: one field evaluation.
#[inline]
pub fn sample_d<R: Real>(field: &dyn IndexField, p: R::V3) -> R::V3 {
    R::sample_field(field, p).n_grad_n()
}

/// Order of accuracy of the integrator's position (global error ~ h^order).
pub fn order(kind: IntegratorKind) -> u32 {
    match kind {
        IntegratorKind::Euler | IntegratorKind::SymplecticEuler => 1,
        IntegratorKind::Verlet => 2,
        IntegratorKind::Sharma | IntegratorKind::Rk4 => 4,
        IntegratorKind::Adaptive => 5,
    }
}

/// One step of `kind` from `s` (with D(s.r) = `d0`) over `h` in t.
/// `Adaptive` takes a Dormand-Prince 5(4) step and reports its error estimate.
pub fn step<R: Real>(
    kind: IntegratorKind,
    field: &dyn IndexField,
    s: RayState<R>,
    d0: R::V3,
    h: R,
) -> Step<R> {
    match kind {
        IntegratorKind::Euler => euler_step(field, s, d0, h),
        IntegratorKind::SymplecticEuler => symplectic_euler_step(field, s, d0, h),
        IntegratorKind::Verlet => verlet_step(field, s, d0, h),
        IntegratorKind::Sharma => sharma_step(field, s, d0, h),
        IntegratorKind::Rk4 => rk4_step(field, s, d0, h),
        IntegratorKind::Adaptive => dopri_step(field, s, d0, h),
    }
}

/// Field evaluations per step in steady state, counting the end-point sample the tracer
/// needs for the next step (sharma 3, rk4 4, dopri 6 with FSAL, the others 1).
pub fn evals_per_step(kind: IntegratorKind) -> u32 {
    match kind {
        IntegratorKind::Euler | IntegratorKind::SymplecticEuler | IntegratorKind::Verlet => 1,
        IntegratorKind::Sharma => 3,
        IntegratorKind::Rk4 => 4,
        IntegratorKind::Adaptive => 6,
    }
}

#[inline]
pub(crate) fn c<R: Real>(x: f64) -> R {
    R::from_f64(x)
}

#[inline]
pub(crate) fn is_finite_v<R: Real>(v: R::V3) -> bool {
    v.x().is_finite() && v.y().is_finite() && v.z().is_finite()
}
