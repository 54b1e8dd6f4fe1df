// The background. CPU twin: grin_trace::render::sky::SkyModel::sky_radiance.

fn env_texel(x: i32, y: i32) -> vec3<f32> {
    return textureLoad(env_tex, vec2<i32>(x, y), 0).xyz;
}

fn env_lookup(d: vec3<f32>) -> vec3<f32> {
    let size = vec2<i32>(textureDimensions(env_tex));
    let w = size.x;
    let h = size.y;
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

fn sky_radiance(d: vec3<f32>) -> vec3<f32> {
    if SKY_MAP {
        return env_lookup(d);
    }
    if d.y < 0.0 {
        return params.sky_ground;
    }
    return mix(params.sky_horizon, params.sky_zenith, min(d.y, 1.0));
}
