//! The render kernel's bind group layout and pipeline-overridable constants (keep in
//! sync with shaders/shared/bindings.wgsl and types.wgsl).

use crate::gpu_data::*;

/// A compute-stage storage buffer binding (`read_only` or read-write).
pub(crate) fn storage_entry(binding: u32, read_only: bool) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only },
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

/// Bind group entries, each `(binding, resource)`.
pub(crate) fn bind_entries<'a, const N: usize>(
    entries: [(u32, wgpu::BindingResource<'a>); N],
) -> [wgpu::BindGroupEntry<'a>; N] {
    entries.map(|(binding, resource)| wgpu::BindGroupEntry { binding, resource })
}

/// The render kernels' bindings (shaders/shared/bindings.wgsl), one layout for both
/// passes.
pub(crate) fn render_layout_entries() -> Vec<wgpu::BindGroupLayoutEntry> {
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
        buffer(0, storage(true)),
        buffer(1, storage(true)),
        buffer(2, storage(true)),
        texture(3, wgpu::TextureViewDimension::D3),
        texture(4, wgpu::TextureViewDimension::D3),
        texture(5, wgpu::TextureViewDimension::D2),
        buffer(6, storage(false)),
        buffer(7, storage(false)),
        buffer(8, storage(false)),
        buffer(9, storage(false)),
    ]
}

/// The kernel's pipeline-overridable constants (shaders/shared/types.wgsl), from the
/// filled-in `params`: the compiler then drops every unused integrator and feature.
pub(crate) fn pipeline_constants(params: &FrameParams, pass: u32) -> Vec<(&'static str, f64)> {
    let flag = |on: bool| if on { 1.0 } else { 0.0 };
    vec![
        ("PASS", f64::from(pass)),
        ("INTEGRATOR", f64::from(params.integrator)),
        ("STEP_POLICY", f64::from(params.step_policy)),
        ("FLAGS", f64::from(params.flags)),
        ("BOUNDS_BOX", flag(params.bounds_kind == BOUNDS_KIND_BOX)),
        ("SKY_MAP", flag(params.sky_kind == SKY_KIND_MAP)),
        ("SKY_PLATE", flag(params.sky_kind == SKY_KIND_PLATE)),
    ]
}
