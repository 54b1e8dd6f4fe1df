// One step of the ray equation in t-parameter form, dr/dt = T, dT/dt = D(r) = n grad n.
// Each step takes D at the step start (sampled by the caller, not counted again).
// CPU twin: grin_trace::integrate (euler_step, symplectic_euler_step, verlet_step,
// sharma_step, rk4_step, dopri_step, step).

struct RayState {
    r: vec3<f32>,
    t: vec3<f32>,
}

struct Step {
    state: RayState,
    // Field evaluations made by the step (the start sample is the caller's).
    evals: u32,
    // The field at state.r when the step evaluated it anyway (verlet, dopri: FSAL).
    has_end: bool,
    end: FieldSample,
    // Local error estimate (e_r, e_T): the adaptive pair's embedded one, or Richardson's
    // of a doubled step.
    err_r: vec3<f32>,
    err_t: vec3<f32>,
    // The increments (dr, dT) the state is the start plus: march_medium adds them with
    // compensation (add_compensated), as the CPU's tracer does.
    delta: RayState,
    // rk4, sharma: the D their last stage used, for the third-order companion's error
    // estimate h/6 (D(r1) - check) (Step::check).
    check: vec3<f32>,
}

fn no_sample() -> FieldSample {
    return FieldSample(0.0, vec3<f32>(0.0), 0.0);
}

fn zero_state() -> RayState {
    return RayState(vec3<f32>(0.0), vec3<f32>(0.0));
}

// A state that is not a step's (a straight flight's end): no increments to compensate.
fn plain_step(r: vec3<f32>, t: vec3<f32>, evals: u32) -> Step {
    return Step(RayState(r, t), evals, false, no_sample(), vec3<f32>(0.0), vec3<f32>(0.0), zero_state(), vec3<f32>(0.0));
}

// s + (dr, dT) (Step::plain).
fn advance(s: RayState, dr: vec3<f32>, dt: vec3<f32>, evals: u32) -> Step {
    return Step(RayState(s.r + dr, s.t + dt), evals, false, no_sample(), vec3<f32>(0.0), vec3<f32>(0.0), RayState(dr, dt), vec3<f32>(0.0));
}

// Knuth's TwoSum per component: a + b rounded (sum) and the roundoff it lost (lost).
struct TwoSum {
    sum: vec3<f32>,
    lost: vec3<f32>,
}

// Both partial sums are multiplied by `params.roundoff_one` (1, unknown to the compiler):
// Mesa's NIR folds (a + b) - a to b in float operations not marked exact (WGSL cannot mark
// them), which compiled the compensation away on lavapipe.
fn two_sum(a: vec3<f32>, b: vec3<f32>) -> TwoSum {
    let sum = (a + b) * params.roundoff_one;
    let b_virtual = (sum - a) * params.roundoff_one;
    return TwoSum(sum, (a - (sum - b_virtual)) + (b - b_virtual));
}

// Compensated state update (integrate::add_compensated): s + delta + comp, leaving in comp
// what the new state could not hold. Start (and restart after a jump) with zero_state().
fn add_compensated(s: RayState, delta: RayState, comp: ptr<function, RayState>) -> RayState {
    let r = two_sum(s.r, delta.r + (*comp).r);
    let t = two_sum(s.t, delta.t + (*comp).t);
    *comp = RayState(r.lost, t.lost);
    return RayState(r.sum, t.sum);
}

// D = n grad n at p: one field evaluation.
fn sample_d(p: vec3<f32>) -> vec3<f32> {
    let f = sample_field(p);
    return f.grad_n * f.n;
}

fn euler_step(s: RayState, d0: vec3<f32>, h: f32) -> Step {
    return advance(s, s.t * h, d0 * h, 0u);
}

fn symplectic_euler_step(s: RayState, d0: vec3<f32>, h: f32) -> Step {
    let dt = d0 * h;
    return advance(s, (s.t + dt) * h, dt, 0u);
}

