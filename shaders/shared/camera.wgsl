// The pinhole camera. CPU twin: grin_trace::render::camera::PinholeCamera::primary_ray.

fn primary_ray(px: u32, py: u32, sx: f32, sy: f32) -> vec3<f32> {
    let w = f32(params.image.x);
    let h = f32(params.image.y);
    let tan_half = params.cam_origin.w;
    let aspect = params.cam_forward.w;
    let u = (2.0 * (f32(px) + sx) / w - 1.0) * aspect * tan_half;
    let v = (1.0 - 2.0 * (f32(py) + sy) / h) * tan_half;
    return normalize(params.cam_forward.xyz + params.cam_right.xyz * u + params.cam_up.xyz * v);
}
