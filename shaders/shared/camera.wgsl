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
