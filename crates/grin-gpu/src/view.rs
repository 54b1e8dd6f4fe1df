//! The viewer's image on the device: the accumulation of a view's frames and the texture
//! a window draws, so a frame reaches the screen without crossing to the CPU.
//!
//! [`GpuRenderer::render_to_view`](crate::GpuRenderer::render_to_view) adds each band of
//! the render kernel's pixels to [`ViewImage`]'s accumulation (`view_accumulate`,
//! shaders/view.wgsl) instead of reading them back, then colours the AOV asked for into
//! the texture (`view_scale`, `view_colour`, as `grin_view::display` colours a [`Frame`]),
//! all in the frame's one submission where it is one band; [`ViewImage::show`] colours it
//! again in another AOV. The device counts the frames' steps, evaluations and loop-limit
//! suspects from one read of those statistics (32 bytes) to the next, so a frame reads
//! nothing back unless its caller asks for them (the viewer: a few times a second).
//! Pixels are read back only when asked ([`ViewImage::read_frame`],
//! [`ViewImage::read_display`]: a screenshot, an export, a test), and counted apart
//! ([`ViewImage::pixel_bytes_read_back`]).
//!
//! Over 600 lines: one concept, the image's buffers and the passes and read-backs on them.

use std::sync::atomic::{AtomicU32, AtomicU64, Ordering};

use grin_render::image::Frame;

use crate::gpu_data::PixelOut;
use crate::pipelines::bind_entries;
use crate::render::read_buffer;
use crate::{GpuContext, GpuError, shaders};

/// `stats` indices (shaders/shared/counts.wgsl's COUNT_*, view.wgsl's STAT_SCALE).
const STAT_STEPS: usize = 0;
const STAT_EVALS: usize = 2;
const STAT_SUSPECTS: usize = 4;
const STAT_SCALE: usize = 5;
/// Bytes of `stats` (8 u32 words).
pub const STATS_BYTES: u64 = 32;
/// Bytes of the statistics cleared after they are read (steps, evaluations, suspects).
const FRAME_STATS_BYTES: u64 = 20;

/// The texture's format: linear, filterable, writable from a compute shader everywhere.
pub const DISPLAY_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;

/// shaders/view.wgsl's `ViewParams`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct ViewParams {
    pub width: u32,
    pub height: u32,
    pub first_row: u32,
    pub rows: u32,
    pub weight: f32,
    pub inv_samples: f32,
    pub overwrite: u32,
    pub aov: u32,
    pub out_width: u32,
    pub out_height: u32,
    pub pad: [u32; 2],
}

/// What the device counted of the frames added since the statistics were last read, and
/// the image shown.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ViewStats {
    /// Frames the counts are of (added since the last read).
    pub frames: u32,
    /// Integration steps of all those frames' rays.
    pub steps: u64,
    /// Field evaluations of all those frames' rays.
    pub evals: u64,
    /// Those frames' pixels that ended `error` after at least
    /// [`crate::device::LOOP_LIMIT_SUSPECT_STEPS`] steps (lavapipe's loop limit).
    pub loop_limit_suspects: u32,
    /// The value the full colour scale of the AOV shown stands for (its largest finite
    /// magnitude; 1 for beauty and status).
    pub scale: f32,
}

/// The texture the window draws: the image scaled to fill it.
#[derive(Debug, Clone)]
pub struct DisplayTexture {
    pub texture: wgpu::Texture,
    pub view: wgpu::TextureView,
    /// Changes whenever the texture is replaced (another display size).
    pub generation: u64,
    /// The texture's size in pixels.
    pub size: [u32; 2],
}

/// The accumulation buffer and display texture of one view, on the device.
#[derive(Debug)]
pub struct ViewImage {
    accum: wgpu::Buffer,
    /// A colour a pixel of the AOV shown (view_shade), scaled into the texture.
    shaded: wgpu::Buffer,
    texture: wgpu::Texture,
    storage_view: wgpu::TextureView,
    /// Pixels the accumulation holds.
    capacity: u64,
    /// The texture's size.
    display: [u32; 2],
    generation: u64,
    /// The accumulate pass's parameters, and the colour passes' (one submission may
    /// hold both).
    params: wgpu::Buffer,
    colour_params: wgpu::Buffer,
    stats: wgpu::Buffer,
    stats_readback: wgpu::Buffer,
    /// Bound as the band in passes that read none.
    no_band: wgpu::Buffer,
    layout: wgpu::BindGroupLayout,
    accumulate: wgpu::ComputePipeline,
    scale: wgpu::ComputePipeline,
    shade: wgpu::ComputePipeline,
    colour: wgpu::ComputePipeline,
    /// The image's size and samples accumulated.
    size: [u32; 2],
    samples: u32,
    /// The frame being added: its samples per pixel, and whether it starts the image.
    frame_samples: u32,
    frame_overwrites: bool,
    /// Frames added since the statistics were last read (0: clear them first).
    frames_counted: AtomicU32,
    /// Bytes of statistics read back so far.
    stats_read: AtomicU64,
    /// Bytes of pixels read back so far (exports and tests only).
    pixels_read: AtomicU64,
}

