//! Classical fourth-order Runge-Kutta on the first-order system (r, T):
//! 4 evaluations per step (the first is the start sample). The step carries D of its
//! last stage for its error estimate (`Step::check`).

use grin_field::{IndexField, Real};

use super::{RayState, Step, c, sample_d};

/// One RK4 step; 3 evaluations beyond the start sample.
pub fn rk4_step<R: Real>(field: &dyn IndexField, s: RayState<R>, d0: R::V3, h: R) -> Step<R> {
    let half = h * c::<R>(0.5);
    let (r, t) = (s.r, s.t);
    // Stage k_i = (T_i, D_i).
    let t1 = t;
    let d1 = d0;
    let t2 = t + d1 * half;
    let d2 = sample_d::<R>(field, r + t1 * half);
    let t3 = t + d2 * half;
    let d3 = sample_d::<R>(field, r + t2 * half);
    let t4 = t + d3 * h;
    let d4 = sample_d::<R>(field, r + t3 * h);
    let sixth = h * c::<R>(1.0 / 6.0);
    let two = c::<R>(2.0);
    let dr = (t1 + t2 * two + t3 * two + t4) * sixth;
    let dt = (d1 + d2 * two + d3 * two + d4) * sixth;
    // The companion y + h/6 (k1 + 2 k2 + 2 k3 + k5), k5 = D(r1): third order.
    Step {
        check: Some(d4),
        ..Step::plain(s, dr, dt, 3)
    }
}
