// Deterministic per-pixel random numbers: the PCG hash, bit for bit the CPU's.
// CPU twin: grin_trace::render::rng.

fn pcg_hash(input: u32) -> u32 {
    let state = input * 747796405u + 2891336453u;
    let word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

fn rng_for_pixel(pixel_index: u32, sample: u32, seed: u32) -> u32 {
    return pcg_hash(seed ^ pcg_hash(sample ^ pcg_hash(pixel_index)));
}

// Uniform in [0, 1) with 24 bits (Rng::next_f32).
fn rng_next_f32(state: ptr<function, u32>) -> f32 {
    *state = pcg_hash(*state);
    return f32(*state >> 8u) * (1.0 / 16777216.0);
}
