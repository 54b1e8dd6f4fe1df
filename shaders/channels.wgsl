// #import shared/counts.wgsl
//
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

// stats (the frame's totals): [steps lo, steps hi, evals lo, evals hi, loop-limit
// suspects (counts.wgsl's), 0, 0, 0, pixels of status 0 .. 7]; channels.rs's TOTAL_*.
const TOTAL_STATUS: u32 = 8u;
const STATUSES: u32 = 8u;

// PixelOut's words: steps, evals, status (gpu_data.rs).
const WORD_STEPS: u32 = 8u;
const WORD_EVALS: u32 = 9u;
const WORD_STATUS: u32 = 10u;

// A read-only storage buffer, not a uniform: lavapipe compiles a variant of a kernel for
// each new value of a uniform it branches on.
@group(0) @binding(0) var<storage, read> params: PackParams;
@group(0) @binding(1) var<storage, read> band: array<f32>;
@group(0) @binding(2) var<storage, read_write> packed: array<f32>;
@group(0) @binding(3) var<storage, read_write> stats: array<atomic<u32>>;

// The workgroup's pixels of each status (its other counts: counts.wgsl's).
var<workgroup> wg_status: array<atomic<u32>, 8>;

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
        let status = u32(max(band[base + WORD_STATUS], 0.0));
        count_pixel(band[base + WORD_STEPS], band[base + WORD_EVALS], status, params.samples);
        if status < STATUSES {
            atomicAdd(&wg_status[status], 1u);
        }
    }
    workgroupBarrier();
    if li == 0u {
        flush_counts();
    }
    if li < STATUSES {
        atomicAdd(&stats[TOTAL_STATUS + li], atomicLoad(&wg_status[li]));
    }
}
