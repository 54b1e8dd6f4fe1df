// The passage through the medium: enter (refracting at the surface), step with the
// integrator and step policy (or fly straight through homogeneous macro cells), test
// each step's chord against the scene objects (the paper's step 4), find where the ray
// leaves (bisection or Hermite dense output), refract out with the Fresnel weight (total
// internal reflection sends it back in), and account for the optical path.
// The error estimate is in estimate.wgsl, the surface in boundary.wgsl, the exit in
// trace.wgsl.
// CPU twins: grin_trace::trace::{trace_ray_observed, leave, accumulate},
// grin_trace::render::medium::{CpuMedium::march_medium, chord_hit, MarchStats}.

// Offset of a ray from a surface it starts on. The CPU uses 1e-6 in f64; in f32 at
// scene scale ~10 an ulp is ~1e-6, so the GPU needs a larger push to stay off surfaces.
const SURFACE_EPS: f32 = 1e-4;
// trace::MIN_SPAN_REL.
const MIN_SPAN_REL: f32 = 1e-9;
// A straight flight shorter than this fraction of a voxel is not taken (an integration
// step is, which is just as straight in a homogeneous cell). In f32 a ray sitting on a
// macro-cell face can get a span of a few ulps that does not move it: without this
// floor such rays repeat zero-length flights until max_steps (seen on the heat-haze
// scene at 640x360: 1557 steps/ray on the GPU vs 16.5 on the CPU).
const MIN_FLIGHT_VOXELS: f32 = 1e-3;

const END_EXITED: u32 = 0u;
const END_OBJECT: u32 = 1u;
const END_MISSED: u32 = 2u;
const END_STOPPED: u32 = 3u;
// march_run's budget of steps ran out: the carry holds the ray, to be run on.
const END_SUSPENDED: u32 = 4u;
// march_run with no budget of steps (the march is whole, its one bound max_steps).
const MARCH_UNBOUNDED: u32 = 0xffffffffu;

// Why march_medium's hot loop stopped: a stop (max_steps, error), a step ending outside
// the bounds, a flight ending on them, an object met.
const MARCH_EVENT_STOP: u32 = 0u;
const MARCH_EVENT_LEAVE: u32 = 1u;
const MARCH_EVENT_SURFACE: u32 = 2u;
const MARCH_EVENT_OBJECT: u32 = 3u;
const MARCH_EVENT_SUSPEND: u32 = 4u;

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

// Trace from `origin` (outside: find the entry and refract; inside: start marching)
// along unit `dir` until the ray leaves the medium, meets an object, or stops.
// `jitter` in (0, 1] scales the first integration step (1: none).
fn march_medium(origin: vec3<f32>, dir: vec3<f32>, jitter: f32, stats: ptr<function, MarchStats>) -> MarchEnd {
    let begun = march_begin(origin, dir, jitter, stats);
    if begun.done {
        return begun.end;
    }
    var carry = begun.carry;
    return march_run(&carry, stats, MARCH_UNBOUNDED);
}

// Everything the march keeps from one pass of its loop to the next: all a split march
// (stages.wgsl's stage_march, a dispatch at a time) stores between its dispatches.
struct MarchCarry {
    state: RayState,
    // The field at state.r.
    s0: FieldSample,
    ctrl: StepController,
    est: ErrorEstimate,
    // Roundoff of the state updates not yet added in.
    comp: RayState,
    transmittance: f32,
    // Direction error the crossings of the bounds add (trace_ray's surface_error).
    surface_err: f32,
    // Passes of march_run's outer loop so far.
    guard: u32,
}

// march_begin: the end where the ray missed the medium or stopped at its surface
// (`done`), else the march's state at its first step.
struct MarchBegin {
    done: bool,
    end: MarchEnd,
    carry: MarchCarry,
}

fn march_begun(end: MarchEnd) -> MarchBegin {
    var b: MarchBegin;
    b.done = true;
    b.end = end;
    return b;
}

