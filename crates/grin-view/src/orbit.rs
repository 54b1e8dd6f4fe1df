//! The viewer's orbit camera: a target point, a distance and two angles about the
//! scene's up axis, started from the scene's `[camera]` and turned back into one.

use glam::DVec3;

/// Radians of orbit per pixel of mouse drag.
pub const ORBIT_RAD_PER_PIXEL: f64 = 0.006;
/// Zoom factor per scroll line (distance x e^-0.1 per line).
pub const ZOOM_PER_LINE: f64 = 0.1;
/// Elevation limit (keeps the view from becoming parallel to up).
const MAX_PITCH: f64 = 89.0 * std::f64::consts::PI / 180.0;

/// An orbit camera around `target`.
#[derive(Debug, Clone, PartialEq)]
pub struct OrbitCamera {
    pub target: DVec3,
    pub distance: f64,
    /// Azimuth about `up` (radians), measured in the plane normal to it.
    pub yaw: f64,
    /// Elevation above that plane (radians).
    pub pitch: f64,
    pub fov_y_deg: f64,
    up: DVec3,
    /// Two unit vectors spanning the plane normal to `up`.
    e1: DVec3,
    e2: DVec3,
}

impl OrbitCamera {
    /// The orbit camera whose view is `cam`'s (position, look_at, up, fov).
    pub fn from_scene(cam: &grin_scene::Camera) -> Self {
        let up = DVec3::from_array(cam.up)
            .try_normalize()
            .unwrap_or(DVec3::Y);
        let e1 = up.any_orthonormal_vector();
        let e2 = up.cross(e1);
        let target = DVec3::from_array(cam.look_at);
        let offset = DVec3::from_array(cam.position) - target;
        let distance = offset.length().max(1e-9);
        let pitch = (offset.dot(up) / distance).clamp(-1.0, 1.0).asin();
        let yaw = offset.dot(e2).atan2(offset.dot(e1));
        OrbitCamera {
            target,
            distance,
            yaw,
            pitch,
            fov_y_deg: cam.fov_y_deg,
            up,
            e1,
            e2,
        }
    }

    /// The orbit camera of `cam`'s view that turns about the point of its line of sight
    /// nearest `pivot` (the medium's centre): the view is the scene's, and a drag keeps
    /// the medium in view where the scene's look_at lies far beyond it (heat haze's is
    /// 22 m away, and one drag swung the haze out of the window). About look_at where
    /// there is no pivot, or it is not in front of the camera.
    pub fn from_scene_about(cam: &grin_scene::Camera, pivot: Option<DVec3>) -> Self {
        let mut orbit = Self::from_scene(cam);
        if let Some(c) = pivot {
            let position = DVec3::from_array(cam.position);
            let forward = (orbit.target - position) / orbit.distance;
            let along = (c - position).dot(forward);
            if along > 1e-6 * orbit.distance {
                orbit.target = position + forward * along;
                orbit.distance = along;
            }
        }
        orbit
    }

    /// The camera's position.
    pub fn position(&self) -> DVec3 {
        let (sy, cy) = self.yaw.sin_cos();
        let (sp, cp) = self.pitch.sin_cos();
        self.target + self.distance * (cp * (cy * self.e1 + sy * self.e2) + sp * self.up)
    }

    /// Unit forward, right and up of the view.
    pub fn basis(&self) -> (DVec3, DVec3, DVec3) {
        let forward = (self.target - self.position()).normalize();
        let right = forward.cross(self.up).try_normalize().unwrap_or(self.e1);
        (forward, right, right.cross(forward))
    }

    /// The scene camera of this view.
    pub fn to_scene(&self) -> grin_scene::Camera {
        grin_scene::Camera {
            position: self.position().to_array(),
            look_at: self.target.to_array(),
            up: self.up.to_array(),
            fov_y_deg: self.fov_y_deg,
            focal_length_mm: None,
            sensor_height_mm: None,
            pixel_pitch_um: None,
            f_number: None,
            focus_distance: None,
        }
    }

    /// Orbit by a mouse drag of (`dx`, `dy`) pixels: right drags turn the scene right,
    /// down drags raise the camera.
    pub fn orbit(&mut self, dx: f64, dy: f64) {
        self.yaw -= dx * ORBIT_RAD_PER_PIXEL;
        self.pitch = (self.pitch + dy * ORBIT_RAD_PER_PIXEL).clamp(-MAX_PITCH, MAX_PITCH);
    }

    /// Orbit about `up` by `degrees` (the headless `--orbit`).
    pub fn orbit_degrees(&mut self, degrees: f64) {
        self.yaw += degrees.to_radians();
    }

    /// Zoom by `lines` scroll lines (positive: closer).
    pub fn zoom(&mut self, lines: f64) {
        self.distance = (self.distance * (-ZOOM_PER_LINE * lines).exp()).clamp(1e-4, 1e7);
    }

