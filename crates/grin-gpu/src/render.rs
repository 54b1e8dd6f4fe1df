//! [`GpuRenderer`]: a [`RenderScene`] on the GPU. Uploads the scene and the baked field,
//! dispatches the render kernel in bands of rows (progress and cancellation between
//! bands), and reads the pixels back into the CPU renderer's [`Frame`].

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use glam::DVec3;
use grin_field::Bounds;
use grin_field::baked::BakedField;
use grin_render::image::Frame;
use grin_render::primitives::Primitive;
use grin_render::scene::RenderScene;
use grin_render::sky::SkyModel;
use grin_scene::{ExitMethod, IntegratorKind, Light, Material, StepSpec};

use crate::field::{
    DEFAULT_GPU_BAKE_RESOLUTION, FieldTextures, bake_for_gpu_auto, empty_field, fits_device,
    upload_field,
};
use crate::gpu_data::*;
use crate::{GpuContext, GpuError, shaders};

/// Pixels per dispatch: big enough to keep every core of lavapipe busy, small enough
/// that progress updates and cancellation stay responsive (~0.1-1 s per band).
const PIXELS_PER_BAND: u32 = 32 * 1024;

/// Workgroup size of `render_main` and `bench_main` (keep in sync with the shaders).
const WORKGROUP: u32 = 8;

/// Field samples per invocation of `bench_main` (keep in sync with BENCH_SAMPLES in
/// shaders/texture_bench.wgsl).
const TEXTURE_BENCH_SAMPLES: u32 = 256;

/// Timing of the last [`GpuRenderer::render`].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RenderTiming {
    pub seconds: f64,
}

/// The scene and field on the device, ready to render.
#[derive(Debug)]
pub struct GpuRenderer<'a> {
    ctx: &'a GpuContext,
    params: FrameParams,
    /// PASS_ALL, or PASS_FIRST when the frame is split ([`Self::medium_pipeline`]).
    pipeline: wgpu::ComputePipeline,
    /// PASS_MEDIUM (render_deferred) over the pixels PASS_FIRST listed, when split.
    medium_pipeline: Option<wgpu::ComputePipeline>,
    bind_group: wgpu::BindGroup,
    params_buffer: wgpu::Buffer,
    /// PASS_FIRST's count of listed pixels, [workgroups, 1, 1, pixels], and its first
    /// three words copied as PASS_MEDIUM's indirect dispatch.
    deferred_count: wgpu::Buffer,
    deferred_dispatch: wgpu::Buffer,
    out_buffer: wgpu::Buffer,
    readback: wgpu::Buffer,
    rows_per_band: u32,
    field: FieldTextures,
    /// What the caller should tell the user about the field: a bake here over the error
    /// budget, a baked file too big for the device and baked again.
    warnings: Vec<String>,
}

fn v4(v: DVec3, w: f32) -> [f32; 4] {
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

/// The render kernels' bindings (shaders/shared/bindings.wgsl), one layout for both
/// passes.
fn render_layout_entries() -> Vec<wgpu::BindGroupLayoutEntry> {
    let buffer = |binding, ty| wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty,
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    };
    let texture = |binding, view_dimension| wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Texture {
            sample_type: wgpu::TextureSampleType::Float { filterable: false },
            view_dimension,
            multisampled: false,
        },
        count: None,
    };
    let storage = |read_only| wgpu::BufferBindingType::Storage { read_only };
    vec![
        buffer(0, wgpu::BufferBindingType::Uniform),
        buffer(1, storage(true)),
        buffer(2, storage(true)),
        texture(3, wgpu::TextureViewDimension::D3),
        texture(4, wgpu::TextureViewDimension::D3),
        texture(5, wgpu::TextureViewDimension::D2),
        buffer(6, storage(false)),
        buffer(7, storage(false)),
        buffer(8, storage(false)),
    ]
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