fn verlet_step(s: RayState, d0: vec3<f32>, h: f32) -> Step {
    let half = h * 0.5;
    let t_half = s.t + d0 * half;
    let dr = t_half * h;
    let r1 = s.r + dr;
    let end = sample_field(r1);
    let dt = (d0 + end.grad_n * end.n) * half;
    return Step(RayState(r1, s.t + dt), 1u, true, end, vec3<f32>(0.0), vec3<f32>(0.0), RayState(dr, dt), vec3<f32>(0.0));
}

// Sharma, Kumar & Ghatak 1982 (the paper's Listing 2): A = h D(r),
// B = h D(r + h/2 T + h/8 A), C = h D(r + h T + h/2 B).
fn sharma_step(s: RayState, d0: vec3<f32>, h: f32) -> Step {
    let a = d0 * h;
    let b = sample_d(s.r + s.t * (h * 0.5) + a * (h * 0.125)) * h;
    let d_c = sample_d(s.r + s.t * h + b * (h * 0.5));
    let c = d_c * h;
    let sixth = 1.0 / 6.0;
    let dr = (s.t + (a + b * 2.0) * sixth) * h;
    let dt = (a + b * 4.0 + c) * sixth;
    var step = advance(s, dr, dt, 2u);
    step.check = d_c;
    return step;
}

// Classical RK4 on (r, T).
fn rk4_step(s: RayState, d0: vec3<f32>, h: f32) -> Step {
    let half = h * 0.5;
    let t1 = s.t;
    let d1 = d0;
    let t2 = s.t + d1 * half;
    let d2 = sample_d(s.r + t1 * half);
    let t3 = s.t + d2 * half;
    let d3 = sample_d(s.r + t2 * half);
    let t4 = s.t + d3 * h;
    let d4 = sample_d(s.r + t3 * h);
    let sixth = h * (1.0 / 6.0);
    let dr = (t1 + t2 * 2.0 + t3 * 2.0 + t4) * sixth;
    let dt = (d1 + d2 * 2.0 + d3 * 2.0 + d4) * sixth;
    var step = advance(s, dr, dt, 3u);
    step.check = d4;
    return step;
}

// Dormand & Prince (1980) tableau rows a_ij (i = 2..7, 6 entries each; row 7 = the
// 5th-order weights) and the error weights b - b*.
const DOPRI_A = array<f32, 36>(
    1.0 / 5.0, 0.0, 0.0, 0.0, 0.0, 0.0,
    3.0 / 40.0, 9.0 / 40.0, 0.0, 0.0, 0.0, 0.0,
    44.0 / 45.0, -56.0 / 15.0, 32.0 / 9.0, 0.0, 0.0, 0.0,
    19372.0 / 6561.0, -25360.0 / 2187.0, 64448.0 / 6561.0, -212.0 / 729.0, 0.0, 0.0,
    9017.0 / 3168.0, -355.0 / 33.0, 46732.0 / 5247.0, 49.0 / 176.0, -5103.0 / 18656.0, 0.0,
    35.0 / 384.0, 0.0, 500.0 / 1113.0, 125.0 / 192.0, -2187.0 / 6784.0, 11.0 / 84.0,
);
const DOPRI_E = array<f32, 7>(
    71.0 / 57600.0, 0.0, -71.0 / 16695.0, 71.0 / 1920.0, -17253.0 / 339200.0, 22.0 / 525.0, -1.0 / 40.0,
);

