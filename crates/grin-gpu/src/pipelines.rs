//! The render kernel's bind group layout and pipeline-overridable constants (keep in
//! sync with shaders/shared/bindings.wgsl and types.wgsl).

use crate::gpu_data::*;

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

/// The kernel's pipeline-overridable constants (shaders/shared/types.wgsl), from the
/// filled-in `params`: the compiler then drops every unused integrator and feature.
pub(crate) fn pipeline_constants(params: &FrameParams, pass: u32) -> Vec<(&'static str, f64)> {
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
