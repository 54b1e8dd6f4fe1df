//! Baked fields on the GPU: the (delta_n, grad n) grid as an rgba32float 3D texture, the
//! macro-cell grid as an r32float 3D texture, and their placement in `FrameParams`.
//!
//! Format choice: rgba32float read with textureLoad and interpolated in the shader.
//! rgba16float cannot hold n itself, and even delta_n of air (~1e-5) is a half-float
//! subnormal there (spacing 6e-8: ~0.6% error, worse for heat haze's gradients);
//! float32 filtering needs the optional FLOAT32_FILTERABLE feature, and filter hardware
//! may keep only 8 fractional bits of the weights (REFERENCES.md, failure mode 2).
//! Manual trilinear costs 8 loads per sample but uses the CPU's weights exactly, so GPU
//! and CPU march the same field: the GPU-vs-CPU tests measure p99 pixel differences
//! <= 2e-5 with it. Its speed on lavapipe (`grin bench speed`, docs/benchmarks.md) is
//! ~100 M trilinear samples/s on a 2-core VM. i16-quantized baked files are decoded to f32
//! on upload.

use grin_field::IndexField;
use grin_field::bake::{
    BUDGET_SAFETY, BakeOptions, BakeReport, CANDIDATE_RESOLUTIONS, DEFAULT_ERROR_BUDGET, bake,
};
use grin_field::baked::{BakedField, Interp, Outside};

use crate::gpu_data::{FLAG_MACRO_CELLS, FLAG_OUTSIDE_AMBIENT, FLAG_TRICUBIC, FrameParams};
use crate::{GpuContext, GpuError};

/// Bytes per texel of the field texture (rgba32float).
pub const FIELD_TEXEL_BYTES: u64 = 16;

/// Grid resolution (nodes along the longest axis) used to bake an analytic field for the
/// GPU when the caller has no baked field: 128 keeps a unit sphere within ~1e-4 of the
/// analytic index for the paper's profiles (bake helper's DEFAULT_RESOLUTION).
pub const DEFAULT_GPU_BAKE_RESOLUTION: usize = grin_field::bake::DEFAULT_RESOLUTION;

/// The field's textures on the device.
#[derive(Debug)]
pub struct FieldTextures {
    pub field: wgpu::Texture,
    pub macro_cells: wgpu::Texture,
    /// Bytes uploaded (field + macro grid).
    pub bytes: u64,
    /// Node counts.
    pub dims: [u32; 3],
}

/// Bake `field` on a grid for the GPU (trilinear, f32 voxels, fixed resolution).
///
/// A fixed resolution can under-resolve a thin layer (a 128-node grid along a long, flat
/// box): when the bake's measured error is over [`DEFAULT_ERROR_BUDGET`] this prints
/// [`bake_warning`] to stderr, so an under-resolved field never renders silently wrong.
/// Use [`bake_for_gpu_with_report`] to get the report (and the warning) instead.
pub fn bake_for_gpu(field: &dyn IndexField, resolution: usize) -> Result<BakedField, GpuError> {
    let (baked, report) = bake_for_gpu_with_report(field, resolution)?;
    if let Some(w) = bake_warning(&report) {
        eprintln!("grin: warning: {w}");
    }
    Ok(baked)
}

/// [`bake_for_gpu`] without the stderr warning: the baked field and the baker's report
/// (measured max error relative to the field's delta_n range).
pub fn bake_for_gpu_with_report(
    field: &dyn IndexField,
    resolution: usize,
) -> Result<(BakedField, BakeReport), GpuError> {
    let opts = BakeOptions {
        resolution: Some(resolution),
        interp: Interp::Trilinear,
        storage: Some(grin_field::baked::Storage::F32),
        ..BakeOptions::default()
    };
    bake(field, &opts, &|_, _, _| {}).map_err(|e| GpuError::Bake(e.to_string()))
}

