//! Structs the GPU reads and writes: `#[repr(C)]`, bytemuck, explicitly padded to WGSL's
//! 16-byte vec4 alignment, sizes pinned by compile-time assertions.
//! Keep in sync with shaders/shared/types.wgsl.

use bytemuck::{Pod, Zeroable};

/// `aov.status` of a ray that ended `error` (the kernel's STATUS_ERROR, grin-trace's
/// `RayStatus::Error`; tests/constants.rs holds all three equal).
pub const STATUS_ERROR: u32 = 4;
/// Integrator codes (`FrameParams::integrator`).
pub const INTEGRATOR_EULER: u32 = 0;
pub const INTEGRATOR_SYMPLECTIC_EULER: u32 = 1;
pub const INTEGRATOR_VERLET: u32 = 2;
pub const INTEGRATOR_SHARMA: u32 = 3;
pub const INTEGRATOR_RK4: u32 = 4;
pub const INTEGRATOR_ADAPTIVE: u32 = 5;

/// Step policy codes (`FrameParams::step_policy`).
pub const STEP_FIXED: u32 = 0;
pub const STEP_HEURISTIC: u32 = 1;
pub const STEP_ADAPTIVE: u32 = 2;

/// Flag bits (`FrameParams::flags`). FLAG_JITTER scales the camera ray's first
/// step in the medium by a per-pixel random fraction (the CPU renderer's twin is
/// grin-trace's `trace_ray_jittered`).
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
/// Some object can meet a chord inside the medium (`FrameParams::medium_objects_first`, `medium_objects_count`); else
/// the marcher skips the per-step object test.
pub const FLAG_MEDIUM_OBJECTS: u32 = 128;
/// The scene has objects (else the kernel is compiled without its surface code).
pub const FLAG_HAS_OBJECTS: u32 = 256;
/// The field is a sparse bake: `field_tex` holds its voxels as one linear array,
/// `macro_tex` its brick table (crate::field::upload_sparse), the grid parameters place
/// its top grid.
pub const FLAG_SPARSE: u32 = 512;
/// The field's voxels are rgba16snorm (i16 / 32767): a dense grid's scaled by
/// `FrameParams::field_scale`, a sparse one's per brick by its table's second block.
pub const FLAG_FIELD_SNORM: u32 = 1024;
/// A sparse Catmull-Rom field whose gradient is the derivative of its interpolated
/// delta_n (`SparseField::gradient_of_n`: a bake on its source's own lattice).
pub const FLAG_GRADIENT_OF_N: u32 = 2048;
/// The flags a field's upload sets (crate::field): how the field is sampled.
pub const FIELD_FLAGS: u32 =
    FLAG_OUTSIDE_AMBIENT | FLAG_TRICUBIC | FLAG_SPARSE | FLAG_FIELD_SNORM | FLAG_GRADIENT_OF_N;

/// Passes of a frame (the `PASS` pipeline constant, shaders/shared/types.wgsl).
pub const PASS_ALL: u32 = 0;
pub const PASS_FIRST: u32 = 1;
pub const PASS_MEDIUM: u32 = 2;

/// Shape codes (`GpuObject::shape`).
pub const SHAPE_SPHERE: u32 = 0;
pub const SHAPE_PLANE: u32 = 1;
pub const SHAPE_BOX: u32 = 2;

/// Material codes (`GpuObject::material`).
pub const MATERIAL_DIFFUSE: u32 = 0;
pub const MATERIAL_CHECKER: u32 = 1;
pub const MATERIAL_MIRROR: u32 = 2;
pub const MATERIAL_METAL: u32 = 3;
pub const MATERIAL_GLASS: u32 = 4;
pub const MATERIAL_TEXTURE: u32 = 5;
pub const MATERIAL_DOTS: u32 = 6;

/// `GpuObject::surface_flags` bits.
pub const SURFACE_EMISSIVE: u32 = 1;
pub const SURFACE_REPEAT: u32 = 2;
pub const SURFACE_HAS_CENTER: u32 = 4;

/// Light codes (`GpuLight::kind`).
pub const LIGHT_KIND_POINT: u32 = 0;
pub const LIGHT_KIND_DIRECTIONAL: u32 = 1;

