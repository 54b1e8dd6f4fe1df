// Structs shared by the kernels. Keep in sync with crates/grin-gpu/src/gpu_data.rs.

// Every field named; a vec3 and the scalar after it share one 16-byte row.
struct FrameParams {
    cam_origin: vec3<f32>,
    tan_half_fov_y: f32,
    cam_forward: vec3<f32>,
    aspect: f32,                 // width / height
    cam_right: vec3<f32>,
    env_intensity: f32,          // environment map's intensity
    cam_up: vec3<f32>,
    ambient_n: f32,              // index outside the medium
    width: u32,
    height: u32,
    spp: u32,
    seed: u32,
    first_row: u32,              // first row of this dispatch
    row_count: u32,              // rows in this dispatch
    max_depth: u32,
    object_count: u32,
    integrator: u32,             // INTEGRATOR_* (also the INTEGRATOR override)
    step_policy: u32,            // STEP_* (also the STEP_POLICY override)
    max_steps: u32,
    flags: u32,                  // FLAG_* (also the FLAGS override)
    light_count: u32,
    bounds_kind: u32,            // BOUNDS_KIND_* (also the BOUNDS_BOX override)
    sky_kind: u32,               // SKY_KIND_* (also the SKY_MAP override)
    macro_cell_voxels: u32,      // voxels per macro cell along an axis
    ds: f32,                     // fixed: the step; heuristic: the shortest step
    ds_max: f32,                 // heuristic: the longest step
    amplitude: f32,              // heuristic: |grad n| at which the step is the shortest
    tolerance: f32,              // adaptive: per step; auto: per unit path length
    ds_initial: f32,             // adaptive: the first step (0: ADAPTIVE_INITIAL_DS_REL)
    tolerance_per_length: u32,   // 1 for `auto` (step::Tolerance::PerLength)
    medium_objects_first: u32,   // copies of the objects a chord in the medium can meet
    medium_objects_count: u32,
    bounds_center: vec3<f32>,    // sphere bounds
    bounds_radius: f32,
    box_min: vec3<f32>,          // box bounds
    macro_threshold: f32,        // max |grad n| of a homogeneous macro cell
    box_max: vec3<f32>,
    first_sample: u32,           // index of this dispatch's first sample (progressive frames)
    grid_origin: vec3<f32>,      // world position of grid node (0, 0, 0)
    spp_total: u32,              // samples of the accumulated image: sub-pixel positions unless 1
    grid_inv_spacing: vec3<f32>, // 1 / node spacing per axis
    ortho_half_width: f32,       // orthographic camera: half the view (0: perspective)
    grid_dims: vec3<u32>,        // node counts
    env_width: u32,              // the sky's image (map or plate) at the atlas' top left
    macro_dims: vec3<u32>,       // macro-cell counts
    env_height: u32,
    sky_horizon: vec3<f32>,
    lens_radius: f32,            // thin lens: aperture radius (0: a pinhole)
    sky_zenith: vec3<f32>,
    focus_distance: f32,         // thin lens: distance in focus along cam_forward
    sky_ground: vec3<f32>,
    n_uncertainty: f32,          // the baked field's max |n error| (IndexField::n_uncertainty)
    plate_forward: vec3<f32>,    // the background plate's camera (the scene's)
    plate_tan_half_fov_y: f32,
    plate_right: vec3<f32>,
    plate_aspect: f32,
    plate_up: vec3<f32>,
    ortho_half_height: f32,
    // Always 1: see two_sum (integrate.wgsl).
    roundoff_one: f32,
    // The exit-direction error asked for (rad) and the integration estimate's limit
    // (TraceSettings::accuracy, estimate_limit): a ray whose own estimate is above the
    // limit, or whose crossings' n uncertainty is above CROSSING_FACTOR x accuracy, ends
    // STATUS_DEGRADED.
    accuracy: f32,
    estimate_limit: f32,
    _pad3: f32,
    // A dense rgba16snorm field's scales (FLAG_FIELD_SNORM): delta_n and grad n, x 32767.
    field_scale: vec4<f32>,
}