// One Dormand-Prince 5(4) step with FSAL: 6 evaluations, the last at the new point.
// One loop over the stages, each stage's share added to the later stages' sums as soon as
// it is known (the sums in the CPU twin's order): 6 loop iterations a step (lavapipe stops
// a shader invocation's loops after 65535 iterations in all; the nested stage loops spent
// 27 a step) and one field sample in the code (lavapipe inlines every call: the stages
// written out, each with its own tricubic sample, took 4x as long to compile).
fn dopri_stage(s: RayState, dr: vec3<f32>, dt: vec3<f32>, h: f32) -> DopriStage {
    let dr_h = dr * h;
    let dt_h = dt * h;
    let f = sample_field(s.r + dr_h);
    return DopriStage(s.r + dr_h, s.t + dt_h, f.grad_n * f.n, f, RayState(dr_h, dt_h));
}

struct DopriStage {
    r: vec3<f32>,
    t: vec3<f32>,
    d: vec3<f32>,
    f: FieldSample,
    // The stage's increments from the step's start.
    delta: RayState,
}

fn dopri_step(s: RayState, d0: vec3<f32>, h: f32) -> Step {
    var a = DOPRI_A;
    var e = DOPRI_E;
    // Stage m's sums (m = 1..6 at m - 1): sum over j < m of a[(m - 1) * 6 + j] k_j.
    var acc_r: array<vec3<f32>, 6>;
    var acc_t: array<vec3<f32>, 6>;
    acc_r[0] = s.t * a[0];
    acc_t[0] = d0 * a[0];
    acc_r[1] = s.t * a[6];
    acc_t[1] = d0 * a[6];
    acc_r[2] = s.t * a[12];
    acc_t[2] = d0 * a[12];
    acc_r[3] = s.t * a[18];
    acc_t[3] = d0 * a[18];
    acc_r[4] = s.t * a[24];
    acc_t[4] = d0 * a[24];
    acc_r[5] = s.t * a[30];
    acc_t[5] = d0 * a[30];
    var er = s.t * e[0];
    var et = d0 * e[0];
    var k: DopriStage;
    for (var i = 1; i < 7; i++) {
        k = dopri_stage(s, acc_r[i - 1], acc_t[i - 1], h);
        if i < 2 {
            acc_r[1] += k.t * a[6 + i];
            acc_t[1] += k.d * a[6 + i];
        }
        if i < 3 {
            acc_r[2] += k.t * a[12 + i];
            acc_t[2] += k.d * a[12 + i];
        }
        if i < 4 {
            acc_r[3] += k.t * a[18 + i];
            acc_t[3] += k.d * a[18 + i];
        }
        if i < 5 {
            acc_r[4] += k.t * a[24 + i];
            acc_t[4] += k.d * a[24 + i];
        }
        if i < 6 {
            acc_r[5] += k.t * a[30 + i];
            acc_t[5] += k.d * a[30 + i];
        }
        er += k.t * e[i];
        et += k.d * e[i];
    }
    return Step(RayState(k.r, k.t), 6u, true, k.f, er * h, et * h, k.delta, vec3<f32>(0.0));
}

// Order of accuracy of the integrator's position (integrate::order).
fn integrator_order(kind: u32) -> u32 {
    switch kind {
        case INTEGRATOR_EULER, INTEGRATOR_SYMPLECTIC_EULER: {
            return 1u;
        }
        case INTEGRATOR_VERLET: {
            return 2u;
        }
        case INTEGRATOR_ADAPTIVE: {
            return 5u;
        }
        default: {
            return 4u;
        }
    }
}

// One step of the configured integrator (integrate::step).
fn integrate_step(s: RayState, d0: vec3<f32>, h: f32) -> Step {
    switch INTEGRATOR {
        case INTEGRATOR_EULER: {
            return euler_step(s, d0, h);
        }
        case INTEGRATOR_SYMPLECTIC_EULER: {
            return symplectic_euler_step(s, d0, h);
        }
        case INTEGRATOR_VERLET: {
            return verlet_step(s, d0, h);
        }
        case INTEGRATOR_RK4: {
            return rk4_step(s, d0, h);
        }
        case INTEGRATOR_ADAPTIVE: {
            return dopri_step(s, d0, h);
        }
        default: {
            return sharma_step(s, d0, h);
        }
    }
}