/// Bounds codes (`FrameParams::bounds_kind`; the kernel reads the `BOUNDS_BOX` override).
pub const BOUNDS_KIND_SPHERE: u32 = 0;
pub const BOUNDS_KIND_BOX: u32 = 1;

/// Sky codes (`FrameParams::sky_kind`; the kernel reads the `SKY_MAP` override).
pub const SKY_KIND_GRADIENT: u32 = 0;
pub const SKY_KIND_MAP: u32 = 1;
pub const SKY_KIND_PLATE: u32 = 2;

/// Everything uniform over one dispatch, every field named. Keep in sync with
/// `FrameParams` in shaders/shared/types.wgsl: a `[f32; 3]` and the 4-byte field after
/// it fill one 16-byte row, as a WGSL vec3 and the scalar after it do.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct FrameParams {
    pub cam_origin: [f32; 3],
    /// tan(fov_y / 2).
    pub tan_half_fov_y: f32,
    /// Unit forward.
    pub cam_forward: [f32; 3],
    /// width / height.
    pub aspect: f32,
    /// Unit right.
    pub cam_right: [f32; 3],
    /// The environment map's intensity.
    pub env_intensity: f32,
    /// Unit up.
    pub cam_up: [f32; 3],
    /// Index outside the medium.
    pub ambient_n: f32,
    pub width: u32,
    pub height: u32,
    pub spp: u32,
    pub seed: u32,
    /// First row of this dispatch.
    pub first_row: u32,
    /// Rows in this dispatch.
    pub row_count: u32,
    pub max_depth: u32,
    pub object_count: u32,
    /// `INTEGRATOR_*` (also the `INTEGRATOR` pipeline constant).
    pub integrator: u32,
    /// `STEP_*` (also `STEP_POLICY`).
    pub step_policy: u32,
    pub max_steps: u32,
    /// `FLAG_*` (also `FLAGS`).
    pub flags: u32,
    pub light_count: u32,
    /// `BOUNDS_KIND_*` (also `BOUNDS_BOX`).
    pub bounds_kind: u32,
    /// `SKY_KIND_*` (also `SKY_MAP`).
    pub sky_kind: u32,
    /// Voxels per macro cell along an axis.
    pub macro_cell_voxels: u32,
    /// Fixed: the step; heuristic: the shortest step.
    pub ds: f32,
    /// Heuristic: the longest step.
    pub ds_max: f32,
    /// Heuristic: |grad n| at which the step is the shortest.
    pub amplitude: f32,
    /// Adaptive: error per step; auto: error per unit path length.
    pub tolerance: f32,
    /// Adaptive: the first step (0: `ADAPTIVE_INITIAL_DS_REL` of the radius).
    pub ds_initial: f32,
    /// 1 for `auto` (`grin_trace::step::Tolerance::PerLength`), else 0.
    pub tolerance_per_length: u32,
    /// The objects a chord inside the medium can meet, as copies in the objects array:
    /// first index and count.
    pub medium_objects_first: u32,
    pub medium_objects_count: u32,
    /// Sphere bounds.
    pub bounds_center: [f32; 3],
    pub bounds_radius: f32,
    /// Box bounds.
    pub box_min: [f32; 3],
    /// Largest max |grad n| of a macro cell counted homogeneous.
    pub macro_threshold: f32,
    pub box_max: [f32; 3],
    /// Index of this dispatch's first sample of each pixel: frames rendered with
    /// `first_sample` 0, spp, 2 spp, ... and averaged are one render of `spp_total`
    /// samples (the viewer's progressive refinement).
    pub first_sample: u32,
    /// World position of grid node (0, 0, 0).
    pub grid_origin: [f32; 3],
    /// Samples of the whole accumulated image (>= spp): sub-pixel positions are drawn
    /// when it is not 1.
    pub spp_total: u32,
    /// 1 / node spacing per axis.
    pub grid_inv_spacing: [f32; 3],
    /// Orthographic camera: half the view's width and height (0: perspective).
    pub ortho_half_width: f32,
    /// Node counts.
    pub grid_dims: [u32; 3],
    /// The sky's image (map or plate) at the top left of the image atlas: its size.
    pub env_width: u32,
    /// Macro-cell counts.
    pub macro_dims: [u32; 3],
    pub env_height: u32,
    /// Gradient sky colours.
    pub sky_horizon: [f32; 3],
    /// Thin lens: aperture radius (0: a pinhole) and the distance in focus.
    pub lens_radius: f32,
    pub sky_zenith: [f32; 3],
    pub focus_distance: f32,
    pub sky_ground: [f32; 3],
    /// The baked field's max |n error| against its source (`IndexField::n_uncertainty`):
    /// refractions at the bounds add it, amplified at grazing angles, to the error
    /// estimate.
    pub n_uncertainty: f32,
    /// The background plate's camera (the scene's, fixed when a viewer moves its own):
    /// unit forward, right and up, tan(fov_y / 2) and width / height.
    pub plate_forward: [f32; 3],
    pub plate_tan_half_fov_y: f32,
    pub plate_right: [f32; 3],
    pub plate_aspect: f32,
    pub plate_up: [f32; 3],
    pub ortho_half_height: f32,
    /// Always 1 (`pack::frame_params` sets it): a 1 the shader compiler cannot
    /// see, by which `two_sum` multiplies so that its roundoff survives. Mesa's NIR
    /// (lavapipe) folds `(a + b) - a` to `b` in float operations not marked exact, and
    /// WGSL cannot mark them: the compensated summation of the ray state was compiled
    /// away, and GPU rays drifted from their CPU twin by ~3e-8 rad a step.
    pub roundoff_one: f32,
    /// The exit-direction error asked for (rad) and the integration estimate's limit
    /// (`TraceSettings::accuracy`, `estimate_limit`).
    pub accuracy: f32,
    pub estimate_limit: f32,
    pub _pad3: f32,
    /// A dense rgba16snorm field's scales (`FLAG_FIELD_SNORM`): delta_n and the gradient's
    /// components, times 32767. A sparse Catmull-Rom bake (`FLAG_SPARSE | FLAG_TRICUBIC`,
    /// its scales per brick) holds its nodes' delta_n range here instead (x, y), which its
    /// samples are clamped to.
    pub field_scale: [f32; 4],
}
const _: () = assert!(std::mem::size_of::<FrameParams>() == 25 * 16);

