//! The scene as both backends render it: camera, primitives, materials, lights, sky and
//! the medium with its tracer settings, resolved and checked from a [`Scene`] once.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use glam::DVec3;
use grin_field::{Bounds, IndexField};
use grin_scene::{Light, Material, RenderSettings, Scene, Shape};

use crate::camera::PinholeCamera;
use crate::image::PixelOut;
use crate::primitives::Primitive;
use crate::rng::Rng;
use crate::settings::TraceSettings;
use crate::sky::SkyModel;
use crate::surface::{Image, load_image};

/// Shortest jittered first step, as a fraction of the nominal step: keeps a jittered
/// step from being vanishingly small (GPU twin: MIN_JITTER_FRACTION in step.wgsl).
pub const MIN_JITTER_FRACTION: f32 = 1e-3;

/// Largest image rendered in one frame: 2^26 pixels (8192^2) keep the frame buffer
/// plus the EXR's channel copies under ~6 GB.
pub const MAX_PIXELS: u64 = 1 << 26;

/// Why a scene cannot be rendered or written.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    #[error("camera: {0}")]
    Camera(String),
    #[error("object {index}: {message}")]
    Object { index: usize, message: String },
    #[error("light {index}: {message}")]
    Light { index: usize, message: String },
    #[error("[render]: {0}")]
    Settings(String),
    #[error("environment map {}: {message}", path.display())]
    EnvMap { path: PathBuf, message: String },
    #[error("{what} {}: {message}", path.display())]
    Image {
        what: &'static str,
        path: PathBuf,
        message: String,
    },
    #[error("{}: {message}", path.display())]
    Output { path: PathBuf, message: String },
    #[error(transparent)]
    Write(#[from] grin_output::OutputError),
    #[error("render cancelled")]
    Cancelled,
    #[error("{0}")]
    Memory(String),
}

/// The medium as the renderer holds it: the field and the tracer settings.
#[derive(Debug, Clone)]
pub struct SceneMedium {
    pub field: Arc<dyn IndexField>,
    pub bounds: Bounds,
    pub ambient: f64,
    pub trace: TraceSettings,
}

impl SceneMedium {
    pub fn new(field: Arc<dyn IndexField>, settings: &RenderSettings) -> Result<Self, RenderError> {
        let trace = TraceSettings::from_render(settings);
        trace
            .validate_for(&field.bounds())
            .map_err(|e| RenderError::Settings(e.to_string()))?;
        Ok(SceneMedium {
            bounds: field.bounds(),
            ambient: field.ambient_index(),
            field,
            trace,
        })
    }
}

/// Everything the renderer needs, resolved from a [`Scene`].
#[derive(Debug, Clone)]
pub struct RenderScene {
    pub camera: PinholeCamera,
    pub objects: Vec<Primitive>,
    pub materials: Vec<Material>,
    pub lights: Vec<Light>,
    pub sky: SkyModel,
    pub medium: Option<SceneMedium>,
    pub settings: RenderSettings,
    /// The images of `texture` materials, each file read once.
    pub images: Vec<Image>,
    /// Per object: its image in `images` (texture materials).
    pub object_images: Vec<Option<usize>>,
}

fn finite3(v: [f64; 3]) -> bool {
    v.iter().all(|x| x.is_finite())
}

