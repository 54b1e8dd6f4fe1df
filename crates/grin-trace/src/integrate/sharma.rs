//! The Runge-Kutta-Nystrom step of Sharma, Kumar & Ghatak (1982) used by the paper:
//! A = h D(r); B = h D(r + h/2 T + h/8 A); C = h D(r + h T + h/2 B);
//! r1 = r + h (T + (A + 2B)/6); T1 = T + (A + 4B + C)/6. Fourth order, 3 evaluations
//! per step (A is the start sample). The step carries C's D for its error estimate
//! (`Step::check`).

use grin_field::{IndexField, Real};

use super::{RayState, Step, c, sample_d};

/// One Sharma RKN step; 2 evaluations beyond the start sample.
pub fn sharma_step<R: Real>(field: &dyn IndexField, s: RayState<R>, d0: R::V3, h: R) -> Step<R> {
    let (r, t) = (s.r, s.t);
    let a = d0 * h;
    let b = sample_d::<R>(field, r + t * (h * c::<R>(0.5)) + a * (h * c::<R>(0.125))) * h;
    let d_c = sample_d::<R>(field, r + t * h + b * (h * c::<R>(0.5)));
    let cc = d_c * h;
    let sixth = c::<R>(1.0 / 6.0);
    let dr = (t + (a + b * c::<R>(2.0)) * sixth) * h;
    let dt = (a + b * c::<R>(4.0) + cc) * sixth;
    // The companion T + (A + 4 B + h D(r1)) / 6 (D(r1) for C's D): third order.
    Step {
        check: Some(d_c),
        ..Step::plain(s, dr, dt, 2)
    }
}
