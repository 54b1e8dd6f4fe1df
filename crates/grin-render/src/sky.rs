//! The background a ray sees when it leaves the scene: a procedural gradient sky or an
//! equirectangular environment map read from an EXR or Radiance HDR file.
//! Keep in sync with shaders' `sky_radiance`.

use std::path::{Path, PathBuf};

use glam::DVec3;

use crate::camera::PinholeCamera;
use crate::optics::project_dir;
use crate::scene::RenderError;
use crate::surface::{Image, load_image};

/// An equirectangular map, linear RGB, row 0 at the zenith.
#[derive(Debug, Clone, PartialEq)]
pub struct EnvMap {
    pub width: usize,
    pub height: usize,
    pub texels: Vec<[f32; 3]>,
    pub intensity: f64,
}

/// The background.
#[derive(Debug, Clone, PartialEq)]
pub enum SkyModel {
    /// Horizon colour blending linearly to the zenith with elevation sine; `ground` below.
    Gradient {
        horizon: DVec3,
        zenith: DVec3,
        ground: DVec3,
    },
    Map(EnvMap),
    /// A plate at infinity filling `camera`'s view (the scene's camera: it stays put
    /// when a viewer moves its own); `mean` lights diffuse surfaces.
    Plate {
        image: Image,
        camera: PinholeCamera,
        intensity: f64,
        mean: DVec3,
    },
}

impl SkyModel {
    /// Build from the scene's `[sky]`, reading a map relative to `scene_dir`.
    pub fn from_scene(
        sky: &grin_scene::Sky,
        scene_dir: &Path,
        camera: &PinholeCamera,
    ) -> Result<Self, RenderError> {
        Ok(match sky {
            grin_scene::Sky::Gradient {
                horizon,
                zenith,
                ground,
            } => SkyModel::Gradient {
                horizon: DVec3::from_array(*horizon),
                zenith: DVec3::from_array(*zenith),
                ground: DVec3::from_array(*ground),
            },
            grin_scene::Sky::Map { path, intensity } => {
                let mut map = load_env_map(&scene_dir.join(path))?;
                map.intensity = *intensity;
                SkyModel::Map(map)
            }
            grin_scene::Sky::Plate { path, intensity } => {
                let path = scene_dir.join(path);
                let image = load_image(&path).map_err(|message| RenderError::Image {
                    what: "background plate",
                    path,
                    message,
                })?;
                SkyModel::Plate {
                    mean: image.mean() * *intensity,
                    image,
                    camera: *camera,
                    intensity: *intensity,
                }
            }
        })
    }

    /// Radiance arriving from unit direction `d`.
    pub fn sky_radiance(&self, d: DVec3) -> DVec3 {
        match self {
            SkyModel::Gradient {
                horizon,
                zenith,
                ground,
            } => {
                if d.y < 0.0 {
                    *ground
                } else {
                    horizon.lerp(*zenith, d.y.min(1.0))
                }
            }
            SkyModel::Map(map) => map.lookup(d),
            SkyModel::Plate {
                image,
                camera,
                intensity,
                ..
            } => match project_dir(camera, d) {
                Some([x, y]) => {
                    let sx = image.width as f64 / f64::from(camera.width);
                    let sy = image.height as f64 / f64::from(camera.height);
                    image.bilinear(x * sx, y * sy, false) * *intensity
                }
                None => DVec3::ZERO,
            },
        }
    }

    /// The sky light on a diffuse surface of normal `n`: the sky in that direction, or
    /// a plate's mean colour.
    pub fn ambient_radiance(&self, n: DVec3) -> DVec3 {
        match self {
            SkyModel::Plate { mean, .. } => *mean,
            _ => self.sky_radiance(n),
        }
    }
}

