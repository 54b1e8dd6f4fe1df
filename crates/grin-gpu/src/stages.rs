//! The marcher's stages one at a time: runs a test-only entry point of
//! shaders/stages.wgsl (field sample, one integrator step, one controlled step, one step
//! with the tunnelling check and the exit search, a straight flight) on a batch of states, with the frame
//! parameters and field texture the renderer would use for the same scene. A test
//! instrument (tests/stages.rs holds each stage against its CPU twin): it compiles one
//! small pipeline per call.

use bytemuck::{Pod, Zeroable};
use grin_field::baked::BakedField;
use grin_render::scene::RenderScene;

use std::time::Instant;

use crate::field::{FieldTextures, upload_field};
use crate::gpu_data::{FrameParams, PASS_ALL};
use crate::pack::{env_texels, env_texture, frame_params, scene_arrays};
use crate::pipelines::{pipeline_constants, render_layout_entries};
use crate::render::{output_buffers, read_buffer};
use crate::{GpuContext, GpuError, specialize};

/// The stages of shaders/stages.wgsl.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stage {
    /// `sample_field` at `r`.
    Sample,
    /// `integrate_step` from (`r`, `t`) by `h`, D sampled at `r`.
    Integrate,
    /// `take_step`: the step policy's step from (`r`, `t`) (controller at `ds_adapt`).
    Take,
    /// `take_step`, then `excursion_step` or `exit_medium` when the step leaves.
    Leave,
    /// `homogeneous_span` from `r` along `t` (in `h`; -1 for none) and `may_fly` (`code`).
    Flight,
    /// The bounds' interval along (`r`, `t`) (`h`, `n`; `code` bit 0 when met), the signed
    /// distance of `r` (`ds_next`), and `refract` of `t` at the surface normal nearest `r`
    /// (`err_r`) from n1 = `h` into n2 = `ds_adapt` (`t`, reflectance in `err_t[0]`,
    /// `code` bit 1 when transmitted).
    Surface,
    /// `intersect_scene` along (`r`, `t`) beyond t_min = `h` (`h` = distance or -1,
    /// `err_r` = normal facing the ray, `code` = scene index + 1 or 0) and `sky_radiance`
    /// of `t`'s direction (`grad_n`).
    Scene,
    /// `march_medium` of a whole ray from `r` along `t` (no jitter): end point `r`,
    /// direction `t`, optical path `h`, length `n`, steps `ds_next`, transmittance
    /// `err_t[0]`, `code` = status | end kind << 8 ([`crate::march`] reads it).
    March,
}

impl Stage {
    fn entry_point(self) -> &'static str {
        match self {
            Stage::Sample => "stage_sample",
            Stage::Integrate => "stage_integrate",
            Stage::Take => "stage_take",
            Stage::Leave => "stage_leave",
            Stage::Flight => "stage_flight",
            Stage::Surface => "stage_surface",
            Stage::Scene => "stage_scene",
            Stage::March => "stage_march",
        }
    }
}

/// One input state. Keep in sync with `StageIn` in shaders/stages.wgsl.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, Pod, Zeroable)]
pub struct StageIn {
    pub r: [f32; 3],
    /// [`Stage::Integrate`]: the t-step.
    pub h: f32,
    pub t: [f32; 3],
    /// [`Stage::Take`], [`Stage::Leave`]: the controller's current error-controlled step
    /// (0: its first).
    pub ds_adapt: f32,
}

/// One result. Keep in sync with `StageOut` in shaders/stages.wgsl.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, Pod, Zeroable)]
pub struct StageOut {
    /// End state (sample: unused).
    pub r: [f32; 3],
    /// t-length of the step (sample: delta_n).
    pub h: f32,
    pub t: [f32; 3],
    /// Field evaluations, the start sample not counted.
    pub evals: u32,
    /// Sample: the field at `r`; integrate: the step's end sample when it made one.
    pub grad_n: [f32; 3],
    pub n: f32,
    /// Integrate: the adaptive pair's embedded error estimate (e_r, e_T).
    pub err_r: [f32; 3],
    /// Take, leave: the controller's step after this one.
    pub ds_next: f32,
    pub err_t: [f32; 3],
    /// Leave: 0 stayed inside, 1 the step ended outside, 2 it left and came back;
    /// flight: 1 where `may_fly`.
    pub code: u32,
}
const _: () = assert!(std::mem::size_of::<StageIn>() == 2 * 16);
const _: () = assert!(std::mem::size_of::<StageOut>() == 5 * 16);

/// Threads per workgroup of every stage entry point (`STAGE_WORKGROUP`).
const STAGE_WORKGROUP: u32 = 64;

