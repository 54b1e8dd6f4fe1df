//! The WGSL kernels, assembled from shaders/ (and validated with naga) by build.rs.

/// The render kernel (`render_main`): shaders/render.wgsl with its shared imports.
pub const RENDER_WGSL: &str = include_str!(concat!(env!("OUT_DIR"), "/render.wgsl"));

/// The field-sampling microbenchmark (`bench_main`): shaders/texture_bench.wgsl.
pub const TEXTURE_BENCH_WGSL: &str = include_str!(concat!(env!("OUT_DIR"), "/texture_bench.wgsl"));

/// The test-only stage kernels (`stage_sample`, `stage_integrate`, `stage_take`,
/// `stage_leave`): shaders/stages.wgsl, run by [`crate::stages`].
pub const STAGES_WGSL: &str = include_str!(concat!(env!("OUT_DIR"), "/stages.wgsl"));

/// The viewer's image on the device (`view_accumulate`, `view_scale`, `view_colour`):
/// shaders/view.wgsl, run by [`crate::view`].
pub const VIEW_WGSL: &str = include_str!(concat!(env!("OUT_DIR"), "/view.wgsl"));

/// The channels `grin render` reads back (`channels_pack`): shaders/channels.wgsl, run by
/// [`crate::channels`].
pub const CHANNELS_WGSL: &str = include_str!(concat!(env!("OUT_DIR"), "/channels.wgsl"));
