// Leaving the medium: a step that ended outside cut at the surface (bisection, or the
// Hermite dense output and Newton steps), a step that left and came back between its
// ends re-taken to the point farthest out, the ray's status at the exit, and the nudge
// that keeps an entry point inside. The march that calls them is in medium.wgsl.
// CPU twin: grin_trace::trace::{exit_medium, excursion_step, segment_of_step,
// nudge_inside, RayStatus} and leave's choice of status.

const STATUS_MISSED: u32 = 0u;
const STATUS_EXITED: u32 = 1u;
const STATUS_ABSORBED: u32 = 2u;
const STATUS_MAX_STEPS: u32 = 3u;
const STATUS_ERROR: u32 = 4u;
const STATUS_DEGRADED: u32 = 5u;

// trace::ENTRY_NUDGE_EPS: a grazing entry point that rounds to outside the bounds is
// moved inside by this many units of roundoff (else the first step "exits" at once).
const ENTRY_NUDGE_EPS: f32 = 4.0;
// trace::ENTRY_NUDGE_MIN_COS: below this cosine of the refracted ray to the inward normal
// the nudge goes along the normal (along the ray it would run far along the surface).
const ENTRY_NUDGE_MIN_COS: f32 = 0.01;

// trace::EXIT_NEWTON_ITERATIONS.
const EXIT_NEWTON_ITERATIONS: u32 = 3u;

// STATUS_EXITED, or STATUS_DEGRADED where the estimate is above its limit or what the
// crossings of the bounds added (`surface`) is above CROSSING_FACTOR x the accuracy.
fn exit_status(e: ErrorEstimate, t: vec3<f32>, n: f32, normal: vec3<f32>, d: vec3<f32>, surface: f32) -> u32 {
    if estimate_value(e, t, n, normal, d) > params.estimate_limit || surface > CROSSING_FACTOR * params.accuracy {
        return STATUS_DEGRADED;
    }
    return STATUS_EXITED;
}

// trace::segment_of_step: the step from s that `taken` made, as a segment.
fn segment_of_step(s: RayState, taken: Taken) -> Segment {
    return Segment(s.r, s.t, taken.step.state.r, taken.step.state.t, taken.h);
}

struct ExcursionStep {
    found: bool,
    taken: Taken,
}

// trace::excursion_step: a step that ended inside, near the surface, whose path dips
// outside between its ends, re-taken to the point farthest out (when the integrator
// agrees it is outside).
fn excursion_step(s: RayState, s0: FieldSample, taken: Taken) -> ExcursionStep {
    let none = ExcursionStep(false, taken);
    let r1 = taken.step.state.r;
    let reach = taken.h * max(length(s.t), length(taken.step.state.t));
    if !(reach < INF) || !finite3(r1) {
        return none;
    }
    if bounds_signed_distance(s.r) < -reach && bounds_signed_distance(r1) < -reach {
        return none;
    }
    let e = segment_excursion(segment_of_step(s, taken), EXCURSION_SLACK_TOLS * exit_tolerance());
    if !e.found {
        return none;
    }
    let st = integrate_step(s, s0.grad_n * s0.n, e.tau);
    if bounds_signed_distance(st.state.r) > 0.0 {
        return ExcursionStep(true, Taken(st, e.tau, st.evals));
    }
    return none;
}

struct ExitOut {
    state: RayState,
    h: f32,
    evals: u32,
}

// The step from s ended outside the bounds: the state on the surface, the t-length
// reaching it, the evaluations spent.
fn exit_medium(s: RayState, s0: FieldSample, taken: Taken, tol: f32) -> ExitOut {
    let d0 = s0.grad_n * s0.n;
    if (FLAGS & FLAG_EXIT_HERMITE) != 0u {
        let seg = segment_of_step(s, taken);
        // Newton steps on the integrator's own state keep its order (trace::exit_medium).
        var tau = first_crossing(seg);
        var st = integrate_step(s, d0, tau);
        var evals = st.evals;
        for (var i = 0u; i < EXIT_NEWTON_ITERATIONS; i++) {
            let g = bounds_signed_distance(st.state.r);
            if abs(g) <= tol {
                break;
            }
            let slope = dot(bounds_normal(st.state.r), st.state.t);
            if !(slope > 0.0) {
                break;
            }
            let next_tau = clamp(tau - g / slope, 0.0, taken.h);
            let trial = integrate_step(s, d0, next_tau);
            evals += trial.evals;
            if abs(bounds_signed_distance(trial.state.r)) < abs(g) {
                tau = next_tau;
                st = trial;
            } else {
                break;
            }
        }
        var state = st.state;
        state.r = project_to_surface(state.r);
        return ExitOut(state, tau, evals);
    }
    var lo = 0.0;
    var hi = taken.h;
    var evals = 0u;
    var best_state = s;
    var best_h = 0.0;
    for (var i = 0u; i < MAX_BISECTIONS; i++) {
        let mid = 0.5 * (lo + hi);
        let st = integrate_step(s, d0, mid);
        evals += st.evals;
        let dist = bounds_signed_distance(st.state.r);
        if dist <= 0.0 {
            best_state = st.state;
            best_h = mid;
        }
        if abs(dist) <= tol {
            return ExitOut(st.state, mid, evals);
        }
        if dist > 0.0 {
            hi = mid;
        } else {
            lo = mid;
        }
        if hi - lo <= mid * F32_EPSILON {
            break;
        }
    }
    best_state.r = project_to_surface(best_state.r);
    return ExitOut(best_state, best_h, evals);
}

// trace::nudge_inside: an entry point that rounds to outside the bounds moves inwards a
// few units of roundoff, along the refracted ray (its own line: a move along the normal
// shifts the ray sideways, ~1e-6 of the bounds' size in f32, and bends its exit by as
// much). The march then starts `skip` further along the ray, and the caller adds the
// field's pull over that length to the ray's direction (one Euler step of dT/ds = grad n).
// Along the normal, with no skip, only where the ray all but grazes the surface.
struct Nudged {
    point: vec3<f32>,
    skip: f32,
}

fn nudge_inside(start: vec3<f32>, d_in: vec3<f32>) -> Nudged {
    if bounds_signed_distance(start) < 0.0 {
        return Nudged(start, 0.0);
    }
    let nudge = ENTRY_NUDGE_EPS * F32_EPSILON * (bounds_radius() + max(max(abs(start.x), abs(start.y)), abs(start.z)));
    let normal = bounds_normal(start);
    let cos_in = -dot(d_in, normal);
    if cos_in > ENTRY_NUDGE_MIN_COS {
        let skip = nudge / cos_in;
        let along = start + d_in * skip;
        if bounds_signed_distance(along) < 0.0 {
            return Nudged(along, skip);
        }
    }
    return Nudged(start - normal * nudge, 0.0);
}
