// #import shared/types.wgsl shared/bindings.wgsl shared/rng.wgsl shared/camera.wgsl shared/primitives.wgsl shared/materials.wgsl shared/sky.wgsl shared/surface.wgsl shared/field.wgsl shared/integrate.wgsl shared/step.wgsl shared/estimate.wgsl shared/boundary.wgsl shared/trace.wgsl shared/medium.wgsl shared/shade.wgsl
//
// The render kernels: one invocation per pixel of a band of rows (render_main), or per
// pixel PASS_FIRST listed (render_deferred); all samples of the pixel, the mean radiance
// and the AOVs into `out_pixels`.
// CPU twin: grin_trace::render::RenderScene::render_pixel.
//
// PASS_MEDIUM's marches are split over dispatches (rounds): each round runs every pixel
// on by at most `resume.round.budget` steps, and a pixel still marching after it keeps
// its whole state in `resume` for the next round (grin_gpu::render dispatches the
// rounds). No invocation runs unbounded (lavapipe stops one after 65,535 loop
// iterations; a desktop driver resets a GPU whose dispatch runs too long), and the
// pixels are those of one whole run.

@compute @workgroup_size(8, 8, 1)
fn render_main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let width = params.width;
    if gid.x >= width || gid.y >= params.row_count {
        return;
    }
    if !render_pixel(gid.x, gid.y) {
        // PASS_FIRST: the pixel's paths reach the medium; list it for PASS_MEDIUM and
        // count the workgroups of that pass's indirect dispatch.
        let slot = atomicAdd(&deferred_pixels.count, 1u);
        deferred[slot] = gid.y * width + gid.x;
        if slot % DEFERRED_WORKGROUP == 0u {
            atomicAdd(&deferred_pixels.workgroups, 1u);
        }
    }
}

// PASS_MEDIUM's rounds (grin_gpu::render::ResumeRound): whether this round resumes the
// pixels the last one left (else it starts those PASS_FIRST listed), which half of
// `entries` it reads, the steps each pixel may take in it, and the pixels a half may
// hold (at most its size).
struct ResumeRound {
    resuming: u32,
    read_half: u32,
    budget: u32,
    capacity: u32,
}

// Pixels a round left in one half of `entries`, and the workgroups of the next round's
// indirect dispatch over them (DeferredPixels' layout).
struct ResumeCount {
    workgroups: atomic<u32>,
    y: u32,
    z: u32,
    count: atomic<u32>,
}

struct Resume {
    round: ResumeRound,
    counts: array<ResumeCount, 2>,
    // Two halves: a round reads one and leaves its unfinished pixels in the other.
    entries: array<PixelCarryStored>,
}

@group(0) @binding(9) var<storage, read_write> resume: Resume;

// PASS_MEDIUM: the pixels PASS_FIRST listed (round 0) or the last round left, each run
// on by at most the round's budget of steps.
const DEFERRED_WORKGROUP: u32 = 64u;

@compute @workgroup_size(64, 1, 1)
fn render_deferred(@builtin(global_invocation_id) gid: vec3<u32>) {
    let round = resume.round;
    let half = arrayLength(&resume.entries) / 2u;
    var st: PixelState;
    if round.resuming == 0u {
        if gid.x >= atomicLoad(&deferred_pixels.count) {
            return;
        }
        let local = deferred[gid.x];
        let width = params.width;
        st = pixel_start(local % width, local / width);
    } else {
        if gid.x >= atomicLoad(&resume.counts[round.read_half].count) {
            return;
        }
        st = pixel_load(resume.entries[round.read_half * half + gid.x]);
    }
    var budget = round.budget;
    // One call of pixel_run (lavapipe inlines every call: a second one doubled the
    // kernel and its compile time): a pixel that finds no place runs on whole.
    loop {
        if pixel_run(&st, &budget) != PATH_SUSPENDED {
            break;
        }
        let into = 1u - round.read_half;
        let slot = atomicAdd(&resume.counts[into].count, 1u);
        if slot < min(round.capacity, half) {
            resume.entries[into * half + slot] = pixel_store(st);
            if slot % DEFERRED_WORKGROUP == 0u {
                atomicAdd(&resume.counts[into].workgroups, 1u);
            }
            return;
        }
        atomicSub(&resume.counts[into].count, 1u);
        budget = MARCH_UNBOUNDED;
    }
    pixel_write(st);
}

// A pixel's samples between loop passes: the samples done and their sums, the one under
// way (its random stream and jitter) and its path.
struct PixelState {
    px: u32,
    row: u32,
    // The sample under way (a path in `path`), or the next to start.
    k: u32,
    in_path: bool,
    rng: u32,
    jitter: f32,
    rgb: vec3<f32>,
    steps: f32,
    evals: f32,
    first: PrimaryAov,
    path: PathState,
}

fn pixel_start(px: u32, row: u32) -> PixelState {
    var st: PixelState;
    st.px = px;
    st.row = row;
    st.k = 0u;
    st.in_path = false;
    st.rgb = vec3<f32>(0.0);
    st.steps = 0.0;
    st.evals = 0.0;
    st.first = PrimaryAov(0.0, vec3<f32>(0.0), 0.0, 0u, 0u, STATUS_MISSED, vec3<f32>(0.0), 0.0);
    return st;
}

