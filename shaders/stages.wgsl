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
//   stage_march      march_begin, march_run (a whole  grin_trace::trace_ray (no jitter)
//                    ray, over as many dispatches
//                    as it needs)
//
// stage_march is also the GPU column of `grin bench accuracy` (grin_gpu::march): a ray
// table traced by the render kernel's own medium loop. It alone also binds its rays'
// state between dispatches (binding 2) and the dispatches' control (binding 3).

// Each stage reads and writes structs of its own (stage_take and stage_leave read the
// same, as do stage_flight and stage_march), mirrored member by member in
// grin_gpu::stages (its tests check the two agree). Every entry point binds its input
// array at group 1, binding 0 and its output array at binding 1; the variables below
// alias those two bindings, one pair per entry point, and the specialised pipeline keeps
// only its entry point's pair.

// stage_sample: a point.
struct SampleIn {
    r: vec3<f32>,
}

// stage_sample: the field there.
struct SampleOut {
    grad_n: vec3<f32>,
    n: f32,
    delta_n: f32,
}

// stage_integrate: the state (r, t) and the t-step h.
struct IntegrateIn {
    r: vec3<f32>,
    h: f32,
    t: vec3<f32>,
}

// stage_integrate: the end state, the field evaluations (the start sample not counted),
// the step's end sample where it made one (else zero), and the adaptive pair's embedded
// error estimate (e_r, e_T).
struct IntegrateOut {
    r: vec3<f32>,
    evals: u32,
    t: vec3<f32>,
    end_n: f32,
    end_grad_n: vec3<f32>,
    err_r: vec3<f32>,
    err_t: vec3<f32>,
}

// stage_take, stage_leave: the state (r, t) and the controller's current error-controlled
// step (0: its first).
struct TakeIn {
    r: vec3<f32>,
    ds_adapt: f32,
    t: vec3<f32>,
}

// stage_take: the end state, the step's t-length, the field evaluations, and the
// controller's step after this one.
struct TakeOut {
    r: vec3<f32>,
    h: f32,
    t: vec3<f32>,
    evals: u32,
    ds_next: f32,
}

// stage_leave: as TakeOut, the state and t-length cut at the surface where the step
// left, and the outcome: 0 stayed inside, 1 the step ended outside, 2 it left and came
// back (tunnelled).
struct LeaveOut {
    r: vec3<f32>,
    h: f32,
    t: vec3<f32>,
    evals: u32,
    ds_next: f32,
    outcome: u32,
}

// stage_flight, stage_march: a ray from r along t (any length).
struct RayIn {
    r: vec3<f32>,
    t: vec3<f32>,
}

// stage_flight: the straight flight's length (-1: none) and may_fly (1 or 0).
struct FlightOut {
    span: f32,
    may_fly: u32,
}

// stage_surface: the ray (r, t), and the indices n1 and n2 of a refraction from n1 into
// n2 of t's direction at the surface.
struct SurfaceIn {
    r: vec3<f32>,
    n1: f32,
    t: vec3<f32>,
    n2: f32,
}

// stage_surface: the refracted (or totally reflected) direction and whether it was
// transmitted, at the normal of the surface point nearest r, with the Fresnel
// reflectance; the ray's interval through the bounds (s_in, s_out) and whether it met
// them; r's signed distance.
struct SurfaceOut {
    dir: vec3<f32>,
    transmitted: u32,
    normal: vec3<f32>,
    reflectance: f32,
    s_in: f32,
    s_out: f32,
    signed_distance: f32,
    met: u32,
}

// stage_scene: the ray (r, t) and the least distance an object may be met at.
struct SceneIn {
    r: vec3<f32>,
    t_min: f32,
    t: vec3<f32>,
}

// stage_scene: the nearest object's normal facing the ray, its distance (-1: none) and
// scene index + 1 (0: none), and the sky's radiance in t's direction.
struct SceneOut {
    normal: vec3<f32>,
    distance: f32,
    sky: vec3<f32>,
    object: u32,
}

