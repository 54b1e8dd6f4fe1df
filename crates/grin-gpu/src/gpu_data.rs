//! Structs the GPU reads and writes: `#[repr(C)]`, bytemuck, explicitly padded to WGSL's
//! 16-byte vec4 alignment, sizes pinned by compile-time assertions.
//! Keep in sync with shaders/shared/types.wgsl.

use bytemuck::{Pod, Zeroable};

/// Integrator codes (`FrameParams::march[0]`).
pub const INTEGRATOR_EULER: u32 = 0;
pub const INTEGRATOR_SYMPLECTIC_EULER: u32 = 1;
pub const INTEGRATOR_VERLET: u32 = 2;
pub const INTEGRATOR_SHARMA: u32 = 3;
pub const INTEGRATOR_RK4: u32 = 4;
pub const INTEGRATOR_ADAPTIVE: u32 = 5;

/// Step policy codes (`FrameParams::march[1]`).
pub const STEP_FIXED: u32 = 0;
pub const STEP_HEURISTIC: u32 = 1;
pub const STEP_ADAPTIVE: u32 = 2;

/// Flag bits (`FrameParams::march[3]`). FLAG_JITTER scales the camera ray's first
/// step in the medium by a per-pixel random fraction (the CPU renderer has no jitter:
/// GPU-vs-CPU comparisons turn it off).
pub const FLAG_HAS_MEDIUM: u32 = 1;
pub const FLAG_MACRO_CELLS: u32 = 2;
pub const FLAG_JITTER: u32 = 4;
pub const FLAG_BEND_SHADOWS: u32 = 8;
/// Beyond the grid's nodes the field is ambient (else clamped to the nearest node).
pub const FLAG_OUTSIDE_AMBIENT: u32 = 16;
/// Field sampled as a tricubic B-spline from prefiltered coefficients.
pub const FLAG_TRICUBIC: u32 = 32;
/// Exit found by the root of the Hermite dense output instead of bisection.
pub const FLAG_EXIT_HERMITE: u32 = 64;
/// Some object can meet a chord inside the medium (`FrameParams::medium_objects`); else
/// the marcher skips the per-step object test.
pub const FLAG_MEDIUM_OBJECTS: u32 = 128;
/// The scene has objects (else the kernel is compiled without its surface code).
pub const FLAG_HAS_OBJECTS: u32 = 256;

/// Passes of a frame (the `PASS` pipeline constant, shaders/shared/types.wgsl).
pub const PASS_ALL: u32 = 0;
pub const PASS_FIRST: u32 = 1;
pub const PASS_MEDIUM: u32 = 2;

/// Shape codes (`GpuObject::kinds[0]`).
pub const SHAPE_SPHERE: u32 = 0;
pub const SHAPE_PLANE: u32 = 1;
pub const SHAPE_BOX: u32 = 2;

/// Material codes (`GpuObject::kinds[1]`).
pub const MATERIAL_DIFFUSE: u32 = 0;
pub const MATERIAL_CHECKER: u32 = 1;
pub const MATERIAL_MIRROR: u32 = 2;
pub const MATERIAL_METAL: u32 = 3;
pub const MATERIAL_GLASS: u32 = 4;

/// Light codes (`GpuLight::position.w`).
pub const LIGHT_POINT: f32 = 0.0;
pub const LIGHT_DIRECTIONAL: f32 = 1.0;

/// Bounds codes (`FrameParams::bounds_box_min.w`).
pub const BOUNDS_SPHERE: f32 = 0.0;
pub const BOUNDS_BOX: f32 = 1.0;

/// Sky codes (`FrameParams::sky_horizon.w`).
pub const SKY_GRADIENT: f32 = 0.0;
pub const SKY_MAP: f32 = 1.0;

