//! Packing a [`RenderScene`] into what the kernel reads (keep in sync with
//! shaders/shared/types.wgsl and gpu_data.rs): the frame parameters, the object and light
//! arrays (with copies of the objects a chord inside the medium can meet) and the
//! environment map's texels.

use bytemuck::Zeroable;
use glam::DVec3;
use grin_field::Bounds;
use grin_render::primitives::Primitive;
use grin_render::scene::RenderScene;
use grin_render::sky::SkyModel;
use grin_scene::{ExitMethod, IntegratorKind, Light, Material, StepSpec};

use crate::gpu_data::*;
use crate::{GpuContext, GpuError};

/// The frame parameters of `scene`: camera, image, integrator, step policy, flags and sky
/// and the medium's bounds (its field is placed by [`crate::field::upload_field`]).
pub(crate) fn frame_params(scene: &RenderScene) -> Result<FrameParams, GpuError> {
    let s = &scene.settings;
    let cam = &scene.camera;
    let mut params = FrameParams::zeroed();
    params.roundoff_one = 1.0;
    params.accuracy = s.accuracy() as f32;
    params.estimate_limit = s.estimate_limit() as f32;
    params.cam_origin = f3(cam.origin);
    params.tan_half_fov_y = cam.tan_half_fov_y as f32;
    params.cam_forward = f3(cam.forward);
    params.aspect = (f64::from(cam.width) / f64::from(cam.height)) as f32;
    params.cam_right = f3(cam.right);
    params.cam_up = f3(cam.up);
    params.lens_radius = cam.lens_radius as f32;
    if let Some([hw, hh]) = cam.ortho {
        params.ortho_half_width = hw as f32;
        params.ortho_half_height = hh as f32;
    }
    params.focus_distance = cam.focus_distance as f32;
    params.width = s.width;
    params.height = s.height;
    params.spp = s.spp;
    params.spp_total = s.spp;
    params.seed = s.seed as u32;
    params.max_depth = s.max_depth;
    params.object_count = u32::try_from(scene.objects.len())
        .map_err(|_| GpuError::Unsupported("more than 2^32 objects".into()))?;
    params.light_count = u32::try_from(scene.lights.len())
        .map_err(|_| GpuError::Unsupported("more than 2^32 lights".into()))?;
    params.ambient_n = scene.medium.as_ref().map_or(1.0, |m| m.ambient as f32);
    params.step_policy = match s.step {
        StepSpec::Fixed(ds) => {
            params.ds = ds as f32;
            STEP_FIXED
        }
        StepSpec::Heuristic {
            min,
            max,
            amplitude,
        } => {
            let amp = amplitude
                .or_else(|| scene.medium.as_ref().map(|m| m.field.max_grad_n()))
                .unwrap_or(0.0);
            params.ds = min as f32;
            params.ds_max = max as f32;
            params.amplitude = amp as f32;
            STEP_HEURISTIC
        }
        StepSpec::Adaptive { tolerance, initial } => {
            params.tolerance = tolerance as f32;
            params.ds_initial = initial.unwrap_or(0.0) as f32;
            STEP_ADAPTIVE
        }
        // Error control per unit path length.
        StepSpec::Auto(accuracy) => {
            params.tolerance = (grin_scene::AUTO_TOL_PER_RAD * accuracy) as f32;
            params.tolerance_per_length = 1;
            STEP_ADAPTIVE
        }
    };
    let mut flags = 0;
    if s.macro_cells {
        flags |= FLAG_MACRO_CELLS;
    }
    if s.jitter {
        flags |= FLAG_JITTER;
    }
    if s.bend_shadow_rays {
        flags |= FLAG_BEND_SHADOWS;
    }
    if s.exit == ExitMethod::Hermite {
        flags |= FLAG_EXIT_HERMITE;
    }
    if !scene.objects.is_empty() {
        flags |= FLAG_HAS_OBJECTS;
    }
    params.integrator = integrator_code(s.integrator());
    params.max_steps = s.max_steps;
    params.flags = flags;
    match &scene.sky {
        SkyModel::Gradient {
            horizon,
            zenith,
            ground,
        } => {
            params.sky_kind = SKY_KIND_GRADIENT;
            params.sky_horizon = f3(*horizon);
            params.sky_zenith = f3(*zenith);
            params.sky_ground = f3(*ground);
            params.env_intensity = 1.0;
        }
        SkyModel::Map(map) => {
            params.sky_kind = SKY_KIND_MAP;
            params.env_intensity = map.intensity as f32;
            params.env_width = map.width as u32;
            params.env_height = map.height as u32;
        }
        SkyModel::Plate {
            image,
            camera,
            intensity,
            mean,
        } => {
            params.sky_kind = SKY_KIND_PLATE;
            params.env_intensity = *intensity as f32;
            params.env_width = image.width as u32;
            params.env_height = image.height as u32;
            params.sky_horizon = f3(*mean);
            params.plate_forward = f3(camera.forward);
            params.plate_right = f3(camera.right);
            params.plate_up = f3(camera.up);
            params.plate_tan_half_fov_y = camera.tan_half_fov_y as f32;
            params.plate_aspect = (f64::from(camera.width) / f64::from(camera.height)) as f32;
        }
    }
    if let Some(m) = &scene.medium {
        params.flags |= FLAG_HAS_MEDIUM;
        match m.bounds {
            Bounds::Sphere { center, radius } => {
                params.bounds_kind = BOUNDS_KIND_SPHERE;
                params.bounds_center = f3(center);
                params.bounds_radius = radius as f32;
            }
            Bounds::Box { min, max } => {
                params.bounds_kind = BOUNDS_KIND_BOX;
                params.box_min = f3(min);
                params.box_max = f3(max);
            }
        }
    }

    Ok(params)
}

