//! The dopri 5(4) packet step: Dormand-Prince steps of four rays at once, error
//! controlled (or fixed), each lane with its own step length and its own accept or
//! reject, as the
//! one-ray tracer takes them (`StepController::take`'s error control, `dopri_step`, the
//! quadrature of the optical path with the fifth-order weights, the error estimate the
//! step reports), operation for operation, so the results are the same bit for bit.
//!
//! A rejected attempt leaves its lane in the packet, to try again at the shorter step
//! the controller chose. An accepted step that ends outside starts the lane's exit search
//! (crate::exit_search), its re-steps dopri steps in the packet. Any other accepted step that
//! is not a plain one (its cubic may leave between its ends, or the exit is bisection's)
//! is not kept: the lane goes back to where its take began (the step the controller tried
//! first, the evaluations counted before) and its march takes the step from there,
//! through the same attempts.

use std::array;

use grin_field::IndexField;
use grin_render::settings::TraceSettings;
use grin_scene::{ExitMethod, IntegratorKind};

use super::{
    L, LANES, Mask, STEPS_PER_GATHER, Soa, StepEnd, Took, V, finish_steps, lane_step, leaves,
    local_cap, plain_steps, sample, signed_distance, two_sum,
};
use crate::boundary::{EXCURSION_SLACK_TOLS, exit_tolerance};
use crate::exit_search::{ExitSearch, Phase};
use crate::integrate::Quad;
use crate::integrate::adaptive::{A, E, opl_error_with_start};
use crate::step::{
    ADAPTIVE_MIN_DS_EPS, ADAPTIVE_MIN_DS_REL, ADAPTIVE_TOL_FLOOR_EPS, MAX_REJECTIONS,
    StepController, step_factor,
};
use crate::trace::March;

