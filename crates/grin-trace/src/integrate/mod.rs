//! One step of the ray equation in t-parameter form, dr/dt = T, dT/dt = D(r) = n grad n,
//! for every integrator. Each step function takes D at the step start (already sampled by
//! the caller, so it is not counted again) and returns the new state, the field
//! evaluations it made and, when it sampled the end point itself, that sample. It also
//! returns the increments (dr, dT) it added, so the tracer can sum them with compensation
//! ([`add_compensated`]): in f32 the roundoff of r + dr over hundreds of steps otherwise
//! grows linearly and dominates the error of fourth-order steps.

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
    /// The increments (dr, dT): `state` is the start state plus these, rounded.
    pub delta: RayState<R>,
    /// Field evaluations made by the step (the start sample is the caller's).
    pub evals: u32,
    /// The field at `state.r`, when the step evaluated it anyway (verlet, dopri: FSAL).
    pub end: Option<FieldSample<R>>,
    /// Local error estimate (e_r, e_T): the adaptive pair's embedded one, or Richardson's
    /// of a doubled step (`StepController`).
    pub error: Option<(R::V3, R::V3)>,
    /// For the fourth-order steps (rk4, sharma): the D their last stage used. With D at
    /// the new point (the next step's first sample, so free) it gives a third-order
    /// companion, and e_T = h/6 (D(r1) - check) estimates the step's local error (the
    /// companion's: an overestimate by the ratio of their orders, as the adaptive pair's
    /// is) ([`crate::estimate`]).
    pub check: Option<R::V3>,
    /// For dopri: the step's quadrature of the optical path, length and swept vector
    /// with its own fifth-order weights, all stages but the first ([`Quad`]).
    pub quad: Option<Quad>,
}

/// A step's integrals of n^2 (optical path), n (length) and n u (swept vector) over t,
/// by the integrator's own weights b_i at its stages, without the first stage's term:
/// the caller, who holds n and T at the start, adds it ([`Quad::with_start`]). With
/// dopri's fifth-order weights the optical path is as accurate as the position; the cubic
/// Hermite rule the tracer uses otherwise is fourth order, and at dopri's long steps its
/// optical path was 20-370x less accurate than the exit position.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Quad {
    pub b0: f64,
    pub opl: f64,
    pub length: f64,
    pub swept: glam::DVec3,
    /// The embedded (fifth- less fourth-order) error of `opl`, first stage's term left out.
    pub opl_error: f64,
}

impl Quad {
    /// The step's embedded optical-path error, the first stage's term (n0, over `h`) added.
    pub fn opl_error_with_start(self, n0: f64, h: f64) -> f64 {
        adaptive::opl_error_with_start(self.opl_error, n0, h)
    }

    /// The whole step's integrals: the first stage's term (n0, T0, over `h`) added.
    pub fn with_start(self, n0: f64, t0: glam::DVec3, h: f64) -> (f64, f64, glam::DVec3) {
        let w = self.b0 * h;
        let u0 = t0.normalize_or_zero();
        (
            self.opl + w * n0 * n0,
            self.length + w * n0,
            self.swept + u0 * (w * n0),
        )
    }
}

impl<R: Real> Step<R> {
    /// The step from `s` by the increments `dr`, `dt`.
    fn plain(s: RayState<R>, dr: R::V3, dt: R::V3, evals: u32) -> Self {
        Step {
            state: RayState {
                r: s.r + dr,
                t: s.t + dt,
            },
            delta: RayState { r: dr, t: dt },
            evals,
            end: None,
            error: None,
            check: None,
            quad: None,
        }
    }
}

impl<R: Real> RayState<R> {
    /// r = T = 0: the empty compensation of [`add_compensated`].
    pub fn zero() -> Self {
        let z = R::V3::new(R::zero(), R::zero(), R::zero());
        RayState { r: z, t: z }
    }
}

/// Knuth's TwoSum, per component: a + b rounded and the exact roundoff it lost.
#[inline]
fn two_sum<R: Real>(a: R::V3, b: R::V3) -> (R::V3, R::V3) {
    let sum = a + b;
    let b_virtual = sum - a;
    let lost = (a - (sum - b_virtual)) + (b - b_virtual);
    (sum, lost)
}

/// Compensated state update (Kahan-Babuska summation via TwoSum): `s + delta + *comp`,
/// leaving in `comp` the roundoff the new state could not hold, to be added in with the
/// next increment. Start a ray (and restart after any state jump: surface, straight
/// flight) with `RayState::zero()`.
#[inline]
pub fn add_compensated<R: Real>(
    s: RayState<R>,
    delta: RayState<R>,
    comp: &mut RayState<R>,
) -> RayState<R> {
    let (r, lost_r) = two_sum::<R>(s.r, delta.r + comp.r);
    let (t, lost_t) = two_sum::<R>(s.t, delta.t + comp.t);
    *comp = RayState {
        r: lost_r,
        t: lost_t,
    };
    RayState { r, t }
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

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::*;

    /// Increments below half an ulp of the state vanish from plain f32 sums; the
    /// compensated update keeps them (and stays exact when they are representable).
    #[test]
    fn compensated_update_keeps_sub_ulp_increments() {
        let inc = 1e-8_f32;
        let delta = RayState::<f32> {
            r: Vec3::new(inc, -inc, 0.25),
            t: Vec3::splat(inc),
        };
        let start = RayState::<f32> {
            r: Vec3::new(1.0, 1.0, 0.0),
            t: Vec3::ONE,
        };
        let (mut plain, mut comp_state) = (start, start);
        let mut comp = RayState::zero();
        let steps = 10_000;
        for _ in 0..steps {
            plain = RayState {
                r: plain.r + delta.r,
                t: plain.t + delta.t,
            };
            comp_state = add_compensated(comp_state, delta, &mut comp);
        }
        assert_eq!(plain.r.x, 1.0, "plain f32 drops the increments");
        let exact = 1.0 + f64::from(inc) * steps as f64;
        assert!((f64::from(comp_state.r.x) - exact).abs() <= 1.2e-7);
        assert!((f64::from(comp_state.r.y) - (2.0 - exact)).abs() <= 1.2e-7);
        assert!((f64::from(comp_state.t.z) - exact).abs() <= 1.2e-7);
        assert_eq!(comp_state.r.z, 0.25 * steps as f32);
    }
}
