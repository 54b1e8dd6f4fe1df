//! Image-space outputs from a rendered frame's AOVs (either backend): displacement and ST
//! maps, knife-edge schlieren, interferograms and BOS image pairs. Each pixel's camera
//! ray is the pixel-centre ray (the frame is rendered with 1 sample a pixel); its AOVs say
//! where it left the medium and in which direction, and its optical path difference.
//! The shadowgraph traces its own collimated beam (grin-trace). Formulas: docs/optics.md.

use glam::DVec3;
use grin_scene::{Dots, Fringes, Knife, PlaneSpec};

use crate::camera::PinholeCamera;
use crate::image::Frame;

/// A plane with an orthonormal frame: `u` along the camera's right, `v` along its up
/// (both projected into the plane).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plane {
    pub point: DVec3,
    pub normal: DVec3,
    pub u: DVec3,
    pub v: DVec3,
}

impl Plane {
    /// The plane of `spec` with axes from `cam`; `None` for a zero normal or a plane
    /// seen edge-on along the camera's right.
    pub fn new(spec: &PlaneSpec, cam: &PinholeCamera) -> Option<Plane> {
        let normal = DVec3::from_array(spec.normal).try_normalize()?;
        let u = (cam.right - normal * cam.right.dot(normal)).try_normalize()?;
        let mut v = normal.cross(u);
        if v.dot(cam.up) < 0.0 {
            v = -v;
        }
        Some(Plane {
            point: DVec3::from_array(spec.point),
            normal,
            u,
            v,
        })
    }

    /// Where the ray `o + t d` (t > 0) meets the plane.
    pub fn hit(&self, o: DVec3, d: DVec3) -> Option<DVec3> {
        crate::primitives::intersect_plane(self.point, self.normal, o, d, 0.0, f64::INFINITY)
            .map(|(t, _)| o + d * t)
    }

    /// Plane coordinates (u, v) of a point on it.
    pub fn coords(&self, p: DVec3) -> [f64; 2] {
        let r = p - self.point;
        [r.dot(self.u), r.dot(self.v)]
    }
}

/// Image position (pixels, x right, y down, pixel (i, j)'s centre at (i + 0.5, j + 0.5))
/// of the direction `d` seen from the camera; `None` behind it.
pub fn project_dir(cam: &PinholeCamera, d: DVec3) -> Option<[f64; 2]> {
    let z = d.dot(cam.forward);
    if z <= 0.0 {
        return None;
    }
    let aspect = f64::from(cam.width) / f64::from(cam.height);
    let x = d.dot(cam.right) / z / (aspect * cam.tan_half_fov_y);
    let y = d.dot(cam.up) / z / cam.tan_half_fov_y;
    Some([
        (x + 1.0) * 0.5 * f64::from(cam.width),
        (1.0 - y) * 0.5 * f64::from(cam.height),
    ])
}

/// Where a ray from `p` along `d` appears in the image (pixels, as [`project_dir`]): the
/// point it lands on `plane`, or, with no plane, its direction (the plane at infinity).
/// `None` where it misses the plane or lands behind the camera.
pub fn landing_px(
    cam: &PinholeCamera,
    plane: Option<&Plane>,
    p: DVec3,
    d: DVec3,
) -> Option<[f64; 2]> {
    match plane {
        Some(pl) => project_dir(cam, pl.hit(p, d)? - cam.origin),
        None => project_dir(cam, d),
    }
}

/// The angles (radians) of direction `d` from the camera's axis, along its right and up.
pub fn camera_angles(cam: &PinholeCamera, d: DVec3) -> [f64; 2] {
    let z = d.dot(cam.forward);
    [d.dot(cam.right).atan2(z), d.dot(cam.up).atan2(z)]
}

/// Where pixel `p`'s camera ray `d0` goes on after the medium (point, unit direction):
/// from its exit if it left it, from the camera if it missed it; `None` if it stopped
/// in it (absorbed, max_steps, error).
fn onward(p: &crate::image::PixelOut, cam: &PinholeCamera, d0: DVec3) -> Option<(DVec3, DVec3)> {
    // `status`: 0 missed, 1 exited, 5 degraded (left, RayStatus order).
    if p.status == 0.0 {
        Some((cam.origin, d0))
    } else if p.status == 1.0 || p.status == 5.0 {
        Some((
            DVec3::from_array(p.exit_pos.map(f64::from)),
            DVec3::from_array(p.exit_dir.map(f64::from)).normalize(),
        ))
    } else {
        None
    }
}