impl ViewImage {
    /// Pipelines and buffers for an image of `width` x `height` shown at that size (see
    /// [`Self::reserve`]).
    pub fn new(ctx: &GpuContext, width: u32, height: u32) -> Result<Self, GpuError> {
        let device = &ctx.device;
        ctx.scoped("creating the viewer's image", || {
            let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("view.wgsl"),
                source: wgpu::ShaderSource::Wgsl(shaders::VIEW_WGSL.into()),
            });
            let storage = crate::pipelines::storage_entry;
            let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("view bindings"),
                entries: &[
                    storage(0, true),
                    storage(1, true),
                    storage(2, false),
                    storage(3, false),
                    storage(5, false),
                    wgpu::BindGroupLayoutEntry {
                        binding: 4,
                        visibility: wgpu::ShaderStages::COMPUTE,
                        ty: wgpu::BindingType::StorageTexture {
                            access: wgpu::StorageTextureAccess::WriteOnly,
                            format: DISPLAY_FORMAT,
                            view_dimension: wgpu::TextureViewDimension::D2,
                        },
                        count: None,
                    },
                ],
            });
            let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("view"),
                bind_group_layouts: &[Some(&layout)],
                immediate_size: 0,
            });
            let pipeline = |entry: &str| {
                device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                    label: Some(entry),
                    layout: Some(&pipeline_layout),
                    module: &module,
                    entry_point: Some(entry),
                    // Workgroup memory zeroed: view_accumulate's sums start at 0.
                    compilation_options: wgpu::PipelineCompilationOptions::default(),
                    cache: ctx.pipeline_cache(),
                })
            };
            let buffer = |label, size, usage| {
                device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size,
                    usage,
                    mapped_at_creation: false,
                })
            };
            use wgpu::BufferUsages as U;
            let display = [width.max(1), height.max(1)];
            let capacity = u64::from(display[0]) * u64::from(display[1]);
            let (texture, storage_view) = display_texture(ctx, display);
            ViewImage {
                accum: accumulation(ctx, capacity),
                shaded: shaded(ctx, capacity),
                texture,
                storage_view,
                capacity,
                display,
                generation: 0,
                params: buffer(
                    "view params",
                    std::mem::size_of::<ViewParams>() as u64,
                    U::STORAGE | U::COPY_DST,
                ),
                colour_params: buffer(
                    "view colour params",
                    std::mem::size_of::<ViewParams>() as u64,
                    U::STORAGE | U::COPY_DST,
                ),
                stats: buffer(
                    "view stats",
                    STATS_BYTES,
                    U::STORAGE | U::COPY_SRC | U::COPY_DST,
                ),
                stats_readback: buffer(
                    "view stats readback",
                    STATS_BYTES,
                    U::MAP_READ | U::COPY_DST,
                ),
                no_band: buffer("view no band", 64, U::STORAGE),
                accumulate: pipeline("view_accumulate"),
                scale: pipeline("view_scale"),
                shade: pipeline("view_shade"),
                colour: pipeline("view_colour"),
                layout,
                size: [0, 0],
                samples: 0,
                frame_samples: 0,
                frame_overwrites: true,
                frames_counted: AtomicU32::new(0),
                stats_read: AtomicU64::new(0),
                pixels_read: AtomicU64::new(0),
            }
        })
    }

    /// Make room for an image of `width` x `height` shown at `display` pixels: a bigger
    /// accumulation when it holds fewer pixels (the image starts again), a new texture
    /// (another [`DisplayTexture::generation`]) when the display size changes.
    pub fn reserve(
        &mut self,
        ctx: &GpuContext,
        width: u32,
        height: u32,
        display: [u32; 2],
    ) -> Result<(), GpuError> {
        let pixels = u64::from(width) * u64::from(height);
        let display = [display[0].max(1), display[1].max(1)];
        if pixels > self.capacity {
            (self.accum, self.shaded) = ctx.scoped("allocating the viewer's image", || {
                (accumulation(ctx, pixels), shaded(ctx, pixels))
            })?;
            self.capacity = pixels;
            self.samples = 0;
        }
        if display != self.display {
            let (texture, view) = ctx.scoped("allocating the viewer's texture", || {
                display_texture(ctx, display)
            })?;
            self.texture = texture;
            self.storage_view = view;
            self.display = display;
            self.generation += 1;
        }
        Ok(())
    }

    /// The texture the window draws, for the image last shown.
    pub fn display_texture(&self) -> DisplayTexture {
        DisplayTexture {
            texture: self.texture.clone(),
            view: self
                .texture
                .create_view(&wgpu::TextureViewDescriptor::default()),
            generation: self.generation,
            size: self.display,
        }
    }

    /// The image's size (the last frame's).
    pub fn size(&self) -> [u32; 2] {
        self.size
    }

    /// Samples per pixel accumulated.
    pub fn samples(&self) -> u32 {
        self.samples
    }

    /// Bytes of statistics read back so far (32 a read).
    pub fn stats_bytes_read_back(&self) -> u64 {
        self.stats_read.load(Ordering::Relaxed)
    }

    /// Bytes of pixels read back so far: only by [`Self::read_frame`] and
    /// [`Self::read_display`], never by a frame.
    pub fn pixel_bytes_read_back(&self) -> u64 {
        self.pixels_read.load(Ordering::Relaxed)
    }

    /// Start an image of `width` x `height` (`overwrite`) or add a frame of `samples` to
    /// the one accumulated.
    pub(crate) fn begin_frame(&mut self, width: u32, height: u32, overwrite: bool, samples: u32) {
        if overwrite {
            self.samples = 0;
        }
        self.frame_samples = samples;
        self.frame_overwrites = overwrite;
        self.size = [width, height];
        self.samples += samples;
    }

    /// Drop what the statistics counted since the last read (a frame cut short, another
    /// method's frames): the next frame clears them.
    pub fn discard_stats(&self) {
        self.frames_counted.store(0, Ordering::Relaxed);
    }

    /// Start counting a frame's statistics, in `encoder` (before its first band): after
    /// a read, clear them first; else the frame adds to what was counted since.
    pub(crate) fn encode_clear(&self, encoder: &mut wgpu::CommandEncoder) {
        if self.frames_counted.fetch_add(1, Ordering::Relaxed) == 0 {
            encoder.clear_buffer(&self.stats, 0, Some(FRAME_STATS_BYTES));
        }
    }

    /// Add `band` (render_main's pixels of rows `first_row .. first_row + rows`) of the
    /// frame [`Self::begin_frame`] started, weighted by its samples, in `encoder`.
    /// `params` is written now: submit the encoder before the next band's.
    pub(crate) fn accumulate_band(
        &self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        band: &wgpu::Buffer,
        first_row: u32,
        rows: u32,
    ) {
        let params = ViewParams {
            width: self.size[0],
            height: self.size[1],
            first_row,
            rows,
            weight: self.frame_samples as f32,
            inv_samples: 0.0,
            overwrite: u32::from(self.frame_overwrites),
            aov: 0,
            out_width: self.display[0],
            out_height: self.display[1],
            pad: [0; 2],
        };
        ctx.queue
            .write_buffer(&self.params, 0, bytemuck::bytes_of(&params));
        let bind = self.bind_group(ctx, &self.params, band);
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("view_accumulate"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&self.accumulate);
        pass.set_bind_group(0, &bind, &[]);
        pass.dispatch_workgroups((self.size[0] * rows).div_ceil(64), 1, 1);
    }

    fn bind_group(
        &self,
        ctx: &GpuContext,
        params: &wgpu::Buffer,
        band: &wgpu::Buffer,
    ) -> wgpu::BindGroup {
        ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("view bindings"),
            layout: &self.layout,
            entries: &bind_entries([
                (0, params.as_entire_binding()),
                (1, band.as_entire_binding()),
                (2, self.accum.as_entire_binding()),
                (3, self.stats.as_entire_binding()),
                (4, wgpu::BindingResource::TextureView(&self.storage_view)),
                (5, self.shaded.as_entire_binding()),
            ]),
        })
    }

    /// Colour AOV `aov` (grin_view::display::Aov's index: beauty, deflection, steps, opd,
    /// status) of the accumulated image into the texture, and read back the statistics
    /// (32 bytes; waits for the device). Like every read, it restarts the counts: the
    /// next frame clears them.
    pub fn show(&self, ctx: &GpuContext, aov: u32) -> Result<ViewStats, GpuError> {
        if self.size[0] == 0 || self.size[1] == 0 {
            return Err(GpuError::DeviceLost("no image to show".into()));
        }
        ctx.scoped("colouring the viewer's image", || {
            let mut encoder = ctx
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("view colour"),
                });
            self.encode_show(ctx, &mut encoder, aov, true);
            ctx.queue.submit([encoder.finish()]);
        })?;
        self.read_stats(ctx, aov)
    }

    /// The colour passes of [`Self::show`] and, with `copy_stats`, the copy of the
    /// statistics to read, in `encoder` (after the frame's last band: one submission a
    /// frame).
    pub(crate) fn encode_show(
        &self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        aov: u32,
        copy_stats: bool,
    ) {
        let [width, height] = self.size;
        let params = ViewParams {
            width,
            height,
            first_row: 0,
            rows: height,
            weight: 0.0,
            inv_samples: 1.0 / self.samples.max(1) as f32,
            overwrite: 0,
            aov,
            out_width: self.display[0],
            out_height: self.display[1],
            pad: [0; 2],
        };
        ctx.queue
            .write_buffer(&self.colour_params, 0, bytemuck::bytes_of(&params));
        let bind = self.bind_group(ctx, &self.colour_params, &self.no_band);
        encoder.clear_buffer(&self.stats, STAT_SCALE as u64 * 4, Some(4));
        let [out_w, out_h] = self.display;
        for (label, pipeline, [w, h]) in [
            ("view_scale", &self.scale, [width, height]),
            ("view_shade", &self.shade, [width, height]),
            ("view_colour", &self.colour, [out_w, out_h]),
        ] {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some(label),
                timestamp_writes: None,
            });
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, &bind, &[]);
            pass.dispatch_workgroups(w.div_ceil(8), h.div_ceil(8), 1);
        }
        if copy_stats {
            encoder.copy_buffer_to_buffer(&self.stats, 0, &self.stats_readback, 0, STATS_BYTES);
        }
    }

    /// The statistics copied by [`Self::encode_show`] (waits for its submission); the
    /// next frame starts counting afresh.
    pub(crate) fn read_stats(&self, ctx: &GpuContext, aov: u32) -> Result<ViewStats, GpuError> {
        let words: Vec<u32> = read_buffer(ctx, &self.stats_readback, STATS_BYTES)?;
        self.stats_read.fetch_add(STATS_BYTES, Ordering::Relaxed);
        let frames = self.frames_counted.swap(0, Ordering::Relaxed);
        let wide = |at: usize| u64::from(words[at]) | (u64::from(words[at + 1]) << 32);
        let scale = match aov {
            1..=3 => f32::from_bits(words[STAT_SCALE]),
            _ => 1.0,
        };
        Ok(ViewStats {
            frames,
            steps: wide(STAT_STEPS),
            evals: wide(STAT_EVALS),
            loop_limit_suspects: words[STAT_SUSPECTS],
            scale,
        })
    }

    /// The accumulated image as a frame (mean radiance, steps and evaluations; the other
    /// AOVs of its first frame), read back from the device: for screenshots and exports.
    pub fn read_frame(&self, ctx: &GpuContext) -> Result<Frame, GpuError> {
        let [width, height] = self.size;
        let n = u64::from(width) * u64::from(height);
        let bytes = n * std::mem::size_of::<PixelOut>() as u64;
        let sums: Vec<PixelOut> = self.read_copied(ctx, "the viewer's image", bytes, |e, to| {
            e.copy_buffer_to_buffer(&self.accum, 0, to, 0, bytes);
        })?;
        let inv = 1.0 / self.samples.max(1) as f32;
        let pixels = sums
            .into_iter()
            .map(|p| {
                let mut out = p.to_cpu();
                out.rgb = p.rgb.map(|c| c * inv);
                out.steps = p.steps * inv;
                out.evals = p.evals * inv;
                out
            })
            .collect();
        Ok(Frame {
            width,
            height,
            pixels,
        })
    }

    /// The texture as last shown: linear RGBA per texel, row by row (read back; for
    /// tests).
    pub fn read_display(&self, ctx: &GpuContext) -> Result<Vec<[f32; 4]>, GpuError> {
        let [width, height] = self.display;
        let row_bytes = u64::from(width) * 8;
        let padded = row_bytes.div_ceil(256) * 256;
        let bytes = padded * u64::from(height);
        let halves: Vec<u16> = self.read_copied(ctx, "the viewer's texture", bytes, |e, to| {
            e.copy_texture_to_buffer(
                wgpu::TexelCopyTextureInfo {
                    texture: &self.texture,
                    mip_level: 0,
                    origin: wgpu::Origin3d::ZERO,
                    aspect: wgpu::TextureAspect::All,
                },
                wgpu::TexelCopyBufferInfo {
                    buffer: to,
                    layout: wgpu::TexelCopyBufferLayout {
                        offset: 0,
                        bytes_per_row: Some(padded as u32),
                        rows_per_image: Some(height),
                    },
                },
                wgpu::Extent3d {
                    width,
                    height,
                    depth_or_array_layers: 1,
                },
            );
        })?;
        let per_row = (padded / 2) as usize;
        let mut out = Vec::with_capacity(width as usize * height as usize);
        for row in halves.chunks(per_row) {
            for px in row[..width as usize * 4].chunks(4) {
                out.push([
                    f16_to_f32(px[0]),
                    f16_to_f32(px[1]),
                    f16_to_f32(px[2]),
                    f16_to_f32(px[3]),
                ]);
            }
        }
        Ok(out)
    }
}

