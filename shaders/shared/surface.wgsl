// Images and the random-dot pattern on planes and boxes.
// CPU twin: grin_render::surface (same axes, same lookup, same hash).

// The axes (u, v) of a surface of unit normal n: u horizontal (x on a floor or ceiling,
// else up x n), v = n x u.
fn face_u(n: vec3<f32>) -> vec3<f32> {
    let a = abs(n);
    if a.y >= a.x && a.y >= a.z {
        return vec3<f32>(1.0, 0.0, 0.0);
    }
    return normalize(vec3<f32>(n.z, 0.0, -n.x));
}

// Surface coordinates of a hit (world units from the frame's centre along u, v) in xy,
// and the face's size on a box in zw (0 on planes).
fn surface_coords(obj: GpuObject, p: vec3<f32>, n: vec3<f32>) -> vec4<f32> {
    let u = face_u(n);
    let v = cross(n, u);
    var c = obj.a;
    var face = vec2<f32>(0.0);
    if obj.shape == SHAPE_BOX {
        let ext = obj.b - obj.a;
        c = (obj.a + obj.b) * 0.5 + n * (dot(abs(n), ext) * 0.5);
        face = vec2<f32>(dot(abs(u), ext), dot(abs(v), ext));
    }
    if (obj.surface_flags & SURFACE_HAS_CENTER) != 0u {
        c = obj.center;
    }
    let r = p - c;
    return vec4<f32>(dot(r, u), dot(r, v), face);
}

// A texture's colour at a hit: the image times its tint, or the border outside it.
fn texture_colour(obj: GpuObject, p: vec3<f32>, n: vec3<f32>) -> vec3<f32> {
    let sc = surface_coords(obj, p, n);
    var s = obj.size;
    if obj.shape == SHAPE_BOX {
        s = sc.zw;
    }
    let uv = sc.xy / s + vec2<f32>(0.5);
    let repeat = (obj.surface_flags & SURFACE_REPEAT) != 0u;
    if !repeat && (uv.x < 0.0 || uv.x > 1.0 || uv.y < 0.0 || uv.y > 1.0) {
        return obj.color_b;
    }
    let w = i32(obj.image_width);
    let h = i32(obj.image_height);
    let texel = atlas_bilinear(obj.image_row, w, h, uv.x * f32(w), (1.0 - uv.y) * f32(h), repeat);
    return texel * obj.color_a;
}

// One Gaussian dot (1/e^2 diameter) per square cell of side
// diameter * sqrt(pi / (4 density)), placed by the seed; clamped to 1.
fn dot_intensity(diameter: f32, density: f32, seed: u32, uv: vec2<f32>) -> f32 {
    let cell = diameter * sqrt(PI / (4.0 * density));
    let ci = i32(floor(uv.x / cell));
    let cj = i32(floor(uv.y / cell));
    var sum = 0.0;
    for (var di = -1; di <= 1; di++) {
        for (var dj = -1; dj <= 1; dj++) {
            let i = ci + di;
            let j = cj + dj;
            let h = pcg_hash(seed ^ pcg_hash(bitcast<u32>(i) ^ pcg_hash(bitcast<u32>(j))));
            let ru = f32(h >> 8u) / 16777216.0;
            let rv = f32(pcg_hash(h) >> 8u) / 16777216.0;
            let centre = vec2<f32>((f32(i) + ru) * cell, (f32(j) + rv) * cell);
            let r = uv - centre;
            sum += exp(-8.0 * dot(r, r) / (diameter * diameter));
        }
    }
    return min(sum, 1.0);
}

fn dots_colour(obj: GpuObject, p: vec3<f32>, n: vec3<f32>) -> vec3<f32> {
    let sc = surface_coords(obj, p, n);
    let a = dot_intensity(obj.param, obj.density, obj.seed, sc.xy);
    return mix(obj.color_b, obj.color_a, a);
}
