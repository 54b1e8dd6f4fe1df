// The ray's own error estimate along the march: each step's local error (the one it
// reports, or its integrator's difference formula) and the position error's feedback,
// summed, and its value at the exit.
// CPU twin: grin_trace::estimate::ErrorEstimate (reported_error: the `reported` errors
// of grin_trace::trace::March::advance).

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