/// The object array (each object, then copies of those a chord inside the medium can
/// meet, listed in `params.medium_objects`) and the light array, each padded to one
/// Copy into `p` (fresh from [`frame_params`]) what the field's upload and the object
/// arrays filled into `uploaded`: the grid, the macro cells, the objects in the medium.
pub(crate) fn copy_uploaded(p: &mut FrameParams, uploaded: &FrameParams) {
    p.grid_origin = uploaded.grid_origin;
    p.grid_inv_spacing = uploaded.grid_inv_spacing;
    p.grid_dims = uploaded.grid_dims;
    p.macro_dims = uploaded.macro_dims;
    p.macro_cell_voxels = uploaded.macro_cell_voxels;
    p.macro_threshold = uploaded.macro_threshold;
    p.n_uncertainty = uploaded.n_uncertainty;
    p.field_scale = uploaded.field_scale;
    p.medium_objects_first = uploaded.medium_objects_first;
    p.medium_objects_count = uploaded.medium_objects_count;
}

/// element (storage arrays may not be empty).
pub(crate) fn scene_arrays(
    scene: &RenderScene,
    params: &mut FrameParams,
) -> (Vec<GpuObject>, Vec<GpuLight>) {
    let n_objects = params.object_count;
    let image_rows = atlas_rows(scene);
    let mut objects: Vec<GpuObject> = scene
        .objects
        .iter()
        .zip(&scene.materials)
        .zip(&scene.object_images)
        .zip(0u32..)
        .map(|(((p, m), image), i)| {
            let mut o = object(p, m, i);
            if let Some(k) = *image {
                o.image_row = image_rows[k];
                o.image_width = scene.images[k].width as u32;
                o.image_height = scene.images[k].height as u32;
            }
            o
        })
        .collect();
    // After them, copies of the objects a chord inside the medium can meet (those
    // reaching into the bounds' bounding ball, with a margin for f32 roundoff): the
    // marcher tests only these at each step, and none when there are none.
    if let Some(m) = &scene.medium {
        let (centre, radius) = bounding_ball(&m.bounds);
        let ball = radius * (1.0 + MEDIUM_BALL_MARGIN);
        let inside: Vec<GpuObject> = scene
            .objects
            .iter()
            .zip(&objects)
            .filter(|(p, _)| p.may_meet_ball(centre, ball))
            .map(|(_, o)| *o)
            .collect();
        if !inside.is_empty() {
            params.medium_objects_first = n_objects;
            params.medium_objects_count = inside.len() as u32;
            params.flags |= FLAG_MEDIUM_OBJECTS;
            objects.extend(inside);
        }
    }
    let lights: Vec<GpuLight> = scene.lights.iter().map(light).collect();
    // Storage arrays may not be empty: pad with one unused element.
    let objects = if objects.is_empty() {
        vec![GpuObject::zeroed()]
    } else {
        objects
    };
    let lights = if lights.is_empty() {
        vec![GpuLight::zeroed()]
    } else {
        lights
    };

    (objects, lights)
}