/// Run `stage` on `input` with `scene`'s settings (integrator, step policy, exit method,
/// bounds) over `baked`, as [`crate::GpuRenderer`] would upload them.
pub fn run_stage(
    ctx: &GpuContext,
    scene: &RenderScene,
    baked: &BakedField,
    stage: Stage,
    input: &[StageIn],
) -> Result<Vec<StageOut>, GpuError> {
    if input.is_empty() {
        return Ok(Vec::new());
    }
    let kit = StageKit::new(ctx, scene, baked)?;
    let pipeline = kit.pipeline(stage, &kit.params)?;
    kit.dispatch(&pipeline, input).map(|(out, _)| out)
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
        baked: &BakedField,
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
            let storage = |binding, read_only| wgpu::BindGroupLayoutEntry {
                binding,
                visibility: wgpu::ShaderStages::COMPUTE,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Storage { read_only },
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            };
            let io_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("stage io"),
                entries: &[storage(0, true), storage(1, false)],
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
            StageKit {
                ctx,
                params: FrameParams::zeroed(),
                layout,
                frame_layout,
                io_layout,
                params_buffer,
                frame: None,
            }
        })?;
        kit.set_scene(scene, baked)?;
        Ok(kit)
    }

    /// Upload `scene`'s objects and sky and `baked`, and take the scene's parameters.
    pub(crate) fn set_scene(
        &mut self,
        scene: &RenderScene,
        baked: &BakedField,
    ) -> Result<(), GpuError> {
        let ctx = self.ctx;
        let mut params = frame_params(scene)?;
        let field = upload_field(ctx, baked, &mut params)?;
        let (objects, _lights) = scene_arrays(scene, &mut params);
        let env = env_texels(ctx, scene)?;
        let frame = ctx.scoped("uploading a scene for the marcher stages", || {
            use wgpu::util::DeviceExt;
            let device = &ctx.device;
            let field_view = field
                .field
                .create_view(&wgpu::TextureViewDescriptor::default());
            let macro_view = field
                .macro_cells
                .create_view(&wgpu::TextureViewDescriptor::default());
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
                entries: &[
                    wgpu::BindGroupEntry {
                        binding: 0,
                        resource: self.params_buffer.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 1,
                        resource: objects_buffer.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 3,
                        resource: wgpu::BindingResource::TextureView(&field_view),
                    },
                    wgpu::BindGroupEntry {
                        binding: 4,
                        resource: wgpu::BindingResource::TextureView(&macro_view),
                    },
                    wgpu::BindGroupEntry {
                        binding: 5,
                        resource: wgpu::BindingResource::TextureView(&env_view),
                    },
                ],
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

    /// The pipeline of `stage` specialised for `params`' constants (integrator, step
    /// policy, flags, bounds).
    pub(crate) fn pipeline(
        &self,
        stage: Stage,
        params: &FrameParams,
    ) -> Result<wgpu::ComputePipeline, GpuError> {
        let constants = pipeline_constants(params, PASS_ALL);
        let entry = stage.entry_point();
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
        Ok(pipeline)
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
    pub(crate) fn dispatch(
        &self,
        pipeline: &wgpu::ComputePipeline,
        input: &[StageIn],
    ) -> Result<(Vec<StageOut>, f64), GpuError> {
        if input.is_empty() {
            return Ok((Vec::new(), 0.0));
        }
        let ctx = self.ctx;
        let frame = self
            .frame
            .as_ref()
            .ok_or_else(|| GpuError::Unsupported("no scene uploaded for the stages".into()))?;
        let count = u32::try_from(input.len())
            .map_err(|_| GpuError::Unsupported("more than 2^32 stage inputs".into()))?;
        let out_bytes = (input.len() * std::mem::size_of::<StageOut>()) as u64;
        let (readback, encoder) = ctx.scoped("running a marcher stage", || {
            use wgpu::util::DeviceExt;
            let device = &ctx.device;
            let in_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("stage in"),
                contents: bytemuck::cast_slice(input),
                usage: wgpu::BufferUsages::STORAGE,
            });
            let (out_buffer, readback) = output_buffers(device, "stage out", out_bytes);
            let io_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("stage io"),
                layout: &self.io_layout,
                entries: &[
                    wgpu::BindGroupEntry {
                        binding: 0,
                        resource: in_buffer.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 1,
                        resource: out_buffer.as_entire_binding(),
                    },
                ],
            });
            let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("stage"),
            });
            {
                let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("stage"),
                    timestamp_writes: None,
                });
                pass.set_pipeline(pipeline);
                pass.set_bind_group(0, &frame.group, &[]);
                pass.set_bind_group(1, &io_group, &[]);
                pass.dispatch_workgroups(count.div_ceil(STAGE_WORKGROUP), 1, 1);
            }
            encoder.copy_buffer_to_buffer(&out_buffer, 0, &readback, 0, out_bytes);
            (readback, encoder)
        })?;
        // Buffer uploads queued above run before the kernel: finish them first.
        ctx.wait()?;
        let start = Instant::now();
        ctx.scoped("running a marcher stage", || {
            ctx.queue.submit([encoder.finish()]);
        })?;
        ctx.wait()?;
        let seconds = start.elapsed().as_secs_f64();
        Ok((read_buffer(ctx, &readback, out_bytes)?, seconds))
    }
}
