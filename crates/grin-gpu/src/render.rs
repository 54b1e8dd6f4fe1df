//! [`GpuRenderer`]: a [`RenderScene`] on the GPU. Uploads the scene and the baked field,
//! dispatches the render kernel in bands of rows (progress and cancellation between
//! bands), and reads the pixels back into the CPU renderer's [`Frame`] (or adds them to the
//! viewer's image on the device, [`crate::view`]).
//!
//! Over 800 lines: one concept, the renderer's buffers and the bands dispatched on them.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use grin_field::baked::BakedField;
use grin_render::image::Frame;
use grin_render::scene::RenderScene;

use crate::channels::{Channels, FrameTotals, Packer, TOTALS_BYTES};
use crate::field::{
    DEFAULT_GPU_BAKE_RESOLUTION, DeviceField, FieldTextures, empty_field, fits_device, upload_field,
};
use crate::gpu_data::*;
use crate::pack::{copy_uploaded, env_texels, env_texture, frame_params, scene_arrays};
use crate::pipelines::{bind_entries, pipeline_constants, render_layout_entries};
use crate::view::{ViewImage, ViewStats};
use crate::{GpuContext, GpuError, specialize};

/// Images of at most this many pixels get buffers with room to grow (a viewer's moving
/// image): 64 Ki pixels, 4 MiB of pixels.
const SMALL_IMAGE_PIXELS: u64 = 64 * 1024;
/// Pixels per dispatch on a CPU adapter (lavapipe): big enough to keep every core busy,
/// small enough that progress updates and cancellation stay responsive (~0.1-1 s a band).
const PIXELS_PER_BAND_CPU: u32 = 32 * 1024;
/// Pixels per dispatch on a GPU. On an H200 (`GRIN_BAND_PIXELS=N grin bench speed
/// --gpu-only --size 1920x1080`), paper (a)'s frame took 7.0 ms on the device in bands of
/// 32 Ki pixels (64 round trips, each band an eighth of the chip's resident threads),
/// 2.0 ms at 256 Ki, 1.7 at 512 Ki and 1.2 at 2 Mi (the frame in one band); the wall
/// clock (62-65 ms) was the read-back of 64 bytes a pixel at every size but 32 Ki (86).
/// 2 Mi pixels is 128 MiB of pixel buffer, wgpu's default binding limit.
const PIXELS_PER_BAND_GPU: u32 = 2 * 1024 * 1024;

/// Pixels per band on `ctx`'s adapter at `spp` samples a pixel, within its buffer limits.
/// A GPU band shrinks with the samples (2 Mi / spp pixels, at least the CPU's band), so
/// no dispatch runs much longer than a one-sample frame's (a display GPU's watchdog).
/// `GRIN_BAND_PIXELS` (a positive integer) overrides the adapter's default, for tuning.
fn pixels_per_band(ctx: &GpuContext, spp: u32) -> u32 {
    let default = if ctx.info.device_type == wgpu::DeviceType::Cpu {
        PIXELS_PER_BAND_CPU
    } else {
        (PIXELS_PER_BAND_GPU / spp.max(1)).max(PIXELS_PER_BAND_CPU)
    };
    let wanted = band_override().ok().flatten().unwrap_or(default);
    let limits = ctx.limits();
    let fits = limits
        .max_storage_buffer_binding_size
        .min(limits.max_buffer_size)
        / std::mem::size_of::<PixelOut>() as u64;
    wanted.min(u32::try_from(fits).unwrap_or(u32::MAX)).max(1)
}

/// `GRIN_BAND_PIXELS` as a positive integer: `Ok(None)` when unset, `Err` with the text
/// when it is something else (the default band is used then, with a warning).
fn band_override() -> Result<Option<u32>, String> {
    match std::env::var("GRIN_BAND_PIXELS") {
        Err(_) => Ok(None),
        Ok(v) => match v.trim().parse::<u32>() {
            Ok(n) if n > 0 => Ok(Some(n)),
            _ => Err(v),
        },
    }
}

/// Workgroup size of `render_main` and `bench_main` (keep in sync with the shaders).
pub(crate) const WORKGROUP: u32 = 8;

/// Steps (or straight flights) a pixel's marches take in one round of PASS_MEDIUM (the
/// ray table's dispatch, for the same reasons: lavapipe's loop limit, a GPU's watchdog).
pub const RENDER_STEPS_PER_ROUND: u32 = crate::stages::MARCH_STEPS_PER_DISPATCH;
/// Rounds encoded in one submission when the pixels are read back: after each such
/// batch the count of pixels still marching (16 bytes) is read, and more rounds follow
/// while there are any.
const ROUNDS_PER_SUBMISSION: u32 = 8;
/// Rounds of a viewer's band (nothing is read back there): the pixels still marching
/// after them run on whole in one last round, as an unsplit march (lavapipe's warning
/// about its loop limit still counts any that it cut short).
const VIEW_ROUNDS: u32 = 16;
/// Bytes of one pixel's state between rounds (WGSL `PixelCarryStored`; held to the WGSL
/// struct's size by a test).
pub(crate) const PIXEL_CARRY_BYTES: u64 = 560;
/// Bytes of `Resume`'s header: the round (ResumeRound) and the two halves' counts.
const RESUME_HEADER_BYTES: u64 = 48;
/// Bytes of the resume buffer at most (both halves). A half holds a band's pixels within
/// it: all of a CPU adapter's 32 Ki-pixel band (35 MiB), 239,674 of a GPU's bigger bands
/// (a 1080p frame at one sample is one band of 2 Mi pixels). In a band where more pixels
/// than that need a second round, the ones that find no place run on whole.
const RESUME_BYTES_MAX: u64 = 256 << 20;

/// A round of PASS_MEDIUM (WGSL `ResumeRound`).
#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct ResumeRound {
    resuming: u32,
    read_half: u32,
    budget: u32,
    capacity: u32,
}

/// The rounds after the first, as copied into the resume buffer's header before each:
/// `[read_half * 2 + last]`, the last round's budget unbounded; then a half's empty
/// count ([`EMPTY_COUNT`]), copied over the count a round is to write. A half holds at
/// most `capacity` pixels.
fn resume_rounds(steps: u32, capacity: u32) -> [ResumeRound; 5] {
    std::array::from_fn(|i| match i {
        4 => bytemuck::cast(EMPTY_COUNT),
        _ => ResumeRound {
            resuming: 1,
            read_half: (i / 2) as u32,
            budget: if i % 2 == 1 { u32::MAX } else { steps },
            capacity,
        },
    })
}

