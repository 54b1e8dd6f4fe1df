// The words of the render kernel's pixels that an output is made of
// (crates/grin-gpu/src/channels.rs): `grin render` reads back only those.
//   channels_pack  one band's pixels (16 f32 words each, types.wgsl's PixelOut) to the
//                  chosen words, packed pixel after pixel; and the frame's totals
//                  (steps, evaluations, loop-limit suspects, pixels of each status), so
//                  its summary needs no per-pixel read of them

// channels.rs's PackParams.
struct PackParams {
    // Pixels in the band.
    pixels: u32,
    // Words kept a pixel (1..16), listed in `word`.
    words: u32,
    // Samples a pixel: the pixel's steps and evals are means over them.
    samples: f32,
    pad: u32,
    word: array<vec4<u32>, 4>,
}

// totals: [steps lo, steps hi, evals lo, evals hi, loop-limit suspects, 0, 0, 0,
// pixels of status 0 .. 7]; channels.rs's TOTAL_* indices.
const TOTAL_STEPS: u32 = 0u;
const TOTAL_EVALS: u32 = 2u;
const TOTAL_SUSPECTS: u32 = 4u;
const TOTAL_STATUS: u32 = 8u;
const STATUSES: u32 = 8u;

// PixelOut's words: steps, evals, status (gpu_data.rs).
const WORD_STEPS: u32 = 8u;
const WORD_EVALS: u32 = 9u;
const WORD_STATUS: u32 = 10u;

// gpu_data.rs's STATUS_ERROR and grin_gpu::device::LOOP_LIMIT_SUSPECT_STEPS.
const STATUS_ERROR: u32 = 4u;
const LOOP_LIMIT_SUSPECT_STEPS: f32 = 2000.0;

// A read-only storage buffer, not a uniform: lavapipe compiles a variant of a kernel for
// each new value of a uniform it branches on.
@group(0) @binding(0) var<storage, read> params: PackParams;
@group(0) @binding(1) var<storage, read> band: array<f32>;
@group(0) @binding(2) var<storage, read_write> packed: array<f32>;
@group(0) @binding(3) var<storage, read_write> totals: array<atomic<u32>>;

// The workgroup's sums of steps and evaluations, 64-bit: [steps lo, steps hi, evals lo,
// evals hi] (TOTAL_STEPS and TOTAL_EVALS index them too).
var<workgroup> wg_sums: array<atomic<u32>, 4>;
var<workgroup> wg_suspects: atomic<u32>;
var<workgroup> wg_status: array<atomic<u32>, 8>;

// A 64-bit counter in totals[at], totals[at + 1]: the adder whose add wraps the low word
// carries into the high one.
fn add64(at: u32, v: u32) {
    let old = atomicAdd(&totals[at], v);
    if old > 0xffffffffu - v {
        atomicAdd(&totals[at + 1u], 1u);
    }
}

// `v` added to the workgroup's 64-bit sum at wg_sums[at], wg_sums[at + 1].
fn wg_add64(at: u32, v: u32) {
    let old = atomicAdd(&wg_sums[at], v);
    if old > 0xffffffffu - v {
        atomicAdd(&wg_sums[at + 1u], 1u);
    }
}

@compute @workgroup_size(64)
fn channels_pack(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    // Dispatched in rows of workgroups (channels.rs's MAX_GROUPS).
    let p = gid.y * groups.x * 64u + gid.x;
    if p < params.pixels {
        let base = p * 16u;
        let out = p * params.words;
        for (var k = 0u; k < params.words; k++) {
            packed[out + k] = band[base + params.word[k / 4u][k % 4u]];
        }
        let steps = band[base + WORD_STEPS];
        // Whole counts of the pixel's rays (means times the samples).
        wg_add64(TOTAL_STEPS, u32(round(max(steps, 0.0) * params.samples)));
        wg_add64(TOTAL_EVALS, u32(round(max(band[base + WORD_EVALS], 0.0) * params.samples)));
        let status = u32(max(band[base + WORD_STATUS], 0.0));
        if status < STATUSES {
            atomicAdd(&wg_status[status], 1u);
        }
        if status == STATUS_ERROR && steps >= LOOP_LIMIT_SUSPECT_STEPS {
            atomicAdd(&wg_suspects, 1u);
        }
    }
    workgroupBarrier();
    if li == 0u {
        for (var at = TOTAL_STEPS; at <= TOTAL_EVALS; at += 2u) {
            add64(at, atomicLoad(&wg_sums[at]));
            atomicAdd(&totals[at + 1u], atomicLoad(&wg_sums[at + 1u]));
        }
        atomicAdd(&totals[TOTAL_SUSPECTS], atomicLoad(&wg_suspects));
    }
    if li < STATUSES {
        atomicAdd(&totals[TOTAL_STATUS + li], atomicLoad(&wg_status[li]));
    }
}