/// Everything uniform over one dispatch. Keep in sync with `FrameParams` in
/// shaders/shared/types.wgsl.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct FrameParams {
    /// Camera origin; w = tan(fov_y / 2).
    pub cam_origin: [f32; 4],
    /// Unit forward; w = aspect (width / height).
    pub cam_forward: [f32; 4],
    /// Unit right; w unused.
    pub cam_right: [f32; 4],
    /// Unit up; w unused.
    pub cam_up: [f32; 4],
    /// width, height, spp, seed.
    pub image: [u32; 4],
    /// First row of this dispatch, rows in it, max_depth, object count.
    pub rows: [u32; 4],
    /// integrator, step policy, max_steps, flags.
    pub march: [u32; 4],
    /// Fixed: (ds, -, -, -); heuristic: (min, max, amplitude, -); adaptive: (tolerance,
    /// initial or 0, -, -).
    pub step: [f32; 4],
    /// Sphere bounds: centre, radius.
    pub bounds_sphere: [f32; 4],
    /// Box bounds min; w = bounds kind.
    pub bounds_box_min: [f32; 4],
    /// Box bounds max; w = ambient index.
    pub bounds_box_max: [f32; 4],
    /// World position of grid node (0, 0, 0); w = macro-cell homogeneity threshold.
    pub grid_origin: [f32; 4],
    /// 1 / node spacing per axis; w unused.
    pub grid_inv_spacing: [f32; 4],
    /// Node counts; w = light count.
    pub grid_dims: [u32; 4],
    /// Macro-cell counts; w = voxels per macro cell.
    pub macro_dims: [u32; 4],
    /// Gradient sky horizon colour; w = sky kind.
    pub sky_horizon: [f32; 4],
    /// Gradient sky zenith colour; w = environment map intensity.
    pub sky_zenith: [f32; 4],
    /// Gradient sky ground colour; w unused.
    pub sky_ground: [f32; 4],
    /// The objects a chord inside the medium can meet, as copies in the objects array:
    /// first index, count; z, w unused.
    pub medium_objects: [u32; 4],
}
const _: () = assert!(std::mem::size_of::<FrameParams>() == 19 * 16);

/// One scene object. Keep in sync with `GpuObject` in shaders/shared/types.wgsl.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct GpuObject {
    /// Sphere: centre, radius; plane: point; box: min.
    pub a: [f32; 4],
    /// Plane: unit normal; box: max.
    pub b: [f32; 4],
    /// Diffuse/mirror/metal/glass colour, checker colour a; w = checker scale or glass ior.
    pub color_a: [f32; 4],
    /// Checker colour b.
    pub color_b: [f32; 4],
    /// shape kind, material kind, 0, 0.
    pub kinds: [u32; 4],
}
const _: () = assert!(std::mem::size_of::<GpuObject>() == 5 * 16);

/// One light. Keep in sync with `GpuLight` in shaders/shared/types.wgsl.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct GpuLight {
    /// Point: position; directional: direction of travel. w = light kind.
    pub position: [f32; 4],
    /// RGB intensity; w unused.
    pub intensity: [f32; 4],
}
const _: () = assert!(std::mem::size_of::<GpuLight>() == 2 * 16);

/// One output pixel: the same 12 floats as `grin_render::image::PixelOut`.
/// Keep in sync with `PixelOut` in shaders/shared/types.wgsl.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, Pod, Zeroable)]
pub struct PixelOut {
    pub rgb: [f32; 3],
    pub deflection_deg: f32,
    pub exit_dir: [f32; 3],
    pub opd: f32,
    pub steps: f32,
    pub evals: f32,
    pub status: f32,
    pub _pad: f32,
}
const _: () = assert!(std::mem::size_of::<PixelOut>() == 12 * 4);

impl PixelOut {
    /// The CPU renderer's pixel type.
    pub fn to_cpu(self) -> grin_render::image::PixelOut {
        grin_render::image::PixelOut {
            rgb: self.rgb,
            deflection_deg: self.deflection_deg,
            exit_dir: self.exit_dir,
            opd: self.opd,
            steps: self.steps,
            evals: self.evals,
            status: self.status,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shaders::RENDER_WGSL;

    /// The Rust structs and their WGSL twins have the same size (naga's layouter on the
    /// assembled render kernel): the "keep in sync" comments, checked.
    #[test]
    fn structs_match_their_wgsl_layouts() {
        let module = naga::front::wgsl::parse_str(RENDER_WGSL).expect("render.wgsl parses");
        let mut layouter = naga::proc::Layouter::default();
        layouter.update(module.to_ctx()).expect("layout");
        let size_of_wgsl = |name: &str| {
            let (handle, _) = module
                .types
                .iter()
                .find(|(_, t)| t.name.as_deref() == Some(name))
                .unwrap_or_else(|| panic!("{name} not in render.wgsl"));
            layouter[handle].size as usize
        };
        assert_eq!(
            size_of_wgsl("FrameParams"),
            std::mem::size_of::<FrameParams>()
        );
        assert_eq!(size_of_wgsl("GpuObject"), std::mem::size_of::<GpuObject>());
        assert_eq!(size_of_wgsl("GpuLight"), std::mem::size_of::<GpuLight>());
        assert_eq!(size_of_wgsl("PixelOut"), std::mem::size_of::<PixelOut>());
    }
}