/// A half's count with no pixels: an indirect dispatch of 0 x 1 x 1 workgroups, 0 pixels
/// (WGSL `ResumeCount`).
const EMPTY_COUNT: [u32; 4] = [0, 1, 1, 0];

/// Timing of the last [`GpuRenderer::render`].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RenderTiming {
    /// Wall-clock seconds of the whole frame: uploads, dispatches, waits, read-back.
    pub seconds: f64,
    /// Seconds the device spent in the render passes (timestamps), where it has them.
    pub device_seconds: Option<f64>,
}

/// Timestamps at the start and end of each of a band's two passes (first / whole frame,
/// medium), resolved and read back after the band: the device's own time per frame.
#[derive(Debug)]
pub(crate) struct PassTimer {
    queries: wgpu::QuerySet,
    resolved: wgpu::Buffer,
    readback: wgpu::Buffer,
    /// Nanoseconds per timestamp tick.
    period_ns: f64,
    /// Device seconds summed over the bands of the last frame (f64 bits).
    last: std::sync::atomic::AtomicU64,
}

/// Timestamps a band writes: begin/end of the first pass, begin/end of the medium pass.
const TIMESTAMPS: u32 = 4;

impl PassTimer {
    fn new(ctx: &GpuContext) -> Option<Self> {
        if !ctx.has_timestamps() {
            return None;
        }
        let bytes = u64::from(TIMESTAMPS) * 8;
        let queries = ctx.device.create_query_set(&wgpu::QuerySetDescriptor {
            label: Some("render pass timestamps"),
            ty: wgpu::QueryType::Timestamp,
            count: TIMESTAMPS,
        });
        let resolved = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("render pass timestamps"),
            size: bytes,
            usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let readback = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("render pass timestamps readback"),
            size: bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        Some(PassTimer {
            queries,
            resolved,
            readback,
            period_ns: f64::from(ctx.queue.get_timestamp_period()),
            last: std::sync::atomic::AtomicU64::new(0),
        })
    }

    /// The timestamp writes of pass `pass` (0: first or whole frame, 1: medium).
    pub(crate) fn writes(&self, pass: u32) -> wgpu::ComputePassTimestampWrites<'_> {
        wgpu::ComputePassTimestampWrites {
            query_set: &self.queries,
            beginning_of_pass_write_index: Some(2 * pass),
            end_of_pass_write_index: Some(2 * pass + 1),
        }
    }

    /// Only the start of pass `pass` (the medium pass's first round).
    pub(crate) fn writes_begin(&self, pass: u32) -> wgpu::ComputePassTimestampWrites<'_> {
        wgpu::ComputePassTimestampWrites {
            end_of_pass_write_index: None,
            ..self.writes(pass)
        }
    }

    /// Only the end of pass `pass` (the medium pass's last round so far).
    pub(crate) fn writes_end(&self, pass: u32) -> wgpu::ComputePassTimestampWrites<'_> {
        wgpu::ComputePassTimestampWrites {
            beginning_of_pass_write_index: None,
            ..self.writes(pass)
        }
    }

    /// Resolve the band's timestamps into the read-back buffer (`passes` of them written).
    pub(crate) fn resolve(&self, encoder: &mut wgpu::CommandEncoder, passes: u32) {
        encoder.resolve_query_set(&self.queries, 0..2 * passes, &self.resolved, 0);
        encoder.copy_buffer_to_buffer(&self.resolved, 0, &self.readback, 0, u64::from(passes) * 16);
    }

    /// Bytes [`Self::pass_seconds`] reads back for `passes` passes.
    pub(crate) fn read_back_bytes(passes: u32) -> u64 {
        u64::from(passes) * 16
    }

    /// Device seconds of each of the `passes` passes just resolved.
    pub(crate) fn pass_seconds(&self, ctx: &GpuContext, passes: u32) -> Result<Vec<f64>, GpuError> {
        let ticks: Vec<u64> = read_buffer(ctx, &self.readback, Self::read_back_bytes(passes))?;
        Ok(ticks
            .chunks_exact(2)
            .map(|t| t[1].saturating_sub(t[0]) as f64 * self.period_ns * 1e-9)
            .collect())
    }
}

/// The scene and field on the device, ready to render.
#[derive(Debug)]
pub struct GpuRenderer<'a> {
    pub(crate) ctx: &'a GpuContext,
    pub(crate) params: FrameParams,
    /// PASS_ALL, or PASS_FIRST when the frame is split ([`Self::medium_pipeline`]).
    pub(crate) pipeline: wgpu::ComputePipeline,
    /// PASS_MEDIUM (render_deferred) over the pixels PASS_FIRST listed, when split.
    pub(crate) medium_pipeline: Option<wgpu::ComputePipeline>,
    pub(crate) bind_group: wgpu::BindGroup,
    pub(crate) params_buffer: wgpu::Buffer,
    /// PASS_FIRST's count of listed pixels, [workgroups, 1, 1, pixels], and its first
    /// three words copied as PASS_MEDIUM's indirect dispatch.
    pub(crate) deferred_count: wgpu::Buffer,
    pub(crate) deferred_dispatch: wgpu::Buffer,
    /// PASS_MEDIUM's pixels between rounds (WGSL `Resume`), the rounds' headers
    /// ([`resume_rounds`]), the 16 bytes read back to see whether a round left any, and
    /// the steps a round allows.
    pub(crate) resume: wgpu::Buffer,
    pub(crate) resume_rounds: wgpu::Buffer,
    pub(crate) resume_status: wgpu::Buffer,
    pub(crate) round_steps: u32,
    /// Pixels a half of `resume` holds (a pixel beyond them runs on whole).
    pub(crate) resume_capacity: u32,
    /// The most rounds one band of the last frame ran (0 without a medium pass).
    pub(crate) rounds: std::sync::atomic::AtomicU32,
    pub(crate) out_buffer: wgpu::Buffer,
    pub(crate) readback: wgpu::Buffer,
    pub(crate) rows_per_band: u32,
    /// Pixels one band's buffers hold (a small image's: room for twice its rows at
    /// creation, within the adapter's band).
    pub(crate) band_capacity: u32,
    /// Flags set by the field's upload and the object arrays, kept by [`Self::retarget`].
    pub(crate) scene_flags: u32,
    pub(crate) field: FieldTextures,
    /// What the caller should tell the user about the field: a bake here over the error
    /// budget, a baked file too big for the device and baked again.
    pub(crate) warnings: Vec<String>,
    /// The device's time in the render passes, where it writes timestamps.
    pub(crate) timer: Option<PassTimer>,
    /// Bytes mapped and read back from the device by [`Self::render`] so far: the
    /// bands' pixels and the passes' timestamps.
    pub(crate) read_back: std::sync::atomic::AtomicU64,
}

