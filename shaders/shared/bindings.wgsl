// The render kernel's resources. Bound by crates/grin-gpu/src/render.rs.

// A read-only storage buffer, not a uniform one: lavapipe compiles a new variant of a
// kernel for each new value of a uniform its branches read (it inlines them), which here
// is every band and every frame (first_row, first_sample).
@group(0) @binding(0) var<storage, read> params: FrameParams;
@group(0) @binding(1) var<storage, read> objects: array<GpuObject>;
@group(0) @binding(2) var<storage, read> lights: array<GpuLight>;
// (delta_n, dn/dx, dn/dy, dn/dz) per grid node (or their B-spline coefficients),
// rgba32float or rgba16snorm (FLAG_FIELD_SNORM), read with textureLoad (manual
// trilinear: see field.wgsl); a sparse bake's voxels as one linear array.
@group(0) @binding(3) var field_tex: texture_3d<f32>;
// max |grad n| per macro cell, r32float; a sparse bake's brick table, rgba32float.
@group(0) @binding(4) var macro_tex: texture_3d<f32>;
// Equirectangular environment map, rgba32float (1x1 when the sky is a gradient).
@group(0) @binding(5) var env_tex: texture_2d<f32>;
@group(0) @binding(6) var<storage, read_write> out_pixels: array<PixelOut>;
// Pixels (index within the band) left by PASS_FIRST for PASS_MEDIUM, and their count.
@group(0) @binding(7) var<storage, read_write> deferred: array<u32>;
@group(0) @binding(8) var<storage, read_write> deferred_pixels: DeferredPixels;
// Binding 9, PASS_MEDIUM's pixels between rounds, is declared in render.wgsl.
