//! The texture microbenchmark: the adapter's raw field sample rate on a renderer's field
//! texture (shaders/texture_bench.wgsl), what `grin bench speed` compares the marcher with.

use std::time::Instant;

use crate::gpu_data::*;
use crate::pipelines::bind_entries;
use crate::render::{GpuRenderer, WORKGROUP};
use crate::{GpuError, shaders};

/// Field samples per invocation of `bench_main` (keep in sync with BENCH_SAMPLES in
/// shaders/texture_bench.wgsl).
const TEXTURE_BENCH_SAMPLES: u32 = 256;

impl GpuRenderer<'_> {
    /// The adapter's raw rate of field samples (trilinear, 8 textureLoads each) on this
    /// renderer's field texture, measured by shaders/texture_bench.wgsl: coherent rays
    /// across the grid, no integrator or scene work. Best of `repeats` dispatches, each
    /// timed on the device where it writes timestamps, else by the wall clock.
    pub fn field_sample_rate(&self, repeats: u32) -> Result<f64, GpuError> {
        let ctx = self.ctx;
        let device = &ctx.device;
        let width = self.params.width;
        let rows = self.rows_per_band;
        let mut params = self.params;
        params.first_row = 0;
        params.row_count = rows;
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
                    usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                });
                let field_view = self
                    .field
                    .field
                    .create_view(&wgpu::TextureViewDescriptor::default());
                let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("bench bindings"),
                    layout: &pipeline.get_bind_group_layout(0),
                    entries: &bind_entries([
                        (0, params_buffer.as_entire_binding()),
                        (3, wgpu::BindingResource::TextureView(&field_view)),
                        (6, self.out_buffer.as_entire_binding()),
                    ]),
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
                        timestamp_writes: self.timer.as_ref().map(|t| t.writes(0)),
                    });
                    pass.set_pipeline(&pipeline);
                    pass.set_bind_group(0, &bind_group, &[]);
                    pass.dispatch_workgroups(
                        width.div_ceil(WORKGROUP),
                        rows.div_ceil(WORKGROUP),
                        1,
                    );
                }
                if let Some(timer) = &self.timer {
                    timer.resolve(&mut encoder, 1);
                }
                ctx.queue.submit([encoder.finish()]);
            })?;
            ctx.wait()?;
            let wall = start.elapsed().as_secs_f64();
            let seconds = match &self.timer {
                Some(timer) => timer.pass_seconds(ctx, 1)?.iter().sum(),
                None => wall,
            };
            best = best.min(seconds);
        }
        let samples = f64::from(width) * f64::from(rows) * f64::from(TEXTURE_BENCH_SAMPLES);
        Ok(samples / best)
    }
}
