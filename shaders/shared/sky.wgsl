// The background. CPU twin: grin_trace::render::sky::SkyModel::sky_radiance.

// Texel (x, y) of the image atlas (the sky's image at the top left, the textures'
// below), clamped to the w x h image whose first row is `row`, or wrapped with `repeat`.
fn atlas_texel(row: u32, w: i32, h: i32, x: i32, y: i32, repeat: bool) -> vec3<f32> {
    var xi = clamp(x, 0, w - 1);
    var yi = clamp(y, 0, h - 1);
    if repeat {
        xi = ((x % w) + w) % w;
        yi = ((y % h) + h) % h;
    }
    return textureLoad(env_tex, vec2<i32>(xi, i32(row) + yi), 0).xyz;
}

// Bilinear value at image position (x, y) in texels (texel (i, j)'s centre at
// (i + 0.5, j + 0.5)). CPU twin: grin_render::surface::Image::bilinear.
fn atlas_bilinear(row: u32, w: i32, h: i32, px: f32, py: f32, repeat: bool) -> vec3<f32> {
    let x = px - 0.5;
    let y = py - 0.5;
    let x0 = floor(x);
    let y0 = floor(y);
    let fx = x - x0;
    let fy = y - y0;
    let xa = i32(x0);
    let ya = i32(y0);
    let top = mix(atlas_texel(row, w, h, xa, ya, repeat), atlas_texel(row, w, h, xa + 1, ya, repeat), fx);
    let bottom = mix(atlas_texel(row, w, h, xa, ya + 1, repeat), atlas_texel(row, w, h, xa + 1, ya + 1, repeat), fx);
    return mix(top, bottom, fy);
}

fn env_texel(x: i32, y: i32) -> vec3<f32> {
    return textureLoad(env_tex, vec2<i32>(x, y), 0).xyz;
}

fn env_lookup(d: vec3<f32>) -> vec3<f32> {
    let w = i32(params.env_width);
    let h = i32(params.env_height);
    let u = 0.5 + atan2(d.x, -d.z) / TAU;
    let v = acos(clamp(d.y, -1.0, 1.0)) / PI;
    let x = u * f32(w) - 0.5;
    let y = clamp(v * f32(h) - 0.5, 0.0, f32(h - 1));
    let x0 = floor(x);
    let y0 = floor(y);
    let fx = x - x0;
    let fy = y - y0;
    let xa = ((i32(x0) % w) + w) % w;
    let xb = ((i32(x0) + 1) % w + w) % w;
    let ya = i32(y0);
    let yb = min(ya + 1, h - 1);
    let top = mix(env_texel(xa, ya), env_texel(xb, ya), fx);
    let bottom = mix(env_texel(xa, yb), env_texel(xb, yb), fx);
    return mix(top, bottom, fy) * params.env_intensity;
}

// The background plate at infinity in the scene camera's view; black behind it.
// CPU twin: SkyModel::Plate.
fn plate_lookup(d: vec3<f32>) -> vec3<f32> {
    let z = dot(d, params.plate_forward);
    if z <= 0.0 {
        return vec3<f32>(0.0);
    }
    let x = dot(d, params.plate_right) / z / (params.plate_aspect * params.plate_tan_half_fov_y);
    let y = dot(d, params.plate_up) / z / params.plate_tan_half_fov_y;
    let w = i32(params.env_width);
    let h = i32(params.env_height);
    let px = (x + 1.0) * 0.5 * f32(w);
    let py = (1.0 - y) * 0.5 * f32(h);
    return atlas_bilinear(0u, w, h, px, py, false) * params.env_intensity;
}

fn sky_radiance(d: vec3<f32>) -> vec3<f32> {
    if SKY_PLATE {
        return plate_lookup(d);
    }
    if SKY_MAP {
        return env_lookup(d);
    }
    if d.y < 0.0 {
        return params.sky_ground;
    }
    return mix(params.sky_horizon, params.sky_zenith, min(d.y, 1.0));
}

// The sky light on a diffuse surface of normal n: a plate's mean colour (sky_horizon),
// else the sky in that direction.
fn ambient_radiance(n: vec3<f32>) -> vec3<f32> {
    if SKY_PLATE {
        return params.sky_horizon;
    }
    return sky_radiance(n);
}