impl<'a> GpuRenderer<'a> {
    /// Upload `scene` (already validated by [`RenderScene::new`]) and its medium. The
    /// medium is marched through `baked` if given, else through the scene's field itself
    /// when it is a baked one (`kind = "baked"`: the file's grid, resolution and
    /// interpolation, so GPU and CPU march the same field) and fits the device (else it
    /// is baked again, with a warning in [`Self::warnings`]), else through a bake of the
    /// field at the coarsest grid meeting the error budget, at most
    /// [`crate::field::DEFAULT_GPU_BAKE_RESOLUTION`] nodes ([`crate::field::bake_for_gpu_auto`]),
    /// or sparse where no dense grid within the cap meets it ([`crate::cache::bake_for_gpu_grid`]). For
    /// GPU and CPU images to agree in that last case, render the CPU reference with the
    /// same baked field.
    pub fn new(
        ctx: &'a GpuContext,
        scene: &RenderScene,
        baked: Option<&BakedField>,
    ) -> Result<Self, GpuError> {
        Self::new_with(ctx, scene, baked.map(DeviceField::Dense))
    }

    /// [`Self::new`] with the grid dense or sparse (a [`crate::field::GpuGrid`]'s
    /// [`crate::field::GpuGrid::device`]).
    pub fn new_with(
        ctx: &'a GpuContext,
        scene: &RenderScene,
        grid: Option<DeviceField<'_>>,
    ) -> Result<Self, GpuError> {
        let (baked, sparse_grid) = match grid {
            Some(DeviceField::Dense(b)) => (Some(b), None),
            Some(DeviceField::Sparse(s)) => (None, Some(s)),
            None => (None, None),
        };
        let s = &scene.settings;
        let mut params = frame_params(scene)?;
        let mut warnings = Vec::new();
        if let Err(v) = band_override() {
            warnings.push(format!(
                "GRIN_BAND_PIXELS={v:?} is not a positive number of pixels: the adapter's default band is used"
            ));
        }
        // A sparse grid (the caller's, else the scene's own sparse file) is marched as it
        // is: baking it again as one dense box would lose what made it sparse.
        let sparse = sparse_grid.or_else(|| {
            baked
                .is_none()
                .then(|| scene.medium.as_ref().and_then(|m| m.field.as_sparse()))
                .flatten()
        });
        let field = match (&scene.medium, sparse) {
            (Some(_), Some(sparse)) => crate::field::upload_sparse(ctx, sparse, &mut params)?,
            (Some(m), None) => {
                let owned;
                // The caller's grid, else the scene's own baked file as it is (if the
                // device can hold it), else a bake of the field here; warnings are kept
                // for the caller.
                let file = m.field.as_baked().filter(|b| match fits_device(ctx, b) {
                    Ok(()) => true,
                    Err(why) => {
                        warnings.push(format!(
                            "the scene's baked field does not fit the GPU ({why}); it is baked again for the GPU at up to {DEFAULT_GPU_BAKE_RESOLUTION} nodes per axis"
                        ));
                        false
                    }
                });
                match baked.or(file) {
                    Some(b) => upload_field(ctx, b, &mut params)?,
                    None => {
                        let (grid, w) = crate::cache::bake_for_gpu_grid(m.field.as_ref())?;
                        warnings.extend(w);
                        owned = grid;
                        crate::field::upload(ctx, owned.device(), &mut params)?
                    }
                }
            }
            (None, _) => empty_field(ctx, &mut params)?,
        };

        let device = &ctx.device;
        let limits = ctx.limits();
        let band_rows = (pixels_per_band(ctx, s.spp) / s.width.max(1)).max(1);
        let rows_per_band = band_rows.min(s.height.max(1));
        let pixel_bytes = std::mem::size_of::<PixelOut>() as u64;
        // A small image's buffers have room for one up to twice as tall (within the
        // adapter's band): a viewer's moving image that grows a little keeps its renderer
        // (`retarget`). A large one's are its own size.
        let small = u64::from(s.width) * u64::from(s.height) <= SMALL_IMAGE_PIXELS;
        let capacity_rows = match band_rows.min(if small { 2 } else { 1 } * s.height.max(1)) {
            rows if u64::from(s.width) * u64::from(rows) * pixel_bytes
                <= limits.max_storage_buffer_binding_size =>
            {
                rows
            }
            _ => rows_per_band,
        };
        let out_bytes = u64::from(s.width) * u64::from(capacity_rows) * pixel_bytes;
        if out_bytes > limits.max_storage_buffer_binding_size {
            return Err(GpuError::TooLarge {
                what: format!("a {}-pixel-wide output band", s.width),
                needed: format!("{out_bytes} bytes"),
                limit: format!(
                    "{} bytes (max_storage_buffer_binding_size)",
                    limits.max_storage_buffer_binding_size
                ),
                adapter: ctx.adapter_name(),
            });
        }
        if s.width.div_ceil(WORKGROUP) > limits.max_compute_workgroups_per_dimension {
            return Err(GpuError::TooLarge {
                what: format!("image width {}", s.width),
                needed: format!("{} workgroups", s.width.div_ceil(WORKGROUP)),
                limit: format!("{}", limits.max_compute_workgroups_per_dimension),
                adapter: ctx.adapter_name(),
            });
        }
        let env = env_texels(ctx, scene)?;
        let (objects, lights) = scene_arrays(scene, &mut params);
        // Split the frame in two passes when there is a medium (PASS_FIRST without the
        // march, PASS_MEDIUM over the pixels whose paths reach it), unless shadow rays
        // bend through the medium: then every diffuse surface's light needs the march.
        let split = scene.medium.is_some() && !s.bend_shadow_rays;
        // Compiled once per device and set of pipeline constants (ctx keeps them).
        let key = format!("split={split} {:?}", pipeline_constants(&params, PASS_ALL));
        let (pipeline, medium_pipeline) = ctx.render_pipelines(&key, || {
            let compiled = ctx.scoped("compiling the render pipelines", || {
                let layout_entries = render_layout_entries();
                let bind_layout =
                    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                        label: Some("render bindings"),
                        entries: &layout_entries,
                    });
                let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                    label: Some("render"),
                    bind_group_layouts: &[Some(&bind_layout)],
                    immediate_size: 0,
                });
                // Each pass gets its own kernel with the constants folded in and the
                // branches they rule out removed (crate::specialize: Mesa inlines before
                // it removes dead code, so this is most of lavapipe's compile time).
                let make = |pass: u32, entry: &str| {
                    specialize::compute_pipeline(
                        device,
                        ctx.pipeline_cache(),
                        &layout,
                        specialize::Kernel::Render,
                        entry,
                        &pipeline_constants(&params, pass),
                    )
                };
                if split {
                    // The two passes' pipelines compile at once (lavapipe compiles each with
                    // LLVM on the calling thread).
                    std::thread::scope(|scope| {
                        let medium = scope.spawn(|| make(PASS_MEDIUM, "render_deferred"));
                        let first = make(PASS_FIRST, "render_main")?;
                        let medium = match medium.join() {
                            Ok(p) => p?,
                            Err(_) => make(PASS_MEDIUM, "render_deferred")?,
                        };
                        Ok((first, Some(medium)))
                    })
                } else {
                    Ok((make(PASS_ALL, "render_main")?, None))
                }
            })?;
            compiled.map_err(|message| GpuError::Wgpu {
                during: "specialising the render kernel".into(),
                message,
            })
        })?;
        ctx.scoped("creating the render pipeline", || {
            use wgpu::util::DeviceExt;
            // The layout the pipelines were compiled with (one for both passes).
            let bind_layout = pipeline.get_bind_group_layout(0);
            let params_buffer = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("frame params"),
                size: std::mem::size_of::<FrameParams>() as u64,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            let objects_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("objects"),
                contents: bytemuck::cast_slice(&objects),
                usage: wgpu::BufferUsages::STORAGE,
            });
            let lights_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("lights"),
                contents: bytemuck::cast_slice(&lights),
                usage: wgpu::BufferUsages::STORAGE,
            });
            let env_tex = env_texture(ctx, &env);
            let (out_buffer, readback) = output_buffers(device, "pixels", out_bytes);
            let deferred = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("deferred pixels"),
                size: (out_bytes / std::mem::size_of::<PixelOut>() as u64) * 4,
                usage: wgpu::BufferUsages::STORAGE,
                mapped_at_creation: false,
            });
            let deferred_count = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("deferred pixel count"),
                size: 16,
                usage: wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::COPY_SRC
                    | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            // The count's first three words, copied for the indirect dispatch (a buffer
            // may not be bound for storage and read as indirect arguments at once).
            let deferred_dispatch = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("deferred pass dispatch"),
                size: 12,
                usage: wgpu::BufferUsages::INDIRECT | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            // Room for a band's pixels in each half (none without PASS_MEDIUM), within the
            // binding limit.
            let resume_pixels = if split {
                let limits = ctx.limits();
                let fits = (limits
                    .max_storage_buffer_binding_size
                    .min(limits.max_buffer_size)
                    .min(RESUME_BYTES_MAX)
                    - RESUME_HEADER_BYTES)
                    / (2 * PIXEL_CARRY_BYTES);
                (s.width * capacity_rows).min(u32::try_from(fits).unwrap_or(u32::MAX))
            } else {
                0
            };
            let resume = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("medium pass rounds"),
                size: RESUME_HEADER_BYTES + 2 * u64::from(resume_pixels.max(1)) * PIXEL_CARRY_BYTES,
                usage: wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::COPY_SRC
                    | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            let resume_rounds = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("medium pass round headers"),
                contents: bytemuck::cast_slice(&resume_rounds(
                    RENDER_STEPS_PER_ROUND,
                    resume_pixels,
                )),
                usage: wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
            });
            let resume_status = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("medium pass pixels left"),
                size: 16,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            let (field_view, macro_view) = field.views();
            let env_view = env_tex.create_view(&wgpu::TextureViewDescriptor::default());
            let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("render bindings"),
                layout: &bind_layout,
                entries: &bind_entries([
                    (0, params_buffer.as_entire_binding()),
                    (1, objects_buffer.as_entire_binding()),
                    (2, lights_buffer.as_entire_binding()),
                    (3, wgpu::BindingResource::TextureView(&field_view)),
                    (4, wgpu::BindingResource::TextureView(&macro_view)),
                    (5, wgpu::BindingResource::TextureView(&env_view)),
                    (6, out_buffer.as_entire_binding()),
                    (7, deferred.as_entire_binding()),
                    (8, deferred_count.as_entire_binding()),
                    (9, resume.as_entire_binding()),
                ]),
            });
            GpuRenderer {
                ctx,
                params,
                pipeline,
                medium_pipeline,
                bind_group,
                params_buffer,
                deferred_count,
                deferred_dispatch,
                resume,
                resume_rounds,
                resume_status,
                round_steps: RENDER_STEPS_PER_ROUND,
                resume_capacity: resume_pixels,
                rounds: std::sync::atomic::AtomicU32::new(0),
                out_buffer,
                readback,
                rows_per_band,
                band_capacity: s.width * capacity_rows,
                scene_flags: params.flags & (FIELD_FLAGS | FLAG_MEDIUM_OBJECTS),
                field,
                warnings,
                timer: PassTimer::new(ctx),
                read_back: std::sync::atomic::AtomicU64::new(0),
            }
        })
    }

    /// Aim the renderer at `scene`, the scene it was built for with another camera, image
    /// size, samples per pixel, seed or step size / tolerance (what the viewer changes
    /// between frames), and render samples `first_sample .. first_sample + spp` of an
    /// image of `spp_total` samples: frames of consecutive ranges, averaged, equal one
    /// render of `spp_total` samples. The objects, lights, sky and field on the device
    /// are kept. `Ok(false)`, with nothing changed, when the change needs other
    /// pipelines (integrator, step policy, flags) or bigger buffers (an image that is one
    /// band on the adapter would be more in these): build a new renderer then.
    pub fn retarget(
        &mut self,
        scene: &RenderScene,
        first_sample: u32,
        spp_total: u32,
    ) -> Result<bool, GpuError> {
        let mut p = frame_params(scene)?;
        let old = &self.params;
        // What the field's upload and the object arrays placed in the parameters.
        copy_uploaded(&mut p, old);
        p.flags |= self.scene_flags;
        if old.flags & FLAG_MACRO_CELLS == 0 {
            p.flags &= !FLAG_MACRO_CELLS;
        }
        p.first_sample = first_sample;
        p.spp_total = spp_total.max(p.spp);
        if pipeline_constants(&p, PASS_ALL) != pipeline_constants(old, PASS_ALL)
            || p.object_count != old.object_count
            || p.light_count != old.light_count
        {
            return Ok(false);
        }
        let wanted = (pixels_per_band(self.ctx, p.spp) / p.width.max(1)).min(p.height.max(1));
        let rows = wanted.min(self.band_capacity / p.width.max(1));
        // An image that is one band on the adapter but more than one in these buffers
        // (made for a smaller image): a submission and a wait each, so a new renderer.
        if rows == 0 || (wanted >= p.height && rows < p.height) {
            return Ok(false);
        }
        self.params = p;
        self.rows_per_band = rows;
        Ok(true)
    }

    /// Let each pixel's marches take at most `steps` steps a round of the medium pass
    /// (default [`RENDER_STEPS_PER_ROUND`]): the image is the same at any value (tested).
    pub fn set_round_steps(&mut self, steps: u32) {
        self.round_steps = steps.max(1);
        self.write_resume_rounds();
    }

    /// Let a round leave at most `pixels` pixels to the next (fewer than its buffer
    /// holds): the others run on whole in the round that finds no room for them (tested:
    /// the image is the same).
    pub fn limit_resume_pixels(&mut self, pixels: u32) {
        self.resume_capacity = self.resume_capacity.min(pixels);
        self.write_resume_rounds();
    }

    fn write_resume_rounds(&self) {
        self.ctx.queue.write_buffer(
            &self.resume_rounds,
            0,
            bytemuck::cast_slice(&resume_rounds(self.round_steps, self.resume_capacity)),
        );
    }

    /// The most rounds of the medium pass one band of the last frame ran, counting the
    /// first (each a dispatch; a viewer's band always runs its fixed number).
    pub fn last_medium_rounds(&self) -> u32 {
        self.rounds.load(Ordering::Relaxed)
    }

    /// Render in bands of at most `rows` rows (the seams between bands, tested; the next
    /// [`Self::retarget`] sets the adapter's band again).
    pub fn limit_band_rows(&mut self, rows: u32) {
        self.rows_per_band = self.rows_per_band.min(rows.max(1));
    }

    /// Rows of the image a band renders (a frame of `height` rows is
    /// `height.div_ceil(rows)` bands: a submission each).
    pub fn rows_per_band(&self) -> u32 {
        self.rows_per_band
    }

    /// `name (backend, device type)` of the adapter.
    pub fn adapter_info(&self) -> String {
        self.ctx.adapter_name()
    }

    /// Where `suspect` pixels of a frame ended `error` after many steps on an adapter with
    /// a loop limit (lavapipe): what they likely are, and what traces them whole. The
    /// device counts them ([`FrameTotals::loop_limit_suspects`],
    /// [`crate::view::ViewStats`]).
    pub fn loop_limit_warning_of(&self, suspect: u64) -> Option<String> {
        let limit = self.ctx.loop_limit()?;
        (suspect > 0).then(|| {
            format!(
                "{suspect} pixels ended `error` after {:.0}+ steps on a CPU adapter (lavapipe), which stops all loops of a shader invocation after {limit} iterations in all (~3 a step, more with dopri, with objects in the scene or an exit search every step: 10,900 steps a ray in the Luneburg scene): they were likely cut short there, not failed; a GPU has no such limit, and the CPU backend (grin render --backend cpu) traces them whole",
                crate::device::LOOP_LIMIT_SUSPECT_STEPS
            )
        })
    }

    /// Warnings about the field, for the user: the bake made here is over the default
    /// error budget ([`crate::field::bake_warning`]), or the scene's baked file did not
    /// fit the device and was baked again. Empty when the field is as the scene asked.
    pub fn warnings(&self) -> &[String] {
        &self.warnings
    }

    /// Node counts of the field grid on the device (a placeholder without a medium).
    pub fn field_dims(&self) -> [u32; 3] {
        self.field.dims
    }

    /// Bytes of field data on the device.
    pub fn field_bytes(&self) -> u64 {
        self.field.bytes
    }

    /// Render every pixel. `progress(rows_done)` is called after each band of rows;
    /// setting `cancel` stops between bands with [`GpuError::Cancelled`].
    pub fn render(&self, progress: &dyn Fn(u32), cancel: &AtomicBool) -> Result<Frame, GpuError> {
        self.collect_frame(progress, cancel, |row, rows, pixels| {
            // Converted straight from the mapped read-back buffer: no copy of the band.
            let mut take = |band: &[PixelOut]| {
                pixels.extend(band.iter().map(|p| p.to_cpu()));
            };
            self.render_band(row, rows, BandSink::ReadBack(&mut take))
        })
    }

    /// A frame of every pixel, each band's added by `band(first_row, rows, pixels)`
    /// (which returns the band's device seconds), `progress` told after each.
    fn collect_frame(
        &self,
        progress: &dyn Fn(u32),
        cancel: &AtomicBool,
        mut band: impl FnMut(
            u32,
            u32,
            &mut Vec<grin_render::image::PixelOut>,
        ) -> Result<Option<f64>, GpuError>,
    ) -> Result<Frame, GpuError> {
        let (width, height) = (self.params.width, self.params.height);
        let mut pixels = grin_field::alloc::try_with_capacity(
            width as usize * height as usize,
            &format!("a {width}x{height} frame"),
        )
        .map_err(|e| GpuError::Memory(e.to_string()))?;
        self.each_band(cancel, |row, rows| {
            let seconds = band(row, rows, &mut pixels)?;
            progress(rows);
            Ok(seconds)
        })?;
        Ok(Frame {
            width,
            height,
            pixels,
        })
    }

    /// Render every pixel, reading back only `channels` of each (those not read are NaN
    /// in the frame), with the frame's [`FrameTotals`] counted on the device (64 bytes
    /// more): what an output made of a few channels needs ([`crate::channels`]). With
    /// [`Channels::ALL`] this is [`Self::render`], the totals counted on the CPU.
    pub fn render_channels(
        &self,
        channels: Channels,
        progress: &dyn Fn(u32),
        cancel: &AtomicBool,
    ) -> Result<(Frame, FrameTotals), GpuError> {
        if channels == Channels::ALL {
            let frame = self.render(progress, cancel)?;
            let totals = FrameTotals::of(&frame, self.params.spp);
            return Ok((frame, totals));
        }
        let width = self.params.width;
        let packer = Packer::new(
            self.ctx,
            channels,
            self.params.spp,
            width * self.rows_per_band,
        )?;
        packer.clear_totals(self.ctx);
        let words = channels.words() as usize;
        let frame = self.collect_frame(progress, cancel, |row, rows, pixels| {
            let n = width as usize * rows as usize;
            let mut take = |band: &[f32]| {
                let pixel = |i: usize| channels.unpack(&band[i * words..(i + 1) * words]);
                pixels.extend((0..n).map(|i| pixel(i).to_cpu()));
            };
            let sink = BandSink::Packed {
                packer: &packer,
                take: &mut take,
            };
            self.render_band(row, rows, sink)
        })?;
        let totals = packer.read_totals(self.ctx)?;
        self.read_back.fetch_add(TOTALS_BYTES, Ordering::Relaxed);
        Ok((frame, totals))
    }

    /// Render every pixel into `image` (the viewer's image on the device): the frame's
    /// samples start the image (`overwrite`) or are added to it and AOV `aov` is coloured
    /// into its texture ([`ViewImage::show`]). With `read`, the statistics counted since
    /// the last read come back (32 bytes) with the passes' timestamps
    /// ([`Self::last_device_seconds`]); without, nothing is read back: the frame is waited
    /// for on the device's fence. A frame of one band is one submission. Setting `cancel`
    /// stops between bands with [`GpuError::Cancelled`], the image then part this frame and
    /// part the last: start it again.
    pub fn render_to_view(
        &self,
        image: &mut ViewImage,
        overwrite: bool,
        aov: u32,
        read: bool,
        cancel: &AtomicBool,
    ) -> Result<Option<ViewStats>, GpuError> {
        let (width, height) = (self.params.width, self.params.height);
        image.begin_frame(width, height, overwrite, self.params.spp);
        let image = &*image;
        self.each_band(cancel, |row, rows| {
            let sink = BandSink::View {
                image,
                first: row == 0,
                show: (row + rows >= height).then_some(aov),
                read,
            };
            self.render_band(row, rows, sink)
        })?;
        if read {
            image.read_stats(self.ctx, aov).map(Some)
        } else {
            self.ctx.wait_submitted()?;
            Ok(None)
        }
    }

    /// Run `band(first_row, rows)` over the frame's bands, stopping between them with
    /// [`GpuError::Cancelled`] when `cancel` is set; the device seconds they return are
    /// the frame's ([`Self::last_device_seconds`]).
    fn each_band(
        &self,
        cancel: &AtomicBool,
        mut band: impl FnMut(u32, u32) -> Result<Option<f64>, GpuError>,
    ) -> Result<(), GpuError> {
        let height = self.params.height;
        let mut row = 0;
        // NaN where no band was timed (a viewer's frame that reads nothing back).
        let mut device_seconds: Option<f64> = None;
        self.rounds.store(0, Ordering::Relaxed);
        while row < height {
            if cancel.load(Ordering::Relaxed) {
                return Err(GpuError::Cancelled);
            }
            let rows = self.rows_per_band.min(height - row);
            if let Some(s) = band(row, rows)? {
                *device_seconds.get_or_insert(0.0) += s;
            }
            row += rows;
        }
        let device_seconds = device_seconds.unwrap_or(f64::NAN);
        if let Some(timer) = &self.timer {
            timer
                .last
                .store(device_seconds.to_bits(), Ordering::Relaxed);
        }
        Ok(())
    }

    /// Bytes read back from the device by this renderer's frames so far (pixels and
    /// timestamps): what a frame costs in transfers is the difference across it.
    pub fn bytes_read_back(&self) -> u64 {
        self.read_back.load(Ordering::Relaxed)
    }

    /// Seconds the device spent in the render passes of the last [`Self::render`]
    /// (timestamps written around each pass; `None` where the adapter has none, or the
    /// last frame was a viewer's that read nothing back).
    pub fn last_device_seconds(&self) -> Option<f64> {
        self.timer
            .as_ref()
            .map(|t| f64::from_bits(t.last.load(Ordering::Relaxed)))
            .filter(|s| !s.is_nan())
    }

    /// Render and time the whole frame (for benchmarks).
    pub fn render_timed(&self) -> Result<(Frame, RenderTiming), GpuError> {
        let start = Instant::now();
        let frame = self.render(&|_| {}, &AtomicBool::new(false))?;
        Ok((
            frame,
            RenderTiming {
                seconds: start.elapsed().as_secs_f64(),
                device_seconds: self.last_device_seconds(),
            },
        ))
    }

    /// Render rows `first_row .. first_row + rows` into `sink`, and return, where the
    /// device writes timestamps, the seconds it spent in the band's passes.
    fn render_band(
        &self,
        first_row: u32,
        rows: u32,
        mut sink: BandSink<'_>,
    ) -> Result<Option<f64>, GpuError> {
        let ctx = self.ctx;
        let width = self.params.width;
        let mut params = self.params;
        params.first_row = first_row;
        params.row_count = rows;
        let per_pixel = match &sink {
            BandSink::Packed { packer, .. } => packer.channels().bytes_per_pixel(),
            _ => std::mem::size_of::<PixelOut>() as u64,
        };
        let bytes = u64::from(width) * u64::from(rows) * per_pixel;
        let passes = if self.medium_pipeline.is_some() { 2 } else { 1 };
        let view = matches!(sink, BandSink::View { .. });
        // The passes' timestamps are read with a view's statistics only.
        let timer = match &sink {
            BandSink::View { read: false, .. } => None,
            _ => self.timer.as_ref(),
        };
        // Every round there could be: each pixel's samples, each path's events, each
        // march's loop bound, a round's steps at a time (never reached: the count of
        // pixels left reaches zero long before).
        let cap = {
            let events = 3 * (u64::from(params.max_depth) + 1);
            let steps = u64::from(params.spp) * events * (2 * u64::from(params.max_steps) + 2);
            u32::try_from(steps.div_ceil(u64::from(self.round_steps)) + 1).unwrap_or(u32::MAX)
        };
        let mut round = 0u32;
        let mut encoder = ctx.scoped("dispatching the render kernel", || {
            ctx.queue
                .write_buffer(&self.params_buffer, 0, bytemuck::bytes_of(&params));
            let mut encoder = ctx
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("render band"),
                });
            if let BandSink::View {
                image, first: true, ..
            } = &sink
            {
                image.encode_clear(&mut encoder);
            }
            if self.medium_pipeline.is_some() {
                ctx.queue.write_buffer(
                    &self.deferred_count,
                    0,
                    bytemuck::cast_slice(&[0u32, 1, 1, 0]),
                );
                // Round 0 starts the pixels PASS_FIRST lists and leaves its unfinished
                // ones in half 0.
                let start = ResumeRound {
                    resuming: 0,
                    read_half: 1,
                    budget: self.round_steps,
                    capacity: self.resume_capacity,
                };
                let header: [[u32; 4]; 3] = [bytemuck::cast(start), EMPTY_COUNT, EMPTY_COUNT];
                ctx.queue
                    .write_buffer(&self.resume, 0, bytemuck::cast_slice(&header));
            }
            {
                let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("render_main"),
                    timestamp_writes: self.timer.as_ref().map(|t| t.writes(0)),
                });
                pass.set_pipeline(&self.pipeline);
                pass.set_bind_group(0, &self.bind_group, &[]);
                pass.dispatch_workgroups(width.div_ceil(WORKGROUP), rows.div_ceil(WORKGROUP), 1);
            }
            if let Some(medium) = &self.medium_pipeline {
                // A new pass: PASS_FIRST's list and count are complete when it starts.
                encoder.copy_buffer_to_buffer(
                    &self.deferred_count,
                    0,
                    &self.deferred_dispatch,
                    0,
                    12,
                );
                let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("render_deferred"),
                    timestamp_writes: self.timer.as_ref().map(|t| t.writes_begin(1)),
                });
                pass.set_pipeline(medium);
                pass.set_bind_group(0, &self.bind_group, &[]);
                pass.dispatch_workgroups_indirect(&self.deferred_dispatch, 0);
            }
            encoder
        })?;
        // Device seconds of the submissions before the last (each its own passes: the
        // host's waits between them are not the device's time).
        let mut earlier_seconds = 0.0;
        let mut submission = 0u32;
        loop {
            let batch_end = if view {
                VIEW_ROUNDS + 1
            } else {
                round + ROUNDS_PER_SUBMISSION
            }
            .min(cap);
            ctx.scoped("dispatching the render kernel", || {
                if let Some(medium) = &self.medium_pipeline {
                    for r in round + 1..=batch_end {
                        let last = r == batch_end && (view || r == cap);
                        // A later submission's medium pass starts at its first round.
                        let begin = submission > 0 && r == round + 1;
                        let stamps = (begin, r == batch_end);
                        self.encode_round(&mut encoder, medium, r, last, stamps);
                    }
                    if !view {
                        // The count the last round left in the half it wrote.
                        let written = u64::from(batch_end & 1);
                        encoder.copy_buffer_to_buffer(
                            &self.resume,
                            16 + 16 * written,
                            &self.resume_status,
                            0,
                            16,
                        );
                    }
                }
                // The pixels, in the first submission (most bands need no other; a band
                // that does copies them again after its last).
                if submission == 0 {
                    self.encode_sink(&mut encoder, &sink, first_row, rows, bytes, false);
                }
                if let Some(timer) = timer {
                    timer.resolve(&mut encoder, passes);
                }
            })?;
            ctx.queue.submit([encoder.finish()]);
            round = batch_end;
            submission += 1;
            if self.medium_pipeline.is_some() {
                self.rounds.fetch_max(round + 1, Ordering::Relaxed);
            }
            if view || self.medium_pipeline.is_none() || round >= cap {
                break;
            }
            let status: Vec<u32> = read_buffer(ctx, &self.resume_status, 16)?;
            self.read_back.fetch_add(16, Ordering::Relaxed);
            if status[3] == 0 {
                break;
            }
            if let Some(timer) = timer {
                earlier_seconds += self.submission_seconds(timer, submission - 1, passes)?;
            }
            encoder = ctx
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("render band rounds"),
                });
        }
        if submission > 1 {
            // The pixels as the last round left them.
            let mut encoder = ctx
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("render band pixels"),
                });
            self.encode_sink(&mut encoder, &sink, first_row, rows, bytes, true);
            ctx.queue.submit([encoder.finish()]);
        }
        match &mut sink {
            BandSink::ReadBack(take) => {
                read_buffer_with(ctx, &self.readback, bytes, |band: &[PixelOut]| take(band))?;
                self.read_back.fetch_add(bytes, Ordering::Relaxed);
            }
            // No channel: the counts alone (nothing to map; waited for, as a read would,
            // so progress and a cancel follow the device).
            BandSink::Packed { take, .. } if bytes == 0 => {
                ctx.wait_submitted()?;
                take(&[]);
            }
            BandSink::Packed { take, .. } => {
                read_buffer_with(ctx, &self.readback, bytes, |band: &[f32]| take(band))?;
                self.read_back.fetch_add(bytes, Ordering::Relaxed);
            }
            // A CPU adapter runs a band for a good part of a second: wait for each, so a
            // cancel stops the frame between them (timestamps below wait too).
            BandSink::View { .. } if timer.is_none() && ctx.is_cpu_adapter() => {
                ctx.wait_submitted()?;
            }
            BandSink::View { .. } => {}
        }
        match timer {
            Some(timer) => {
                let last = self.submission_seconds(timer, submission - 1, passes)?;
                Ok(Some(earlier_seconds + last))
            }
            None => Ok(None),
        }
    }

    /// Where the band's pixels go: copied for reading back, or added to the viewer's
    /// image (and coloured after the frame's last band). `again`: the band's pixels once
    /// more, after the submissions that finished its marches (the first copy, in its
    /// first submission, held some unfinished).
    fn encode_sink(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        sink: &BandSink<'_>,
        first_row: u32,
        rows: u32,
        bytes: u64,
        again: bool,
    ) {
        match sink {
            BandSink::ReadBack(_) => {
                encoder.copy_buffer_to_buffer(&self.out_buffer, 0, &self.readback, 0, bytes);
            }
            BandSink::Packed { packer, .. } => {
                packer.encode(
                    self.ctx,
                    encoder,
                    &self.out_buffer,
                    self.params.width * rows,
                    again,
                );
                if bytes > 0 {
                    encoder.copy_buffer_to_buffer(&packer.packed, 0, &self.readback, 0, bytes);
                }
            }
            BandSink::View {
                image, show, read, ..
            } => {
                image.accumulate_band(self.ctx, encoder, &self.out_buffer, first_row, rows);
                if let Some(aov) = show {
                    image.encode_show(self.ctx, encoder, *aov, *read);
                }
            }
        }
    }

    /// The device seconds of a band's submission `n`: the first runs every pass, a later
    /// one only rounds of the medium pass.
    fn submission_seconds(&self, timer: &PassTimer, n: u32, passes: u32) -> Result<f64, GpuError> {
        self.read_back
            .fetch_add(PassTimer::read_back_bytes(passes), Ordering::Relaxed);
        let seconds = timer.pass_seconds(self.ctx, passes)?;
        Ok(if n == 0 {
            seconds.iter().sum()
        } else {
            seconds[passes as usize - 1]
        })
    }

    /// Encode round `r` (1 or later) of the medium pass: it reads the half round `r - 1`
    /// wrote (emptying the count of the other, which it writes), with the round's budget
    /// of steps (none in the `last` round), dispatched over the pixels left.
    fn encode_round(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        medium: &wgpu::ComputePipeline,
        r: u32,
        last: bool,
        (stamp_begin, stamp_end): (bool, bool),
    ) {
        let read = u64::from((r - 1) & 1);
        let write = 1 - read;
        encoder.copy_buffer_to_buffer(
            &self.resume_rounds,
            4 * 16,
            &self.resume,
            16 + 16 * write,
            16,
        );
        encoder.copy_buffer_to_buffer(
            &self.resume_rounds,
            (read * 2 + u64::from(last)) * 16,
            &self.resume,
            0,
            16,
        );
        encoder.copy_buffer_to_buffer(&self.resume, 16 + 16 * read, &self.deferred_dispatch, 0, 12);
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("render_deferred round"),
            timestamp_writes: self
                .timer
                .as_ref()
                .and_then(|t| match (stamp_begin, stamp_end) {
                    (true, true) => Some(t.writes(1)),
                    (true, false) => Some(t.writes_begin(1)),
                    (false, true) => Some(t.writes_end(1)),
                    (false, false) => None,
                }),
        });
        pass.set_pipeline(medium);
        pass.set_bind_group(0, &self.bind_group, &[]);
        pass.dispatch_workgroups_indirect(&self.deferred_dispatch, 0);
    }
}