/// Error-controlled dopri steps of the occupied lanes while they all can take them (up
/// to [`STEPS_PER_GATHER`] attempts).
// The lane loops index several lane arrays at once.
#[allow(clippy::needless_range_loop)]
#[inline(always)]
pub(super) fn march_dopri_in(
    field: &dyn IndexField,
    settings: &TraceSettings,
    lanes: &[Option<(usize, March<f64>)>; LANES],
    s: &mut Soa,
) -> Took {
    let mut took = [0u32; LANES];
    let mut control = [None; LANES];
    let mut feature_cap = [f64::INFINITY; LANES];
    let mut min_flight = [0.0; LANES];
    let mut bounds = None;
    for (i, lane) in lanes.iter().enumerate() {
        if let Some((_, m)) = lane
            && let Some(c) = m.ctrl.dopri_control()
        {
            control[i] = Some(c);
            feature_cap[i] = m.ctrl.feature_cap();
            min_flight[i] = m.min_flight;
            bounds = Some(m.bounds);
        }
    }
    let Some(bounds) = bounds else {
        return Took::all_own(lanes);
    };
    let occupied: [bool; LANES] = array::from_fn(|i| control[i].is_some());
    // StepController::take_adaptive's constants, per lane (every lane has the same
    // settings; the unoccupied ones get harmless values).
    let eps = f64::EPSILON;
    let len_scale = L(array::from_fn(|i| control[i].map_or(1.0, |c| c.len_scale)));
    let ds_max_c = L(array::from_fn(|i| control[i].map_or(1.0, |c| c.ds_max)));
    let ds_min = len_scale.map(|r| ADAPTIVE_MIN_DS_REL.max(ADAPTIVE_MIN_DS_EPS * eps) * r);
    let floor_eps = eps.max(field.sample_eps());
    let tol_floor = len_scale.map(|r| ADAPTIVE_TOL_FLOOR_EPS * floor_eps * r);
    let exponent = 1.0 / f64::from(crate::integrate::order(IntegratorKind::Adaptive));
    let feature_cap = L(feature_cap);
    let mut sd0 = signed_distance(&bounds, s.r);
    let exit_tol = exit_tolerance::<f64>(&bounds);
    let slack = EXCURSION_SLACK_TOLS * exit_tol;
    let hermite = settings.exit == ExitMethod::Hermite;
    let local_limits = field.has_local_step_limits();
    let evals_per_step = u64::from(crate::integrate::evals_per_step(IntegratorKind::Adaptive));
    let mut active = [false; LANES];
    // Lanes whose step is their march's to take.
    let mut own = [false; LANES];
    // Lanes searching for their exit (the re-step due is a packet step).
    let mut searching = [false; LANES];
    for _ in 0..STEPS_PER_GATHER {
        // A take begins where the one-ray tracer's `advance` would take one: its caps
        // are fixed for all of the take's attempts.
        let g_len = s.g0.length();
        let cap = L(array::from_fn(|i| {
            StepController::length_scale_cap(s.n0.0[i], g_len.0[i])
        }))
        .zip(feature_cap, f64::min);
        for i in 0..LANES {
            searching[i] = occupied[i] && s.exits[i].phase == Phase::Search;
            active[i] = occupied[i] && !own[i] && s.may_step(i, settings.max_steps);
            if !active[i] || s.in_take[i] {
                continue;
            }
            let mut lane_cap = cap.0[i];
            let fixed = control[i].is_some_and(|c| c.tol.is_none());
            if local_limits {
                // StepController::take's reach: the fixed step, or the controller's.
                let (ds_max, ds_adapt) = (ds_max_c.0[i], s.ds_adapt.0[i]);
                let reach = |c: f64| {
                    if fixed {
                        ds_max.min(c)
                    } else {
                        ds_adapt.min(ds_max).min(c)
                    }
                };
                match local_cap(field, settings, s, i, min_flight[i], lane_cap, reach) {
                    Some(c) => lane_cap = c,
                    None => {
                        active[i] = false;
                        continue;
                    }
                }
            }
            s.in_take[i] = true;
            s.take_ds.0[i] = s.ds_adapt.0[i];
            s.take_evals[i] = s.evals[i];
            s.take_cap.0[i] = lane_cap;
            s.rejections[i] = 0;
        }
        if !(0..LANES).any(|i| active[i] || searching[i]) {
            break;
        }
        // The attempt's length (take_adaptive), in the stepping lanes.
        let mut ds = L::splat(0.0);
        let mut ds_max = L::splat(0.0);
        for i in 0..LANES {
            if !active[i] {
                continue;
            }
            match control[i].and_then(|c| c.tol) {
                Some(_) => {
                    ds_max.0[i] = ds_max_c.0[i].min(s.take_cap.0[i]).max(ds_min.0[i]);
                    ds.0[i] = s.ds_adapt.0[i].clamp(ds_min.0[i], ds_max.0[i]);
                }
                // A fixed step: (ds * jitter).min(cap), the jitter spent.
                None => ds.0[i] = ds_max_c.0[i].min(s.take_cap.0[i]),
            }
        }
        let mut h = Mask::of(active).select(ds / s.n0, L::splat(0.0));
        for i in 0..LANES {
            if searching[i] {
                h.0[i] = s.exits[i].trial;
            }
        }
        // dopri_step, lane by lane: six stages, the last at the new point (FSAL), and the
        // quadrature of n^2, n and n u with the fifth-order weights.
        let (r, t) = (s.r, s.t);
        let d0 = s.g0.scale(s.n0);
        let mut ts = [t; 7];
        let mut dd = [d0; 7];
        let mut delta_r = V::zero();
        let mut delta_t = V::zero();
        let mut r_end = r;
        let (mut n_end, mut g_end) = (s.n0, s.g0);
        let (mut q_opl, mut q_length, mut q_swept) = (L::splat(0.0), L::splat(0.0), V::zero());
        // The optical path's embedded error (dopri_step's Quad::opl_error).
        let mut q_err = L::splat(0.0);
        for k in 1..7 {
            let row = &A[k - 1];
            let mut dr = t.scale(L::splat(row[0]));
            let mut dt = d0.scale(L::splat(row[0]));
            for j in 1..k {
                dr = dr + ts[j].scale(L::splat(row[j]));
                dt = dt + dd[j].scale(L::splat(row[j]));
            }
            delta_r = dr.scale(h);
            delta_t = dt.scale(h);
            let rk = r + delta_r;
            ts[k] = t + delta_t;
            let (n, g) = sample(field, rk);
            dd[k] = g.scale(n);
            q_err = q_err + L::splat(E[k]) * n * n;
            let b = A[5].get(k).copied().unwrap_or(0.0);
            if b != 0.0 {
                let u = ts[k].normalize_or_zero();
                let bn = L::splat(b) * n;
                q_opl = q_opl + bn * n;
                q_length = q_length + bn;
                q_swept = q_swept + u.scale(bn);
            }
            r_end = rk;
            (n_end, g_end) = (n, g);
        }
        let t_end = ts[6];
        let mut er = ts[0].scale(L::splat(E[0]));
        let mut et = dd[0].scale(L::splat(E[0]));
        for j in 1..7 {
            er = er + ts[j].scale(L::splat(E[j]));
            et = et + dd[j].scale(L::splat(E[j]));
        }
        let (er, et) = (er.scale(h), et.scale(h));
        // The controller's error norm, tolerance and next step (take_adaptive).
        let pos = er.length();
        let dir = et.length() / s.n0.map(|n| n.abs().max(f64::MIN_POSITIVE)) * len_scale;
        let mut err = pos.zip(dir, f64::max);
        let q_err = q_err * h;
        for i in 0..LANES {
            if control[i].is_some_and(|c| c.opl) {
                let opl = opl_error_with_start(q_err.0[i], s.n0.0[i], h.0[i]).abs();
                err.0[i] = err.0[i].max(opl);
            }
        }
        let mut accepted = [false; LANES];
        for i in 0..LANES {
            if !active[i] {
                continue;
            }
            let Some(c) = control[i] else { continue };
            s.evals[i] += evals_per_step;
            let Some(c_tol) = c.tol else {
                accepted[i] = true;
                continue;
            };
            let (ds, ds_min, ds_max, err) = (ds.0[i], ds_min.0[i], ds_max.0[i], err.0[i]);
            let tol = c_tol.for_step(ds).max(tol_floor.0[i]);
            accepted[i] = err <= tol || ds <= ds_min || s.rejections[i] >= MAX_REJECTIONS;
            s.ds_adapt.0[i] = (ds * step_factor(err, tol, exponent)).clamp(ds_min, ds_max);
            if !accepted[i] {
                s.rejections[i] += 1;
            }
        }
        // An accepted step is the packet's where the one-ray tracer would take it as a
        // plain step: inside at its end, and no excursion between (excursion_step).
        let plain = plain_steps(&bounds, slack, &accepted, sd0, (r, t), (r_end, t_end), h);
        let mut committed = [false; LANES];
        for i in 0..LANES {
            if searching[i] {
                // The exit search's re-step, with its quadrature (dopri_step's Quad).
                s.evals[i] += evals_per_step;
                let quad = Quad {
                    b0: A[5][0],
                    opl: q_opl.0[i] * h.0[i],
                    length: q_length.0[i] * h.0[i],
                    swept: q_swept.lane(i) * h.0[i],
                    opl_error: q_err.0[i],
                };
                let (end, _) = lane_step((r, t), (r_end, t_end), h, i);
                s.exits[i].restepped(&bounds, exit_tol, end, Some(quad));
                searching[i] = s.exits[i].phase == Phase::Search;
                continue;
            }
            if !accepted[i] {
                continue;
            }
            s.in_take[i] = false;
            if plain[i] {
                committed[i] = true;
                continue;
            }
            let (end, seg) = lane_step((r, t), (r_end, t_end), h, i);
            if hermite && leaves(&bounds, s, i, delta_r.lane(i), end) {
                // The step left: the lane searches for its exit, its controller as the
                // accepted step left it.
                let error = Some((er.lane(i), et.lane(i)));
                s.exits[i] = ExitSearch::begin(&bounds, seg, error);
                searching[i] = true;
            } else {
                // Back to where the take began: the march takes this step itself.
                s.ds_adapt.0[i] = s.take_ds.0[i];
                s.evals[i] = s.take_evals[i];
                own[i] = true;
            }
            active[i] = false;
        }
        if committed.iter().any(|&c| c) {
            commit(
                s,
                &bounds,
                &committed,
                &mut sd0,
                Step {
                    t,
                    d0,
                    h,
                    delta_r,
                    delta_t,
                    n1: n_end,
                    g1: g_end,
                    q: (q_opl, q_length, q_swept),
                    er,
                    et,
                },
            );
            for i in 0..LANES {
                if committed[i] {
                    took[i] += 1;
                }
            }
        }
        if (0..LANES).any(|i| occupied[i] && !active[i] && !searching[i]) {
            break;
        }
    }
    Took {
        steps: took,
        own: array::from_fn(|i| lanes[i].is_some() && !active[i] && !searching[i] && !s.in_take[i]),
    }
}

