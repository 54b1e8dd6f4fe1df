//! Ray packets: the plain steps inside the medium of [`LANES`] rays at once, in lane
//! vectors the compiler turns into SIMD instructions (f64 lanes; the one piece of
//! target-specific code compiles the same step for AVX2, chosen at run time).
//!
//! A ray enters the medium, flies straight, meets a surface or anything else out of the
//! ordinary one ray at a time, in the scalar tracer ([`March::advance`]); a packet takes
//! the plain steps inside: a fourth-order Runge-Kutta step of fixed length, or a dopri
//! 5(4) step, fixed or error-controlled ([`dopri`]), in f64, that ends inside and stays
//! inside, either because both ends are farther from the surface than the step reaches
//! or because the scalar tracer's own excursion test proves its cubic inside (the steps
//! near the surface: the first ones after the entry, the last before the exit). A step
//! that ends outside starts its lane's exit search (crate::exit_search: the Hermite method's
//! re-steps, taken in the packet beside the other lanes' steps); the march then only
//! records the step and refracts out. Each step computes exactly what the scalar tracer
//! computes, operation for operation (the state with its compensated sums, the optical
//! path and length by the method's own rule, the ray's own error estimate, the near-miss
//! check, the exit search), so a table traced in packets is bit for bit the table traced
//! ray by ray (tested). The lanes' state stays in lane vectors between packet calls; a
//! lane moves back into its ray's march only for the march's own step, and a ray that
//! leaves hands its lane to the next of the queue.
//!
//! Over 600 lines: one concept, the packets' driver and the rk4 packet step with the
//! bookkeeping every packet step shares (the lane vectors, state and twin tests are apart).

use std::array;

use glam::DVec3;
use grin_field::{Bounds, IndexField, Real};
use grin_scene::{ExitMethod, IntegratorKind, StepSpec};

mod dopri;
mod lanes;
mod soa;
#[cfg(test)]
mod tests;

use lanes::{L, Mask, V, normal, sample, signed_distance, two_sum};
use soa::Soa;

use crate::boundary::{EXCURSION_SLACK_TOLS, Segment, exit_tolerance};
use crate::estimate::POSITION_SAFETY;
use crate::exit_search::{ExitSearch, Phase};
use crate::integrate::RayState;
use crate::step::StepController;
use crate::trace::{Control, March, MarchStart, RayResult};
use grin_render::settings::TraceSettings;

/// Rays a packet advances together.
pub const LANES: usize = 4;

/// Packet steps (a dopri packet's attempts) in one packet call at most: the driver then
/// sees to the lanes again (none need it while all of them step).
const STEPS_PER_GATHER: usize = 32;

/// Whether `settings` are ones the packets take (the packets trace in f64):
/// fourth-order Runge-Kutta at fixed steps, or dopri 5(4) under error control
/// (`adaptive` or `auto` steps) or at fixed steps ([`dopri`]).
pub fn packets_apply(settings: &TraceSettings) -> bool {
    match settings.integrator {
        IntegratorKind::Rk4 => matches!(settings.step, StepSpec::Fixed(_)),
        IntegratorKind::Adaptive => matches!(
            settings.step,
            StepSpec::Adaptive { .. } | StepSpec::Auto(_) | StepSpec::Fixed(_)
        ),
        _ => false,
    }
}

/// Whether a table traced in precision `R` with `settings` runs in packets: f64, and
/// [`packets_apply`].
pub fn traced_in_packets<R: Real>(settings: &TraceSettings) -> bool {
    R::EPS.to_f64() == f64::EPSILON && packets_apply(settings)
}

/// What a packet call did: the steps each lane took, and the lanes that need a step of
/// their own march now (the step that leaves, a flight, `max_steps`, a jittered first
/// step, ...).
#[derive(Debug, Clone, Copy)]
struct Took {
    steps: [u32; LANES],
    own: [bool; LANES],
}

impl Took {
    /// No steps; every ray in a lane needs its march.
    fn all_own(lanes: &[Option<(usize, March<f64>)>; LANES]) -> Took {
        Took {
            steps: [0; LANES],
            own: array::from_fn(|i| lanes[i].is_some()),
        }
    }
}

/// Trace `rays` (origin, direction) with `settings`: the same results as
/// `trace_ray::<f64>` ray by ray, in packets where [`packets_apply`] holds (else ray by
/// ray).
pub fn trace_packets(
    field: &dyn IndexField,
    settings: &TraceSettings,
    rays: &[(DVec3, DVec3)],
) -> Vec<RayResult> {
    trace_packets_counted(field, settings, rays).0
}

