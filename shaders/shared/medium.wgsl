// The passage through the medium: enter (refracting at the surface), step with the
// integrator and step policy (or fly straight through homogeneous macro cells), test
// each step's chord against the scene objects (the paper's step 4), find where the ray
// leaves (bisection or Hermite dense output), refract out with the Fresnel weight (total
// internal reflection sends it back in), and account for the optical path.
// CPU twins: grin_trace::trace::{trace_ray_observed, exit_medium, leave, accumulate},
// grin_trace::boundary::{refract, project_to_surface, Segment::first_crossing},
// grin_trace::render::medium::SceneMedium::march_medium.

// Offset of a ray from a surface it starts on. The CPU uses 1e-6 in f64; in f32 at
// scene scale ~10 an ulp is ~1e-6, so the GPU needs a larger push to stay off surfaces.
const SURFACE_EPS: f32 = 1e-4;
// boundary::MAX_BISECTIONS, HERMITE_SCAN; trace::MIN_SPAN_REL.
const MAX_BISECTIONS: u32 = 64u;
const HERMITE_SCAN: u32 = 8u;
const MIN_SPAN_REL: f32 = 1e-9;
// A straight flight shorter than this fraction of a voxel is not taken (an integration
// step is, which is just as straight in a homogeneous cell). In f32 a ray sitting on a
// macro-cell face can get a span of a few ulps that does not move it: without this
// floor such rays repeat zero-length flights until max_steps (seen on the heat-haze
// scene at 640x360: 1557 steps/ray on the GPU vs 16.5 on the CPU).
const MIN_FLIGHT_VOXELS: f32 = 1e-3;
// boundary::EXIT_TOL_REL (unreachable in f32: the bisection stops when the step
// fraction runs out of bits, then projects onto the surface, as the CPU's f32 path does).
const EXIT_TOL_REL: f32 = 1e-14;
const F32_EPSILON: f32 = 1.1920929e-7;
// boundary::EXIT_TOL_EPS: the tolerance is at least this much roundoff times the
// bounds' largest coordinate.
const EXIT_TOL_EPS: f32 = 4.0;

// boundary::exit_tolerance in f32.
fn exit_tolerance() -> f32 {
    var coordinates = max_element(abs(params.bounds_center)) + params.bounds_radius;
    if bounds_is_box() {
        coordinates = max_element(max(abs(params.box_min), abs(params.box_max)));
    }
    return max(EXIT_TOL_REL * bounds_radius(), EXIT_TOL_EPS * F32_EPSILON * coordinates);
}
// trace::ENTRY_NUDGE_EPS: a grazing entry point that rounds to outside the bounds is
// moved inside by this many units of roundoff (else the first step "exits" at once).
const ENTRY_NUDGE_EPS: f32 = 4.0;
// trace::ENTRY_NUDGE_MIN_COS: below this cosine of the refracted ray to the inward normal
// the nudge goes along the normal (along the ray it would run far along the surface).
const ENTRY_NUDGE_MIN_COS: f32 = 0.01;

const END_EXITED: u32 = 0u;
const END_OBJECT: u32 = 1u;
const END_MISSED: u32 = 2u;
const END_STOPPED: u32 = 3u;

// Why march_medium's hot loop stopped: a stop (max_steps, error), a step ending outside
// the bounds, a flight ending on them, an object met.
const MARCH_EVENT_STOP: u32 = 0u;
const MARCH_EVENT_LEAVE: u32 = 1u;
const MARCH_EVENT_SURFACE: u32 = 2u;
const MARCH_EVENT_OBJECT: u32 = 3u;

const STATUS_MISSED: u32 = 0u;
const STATUS_EXITED: u32 = 1u;
const STATUS_ABSORBED: u32 = 2u;
const STATUS_MAX_STEPS: u32 = 3u;
const STATUS_ERROR: u32 = 4u;
const STATUS_DEGRADED: u32 = 5u;

// The ray's own error estimate, for every integrator and step policy
// (grin_trace::estimate::ErrorEstimate): a ray leaving with it above params.estimate_limit,
// or with its crossings' n uncertainty above CROSSING_FACTOR x params.accuracy, ends
// STATUS_DEGRADED, not STATUS_EXITED.
const CROSSING_FACTOR: f32 = 10.0;
const POSITION_SAFETY: f32 = 4.0;
// The estimate of an exit that is itself uncertain (the CPU's is infinite; WGSL has no
// infinity literal).
const UNSURE_ESTIMATE: f32 = 3.0e38;