/// Bake `field` for the GPU with no more nodes than it needs: first at
/// [`DEFAULT_GPU_BAKE_RESOLUTION`]; if that meets the default error budget
/// ([`DEFAULT_ERROR_BUDGET`], with the bake's [`BUDGET_SAFETY`] margin), trilinear error
/// falling as h^2 predicts the coarsest candidate resolution that still meets it, which
/// is baked and kept if its measured error confirms it. Over budget at the full
/// resolution, that bake is used and [`bake_warning`] of the report says so. Two bakes
/// at most (the automatic search of `grin bake` would try every coarser candidate first).
pub fn bake_for_gpu_auto(field: &dyn IndexField) -> Result<(BakedField, BakeReport), GpuError> {
    let full = bake_for_gpu_with_report(field, DEFAULT_GPU_BAKE_RESOLUTION)?;
    let goal = DEFAULT_ERROR_BUDGET * BUDGET_SAFETY;
    let rel = full.1.relative_error;
    if rel > goal {
        return Ok(full);
    }
    let predicted = if rel > 0.0 {
        DEFAULT_GPU_BAKE_RESOLUTION as f64 * (rel / goal).sqrt()
    } else {
        0.0
    };
    let Some(&coarse) = CANDIDATE_RESOLUTIONS
        .iter()
        .find(|&&r| r as f64 >= predicted && r < DEFAULT_GPU_BAKE_RESOLUTION)
    else {
        return Ok(full);
    };
    let small = bake_for_gpu_with_report(field, coarse)?;
    Ok(if small.1.relative_error <= goal {
        small
    } else {
        full
    })
}

/// A one-line warning when a GPU bake's measured error is over the default budget
/// ([`DEFAULT_ERROR_BUDGET`] of the delta_n range), naming the grid, its spacing and the
/// error; `None` when the bake meets the budget.
pub fn bake_warning(report: &BakeReport) -> Option<String> {
    if report.relative_error <= DEFAULT_ERROR_BUDGET {
        return None;
    }
    let [nx, ny, nz] = report.dims;
    let spacing = (report.grid_max.x - report.grid_min.x) / (nx.max(2) - 1) as f64;
    Some(format!(
        "the GPU field bake ({nx}x{ny}x{nz} nodes, spacing {spacing:.3}) has max |n error| {:.3e} = {:.2}% of the delta_n range {:.3e} ({:.0}x the budget of {}%): the field is under-resolved and the GPU image will differ from the CPU's; shrink the medium's bounds to where the field matters or pass a finer baked field",
        report.errors.max_err_n,
        report.relative_error * 100.0,
        report.delta_n_range,
        report.relative_error / DEFAULT_ERROR_BUDGET,
        DEFAULT_ERROR_BUDGET * 100.0,
    ))
}

/// Whether `baked` fits the device as it is: its node counts within
/// `max_texture_dimension_3d` and its f32 texels within `max_buffer_size`. `Err` says
/// what is over which limit.
pub fn fits_device(ctx: &GpuContext, baked: &BakedField) -> Result<(), String> {
    let limits = ctx.limits();
    let d = baked.geometry().dims;
    let axis = limits.max_texture_dimension_3d as usize;
    if d.iter().any(|&n| n > axis) {
        return Err(format!(
            "grid {}x{}x{} has more than the adapter's {axis} texels per axis",
            d[0], d[1], d[2]
        ));
    }
    let bytes = d.iter().map(|&n| n as u64).product::<u64>() * FIELD_TEXEL_BYTES;
    if bytes > limits.max_buffer_size {
        return Err(format!(
            "grid {}x{}x{} needs {bytes} bytes as f32 texels, more than the adapter's max_buffer_size of {}",
            d[0], d[1], d[2], limits.max_buffer_size
        ));
    }
    Ok(())
}

fn check_dims(ctx: &GpuContext, what: &str, dims: [u32; 3]) -> Result<(), GpuError> {
    let limit = ctx.limits().max_texture_dimension_3d;
    if dims.iter().any(|&d| d > limit) {
        return Err(GpuError::TooLarge {
            what: format!("{what} {}x{}x{}", dims[0], dims[1], dims[2]),
            needed: format!(
                "{} texels per axis",
                dims.iter().max().copied().unwrap_or(0)
            ),
            limit: format!("{limit} (max_texture_dimension_3d)"),
            adapter: ctx.adapter_name(),
        });
    }
    Ok(())
}