impl ViewImage {
    /// `bytes` of `what`, copied by `copy` into a mappable buffer and read back (counted
    /// as pixels read).
    fn read_copied<T: bytemuck::Pod>(
        &self,
        ctx: &GpuContext,
        what: &str,
        bytes: u64,
        copy: impl FnOnce(&mut wgpu::CommandEncoder, &wgpu::Buffer),
    ) -> Result<Vec<T>, GpuError> {
        let readback = ctx.scoped(&format!("reading {what} back"), || {
            let readback = ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("view readback"),
                size: bytes.max(4),
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            let mut encoder = ctx
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("view readback"),
                });
            copy(&mut encoder, &readback);
            ctx.queue.submit([encoder.finish()]);
            readback
        })?;
        let out = read_buffer(ctx, &readback, bytes)?;
        self.pixels_read.fetch_add(bytes, Ordering::Relaxed);
        Ok(out)
    }
}

/// An accumulation of `pixels` pixels.
fn accumulation(ctx: &GpuContext, pixels: u64) -> wgpu::Buffer {
    ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("view accumulation"),
        size: pixels.max(1) * std::mem::size_of::<PixelOut>() as u64,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    })
}

/// A colour (4 f32) for each of `pixels` pixels.
fn shaded(ctx: &GpuContext, pixels: u64) -> wgpu::Buffer {
    ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("view colours"),
        size: pixels.max(1) * 16,
        usage: wgpu::BufferUsages::STORAGE,
        mapped_at_creation: false,
    })
}

