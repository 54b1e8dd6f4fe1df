//! Velocity Verlet (Stormer-Verlet): kick h/2, drift h, kick h/2. Second order,
//! symplectic, one new evaluation per step (at the end point, reused by the next step).

use grin_field::{IndexField, Real};

use super::{RayState, Step, c};

/// One velocity Verlet step; evaluates the field at the end point (returned as `end`).
pub fn verlet_step<R: Real>(field: &dyn IndexField, s: RayState<R>, d0: R::V3, h: R) -> Step<R> {
    let half = h * c::<R>(0.5);
    let t_half = s.t + d0 * half;
    let dr = t_half * h;
    let r1 = s.r + dr;
    let end = R::sample_field(field, r1);
    let dt = (d0 + end.n_grad_n()) * half;
    Step {
        state: RayState { r: r1, t: s.t + dt },
        delta: RayState { r: dr, t: dt },
        evals: 1,
        end: Some(end),
        error: None,
        check: None,
        quad: None,
    }
}
