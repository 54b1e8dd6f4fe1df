// #import shared/types.wgsl shared/counts.wgsl
//
// The viewer's image on the device (crates/grin-gpu/src/view.rs): the render kernel's
// pixels are added to an accumulation buffer that stays on the GPU, and the image is
// coloured into a texture the window draws, so no pixel crosses to the CPU per frame.
//   view_accumulate  one band of render_main's pixels, weighted by the frame's samples,
//                    into the accumulation (and its steps, evaluations and loop-limit
//                    suspects into `stats`, summed over the frames since they were read)
//   view_scale       the largest finite |value| of the AOV shown (its colour scale)
//   view_shade       the AOV shown, as grin_view::display::rgba colours it, a colour a
//                    pixel (linear; the window's sampler and framebuffer encode sRGB)
//   view_colour      those colours scaled to fill the texture the window draws

// The render kernel's pixels (types.wgsl's PixelOut). In the accumulation r, g, b, steps
// and evals are sums weighted by samples; the other fields are the first frame's.

// view.rs's ViewParams.
struct ViewParams {
    width: u32,
    height: u32,
    first_row: u32,
    rows: u32,
    // Samples per pixel of the frame being added.
    weight: f32,
    // 1 / samples accumulated (the colour pass).
    inv_samples: f32,
    // 1: the frame starts the image (its pixels replace the accumulation).
    overwrite: u32,
    // grin_view::display::Aov, in its order.
    aov: u32,
    // The texture's size (the colour pass scales the image to fill it).
    out_width: u32,
    out_height: u32,
    pad0: u32,
    pad1: u32,
}

const AOV_BEAUTY: u32 = 0u;
const AOV_DEFLECTION: u32 = 1u;
const AOV_STEPS: u32 = 2u;
const AOV_OPD: u32 = 3u;
const AOV_STATUS: u32 = 4u;

// stats: [steps lo, steps hi, evals lo, evals hi, loop-limit suspects (counts.wgsl's),
// scale (f32 bits), 0, 0]; view.rs's STAT_* indices.
const STAT_SCALE: u32 = 5u;

// A read-only storage buffer, not a uniform: lavapipe compiles a variant of a kernel for
// each new value of a uniform it branches on (sizes change every frame while moving).
@group(0) @binding(0) var<storage, read> params: ViewParams;
@group(0) @binding(1) var<storage, read> band: array<PixelOut>;
@group(0) @binding(2) var<storage, read_write> accum: array<PixelOut>;
@group(0) @binding(3) var<storage, read_write> stats: array<atomic<u32>>;
@group(0) @binding(4) var display: texture_storage_2d<rgba16float, write>;
@group(0) @binding(5) var<storage, read_write> shaded: array<vec4<f32>>;

fn is_finite(v: f32) -> bool {
    return (bitcast<u32>(v) & 0x7f800000u) != 0x7f800000u;
}

@compute @workgroup_size(64)
fn view_accumulate(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    let n = params.width * params.rows;
    if gid.x < n {
        let q = band[gid.x];
        let i = params.first_row * params.width + gid.x;
        let w = params.weight;
        count_pixel(q.steps, q.evals, u32(q.status), w);
        if params.overwrite == 1u {
            var a = q;
            a.r = q.r * w;
            a.g = q.g * w;
            a.b = q.b * w;
            a.steps = q.steps * w;
            a.evals = q.evals * w;
            accum[i] = a;
        } else {
            accum[i].r += q.r * w;
            accum[i].g += q.g * w;
            accum[i].b += q.b * w;
            accum[i].steps += q.steps * w;
            accum[i].evals += q.evals * w;
        }
    }
    workgroupBarrier();
    if li == 0u {
        flush_counts();
    }
}

// The value an AOV maps to colour (display.rs's `value`).
fn aov_value(a: PixelOut) -> f32 {
    switch params.aov {
        case AOV_DEFLECTION: { return a.deflection_deg; }
        case AOV_STEPS: { return a.steps * params.inv_samples; }
        case AOV_OPD: { return a.opd; }
        default: { return 0.0; }
    }
}

@compute @workgroup_size(8, 8)
fn view_scale(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= params.width || gid.y >= params.height {
        return;
    }
    let v = aov_value(accum[gid.y * params.width + gid.x]);
    if is_finite(v) {
        // Non-negative floats order as their bits.
        atomicMax(&stats[STAT_SCALE], bitcast<u32>(abs(v)));
    }
}

