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
/// (the medium's bounds and field are placed by the caller).
pub(crate) fn frame_params(scene: &RenderScene) -> Result<FrameParams, GpuError> {
    let s = &scene.settings;
    let cam = &scene.camera;
    let mut params = FrameParams::zeroed();
    params.cam_origin = v4(cam.origin, cam.tan_half_fov_y as f32);
    params.cam_forward = v4(
        cam.forward,
        (f64::from(cam.width) / f64::from(cam.height)) as f32,
    );
    params.cam_right = v4(cam.right, 0.0);
    params.cam_up = v4(cam.up, 0.0);
    params.image = [s.width, s.height, s.spp, s.seed as u32];
    let n_objects = u32::try_from(scene.objects.len())
        .map_err(|_| GpuError::Unsupported("more than 2^32 objects".into()))?;
    let n_lights = u32::try_from(scene.lights.len())
        .map_err(|_| GpuError::Unsupported("more than 2^32 lights".into()))?;
    params.rows = [0, 0, s.max_depth, n_objects];
    params.grid_dims[3] = n_lights;
    let (step_code, step) = match s.step {
        StepSpec::Fixed(ds) => (STEP_FIXED, [ds as f32, 0.0, 0.0, 0.0]),
        StepSpec::Heuristic {
            min,
            max,
            amplitude,
        } => {
            let amp = amplitude
                .or_else(|| scene.medium.as_ref().map(|m| m.field.max_grad_n()))
                .unwrap_or(0.0);
            (STEP_HEURISTIC, [min as f32, max as f32, amp as f32, 0.0])
        }
        StepSpec::Adaptive { tolerance, initial } => (
            STEP_ADAPTIVE,
            [tolerance as f32, initial.unwrap_or(0.0) as f32, 0.0, 0.0],
        ),
        // Error control per unit path length (step.z = 1 selects it in step.wgsl).
        StepSpec::Auto(accuracy) => (
            STEP_ADAPTIVE,
            [
                (grin_scene::AUTO_TOL_PER_RAD * accuracy) as f32,
                0.0,
                1.0,
                0.0,
            ],
        ),
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
    params.march = [integrator_code(s.integrator), step_code, s.max_steps, flags];
    params.step = step;
    match &scene.sky {
        SkyModel::Gradient {
            horizon,
            zenith,
            ground,
        } => {
            params.sky_horizon = v4(*horizon, SKY_GRADIENT);
            params.sky_zenith = v4(*zenith, 1.0);
            params.sky_ground = v4(*ground, 0.0);
        }
        SkyModel::Map(map) => {
            params.sky_horizon = [0.0, 0.0, 0.0, SKY_MAP];
            params.sky_zenith = [0.0, 0.0, 0.0, map.intensity as f32];
        }
    }

    Ok(params)
}

/// The object array (each object, then copies of those a chord inside the medium can
/// meet, listed in `params.medium_objects`) and the light array, each padded to one
/// element (storage arrays may not be empty).
pub(crate) fn scene_arrays(
    scene: &RenderScene,
    params: &mut FrameParams,
) -> (Vec<GpuObject>, Vec<GpuLight>) {
    let n_objects = params.rows[3];
    let mut objects: Vec<GpuObject> = scene
        .objects
        .iter()
        .zip(&scene.materials)
        .zip(0u32..)
        .map(|((p, m), i)| object(p, m, i))
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
            params.medium_objects = [n_objects, inside.len() as u32, 0, 0];
            params.march[3] |= FLAG_MEDIUM_OBJECTS;
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

/// The environment map as rgba32float texels (a 1x1 placeholder for a gradient sky),
/// checked against the device's 2D texture limit.
pub(crate) fn env_texels(
    ctx: &GpuContext,
    scene: &RenderScene,
) -> Result<(u32, u32, Vec<[f32; 4]>), GpuError> {
    let limits = ctx.limits();
    let env = match &scene.sky {
        SkyModel::Map(map) => {
            let limit = limits.max_texture_dimension_2d;
            if map.width > limit as usize || map.height > limit as usize {
                return Err(GpuError::TooLarge {
                    what: format!("environment map {}x{}", map.width, map.height),
                    needed: format!("{} texels per axis", map.width.max(map.height)),
                    limit: format!("{limit} (max_texture_dimension_2d)"),
                    adapter: ctx.adapter_name(),
                });
            }
            let texels: Vec<[f32; 4]> =
                map.texels.iter().map(|t| [t[0], t[1], t[2], 1.0]).collect();
            (map.width as u32, map.height as u32, texels)
        }
        SkyModel::Gradient { .. } => (1, 1, vec![[0.0; 4]]),
    };

    Ok(env)
}

pub(crate) fn v4(v: DVec3, w: f32) -> [f32; 4] {
    let f = v.as_vec3();
    [f.x, f.y, f.z, w]
}

fn a4(v: [f64; 3], w: f32) -> [f32; 4] {
    v4(DVec3::from_array(v), w)
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
    let (a, b, shape) = match *prim {
        Primitive::Sphere { center, radius } => (v4(center, radius as f32), [0.0; 4], SHAPE_SPHERE),
        Primitive::Plane { point, normal } => (v4(point, 0.0), v4(normal, 0.0), SHAPE_PLANE),
        Primitive::Box { min, max } => (v4(min, 0.0), v4(max, 0.0), SHAPE_BOX),
    };
    let (color_a, color_b, mat) = match *material {
        Material::Diffuse { color } => (a4(color, 0.0), [0.0; 4], MATERIAL_DIFFUSE),
        Material::Checker {
            color_a,
            color_b,
            scale,
        } => (
            a4(color_a, scale as f32),
            a4(color_b, 0.0),
            MATERIAL_CHECKER,
        ),
        Material::Mirror { color } => (a4(color, 0.0), [0.0; 4], MATERIAL_MIRROR),
        Material::Metal { color } => (a4(color, 0.0), [0.0; 4], MATERIAL_METAL),
        Material::Glass { ior, color } => (a4(color, ior as f32), [0.0; 4], MATERIAL_GLASS),
    };
    GpuObject {
        a,
        b,
        color_a,
        color_b,
        kinds: [shape, mat, index, 0],
    }
}

fn light(l: &Light) -> GpuLight {
    match *l {
        Light::Point {
            position,
            intensity,
        } => GpuLight {
            position: a4(position, LIGHT_POINT),
            intensity: a4(intensity, 0.0),
        },
        Light::Directional {
            direction,
            intensity,
        } => GpuLight {
            position: a4(direction, LIGHT_DIRECTIONAL),
            intensity: a4(intensity, 0.0),
        },
    }
}
