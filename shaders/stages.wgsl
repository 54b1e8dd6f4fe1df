// #import shared/types.wgsl shared/bindings.wgsl shared/rng.wgsl shared/camera.wgsl shared/primitives.wgsl shared/materials.wgsl shared/sky.wgsl shared/field.wgsl shared/integrate.wgsl shared/step.wgsl shared/estimate.wgsl shared/boundary.wgsl shared/trace.wgsl shared/medium.wgsl
//
// Test-only entry points: each runs one stage of the marcher on a batch of states, so the
// stage can be held against its CPU twin in isolation (crates/grin-gpu/tests/stages.rs,
// run by crates/grin-gpu/src/stages.rs). They read the frame parameters and the field
// texture of the render kernel (group 0), and for stage_scene its objects and sky.
//   stage_sample     sample_field                     grin_field::IndexField::sample_f32
//   stage_integrate  integrate_step (INTEGRATOR)      grin_trace::integrate::step
//   stage_take       take_step (STEP_POLICY)          grin_trace::step::StepController::take
//   stage_leave      take_step, excursion_step and    grin_trace::trace::{excursion_step,
//                    exit_medium (FLAG_EXIT_HERMITE)    exit_medium}
//   stage_flight     may_fly, homogeneous_span        grin_field::IndexField::homogeneous_span
//   stage_surface    bounds_intersect,                grin_field::Bounds::{intersect,
//                    bounds_signed_distance, refract    signed_distance}, boundary::refract
//   stage_scene      intersect_scene, sky_radiance    grin_render::primitives::intersect_scene,
//                                                     grin_render::sky::SkyModel::sky_radiance
//   stage_march      march_medium (a whole ray)       grin_trace::trace_ray (no jitter)
//
// stage_march is also the GPU column of `grin bench accuracy` (grin_gpu::march): a ray
// table traced by the render kernel's own medium loop.

// Keep in sync with grin_gpu::stages::StageIn.
struct StageIn {
    r: vec3<f32>,
    h: f32,          // stage_integrate: the t-step
    t: vec3<f32>,
    ds_adapt: f32,   // stage_take, stage_leave: the controller's current step (0: its first)
}

// Keep in sync with grin_gpu::stages::StageOut.
struct StageOut {
    r: vec3<f32>,
    h: f32,
    t: vec3<f32>,
    evals: u32,
    grad_n: vec3<f32>,
    n: f32,
    err_r: vec3<f32>,
    ds_next: f32,    // the controller's step after this one
    err_t: vec3<f32>,
    code: u32,       // stage_leave: 0 stayed inside, 1 the step ended outside, 2 it tunnelled;
                     // stage_flight: may_fly; stage_surface: bounds met, refraction transmitted;
                     // stage_march: STATUS_* | END_* << 8
}

@group(1) @binding(0) var<storage, read> stage_in: array<StageIn>;
@group(1) @binding(1) var<storage, read_write> stage_out: array<StageOut>;

const STAGE_WORKGROUP: u32 = 64u;

fn stage_blank() -> StageOut {
    return StageOut(vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0u, vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0u);
}

fn stage_controller(ds_adapt: f32) -> StepController {
    var ctrl = step_controller_new(1.0);
    if ds_adapt > 0.0 {
        ctrl.ds_adapt = ds_adapt;
    }
    return ctrl;
}

@compute @workgroup_size(64, 1, 1)
fn stage_sample(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= arrayLength(&stage_in) {
        return;
    }
    let f = sample_field(stage_in[gid.x].r);
    var out = stage_blank();
    out.n = f.n;
    out.grad_n = f.grad_n;
    out.h = f.delta_n;
    stage_out[gid.x] = out;
}

@compute @workgroup_size(64, 1, 1)
fn stage_integrate(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= arrayLength(&stage_in) {
        return;
    }
    let input = stage_in[gid.x];
    let s = RayState(input.r, input.t);
    let s0 = sample_field(s.r);
    let step = integrate_step(s, s0.grad_n * s0.n, input.h);
    var out = stage_blank();
    out.r = step.state.r;
    out.t = step.state.t;
    out.h = input.h;
    out.evals = step.evals;
    out.err_r = step.err_r;
    out.err_t = step.err_t;
    if step.has_end {
        out.n = step.end.n;
        out.grad_n = step.end.grad_n;
    }
    stage_out[gid.x] = out;
}

@compute @workgroup_size(64, 1, 1)
fn stage_take(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= arrayLength(&stage_in) {
        return;
    }
    let input = stage_in[gid.x];
    let s = RayState(input.r, input.t);
    let s0 = sample_field(s.r);
    var ctrl = stage_controller(input.ds_adapt);
    let taken = take_step(&ctrl, s, s0);
    var out = stage_blank();
    out.r = taken.step.state.r;
    out.t = taken.step.state.t;
    out.h = taken.h;
    out.evals = taken.evals;
    out.ds_next = ctrl.ds_adapt;
    stage_out[gid.x] = out;
}