/// The display texture of `size` texels, and its view for the colour pass.
fn display_texture(ctx: &GpuContext, size: [u32; 2]) -> (wgpu::Texture, wgpu::TextureView) {
    let texture = ctx.device.create_texture(&wgpu::TextureDescriptor {
        label: Some("view display"),
        size: wgpu::Extent3d {
            width: size[0],
            height: size[1],
            depth_or_array_layers: 1,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: DISPLAY_FORMAT,
        usage: wgpu::TextureUsages::STORAGE_BINDING
            | wgpu::TextureUsages::TEXTURE_BINDING
            | wgpu::TextureUsages::COPY_SRC,
        view_formats: &[],
    });
    let view = texture.create_view(&wgpu::TextureViewDescriptor::default());
    (texture, view)
}

/// An IEEE half as f32.
fn f16_to_f32(h: u16) -> f32 {
    let sign = if h & 0x8000 != 0 { -1.0 } else { 1.0 };
    let exp = i32::from((h >> 10) & 0x1f);
    let frac = f32::from(h & 0x3ff);
    sign * match exp {
        0 => frac * 2f32.powi(-24),
        31 if frac == 0.0 => f32::INFINITY,
        31 => f32::NAN,
        e => (1.0 + frac / 1024.0) * 2f32.powi(e - 15),
    }
}

#[cfg(test)]
mod tests {
    use super::f16_to_f32;

    #[test]
    fn halves_decode() {
        assert_eq!(f16_to_f32(0x3c00), 1.0);
        assert_eq!(f16_to_f32(0xc000), -2.0);
        assert_eq!(f16_to_f32(0x3555), 0.333_251_95);
        assert_eq!(f16_to_f32(0x0001), 2f32.powi(-24));
        assert!(f16_to_f32(0x7c00).is_infinite());
        assert!(f16_to_f32(0x7e00).is_nan());
    }
}