fn texture_3d(
    ctx: &GpuContext,
    label: &str,
    dims: [u32; 3],
    format: wgpu::TextureFormat,
    texel_bytes: u32,
    data: &[u8],
) -> Result<wgpu::Texture, GpuError> {
    check_dims(ctx, label, dims)?;
    let size = wgpu::Extent3d {
        width: dims[0],
        height: dims[1],
        depth_or_array_layers: dims[2],
    };
    ctx.scoped(&format!("uploading the {label} texture"), || {
        let texture = ctx.device.create_texture(&wgpu::TextureDescriptor {
            label: Some(label),
            size,
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D3,
            format,
            usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            view_formats: &[],
        });
        ctx.queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture: &texture,
                mip_level: 0,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            data,
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(dims[0] * texel_bytes),
                rows_per_image: Some(dims[1]),
            },
            size,
        );
        texture
    })
}

fn dims_u32(d: [usize; 3], what: &str) -> Result<[u32; 3], GpuError> {
    let mut out = [0u32; 3];
    for (o, &n) in out.iter_mut().zip(&d) {
        *o = u32::try_from(n).map_err(|_| GpuError::TooLarge {
            what: what.into(),
            needed: format!("{n} texels"),
            limit: format!("{}", u32::MAX),
            adapter: String::new(),
        })?;
    }
    Ok(out)
}

/// Upload `baked` and fill the field part of `params`.
pub fn upload_field(
    ctx: &GpuContext,
    baked: &BakedField,
    params: &mut FrameParams,
) -> Result<FieldTextures, GpuError> {
    let geometry = baked.geometry();
    let dims = dims_u32(geometry.dims, "baked grid")?;
    check_dims(ctx, "baked grid", dims)?;
    let texels: Vec<[f32; 4]> = match (baked.interp(), baked.spline_coefficients()) {
        (Interp::Tricubic, Some(c)) => c.to_vec(),
        _ => baked.voxels().to_f32(),
    };
    let bytes = texels.len() as u64 * FIELD_TEXEL_BYTES;
    let max_buffer = ctx.limits().max_buffer_size;
    if bytes > max_buffer {
        return Err(GpuError::TooLarge {
            what: format!("baked grid {}x{}x{}", dims[0], dims[1], dims[2]),
            needed: format!("{bytes} bytes"),
            limit: format!("{max_buffer} bytes (max_buffer_size)"),
            adapter: ctx.adapter_name(),
        });
    }
    let field = texture_3d(
        ctx,
        "baked field",
        dims,
        wgpu::TextureFormat::Rgba32Float,
        FIELD_TEXEL_BYTES as u32,
        bytemuck::cast_slice(&texels),
    )?;
    let grid = baked.macro_grid();
    let mdims = dims_u32(grid.dims, "macro-cell grid")?;
    let macro_cells = texture_3d(
        ctx,
        "macro cells",
        mdims,
        wgpu::TextureFormat::R32Float,
        4,
        bytemuck::cast_slice(&grid.max_grad),
    )?;
    let o = geometry.origin.as_vec3();
    let inv = geometry.spacing.recip().as_vec3();
    params.grid_origin = [o.x, o.y, o.z, grid.threshold as f32];
    params.grid_inv_spacing = [inv.x, inv.y, inv.z, 0.0];
    params.grid_dims[0..3].copy_from_slice(&dims);
    params.macro_dims = [mdims[0], mdims[1], mdims[2], grid.cell as u32];
    if baked.outside() == Outside::Ambient {
        params.march[3] |= FLAG_OUTSIDE_AMBIENT;
    }
    if baked.interp() == Interp::Tricubic {
        params.march[3] |= FLAG_TRICUBIC;
    }
    // No straight flight anywhere: the marcher skips the macro-cell test (same result).
    if !baked.may_fly() {
        params.march[3] &= !FLAG_MACRO_CELLS;
    }
    Ok(FieldTextures {
        field,
        macro_cells,
        bytes: bytes + grid.max_grad.len() as u64 * 4,
        dims,
    })
}