struct ErrorEstimate {
    // The integrator's order (the difference formulas for 1 and 2).
    order: u32,
    // The position errors' feedback so far (the local errors are in vsum).
    sum: f32,
    bend: f32,
    pos: f32,
    near_miss: bool,
    has_prev: bool,
    prev_d: vec3<f32>,
    prev_h: f32,
    // The last step's local errors (across the ray, position), for a step that reports
    // none (a fourth-order step cut at the surface).
    last_local: vec3<f32>,
    last_local_r: f32,
    // Symplectic Euler: T is half a kick off the leapfrog's (h/2 D at the last step end).
    staggered: bool,
    staggered_half: vec3<f32>,
    // The local direction errors summed as vectors (their leading terms telescope along
    // a weakly bending ray).
    vsum: vec3<f32>,
}

fn estimate_new() -> ErrorEstimate {
    let staggered = INTEGRATOR == INTEGRATOR_SYMPLECTIC_EULER;
    var order = integrator_order(INTEGRATOR);
    if staggered {
        order = 2u;
    }
    return ErrorEstimate(order, 0.0, 0.0, 0.0, false, false, vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0.0, staggered, vec3<f32>(0.0), vec3<f32>(0.0));
}

// The local error (e_r, e_T) a step reports, for estimate_step: the adaptive pair's
// embedded one or a doubled step's Richardson's (`step.err_r`, `err_t`), a fourth-order
// step's companion against D at its end `d1` (not for a step cut at the surface: `cut`),
// or none (`reported` false).
struct Reported {
    reported: bool,
    er: vec3<f32>,
    et: vec3<f32>,
}

fn reported_error(step: Step, d1: vec3<f32>, h: f32, cut: bool) -> Reported {
    if INTEGRATOR == INTEGRATOR_ADAPTIVE || STEP_POLICY == STEP_ADAPTIVE {
        return Reported(true, step.err_r, step.err_t);
    }
    if (INTEGRATOR == INTEGRATOR_RK4 || INTEGRATOR == INTEGRATOR_SHARMA) && !cut {
        let et = (d1 - step.check) * (h / 6.0);
        return Reported(true, et * (0.5 * h), et);
    }
    return Reported(false, vec3<f32>(0.0), vec3<f32>(0.0));
}

// v across the unit direction u, and its length.
fn across_v(v: vec3<f32>, u: vec3<f32>) -> vec3<f32> {
    return v - u * dot(v, u);
}

fn across(v: vec3<f32>, u: vec3<f32>) -> f32 {
    return length(across_v(v, u));
}

// The direction error so far: the local errors' vector sum and the feedback.
fn estimate_direction(e: ErrorEstimate) -> f32 {
    return length(e.vsum) + e.sum;
}

// A step of t-length h from T = t0, D = d0 (index n0) to T = t1, D = d1.
fn estimate_step(e: ptr<function, ErrorEstimate>, t0: vec3<f32>, t1: vec3<f32>, d0: vec3<f32>, d1: vec3<f32>, h: f32, n0: f32, rep: Reported) {
    if !(h > 0.0) || !(n0 > 0.0) {
        return;
    }
    if dot(t0, t1) <= 0.0 {
        (*e).near_miss = true;
    }
    let u = normalize_or_zero(t0);
    var local = vec3<f32>(0.0);
    var local_r = 0.0;
    if rep.reported {
        local = across_v(rep.et, u);
        local_r = across(rep.er, u);
    } else if (*e).order == 1u {
        local = 0.5 * h * across_v(d1 - d0, u);
        local_r = 0.5 * h * h * across(d0, u);
    } else if (*e).order == 2u {
        if (*e).has_prev && (*e).prev_h > 0.0 {
            let hp = (*e).prev_h;
            let second = 2.0 * ((d1 - d0) / h - (d0 - (*e).prev_d) / hp) / (h + hp);
            local = h * h * h / 12.0 * across_v(second, u);
        } else if (*e).staggered {
            // Symplectic Euler's first kick of a sequence is a whole one.
            local = 0.5 * h * across_v(d0, u);
        }
        local_r = h * h / 6.0 * across(d1 - d0, u);
    } else {
        local = (*e).last_local;
        local_r = (*e).last_local_r;
    }
    (*e).last_local = local;
    (*e).last_local_r = local_r;
    (*e).staggered_half = d1 * (0.5 * h);
    (*e).bend += across(d0, u) * h / n0;
    // The position error's feedback: D sampled e_r off turns T by |dD/dr| e_r h (the
    // change of D across the ray only).
    let feedback = across(d1 - d0, u) * (*e).pos / n0;
    if finite3(local) && finite3(vec3<f32>(local_r, feedback, 0.0)) {
        (*e).pos += local_r + estimate_direction(*e) * h * n0;
        (*e).vsum += local / n0;
        (*e).sum += feedback / n0;
    }
    (*e).has_prev = true;
    (*e).prev_d = d0;
    (*e).prev_h = h;
}