// stage_march: the end point and direction, the optical path and length, the field
// evaluations and steps, the transmittance, the status (STATUS_*) and how the march
// ended (END_*).
struct MarchOut {
    point: vec3<f32>,
    opl: f32,
    dir: vec3<f32>,
    length: f32,
    evals: u32,
    steps: u32,
    transmittance: f32,
    status: u32,
    end: u32,
}

@group(1) @binding(0) var<storage, read> sample_in: array<SampleIn>;
@group(1) @binding(1) var<storage, read_write> sample_out: array<SampleOut>;
@group(1) @binding(0) var<storage, read> integrate_in: array<IntegrateIn>;
@group(1) @binding(1) var<storage, read_write> integrate_out: array<IntegrateOut>;
@group(1) @binding(0) var<storage, read> take_in: array<TakeIn>;
@group(1) @binding(1) var<storage, read_write> take_out: array<TakeOut>;
@group(1) @binding(1) var<storage, read_write> leave_out: array<LeaveOut>;
@group(1) @binding(0) var<storage, read> ray_in: array<RayIn>;
@group(1) @binding(1) var<storage, read_write> flight_out: array<FlightOut>;
@group(1) @binding(1) var<storage, read_write> march_out: array<MarchOut>;
// stage_march's state between its dispatches (MarchCarry with its flags as u32: bool
// has no layout in a storage buffer), and the dispatches' control.
@group(1) @binding(2) var<storage, read_write> march_carry: array<MarchCarryStored>;
@group(1) @binding(3) var<storage, read_write> march_control: MarchControl;
@group(1) @binding(0) var<storage, read> surface_in: array<SurfaceIn>;
@group(1) @binding(1) var<storage, read_write> surface_out: array<SurfaceOut>;
@group(1) @binding(0) var<storage, read> scene_in: array<SceneIn>;
@group(1) @binding(1) var<storage, read_write> scene_out: array<SceneOut>;

const STAGE_WORKGROUP: u32 = 64u;

// One controlled step from a TakeIn: the start state and sample, the step, and the
// controller's step after it.
struct Controlled {
    s: RayState,
    s0: FieldSample,
    taken: Taken,
    ds_next: f32,
}

fn controlled_step(input: TakeIn) -> Controlled {
    let s = RayState(input.r, input.t);
    let s0 = sample_field(s.r);
    var ctrl = step_controller_new(1.0);
    if input.ds_adapt > 0.0 {
        ctrl.ds_adapt = input.ds_adapt;
    }
    let taken = take_step(&ctrl, s, s0);
    return Controlled(s, s0, taken, ctrl.ds_adapt);
}

@compute @workgroup_size(64, 1, 1)
fn stage_sample(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= arrayLength(&sample_in) {
        return;
    }
    let f = sample_field(sample_in[gid.x].r);
    sample_out[gid.x] = SampleOut(f.grad_n, f.n, f.delta_n);
}

@compute @workgroup_size(64, 1, 1)
fn stage_integrate(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= arrayLength(&integrate_in) {
        return;
    }
    let input = integrate_in[gid.x];
    let s = RayState(input.r, input.t);
    let s0 = sample_field(s.r);
    let step = integrate_step(s, s0.grad_n * s0.n, input.h);
    var out = IntegrateOut(step.state.r, step.evals, step.state.t, 0.0, vec3<f32>(0.0), step.err_r, step.err_t);
    if step.has_end {
        out.end_n = step.end.n;
        out.end_grad_n = step.end.grad_n;
    }
    integrate_out[gid.x] = out;
}

@compute @workgroup_size(64, 1, 1)
fn stage_take(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= arrayLength(&take_in) {
        return;
    }
    let c = controlled_step(take_in[gid.x]);
    let end = c.taken.step.state;
    take_out[gid.x] = TakeOut(end.r, c.taken.h, end.t, c.taken.evals, c.ds_next);
}

// One step of the march near the surface: the step, the tunnelling check, the exit
// search (march_medium's order of them).
@compute @workgroup_size(64, 1, 1)
fn stage_leave(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= arrayLength(&take_in) {
        return;
    }
    let c = controlled_step(take_in[gid.x]);
    let s = c.s;
    let s0 = c.s0;
    var taken = c.taken;
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
    leave_out[gid.x] = LeaveOut(state.r, h, state.t, evals, c.ds_next, code);
}

