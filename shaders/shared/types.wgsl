// Structs shared by the kernels. Keep in sync with crates/grin-gpu/src/gpu_data.rs.

struct FrameParams {
    cam_origin: vec4<f32>,       // w = tan(fov_y / 2)
    cam_forward: vec4<f32>,      // w = aspect
    cam_right: vec4<f32>,
    cam_up: vec4<f32>,
    image: vec4<u32>,            // width, height, spp, seed
    rows: vec4<u32>,             // first row, row count, max_depth, object count
    march: vec4<u32>,            // integrator, step policy, max_steps, flags
    step: vec4<f32>,             // fixed ds | (min, max, amplitude) | adaptive initial
    bounds_sphere: vec4<f32>,    // centre, radius
    bounds_box_min: vec4<f32>,   // w = bounds kind
    bounds_box_max: vec4<f32>,   // w = ambient index
    grid_origin: vec4<f32>,      // w = macro-cell homogeneity threshold
    grid_inv_spacing: vec4<f32>,
    grid_dims: vec4<u32>,        // w = light count
    macro_dims: vec4<u32>,       // w = voxels per macro cell
    sky_horizon: vec4<f32>,      // w = sky kind
    sky_zenith: vec4<f32>,       // w = environment map intensity
    sky_ground: vec4<f32>,
    medium_objects: vec4<u32>,   // first, count (copies with kinds.z = scene index)
}

struct GpuObject {
    a: vec4<f32>,
    b: vec4<f32>,
    color_a: vec4<f32>,          // w = checker scale | glass ior
    color_b: vec4<f32>,
    kinds: vec4<u32>,            // shape, material, scene index
}

struct GpuLight {
    position: vec4<f32>,         // w = kind (0 point, 1 directional)
    intensity: vec4<f32>,
}

struct PixelOut {
    r: f32, g: f32, b: f32,
    deflection_deg: f32,
    exit_x: f32, exit_y: f32, exit_z: f32,
    opd: f32,
    steps: f32,
    evals: f32,
    status: f32,
    pad: f32,
}

// gpu_data.rs codes.
const INTEGRATOR_EULER: u32 = 0u;
const INTEGRATOR_SYMPLECTIC_EULER: u32 = 1u;
const INTEGRATOR_VERLET: u32 = 2u;
const INTEGRATOR_SHARMA: u32 = 3u;
const INTEGRATOR_RK4: u32 = 4u;
const INTEGRATOR_ADAPTIVE: u32 = 5u;
const STEP_FIXED: u32 = 0u;
const STEP_HEURISTIC: u32 = 1u;
const STEP_ADAPTIVE: u32 = 2u;
const FLAG_HAS_MEDIUM: u32 = 1u;
const FLAG_MACRO_CELLS: u32 = 2u;
const FLAG_JITTER: u32 = 4u;
const FLAG_BEND_SHADOWS: u32 = 8u;
const FLAG_OUTSIDE_AMBIENT: u32 = 16u;
const FLAG_TRICUBIC: u32 = 32u;
const FLAG_EXIT_HERMITE: u32 = 64u;
const FLAG_MEDIUM_OBJECTS: u32 = 128u;
const FLAG_HAS_OBJECTS: u32 = 256u;
const SHAPE_SPHERE: u32 = 0u;
const SHAPE_PLANE: u32 = 1u;
const SHAPE_BOX: u32 = 2u;
const MATERIAL_DIFFUSE: u32 = 0u;
const MATERIAL_CHECKER: u32 = 1u;
const MATERIAL_MIRROR: u32 = 2u;
const MATERIAL_METAL: u32 = 3u;
const MATERIAL_GLASS: u32 = 4u;

const PI: f32 = 3.14159265358979;
const TAU: f32 = 6.28318530717959;
const INF: f32 = 3.0e38;

// Pipeline-overridable constants, set by crates/grin-gpu/src/render.rs from the scene:
// the compiler drops every integrator, policy and feature the scene does not use, which
// keeps lavapipe's pipeline compile short (one shader with everything inlined takes
// ~20 s) and the kernel free of dead branches. Their values also sit in FrameParams.
override INTEGRATOR: u32 = 3u;
override STEP_POLICY: u32 = 0u;
override FLAGS: u32 = 0u;
override BOUNDS_BOX: bool = false;
override SKY_MAP: bool = false;
// Which pass of the frame this pipeline runs (render.rs): PASS_ALL, every pixel whole;
// PASS_FIRST, every pixel whose paths never touch the medium, the others listed for
// PASS_MEDIUM (render_deferred), which traces them whole. Splitting keeps the march out
// of the pass most pixels take (lavapipe runs a kernel's every branch under a mask) and
// packs the marching rays together.
override PASS: u32 = 0u;
const PASS_ALL: u32 = 0u;
const PASS_FIRST: u32 = 1u;
const PASS_MEDIUM: u32 = 2u;

// The pixels PASS_FIRST left to PASS_MEDIUM, and the indirect dispatch of that pass.
struct DeferredPixels {
    workgroups: atomic<u32>,
    y: u32,
    z: u32,
    count: atomic<u32>,
}