// At a step end inside, `depth` from the surface of outward unit `normal`, after a step
// of length h: a near miss if the path's closest approach is within the position error
// of the surface, where the path's parabola turns within a step (ErrorEstimate::check_approach).
fn estimate_check_approach(e: ptr<function, ErrorEstimate>, depth: f32, normal: vec3<f32>, t: vec3<f32>, n: f32, d: vec3<f32>, h: f32) {
    if (*e).near_miss || !(n > 0.0) {
        return;
    }
    let v = dot(normalize_or_zero(t), normal);
    let kappa = -dot(d, normal) / (n * n);
    if v > 0.0 && kappa > 0.0 && v <= kappa * abs(h) {
        let closest = depth - v * v / (2.0 * kappa);
        if abs(closest) < POSITION_SAFETY * (*e).pos {
            (*e).near_miss = true;
        }
    }
}

// The estimate at an exit through `normal` with T = t, index n, D = d (infinite where
// the exit itself is uncertain).
fn estimate_value(e: ErrorEstimate, t: vec3<f32>, n: f32, normal: vec3<f32>, d: vec3<f32>) -> f32 {
    if !(n > 0.0) {
        return 0.0;
    }
    let drift = abs(length(t) - n) / n * 2.0 * e.bend;
    let u = normalize_or_zero(t);
    let c = abs(dot(u, normal));
    let curvature = across(d, u) / (n * n);
    let reach = 2.0 * curvature * POSITION_SAFETY * e.pos;
    if reach > c * c || e.near_miss || !(c > 0.0) {
        return UNSURE_ESTIMATE;
    }
    // The position error moves the crossing along the path by pos / c.
    let shift = curvature * e.pos / c;
    var offset = 0.0;
    if e.staggered {
        offset = across(e.staggered_half, u) / n;
    }
    return max(estimate_direction(e) + shift + offset, drift);
}

// STATUS_EXITED, or STATUS_DEGRADED where the estimate is above its limit or what the
// crossings of the bounds added (`surface`) is above CROSSING_FACTOR x the accuracy.
fn exit_status(e: ErrorEstimate, t: vec3<f32>, n: f32, normal: vec3<f32>, d: vec3<f32>, surface: f32) -> u32 {
    if estimate_value(e, t, n, normal, d) > params.estimate_limit || surface > CROSSING_FACTOR * params.accuracy {
        return STATUS_DEGRADED;
    }
    return STATUS_EXITED;
}

// boundary::refraction_uncertainty: the direction error a refraction at the bounds adds
// when the field's n is uncertain by dn (amplified by tan of the refracted angle);
// UNSURE_ESTIMATE where dn could turn transmission into total reflection or back.
fn refraction_uncertainty(d: vec3<f32>, normal: vec3<f32>, n1: f32, n2: f32, n_field: f32, dn: f32) -> f32 {
    if !(dn > 0.0) {
        return 0.0;
    }
    let cos_i = min(abs(dot(d, normal)), 1.0);
    let eta = n1 / n2;
    let sin2_t = eta * eta * (1.0 - cos_i * cos_i);
    if abs(1.0 - sin2_t) <= 2.0 * sin2_t * dn / n_field {
        return UNSURE_ESTIMATE;
    }
    if sin2_t >= 1.0 {
        return 0.0;
    }
    return dn * sqrt(sin2_t / (1.0 - sin2_t)) / n_field;
}

struct MarchStats {
    steps: u32,
    evals: u32,
    opl: f32,
    length: f32,
    // The optical path difference in two small parts, each summed with f32's relative
    // precision (opl - n_amb * straight cancels ~1 m to keep ~1e-5 m: the interferogram
    // was noise): excess = integral of (n - n_amb) ds, geo = integral of (1 - u . dir0) ds,
    // u the ray's unit direction and dir0 the direction it came in with.
    excess: f32,
    geo: f32,
    dir0: vec3<f32>,
}

