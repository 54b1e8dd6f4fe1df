//! A ray table on the GPU: the render kernel's own medium loop (`march_medium`, run by
//! the `stage_march` entry point of shaders/stages.wgsl) on given rays through a baked
//! field, with the tracer's settings. What `grin bench accuracy` measures the GPU with:
//! the same rays, methods and error measure as its CPU columns, in the GPU's arithmetic
//! and timed on the adapter.
//!
//! ```ignore
//! let ctx = GpuContext::new_headless()?;
//! let mut gpu = GpuRayTracer::new(&ctx, baked)?;    // Arc<BakedField> or Arc<SparseField>
//! let (rays_out, seconds) = gpu.trace(&settings, &rays, 1)?;  // Vec<GpuRay>
//! gpu.set_field(other_baked)?;                                 // pipelines are kept
//! ```
//!
//! One pipeline per set of the kernel's constants (integrator, step policy, exit method,
//! flags, bounds shape) is compiled on first use and kept across fields; step sizes and
//! tolerances are parameters.
//!
//! A ray's march is split over dispatches of at most
//! [`MARCH_STEPS_PER_DISPATCH`](crate::stages::MARCH_STEPS_PER_DISPATCH) steps each, its
//! state kept on the device between them: no invocation runs unbounded (lavapipe stops
//! one after 65,535 loop iterations; a desktop driver resets a GPU whose dispatch runs
//! too long), and the results are those of one whole march.

use std::collections::HashMap;

use glam::DVec3;
use grin_render::camera::PinholeCamera;
use grin_render::scene::{RenderScene, SceneMedium};
use grin_render::settings::TraceSettings;
use grin_render::sky::SkyModel;
use grin_scene::RenderSettings;

use crate::field::GpuGrid;
use crate::gpu_data::{FIELD_FLAGS, FLAG_MACRO_CELLS, FrameParams};
use crate::pack::{copy_uploaded, frame_params};
use crate::pipelines::pipeline_constants;
use crate::stages::{self, MarchOut, RayIn, StageKit, StagePipeline};
use crate::{GpuContext, GpuError};

/// Traces rays through one baked field (dense or sparse) on the GPU.
pub struct GpuRayTracer<'a> {
    kit: StageKit<'a>,
    field: GpuGrid,
    /// The parameters as the field's upload left them (grid, macro cells, flags).
    uploaded: FrameParams,
    pipelines: HashMap<Vec<u64>, StagePipeline<stages::March>>,
    steps_per_dispatch: u32,
    last_dispatches: u32,
}

impl std::fmt::Debug for GpuRayTracer<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpuRayTracer")
            .field("field", &self.field.field().describe())
            .field("pipelines", &self.pipelines.len())
            .field("steps_per_dispatch", &self.steps_per_dispatch)
            .finish_non_exhaustive()
    }
}

/// A scene of nothing but `field`, marched with `trace` (no jitter).
fn ray_scene(field: &GpuGrid, trace: &TraceSettings) -> Result<RenderScene, GpuError> {
    let settings = RenderSettings {
        width: 1,
        height: 1,
        integrator: Some(trace.integrator),
        step: trace.step,
        max_steps: trace.max_steps,
        exit: trace.exit,
        macro_cells: trace.macro_cells,
        jitter: false,
        pilot_rays: 0,
        resolved_accuracy: Some(trace.accuracy),
        resolved_estimate_limit: Some(trace.estimate_limit),
        ..RenderSettings::default()
    };
    let medium = SceneMedium::new(field.field(), &settings)
        .map_err(|e| GpuError::Unsupported(format!("tracer settings: {e}")))?;
    let camera = PinholeCamera {
        origin: DVec3::ZERO,
        forward: DVec3::Z,
        right: DVec3::X,
        up: DVec3::Y,
        tan_half_fov_y: 1.0,
        width: 1,
        height: 1,
        lens_radius: 0.0,
        focus_distance: 1.0,
        ortho: None,
    };
    Ok(RenderScene {
        camera,
        objects: Vec::new(),
        materials: Vec::new(),
        lights: Vec::new(),
        sky: SkyModel::Gradient {
            horizon: DVec3::ONE,
            zenith: DVec3::ONE,
            ground: DVec3::ONE,
        },
        medium: Some(medium),
        settings,
        images: Vec::new(),
        object_images: Vec::new(),
    })
}

impl<'a> GpuRayTracer<'a> {
    /// Upload `field` (its own interpolation and storage, as a render would).
    pub fn new(ctx: &'a GpuContext, field: impl Into<GpuGrid>) -> Result<Self, GpuError> {
        let field = field.into();
        let scene = ray_scene(
            &field,
            &TraceSettings::from_render(&RenderSettings::default()),
        )?;
        let kit = StageKit::new(ctx, &scene, field.device())?;
        let uploaded = kit.params;
        Ok(GpuRayTracer {
            kit,
            field,
            uploaded,
            pipelines: HashMap::new(),
            steps_per_dispatch: stages::MARCH_STEPS_PER_DISPATCH,
            last_dispatches: 0,
        })
    }