/// [`trace_packets`] into `out` (one result a ray, in order; `out.len() == rays.len()`),
/// with what the packets did: a caller tracing a table writes each chunk's results in
/// place, with no vector of its own to gather and copy.
pub fn trace_packets_into(
    field: &dyn IndexField,
    settings: &TraceSettings,
    rays: &[(DVec3, DVec3)],
    out: &mut [RayResult],
) -> PacketCounts {
    assert_eq!(rays.len(), out.len(), "one result a ray");
    if !packets_apply(settings) {
        for (o, &(origin, dir)) in out.iter_mut().zip(rays) {
            *o = crate::trace::trace_ray::<f64>(field, settings, origin, dir);
        }
        return PacketCounts::default();
    }
    trace_packets_with(field, settings, rays, out, packet_step(settings, false))
}

/// What the packets did of a trace: the plain steps they took, and the exits they found
/// (the step that leaves, searched in the packet; the march only records it). The rest
/// was the scalar tracer's.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PacketCounts {
    pub steps: u64,
    pub exits: u64,
}

/// [`trace_packets`], with what the packets did.
pub fn trace_packets_counted(
    field: &dyn IndexField,
    settings: &TraceSettings,
    rays: &[(DVec3, DVec3)],
) -> (Vec<RayResult>, PacketCounts) {
    let mut out = vec![untraced_result(); rays.len()];
    let counts = trace_packets_into(field, settings, rays, &mut out);
    (out, counts)
}

/// The packets' trace of `rays` into `out` (the same length): every ray's result is set
/// before the queue and the lanes run dry.
fn trace_packets_with(
    field: &dyn IndexField,
    settings: &TraceSettings,
    rays: &[(DVec3, DVec3)],
    out: &mut [RayResult],
    march_packet: PacketStep,
) -> PacketCounts {
    let mut counts = PacketCounts::default();
    let mut queue = 0..rays.len();
    let mut lanes: [Option<(usize, March<f64>)>; LANES] = array::from_fn(|_| None);
    // The lanes' state stays in lane vectors between packet calls; a lane moves back
    // into its march only for the march's own steps (and moves in again after them).
    let mut soa = Soa::new();
    let mut cont = |_: &Segment| Control::Continue;
    let init = MarchStart::new::<f64>(field, settings);
    loop {
        for (i, slot) in lanes.iter_mut().enumerate() {
            while slot.is_none() {
                let Some(k) = queue.next() else { break };
                let (o, d) = rays[k];
                match March::<f64>::begin_from(&init, field, settings, o, d, 1.0) {
                    Ok(m) => {
                        soa.load(i, &m);
                        *slot = Some((k, m));
                    }
                    Err(done) => out[k] = done,
                }
            }
        }
        if lanes.iter().all(Option::is_none) {
            break;
        }
        let took = march_packet(field, settings, &lanes, &mut soa);
        // The lanes the packet could not step: one step of their own march each.
        for (i, slot) in lanes.iter_mut().enumerate() {
            counts.steps += u64::from(took.steps[i]);
            if !took.own[i] {
                continue;
            }
            let Some((k, m)) = slot else { continue };
            soa.store(i, m);
            let done = match soa.exits[i].take_found(&m.bounds) {
                Some(exit) => {
                    counts.exits += 1;
                    m.finish_exit(field, &mut cont, exit)
                }
                None => m.advance(field, settings, &mut cont),
            };
            match done {
                Some(done) => {
                    out[*k] = done;
                    *slot = None;
                }
                None => soa.load(i, m),
            }
        }
    }
    counts
}

/// What a new result slot holds until its ray is traced: an `error` with no estimate it
/// could vouch for. Every ray's result is written, the packets' and the one-ray
/// tracer's alike (the test `traced_rows_fill_a_reused_vector_as_a_fresh_one`).
pub(crate) fn untraced_result() -> RayResult {
    RayResult {
        error_estimate: f64::INFINITY,
        ..RayResult::at(crate::trace::RayStatus::Error, DVec3::ZERO, DVec3::ZERO)
    }
}