struct GpuObject {
    a: vec3<f32>,                // sphere: centre; plane: point; box: min
    radius: f32,                 // sphere
    b: vec3<f32>,                // plane: unit normal; box: max
    density: f32,                // dots: fraction of the surface covered
    color_a: vec3<f32>,          // colour | checker a | texture tint | dot colour
    param: f32,                  // checker scale | glass ior | dot diameter
    color_b: vec3<f32>,          // checker b | texture border | dots' background
    seed: u32,                   // dots
    shape: u32,                  // SHAPE_*
    material: u32,               // MATERIAL_*
    scene_index: u32,            // the object's index in the scene (copies keep it)
    surface_flags: u32,          // SURFACE_*
    center: vec3<f32>,           // texture, dots: centre of the surface frame
    image_row: u32,              // texture: first row in the image atlas
    size: vec2<f32>,             // texture on a plane: world size
    image_width: u32,            // texture: size in texels
    image_height: u32,
}

struct GpuLight {
    position: vec3<f32>,         // point: position; directional: direction of travel
    kind: u32,                   // LIGHT_KIND_*
    intensity: vec3<f32>,
    _pad0: f32,
}

struct PixelOut {
    r: f32, g: f32, b: f32,
    deflection_deg: f32,
    exit_x: f32, exit_y: f32, exit_z: f32,
    opd: f32,
    steps: f32,
    evals: f32,
    status: f32,
    pos_x: f32, pos_y: f32, pos_z: f32,
    opd_plane: f32,
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
const FLAG_SPARSE: u32 = 512u;
const FLAG_FIELD_SNORM: u32 = 1024u;
const FLAG_GRADIENT_OF_N: u32 = 2048u;
const SHAPE_SPHERE: u32 = 0u;
const SHAPE_PLANE: u32 = 1u;
const SHAPE_BOX: u32 = 2u;
const MATERIAL_DIFFUSE: u32 = 0u;
const MATERIAL_CHECKER: u32 = 1u;
const MATERIAL_MIRROR: u32 = 2u;
const MATERIAL_METAL: u32 = 3u;
const MATERIAL_GLASS: u32 = 4u;
const MATERIAL_TEXTURE: u32 = 5u;
const MATERIAL_DOTS: u32 = 6u;
const SURFACE_EMISSIVE: u32 = 1u;
const SURFACE_REPEAT: u32 = 2u;
const SURFACE_HAS_CENTER: u32 = 4u;
const LIGHT_KIND_POINT: u32 = 0u;
const LIGHT_KIND_DIRECTIONAL: u32 = 1u;
const BOUNDS_KIND_SPHERE: u32 = 0u;
const BOUNDS_KIND_BOX: u32 = 1u;
const SKY_KIND_GRADIENT: u32 = 0u;
const SKY_KIND_MAP: u32 = 1u;
const SKY_KIND_PLATE: u32 = 2u;

const PI: f32 = 3.14159265358979;
const TAU: f32 = 6.28318530717959;
const INF: f32 = 3.0e38;

// Pipeline-overridable constants, set by crates/grin-gpu/src/render.rs from the scene.
// crates/grin-gpu/src/specialize.rs folds them in and cuts every `if` and `switch` they
// decide before the driver sees the kernel, so each pipeline holds only the integrator,
// policy, interpolation and features its scene uses (Mesa inlines every call before it
// removes dead branches: without the cut, lavapipe's compile takes 3-4x longer). For the
// cut to see them, test the flags inline, `(FLAGS & FLAG_X) != 0u`, not through a
// function. Their values also sit in FrameParams.
override INTEGRATOR: u32 = 3u;
override STEP_POLICY: u32 = 0u;
override FLAGS: u32 = 0u;
override BOUNDS_BOX: bool = false;
override SKY_MAP: bool = false;
override SKY_PLATE: bool = false;
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