/// Each pixel's displacement: where its ray lands with the medium minus without.
#[derive(Debug, Clone, PartialEq)]
pub struct Displacement {
    pub width: u32,
    pub height: u32,
    /// Image pixels (x right, y down): where the plane point the ray lands on appears
    /// without the medium, minus the pixel's centre.
    pub pixels: Vec<[f64; 2]>,
    /// On the plane, (u, v) in world units; at infinity, angles (radians) along the
    /// camera's right and up.
    pub world: Vec<[f64; 2]>,
    /// False where the ray did not leave the medium (absorbed, max_steps, error) or does
    /// not reach the plane: NaN in the outputs.
    pub valid: Vec<bool>,
}

impl Displacement {
    /// From `frame` (rendered at 1 sample a pixel by `cam`) onto `plane` (or infinity).
    pub fn new(frame: &Frame, cam: &PinholeCamera, plane: Option<&Plane>) -> Displacement {
        let (w, h) = (frame.width, frame.height);
        let n = frame.pixels.len();
        let mut out = Displacement {
            width: w,
            height: h,
            pixels: vec![[f64::NAN; 2]; n],
            world: vec![[f64::NAN; 2]; n],
            valid: vec![false; n],
        };
        for (idx, p) in frame.pixels.iter().enumerate() {
            let (i, j) = ((idx as u32) % w, (idx as u32) / w);
            let d0 = cam.primary_ray(i, j, 0.5, 0.5);
            let Some((exit_pos, exit_dir)) = onward(p, cam, d0) else {
                continue;
            };
            let centre = [f64::from(i) + 0.5, f64::from(j) + 0.5];
            let (seen, world) = match plane {
                Some(pl) => {
                    let (Some(with), Some(without)) =
                        (pl.hit(exit_pos, exit_dir), pl.hit(cam.origin, d0))
                    else {
                        continue;
                    };
                    let (a, b) = (pl.coords(with), pl.coords(without));
                    (
                        project_dir(cam, with - cam.origin),
                        [a[0] - b[0], a[1] - b[1]],
                    )
                }
                None => {
                    let (a, b) = (camera_angles(cam, exit_dir), camera_angles(cam, d0));
                    (project_dir(cam, exit_dir), [a[0] - b[0], a[1] - b[1]])
                }
            };
            let Some(seen) = seen else { continue };
            out.pixels[idx] = [seen[0] - centre[0], seen[1] - centre[1]];
            out.world[idx] = world;
            out.valid[idx] = true;
        }
        out
    }

    /// The ST map: for each pixel, the normalized position in the undistorted plate to
    /// read (s = x / width, t = 1 - y / height, origin at the bottom left as Nuke's
    /// STMap reads it).
    pub fn st(&self) -> Vec<[f64; 2]> {
        let (w, h) = (f64::from(self.width), f64::from(self.height));
        self.pixels
            .iter()
            .enumerate()
            .map(|(idx, d)| {
                let x = (idx as u32 % self.width) as f64 + 0.5 + d[0];
                let y = (idx as u32 / self.width) as f64 + 0.5 + d[1];
                [x / w, 1.0 - y / h]
            })
            .collect()
    }
}

/// Deflection of each pixel's ray as angles (radians) along the camera's right and up:
/// the exit direction's minus the camera ray's. NaN where the ray did not leave.
pub fn deflection_angles(frame: &Frame, cam: &PinholeCamera) -> Vec<[f64; 2]> {
    frame
        .pixels
        .iter()
        .enumerate()
        .map(|(idx, p)| {
            let (i, j) = ((idx as u32) % frame.width, (idx as u32) / frame.width);
            let d0 = cam.primary_ray(i, j, 0.5, 0.5);
            let Some((_, e)) = onward(p, cam, d0) else {
                return [f64::NAN; 2];
            };
            let (a, b) = (camera_angles(cam, e), camera_angles(cam, d0));
            [a[0] - b[0], a[1] - b[1]]
        })
        .collect()
}

/// Knife-edge schlieren: the light passing the knife, 1 where nothing deflects.
/// The source's image spans [-a, a] along the knife's direction k (a = source_size_rad),
/// the edge blocks below a(2 cutoff - 1); a deflection e moves the image by e.k, so the
/// passing fraction is clamp((a + e.k - a(2c - 1)) / 2a, 0, 1), divided by its value at
/// e = 0 (1 - c). In the linear range, I - 1 = e.k / (2 a (1 - c)).
pub fn schlieren(angles: &[[f64; 2]], knife: &Knife) -> Vec<f64> {
    let (s, c) = knife.angle_deg.to_radians().sin_cos();
    let a = knife.source_size_rad;
    let edge = a * (2.0 * knife.cutoff - 1.0);
    let base = 1.0 - knife.cutoff;
    angles
        .iter()
        .map(|e| {
            let ek = e[0] * c + e[1] * s;
            ((a + ek - edge) / (2.0 * a)).clamp(0.0, 1.0) / base
        })
        .collect()
}