    /// Pan by a drag of (`dx`, `dy`) pixels in a view `height` pixels tall: the point
    /// under the cursor stays under it at the target's depth.
    pub fn pan(&mut self, dx: f64, dy: f64, height: f64) {
        let (_, right, up) = self.basis();
        let per_pixel =
            2.0 * self.distance * (self.fov_y_deg.to_radians() * 0.5).tan() / height.max(1.0);
        self.target += (-dx * right + dy * up) * per_pixel;
    }

    /// Fly: move camera and target by `forward`, `right`, `up` (in units of the
    /// distance to the target).
    pub fn fly(&mut self, forward: f64, right: f64, up: f64) {
        let (f, r, u) = self.basis();
        self.target += (f * forward + r * right + u * up) * self.distance;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam() -> grin_scene::Camera {
        grin_scene::Camera {
            position: [0.3, 1.2, -4.0],
            look_at: [0.1, 0.4, 0.5],
            up: [0.0, 1.0, 0.0],
            fov_y_deg: 35.0,
            focal_length_mm: None,
            sensor_height_mm: None,
            pixel_pitch_um: None,
            f_number: None,
            focus_distance: None,
        }
    }

    fn close(a: [f64; 3], b: [f64; 3], tol: f64) -> bool {
        a.iter().zip(&b).all(|(x, y)| (x - y).abs() <= tol)
    }

    /// About the medium: the same view, turning about the point of the line of sight
    /// nearest the medium's centre, which stays in the middle of the view as it turns.
    #[test]
    fn the_pivot_is_on_the_line_of_sight_nearest_the_medium() {
        let c = cam();
        let medium = DVec3::new(0.4, 0.6, 0.0);
        let mut o = OrbitCamera::from_scene_about(&c, Some(medium));
        let plain = OrbitCamera::from_scene(&c);
        assert!(close(o.position().to_array(), c.position, 1e-12));
        let (f, _, _) = o.basis();
        assert!(
            (f - plain.basis().0).length() < 1e-12,
            "{f} vs {:?}",
            plain.basis()
        );
        // The pivot is the foot of the perpendicular from the medium's centre.
        assert!((medium - o.target).dot(f).abs() < 1e-12);
        assert!(o.distance < plain.distance);
        let pivot = o.target;
        o.orbit(120.0, -40.0);
        assert_eq!(o.target, pivot);
        assert!((o.position().distance(pivot) - o.distance).abs() < 1e-12);
        assert!(((pivot - o.position()).normalize() - o.basis().0).length() < 1e-12);
        // A medium behind the camera: about look_at.
        let behind = OrbitCamera::from_scene_about(&c, Some(DVec3::new(0.3, 1.2, -9.0)));
        assert_eq!(behind, plain);
        assert_eq!(OrbitCamera::from_scene_about(&c, None), plain);
    }

    #[test]
    fn starts_from_the_scene_camera_exactly() {
        for up in [[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.3, 0.9, 0.1]] {
            let mut c = cam();
            c.up = up;
            let o = OrbitCamera::from_scene(&c);
            let back = o.to_scene();
            assert!(close(back.position, c.position, 1e-12), "{back:?} vs {c:?}");
            assert_eq!(back.look_at, c.look_at);
            assert_eq!(back.fov_y_deg, c.fov_y_deg);
        }
    }

    #[test]
    fn orbiting_keeps_the_distance_and_a_full_turn_comes_back() {
        let start = OrbitCamera::from_scene(&cam());
        let mut o = start.clone();
        for _ in 0..36 {
            o.orbit_degrees(10.0);
            let d = (o.position() - o.target).length();
            assert!((d - start.distance).abs() < 1e-12);
        }
        assert!(close(o.to_scene().position, cam().position, 1e-9));
        // Pitch is held below the pole.
        o.orbit(0.0, 1e6);
        assert!(o.pitch <= MAX_PITCH && o.basis().1.length() > 0.99);
    }

    #[test]
    fn zoom_and_pan_move_as_the_user_expects() {
        let mut o = OrbitCamera::from_scene(&cam());
        let d = o.distance;
        o.zoom(1.0);
        assert!((o.distance - d * (-ZOOM_PER_LINE).exp()).abs() < 1e-12);
        let (_, right, _) = o.basis();
        let t = o.target;
        o.pan(-100.0, 0.0, 200.0);
        // Dragging left by half the view height moves the target right by
        // distance * tan(fov/2).
        let moved = (o.target - t).dot(right);
        let want = o.distance * (o.fov_y_deg.to_radians() * 0.5).tan();
        assert!((moved - want).abs() < 1e-12, "{moved} vs {want}");
    }
}
