// The pinhole camera. CPU twin: grin_trace::render::camera::PinholeCamera::primary_ray.

fn primary_ray(px: u32, py: u32, sx: f32, sy: f32) -> vec3<f32> {
    let w = f32(params.width);
    let h = f32(params.height);
    let tan_half = params.tan_half_fov_y;
    let aspect = params.aspect;
    let u = (2.0 * (f32(px) + sx) / w - 1.0) * aspect * tan_half;
    let v = (1.0 - 2.0 * (f32(py) + sy) / h) * tan_half;
    return normalize(params.cam_forward + params.cam_right * u + params.cam_up * v);
}

// The thin-lens ray of the pinhole ray d for the lens sample (u1, u2): from a point
// uniform on the aperture disc through where d meets the plane in focus; xyz of `o`
// the origin. CPU twin: PinholeCamera::lens_ray.
struct LensRay {
    o: vec3<f32>,
    d: vec3<f32>,
}

fn lens_ray(d: vec3<f32>, u1: f32, u2: f32) -> LensRay {
    let r = params.lens_radius * sqrt(u1);
    let a = TAU * u2;
    let o = params.cam_origin + params.cam_right * (r * cos(a)) + params.cam_up * (r * sin(a));
    let focus = params.cam_origin + d * (params.focus_distance / dot(d, params.cam_forward));
    return LensRay(o, normalize(focus - o));
}

// The camera ray through image position (px + sx, py + sy): from the camera through the
// image plane, or, orthographic, along cam_forward from its point on the view plane.
// CPU twin: PinholeCamera::camera_ray.
fn camera_ray(px: u32, py: u32, sx: f32, sy: f32) -> LensRay {
    if params.ortho_half_height > 0.0 {
        let u = (2.0 * (f32(px) + sx) / f32(params.width) - 1.0) * params.ortho_half_width;
        let v = (1.0 - 2.0 * (f32(py) + sy) / f32(params.height)) * params.ortho_half_height;
        return LensRay(params.cam_origin + params.cam_right * u + params.cam_up * v, params.cam_forward);
    }
    return LensRay(params.cam_origin, primary_ray(px, py, sx, sy));
}