impl<'a> GpuRenderer<'a> {
    /// Upload `scene` (already validated by [`RenderScene::new`]) and its medium. The
    /// medium is marched through `baked` if given, else through the scene's field itself
    /// when it is a baked one (`kind = "baked"`: the file's grid, resolution and
    /// interpolation, so GPU and CPU march the same field) and fits the device (else it
    /// is baked again, with a warning in [`Self::warnings`]), else through a bake of the
    /// field at the coarsest grid meeting the error budget, at most
    /// [`crate::field::DEFAULT_GPU_BAKE_RESOLUTION`] nodes ([`crate::field::bake_for_gpu_auto`]). For
    /// GPU and CPU images to agree in that last case, render the CPU reference with the
    /// same baked field.
    pub fn new(
        ctx: &'a GpuContext,
        scene: &RenderScene,
        baked: Option<&BakedField>,
    ) -> Result<Self, GpuError> {
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

        let mut warnings = Vec::new();
        let field = match &scene.medium {
            Some(m) => {
                params.march[3] |= FLAG_HAS_MEDIUM;
                match m.bounds {
                    Bounds::Sphere { center, radius } => {
                        params.bounds_sphere = v4(center, radius as f32);
                        params.bounds_box_min = [0.0, 0.0, 0.0, BOUNDS_SPHERE];
                        params.bounds_box_max = [0.0, 0.0, 0.0, m.ambient as f32];
                    }
                    Bounds::Box { min, max } => {
                        params.bounds_box_min = v4(min, BOUNDS_BOX);
                        params.bounds_box_max = v4(max, m.ambient as f32);
                    }
                }
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
                let baked = match baked.or(file) {
                    Some(b) => b,
                    None => {
                        let (b, report) = bake_for_gpu_auto(m.field.as_ref())?;
                        warnings.extend(crate::field::bake_warning(&report));
                        owned = b;
                        &owned
                    }
                };
                upload_field(ctx, baked, &mut params)?
            }
            None => {
                params.bounds_box_max = [0.0, 0.0, 0.0, 1.0];
                empty_field(ctx, &mut params)?
            }
        };

        let device = &ctx.device;
        let limits = ctx.limits();
        let rows_per_band = (PIXELS_PER_BAND / s.width.max(1)).clamp(1, s.height.max(1));
        let out_bytes =
            u64::from(s.width) * u64::from(rows_per_band) * std::mem::size_of::<PixelOut>() as u64;
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

        // Split the frame in two passes when there is a medium (PASS_FIRST without the
        // march, PASS_MEDIUM over the pixels whose paths reach it), unless shadow rays
        // bend through the medium: then every diffuse surface's light needs the march.
        let split = scene.medium.is_some() && !s.bend_shadow_rays;
        ctx.scoped("creating the render pipeline", || {
            use wgpu::util::DeviceExt;
            let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("render.wgsl"),
                source: wgpu::ShaderSource::Wgsl(shaders::RENDER_WGSL.into()),
            });
            let layout_entries = render_layout_entries();
            let bind_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("render bindings"),
                entries: &layout_entries,
            });
            let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("render"),
                bind_group_layouts: &[Some(&bind_layout)],
                immediate_size: 0,
            });
            let make = |pass: u32, entry: &str| {
                let constants = pipeline_constants(&params, pass);
                device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                    label: Some(entry),
                    layout: Some(&layout),
                    module: &module,
                    entry_point: Some(entry),
                    compilation_options: wgpu::PipelineCompilationOptions {
                        constants: &constants,
                        zero_initialize_workgroup_memory: false,
                    },
                    cache: None,
                })
            };
            let (pipeline, medium_pipeline) = if split {
                (
                    make(PASS_FIRST, "render_main"),
                    Some(make(PASS_MEDIUM, "render_deferred")),
                )
            } else {
                (make(PASS_ALL, "render_main"), None)
            };
            let params_buffer = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("frame params"),
                size: std::mem::size_of::<FrameParams>() as u64,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
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
            let env_tex = device.create_texture_with_data(
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
            );
            let out_buffer = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("pixels"),
                size: out_bytes,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            });
            let readback = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("pixels readback"),
                size: out_bytes,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
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
            let field_view = field
                .field
                .create_view(&wgpu::TextureViewDescriptor::default());
            let macro_view = field
                .macro_cells
                .create_view(&wgpu::TextureViewDescriptor::default());
            let env_view = env_tex.create_view(&wgpu::TextureViewDescriptor::default());
            let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("render bindings"),
                layout: &bind_layout,
                entries: &[
                    wgpu::BindGroupEntry {
                        binding: 0,
                        resource: params_buffer.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 1,
                        resource: objects_buffer.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 2,
                        resource: lights_buffer.as_entire_binding(),
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
                    wgpu::BindGroupEntry {
                        binding: 6,
                        resource: out_buffer.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 7,
                        resource: deferred.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 8,
                        resource: deferred_count.as_entire_binding(),
                    },
                ],
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
                out_buffer,
                readback,
                rows_per_band,
                field,
                warnings,
            }
        })
    }

    /// `name (backend, device type)` of the adapter.
    pub fn adapter_info(&self) -> String {
        self.ctx.adapter_name()
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
        let [width, height, ..] = self.params.image;
        let mut pixels = grin_field::alloc::try_with_capacity(
            width as usize * height as usize,
            &format!("a {width}x{height} frame"),
        )
        .map_err(|e| GpuError::Memory(e.to_string()))?;
        let mut row = 0;
        while row < height {
            if cancel.load(Ordering::Relaxed) {
                return Err(GpuError::Cancelled);
            }
            let rows = self.rows_per_band.min(height - row);
            let band = self.render_band(row, rows)?;
            pixels.extend(band.into_iter().map(PixelOut::to_cpu));
            row += rows;
            progress(rows);
        }
        Ok(Frame {
            width,
            height,
            pixels,
        })
    }

    /// Render and time the whole frame (for benchmarks).
    pub fn render_timed(&self) -> Result<(Frame, RenderTiming), GpuError> {
        let start = Instant::now();
        let frame = self.render(&|_| {}, &AtomicBool::new(false))?;
        Ok((
            frame,
            RenderTiming {
                seconds: start.elapsed().as_secs_f64(),
            },
        ))
    }

    /// The adapter's raw rate of field samples (trilinear, 8 textureLoads each) on this
    /// renderer's field texture, measured by shaders/texture_bench.wgsl: coherent rays
    /// across the grid, no integrator or scene work. Best of `repeats` dispatches.
    pub fn field_sample_rate(&self, repeats: u32) -> Result<f64, GpuError> {
        let ctx = self.ctx;
        let device = &ctx.device;
        let width = self.params.image[0];
        let rows = self.rows_per_band;
        let mut params = self.params;
        params.rows[0] = 0;
        params.rows[1] = rows;
        let (pipeline, bind_group, params_buffer) =
            ctx.scoped("creating the texture microbenchmark", || {
                let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                    label: Some("texture_bench.wgsl"),
                    source: wgpu::ShaderSource::Wgsl(shaders::TEXTURE_BENCH_WGSL.into()),
                });
                let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                    label: Some("bench_main"),
                    layout: None,
                    module: &module,
                    entry_point: Some("bench_main"),
                    compilation_options: wgpu::PipelineCompilationOptions::default(),
                    cache: None,
                });
                let params_buffer = device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("bench params"),
                    size: std::mem::size_of::<FrameParams>() as u64,
                    usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                });
                let field_view = self
                    .field
                    .field
                    .create_view(&wgpu::TextureViewDescriptor::default());
                let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("bench bindings"),
                    layout: &pipeline.get_bind_group_layout(0),
                    entries: &[
                        wgpu::BindGroupEntry {
                            binding: 0,
                            resource: params_buffer.as_entire_binding(),
                        },
                        wgpu::BindGroupEntry {
                            binding: 3,
                            resource: wgpu::BindingResource::TextureView(&field_view),
                        },
                        wgpu::BindGroupEntry {
                            binding: 6,
                            resource: self.out_buffer.as_entire_binding(),
                        },
                    ],
                });
                (pipeline, bind_group, params_buffer)
            })?;
        ctx.queue
            .write_buffer(&params_buffer, 0, bytemuck::bytes_of(&params));
        let mut best = f64::INFINITY;
        for _ in 0..repeats.max(1) {
            let start = Instant::now();
            ctx.scoped("dispatching the texture microbenchmark", || {
                let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("bench"),
                });
                {
                    let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                        label: Some("bench_main"),
                        timestamp_writes: None,
                    });
                    pass.set_pipeline(&pipeline);
                    pass.set_bind_group(0, &bind_group, &[]);
                    pass.dispatch_workgroups(
                        width.div_ceil(WORKGROUP),
                        rows.div_ceil(WORKGROUP),
                        1,
                    );
                }
                ctx.queue.submit([encoder.finish()]);
            })?;
            ctx.wait()?;
            best = best.min(start.elapsed().as_secs_f64());
        }
        let samples = f64::from(width) * f64::from(rows) * f64::from(TEXTURE_BENCH_SAMPLES);
        Ok(samples / best)
    }

    fn render_band(&self, first_row: u32, rows: u32) -> Result<Vec<PixelOut>, GpuError> {
        let ctx = self.ctx;
        let width = self.params.image[0];
        let mut params = self.params;
        params.rows[0] = first_row;
        params.rows[1] = rows;
        let bytes = u64::from(width) * u64::from(rows) * std::mem::size_of::<PixelOut>() as u64;
        ctx.scoped("dispatching the render kernel", || {
            ctx.queue
                .write_buffer(&self.params_buffer, 0, bytemuck::bytes_of(&params));
            let mut encoder = ctx
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("render band"),
                });
            if self.medium_pipeline.is_some() {
                ctx.queue.write_buffer(
                    &self.deferred_count,
                    0,
                    bytemuck::cast_slice(&[0u32, 1, 1, 0]),
                );
            }
            {
                let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("render_main"),
                    timestamp_writes: None,
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
                    timestamp_writes: None,
                });
                pass.set_pipeline(medium);
                pass.set_bind_group(0, &self.bind_group, &[]);
                pass.dispatch_workgroups_indirect(&self.deferred_dispatch, 0);
            }
            encoder.copy_buffer_to_buffer(&self.out_buffer, 0, &self.readback, 0, bytes);
            ctx.queue.submit([encoder.finish()]);
        })?;
        read_buffer(ctx, &self.readback, bytes)
    }
}

