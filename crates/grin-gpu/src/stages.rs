//! The marcher's stages one at a time: runs a test-only entry point of
//! shaders/stages.wgsl (field sample, one integrator step, one controlled step, one step
//! with the tunnelling check and the exit search, a straight flight, the medium's surface,
//! the scene outside it, a whole march) on a batch of inputs, each stage with an input
//! and a result struct of its own ([`Stage`]), with the frame parameters and field
//! texture the renderer would use for the same scene. A test instrument (tests/stages.rs
//! holds each stage against its CPU twin): it compiles one small pipeline per call.
//!
//! Over 600 lines: one concept, one runner and one I/O struct per stage, each beside the next.

use bytemuck::{Pod, Zeroable};
use grin_render::scene::RenderScene;

use std::marker::PhantomData;
use std::time::Instant;

use crate::field::{DeviceField, FieldTextures, upload};
use crate::gpu_data::{FrameParams, PASS_ALL};
use crate::pack::{env_texels, env_texture, frame_params, scene_arrays};
use crate::pipelines::{bind_entries, pipeline_constants, render_layout_entries};
use crate::render::{output_buffers, read_buffer};
use crate::{GpuContext, GpuError, specialize};

/// A stage of shaders/stages.wgsl: its entry point and the structs it reads and writes
/// (each mirrors the WGSL struct of the same name, member by member, as the test
/// `stage_structs_match_their_wgsl_twins` checks).
pub trait Stage {
    /// The entry point.
    const ENTRY_POINT: &'static str;
    /// One input.
    type In: Pod;
    /// One result.
    type Out: Pod;
}

