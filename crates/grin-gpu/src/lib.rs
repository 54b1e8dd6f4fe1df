//! GPU rendering with wgpu: device, textures, the WGSL RK marcher, readback.
//!
//! The entry point is [`GpuRenderer`]: build a [`grin_render::scene::RenderScene`] (every
//! scene check happens there, before any GPU work), a [`GpuContext`], and call
//!
//! ```ignore
//! let ctx = GpuContext::new_headless()?;
//! let gpu = GpuRenderer::new(&ctx, &render_scene, baked.as_ref())?; // Option<&BakedField>
//! let frame = gpu.render(&|rows| bar.inc(rows.into()), &cancel)?;   // grin_render::image::Frame
//! ```
//!
//! The frame has exactly the CPU renderer's layout ([`grin_render::image::PixelOut`]), so
//! `grin render --backend gpu` writes it with the same EXR/PNG code. Media are marched
//! through a baked grid (a 3D texture): pass the scene's [`BakedField`] if it has one,
//! or `None` and the analytic field is baked here (see [`field::bake_for_gpu`]).
//!
//! Every WGSL kernel in `shaders/` has a CPU twin of the same name in
//! `grin_trace::render` (`trace_path`, `march_medium`, `exit_medium`, `cross_boundary`,
//! `sky_radiance`, `intersect_scene`, ...); `tests/` compares their images, and
//! [`stages`] runs the marcher's stages one by one on batches of states for
//! `tests/stages.rs` to hold against their CPU twins.
//!
//! [`BakedField`]: grin_field::baked::BakedField

mod bench;
pub mod cache;
pub mod channels;
pub mod device;
pub mod error;
pub mod field;
pub mod gpu_data;
pub mod march;
mod pack;
pub mod pipeline_cache;
mod pipelines;
pub mod render;
pub mod shaders;
mod specialize;
pub mod stages;
pub mod view;

pub use device::{GpuContext, describe_adapter};
pub use error::GpuError;
pub use field::GpuGrid;
pub use march::GpuRayTracer;
pub use render::GpuRenderer;
pub use view::ViewImage;
