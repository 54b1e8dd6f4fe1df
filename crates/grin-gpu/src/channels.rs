//! The channels a render reads back: [`Channels`], the words of a pixel an output is made
//! of, and [`FrameTotals`], the counts its summary needs, added up on the device.
//!
//! The render kernel writes 64 bytes a pixel (the beauty and every AOV). An `[optics]`
//! output is made of a few of them (a schlieren image of the exit direction and position
//! and the status, 28 bytes; an interferogram of the optical path to the plane, 4), so
//! [`crate::GpuRenderer::render_channels`] packs the chosen words on the device
//! (`channels_pack`, shaders/channels.wgsl) and reads back only those, f32 as written
//! (exactly the values a whole read gives), with the frame's steps, evaluations, loop-limit
//! suspects and pixels of each status (64 bytes a frame).

use grin_render::image::Frame;

use crate::gpu_data::PixelOut;
use crate::pipelines::{bind_entries, storage_entry};
use crate::render::read_buffer;
use crate::{GpuContext, GpuError, shaders};

/// Words of [`PixelOut`] a render reads back, as a mask (bit `i`: word `i`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Channels(u16);

impl Channels {
    /// Every channel of the pixel: read back whole, as it is written (64 bytes).
    pub const ALL: Self = Self(0x7fff);
    /// No channel (the counts alone).
    pub const NONE: Self = Self(0);
    /// The beauty's red, green and blue.
    pub const RGB: Self = Self(0b111);
    /// The beauty's red alone (the BOS images are grey).
    pub const RED: Self = Self(0b1);
    pub const DEFLECTION: Self = Self(1 << 3);
    pub const EXIT_DIR: Self = Self(0b111 << 4);
    pub const OPD: Self = Self(1 << 7);
    pub const STEPS: Self = Self(1 << 8);
    pub const EVALS: Self = Self(1 << 9);
    pub const STATUS: Self = Self(1 << 10);
    pub const EXIT_POS: Self = Self(0b111 << 11);
    pub const OPD_PLANE: Self = Self(1 << 14);

    /// The channels of both.
    pub const fn and(self, other: Self) -> Self {
        Self(self.0 | other.0)
    }

    /// Whether every channel of `other` is read.
    pub const fn contains(self, other: Self) -> bool {
        self.0 & other.0 == other.0
    }

    /// Words read back a pixel.
    pub fn words(self) -> u32 {
        self.0.count_ones()
    }

    /// Bytes read back a pixel: 64 for [`Self::ALL`] (the pixel as written, with its pad).
    pub fn bytes_per_pixel(self) -> u64 {
        if self == Self::ALL {
            std::mem::size_of::<PixelOut>() as u64
        } else {
            4 * u64::from(self.words())
        }
    }

    /// The words read, in order.
    fn list(self) -> impl Iterator<Item = u32> {
        (0..16u32).filter(move |i| self.0 & (1 << i) != 0)
    }

    /// A pixel from its packed words: the channels not read are NaN.
    pub(crate) fn unpack(self, words: &[f32]) -> PixelOut {
        let mut all = [f32::NAN; 16];
        for (i, &w) in self.list().zip(words) {
            all[i as usize] = w;
        }
        bytemuck::cast(all)
    }
}

/// A frame's counts over all its pixels: steps and field evaluations (over every
/// sample), pixels that ended `error` after so many steps that lavapipe's loop limit
/// likely cut them short, and pixels of each `aov.status` value.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FrameTotals {
    pub steps: u64,
    pub evals: u64,
    pub loop_limit_suspects: u64,
    pub status: [u64; 8],
}

impl FrameTotals {
    /// The totals of `frame`'s pixels (each pixel's steps and evaluations the means over
    /// its `samples`), counted as the device counts them.
    pub fn of(frame: &Frame, samples: u32) -> Self {
        let error = crate::gpu_data::STATUS_ERROR as f32;
        let mut t = Self::default();
        let whole = |v: f32| (v.max(0.0) * samples as f32).round() as u64;
        for p in &frame.pixels {
            t.steps += whole(p.steps);
            t.evals += whole(p.evals);
            if let Some(n) = t.status.get_mut(p.status.max(0.0) as usize) {
                *n += 1;
            }
            if p.status == error && p.steps >= crate::device::LOOP_LIMIT_SUSPECT_STEPS {
                t.loop_limit_suspects += 1;
            }
        }
        t
    }

    fn from_words(w: &[u32]) -> Self {
        let wide = |at: usize| u64::from(w[at]) | (u64::from(w[at + 1]) << 32);
        let mut status = [0; 8];
        for (s, &n) in status.iter_mut().zip(&w[TOTAL_STATUS..TOTAL_STATUS + 8]) {
            *s = u64::from(n);
        }
        Self {
            steps: wide(TOTAL_STEPS),
            evals: wide(TOTAL_EVALS),
            loop_limit_suspects: u64::from(w[TOTAL_SUSPECTS]),
            status,
        }
    }
}

/// `totals` indices (shaders/shared/counts.wgsl's COUNT_*, channels.wgsl's TOTAL_STATUS).
const TOTAL_STEPS: usize = 0;
const TOTAL_EVALS: usize = 2;
const TOTAL_SUSPECTS: usize = 4;
const TOTAL_STATUS: usize = 8;
/// Bytes of `totals` (16 u32 words).
pub(crate) const TOTALS_BYTES: u64 = 64;
/// Workgroups along x in one dispatch (WebGPU's guaranteed limit per dimension).
const MAX_GROUPS: u32 = 65_535;