// All samples of pixel (px, band row `row`): the mean radiance and the first sample's
// AOVs into `out_pixels`. False (nothing written) when PASS_FIRST left it to PASS_MEDIUM.
fn render_pixel(px: u32, row: u32) -> bool {
    var st = pixel_start(px, row);
    var budget = MARCH_UNBOUNDED;
    if pixel_run(&st, &budget) == PATH_DEFERRED {
        return false;
    }
    pixel_write(st);
    return true;
}

// Run the pixel's samples on: PATH_DONE when all are in `st`'s sums, PATH_DEFERRED when
// PASS_FIRST leaves it to PASS_MEDIUM, PATH_SUSPENDED when a march ran out of `budget`.
fn pixel_run(st: ptr<function, PixelState>, budget: ptr<function, u32>) -> u32 {
    let index = (params.first_row + (*st).row) * params.width + (*st).px;
    let spp = params.spp;
    // Samples first_sample .. first_sample + spp of spp_total: frames of consecutive
    // ranges, averaged, are one render of spp_total samples.
    // Resumed in the middle of a sample: its path, stream and jitter are read where it
    // runs on (kept out of the loop's own variables).
    var resuming = (*st).in_path;
    for (var k = (*st).k; k < spp; k++) {
        var path: PathState;
        var rng: u32;
        var jitter = 1.0;
        if resumable() && resuming {
            path = (*st).path;
            rng = (*st).rng;
            jitter = (*st).jitter;
            resuming = false;
        } else {
            let sample = params.first_sample + k;
            rng = rng_for_pixel(index, sample, params.seed);
            var sx = 0.5;
            var sy = 0.5;
            if params.spp_total != 1u {
                sx = rng_next_f32(&rng);
                sy = rng_next_f32(&rng);
            }
            // Per-pixel jitter of the camera ray's first step in the medium (settable;
            // drawn after the sub-pixel position so the stream is the CPU's when it is off).
            if (FLAGS & FLAG_JITTER) != 0u {
                jitter = max(rng_next_f32(&rng), MIN_JITTER_FRACTION);
            }
            var ray = camera_ray((*st).px, params.first_row + (*st).row, sx, sy);
            // A thin lens's aperture point, drawn last, none for a single-sample image.
            if params.lens_radius > 0.0 && params.spp_total != 1u {
                let u1 = rng_next_f32(&rng);
                let u2 = rng_next_f32(&rng);
                ray = lens_ray(ray.d, u1, u2);
            }
            path = path_start(ray.o, ray.d);
        }
        let outcome = path_run(&path, jitter, &rng, budget);
        if outcome != PATH_DONE {
            if resumable() {
                (*st).k = k;
                (*st).in_path = true;
                (*st).path = path;
                (*st).rng = rng;
                (*st).jitter = jitter;
            }
            return outcome;
        }
        (*st).rgb += path.radiance;
        (*st).steps += f32(path.aov.steps);
        (*st).evals += f32(path.aov.evals);
        if k == 0u {
            (*st).first = path.aov;
        }
    }
    (*st).k = spp;
    (*st).in_path = false;
    return PATH_DONE;
}

fn pixel_write(st: PixelState) {
    let width = params.width;
    let inv = 1.0 / f32(params.spp);
    let rgb = st.rgb * inv;
    let first = st.first;
    var out: PixelOut;
    out.r = rgb.x;
    out.g = rgb.y;
    out.b = rgb.z;
    out.deflection_deg = first.deflection_deg;
    out.exit_x = first.exit_dir.x;
    out.exit_y = first.exit_dir.y;
    out.exit_z = first.exit_dir.z;
    out.opd = first.opd;
    out.steps = st.steps * inv;
    out.evals = st.evals * inv;
    out.status = f32(first.status);
    out.pos_x = first.exit_pos.x;
    out.pos_y = first.exit_pos.y;
    out.pos_z = first.exit_pos.z;
    out.opd_plane = first.opd_plane;
    out.pad = 0.0;
    out_pixels[st.row * width + st.px] = out;
}

// PixelState as `resume` holds it between rounds (bools as u32). A pixel is suspended
// only in a march: its sample is under way and its path marching.
struct PixelCarryStored {
    px: u32,
    row: u32,
    k: u32,
    rng: u32,
    rgb: vec3<f32>,
    jitter: f32,
    steps: f32,
    evals: f32,
    first: PrimaryAov,
    origin: vec3<f32>,
    primary: u32,
    dir: vec3<f32>,
    inside: u32,
    throughput: vec3<f32>,
    bounces: u32,
    radiance: vec3<f32>,
    event: u32,
    entry_dir: vec3<f32>,
    straight_exit: vec3<f32>,
    aov: PrimaryAov,
    march: MarchCarryStored,
}

fn pixel_store(st: PixelState) -> PixelCarryStored {
    let p = st.path;
    return PixelCarryStored(st.px, st.row, st.k, st.rng, st.rgb, st.jitter, st.steps, st.evals, st.first, p.origin, u32(p.primary), p.dir, u32(p.inside), p.throughput, p.bounces, p.radiance, p.event, p.entry_dir, p.straight_exit, p.aov, march_carry_store(p.march, p.stats));
}

fn pixel_load(c: PixelCarryStored) -> PixelState {
    let path = PathState(c.origin, c.dir, c.throughput, c.radiance, c.aov, c.primary != 0u, c.inside != 0u, c.bounces, c.event, true, march_carry_load(c.march), c.march.stats, c.entry_dir, c.straight_exit);
    return PixelState(c.px, c.row, c.k, true, c.rng, c.jitter, c.rgb, c.steps, c.evals, c.first, path);
}