/// The sky's image (environment map or plate), if any, and the textures' images, in
/// atlas order, as (width, height, texels).
fn atlas_images(scene: &RenderScene) -> Vec<(usize, usize, &[[f32; 3]])> {
    let sky = match &scene.sky {
        SkyModel::Map(map) => Some((map.width, map.height, &map.texels[..])),
        SkyModel::Plate { image, .. } => Some((image.width, image.height, &image.texels[..])),
        SkyModel::Gradient { .. } => None,
    };
    sky.into_iter()
        .chain(
            scene
                .images
                .iter()
                .map(|i| (i.width, i.height, &i.texels[..])),
        )
        .collect()
}

/// The first atlas row of each of `scene.images`: the running sum of the heights of
/// [`atlas_images`], whose last `scene.images.len()` entries they are.
fn atlas_rows(scene: &RenderScene) -> Vec<u32> {
    let images = atlas_images(scene);
    let mut row = 0u32;
    let starts: Vec<u32> = images
        .iter()
        .map(|i| {
            let r = row;
            row += i.1 as u32;
            r
        })
        .collect();
    starts[images.len() - scene.images.len()..].to_vec()
}

/// The image atlas as rgba32float texels: the sky's image at the top left, the
/// textures stacked below it, left-aligned (a 1x1 placeholder when there are none),
/// checked against the device's 2D texture limit.
pub(crate) fn env_texels(
    ctx: &GpuContext,
    scene: &RenderScene,
) -> Result<(u32, u32, Vec<[f32; 4]>), GpuError> {
    let limit = ctx.limits().max_texture_dimension_2d as usize;
    let images = atlas_images(scene);
    if images.is_empty() {
        return Ok((1, 1, vec![[0.0; 4]]));
    }
    let width = images.iter().map(|i| i.0).max().unwrap_or(1);
    let height: usize = images.iter().map(|i| i.1).sum();
    if width > limit || height > limit {
        return Err(GpuError::TooLarge {
            what: format!(
                "the scene's images ({} stacked in one {width}x{height} atlas)",
                images.len()
            ),
            needed: format!("{} texels per axis", width.max(height)),
            limit: format!("{limit} (max_texture_dimension_2d)"),
            adapter: ctx.adapter_name(),
        });
    }
    let mut texels = vec![[0.0f32; 4]; width * height];
    let mut row = 0;
    for (w, h, image) in images {
        for (y, line) in image.chunks_exact(w).enumerate() {
            let start = (row + y) * width;
            for (dst, t) in texels[start..start + w].iter_mut().zip(line) {
                *dst = [t[0], t[1], t[2], 1.0];
            }
        }
        row += h;
    }
    Ok((width as u32, height as u32, texels))
}

