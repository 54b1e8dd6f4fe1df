//! GPU rendering with wgpu: device, textures, the WGSL RK marcher, readback.
