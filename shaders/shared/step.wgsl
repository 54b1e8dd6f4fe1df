// Step policies: fixed, the paper's gradient heuristic, and error control (the adaptive
// pair's embedded estimate, or step doubling with Richardson's estimate). Lengths are
// world lengths ds; h = ds / n at the step start. Plus the GPU's per-pixel jitter of the
// first step (turns banding into noise; off in GPU-vs-CPU comparisons).
// CPU twin: grin_trace::step::StepController.

// ADAPTIVE_MAX_DS_REL, ADAPTIVE_MIN_DS_REL, ADAPTIVE_INITIAL_DS_REL (of the bounds' radius).
const ADAPTIVE_MAX_DS_REL: f32 = 0.25;
const ADAPTIVE_MIN_DS_REL: f32 = 1e-12;
const ADAPTIVE_INITIAL_DS_REL: f32 = 0.01;
// step::ADAPTIVE_MIN_DS_EPS and ADAPTIVE_TOL_FLOOR_EPS: the f32 floors of the smallest step
// and the tolerance (units of roundoff times the radius), as the CPU's f32 path has them.
const ADAPTIVE_MIN_DS_EPS: f32 = 1e3;
const ADAPTIVE_TOL_FLOOR_EPS: f32 = 2.0;
// Controller safety factor and growth limits (Hairer, Norsett & Wanner II.4).
const SAFETY: f32 = 0.9;
const MAX_GROWTH: f32 = 5.0;
const MIN_SHRINK: f32 = 0.2;
const MAX_REJECTIONS: u32 = 60u;
// step::LENGTH_SCALE_STEP_FRACTION: every step is at most this fraction of n / |grad n|
// at its start (no reversal of T where n is small).
const LENGTH_SCALE_STEP_FRACTION: f32 = 0.5;
// step::FEATURE_STEP_FRACTION of the field's feature size: the GPU's field is a baked
// grid, whose feature size (BakedField::feature_size) is two spacings; a sparse bake's is
// local (SparseField::step_cap, sparse_step_cap).
const FEATURE_STEP_FRACTION: f32 = 1.0;
// Shortest jittered first step, as a fraction of the nominal step.
const MIN_JITTER_FRACTION: f32 = 1e-3;

struct StepController {
    len_scale: f32,
    ds_adapt: f32,
    // Factor for the next fixed/heuristic step (the jitter of the first step, then 1).
    jitter: f32,
}

struct Taken {
    step: Step,
    h: f32,
    evals: u32,
}

fn bounds_radius() -> f32 {
    if bounds_is_box() {
        return min_element((params.box_max - params.box_min) * 0.5);
    }
    return params.bounds_radius;
}

fn step_controller_new(jitter: f32) -> StepController {
    let len_scale = bounds_radius();
    var ds = ADAPTIVE_INITIAL_DS_REL * len_scale;
    // ds_initial > 0 carries the scene's adaptive `initial`.
    if STEP_POLICY == STEP_ADAPTIVE && params.ds_initial > 0.0 {
        ds = params.ds_initial;
    }
    return StepController(len_scale, ds, jitter);
}

// lerp(min, max, clamp(1 - |dir . grad n| / amplitude, 0, 1)).
fn heuristic_ds(ds_min: f32, ds_max: f32, amplitude: f32, dir: vec3<f32>, grad_n: vec3<f32>) -> f32 {
    var w = 1.0;
    if amplitude > 0.0 {
        w = clamp(1.0 - abs(dot(dir, grad_n)) / amplitude, 0.0, 1.0);
    }
    return ds_min + (ds_max - ds_min) * w;
}

fn error_norm(ctrl: StepController, er: vec3<f32>, et: vec3<f32>, n: f32) -> f32 {
    let pos = length(er);
    let dir = length(et) / max(abs(n), 1.17549435e-38) * ctrl.len_scale;
    return max(pos, dir);
}

struct Doubled {
    // The two half steps, with Richardson's (e_r, e_T) as their error.
    step: Step,
    // Its norm (error_norm at the midpoint's n).
    err: f32,
}

// Step doubling: one step of h and two of h/2; Richardson's error of the half steps.
fn doubled_step(ctrl: StepController, s: RayState, d0: vec3<f32>, h: f32, p: u32) -> Doubled {
    let half = h * 0.5;
    let big = integrate_step(s, d0, h);
    let first = integrate_step(s, d0, half);
    var mid = first.end;
    var mid_evals = 0u;
    if !first.has_end {
        mid = sample_field(first.state.r);
        mid_evals = 1u;
    }
    var second = integrate_step(first.state, mid.grad_n * mid.n, half);
    let scale = 1.0 / (f32(1u << p) - 1.0);
    let er = (second.state.r - big.state.r) * scale;
    let et = (second.state.t - big.state.t) * scale;
    let err = error_norm(ctrl, er, et, mid.n);
    second.evals = big.evals + first.evals + mid_evals + second.evals;
    // Both halves' increments from s (Controller::doubled).
    second.delta = RayState((first.state.r - s.r) + second.delta.r, (first.state.t - s.t) + second.delta.t);
    second.err_r = er;
    second.err_t = et;
    second.check = vec3<f32>(0.0);
    return Doubled(second, err);
}