/// The environment map's texture from [`env_texels`] (call inside an error scope).
pub(crate) fn env_texture(ctx: &GpuContext, env: &(u32, u32, Vec<[f32; 4]>)) -> wgpu::Texture {
    use wgpu::util::DeviceExt;
    ctx.device.create_texture_with_data(
        &ctx.queue,
        &wgpu::TextureDescriptor {
            label: Some("environment map"),
            size: wgpu::Extent3d {
                width: env.0,
                height: env.1,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::Rgba32Float,
            usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            view_formats: &[],
        },
        wgpu::util::TextureDataOrder::LayerMajor,
        bytemuck::cast_slice(&env.2),
    )
}

pub(crate) fn f3(v: DVec3) -> [f32; 3] {
    v.as_vec3().to_array()
}

fn a3(v: [f64; 3]) -> [f32; 3] {
    f3(DVec3::from_array(v))
}

fn integrator_code(k: IntegratorKind) -> u32 {
    match k {
        IntegratorKind::Euler => INTEGRATOR_EULER,
        IntegratorKind::SymplecticEuler => INTEGRATOR_SYMPLECTIC_EULER,
        IntegratorKind::Verlet => INTEGRATOR_VERLET,
        IntegratorKind::Sharma => INTEGRATOR_SHARMA,
        IntegratorKind::Rk4 => INTEGRATOR_RK4,
        IntegratorKind::Adaptive => INTEGRATOR_ADAPTIVE,
    }
}

/// Relative margin of the ball around the medium's bounds within which objects are
/// tested against the marcher's chords (f32 positions may stray ulps outside the bounds).
const MEDIUM_BALL_MARGIN: f64 = 1e-3;

/// Centre and radius of the smallest ball holding the bounds.
fn bounding_ball(bounds: &Bounds) -> (DVec3, f64) {
    match *bounds {
        Bounds::Sphere { center, radius } => (center, radius),
        Bounds::Box { min, max } => ((min + max) * 0.5, (max - min).length() * 0.5),
    }
}

fn object(prim: &Primitive, material: &Material, index: u32) -> GpuObject {
    let mut o = GpuObject::zeroed();
    o.scene_index = index;
    match *prim {
        Primitive::Sphere { center, radius } => {
            o.shape = SHAPE_SPHERE;
            o.a = f3(center);
            o.radius = radius as f32;
        }
        Primitive::Plane { point, normal } => {
            o.shape = SHAPE_PLANE;
            o.a = f3(point);
            o.b = f3(normal);
        }
        Primitive::Box { min, max } => {
            o.shape = SHAPE_BOX;
            o.a = f3(min);
            o.b = f3(max);
        }
    }
    match *material {
        Material::Diffuse { color } => {
            o.material = MATERIAL_DIFFUSE;
            o.color_a = a3(color);
        }
        Material::Checker {
            color_a,
            color_b,
            scale,
        } => {
            o.material = MATERIAL_CHECKER;
            o.color_a = a3(color_a);
            o.color_b = a3(color_b);
            o.param = scale as f32;
        }
        Material::Mirror { color } => {
            o.material = MATERIAL_MIRROR;
            o.color_a = a3(color);
        }
        Material::Metal { color } => {
            o.material = MATERIAL_METAL;
            o.color_a = a3(color);
        }
        Material::Glass { ior, color } => {
            o.material = MATERIAL_GLASS;
            o.color_a = a3(color);
            o.param = ior as f32;
        }
        // The image's place in the atlas is filled in by `scene_arrays`.
        Material::Texture {
            size,
            center,
            repeat,
            border,
            color,
            emissive,
            ..
        } => {
            o.material = MATERIAL_TEXTURE;
            o.color_a = a3(color);
            o.color_b = a3(border);
            o.size = size.map_or([1.0, 1.0], |s| s.map(|x| x as f32));
            o.surface_flags = surface_flags(emissive, repeat, center);
            o.center = center.map_or([0.0; 3], a3);
        }
        Material::Dots {
            diameter,
            density,
            seed,
            color,
            background,
            center,
            emissive,
        } => {
            o.material = MATERIAL_DOTS;
            o.param = diameter as f32;
            o.density = density as f32;
            o.seed = seed;
            o.color_a = a3(color);
            o.color_b = a3(background);
            o.surface_flags = surface_flags(emissive, false, center);
            o.center = center.map_or([0.0; 3], a3);
        }
    }
    o
}

fn surface_flags(emissive: bool, repeat: bool, center: Option<[f64; 3]>) -> u32 {
    let bit = |on: bool, b: u32| if on { b } else { 0 };
    bit(emissive, SURFACE_EMISSIVE)
        | bit(repeat, SURFACE_REPEAT)
        | bit(center.is_some(), SURFACE_HAS_CENTER)
}

fn light(l: &Light) -> GpuLight {
    let (position, kind, intensity) = match *l {
        Light::Point {
            position,
            intensity,
        } => (position, LIGHT_KIND_POINT, intensity),
        Light::Directional {
            direction,
            intensity,
        } => (direction, LIGHT_KIND_DIRECTIONAL, intensity),
    };
    GpuLight {
        position: a3(position),
        kind,
        intensity: a3(intensity),
        _pad0: 0.0,
    }
}