/// An accepted dopri step of every lane, as lane vectors.
struct Step {
    t: V,
    d0: V,
    h: L,
    delta_r: V,
    delta_t: V,
    /// The sample at the step's end (its seventh stage).
    n1: L,
    g1: V,
    /// The quadrature of n^2, n and n u over stages 2..6 (times h to come).
    q: (L, L, V),
    /// The step's reported local errors (position, T).
    er: V,
    et: V,
}

/// The one-ray tracer's bookkeeping of an accepted plain step, in the `committed`
/// lanes: the compensated state update and the optical path by the step's quadrature
/// (`Quad::with_start`), then what every packet step does after
/// ([`super::finish_steps`]).
#[inline(always)]
fn commit(
    s: &mut Soa,
    bounds: &grin_field::Bounds,
    committed: &[bool; LANES],
    sd0: &mut L,
    st: Step,
) {
    let Step {
        t,
        d0,
        h,
        delta_r,
        delta_t,
        n1,
        g1,
        q,
        er,
        et,
    } = st;
    let (nr, lost_r) = two_sum(s.r, delta_r + s.comp_r);
    let (nt, lost_t) = two_sum(t, delta_t + s.comp_t);
    let n0 = s.n0;
    // accumulate with the step's quadrature (Quad { opl: q * h, .. }.with_start).
    let w = L::splat(A[5][0]) * h;
    let u0 = t.normalize_or_zero();
    let opl = q.0 * h + w * n0 * n0;
    let length = q.1 * h + w * n0;
    let swept = q.2.scale(h) + u0.scale(w * n0);
    finish_steps(
        s,
        bounds,
        committed,
        sd0,
        StepEnd {
            t,
            u0,
            d0,
            h,
            next: (nr, nt),
            lost: (lost_r, lost_t),
            end: (n1, g1),
            path: (opl, length, swept),
            error: (er, et),
        },
    );
}