// LENGTH_SCALE_STEP_FRACTION of n / |grad n| (infinite where grad n = 0).
fn length_scale_cap(n: f32, grad_n: f32) -> f32 {
    if grad_n > 0.0 && grad_n < INF {
        return LENGTH_SCALE_STEP_FRACTION * abs(n) / grad_n;
    }
    return INF;
}

fn take_adaptive(ctrl: ptr<function, StepController>, s: RayState, s0: FieldSample, tol_asked: f32, cap: f32) -> Taken {
    let n0 = s0.n;
    let d0 = s0.grad_n * s0.n;
    let kind = INTEGRATOR;
    let exponent = 1.0 / f32(integrator_order(kind));
    let ds_min = max(ADAPTIVE_MIN_DS_REL, ADAPTIVE_MIN_DS_EPS * F32_EPSILON) * (*ctrl).len_scale;
    let tol_floor = ADAPTIVE_TOL_FLOOR_EPS * F32_EPSILON * (*ctrl).len_scale;
    // `auto`: tol_asked is per unit path length (step::Tolerance).
    let per_length = params.tolerance_per_length != 0u;
    let ds_max = max(min(ADAPTIVE_MAX_DS_REL * (*ctrl).len_scale, cap), ds_min);
    var evals = 0u;
    var rejections = 0u;
    loop {
        let ds = clamp((*ctrl).ds_adapt, ds_min, ds_max);
        let h = ds / n0;
        var step: Step;
        var err: f32;
        if kind == INTEGRATOR_ADAPTIVE {
            step = dopri_step(s, d0, h);
            err = error_norm(*ctrl, step.err_r, step.err_t, n0);
        } else {
            let d = doubled_step(*ctrl, s, d0, h, integrator_order(kind));
            step = d.step;
            err = d.err;
        }
        evals += step.evals;
        var tol = tol_asked;
        if per_length {
            tol = tol_asked * ds;
        }
        tol = max(tol, tol_floor);
        let accept = err <= tol || ds <= ds_min || rejections >= MAX_REJECTIONS;
        var factor = MIN_SHRINK;
        if err > 0.0 && err < INF {
            factor = clamp(SAFETY * pow(tol / err, exponent), MIN_SHRINK, MAX_GROWTH);
        } else if err == 0.0 {
            factor = MAX_GROWTH;
        }
        (*ctrl).ds_adapt = clamp(ds * factor, ds_min, ds_max);
        if accept {
            return Taken(step, h, evals);
        }
        rejections += 1u;
    }
    // Unreachable: the loop accepts after MAX_REJECTIONS.
    return Taken(plain_step(s.r, s.t, 0u), 0.0, evals);
}

// Take one step from s (field sample s0 there), its length chosen by the policy.
fn take_step(ctrl: ptr<function, StepController>, s: RayState, s0: FieldSample) -> Taken {
    let n0 = s0.n;
    let d0 = s0.grad_n * s0.n;
    var feature = 2.0 / max_element(params.grid_inv_spacing);
    if (FLAGS & FLAG_SPARSE) != 0u {
        feature = sparse_step_cap(s.r);
    }
    let cap = min(length_scale_cap(n0, length(s0.grad_n)), FEATURE_STEP_FRACTION * feature);
    var ds: f32;
    switch STEP_POLICY {
        case STEP_HEURISTIC: {
            let dir = normalize_or_zero(s.t);
            ds = heuristic_ds(params.ds, params.ds_max, params.amplitude, dir, s0.grad_n);
        }
        case STEP_ADAPTIVE: {
            return take_adaptive(ctrl, s, s0, params.tolerance, cap);
        }
        default: {
            ds = params.ds;
        }
    }
    ds = min(ds * (*ctrl).jitter, cap);
    (*ctrl).jitter = 1.0;
    let h = ds / n0;
    let step = integrate_step(s, d0, h);
    return Taken(step, h, step.evals);
}

fn normalize_or_zero(v: vec3<f32>) -> vec3<f32> {
    let l = length(v);
    if l > 0.0 && l < INF {
        return v / l;
    }
    return vec3<f32>(0.0);
}

fn finite3(v: vec3<f32>) -> bool {
    return all(v - v == vec3<f32>(0.0));
}