/// One scene object. Keep in sync with `GpuObject` in shaders/shared/types.wgsl.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct GpuObject {
    /// Sphere: centre; plane: point; box: min.
    pub a: [f32; 3],
    /// Sphere: radius.
    pub radius: f32,
    /// Plane: unit normal; box: max.
    pub b: [f32; 3],
    /// Dots: the fraction of the surface covered.
    pub density: f32,
    /// Diffuse/mirror/metal/glass colour, checker colour a, texture tint, dot colour.
    pub color_a: [f32; 3],
    /// Checker scale, glass ior or dot diameter.
    pub param: f32,
    /// Checker colour b, texture border, dots' background.
    pub color_b: [f32; 3],
    /// Dots: the seed.
    pub seed: u32,
    /// `SHAPE_*`.
    pub shape: u32,
    /// `MATERIAL_*`.
    pub material: u32,
    /// The object's index in the scene (its copies keep it).
    pub scene_index: u32,
    /// `SURFACE_*` bits.
    pub surface_flags: u32,
    /// Texture and dots: the centre of the surface frame (with `SURFACE_HAS_CENTER`).
    pub center: [f32; 3],
    /// Texture: its first row in the image atlas.
    pub image_row: u32,
    /// Texture on a plane: its world size.
    pub size: [f32; 2],
    /// Texture: its size in texels.
    pub image_width: u32,
    pub image_height: u32,
}
const _: () = assert!(std::mem::size_of::<GpuObject>() == 7 * 16);

/// One light. Keep in sync with `GpuLight` in shaders/shared/types.wgsl.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct GpuLight {
    /// Point: position; directional: direction of travel.
    pub position: [f32; 3],
    /// `LIGHT_KIND_*`.
    pub kind: u32,
    /// RGB intensity.
    pub intensity: [f32; 3],
    pub _pad0: f32,
}
const _: () = assert!(std::mem::size_of::<GpuLight>() == 2 * 16);