// One step of the march near the surface: the step, the tunnelling check, the exit
// search (march_medium's order of them).
@compute @workgroup_size(64, 1, 1)
fn stage_leave(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= arrayLength(&stage_in) {
        return;
    }
    let input = stage_in[gid.x];
    let s = RayState(input.r, input.t);
    let s0 = sample_field(s.r);
    var ctrl = stage_controller(input.ds_adapt);
    var taken = take_step(&ctrl, s, s0);
    var evals = taken.evals;
    var code = 0u;
    if bounds_signed_distance(taken.step.state.r) > 0.0 {
        code = 1u;
    } else {
        let cut = excursion_step(s, s0, taken);
        if cut.found {
            taken = cut.taken;
            evals += taken.evals;
            code = 2u;
        }
    }
    var state = taken.step.state;
    var h = taken.h;
    if code != 0u && finite3(state.r) {
        let ex = exit_medium(s, s0, taken, exit_tolerance());
        evals += ex.evals;
        state = ex.state;
        h = ex.h;
    }
    var out = stage_blank();
    out.r = state.r;
    out.t = state.t;
    out.h = h;
    out.evals = evals;
    out.ds_next = ctrl.ds_adapt;
    out.code = code;
    stage_out[gid.x] = out;
}

// A straight flight from r along t: its length (h; -1 for none) and may_fly (code).
@compute @workgroup_size(64, 1, 1)
fn stage_flight(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= arrayLength(&stage_in) {
        return;
    }
    let input = stage_in[gid.x];
    var out = stage_blank();
    out.h = homogeneous_span(input.r, normalize_or_zero(input.t));
    out.code = select(0u, 1u, may_fly(input.r));
    stage_out[gid.x] = out;
}

// The medium's surface: the ray (r, t)'s interval through the bounds (h = s_in, n = s_out,
// code bit 0 = found), r's signed distance (ds_next), and the refraction of t's direction
// at the normal err_r from n1 = input.h into n2 = input.ds_adapt (out.t = direction,
// err_t.x = reflectance, code bit 1 = transmitted).
@compute @workgroup_size(64, 1, 1)
fn stage_surface(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= arrayLength(&stage_in) {
        return;
    }
    let input = stage_in[gid.x];
    let d = normalize_or_zero(input.t);
    let b = bounds_intersect(input.r, d);
    let nrm = bounds_normal(project_to_surface(input.r));
    let i = refract(d, nrm, input.h, input.ds_adapt);
    var out = stage_blank();
    out.h = b.s_in;
    out.n = b.s_out;
    out.ds_next = bounds_signed_distance(input.r);
    out.t = i.dir;
    out.err_r = nrm;
    out.err_t = vec3<f32>(i.reflectance, 0.0, 0.0);
    out.code = select(0u, 1u, b.found) | select(0u, 2u, i.transmitted);
    stage_out[gid.x] = out;
}

// The scene outside the medium: the nearest object along (r, t) beyond t_min = input.h
// (h = its distance or -1, err_r = the normal facing the ray, code = scene index + 1 or 0)
// and the sky's radiance in t's direction (grad_n).
@compute @workgroup_size(64, 1, 1)
fn stage_scene(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= arrayLength(&stage_in) {
        return;
    }
    let input = stage_in[gid.x];
    let d = normalize_or_zero(input.t);
    let hit = intersect_scene(input.r, d, input.h, INF);
    var out = stage_blank();
    out.h = select(-1.0, hit.t, hit.found);
    out.err_r = hit.normal;
    out.code = select(0u, hit.object + 1u, hit.found);
    out.grad_n = sky_radiance(d);
    stage_out[gid.x] = out;
}

// A whole ray through the medium from r along t (outside: entered with refraction, as a
// camera ray is), no jitter: the end point (r), direction (t), optical path (h), length
// (n), field evaluations, steps (ds_next, exact below 2^24), transmittance (err_t.x) and
// status (code: STATUS_* in the low byte, END_* in the next).
@compute @workgroup_size(64, 1, 1)
fn stage_march(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= arrayLength(&stage_in) {
        return;
    }
    let input = stage_in[gid.x];
    var stats = march_stats_new(input.t);
    let end = march_medium(input.r, input.t, 1.0, &stats);
    var out = stage_blank();
    out.r = end.point;
    out.t = end.dir;
    out.h = stats.opl;
    out.n = stats.length;
    out.evals = stats.evals;
    out.ds_next = f32(stats.steps);
    out.err_t = vec3<f32>(end.transmittance, 0.0, 0.0);
    out.code = end.status | (end.kind << 8u);
    stage_out[gid.x] = out;
}
