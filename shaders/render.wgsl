// #import shared/types.wgsl shared/bindings.wgsl shared/rng.wgsl shared/camera.wgsl shared/primitives.wgsl shared/materials.wgsl shared/sky.wgsl shared/surface.wgsl shared/field.wgsl shared/integrate.wgsl shared/step.wgsl shared/estimate.wgsl shared/boundary.wgsl shared/trace.wgsl shared/medium.wgsl shared/shade.wgsl
//
// The render kernels: one invocation per pixel of a band of rows (render_main), or per
// pixel PASS_FIRST listed (render_deferred); all samples of the pixel, the mean radiance
// and the AOVs into `out_pixels`.
// CPU twin: grin_trace::render::RenderScene::render_pixel.

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

// PASS_MEDIUM: the pixels PASS_FIRST listed, traced whole.
const DEFERRED_WORKGROUP: u32 = 64u;

@compute @workgroup_size(64, 1, 1)
fn render_deferred(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= atomicLoad(&deferred_pixels.count) {
        return;
    }
    let local = deferred[gid.x];
    let width = params.width;
    render_pixel(local % width, local / width);
}

// All samples of pixel (px, band row `row`): the mean radiance and the first sample's
// AOVs into `out_pixels`. False (nothing written) when PASS_FIRST left it to PASS_MEDIUM.
fn render_pixel(px: u32, row: u32) -> bool {
    let width = params.width;
    let py = params.first_row + row;
    let index = py * width + px;
    let spp = params.spp;
    var rgb = vec3<f32>(0.0);
    var steps = 0.0;
    var evals = 0.0;
    var first = PrimaryAov(0.0, vec3<f32>(0.0), 0.0, 0u, 0u, STATUS_MISSED, vec3<f32>(0.0), 0.0);
    // Samples first_sample .. first_sample + spp of spp_total: frames of consecutive
    // ranges, averaged, are one render of spp_total samples.
    for (var k = 0u; k < spp; k++) {
        let sample = params.first_sample + k;
        var rng = rng_for_pixel(index, sample, params.seed);
        var sx = 0.5;
        var sy = 0.5;
        if params.spp_total != 1u {
            sx = rng_next_f32(&rng);
            sy = rng_next_f32(&rng);
        }
        // Per-pixel jitter of the camera ray's first step in the medium (settable;
        // drawn after the sub-pixel position so the stream is the CPU's when it is off).
        var jitter = 1.0;
        if (FLAGS & FLAG_JITTER) != 0u {
            jitter = max(rng_next_f32(&rng), MIN_JITTER_FRACTION);
        }
        var ray = camera_ray(px, py, sx, sy);
        // A thin lens's aperture point, drawn last, none for a single-sample image.
        if params.lens_radius > 0.0 && params.spp_total != 1u {
            let u1 = rng_next_f32(&rng);
            let u2 = rng_next_f32(&rng);
            ray = lens_ray(ray.d, u1, u2);
        }
        let path = trace_path(ray.o, ray.d, jitter, &rng);
        if path.deferred {
            return false;
        }
        rgb += path.rgb;
        steps += f32(path.aov.steps);
        evals += f32(path.aov.evals);
        if k == 0u {
            first = path.aov;
        }
    }
    let inv = 1.0 / f32(spp);
    rgb *= inv;
    var out: PixelOut;
    out.r = rgb.x;
    out.g = rgb.y;
    out.b = rgb.z;
    out.deflection_deg = first.deflection_deg;
    out.exit_x = first.exit_dir.x;
    out.exit_y = first.exit_dir.y;
    out.exit_z = first.exit_dir.z;
    out.opd = first.opd;
    out.steps = steps * inv;
    out.evals = evals * inv;
    out.status = f32(first.status);
    out.pos_x = first.exit_pos.x;
    out.pos_y = first.exit_pos.y;
    out.pos_z = first.exit_pos.z;
    out.opd_plane = first.opd_plane;
    out.pad = 0.0;
    out_pixels[row * width + px] = out;
    return true;
}