/// One output pixel: the 15 floats of `grin_render::image::PixelOut` and 1 of padding.
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
    pub exit_pos: [f32; 3],
    pub opd_plane: f32,
    pub _pad: f32,
}
const _: () = assert!(std::mem::size_of::<PixelOut>() == 16 * 4);

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
            exit_pos: self.exit_pos,
            opd_plane: self.opd_plane,
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::shaders::RENDER_WGSL;

    /// Size and byte offset of every member of the WGSL struct `name` (naga's layouter
    /// on the assembled kernel `source`).
    pub(crate) fn wgsl_offsets(source: &str, name: &str) -> (usize, Vec<(String, usize)>) {
        let module = naga::front::wgsl::parse_str(source).expect("the kernel parses");
        let mut layouter = naga::proc::Layouter::default();
        layouter.update(module.to_ctx()).expect("layout");
        let (handle, ty) = module
            .types
            .iter()
            .find(|(_, t)| t.name.as_deref() == Some(name))
            .unwrap_or_else(|| panic!("{name} not in the kernel"));
        let naga::TypeInner::Struct { members, .. } = &ty.inner else {
            panic!("{name} is not a struct");
        };
        let offsets = members
            .iter()
            .map(|m| (m.name.clone().unwrap_or_default(), m.offset as usize))
            .collect();
        (layouter[handle].size as usize, offsets)
    }

    /// The WGSL struct of the kernel `source` has exactly these members, in this order,
    /// at the Rust offsets, and the same size.
    macro_rules! same_layout {
        ($source:expr, $ty:ident, $($field:ident),+ $(,)?) => {{
            let (size, wgsl) = $crate::gpu_data::tests::wgsl_offsets($source, stringify!($ty));
            let rust: Vec<(String, usize)> = vec![
                $((stringify!($field).to_string(), std::mem::offset_of!($ty, $field))),+
            ];
            assert_eq!(wgsl, rust, "{} members: WGSL (left) vs Rust (right)", stringify!($ty));
            assert_eq!(size, std::mem::size_of::<$ty>(), "{} size", stringify!($ty));
        }};
    }
    pub(crate) use same_layout;

    /// The named fields of the Rust structs and their WGSL twins agree member by member:
    /// a field added, dropped, renamed or moved on one side only fails here.
    #[test]
    fn struct_members_match_their_wgsl_twins() {
        same_layout!(
            RENDER_WGSL,
            FrameParams,
            cam_origin,
            tan_half_fov_y,
            cam_forward,
            aspect,
            cam_right,
            env_intensity,
            cam_up,
            ambient_n,
            width,
            height,
            spp,
            seed,
            first_row,
            row_count,
            max_depth,
            object_count,
            integrator,
            step_policy,
            max_steps,
            flags,
            light_count,
            bounds_kind,
            sky_kind,
            macro_cell_voxels,
            ds,
            ds_max,
            amplitude,
            tolerance,
            ds_initial,
            tolerance_per_length,
            medium_objects_first,
            medium_objects_count,
            bounds_center,
            bounds_radius,
            box_min,
            macro_threshold,
            box_max,
            first_sample,
            grid_origin,
            spp_total,
            grid_inv_spacing,
            ortho_half_width,
            grid_dims,
            env_width,
            macro_dims,
            env_height,
            sky_horizon,
            lens_radius,
            sky_zenith,
            focus_distance,
            sky_ground,
            n_uncertainty,
            plate_forward,
            plate_tan_half_fov_y,
            plate_right,
            plate_aspect,
            plate_up,
            ortho_half_height,
            roundoff_one,
            accuracy,
            estimate_limit,
            _pad3,
            field_scale,
        );
        same_layout!(
            RENDER_WGSL,
            GpuObject,
            a,
            radius,
            b,
            density,
            color_a,
            param,
            color_b,
            seed,
            shape,
            material,
            scene_index,
            surface_flags,
            center,
            image_row,
            size,
            image_width,
            image_height,
        );
        same_layout!(RENDER_WGSL, GpuLight, position, kind, intensity, _pad0);
    }

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
        assert_eq!(
            size_of_wgsl("PixelCarryStored") as u64,
            crate::render::PIXEL_CARRY_BYTES
        );
        assert_eq!(size_of_wgsl("ResumeRound"), 16);
        let (_, offsets) = wgsl_offsets(RENDER_WGSL, "Resume");
        let offsets: Vec<usize> = offsets.into_iter().map(|(_, o)| o).collect();
        assert_eq!(offsets, [0, 16, 48], "Resume's header");
    }
}