/// Where a band's pixels go: read back (whole, or the channels packed) and handed to a
/// closure (while the read-back buffer is mapped), or added to the viewer's image on the
/// device.
enum BandSink<'s> {
    ReadBack(&'s mut dyn FnMut(&[PixelOut])),
    /// The channels `packer` keeps, packed on the device, read back and handed over.
    Packed {
        packer: &'s Packer,
        take: &'s mut dyn FnMut(&[f32]),
    },
    View {
        image: &'s ViewImage,
        /// The frame's first band: its statistics start counting (cleared first after a
        /// read).
        first: bool,
        /// The frame's last band: colour this AOV after it.
        show: Option<u32>,
        /// The frame's statistics and timestamps are read back.
        read: bool,
    },
}

/// A storage buffer of `bytes` a kernel writes (`label`) and the mappable buffer it is
/// copied into for reading back (`label readback`).
pub(crate) fn output_buffers(
    device: &wgpu::Device,
    label: &str,
    bytes: u64,
) -> (wgpu::Buffer, wgpu::Buffer) {
    let out = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: bytes,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let readback = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(&format!("{label} readback")),
        size: bytes,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    (out, readback)
}

/// Map `buffer` (MAP_READ), copy out its first `bytes` as `T`s (pixels), unmap.
pub(crate) fn read_buffer<T: bytemuck::Pod>(
    ctx: &GpuContext,
    buffer: &wgpu::Buffer,
    bytes: u64,
) -> Result<Vec<T>, GpuError> {
    read_buffer_with(ctx, buffer, bytes, |items: &[T]| items.to_vec())
}

/// Map `buffer` (MAP_READ), hand its first `bytes` as `T`s to `take`, unmap.
pub(crate) fn read_buffer_with<T: bytemuck::Pod, R>(
    ctx: &GpuContext,
    buffer: &wgpu::Buffer,
    bytes: u64,
    take: impl FnOnce(&[T]) -> R,
) -> Result<R, GpuError> {
    let slice = buffer.slice(0..bytes);
    let (tx, rx) = std::sync::mpsc::channel();
    slice.map_async(wgpu::MapMode::Read, move |r| {
        let _ = tx.send(r);
    });
    // Without holding the device: a window may share it (the viewer).
    if let Err(e) = ctx.wait_until(&rx)? {
        return Err(GpuError::DeviceLost(format!("reading pixels back: {e}")));
    }
    let out = {
        let view = slice
            .get_mapped_range()
            .map_err(|e| GpuError::DeviceLost(format!("reading pixels back: {e}")))?;
        take(bytemuck::cast_slice::<u8, T>(&view))
    };
    buffer.unmap();
    Ok(out)
}
