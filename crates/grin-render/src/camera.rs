//! The pinhole camera: pixel -> primary ray in world space.

use glam::DVec3;

/// A pinhole camera with an orthonormal frame; `tan_half_fov_y` scales the image plane.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PinholeCamera {
    pub origin: DVec3,
    pub forward: DVec3,
    pub right: DVec3,
    pub up: DVec3,
    pub tan_half_fov_y: f64,
    pub width: u32,
    pub height: u32,
}

impl PinholeCamera {
    /// Camera at `position` looking at `look_at`; `None` if the view direction is zero or
    /// parallel to `up`.
    pub fn new(cam: &grin_scene::Camera, width: u32, height: u32) -> Option<Self> {
        let origin = DVec3::from_array(cam.position);
        let forward = (DVec3::from_array(cam.look_at) - origin).try_normalize()?;
        let right = forward.cross(DVec3::from_array(cam.up)).try_normalize()?;
        let up = right.cross(forward);
        Some(PinholeCamera {
            origin,
            forward,
            right,
            up,
            tan_half_fov_y: (cam.fov_y_deg.to_radians() * 0.5).tan(),
            width,
            height,
        })
    }

    /// Unit direction of the ray through image position (`px + sx`, `py + sy`), pixel
    /// (0, 0) at the top left, (sx, sy) in [0, 1) the position inside the pixel.
    pub fn primary_ray(&self, px: u32, py: u32, sx: f64, sy: f64) -> DVec3 {
        let aspect = f64::from(self.width) / f64::from(self.height);
        let u = (2.0 * (f64::from(px) + sx) / f64::from(self.width) - 1.0)
            * aspect
            * self.tan_half_fov_y;
        let v = (1.0 - 2.0 * (f64::from(py) + sy) / f64::from(self.height)) * self.tan_half_fov_y;
        (self.forward + self.right * u + self.up * v).normalize()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam() -> PinholeCamera {
        let c = grin_scene::Camera {
            position: [0.0, 1.0, -4.0],
            look_at: [0.0, 1.0, 0.0],
            up: [0.0, 1.0, 0.0],
            fov_y_deg: 90.0,
        };
        PinholeCamera::new(&c, 200, 100).expect("valid camera")
    }

    #[test]
    fn centre_pixel_looks_forward_and_edges_span_the_fov() {
        let c = cam();
        let d = c.primary_ray(100, 50, 0.0, 0.0);
        assert!((d - DVec3::Z).length() < 1e-12);
        // Top edge at fov_y/2 = 45 degrees above the axis.
        let top = c.primary_ray(100, 0, 0.0, 0.0);
        assert!((top.y.atan2(top.z).to_degrees() - 45.0).abs() < 1e-9);
        // Right edge: tan = aspect * tan(45) = 2; right-handed frame puts +x... on `right`.
        let r = c.primary_ray(200, 50, 0.0, 0.0);
        assert!((r.dot(c.right) / r.dot(c.forward) - 2.0).abs() < 1e-9);
    }

    #[test]
    fn degenerate_camera_is_rejected() {
        let c = grin_scene::Camera {
            position: [0.0; 3],
            look_at: [0.0, 2.0, 0.0],
            up: [0.0, 1.0, 0.0],
            fov_y_deg: 40.0,
        };
        assert!(PinholeCamera::new(&c, 10, 10).is_none());
    }
}