    /// Trace through `field` from now on (uploaded unless it is the current one); the
    /// compiled pipelines are kept.
    pub fn set_field(&mut self, field: impl Into<GpuGrid>) -> Result<(), GpuError> {
        let field = field.into();
        if field.same(&self.field) {
            return Ok(());
        }
        let scene = ray_scene(
            &field,
            &TraceSettings::from_render(&RenderSettings::default()),
        )?;
        self.kit.set_scene(&scene, field.device())?;
        self.uploaded = self.kit.params;
        self.field = field;
        Ok(())
    }

    /// Steps (or straight flights) a ray takes in one dispatch (at least 1); the results
    /// do not depend on it.
    pub fn set_steps_per_dispatch(&mut self, steps: u32) {
        self.steps_per_dispatch = steps.max(1);
    }

    /// Dispatches the last [`Self::trace`] took (1 where no ray needed more than
    /// [`Self::set_steps_per_dispatch`]'s steps).
    pub fn last_dispatches(&self) -> u32 {
        self.last_dispatches
    }

    /// Pipelines compiled so far (one per integrator, step policy and exit used).
    pub fn pipelines_compiled(&self) -> usize {
        self.pipelines.len()
    }

    /// Trace `rays` (origin, direction; origins outside the bounds enter with
    /// refraction) with `settings`, each ray `copies` times in one batch (to time a
    /// batch big enough for the adapter; results are the first copy's). Returns the
    /// results, in the order of `rays`, and the seconds the kernel's dispatches took.
    pub fn trace(
        &mut self,
        settings: &TraceSettings,
        rays: &[(DVec3, DVec3)],
        copies: usize,
    ) -> Result<(Vec<GpuRay>, f64), GpuError> {
        let mut params = frame_params(&ray_scene(&self.field, settings)?)?;
        copy_uploaded(&mut params, &self.uploaded);
        params.flags |= self.uploaded.flags & FIELD_FLAGS;
        if self.uploaded.flags & FLAG_MACRO_CELLS == 0 {
            params.flags &= !FLAG_MACRO_CELLS;
        }
        let key: Vec<u64> = pipeline_constants(&params, crate::gpu_data::PASS_ALL)
            .iter()
            .map(|(_, v)| v.to_bits())
            .collect();
        if !self.pipelines.contains_key(&key) {
            let pipeline = self.kit.pipeline::<stages::March>(&params)?;
            self.pipelines.insert(key.clone(), pipeline);
        }
        self.kit.set_params(params);
        let input: Vec<RayIn> = (0..copies.max(1))
            .flat_map(|_| rays.iter())
            .map(|&(o, d)| RayIn::new(o.as_vec3().to_array(), d.as_vec3().to_array()))
            .collect();
        let pipeline = self
            .pipelines
            .get(&key)
            .ok_or_else(|| GpuError::Unsupported("pipeline cache lost an entry".into()))?;
        let (out, seconds, dispatches) =
            self.kit
                .dispatch_march(pipeline, &input, self.steps_per_dispatch)?;
        self.last_dispatches = dispatches;
        Ok((
            out.iter().take(rays.len()).map(GpuRay::from).collect(),
            seconds,
        ))
    }
}

/// One traced ray, as the CPU tracer's `grin_trace::RayResult` reports it (f32 values).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GpuRay {
    /// `grin_trace::RayStatus`'s code: 0 missed, 1 exited, 2 absorbed, 3 max_steps,
    /// 4 error, 5 degraded (`STATUS_*` in shaders/shared/trace.wgsl).
    pub status: u32,
    /// Where the ray left the medium (or stopped).
    pub position: DVec3,
    /// Unit direction there (after refraction out).
    pub direction: DVec3,
    /// Optical path length inside the medium.
    pub opl: f64,
    /// Geometric length inside the medium.
    pub length: f64,
    /// Steps (straight flights included).
    pub steps: u32,
    /// Field evaluations.
    pub evals: u32,
    /// Product of the Fresnel transmittances at the crossings.
    pub transmittance: f64,
}

impl From<&MarchOut> for GpuRay {
    fn from(o: &MarchOut) -> Self {
        let v = |a: [f32; 3]| glam::Vec3::from_array(a).as_dvec3();
        GpuRay {
            status: o.status,
            position: v(o.point),
            direction: v(o.dir),
            opl: f64::from(o.opl),
            length: f64::from(o.length),
            steps: o.steps,
            evals: o.evals,
            transmittance: f64::from(o.transmittance),
        }
    }
}