macro_rules! stages {
    ($($(#[$doc:meta])* $name:ident: $entry:literal, $input:ty => $output:ty;)+) => {$(
        $(#[$doc])*
        #[derive(Debug)]
        pub enum $name {}
        impl Stage for $name {
            const ENTRY_POINT: &'static str = $entry;
            type In = $input;
            type Out = $output;
        }
    )+};
}

stages! {
    /// `sample_field` at a point.
    Sample: "stage_sample", SampleIn => SampleOut;
    /// `integrate_step` by a t-step, D sampled at the start.
    Integrate: "stage_integrate", IntegrateIn => IntegrateOut;
    /// `take_step`: the step policy's step.
    Take: "stage_take", TakeIn => TakeOut;
    /// `take_step`, then `excursion_step` or `exit_medium` when the step leaves.
    Leave: "stage_leave", TakeIn => LeaveOut;
    /// `homogeneous_span` along a ray, and `may_fly` at its origin.
    Flight: "stage_flight", RayIn => FlightOut;
    /// The bounds' interval along a ray, the signed distance of its origin, and
    /// `refract` at the surface normal nearest the origin.
    Surface: "stage_surface", SurfaceIn => SurfaceOut;
    /// `intersect_scene` along a ray, and `sky_radiance` of its direction.
    Scene: "stage_scene", SceneIn => SceneOut;
    /// `march_medium` of a whole ray (no jitter) ([`crate::march`] reads it).
    March: "stage_march", RayIn => MarchOut;
}

/// [`Sample`]'s input: a point.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, Pod, Zeroable)]
pub struct SampleIn {
    pub r: [f32; 3],
    _pad: f32,
}

impl SampleIn {
    pub fn new(r: [f32; 3]) -> Self {
        SampleIn { r, _pad: 0.0 }
    }
}

/// [`Sample`]'s result: the field at the point.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, Pod, Zeroable)]
pub struct SampleOut {
    pub grad_n: [f32; 3],
    pub n: f32,
    pub delta_n: f32,
    _pad: [f32; 3],
}

/// [`Integrate`]'s input: the state (`r`, `t`) and the t-step `h`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, Pod, Zeroable)]
pub struct IntegrateIn {
    pub r: [f32; 3],
    pub h: f32,
    pub t: [f32; 3],
    _pad: f32,
}

impl IntegrateIn {
    pub fn new(r: [f32; 3], t: [f32; 3], h: f32) -> Self {
        IntegrateIn { r, h, t, _pad: 0.0 }
    }
}

/// [`Integrate`]'s result.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, Pod, Zeroable)]
pub struct IntegrateOut {
    /// The end state.
    pub r: [f32; 3],
    /// Field evaluations, the start sample not counted.
    pub evals: u32,
    pub t: [f32; 3],
    /// The step's end sample where it made one (else zero).
    pub end_n: f32,
    pub end_grad_n: [f32; 3],
    _pad0: f32,
    /// The adaptive pair's embedded error estimate (e_r, e_T).
    pub err_r: [f32; 3],
    _pad1: f32,
    pub err_t: [f32; 3],
    _pad2: f32,
}

/// [`Take`]'s and [`Leave`]'s input: the state (`r`, `t`) and the controller's current
/// error-controlled step `ds_adapt` (0: its first).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, Pod, Zeroable)]
pub struct TakeIn {
    pub r: [f32; 3],
    pub ds_adapt: f32,
    pub t: [f32; 3],
    _pad: f32,
}

impl TakeIn {
    pub fn new(r: [f32; 3], t: [f32; 3], ds_adapt: f32) -> Self {
        TakeIn {
            r,
            ds_adapt,
            t,
            _pad: 0.0,
        }
    }
}

/// [`Take`]'s result.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, Pod, Zeroable)]
pub struct TakeOut {
    /// The end state.
    pub r: [f32; 3],
    /// The step's t-length.
    pub h: f32,
    pub t: [f32; 3],
    /// Field evaluations, the start sample not counted.
    pub evals: u32,
    /// The controller's step after this one.
    pub ds_next: f32,
    _pad: [f32; 3],
}

/// [`Leave`]'s result: as [`TakeOut`], with the state and t-length cut at the surface
/// where the step left.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, Pod, Zeroable)]
pub struct LeaveOut {
    pub r: [f32; 3],
    pub h: f32,
    pub t: [f32; 3],
    pub evals: u32,
    pub ds_next: f32,
    /// 0 stayed inside, 1 the step ended outside, 2 it left and came back.
    pub outcome: u32,
    _pad: [u32; 2],
}

/// [`Flight`]'s and [`March`]'s input: a ray from `r` along `t` (any length).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, Pod, Zeroable)]
pub struct RayIn {
    pub r: [f32; 3],
    _pad0: f32,
    pub t: [f32; 3],
    _pad1: f32,
}

impl RayIn {
    pub fn new(r: [f32; 3], t: [f32; 3]) -> Self {
        RayIn {
            r,
            _pad0: 0.0,
            t,
            _pad1: 0.0,
        }
    }
}

/// [`Flight`]'s result.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, Pod, Zeroable)]
pub struct FlightOut {
    /// The straight flight's length (-1: none).
    pub span: f32,
    /// 1 where `may_fly`, else 0.
    pub may_fly: u32,
}

/// [`Surface`]'s input: the ray (`r`, `t`), refracted at the surface from index `n1`
/// into `n2`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, Pod, Zeroable)]
pub struct SurfaceIn {
    pub r: [f32; 3],
    pub n1: f32,
    pub t: [f32; 3],
    pub n2: f32,
}

/// [`Surface`]'s result.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, Pod, Zeroable)]
pub struct SurfaceOut {
    /// The refracted (or totally reflected) direction.
    pub dir: [f32; 3],
    /// 1 where the refraction transmitted, else 0.
    pub transmitted: u32,
    /// The normal of the surface point nearest `r`, where it refracted.
    pub normal: [f32; 3],
    /// The Fresnel reflectance.
    pub reflectance: f32,
    /// The ray's interval through the bounds, where it met them.
    pub s_in: f32,
    pub s_out: f32,
    /// `r`'s signed distance from the surface.
    pub signed_distance: f32,
    /// 1 where the ray met the bounds, else 0.
    pub met: u32,
}

/// [`Scene`]'s input: the ray (`r`, `t`) and the least distance `t_min` an object may be
/// met at.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, Pod, Zeroable)]
pub struct SceneIn {
    pub r: [f32; 3],
    pub t_min: f32,
    pub t: [f32; 3],
    _pad: f32,
}

impl SceneIn {
    pub fn new(r: [f32; 3], t: [f32; 3], t_min: f32) -> Self {
        SceneIn {
            r,
            t_min,
            t,
            _pad: 0.0,
        }
    }
}

/// [`Scene`]'s result.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, Pod, Zeroable)]
pub struct SceneOut {
    /// The nearest object's normal, facing the ray.
    pub normal: [f32; 3],
    /// Its distance (-1: none).
    pub distance: f32,
    /// The sky's radiance in `t`'s direction.
    pub sky: [f32; 3],
    /// Its scene index + 1 (0: none).
    pub object: u32,
}

/// The control of [`March`]'s dispatches (WGSL `MarchControl`): the rays still
/// marching after a dispatch (the kernel counts them), the dispatch's number (0: the
/// rays start from their [`RayIn`]) and the steps each ray may take in it.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, Pod, Zeroable)]
pub struct MarchControl {
    pub pending: u32,
    pub round: u32,
    pub budget: u32,
}

/// Bytes of one ray's state between [`March`]'s dispatches (WGSL `MarchCarryStored`;
/// held to the WGSL struct's size by a test).
pub const MARCH_CARRY_BYTES: u64 = 288;

/// Steps (or straight flights) a ray takes in one dispatch of [`March`] by default:
/// lavapipe stops a shader invocation's loops after 65,535 iterations in all, ~3 a step
/// (9 with dopri) and up to ~50 where a step runs the exit and excursion searches
/// (docs/accuracy.md), so 1,024 steps stay under it; on a GPU a short dispatch keeps
/// the driver's watchdog away.
pub const MARCH_STEPS_PER_DISPATCH: u32 = 1024;

/// [`March`]'s result.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, Pod, Zeroable)]
pub struct MarchOut {
    /// The end point.
    pub point: [f32; 3],
    /// The optical path inside the medium.
    pub opl: f32,
    /// The unit direction at the end (after refraction out).
    pub dir: [f32; 3],
    /// The geometric length inside the medium.
    pub length: f32,
    pub evals: u32,
    pub steps: u32,
    /// The product of the Fresnel transmittances at the crossings.
    pub transmittance: f32,
    /// `STATUS_*` (shaders/shared/trace.wgsl).
    pub status: u32,
    /// How the march ended: `END_*` (shaders/shared/medium.wgsl).
    pub end: u32,
    _pad: [u32; 3],
}

/// Threads per workgroup of every stage entry point (`STAGE_WORKGROUP`).
const STAGE_WORKGROUP: u32 = 64;

/// Run stage `S` on `input` with `scene`'s settings (integrator, step policy, exit
/// method, bounds) over `field` (a dense or a sparse bake), as [`crate::GpuRenderer`]
/// would upload it.
pub fn run_stage<'f, S: Stage>(
    ctx: &GpuContext,
    scene: &RenderScene,
    field: impl Into<DeviceField<'f>>,
    input: &[S::In],
) -> Result<Vec<S::Out>, GpuError> {
    if input.is_empty() {
        return Ok(Vec::new());
    }
    let kit = StageKit::new(ctx, scene, field.into())?;
    let pipeline = kit.pipeline::<S>(&kit.params)?;
    kit.dispatch(&pipeline, input).map(|(out, _)| out)
}

/// The compute pipeline of stage `S`, for [`StageKit::dispatch`] of `S`'s structs.
pub(crate) struct StagePipeline<S> {
    pipeline: wgpu::ComputePipeline,
    stage: PhantomData<S>,
}

/// What every stage dispatch shares: the layouts, the frame parameters
/// (in a buffer rewritten per dispatch), and the current scene's field, objects and sky
/// on the device ([`StageKit::set_scene`] swaps them; pipelines stay valid).
pub(crate) struct StageKit<'a> {
    ctx: &'a GpuContext,
    /// The scene's parameters with the field's part filled in by its upload.
    pub(crate) params: FrameParams,
    layout: wgpu::PipelineLayout,
    frame_layout: wgpu::BindGroupLayout,
    io_layout: wgpu::BindGroupLayout,
    params_buffer: wgpu::Buffer,
    frame: Option<FrameBinding>,
    /// Bound at the io group's bindings 2 and 3 by the stages that do not use them
    /// (only [`March`] keeps state between dispatches).
    spare: wgpu::Buffer,
}