fn march_stats_new(dir0: vec3<f32>) -> MarchStats {
    return MarchStats(0u, 0u, 0.0, 0.0, 0.0, 0.0, dir0);
}

// 1 - u . dir0 for unit u as |u - dir0|^2 / 2: no cancellation at small angles.
fn off_axis(u: vec3<f32>, dir0: vec3<f32>) -> f32 {
    let w = u - dir0;
    return 0.5 * dot(w, w);
}

struct MarchEnd {
    kind: u32,
    // For END_STOPPED: STATUS_MAX_STEPS or STATUS_ERROR.
    status: u32,
    point: vec3<f32>,
    dir: vec3<f32>,
    transmittance: f32,
    hit: Hit,
}

fn no_hit() -> Hit {
    return Hit(false, 0.0, vec3<f32>(0.0), vec3<f32>(0.0), false, 0u);
}

fn march_end(kind: u32, status: u32, point: vec3<f32>, dir: vec3<f32>, transmittance: f32) -> MarchEnd {
    return MarchEnd(kind, status, point, dir, transmittance, no_hit());
}

// Snell's law at a surface with unit normal (either orientation), from n1 into n2.
struct Interface {
    transmitted: bool,
    dir: vec3<f32>,
    reflectance: f32,
}

fn fresnel(n1: f32, n2: f32, cos_i: f32, cos_t: f32) -> f32 {
    let rs = (n1 * cos_i - n2 * cos_t) / (n1 * cos_i + n2 * cos_t);
    let rp = (n1 * cos_t - n2 * cos_i) / (n1 * cos_t + n2 * cos_i);
    return 0.5 * (rs * rs + rp * rp);
}

fn refract(d: vec3<f32>, normal: vec3<f32>, n1: f32, n2: f32) -> Interface {
    let nrm = select(normal, -normal, dot(d, normal) > 0.0);
    let cos_i = clamp(-dot(d, nrm), 0.0, 1.0);
    let eta = n1 / n2;
    let sin2_t = eta * eta * (1.0 - cos_i * cos_i);
    if sin2_t >= 1.0 {
        return Interface(false, reflect_dir(d, nrm), 1.0);
    }
    let cos_t = sqrt(1.0 - sin2_t);
    let dir = normalize(d * eta + nrm * (eta * cos_i - cos_t));
    return Interface(true, dir, fresnel(n1, n2, cos_i, cos_t));
}

fn project_to_surface(p: vec3<f32>) -> vec3<f32> {
    if bounds_is_box() {
        let bmin = params.box_min;
        let bmax = params.box_max;
        let normal = bounds_normal(p);
        var q = clamp(p, bmin, bmax);
        for (var axis = 0; axis < 3; axis++) {
            if normal[axis] > 0.0 {
                q[axis] = bmax[axis];
            } else if normal[axis] < 0.0 {
                q[axis] = bmin[axis];
            }
        }
        return q;
    }
    let c = params.bounds_center;
    let d = p - c;
    let len = length(d);
    if len > 0.0 {
        return c + d * (params.bounds_radius / len);
    }
    return p;
}

// Cubic Hermite dense output of one step over t in [0, h].
struct Segment {
    r0: vec3<f32>,
    t0: vec3<f32>,
    r1: vec3<f32>,
    t1: vec3<f32>,
    h: f32,
}

fn segment_point(seg: Segment, tau: f32) -> vec3<f32> {
    if seg.h == 0.0 {
        return seg.r0;
    }
    let u = tau / seg.h;
    let u2 = u * u;
    let u3 = u2 * u;
    let h00 = 2.0 * u3 - 3.0 * u2 + 1.0;
    let h10 = u3 - 2.0 * u2 + u;
    let h01 = -2.0 * u3 + 3.0 * u2;
    let h11 = u3 - u2;
    return seg.r0 * h00 + seg.t0 * (h10 * seg.h) + seg.r1 * h01 + seg.t1 * (h11 * seg.h);
}

