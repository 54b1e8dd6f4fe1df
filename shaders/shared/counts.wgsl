// The counts a frame's pixels add up on the device: the viewer's statistics (view.wgsl)
// and the totals of a packed read-back (channels.wgsl). A kernel importing this declares
// `stats`, its storage array<atomic<u32>> whose first five words are [steps lo, steps hi,
// evals lo, evals hi, loop-limit suspects] (view.rs's STAT_*, channels.rs's TOTAL_*).

const COUNT_STEPS: u32 = 0u;
const COUNT_EVALS: u32 = 2u;
const COUNT_SUSPECTS: u32 = 4u;

// gpu_data.rs's STATUS_ERROR and grin_gpu::device::LOOP_LIMIT_SUSPECT_STEPS.
const STATUS_ERROR: u32 = 4u;
const LOOP_LIMIT_SUSPECT_STEPS: f32 = 2000.0;

// The workgroup's sums, in the order of `stats`' first five words (steps and evaluations
// 64-bit: a workgroup's can pass 2^32).
var<workgroup> wg_counts: array<atomic<u32>, 5>;

// A 64-bit counter in stats[at], stats[at + 1]: the adder whose add wraps the low word
// carries into the high one.
fn add64(at: u32, v: u32) {
    let old = atomicAdd(&stats[at], v);
    if old > 0xffffffffu - v {
        atomicAdd(&stats[at + 1u], 1u);
    }
}

// The same in the workgroup's sums.
fn wg_add64(at: u32, v: u32) {
    let old = atomicAdd(&wg_counts[at], v);
    if old > 0xffffffffu - v {
        atomicAdd(&wg_counts[at + 1u], 1u);
    }
}

// A pixel's rays into the workgroup's sums: its steps and evaluations are means over
// `samples` samples (whole counts once multiplied), `status` its aov.status.
fn count_pixel(steps: f32, evals: f32, status: u32, samples: f32) {
    wg_add64(COUNT_STEPS, u32(round(max(steps, 0.0) * samples)));
    wg_add64(COUNT_EVALS, u32(round(max(evals, 0.0) * samples)));
    if status == STATUS_ERROR && steps >= LOOP_LIMIT_SUSPECT_STEPS {
        atomicAdd(&wg_counts[COUNT_SUSPECTS], 1u);
    }
}

// The workgroup's sums into `stats`: by one invocation, after a workgroup barrier.
fn flush_counts() {
    for (var at = COUNT_STEPS; at <= COUNT_EVALS; at += 2u) {
        add64(at, atomicLoad(&wg_counts[at]));
        atomicAdd(&stats[at + 1u], atomicLoad(&wg_counts[at + 1u]));
    }
    atomicAdd(&stats[COUNT_SUSPECTS], atomicLoad(&wg_counts[COUNT_SUSPECTS]));
}