// The ray into the medium: the entry found and refracted (from outside), the first
// sample, the controller and the estimate.
fn march_begin(origin: vec3<f32>, dir: vec3<f32>, jitter: f32, stats: ptr<function, MarchStats>) -> MarchBegin {
    let len2 = dot(dir, dir);
    if !finite3(origin) || !finite3(dir) || len2 == 0.0 {
        return march_begun(march_end(END_STOPPED, STATUS_ERROR, origin, normalize_or_zero(dir), 1.0));
    }
    let d = dir / sqrt(len2);
    let n_amb = ambient_index();
    var transmittance = 1.0;
    var start = origin;
    let outside = bounds_signed_distance(origin) >= 0.0;
    if outside {
        let b = bounds_intersect(origin, d);
        if !b.found || b.s_out < 0.0 || b.s_out <= b.s_in {
            return march_begun(march_end(END_MISSED, STATUS_MISSED, origin, d, 1.0));
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
            return march_begun(march_end(END_STOPPED, STATUS_ERROR, start, d, transmittance));
        }
        surface_err += refraction_uncertainty(d, bounds_normal(start), n_amb, s0.n, s0.n, params.n_uncertainty);
        let i = refract(d, bounds_normal(start), n_amb, s0.n);
        if !i.transmitted {
            return march_begun(march_end(END_EXITED, select(STATUS_EXITED, STATUS_DEGRADED, surface_err > CROSSING_FACTOR * params.accuracy), start, i.dir, transmittance));
        }
        transmittance *= 1.0 - i.reflectance;
        d_in = i.dir;
        let nudged = nudge_inside(start, d_in);
        start = nudged.point;
        skip = nudged.skip;
    }
    var begun: MarchBegin;
    begun.done = false;
    begun.carry = MarchCarry(RayState(start, d_in * s0.n + s0.grad_n * skip), s0, step_controller_new(jitter), estimate_new(), zero_state(), transmittance, surface_err, 0u);
    return begun;
}

// Run the march on from `carry` until the ray leaves the medium, meets an object or
// stops, or until `budget` steps and flights are taken (END_SUSPENDED, the carry updated
// to run on from: the same steps, in the same arithmetic, as one whole run).
fn march_run(carry: ptr<function, MarchCarry>, stats: ptr<function, MarchStats>, budget: u32) -> MarchEnd {
    var state = (*carry).state;
    var s0 = (*carry).s0;
    var ctrl = (*carry).ctrl;
    var est = (*carry).est;
    // Roundoff of the state updates not yet added in (compensated summation, reset at
    // every jump of the state: flights, the surface, reflections), as trace_ray.
    var comp = (*carry).comp;
    var transmittance = (*carry).transmittance;
    var surface_err = (*carry).surface_err;
    let n_amb = ambient_index();
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
    // Steps and flights this call (against `budget`).
    var taken_here = 0u;
    for (var guard = (*carry).guard; guard < 2u * max_steps + 2u; guard++) {
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
            if taken_here >= budget {
                (*carry) = MarchCarry(state, s0, ctrl, est, comp, transmittance, surface_err, guard);
                event = MARCH_EVENT_SUSPEND;
                break;
            }
            taken_here += 1u;
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

        if event == MARCH_EVENT_SUSPEND {
            return march_end(END_SUSPENDED, STATUS_ERROR, state.r, normalize_or_zero(state.t), transmittance);
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

// ErrorEstimate with its flags as u32.
struct ErrorEstimateStored {
    order: u32,
    sum: f32,
    bend: f32,
    pos: f32,
    near_miss: u32,
    has_prev: u32,
    prev_d: vec3<f32>,
    prev_h: f32,
    last_local: vec3<f32>,
    last_local_r: f32,
    staggered: u32,
    staggered_half: vec3<f32>,
    vsum: vec3<f32>,
}

// MarchCarry and MarchStats as a storage buffer holds them between dispatches (stages.wgsl's
// stage_march, render.wgsl's PASS_MEDIUM), and whether the ray is still marching (1) or
// has finished (0).
struct MarchCarryStored {
    state: RayState,
    s0: FieldSample,
    ctrl: StepController,
    est: ErrorEstimateStored,
    comp: RayState,
    transmittance: f32,
    surface_err: f32,
    guard: u32,
    marching: u32,
    stats: MarchStats,
}

fn march_carry_store(c: MarchCarry, stats: MarchStats) -> MarchCarryStored {
    let e = c.est;
    let est = ErrorEstimateStored(e.order, e.sum, e.bend, e.pos, u32(e.near_miss), u32(e.has_prev), e.prev_d, e.prev_h, e.last_local, e.last_local_r, u32(e.staggered), e.staggered_half, e.vsum);
    return MarchCarryStored(c.state, c.s0, c.ctrl, est, c.comp, c.transmittance, c.surface_err, c.guard, 1u, stats);
}

fn march_carry_load(c: MarchCarryStored) -> MarchCarry {
    let e = c.est;
    let est = ErrorEstimate(e.order, e.sum, e.bend, e.pos, e.near_miss != 0u, e.has_prev != 0u, e.prev_d, e.prev_h, e.last_local, e.last_local_r, e.staggered != 0u, e.staggered_half, e.vsum);
    return MarchCarry(c.state, c.s0, c.ctrl, est, c.comp, c.transmittance, c.surface_err, c.guard);
}