// Smallest tau in [0, h] where the dense output crosses out of the bounds: an
// 8-point scan, then the Illinois method on the bracket until it is one ulp wide
// (bisection when the start reads outside, after total reflection).
fn first_crossing(seg: Segment) -> f32 {
    var lo = 0.0;
    var f_lo = 0.0;
    var hi = seg.h;
    var f_hi = 0.0;
    var found = false;
    for (var k = 1u; k <= HERMITE_SCAN; k++) {
        let tau = seg.h * f32(k) / f32(HERMITE_SCAN);
        let v = bounds_signed_distance(segment_point(seg, tau));
        if v > 0.0 {
            hi = tau;
            f_hi = v;
            found = true;
            break;
        }
        lo = tau;
        f_lo = v;
    }
    if lo == 0.0 {
        f_lo = bounds_signed_distance(seg.r0);
    }
    let secant = found && f_lo <= 0.0 && f_hi > 0.0;
    var stuck = 0;
    for (var i = 0u; i < MAX_BISECTIONS; i++) {
        let mid = 0.5 * (lo + hi);
        var m = mid;
        if secant {
            m = hi - f_hi * (hi - lo) / (f_hi - f_lo);
            if !(m > lo && m < hi) {
                m = mid;
            }
        }
        if m <= lo || m >= hi {
            break;
        }
        let v = bounds_signed_distance(segment_point(seg, m));
        if v > 0.0 {
            hi = m;
            f_hi = v;
            if stuck > 0 {
                f_lo *= 0.5;
            }
            stuck = 1;
        } else {
            lo = m;
            f_lo = v;
            if stuck < 0 {
                f_hi *= 0.5;
            }
            stuck = -1;
        }
    }
    return 0.5 * (lo + hi);
}

// trace::EXIT_NEWTON_ITERATIONS and boundary::EXCURSION_ITERATIONS,
// EXCURSION_SLACK_TOLS.
const EXIT_NEWTON_ITERATIONS: u32 = 3u;
const EXCURSION_ITERATIONS: u32 = 40u;
const EXCURSION_SLACK_TOLS: f32 = 8.0;
const INV_PHI: f32 = 0.618034;

struct Excursion {
    found: bool,
    tau: f32,
}

// Segment::bend: how far the cubic can bend off the chord between two of its points
// len apart, M len^2 / 8 with M = max |r''| (linear in t: its larger end value).
fn segment_bend(seg: Segment, len: f32) -> f32 {
    if !(seg.h > 0.0) {
        return 0.0;
    }
    let d = seg.r1 - seg.r0;
    let a0 = length(6.0 * d - 4.0 * seg.h * seg.t0 - 2.0 * seg.h * seg.t1);
    let a1 = length(-6.0 * d + 2.0 * seg.h * seg.t0 + 4.0 * seg.h * seg.t1);
    let u = len / seg.h;
    return max(a0, a1) / 8.0 * u * u;
}