/// An interferogram from the `opd_plane` AOV (world units, metres; the OPD taken on to a
/// plane normal to the ray): phase in waves opd / lambda plus the carrier of `fringes`,
/// and intensity (1 + cos 2 pi phase) / 2.
pub fn interferogram(frame: &Frame, wavelength_nm: f64, fringes: &Fringes) -> (Vec<f64>, Vec<f64>) {
    let lambda = wavelength_nm * 1e-9;
    let (s, c) = fringes.angle_deg.to_radians().sin_cos();
    let phase: Vec<f64> = frame
        .pixels
        .iter()
        .enumerate()
        .map(|(idx, p)| {
            let x = (idx as u32 % frame.width) as f64 + 0.5;
            let y = (idx as u32 / frame.width) as f64 + 0.5;
            let carrier = if fringes.spacing_px > 0.0 {
                (x * c - y * s) / fringes.spacing_px
            } else {
                0.0
            };
            f64::from(p.opd_plane) / lambda + carrier
        })
        .collect();
    let intensity = phase
        .iter()
        .map(|ph| 0.5 * (1.0 + (std::f64::consts::TAU * ph).cos()))
        .collect();
    (phase, intensity)
}

/// The random-dot background at plane coordinates `uv` (the `dots` material's pattern:
/// [`crate::surface::dot_intensity`]).
pub fn dot_intensity(dots: &Dots, uv: [f64; 2]) -> f64 {
    crate::surface::dot_intensity(dots.diameter, dots.density, dots.seed, uv)
}

/// A BOS image pair on `plane`: the reference (each pixel's camera ray straight onto the
/// dots) and the distorted image (the ray through the medium), NaN where the ray does not
/// reach the plane.
pub fn bos_pair(
    frame: &Frame,
    cam: &PinholeCamera,
    plane: &Plane,
    dots: &Dots,
) -> (Vec<f64>, Vec<f64>) {
    let mut reference = Vec::with_capacity(frame.pixels.len());
    let mut distorted = Vec::with_capacity(frame.pixels.len());
    for (idx, p) in frame.pixels.iter().enumerate() {
        let (i, j) = ((idx as u32) % frame.width, (idx as u32) / frame.width);
        let d0 = cam.primary_ray(i, j, 0.5, 0.5);
        let r = plane
            .hit(cam.origin, d0)
            .map_or(f64::NAN, |q| dot_intensity(dots, plane.coords(q)));
        let landed = onward(p, cam, d0).and_then(|(o, d)| plane.hit(o, d));
        reference.push(r);
        distorted.push(landed.map_or(f64::NAN, |q| dot_intensity(dots, plane.coords(q))));
    }
    (reference, distorted)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam() -> PinholeCamera {
        let c = grin_scene::Camera {
            position: [0.0, 0.0, -4.0],
            look_at: [0.0, 0.0, 0.0],
            up: [0.0, 1.0, 0.0],
            fov_y_deg: 30.0,
            focal_length_mm: None,
            sensor_height_mm: None,
            pixel_pitch_um: None,
            f_number: None,
            focus_distance: None,
        };
        PinholeCamera::new(&c, 64, 48).expect("camera")
    }

    #[test]
    fn pixel_centre_rays_project_back_to_their_centres() {
        let c = cam();
        for &(i, j) in &[(0u32, 0u32), (10, 20), (63, 47)] {
            let d = c.primary_ray(i, j, 0.5, 0.5);
            let p = project_dir(&c, d).expect("in front");
            assert!((p[0] - (f64::from(i) + 0.5)).abs() < 1e-9, "{p:?}");
            assert!((p[1] - (f64::from(j) + 0.5)).abs() < 1e-9, "{p:?}");
        }
    }

    #[test]
    fn schlieren_is_linear_then_saturates() {
        let k = Knife {
            angle_deg: 0.0,
            cutoff: 0.5,
            source_size_rad: 1e-4,
        };
        let i = schlieren(
            &[
                [0.0, 0.0],
                [2e-5, 5e-5],
                [-2e-5, 0.0],
                [3e-4, 0.0],
                [-3e-4, 0.0],
            ],
            &k,
        );
        assert!((i[0] - 1.0).abs() < 1e-12);
        // I - 1 = e.k / (2 a (1 - c)) = 2e-5 / 1e-4 = 0.2 (the y deflection is along the edge).
        assert!((i[1] - 1.2).abs() < 1e-12, "{i:?}");
        assert!((i[2] - 0.8).abs() < 1e-12, "{i:?}");
        assert_eq!((i[3], i[4]), (2.0, 0.0));
    }
}