impl EnvMap {
    /// Bilinear lookup: u = azimuth (atan2(x, -z)), v = polar angle from +y.
    pub fn lookup(&self, d: DVec3) -> DVec3 {
        let u = 0.5 + d.x.atan2(-d.z) / std::f64::consts::TAU;
        let v = d.y.clamp(-1.0, 1.0).acos() / std::f64::consts::PI;
        let x = u * self.width as f64 - 0.5;
        let y = (v * self.height as f64 - 0.5).clamp(0.0, (self.height - 1) as f64);
        let x0 = x.floor();
        let y0 = y.floor();
        let fx = x - x0;
        let fy = y - y0;
        let wrap = |i: f64| (i as i64).rem_euclid(self.width as i64) as usize;
        let (xa, xb) = (wrap(x0), wrap(x0 + 1.0));
        let ya = y0 as usize;
        let yb = (ya + 1).min(self.height - 1);
        let t =
            |xi: usize, yi: usize| DVec3::from(self.texels[yi * self.width + xi].map(f64::from));
        let top = t(xa, ya).lerp(t(xb, ya), fx);
        let bottom = t(xa, yb).lerp(t(xb, yb), fx);
        top.lerp(bottom, fy) * self.intensity
    }
}

/// Read an `.exr` (first RGBA layer) or `.hdr` (Radiance) equirectangular map.
pub fn load_env_map(path: &Path) -> Result<EnvMap, RenderError> {
    let err = |message: String| RenderError::EnvMap {
        path: PathBuf::from(path),
        message,
    };
    if path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("png"))
    {
        return Err(err("environment map must be an .exr or .hdr file".into()));
    }
    let image = load_image(path).map_err(err)?;
    Ok(EnvMap {
        width: image.width,
        height: image.height,
        texels: image.texels,
        intensity: 1.0,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gradient_has_a_horizon() {
        let c = grin_scene::Camera {
            position: [0.0; 3],
            look_at: [0.0, 0.0, -1.0],
            up: [0.0, 1.0, 0.0],
            fov_y_deg: 40.0,
            focal_length_mm: None,
            sensor_height_mm: None,
            pixel_pitch_um: None,
            f_number: None,
            focus_distance: None,
        };
        let cam = PinholeCamera::new(&c, 4, 4).expect("camera");
        let sky =
            SkyModel::from_scene(&grin_scene::Sky::default(), Path::new("."), &cam).expect("sky");
        let SkyModel::Gradient {
            horizon,
            zenith,
            ground,
        } = sky.clone()
        else {
            panic!("default sky is a gradient")
        };
        assert_eq!(sky.sky_radiance(DVec3::Y), zenith);
        assert_eq!(sky.sky_radiance(DVec3::X), horizon);
        assert_eq!(sky.sky_radiance(-DVec3::Y), ground);
    }

    #[test]
    fn map_lookup_hits_the_right_texel() {
        // 4x2 map: top row (up) red, bottom row (down) blue.
        let mut texels = vec![[1.0, 0.0, 0.0]; 4];
        texels.extend(vec![[0.0, 0.0, 1.0]; 4]);
        let map = EnvMap {
            width: 4,
            height: 2,
            texels,
            intensity: 2.0,
        };
        assert!((map.lookup(DVec3::Y) - DVec3::new(2.0, 0.0, 0.0)).length() < 1e-12);
        assert!((map.lookup(-DVec3::Y) - DVec3::new(0.0, 0.0, 2.0)).length() < 1e-12);
    }

    #[test]
    fn exr_map_round_trip_and_bad_extension() {
        let dir = std::env::temp_dir().join(format!("grin-sky-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("tmp dir");
        let path = dir.join("env.exr");
        exr::prelude::write_rgb_file(&path, 8, 4, |x, y| (x as f32, y as f32, 0.5f32))
            .expect("write exr");
        let map = load_env_map(&path).expect("read exr");
        assert_eq!((map.width, map.height), (8, 4));
        assert_eq!(map.texels[2 * 8 + 3], [3.0, 2.0, 0.5]);
        let e = load_env_map(&dir.join("env.png")).expect_err("png is not a map");
        assert!(e.to_string().contains("env.png"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