impl RenderScene {
    /// Resolve `scene` (size and spp from its `[render]`) with the medium's `field`, built
    /// by the caller with `grin_field::build_field`. Environment maps are read relative to
    /// `scene_dir`. Every check happens here, before any pixel is traced.
    pub fn new(
        scene: &Scene,
        scene_dir: &Path,
        field: Option<Arc<dyn IndexField>>,
    ) -> Result<Self, RenderError> {
        let s = &scene.render;
        if s.width == 0 || s.height == 0 {
            return Err(RenderError::Settings(format!(
                "image size {}x{} is empty",
                s.width, s.height
            )));
        }
        if u64::from(s.width) * u64::from(s.height) > MAX_PIXELS {
            return Err(RenderError::Settings(format!(
                "image size {}x{} exceeds {MAX_PIXELS} pixels (the frame and its EXR channels would need ~{} GB)",
                s.width,
                s.height,
                u64::from(s.width)
                    * u64::from(s.height)
                    * 2
                    * std::mem::size_of::<PixelOut>() as u64
                    / 1_000_000_000
            )));
        }
        if s.spp == 0 {
            return Err(RenderError::Settings("spp must be at least 1".into()));
        }
        let c = &scene.camera;
        if !(finite3(c.position) && finite3(c.look_at) && finite3(c.up)) {
            return Err(RenderError::Camera(
                "position, look_at and up must be finite".into(),
            ));
        }
        if !(c.fov_y_deg > 0.0 && c.fov_y_deg < 180.0) {
            return Err(RenderError::Camera(format!(
                "fov_y_deg = {} must be in (0, 180)",
                c.fov_y_deg
            )));
        }
        let camera = PinholeCamera::new(c, s.width, s.height).ok_or_else(|| {
            RenderError::Camera(
                "look_at must differ from position and the view must not be parallel to up".into(),
            )
        })?;
        for (index, o) in scene.objects.iter().enumerate() {
            let bad = |message: &str| RenderError::Object {
                index,
                message: message.into(),
            };
            match o.shape {
                Shape::Sphere { center, radius } => {
                    if !(finite3(center) && radius > 0.0 && radius.is_finite()) {
                        return Err(bad("sphere needs a finite center and a positive radius"));
                    }
                }
                Shape::Plane { point, normal } => {
                    if !finite3(point)
                        || !finite3(normal)
                        || DVec3::from_array(normal).length() == 0.0
                    {
                        return Err(bad("plane needs a finite point and a non-zero normal"));
                    }
                }
                Shape::Box { min, max } => {
                    if !finite3(min) || !finite3(max) || (0..3).any(|i| min[i] >= max[i]) {
                        return Err(bad("box needs finite min < max on every axis"));
                    }
                }
            }
            if let Material::Glass { ior, .. } = o.material
                && !(ior > 0.0 && ior.is_finite())
            {
                return Err(bad("glass ior must be positive"));
            }
            if let Material::Checker { scale, .. } = o.material
                && !(scale > 0.0 && scale.is_finite())
            {
                return Err(bad("checker scale must be positive"));
            }
        }
        let mut images = Vec::new();
        let mut object_images = Vec::with_capacity(scene.objects.len());
        let mut read: Vec<PathBuf> = Vec::new();
        for (index, o) in scene.objects.iter().enumerate() {
            let bad = |message: &str| RenderError::Object {
                index,
                message: message.into(),
            };
            let image = match &o.material {
                Material::Texture { path, size, .. } => {
                    match o.shape {
                        Shape::Sphere { .. } => {
                            return Err(bad("texture maps onto planes and boxes, not spheres"));
                        }
                        Shape::Plane { .. } if size.is_none() => {
                            return Err(bad("texture on a plane needs size = [width, height]"));
                        }
                        _ => {}
                    }
                    let path = scene_dir.join(path);
                    Some(match read.iter().position(|p| *p == path) {
                        Some(i) => i,
                        None => {
                            let image =
                                load_image(&path).map_err(|message| RenderError::Image {
                                    what: "texture",
                                    path: path.clone(),
                                    message,
                                })?;
                            images.push(image);
                            read.push(path);
                            images.len() - 1
                        }
                    })
                }
                Material::Dots { .. } if matches!(o.shape, Shape::Sphere { .. }) => {
                    return Err(bad("dots map onto planes and boxes, not spheres"));
                }
                _ => None,
            };
            object_images.push(image);
        }
        for (index, light) in scene.lights.iter().enumerate() {
            let ok = match *light {
                Light::Point {
                    position,
                    intensity,
                } => finite3(position) && finite3(intensity),
                Light::Directional {
                    direction,
                    intensity,
                } => {
                    finite3(direction)
                        && finite3(intensity)
                        && DVec3::from_array(direction).length() > 0.0
                }
            };
            if !ok {
                return Err(RenderError::Light {
                    index,
                    message: "position/direction and intensity must be finite (direction non-zero)"
                        .into(),
                });
            }
        }
        Ok(RenderScene {
            camera,
            objects: scene
                .objects
                .iter()
                .map(|o| Primitive::from_shape(&o.shape))
                .collect(),
            materials: scene.objects.iter().map(|o| o.material.clone()).collect(),
            lights: scene.lights.clone(),
            sky: SkyModel::from_scene(&scene.sky, scene_dir, &camera)?,
            images,
            object_images,
            medium: field.map(|f| SceneMedium::new(f, s)).transpose()?,
            settings: s.clone(),
        })
    }

    /// Fix a background plate to `camera` (the scene file's), seen at this render's
    /// size: a viewer that renders through its own moving camera keeps the plate where
    /// the scene put it. Nothing changes for another sky or a degenerate camera.
    pub fn pin_plate_to(&mut self, camera: &grin_scene::Camera) {
        if let SkyModel::Plate { camera: c, .. } = &mut self.sky
            && let Some(pinned) =
                PinholeCamera::new(camera, self.settings.width, self.settings.height)
        {
            *c = pinned;
        }
    }

    /// The sub-pixel position of sample `sample`: the pixel centre for one sample per
    /// pixel, uniformly random otherwise.
    pub fn subpixel(&self, rng: &mut Rng) -> (f64, f64) {
        if self.settings.spp == 1 {
            (0.5, 0.5)
        } else {
            (f64::from(rng.next_f32()), f64::from(rng.next_f32()))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A plate pinned to the file's camera stays put when the render's camera turns: the
    /// file camera's centre ray still sees the plate's centre, the turned camera's
    /// centre ray sees another part of it.
    #[test]
    fn a_pinned_plate_stays_where_the_file_camera_sees_it() {
        let dir = std::env::temp_dir().join(format!("grin-plate-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("tmp");
        exr::prelude::write_rgb_file(dir.join("p.exr"), 8, 8, |x, y| (x as f32, y as f32, 0.0))
            .expect("exr");
        let text = "[camera]\nposition = [0.0, 0.0, 0.0]\nlook_at = [0.0, 0.0, 1.0]\n\
                    [sky]\nplate = { path = \"p.exr\" }\n[render]\nwidth = 8\nheight = 8\n";
        let file = grin_scene::parse_scene(text, &dir.join("s.toml")).expect("scene");
        let mut turned = file.clone();
        turned.camera.look_at = [0.3, 0.0, 1.0];
        let mut rs = RenderScene::new(&turned, &dir, None).expect("render scene");
        let centre = |rs: &RenderScene, d: DVec3| rs.sky.sky_radiance(d.normalize());
        // Unpinned, the plate follows the turned camera: its centre is the plate's centre.
        let mid = DVec3::new(3.5, 3.5, 0.0); // bilinear between texels 3 and 4
        assert!((centre(&rs, rs.camera.forward) - mid).length() < 1e-9);
        rs.pin_plate_to(&file.camera);
        assert!((centre(&rs, DVec3::Z) - mid).length() < 1e-9);
        assert!((centre(&rs, rs.camera.forward) - mid).length() > 0.5);
        std::fs::remove_dir_all(&dir).ok();
    }
}
