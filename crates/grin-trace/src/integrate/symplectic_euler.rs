//! Symplectic Euler: T1 = T + h D(r), r1 = r + h T1. First order, but symplectic: the
//! invariant |T|^2 - n^2 stays bounded instead of drifting.

use grin_field::{IndexField, Real};

use super::{RayState, Step};

/// One symplectic Euler step; no evaluations beyond the start sample.
pub fn symplectic_euler_step<R: Real>(
    _field: &dyn IndexField,
    s: RayState<R>,
    d0: R::V3,
    h: R,
) -> Step<R> {
    let dt = d0 * h;
    Step::plain(s, (s.t + dt) * h, dt, 0)
}