/// shaders/channels.wgsl's `PackParams`.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct PackParams {
    pixels: u32,
    words: u32,
    samples: f32,
    pad: u32,
    word: [u32; 16],
}

/// One frame's packing: the kernel, the packed band and the totals, for bands of at most
/// `band_pixels` pixels.
pub(crate) struct Packer {
    channels: Channels,
    samples: u32,
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    params: wgpu::Buffer,
    pub(crate) packed: wgpu::Buffer,
    totals: wgpu::Buffer,
    /// The totals before the band being packed: a band packed again (its marches took
    /// more than one submission) is counted once.
    totals_before: wgpu::Buffer,
    totals_readback: wgpu::Buffer,
}

impl Packer {
    pub(crate) fn new(
        ctx: &GpuContext,
        channels: Channels,
        samples: u32,
        band_pixels: u32,
    ) -> Result<Self, GpuError> {
        let device = &ctx.device;
        ctx.scoped("creating the channel packing", || {
            let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("channels.wgsl"),
                source: wgpu::ShaderSource::Wgsl(shaders::CHANNELS_WGSL.into()),
            });
            let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("channel packing"),
                entries: &[
                    storage_entry(0, true),
                    storage_entry(1, true),
                    storage_entry(2, false),
                    storage_entry(3, false),
                ],
            });
            let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("channel packing"),
                bind_group_layouts: &[Some(&layout)],
                immediate_size: 0,
            });
            let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some("channels_pack"),
                layout: Some(&pipeline_layout),
                module: &module,
                entry_point: Some("channels_pack"),
                // Workgroup memory zeroed: the workgroup's sums start at 0.
                compilation_options: wgpu::PipelineCompilationOptions::default(),
                cache: ctx.pipeline_cache(),
            });
            let buffer = |label, size: u64, usage| {
                device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size: size.max(4),
                    usage,
                    mapped_at_creation: false,
                })
            };
            use wgpu::BufferUsages as U;
            let packed_bytes = u64::from(band_pixels) * channels.bytes_per_pixel();
            Self {
                channels,
                samples,
                pipeline,
                layout,
                params: buffer(
                    "packing params",
                    std::mem::size_of::<PackParams>() as u64,
                    U::STORAGE | U::COPY_DST,
                ),
                packed: buffer("packed pixels", packed_bytes, U::STORAGE | U::COPY_SRC),
                totals: buffer(
                    "frame totals",
                    TOTALS_BYTES,
                    U::STORAGE | U::COPY_SRC | U::COPY_DST,
                ),
                totals_before: buffer(
                    "frame totals before the band",
                    TOTALS_BYTES,
                    U::COPY_SRC | U::COPY_DST,
                ),
                totals_readback: buffer(
                    "frame totals readback",
                    TOTALS_BYTES,
                    U::MAP_READ | U::COPY_DST,
                ),
            }
        })
    }

    pub(crate) fn channels(&self) -> Channels {
        self.channels
    }

    /// Start the frame's totals at zero (before its first band's submission).
    pub(crate) fn clear_totals(&self, ctx: &GpuContext) {
        ctx.queue
            .write_buffer(&self.totals, 0, &[0u8; TOTALS_BYTES as usize]);
    }

    /// Pack `pixels` pixels of `band` into [`Self::packed`] and add them to the totals;
    /// `again`: the same band packed once more (after the rest of its marches), its
    /// first count taken back.
    pub(crate) fn encode(
        &self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        band: &wgpu::Buffer,
        pixels: u32,
        again: bool,
    ) {
        if again {
            encoder.copy_buffer_to_buffer(&self.totals_before, 0, &self.totals, 0, TOTALS_BYTES);
        } else {
            encoder.copy_buffer_to_buffer(&self.totals, 0, &self.totals_before, 0, TOTALS_BYTES);
        }
        let mut word = [0u32; 16];
        for (w, i) in word.iter_mut().zip(self.channels.list()) {
            *w = i;
        }
        let params = PackParams {
            pixels,
            words: self.channels.words(),
            samples: self.samples as f32,
            pad: 0,
            word,
        };
        ctx.queue
            .write_buffer(&self.params, 0, bytemuck::bytes_of(&params));
        let bind = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("channel packing"),
            layout: &self.layout,
            entries: &bind_entries([
                (0, self.params.as_entire_binding()),
                (1, band.as_entire_binding()),
                (2, self.packed.as_entire_binding()),
                (3, self.totals.as_entire_binding()),
            ]),
        });
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("channels_pack"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &bind, &[]);
        // Rows of at most MAX_GROUPS workgroups (the kernel reads the grid's width).
        let groups = pixels.div_ceil(64);
        pass.dispatch_workgroups(groups.min(MAX_GROUPS), groups.div_ceil(MAX_GROUPS), 1);
    }

    /// The frame's totals (after its last band): 64 bytes read back.
    pub(crate) fn read_totals(&self, ctx: &GpuContext) -> Result<FrameTotals, GpuError> {
        let mut encoder = ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("frame totals"),
            });
        encoder.copy_buffer_to_buffer(&self.totals, 0, &self.totals_readback, 0, TOTALS_BYTES);
        ctx.queue.submit([encoder.finish()]);
        let words: Vec<u32> = read_buffer(ctx, &self.totals_readback, TOTALS_BYTES)?;
        Ok(FrameTotals::from_words(&words))
    }
}