/// The packet step a trace uses: [`march_packet_in`] (RK4) or [`dopri::march_dopri_in`]
/// as compiled for the CPU's widest lane vectors (AVX2 on x86-64 CPUs that have it: one
/// 256-bit register per lane vector), else as compiled for the target. The same IEEE
/// operations in the same order either way (no fused multiply-add), so the results do not
/// depend on which.
type PacketStep =
    fn(&dyn IndexField, &TraceSettings, &[Option<(usize, March<f64>)>; LANES], &mut Soa) -> Took;

fn packet_step(settings: &TraceSettings, portable: bool) -> PacketStep {
    let dopri = settings.integrator == IntegratorKind::Adaptive;
    #[cfg(target_arch = "x86_64")]
    if !portable && std::arch::is_x86_feature_detected!("avx2") {
        return if dopri { dopri_avx2 } else { rk4_avx2 };
    }
    if dopri {
        dopri::march_dopri_in
    } else {
        march_packet_in
    }
}

/// `$name`: the packet step `$step` compiled for AVX2; called only where the CPU has it.
macro_rules! avx2_build {
    ($name:ident, $step:path) => {
        #[cfg(target_arch = "x86_64")]
        #[allow(unsafe_code)]
        fn $name(
            field: &dyn IndexField,
            settings: &TraceSettings,
            lanes: &[Option<(usize, March<f64>)>; LANES],
            soa: &mut Soa,
        ) -> Took {
            #[target_feature(enable = "avx2")]
            fn compiled(
                field: &dyn IndexField,
                settings: &TraceSettings,
                lanes: &[Option<(usize, March<f64>)>; LANES],
                soa: &mut Soa,
            ) -> Took {
                $step(field, settings, lanes, soa)
            }
            debug_assert!(std::arch::is_x86_feature_detected!("avx2"));
            // SAFETY: `packet_step` hands this function out only on CPUs with AVX2.
            unsafe { compiled(field, settings, lanes, soa) }
        }
    };
}
avx2_build!(rk4_avx2, march_packet_in);
avx2_build!(dopri_avx2, dopri::march_dopri_in);