/// One scene's resources of group 0.
struct FrameBinding {
    group: wgpu::BindGroup,
    _field: FieldTextures,
    _env: wgpu::Texture,
    _objects: wgpu::Buffer,
}

impl<'a> StageKit<'a> {
    pub(crate) fn new(
        ctx: &'a GpuContext,
        scene: &RenderScene,
        field: DeviceField<'_>,
    ) -> Result<Self, GpuError> {
        let mut kit = ctx.scoped("preparing the marcher stages", || {
            let device = &ctx.device;
            // Group 0: the render kernel's params, objects, field texture, macro cells
            // and environment map, the only resources of it the stages read.
            let frame_entries: Vec<_> = render_layout_entries()
                .into_iter()
                .filter(|e| matches!(e.binding, 0 | 1 | 3 | 4 | 5))
                .collect();
            let frame_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("stage frame bindings"),
                entries: &frame_entries,
            });
            let storage = crate::pipelines::storage_entry;
            let io_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("stage io"),
                entries: &[
                    storage(0, true),
                    storage(1, false),
                    storage(2, false),
                    storage(3, false),
                ],
            });
            let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("stage"),
                bind_group_layouts: &[Some(&frame_layout), Some(&io_layout)],
                immediate_size: 0,
            });
            let params_buffer = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("stage params"),
                size: std::mem::size_of::<FrameParams>() as u64,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            let spare = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("stage spare"),
                size: 16,
                usage: wgpu::BufferUsages::STORAGE,
                mapped_at_creation: false,
            });
            StageKit {
                ctx,
                params: FrameParams::zeroed(),
                layout,
                frame_layout,
                io_layout,
                params_buffer,
                frame: None,
                spare,
            }
        })?;
        kit.set_scene(scene, field)?;
        Ok(kit)
    }

    /// Upload `scene`'s objects and sky and `field`, and take the scene's parameters.
    pub(crate) fn set_scene(
        &mut self,
        scene: &RenderScene,
        field: DeviceField<'_>,
    ) -> Result<(), GpuError> {
        let ctx = self.ctx;
        let mut params = frame_params(scene)?;
        let field = upload(ctx, field, &mut params)?;
        let (objects, _lights) = scene_arrays(scene, &mut params);
        let env = env_texels(ctx, scene)?;
        let frame = ctx.scoped("uploading a scene for the marcher stages", || {
            use wgpu::util::DeviceExt;
            let device = &ctx.device;
            let (field_view, macro_view) = field.views();
            let objects_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("stage objects"),
                contents: bytemuck::cast_slice(&objects),
                usage: wgpu::BufferUsages::STORAGE,
            });
            let env_tex = env_texture(ctx, &env);
            let env_view = env_tex.create_view(&wgpu::TextureViewDescriptor::default());
            let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("stage frame bindings"),
                layout: &self.frame_layout,
                entries: &bind_entries([
                    (0, self.params_buffer.as_entire_binding()),
                    (1, objects_buffer.as_entire_binding()),
                    (3, wgpu::BindingResource::TextureView(&field_view)),
                    (4, wgpu::BindingResource::TextureView(&macro_view)),
                    (5, wgpu::BindingResource::TextureView(&env_view)),
                ]),
            });
            FrameBinding {
                group,
                _field: field,
                _env: env_tex,
                _objects: objects_buffer,
            }
        })?;
        self.frame = Some(frame);
        self.set_params(params);
        Ok(())
    }

    /// The pipeline of stage `S` specialised for `params`' constants (integrator, step
    /// policy, flags, bounds).
    pub(crate) fn pipeline<S: Stage>(
        &self,
        params: &FrameParams,
    ) -> Result<StagePipeline<S>, GpuError> {
        let constants = pipeline_constants(params, PASS_ALL);
        let entry = S::ENTRY_POINT;
        // Each pipeline gets the stage kernel with its constants folded in
        // (crate::specialize), as the render pipelines do.
        let compiled = self.ctx.scoped("compiling a marcher stage", || {
            specialize::compute_pipeline(
                &self.ctx.device,
                self.ctx.pipeline_cache(),
                &self.layout,
                specialize::Kernel::Stages,
                entry,
                &constants,
            )
        })?;
        let pipeline = compiled.map_err(|message| GpuError::Wgpu {
            during: "specialising a marcher stage".into(),
            message,
        })?;
        self.ctx.persist_pipeline_cache();
        Ok(StagePipeline {
            pipeline,
            stage: PhantomData,
        })
    }

    /// Write `params` for the next dispatches (their constants must be the pipeline's).
    pub(crate) fn set_params(&mut self, params: FrameParams) {
        self.ctx
            .queue
            .write_buffer(&self.params_buffer, 0, bytemuck::bytes_of(&params));
        self.params = params;
    }

    /// Run `pipeline` on `input`: the outputs, and the seconds from the submission to
    /// the end of the kernel (buffer setup and readback not counted).
    pub(crate) fn dispatch<S: Stage>(
        &self,
        pipeline: &StagePipeline<S>,
        input: &[S::In],
    ) -> Result<(Vec<S::Out>, f64), GpuError> {
        self.dispatch_rounds(pipeline, input, None)
            .map(|(out, seconds, _)| (out, seconds))
    }

    /// Run [`March`] on `input` over as many dispatches as its rays need, each taking at
    /// most `budget` steps a ray (a ray's state kept on the device between them): the
    /// results, the seconds the dispatches took (from each submission to its end) and
    /// the number of dispatches.
    pub(crate) fn dispatch_march(
        &self,
        pipeline: &StagePipeline<March>,
        input: &[RayIn],
        budget: u32,
    ) -> Result<(Vec<MarchOut>, f64, u32), GpuError> {
        self.dispatch_rounds(pipeline, input, Some(budget.max(1)))
    }

    fn dispatch_rounds<S: Stage>(
        &self,
        pipeline: &StagePipeline<S>,
        input: &[S::In],
        march_budget: Option<u32>,
    ) -> Result<(Vec<S::Out>, f64, u32), GpuError> {
        if input.is_empty() {
            return Ok((Vec::new(), 0.0, 0));
        }
        let ctx = self.ctx;
        let frame = self
            .frame
            .as_ref()
            .ok_or_else(|| GpuError::Unsupported("no scene uploaded for the stages".into()))?;
        let count = u32::try_from(input.len())
            .map_err(|_| GpuError::Unsupported("more than 2^32 stage inputs".into()))?;
        let out_bytes = (input.len() * std::mem::size_of::<S::Out>()) as u64;
        let carry_bytes = match march_budget {
            Some(_) => input.len() as u64 * MARCH_CARRY_BYTES,
            None => 0,
        };
        let limit = ctx.limits().max_storage_buffer_binding_size;
        if carry_bytes > limit {
            return Err(GpuError::Unsupported(format!(
                "{} rays in one march need {carry_bytes} bytes of state, more than the adapter's max_storage_buffer_binding_size of {limit}",
                input.len()
            )));
        }
        let (in_buffer, out_buffer, readback, carry, control) =
            ctx.scoped("preparing a marcher stage", || {
                use wgpu::util::DeviceExt;
                let device = &ctx.device;
                let in_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("stage in"),
                    contents: bytemuck::cast_slice(input),
                    usage: wgpu::BufferUsages::STORAGE,
                });
                let (out_buffer, readback) = output_buffers(device, "stage out", out_bytes);
                let (carry, control) = match march_budget {
                    Some(_) => {
                        let carry = device.create_buffer(&wgpu::BufferDescriptor {
                            label: Some("march carry"),
                            size: carry_bytes,
                            usage: wgpu::BufferUsages::STORAGE,
                            mapped_at_creation: false,
                        });
                        let bytes = std::mem::size_of::<MarchControl>() as u64;
                        let (_, back) = output_buffers(device, "march control", bytes);
                        let control = device.create_buffer(&wgpu::BufferDescriptor {
                            label: Some("march control"),
                            size: bytes,
                            usage: wgpu::BufferUsages::STORAGE
                                | wgpu::BufferUsages::COPY_SRC
                                | wgpu::BufferUsages::COPY_DST,
                            mapped_at_creation: false,
                        });
                        (Some(carry), Some((control, back)))
                    }
                    None => (None, None),
                };
                (in_buffer, out_buffer, readback, carry, control)
            })?;
        let io_group = ctx.scoped("binding a marcher stage", || {
            let spare = self.spare.as_entire_binding();
            let carry = carry
                .as_ref()
                .map_or(spare.clone(), |b| b.as_entire_binding());
            let control = control
                .as_ref()
                .map_or(spare.clone(), |(b, _)| b.as_entire_binding());
            ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("stage io"),
                layout: &self.io_layout,
                entries: &bind_entries([
                    (0, in_buffer.as_entire_binding()),
                    (1, out_buffer.as_entire_binding()),
                    (2, carry),
                    (3, control),
                ]),
            })
        })?;
        // Buffer uploads queued above run before the kernel: finish them first.
        ctx.wait()?;
        let mut seconds = 0.0;
        let mut round = 0u32;
        loop {
            if let (Some((control, _)), Some(budget)) = (&control, march_budget) {
                let c = MarchControl {
                    pending: 0,
                    round,
                    budget,
                };
                // Queued writes land before the next submission.
                ctx.queue.write_buffer(control, 0, bytemuck::bytes_of(&c));
            }
            let start = Instant::now();
            ctx.scoped("running a marcher stage", || {
                let mut encoder =
                    ctx.device
                        .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                            label: Some("stage"),
                        });
                {
                    let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                        label: Some("stage"),
                        timestamp_writes: None,
                    });
                    pass.set_pipeline(&pipeline.pipeline);
                    pass.set_bind_group(0, &frame.group, &[]);
                    pass.set_bind_group(1, &io_group, &[]);
                    pass.dispatch_workgroups(count.div_ceil(STAGE_WORKGROUP), 1, 1);
                }
                if let Some((control, back)) = &control {
                    let bytes = std::mem::size_of::<MarchControl>() as u64;
                    encoder.copy_buffer_to_buffer(control, 0, back, 0, bytes);
                }
                ctx.queue.submit([encoder.finish()]);
            })?;
            ctx.wait()?;
            seconds += start.elapsed().as_secs_f64();
            round += 1;
            let Some((_, back)) = &control else { break };
            let c: Vec<MarchControl> =
                read_buffer(ctx, back, std::mem::size_of::<MarchControl>() as u64)?;
            if c[0].pending == 0 {
                break;
            }
            // Every ray still marching took its whole budget in that dispatch, and the
            // march ends at max_steps: more dispatches than that is a kernel fault.
            let most = self.params.max_steps / march_budget.unwrap_or(1) + 2;
            if round > most {
                return Err(GpuError::Wgpu {
                    during: "running the march".into(),
                    message: format!(
                        "{} rays still marching after {round} dispatches of {} steps (max_steps {})",
                        c[0].pending,
                        march_budget.unwrap_or(0),
                        self.params.max_steps
                    ),
                });
            }
        }
        ctx.scoped("reading a marcher stage back", || {
            let mut encoder = ctx
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("stage readback"),
                });
            encoder.copy_buffer_to_buffer(&out_buffer, 0, &readback, 0, out_bytes);
            ctx.queue.submit([encoder.finish()]);
        })?;
        Ok((read_buffer(ctx, &readback, out_bytes)?, seconds, round))
    }
}

#[cfg(test)]
mod tests;
