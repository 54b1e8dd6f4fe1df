// Surface optics: reflection, Snell refraction, dielectric and Schlick Fresnel, checker.
// CPU twin: grin_trace::render::materials.

fn reflect_dir(d: vec3<f32>, n: vec3<f32>) -> vec3<f32> {
    return d - n * (2.0 * dot(d, n));
}

// Snell refraction of unit d through unit n facing against d, from n1 into n2.
// w = 1 when refracted, 0 on total internal reflection.
fn refract_dir(d: vec3<f32>, n: vec3<f32>, n1: f32, n2: f32) -> vec4<f32> {
    let eta = n1 / n2;
    let cos_i = -dot(d, n);
    let sin2_t = eta * eta * (1.0 - cos_i * cos_i);
    if sin2_t > 1.0 {
        return vec4<f32>(0.0);
    }
    let cos_t = sqrt(1.0 - sin2_t);
    return vec4<f32>(normalize(d * eta + n * (eta * cos_i - cos_t)), 1.0);
}

fn fresnel_dielectric(cos_in: f32, n1: f32, n2: f32) -> f32 {
    let cos_i = clamp(cos_in, 0.0, 1.0);
    let eta = n1 / n2;
    let sin2_t = eta * eta * (1.0 - cos_i * cos_i);
    if sin2_t >= 1.0 {
        return 1.0;
    }
    let cos_t = sqrt(1.0 - sin2_t);
    let rs = (n1 * cos_i - n2 * cos_t) / (n1 * cos_i + n2 * cos_t);
    let rp = (n1 * cos_t - n2 * cos_i) / (n1 * cos_t + n2 * cos_i);
    return 0.5 * (rs * rs + rp * rp);
}

fn fresnel_schlick(cos_i: f32, f0: vec3<f32>) -> vec3<f32> {
    let m = pow(1.0 - clamp(cos_i, 0.0, 1.0), 5.0);
    return f0 + (vec3<f32>(1.0) - f0) * m;
}

// Checkerboard with squares of side `scale` in the two world axes across the surface's
// dominant normal axis (x/z on a floor, x/y on a wall facing z, y/z facing x).
fn checker_is_a(p: vec3<f32>, normal: vec3<f32>, scale: f32) -> bool {
    let a = abs(normal);
    var uv = vec2<f32>(p.y, p.z);
    if a.y >= a.x && a.y >= a.z {
        uv = vec2<f32>(p.x, p.z);
    } else if a.z >= a.x {
        uv = vec2<f32>(p.x, p.y);
    }
    let iu = i32(floor(uv.x / scale));
    let iv = i32(floor(uv.y / scale));
    return ((iu + iv) & 1) == 0;
}