/// Plain steps of the occupied lanes while they all can take them (up to
/// [`STEPS_PER_GATHER`]); returns the steps each lane took.
// The lane loops index several lane arrays at once.
#[allow(clippy::needless_range_loop)]
#[inline(always)]
fn march_packet_in(
    field: &dyn IndexField,
    settings: &TraceSettings,
    lanes: &[Option<(usize, March<f64>)>; LANES],
    s: &mut Soa,
) -> Took {
    let mut took = [0u32; LANES];
    let mut ds = [f64::NAN; LANES];
    let mut feature_cap = [f64::INFINITY; LANES];
    let mut bounds = None;
    let mut min_flight = [0.0; LANES];
    for (i, lane) in lanes.iter().enumerate() {
        if let Some((_, m)) = lane
            && let Some(d) = m.ctrl.fixed_ds()
        {
            ds[i] = d;
            feature_cap[i] = m.ctrl.feature_cap();
            min_flight[i] = m.min_flight;
            bounds = Some(m.bounds);
        }
    }
    let Some(bounds) = bounds else {
        return Took::all_own(lanes);
    };
    let occupied: [bool; LANES] = array::from_fn(|i| lanes[i].is_some() && ds[i].is_finite());
    let ds = L(ds);
    let feature_cap = L(feature_cap);
    // The signed distance of each lane's point (carried from the step that got there).
    let mut sd0 = signed_distance(&bounds, s.r);
    // The exit search's tolerance, and the scalar tracer's slack for proving a step
    // near the surface inside.
    let exit_tol = exit_tolerance::<f64>(&bounds);
    let slack = EXCURSION_SLACK_TOLS * exit_tol;
    let hermite = settings.exit == ExitMethod::Hermite;
    // Whether the field's macro cells and local caps need asking at every step.
    let local_limits = field.has_local_step_limits();
    // The lanes still with the packet after a step (a plain step taken, or an exit
    // search under way); at the end, those that are not need their march.
    let mut stay = [false; LANES];
    for _ in 0..STEPS_PER_GATHER {
        // Lanes searching for their exit take the re-step due; the others, the step the
        // scalar tracer would give them now if it is a plain one, of its length
        // (StepController::take for a fixed step after the first).
        let searching: [bool; LANES] =
            array::from_fn(|i| occupied[i] && s.exits[i].phase == Phase::Search);
        let g_len = s.g0.length();
        let mut cap = L(array::from_fn(|i| {
            StepController::length_scale_cap(s.n0.0[i], g_len.0[i])
        }))
        .zip(feature_cap, f64::min);
        let mut active: [bool; LANES] =
            array::from_fn(|i| occupied[i] && s.may_step(i, settings.max_steps));
        if local_limits {
            for i in 0..LANES {
                if !active[i] {
                    continue;
                }
                match local_cap(field, settings, s, i, min_flight[i], cap.0[i], |c| {
                    ds.0[i].min(c)
                }) {
                    Some(c) => cap.0[i] = c,
                    None => active[i] = false,
                }
            }
        }
        let hi = ds.zip(cap, f64::min) / s.n0;
        for i in 0..LANES {
            active[i] &= hi.0[i] > 0.0;
        }
        let mut h = Mask::of(active).select(hi, L::splat(0.0));
        for i in 0..LANES {
            if searching[i] {
                h.0[i] = s.exits[i].trial;
            }
        }
        stay = array::from_fn(|i| active[i] || searching[i]);
        if !stay.iter().any(|&a| a) {
            break;
        }
        // rk4_step, lane by lane.
        let (r, t) = (s.r, s.t);
        let d0 = s.g0.scale(s.n0);
        let half = h * L::splat(0.5);
        let t1 = t;
        let d1 = d0;
        let t2 = t + d1.scale(half);
        let (n, g) = sample(field, r + t1.scale(half));
        let d2 = g.scale(n);
        let t3 = t + d2.scale(half);
        let (n, g) = sample(field, r + t2.scale(half));
        let d3 = g.scale(n);
        let t4 = t + d3.scale(h);
        let (n, g) = sample(field, r + t3.scale(h));
        let d4 = g.scale(n);
        let sixth = h * L::splat(1.0 / 6.0);
        let two = L::splat(2.0);
        let dr = (t1 + t2.scale(two) + t3.scale(two) + t4).scale(sixth);
        let dt = (d1 + d2.scale(two) + d3.scale(two) + d4).scale(sixth);
        let r_end = r + dr;
        let t_end = t + dt;
        // The scalar tracer's tests (`excursion_step`): not outside, and no excursion:
        // both ends deeper than the step reaches, or else the step's cubic proven
        // inside (the common case near the surface, and the same test).
        let plain = plain_steps(&bounds, slack, &active, sd0, (r, t), (r_end, t_end), h);
        // A step that left begins its lane's exit search, a re-step goes on with it
        // (rk4_step's own 3 evaluations each: the exit's sample is its march's).
        let rk4_evals = u64::from(crate::integrate::evals_per_step(IntegratorKind::Rk4)) - 1;
        for i in 0..LANES {
            if !searching[i] && (plain[i] || !active[i]) {
                continue;
            }
            let (end, seg) = lane_step((r, t), (r_end, t_end), h, i);
            if searching[i] {
                s.evals[i] += rk4_evals;
                s.exits[i].restepped(&bounds, exit_tol, end, None);
                stay[i] = s.exits[i].phase == Phase::Search;
            } else {
                stay[i] = hermite && leaves(&bounds, s, i, dr.lane(i), end);
                if stay[i] {
                    s.evals[i] += rk4_evals;
                    s.exits[i] = ExitSearch::begin(&bounds, seg, None);
                }
            }
        }
        if plain.iter().any(|&a| a) {
            // add_compensated.
            let (nr, lost_r) = two_sum(r, dr + s.comp_r);
            let (nt, lost_t) = two_sum(t, dt + s.comp_t);
            // The end sample (rk4 has none of its own).
            let (n1, g1) = sample(field, nr);
            let d1_end = g1.scale(n1);
            // accumulate: the cubic Hermite rule.
            let (n0, g0) = (s.n0, s.g0);
            let dn0 = g0.dot(t);
            let dn1 = g1.dot(nt);
            let h2 = h * h / L::splat(12.0);
            let length = L::splat(0.5) * h * (n0 + n1) + h2 * (dn0 - dn1);
            let opl = L::splat(0.5) * h * (n0 * n0 + n1 * n1)
                + h2 * L::splat(2.0) * (n0 * dn0 - n1 * dn1);
            let (u0, u1) = (t.normalize_or_zero(), nt.normalize_or_zero());
            let d_swept = |n: L, dn: L, u: V, g: V| u.scale(dn) + (g - u.scale(u.dot(g))).scale(n);
            let swept = (u0.scale(n0) + u1.scale(n1)).scale(L::splat(0.5) * h)
                + (d_swept(n0, dn0, u0, g0) - d_swept(n1, dn1, u1, g1)).scale(h2);
            // ErrorEstimate::step with the third-order companion's e_T = h/6 (D(r1) - D4)
            // (its early return cannot happen: h and n0 are positive here).
            let et = (d1_end - d4).scale(h / L::splat(6.0));
            let er = et.scale(L::splat(0.5) * h);
            finish_steps(
                s,
                &bounds,
                &plain,
                &mut sd0,
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
            // The step's own 3 and the end sample.
            for i in 0..LANES {
                if plain[i] {
                    s.evals[i] += rk4_evals + 1;
                    took[i] += 1;
                }
            }
        }
        if (0..LANES).any(|i| occupied[i] && !stay[i]) {
            break;
        }
    }
    Took {
        steps: took,
        own: array::from_fn(|i| lanes[i].is_some() && !stay[i]),
    }
}

/// Lane `i`'s step cap `cap` lowered to the field's own local cap over the step's reach
/// (`reach` of the cap: `StepController::take`'s), or `None` where the lane flies straight
/// over a homogeneous macro cell instead (its march's step).
#[inline(always)]
fn local_cap(
    field: &dyn IndexField,
    settings: &TraceSettings,
    s: &Soa,
    i: usize,
    min_flight: f64,
    cap: f64,
    reach: impl Fn(f64) -> f64,
) -> Option<f64> {
    let p = s.r.lane(i);
    let flies = settings.macro_cells
        && field
            .homogeneous_span(p, s.t.lane(i).normalize_or_zero())
            .is_some_and(|span| span > min_flight);
    (!flies).then(|| cap.min(field.step_cap(p, reach(cap))))
}

/// Lane `i`'s step from `start` to `end` (position and T) over `h`: the state it
/// reached, and its segment.
#[inline(always)]
fn lane_step(start: (V, V), end: (V, V), h: L, i: usize) -> (RayState<f64>, Segment) {
    let state = RayState {
        r: end.0.lane(i),
        t: end.1.lane(i),
    };
    let seg = Segment {
        r0: start.0.lane(i),
        t0: start.1.lane(i),
        r1: state.r,
        t1: state.t,
        h: h.0[i],
    };
    (state, seg)
}

/// Whether lane `i`'s step (its position increment `dr`, its end `end`) left the medium
/// as the one-ray tracer sees it: its end outside, and the compensated sum the march
/// would form finite (else the march finds no exit: its own step handles the lane).
fn leaves(bounds: &Bounds, s: &Soa, i: usize, dr: DVec3, end: RayState<f64>) -> bool {
    bounds.signed_distance(end.r) > 0.0 && (s.r.lane(i) + (dr + s.comp_r.lane(i))).is_finite()
}

/// The lanes among `candidates` whose step (from `start` to `end`, position and T, over
/// `h`) the one-ray tracer would take as a plain one (`excursion_step`): not outside,
/// and no excursion between its ends: both ends deeper than the step reaches, or else
/// the step's cubic proven inside by the same test (the common case near the surface).
/// `sd0`: the signed distance at the start.
#[inline(always)]
fn plain_steps(
    bounds: &Bounds,
    slack: f64,
    candidates: &[bool; LANES],
    sd0: L,
    start: (V, V),
    end: (V, V),
    h: L,
) -> [bool; LANES] {
    let ((r, t), (r_end, t_end)) = (start, end);
    let sd1 = signed_distance(bounds, r_end);
    let reach = h * t.length().zip(t_end.length(), f64::max);
    array::from_fn(|i| {
        candidates[i]
            && reach.0[i].is_finite()
            && r_end.finite(i)
            && ((sd0.0[i] < -reach.0[i] && sd1.0[i] < -reach.0[i])
                || (sd1.0[i] <= 0.0
                    && Segment {
                        r0: r.lane(i),
                        t0: t.lane(i),
                        r1: r_end.lane(i),
                        t1: t_end.lane(i),
                        h: h.0[i],
                    }
                    .excursion(|p| bounds.signed_distance(p), slack)
                    .is_none()))
    })
}

/// What a lane's accepted step leaves: the step's start direction T0 (and its unit
/// vector), D at its start, its t-length, the new state and its lost low parts (the
/// compensated sums), the sample at its end (n, grad n), what it adds to the optical
/// path, the length and the swept vector, and its local errors (position, T).
struct StepEnd {
    t: V,
    u0: V,
    d0: V,
    h: L,
    next: (V, V),
    lost: (V, V),
    end: (L, V),
    path: (L, L, V),
    error: (V, V),
}

/// The one-ray tracer's bookkeeping after a plain step, in the `stepped` lanes: the new
/// state, the sums of the path, the ray's error estimate (`ErrorEstimate::step` with the
/// step's local errors), and the near-miss check at the new point (`check_approach`);
/// `sd0` becomes the signed distance there.
#[allow(clippy::needless_range_loop)]
#[inline(always)]
fn finish_steps(s: &mut Soa, bounds: &Bounds, stepped: &[bool; LANES], sd0: &mut L, e: StepEnd) {
    let StepEnd {
        t,
        u0,
        d0,
        h,
        next: (nr, nt),
        lost: (lost_r, lost_t),
        end: (n1, g1),
        path: (opl, length, swept),
        error: (er, et),
    } = e;
    let n0 = s.n0;
    let d1 = g1.scale(n1);
    let across_v = |v: V| v - u0.scale(v.dot(u0));
    let across = |v: V| across_v(v).length();
    let local = across_v(et);
    let local_r = across(er);
    let bend_inc = across(d0) * h / n0;
    let feedback = across(d1 - d0) * s.pos / n0;
    let direction = s.vsum.length() + s.sum;
    let turned = t.dot(nt);
    let pos_new = s.pos + (local_r + direction * h * n0);
    let vsum_new = s.vsum + local.over(n0);
    let sum_new = s.sum + feedback / n0;
    let sd_new = signed_distance(bounds, nr);
    let m = Mask::of(*stepped);
    s.r = m.select_v(nr, s.r);
    s.t = m.select_v(nt, s.t);
    s.comp_r = m.select_v(lost_r, s.comp_r);
    s.comp_t = m.select_v(lost_t, s.comp_t);
    s.length = m.select(s.length + length, s.length);
    s.opl = m.select(s.opl + opl, s.opl);
    s.swept = m.select_v(s.swept + swept, s.swept);
    s.last_local = m.select_v(local, s.last_local);
    s.last_r = m.select(local_r, s.last_r);
    s.bend = m.select(s.bend + bend_inc, s.bend);
    let counted = Mask::of(array::from_fn(|i| {
        stepped[i] && local.finite(i) && local_r.0[i].is_finite() && feedback.0[i].is_finite()
    }));
    s.pos = counted.select(pos_new, s.pos);
    s.vsum = counted.select_v(vsum_new, s.vsum);
    s.sum = counted.select(sum_new, s.sum);
    *sd0 = m.select(sd_new, *sd0);
    s.n0 = m.select(n1, s.n0);
    s.g0 = m.select_v(g1, s.g0);
    // ErrorEstimate::check_approach at the new point. Its test needs 0 < v <= kappa |h|,
    // so v^2 / (2 kappa) <= |h| v / 2 <= |h| / 2 (v a cosine) and closest >= -sd - |h| / 2:
    // where every lane is deeper than |h| past POSITION_SAFETY pos, no lane's test can hold
    // (NaNs fail the depth test, so their lanes are tested), and the normals are skipped.
    let deep = |i: usize| -sd_new.0[i] - h.0[i].abs() > POSITION_SAFETY * s.pos.0[i];
    let (v, kappa, closest) = if (0..LANES).any(|i| stepped[i] && !deep(i)) {
        let normals = normal(bounds, nr);
        let v = nt.normalize_or_zero().dot(normals);
        let kappa = -d1.dot(normals) / (n1 * n1);
        (v, kappa, -sd_new - v * v / (L::splat(2.0) * kappa))
    } else {
        (L::splat(0.0), L::splat(0.0), L::splat(f64::INFINITY))
    };
    for i in 0..LANES {
        if !stepped[i] {
            continue;
        }
        if turned.0[i] <= 0.0 {
            s.near_miss[i] = true;
        }
        let n = n1.0[i];
        if !(s.near_miss[i] || n.is_nan() || n <= 0.0)
            && v.0[i] > 0.0
            && kappa.0[i] > 0.0
            && v.0[i] <= kappa.0[i] * h.0[i].abs()
            && closest.0[i].abs() < POSITION_SAFETY * s.pos.0[i]
        {
            s.near_miss[i] = true;
        }
        s.steps[i] += 1;
    }
}