fn srgb_to_linear(s: f32) -> f32 {
    if s <= 0.04045 {
        return s / 12.92;
    }
    return pow((s + 0.055) / 1.055, 2.4);
}

fn unit(x: f32) -> f32 {
    if !is_finite(x) {
        return 0.0;
    }
    return clamp(x, 0.0, 1.0);
}

// An sRGB-encoded colour (each channel in [0, 1]) as linear values.
fn linear_of(s: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(srgb_to_linear(s.x), srgb_to_linear(s.y), srgb_to_linear(s.z));
}

// display.rs's STATUS_COLOURS (sRGB bytes).
fn status_colour(status: f32) -> vec3<f32> {
    switch u32(status) {
        case 0u: { return vec3<f32>(90.0, 90.0, 90.0) / 255.0; }
        case 1u: { return vec3<f32>(40.0, 170.0, 70.0) / 255.0; }
        case 2u: { return vec3<f32>(50.0, 90.0, 200.0) / 255.0; }
        case 3u: { return vec3<f32>(240.0, 150.0, 20.0) / 255.0; }
        case 4u: { return vec3<f32>(220.0, 30.0, 30.0) / 255.0; }
        case 5u: { return vec3<f32>(230.0, 220.0, 40.0) / 255.0; }
        default: { return vec3<f32>(1.0, 0.0, 1.0); }
    }
}

// The colour of accumulated pixel (x, y).
fn colour_at(x: u32, y: u32, inv: f32) -> vec3<f32> {
    let a = accum[y * params.width + x];
    let t = aov_value(a) * inv;
    switch params.aov {
        case AOV_BEAUTY: {
            let s = params.inv_samples;
            return vec3<f32>(unit(a.r * s), unit(a.g * s), unit(a.b * s));
        }
        case AOV_DEFLECTION: {
            return vec3<f32>(unit(t));
        }
        case AOV_STEPS: {
            // Black -> red -> yellow -> white.
            let h = unit(t);
            return linear_of(vec3<f32>(unit(3.0 * h), unit(3.0 * h - 1.0), unit(3.0 * h - 2.0)));
        }
        case AOV_OPD: {
            // Blue (-1) -> white (0) -> red (+1).
            var d = 0.0;
            if is_finite(t) {
                d = clamp(t, -1.0, 1.0);
            }
            if d >= 0.0 {
                return linear_of(vec3<f32>(1.0, 1.0 - d, 1.0 - d));
            }
            return linear_of(vec3<f32>(1.0 + d, 1.0 + d, 1.0));
        }
        default: {
            return linear_of(status_colour(a.status));
        }
    }
}

// Each pixel's colour, once (the texture may have many texels a pixel).
@compute @workgroup_size(8, 8)
fn view_shade(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= params.width || gid.y >= params.height {
        return;
    }
    let scale = bitcast<f32>(atomicLoad(&stats[STAT_SCALE]));
    var inv = 0.0;
    if scale > 0.0 {
        inv = 1.0 / scale;
    }
    shaded[gid.y * params.width + gid.x] = vec4<f32>(colour_at(gid.x, gid.y, inv), 1.0);
}

fn shaded_at(p: vec2<u32>) -> vec4<f32> {
    return shaded[p.y * params.width + p.x];
}

// One texel of the texture: the image's pixel there where the sizes agree, else the
// image scaled to the texture (bilinear between pixel centres; nearest for status).
@compute @workgroup_size(8, 8)
fn view_colour(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= params.out_width || gid.y >= params.out_height {
        return;
    }
    let size = vec2<f32>(f32(params.width), f32(params.height));
    let out = vec2<f32>(f32(params.out_width), f32(params.out_height));
    let f = clamp(
        (vec2<f32>(gid.xy) + 0.5) * size / out - 0.5,
        vec2<f32>(0.0),
        size - 1.0,
    );
    var c: vec4<f32>;
    if params.aov == AOV_STATUS {
        c = shaded_at(vec2<u32>(round(f)));
    } else {
        let p0 = vec2<u32>(floor(f));
        let p1 = min(p0 + 1u, vec2<u32>(params.width - 1u, params.height - 1u));
        let t = f - floor(f);
        let top = mix(shaded_at(p0), shaded_at(vec2<u32>(p1.x, p0.y)), t.x);
        let bottom = mix(shaded_at(vec2<u32>(p0.x, p1.y)), shaded_at(p1), t.x);
        c = mix(top, bottom, t.y);
    }
    textureStore(display, vec2<u32>(gid.x, gid.y), c);
}