/// The kernel's pipeline-overridable constants (shaders/shared/types.wgsl), from the
/// filled-in `params`: the compiler then drops every unused integrator and feature.
fn pipeline_constants(params: &FrameParams, pass: u32) -> Vec<(&'static str, f64)> {
    vec![
        ("PASS", f64::from(pass)),
        ("INTEGRATOR", f64::from(params.march[0])),
        ("STEP_POLICY", f64::from(params.march[1])),
        ("FLAGS", f64::from(params.march[3])),
        (
            "BOUNDS_BOX",
            if params.bounds_box_min[3] == BOUNDS_BOX {
                1.0
            } else {
                0.0
            },
        ),
        (
            "SKY_MAP",
            if params.sky_horizon[3] == SKY_MAP {
                1.0
            } else {
                0.0
            },
        ),
    ]
}

/// Map `buffer` (MAP_READ), copy out its first `bytes` as pixels, unmap.
pub(crate) fn read_buffer(
    ctx: &GpuContext,
    buffer: &wgpu::Buffer,
    bytes: u64,
) -> Result<Vec<PixelOut>, GpuError> {
    let slice = buffer.slice(0..bytes);
    let (tx, rx) = std::sync::mpsc::channel();
    slice.map_async(wgpu::MapMode::Read, move |r| {
        let _ = tx.send(r);
    });
    ctx.wait()?;
    match rx.recv() {
        Ok(Ok(())) => {}
        Ok(Err(e)) => return Err(GpuError::DeviceLost(format!("reading pixels back: {e}"))),
        Err(_) => {
            return Err(GpuError::DeviceLost(
                "reading pixels back: map callback dropped".into(),
            ));
        }
    }
    let out = {
        let view = slice
            .get_mapped_range()
            .map_err(|e| GpuError::DeviceLost(format!("reading pixels back: {e}")))?;
        bytemuck::cast_slice::<u8, PixelOut>(&view).to_vec()
    };
    buffer.unmap();
    Ok(out)
}

use bytemuck::Zeroable;