/// Placeholder textures for a scene without a medium (never sampled).
pub fn empty_field(ctx: &GpuContext, params: &mut FrameParams) -> Result<FieldTextures, GpuError> {
    let zeros = [[0.0f32; 4]; 8];
    let field = texture_3d(
        ctx,
        "empty field",
        [2, 2, 2],
        wgpu::TextureFormat::Rgba32Float,
        16,
        bytemuck::cast_slice(&zeros),
    )?;
    let macro_cells = texture_3d(
        ctx,
        "empty macro cells",
        [1, 1, 1],
        wgpu::TextureFormat::R32Float,
        4,
        &[0; 4],
    )?;
    params.grid_inv_spacing = [1.0, 1.0, 1.0, 0.0];
    params.grid_dims[0..3].copy_from_slice(&[2, 2, 2]);
    params.macro_dims = [1, 1, 1, 8];
    Ok(FieldTextures {
        field,
        macro_cells,
        bytes: 0,
        dims: [2, 2, 2],
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;
    use grin_field::Bounds;
    use grin_field::analytic::ExponentialAtmosphere;
    use grin_scene::Axis;

    /// An exponential hot layer (scale height `h`) over a box `len` long and 1.6 tall.
    fn layer(len: f64, h: f64) -> ExponentialAtmosphere {
        let bounds = Bounds::Box {
            min: DVec3::new(-len / 2.0, -0.1, 0.0),
            max: DVec3::new(len / 2.0, 1.5, len),
        };
        ExponentialAtmosphere::new(bounds, 1.0, -6e-4, h, 0.0, Axis::Y).expect("valid layer")
    }

    #[test]
    fn thin_layer_in_long_box_is_reported_under_resolved() {
        // The old mirage scene: a 120-unit box at 128 nodes (spacing ~0.95) against a
        // 0.15 scale height; its n error is hundreds of times the budget.
        let (_, report) =
            bake_for_gpu_with_report(&layer(120.0, 0.15), DEFAULT_GPU_BAKE_RESOLUTION)
                .expect("bake");
        assert!(
            report.relative_error > 100.0 * DEFAULT_ERROR_BUDGET,
            "{report:?}"
        );
        let w = bake_warning(&report).expect("a warning");
        assert!(
            w.contains("under-resolved") && w.contains("spacing 0.94"),
            "{w}"
        );
    }

    #[test]
    fn resolved_layer_has_no_warning() {
        // 11.5 nodes per scale height: trilinear error (h/H)^2/8 ~ 1e-3 of the range.
        let (_, report) =
            bake_for_gpu_with_report(&layer(1.5, 0.15), DEFAULT_GPU_BAKE_RESOLUTION).expect("bake");
        assert!(report.relative_error <= DEFAULT_ERROR_BUDGET, "{report:?}");
        assert_eq!(bake_warning(&report), None);
    }

    /// The GPU bakes no more than the field needs: a smooth lens meets the budget on a
    /// coarser grid than 128 nodes (and the coarse grid's measured error says so); a
    /// field no grid up to 128 resolves keeps 128 nodes and its warning.
    #[test]
    fn automatic_gpu_bake_is_as_coarse_as_the_budget_allows() {
        let lens = grin_field::analytic::Luneburg::new(
            Bounds::Sphere {
                center: DVec3::ZERO,
                radius: 1.0,
            },
            1.0,
            None,
        )
        .expect("lens");
        let (_, full) = bake_for_gpu_with_report(&lens, DEFAULT_GPU_BAKE_RESOLUTION).expect("bake");
        let (_, auto) = bake_for_gpu_auto(&lens).expect("bake");
        assert!(auto.resolution < DEFAULT_GPU_BAKE_RESOLUTION, "{auto:?}");
        assert!(auto.relative_error <= DEFAULT_ERROR_BUDGET * BUDGET_SAFETY);
        assert!(
            auto.bytes * 2 < full.bytes,
            "{} vs {}",
            auto.bytes,
            full.bytes
        );

        let (_, thin) = bake_for_gpu_auto(&layer(120.0, 0.15)).expect("bake");
        assert_eq!(thin.resolution, DEFAULT_GPU_BAKE_RESOLUTION);
        assert!(bake_warning(&thin).is_some());
    }
}