// For a step whose ends are both inside: where its dense output goes farthest outside,
// if it leaves and comes back between them (Segment::excursion): a scan, then golden
// section around the largest sample; either stops with "none" once the samples and the
// cubic's bend prove the segment (or the bracket) inside by `slack` (the bounds' signed
// distance is convex and 1-Lipschitz). A ray running along the surface then spends no
// loop iterations here: lavapipe caps them per invocation.
fn segment_excursion(seg: Segment, slack: f32) -> Excursion {
    if !(seg.h > 0.0) {
        return Excursion(false, 0.0);
    }
    let f0 = bounds_signed_distance(seg.r0);
    let f1 = bounds_signed_distance(seg.r1);
    if max(f0, f1) + segment_bend(seg, seg.h) + slack < 0.0 {
        return Excursion(false, 0.0);
    }
    var best_k = 1u;
    var best_v = -INF;
    for (var k = 1u; k < HERMITE_SCAN; k++) {
        let tau = seg.h * f32(k) / f32(HERMITE_SCAN);
        let v = bounds_signed_distance(segment_point(seg, tau));
        if v > 0.0 {
            return Excursion(true, tau);
        }
        if v > best_v {
            best_k = k;
            best_v = v;
        }
    }
    if max(best_v, max(f0, f1)) + segment_bend(seg, seg.h / f32(HERMITE_SCAN)) + slack < 0.0 {
        return Excursion(false, 0.0);
    }
    var a = seg.h * f32(best_k - 1u) / f32(HERMITE_SCAN);
    var b = seg.h * f32(min(best_k + 1u, HERMITE_SCAN)) / f32(HERMITE_SCAN);
    var c = b - (b - a) * INV_PHI;
    var d = a + (b - a) * INV_PHI;
    var fa = bounds_signed_distance(segment_point(seg, a));
    var fb = bounds_signed_distance(segment_point(seg, b));
    var fc = bounds_signed_distance(segment_point(seg, c));
    var fd = bounds_signed_distance(segment_point(seg, d));
    for (var i = 0u; i < EXCURSION_ITERATIONS; i++) {
        if fc > 0.0 {
            return Excursion(true, c);
        }
        if fd > 0.0 {
            return Excursion(true, d);
        }
        if max(max(fa, fb), max(fc, fd)) + segment_bend(seg, b - a) + slack < 0.0 {
            return Excursion(false, 0.0);
        }
        if fc > fd {
            b = d;
            fb = fd;
            d = c;
            fd = fc;
            c = b - (b - a) * INV_PHI;
            fc = bounds_signed_distance(segment_point(seg, c));
        } else {
            a = c;
            fa = fc;
            c = d;
            fc = fd;
            d = a + (b - a) * INV_PHI;
            fd = bounds_signed_distance(segment_point(seg, d));
        }
    }
    return Excursion(false, 0.0);
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

// Add one step's length and optical path (Hermite rule in t) and return its segment.
fn accumulate(stats: ptr<function, MarchStats>, a: RayState, sa: FieldSample, b: RayState, sb: FieldSample, h: f32) -> Segment {
    let n0 = sa.n;
    let n1 = sb.n;
    let dn0 = dot(sa.grad_n, a.t);
    let dn1 = dot(sb.grad_n, b.t);
    let h2 = h * h / 12.0;
    (*stats).length += 0.5 * h * (n0 + n1) + h2 * (dn0 - dn1);
    (*stats).opl += 0.5 * h * (n0 * n0 + n1 * n1) + h2 * 2.0 * (n0 * dn0 - n1 * dn1);
    // The same rule for (n - n_amb) n (d/dt: (2n - n_amb) n' = (n + delta) n') and for
    // off_axis(u) n (d/dt: g' n + g n', g' = (u - dir0) . (grad n - u (u . grad n))).
    let d0 = sa.delta_n;
    let d1 = sb.delta_n;
    (*stats).excess += 0.5 * h * (d0 * n0 + d1 * n1) + h2 * ((n0 + d0) * dn0 - (n1 + d1) * dn1);
    let dir0 = (*stats).dir0;
    let u0 = normalize_or_zero(a.t);
    let u1 = normalize_or_zero(b.t);
    let g0 = off_axis(u0, dir0);
    let g1 = off_axis(u1, dir0);
    let dg0 = dot(u0 - dir0, sa.grad_n - u0 * dot(u0, sa.grad_n));
    let dg1 = dot(u1 - dir0, sb.grad_n - u1 * dot(u1, sb.grad_n));
    (*stats).geo += 0.5 * h * (g0 * n0 + g1 * n1) + h2 * ((dg0 * n0 + g0 * dn0) - (dg1 * n1 + g1 * dn1));
    return Segment(a.r, a.t, b.r, b.t, h);
}

// The first object met by a segment's chord (render::medium::chord_hit). Only the
// objects that reach into the bounds are tested (params.medium_objects; none: no test at
// all); the CPU tests every object, and the others cannot meet a chord inside the bounds.
fn chord_hit(seg: Segment) -> Hit {
    if (FLAGS & FLAG_MEDIUM_OBJECTS) == 0u {
        return no_hit();
    }
    let chord = seg.r1 - seg.r0;
    let len = length(chord);
    if len == 0.0 {
        return no_hit();
    }
    return intersect_objects(params.medium_objects_first, params.medium_objects_count, seg.r0, chord / len, 0.0, len);
}

fn finite3(v: vec3<f32>) -> bool {
    return all(v - v == vec3<f32>(0.0));
}

fn sample_ok(f: FieldSample) -> bool {
    return f.n > 0.0 && f.n < INF;
}

// An object met inside the medium: keep only the chord up to the hit
// (SceneMedium::march_medium's `cut`).
fn absorbed(stats: ptr<function, MarchStats>, seg: Segment, hit: Hit, transmittance: f32) -> MarchEnd {
    let chord = seg.r1 - seg.r0;
    let len = length(chord);
    let cut = max(len - hit.t, 0.0);
    let at = sample_field(hit.point);
    (*stats).length -= cut;
    (*stats).opl -= at.n * cut;
    (*stats).excess -= at.delta_n * cut;
    (*stats).geo -= off_axis(chord / len, (*stats).dir0) * cut;
    return MarchEnd(END_OBJECT, STATUS_ABSORBED, hit.point, chord / len, transmittance, hit);
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

// Trace from `origin` (outside: find the entry and refract; inside: start marching)
// along unit `dir` until the ray leaves the medium, meets an object, or stops.
// `jitter` in (0, 1] scales the first integration step (1: none).
fn march_medium(origin: vec3<f32>, dir: vec3<f32>, jitter: f32, stats: ptr<function, MarchStats>) -> MarchEnd {
    let len2 = dot(dir, dir);
    if !finite3(origin) || !finite3(dir) || len2 == 0.0 {
        return march_end(END_STOPPED, STATUS_ERROR, origin, normalize_or_zero(dir), 1.0);
    }
    let d = dir / sqrt(len2);
    let n_amb = ambient_index();
    var transmittance = 1.0;
    var start = origin;
    let outside = bounds_signed_distance(origin) >= 0.0;
    if outside {
        let b = bounds_intersect(origin, d);
        if !b.found || b.s_out < 0.0 || b.s_out <= b.s_in {
            return march_end(END_MISSED, STATUS_MISSED, origin, d, 1.0);
        }
        start = origin + d * max(b.s_in, 0.0);
    }
    // Direction error the crossings of the bounds add (trace_ray's surface_error).
    var surface_err = 0.0;
    // The first sample: where the ray enters, or where it starts inside.
    var s0 = sample_field(start);
    (*stats).evals += 1u;
    var d_in = d;
    var skip = 0.0;
    if outside {
        if !sample_ok(s0) {
            return march_end(END_STOPPED, STATUS_ERROR, start, d, transmittance);
        }
        surface_err += refraction_uncertainty(d, bounds_normal(start), n_amb, s0.n, s0.n, params.n_uncertainty);
        let i = refract(d, bounds_normal(start), n_amb, s0.n);
        if !i.transmitted {
            return march_end(END_EXITED, select(STATUS_EXITED, STATUS_DEGRADED, surface_err > CROSSING_FACTOR * params.accuracy), start, i.dir, transmittance);
        }
        transmittance *= 1.0 - i.reflectance;
        d_in = i.dir;
        let nudged = nudge_inside(start, d_in);
        start = nudged.point;
        skip = nudged.skip;
    }
    var state = RayState(start, d_in * s0.n + s0.grad_n * skip);
    var ctrl = step_controller_new(jitter);
    var est = estimate_new();
    let len_scale = ctrl.len_scale;
    let exit_tol = exit_tolerance();
    let max_steps = params.max_steps;
    // The hot loop below takes steps and straight flights, which share its field
    // sample, length sum and object test, and breaks out for the rarer events (leaving
    // the bounds, an object, a stop), handled after it. SIMD implementations that run
    // both sides of a branch under a lane mask (lavapipe does) then pay for the event
    // code once per event instead of on every step; on a GPU it keeps divergent lanes
    // out of the step's critical path. Each outer pass ends with a counted step or
    // flight, or a total reflection after one: 2 * max_steps + 2 passes bound it.
    let min_flight = max(MIN_SPAN_REL * len_scale, MIN_FLIGHT_VOXELS / max_element(params.grid_inv_spacing));
    // Roundoff of the state updates not yet added in (compensated summation, reset at
    // every jump of the state: flights, the surface, reflections), as trace_ray.
    var comp = zero_state();
    for (var guard = 0u; guard < 2u * max_steps + 2u; guard++) {
        var event = MARCH_EVENT_STOP;
        var taken: Taken;
        var next: RayState;
        var s1: FieldSample;
        var seg: Segment;
        var hit: Hit;
        loop {
            if !finite3(state.r) || !finite3(state.t) || !sample_ok(s0) || (*stats).steps >= max_steps {
                event = MARCH_EVENT_STOP;
                break;
            }
            // A straight flight through homogeneous macro cells, else a step. Both end
            // in the same sample, length sum and object test below.
            let position = state.r;
            let direction = normalize_or_zero(state.t);
            var span = -1.0;
            if (FLAGS & FLAG_MACRO_CELLS) != 0u && may_fly(position) {
                span = homogeneous_span(position, direction);
            }
            let fly = (FLAGS & FLAG_MACRO_CELLS) != 0u && span > min_flight;
            var exits = false;
            var fly_len = 0.0;
            if fly {
                let b = bounds_intersect(position, direction);
                var to_exit = 0.0;
                if b.found {
                    to_exit = max(b.s_out, 0.0);
                }
                fly_len = min(span, to_exit);
                exits = span >= to_exit;
                var p1 = position + direction * fly_len;
                if exits {
                    p1 = project_to_surface(p1);
                }
                // (Every pass assigns all of `taken`: nothing of it is carried round the loop.)
                taken = Taken(plain_step(p1, state.t, 0u), fly_len / s0.n, 0u);
            } else {
                taken = take_step(&ctrl, state, s0);
            }
            (*stats).evals += taken.evals;
            next = taken.step.state;
            if !fly && bounds_signed_distance(next.r) > 0.0 {
                event = MARCH_EVENT_LEAVE;
                break;
            }
            if !fly {
                // Left and came back between the step's ends: cut there and leave.
                let cut = excursion_step(state, s0, taken);
                if cut.found {
                    taken = cut.taken;
                    (*stats).evals += taken.evals;
                    next = taken.step.state;
                    event = MARCH_EVENT_LEAVE;
                    break;
                }
            }
            if fly {
                comp = zero_state();
            } else {
                next = add_compensated(state, taken.step.delta, &comp);
            }
            if taken.step.has_end && !fly {
                s1 = taken.step.end;
            } else {
                (*stats).evals += 1u;
                s1 = sample_field(next.r);
            }
            if fly {
                let n = s0.n;
                (*stats).length += fly_len;
                (*stats).opl += n * fly_len;
                (*stats).excess += s0.delta_n * fly_len;
                (*stats).geo += off_axis(direction, (*stats).dir0) * fly_len;
                seg = Segment(position, direction * n, next.r, direction * n, taken.h);
                est.has_prev = false;
            } else {
                seg = accumulate(stats, state, s0, next, s1, taken.h);
                let d1 = s1.n * s1.grad_n;
                estimate_step(&est, state.t, next.t, s0.n * s0.grad_n, d1, taken.h, s0.n, reported_error(taken.step, d1, taken.h, false));
                estimate_check_approach(&est, -bounds_signed_distance(next.r), bounds_normal(next.r), next.t, s1.n, d1, taken.h);
            }
            (*stats).steps += 1u;
            hit = chord_hit(seg);
            if hit.found {
                event = MARCH_EVENT_OBJECT;
                break;
            }
            state = next;
            s0 = s1;
            if exits {
                event = MARCH_EVENT_SURFACE;
                break;
            }
        }

        if event == MARCH_EVENT_OBJECT {
            return absorbed(stats, seg, hit, transmittance);
        }
        if event == MARCH_EVENT_STOP {
            let position = state.r;
            let direction = normalize_or_zero(state.t);
            if (*stats).steps >= max_steps && finite3(position) && finite3(state.t) && sample_ok(s0) {
                return march_end(END_STOPPED, STATUS_MAX_STEPS, position, direction, transmittance);
            }
            return march_end(END_STOPPED, STATUS_ERROR, position, direction, transmittance);
        }
        if event == MARCH_EVENT_LEAVE {
            // The step ended outside: cut it at the surface (an infinite end is kept as
            // is, as the CPU's trace_ray keeps it).
            var h = taken.h;
            if finite3(next.r) {
                let ex = exit_medium(state, s0, taken, exit_tol);
                (*stats).evals += ex.evals;
                next = ex.state;
                h = ex.h;
            }
            (*stats).evals += 1u;
            s1 = sample_field(next.r);
            seg = accumulate(stats, state, s0, next, s1, h);
            let d1 = s1.n * s1.grad_n;
            estimate_step(&est, state.t, next.t, s0.n * s0.grad_n, d1, h, s0.n, reported_error(taken.step, d1, h, true));
            (*stats).steps += 1u;
            hit = chord_hit(seg);
            if hit.found {
                return absorbed(stats, seg, hit, transmittance);
            }
            state = next;
            s0 = s1;
        }
        // On the surface (a step cut there, or a flight to it): leave(), refract out or
        // reflect T totally back inside.
        let p = state.r;
        surface_err += refraction_uncertainty(normalize_or_zero(state.t), bounds_normal(p), s0.n, n_amb, s0.n, params.n_uncertainty);
        let i = refract(normalize_or_zero(state.t), bounds_normal(p), s0.n, n_amb);
        if i.transmitted {
            let status = exit_status(est, state.t, s0.n, bounds_normal(p), s0.n * s0.grad_n, surface_err);
            return march_end(END_EXITED, status, p, i.dir, transmittance * (1.0 - i.reflectance));
        }
        let nrm = bounds_normal(p);
        state.t = state.t - nrm * (2.0 * dot(state.t, nrm));
        est.has_prev = false;
        comp = zero_state();
    }
    return march_end(END_STOPPED, STATUS_MAX_STEPS, state.r, normalize_or_zero(state.t), transmittance);
}
