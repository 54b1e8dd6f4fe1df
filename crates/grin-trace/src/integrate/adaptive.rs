//! The embedded Dormand-Prince 5(4) pair on the first-order system (r, T), with FSAL:
//! the seventh stage is evaluated at the new point and becomes the next step's first,
//! so an accepted step costs 6 evaluations. The step returns the fifth-order solution and
//! the difference to the fourth-order one as its local error estimate.

use glam::DVec3;
use grin_field::{IndexField, Real, Vec3Like};

use super::{Quad, RayState, Step, c};

/// Dormand & Prince (1980) tableau, rows a_ij (i = 2..7); row 7 equals the 5th-order weights.
pub(crate) const A: [[f64; 6]; 6] = [
    [1.0 / 5.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [3.0 / 40.0, 9.0 / 40.0, 0.0, 0.0, 0.0, 0.0],
    [44.0 / 45.0, -56.0 / 15.0, 32.0 / 9.0, 0.0, 0.0, 0.0],
    [
        19372.0 / 6561.0,
        -25360.0 / 2187.0,
        64448.0 / 6561.0,
        -212.0 / 729.0,
        0.0,
        0.0,
    ],
    [
        9017.0 / 3168.0,
        -355.0 / 33.0,
        46732.0 / 5247.0,
        49.0 / 176.0,
        -5103.0 / 18656.0,
        0.0,
    ],
    [
        35.0 / 384.0,
        0.0,
        500.0 / 1113.0,
        125.0 / 192.0,
        -2187.0 / 6784.0,
        11.0 / 84.0,
    ],
];

/// b (5th order) - b* (4th order), the error weights of stages 1..7.
pub(crate) const E: [f64; 7] = [
    71.0 / 57600.0,
    0.0,
    -71.0 / 16695.0,
    71.0 / 1920.0,
    -17253.0 / 339200.0,
    22.0 / 525.0,
    -1.0 / 40.0,
];

/// The embedded error of a step's optical path over `h`: `rest` (the stages after the
/// first, already times `h`) and the first stage's term, of the index `n0` at the start.
/// The one-ray step ([`super::Quad::opl_error_with_start`]) and the packets share it.
#[inline]
pub(crate) fn opl_error_with_start(rest: f64, n0: f64, h: f64) -> f64 {
    rest + E[0] * h * n0 * n0
}

/// One Dormand-Prince 5(4) step; 6 evaluations beyond the start sample, the last at the
/// new point (returned as `end`).
pub fn dopri_step<R: Real>(field: &dyn IndexField, s: RayState<R>, d0: R::V3, h: R) -> Step<R> {
    let mut ts = [s.t; 7];
    let mut ds = [d0; 7];
    let mut r_end = s.r;
    let mut delta = RayState::zero();
    let mut end = None;
    // The quadrature of n^2, n and n u over the stages 2..6 (the first is the caller's;
    // the seventh has weight 0), in f64.
    let (mut opl, mut length, mut swept) = (0.0, 0.0, DVec3::ZERO);
    // The embedded error of the optical path (the stages' n^2 by E), first stage's left out.
    let mut opl_error = 0.0;
    for i in 1..7 {
        let row = &A[i - 1];
        let mut dr = s.t * c::<R>(row[0]);
        let mut dt = d0 * c::<R>(row[0]);
        for j in 1..i {
            dr += ts[j] * c::<R>(row[j]);
            dt += ds[j] * c::<R>(row[j]);
        }
        delta = RayState {
            r: dr * h,
            t: dt * h,
        };
        let ri = s.r + delta.r;
        ts[i] = s.t + delta.t;
        let sample = R::sample_field(field, ri);
        ds[i] = sample.n_grad_n();
        // The fifth-order weights b_i are the last row of A (b_7 = 0).
        let n = sample.n.to_f64();
        opl_error += E[i] * n * n;
        let b = A[5].get(i).copied().unwrap_or(0.0);
        if b != 0.0 {
            let u = ts[i].to_dvec3().normalize_or_zero();
            opl += b * n * n;
            length += b * n;
            swept += u * (b * n);
        }
        // Stage 7 sits at the new point: r7 = r1, T7 = T1 (FSAL).
        r_end = ri;
        end = Some(sample);
    }
    let mut er = ts[0] * c::<R>(E[0]);
    let mut et = ds[0] * c::<R>(E[0]);
    for j in 1..7 {
        er += ts[j] * c::<R>(E[j]);
        et += ds[j] * c::<R>(E[j]);
    }
    Step {
        state: RayState { r: r_end, t: ts[6] },
        delta,
        evals: 6,
        end,
        error: Some((er * h, et * h)),
        check: None,
        quad: Some(Quad {
            b0: A[5][0],
            opl: opl * h.to_f64(),
            length: length * h.to_f64(),
            swept: swept * h.to_f64(),
            opl_error: opl_error * h.to_f64(),
        }),
    }
}