// A straight flight from r along t.
@compute @workgroup_size(64, 1, 1)
fn stage_flight(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= arrayLength(&ray_in) {
        return;
    }
    let input = ray_in[gid.x];
    let span = homogeneous_span(input.r, normalize_or_zero(input.t));
    flight_out[gid.x] = FlightOut(span, select(0u, 1u, may_fly(input.r)));
}

// The medium's surface: the ray's interval through the bounds, r's signed distance, and
// the refraction of t's direction at the bounds' normal nearest r.
@compute @workgroup_size(64, 1, 1)
fn stage_surface(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= arrayLength(&surface_in) {
        return;
    }
    let input = surface_in[gid.x];
    let d = normalize_or_zero(input.t);
    let b = bounds_intersect(input.r, d);
    let nrm = bounds_normal(project_to_surface(input.r));
    let i = refract(d, nrm, input.n1, input.n2);
    surface_out[gid.x] = SurfaceOut(
        i.dir,
        select(0u, 1u, i.transmitted),
        nrm,
        i.reflectance,
        b.s_in,
        b.s_out,
        bounds_signed_distance(input.r),
        select(0u, 1u, b.found),
    );
}

// The scene outside the medium: the nearest object along (r, t) beyond t_min, and the
// sky's radiance in t's direction.
@compute @workgroup_size(64, 1, 1)
fn stage_scene(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= arrayLength(&scene_in) {
        return;
    }
    let input = scene_in[gid.x];
    let d = normalize_or_zero(input.t);
    let hit = intersect_scene(input.r, d, input.t_min, INF);
    scene_out[gid.x] = SceneOut(hit.normal, select(-1.0, hit.t, hit.found), sky_radiance(d), select(0u, hit.object + 1u, hit.found));
}

// A whole ray through the medium from r along t (outside: entered with refraction, as a
// camera ray is), no jitter, over as many dispatches as it needs: each runs every ray
// still marching on by at most march_control.budget steps, and counts those that are
// still marching after it in march_control.pending (grin_gpu::march dispatches until
// none is). lavapipe stops a shader invocation's loops after 65,535 iterations in all,
// and a desktop driver resets a GPU whose dispatch runs too long: a ray's march is cut
// into dispatches short enough for both, the same steps in the same arithmetic as one
// whole march.
@compute @workgroup_size(64, 1, 1)
fn stage_march(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= arrayLength(&ray_in) {
        return;
    }
    var carry: MarchCarry;
    var stats: MarchStats;
    if march_control.round == 0u {
        let input = ray_in[gid.x];
        stats = march_stats_new(input.t);
        let begun = march_begin(input.r, input.t, 1.0, &stats);
        if begun.done {
            march_finished(gid.x, begun.end, stats);
            return;
        }
        carry = begun.carry;
    } else {
        let stored = march_carry[gid.x];
        if stored.marching == 0u {
            return;
        }
        carry = march_carry_load(stored);
        stats = stored.stats;
    }
    let end = march_run(&carry, &stats, march_control.budget);
    if end.kind == END_SUSPENDED {
        march_carry[gid.x] = march_carry_store(carry, stats);
        atomicAdd(&march_control.pending, 1u);
        return;
    }
    march_finished(gid.x, end, stats);
}

fn march_finished(i: u32, end: MarchEnd, stats: MarchStats) {
    march_out[i] = MarchOut(end.point, stats.opl, end.dir, stats.length, stats.evals, stats.steps, end.transmittance, end.status, end.kind);
    march_carry[i].marching = 0u;
}

// The dispatches' control (grin_gpu::stages::MarchControl): rays still marching after
// this dispatch (counted by it), the dispatch's number (0: the rays start from ray_in)
// and the steps each ray may take in it.
struct MarchControl {
    pending: atomic<u32>,
    round: u32,
    budget: u32,
}
