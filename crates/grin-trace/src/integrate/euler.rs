//! Explicit Euler: r1 = r + h T, T1 = T + h D(r). First order, drifts (|T| - n grows).

use grin_field::{IndexField, Real};

use super::{RayState, Step};

/// One explicit Euler step; no evaluations beyond the start sample.
pub fn euler_step<R: Real>(_field: &dyn IndexField, s: RayState<R>, d0: R::V3, h: R) -> Step<R> {
    Step::plain(s, s.t * h, d0 * h, 0)
}
