// #import shared/types.wgsl shared/bindings.wgsl shared/primitives.wgsl shared/field.wgsl
//
// Microbenchmark: the adapter's raw rate of field samples (the marcher's `sample_field`,
// 8 textureLoads + trilinear weights) along straight coherent rays through the grid,
// with no integrator or scene work. `grin bench speed` divides the marcher's rate by it.

// Field samples per invocation.
const BENCH_SAMPLES: u32 = 256u;

@compute @workgroup_size(8, 8, 1)
fn bench_main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let width = params.width;
    if gid.x >= width || gid.y >= params.row_count {
        return;
    }
    let gmax = grid_max();
    // A ray per pixel across the grid, like a camera looking down z.
    let u = (f32(gid.x) + 0.5) / f32(width);
    let v = (f32(gid.y) + 0.5) / f32(params.row_count);
    var g = vec3<f32>(u * gmax.x, v * gmax.y, 0.0);
    let dg = vec3<f32>(0.01 * gmax.x, -0.005 * gmax.y, gmax.z) / f32(BENCH_SAMPLES);
    var acc = vec4<f32>(0.0);
    for (var i = 0u; i < BENCH_SAMPLES; i++) {
        acc += trilinear(clamp(g, vec3<f32>(0.0), gmax));
        g += dg;
    }
    var out: PixelOut;
    out.r = acc.x;
    out.g = acc.y;
    out.b = acc.z;
    out.deflection_deg = acc.w;
    out_pixels[gid.y * width + gid.x] = out;
}
