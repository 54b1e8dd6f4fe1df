//! The camera: pixel -> primary ray in world space, through a pinhole or a thin lens.

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
    /// Thin lens: aperture radius (0: a pinhole) and the distance in focus along
    /// `forward`.
    pub lens_radius: f64,
    pub focus_distance: f64,
    /// Orthographic: half the width and height of the view in world units (rays
    /// parallel to `forward` from the plane through `origin`); `None`: perspective.
    pub ortho: Option<[f64; 2]>,
}

impl PinholeCamera {
    /// Camera at `position` looking at `look_at`; `None` if the view direction is zero or
    /// parallel to `up`.
    pub fn new(cam: &grin_scene::Camera, width: u32, height: u32) -> Option<Self> {
        let origin = DVec3::from_array(cam.position);
        let forward = (DVec3::from_array(cam.look_at) - origin).try_normalize()?;
        let right = forward.cross(DVec3::from_array(cam.up)).try_normalize()?;
        let up = right.cross(forward);
        let (aperture, focus) = cam.aperture().unwrap_or((0.0, 1.0));
        Some(PinholeCamera {
            lens_radius: 0.5 * aperture,
            focus_distance: focus,
            ortho: None,
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

    /// The camera ray (origin, unit direction) through image position (`px + sx`,
    /// `py + sy`): from `origin` through the image plane, or, orthographic, along
    /// `forward` from its point on the view plane. GPU twin: `camera_ray` in camera.wgsl.
    pub fn camera_ray(&self, px: u32, py: u32, sx: f64, sy: f64) -> (DVec3, DVec3) {
        match self.ortho {
            Some([hw, hh]) => {
                let u = (2.0 * (f64::from(px) + sx) / f64::from(self.width) - 1.0) * hw;
                let v = (1.0 - 2.0 * (f64::from(py) + sy) / f64::from(self.height)) * hh;
                (self.origin + self.right * u + self.up * v, self.forward)
            }
            None => (self.origin, self.primary_ray(px, py, sx, sy)),
        }
    }

    /// The thin-lens ray (origin, unit direction) of the pinhole ray `d` for the lens
    /// sample (`u1`, `u2`) in [0, 1)^2: from a point uniform on the aperture disc
    /// (radius R sqrt(u1), angle 2 pi u2) through where `d` meets the plane in focus.
    /// GPU twin: `lens_ray` in camera.wgsl.
    pub fn lens_ray(&self, d: DVec3, u1: f64, u2: f64) -> (DVec3, DVec3) {
        let r = self.lens_radius * u1.sqrt();
        let (s, c) = (std::f64::consts::TAU * u2).sin_cos();
        let o = self.origin + self.right * (r * c) + self.up * (r * s);
        let focus = self.origin + d * (self.focus_distance / d.dot(self.forward));
        (o, (focus - o).normalize())
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
            focal_length_mm: None,
            sensor_height_mm: None,
            pixel_pitch_um: None,
            f_number: None,
            focus_distance: None,
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
            focal_length_mm: None,
            sensor_height_mm: None,
            pixel_pitch_um: None,
            f_number: None,
            focus_distance: None,
        };
        assert!(PinholeCamera::new(&c, 10, 10).is_none());
    }
}
