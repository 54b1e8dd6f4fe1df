//! Baked fields on the GPU: the (delta_n, grad n) grid as a 3D texture (rgba32float, or
//! rgba16snorm for i16 voxels), the macro-cell grid as an r32float 3D texture (a sparse
//! bake's brick table as rgba32float), and their placement in `FrameParams`.
//!
//! Format choice: texels read with textureLoad and interpolated in the shader.
//! rgba16float cannot hold n itself, and even delta_n of air (~1e-5) is a half-float
//! subnormal there (spacing 6e-8: ~0.6% error, worse for heat haze's gradients);
//! float32 filtering needs the optional FLOAT32_FILTERABLE feature, and filter hardware
//! may keep only 8 fractional bits of the weights (docs/physics.md, failure mode 2).
//! Manual trilinear costs 8 loads per sample but uses the CPU's weights exactly, so GPU
//! and CPU march the same field: the GPU-vs-CPU tests measure p99 pixel differences
//! <= 2e-5 with it. Its speed on lavapipe (`grin bench speed`, docs/benchmarks.md) is
//! ~100 M trilinear samples/s on a 2-core VM. i16 voxels (`grin bake`'s storage where its
//! rounding fits the budget) stay 16-bit where the device has rgba16snorm
//! ([`GpuContext::has_snorm16`]): half the memory, the same integers the CPU blends,
//! scaled after the blend (a dense grid by `FrameParams::field_scale`, a sparse bake per
//! brick); elsewhere, and for tricubic coefficients, f32.

use std::sync::Arc;

use grin_field::IndexField;
use grin_field::baked::{BakedField, Interp, Outside, Voxels};
use grin_field::sparse::{Pool, SparseField};

/// The policy for baking a field the GPU marches is grin-field's (its `bake::device`);
/// re-exported here, where callers of the GPU look for it.
pub use grin_field::bake::device::{
    DEFAULT_GPU_BAKE_RESOLUTION, bake_for_gpu, bake_for_gpu_auto, bake_for_gpu_with_report,
    bake_warning,
};

use crate::gpu_data::{
    FLAG_FIELD_SNORM, FLAG_GRADIENT_OF_N, FLAG_MACRO_CELLS, FLAG_OUTSIDE_AMBIENT, FLAG_SPARSE,
    FLAG_TRICUBIC, FrameParams,
};
use crate::{GpuContext, GpuError};

/// Bytes per texel of the field texture (rgba32float).
pub const FIELD_TEXEL_BYTES: u64 = 16;
/// Bytes per texel of an i16 field's texture (rgba16snorm), dense or sparse.
pub const SNORM_TEXEL_BYTES: u64 = 8;

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

impl FieldTextures {
    /// Views of the field and the macro-cell textures, to bind.
    pub fn views(&self) -> (wgpu::TextureView, wgpu::TextureView) {
        let view = |t: &wgpu::Texture| t.create_view(&wgpu::TextureViewDescriptor::default());
        (view(&self.field), view(&self.macro_cells))
    }
}

/// The texels a dense grid is uploaded as, and their bytes: rgba16snorm for trilinear i16
/// voxels where the device has it, else rgba32float (f32 voxels, i16 ones decoded, or
/// tricubic coefficients).
fn dense_texels(ctx: &GpuContext, baked: &BakedField) -> (wgpu::TextureFormat, u64) {
    field_texels(
        baked.interp() == Interp::Trilinear
            && matches!(baked.voxels(), Voxels::I16 { .. })
            && ctx.has_snorm16(),
    )
}

/// A field texture's texel format and bytes: rgba16snorm where `snorm`, else rgba32float.
fn field_texels(snorm: bool) -> (wgpu::TextureFormat, u64) {
    if snorm {
        (wgpu::TextureFormat::Rgba16Snorm, SNORM_TEXEL_BYTES)
    } else {
        (wgpu::TextureFormat::Rgba32Float, FIELD_TEXEL_BYTES)
    }
}

/// Whether `baked` fits the device as it is: its node counts within
/// `max_texture_dimension_3d` and its texels (as [`upload_field`] makes them) within
/// `max_buffer_size`. `Err` says what is over which limit.
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
    let (format, texel_bytes) = dense_texels(ctx, baked);
    let bytes = d.iter().map(|&n| n as u64).product::<u64>() * texel_bytes;
    if bytes > limits.max_buffer_size {
        return Err(format!(
            "grid {}x{}x{} needs {bytes} bytes as {format:?} texels, more than the adapter's max_buffer_size of {}",
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
    // The spline coefficients are uploaded as they are (no copy); i16 node samples as
    // rgba16snorm where the device has it (scaled in the shader), else decoded to f32.
    let samples;
    let (format, texel_bytes) = dense_texels(ctx, baked);
    let data: &[u8] = match (baked.spline_coefficients(), baked.voxels()) {
        (Some(c), _) if baked.interp() == Interp::Tricubic => bytemuck::cast_slice(c),
        (_, Voxels::I16 { data, scale }) if format == wgpu::TextureFormat::Rgba16Snorm => {
            params.flags |= FLAG_FIELD_SNORM;
            params.field_scale = scale.map(|s| s * f32::from(i16::MAX));
            bytemuck::cast_slice(data)
        }
        (_, v) => {
            samples = v.to_f32();
            bytemuck::cast_slice(&samples)
        }
    };
    let bytes = data.len() as u64;
    let max_buffer = ctx.limits().max_buffer_size;
    if bytes > max_buffer {
        return Err(GpuError::TooLarge {
            what: format!("baked grid {}x{}x{}", dims[0], dims[1], dims[2]),
            needed: format!("{bytes} bytes"),
            limit: format!("{max_buffer} bytes (max_buffer_size)"),
            adapter: ctx.adapter_name(),
        });
    }
    let field = texture_3d(ctx, "baked field", dims, format, texel_bytes as u32, data)?;
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
    params.grid_origin = o.to_array();
    params.macro_threshold = grid.threshold as f32;
    params.grid_inv_spacing = inv.to_array();
    params.grid_dims = dims;
    params.macro_dims = mdims;
    params.macro_cell_voxels = grid.cell as u32;
    params.n_uncertainty = grin_field::IndexField::n_uncertainty(baked) as f32;
    if baked.outside() == Outside::Ambient {
        params.flags |= FLAG_OUTSIDE_AMBIENT;
    }
    if baked.interp() == Interp::Tricubic {
        params.flags |= FLAG_TRICUBIC;
    }
    // No straight flight anywhere: the marcher skips the macro-cell test (same result).
    if !baked.may_fly() {
        params.flags &= !FLAG_MACRO_CELLS;
    }
    Ok(FieldTextures {
        field,
        macro_cells,
        bytes: bytes + grid.max_grad.len() as u64 * 4,
        dims,
    })
}

/// A field the GPU marches as it is: a dense bake or a sparse one.
#[derive(Debug, Clone, Copy)]
pub enum DeviceField<'a> {
    Dense(&'a BakedField),
    Sparse(&'a SparseField),
}

impl<'a> From<&'a BakedField> for DeviceField<'a> {
    fn from(f: &'a BakedField) -> Self {
        DeviceField::Dense(f)
    }
}

impl<'a> From<&'a SparseField> for DeviceField<'a> {
    fn from(f: &'a SparseField) -> Self {
        DeviceField::Sparse(f)
    }
}

/// A grid for the GPU, shared with its caller: one dense box, or (where a dense grid within
/// the GPU's cap misses the error budget and a sparse bake meets it) a sparse one. What a
/// GPU bake gives (the bake cache's entries) and what a
/// [`GpuRayTracer`](crate::GpuRayTracer) marches.
#[derive(Debug, Clone)]
pub enum GpuGrid {
    Dense(Arc<BakedField>),
    Sparse(Arc<SparseField>),
}

impl GpuGrid {
    /// The grid to upload.
    pub fn device(&self) -> DeviceField<'_> {
        match self {
            GpuGrid::Dense(b) => DeviceField::Dense(b),
            GpuGrid::Sparse(s) => DeviceField::Sparse(s),
        }
    }
    /// The grid as a shared field.
    pub fn field(&self) -> Arc<dyn IndexField> {
        match self {
            GpuGrid::Dense(b) => Arc::clone(b) as Arc<dyn IndexField>,
            GpuGrid::Sparse(s) => Arc::clone(s) as Arc<dyn IndexField>,
        }
    }
    /// Bytes of the grid's voxels (and, sparse, its table and brick records) in memory.
    pub fn data_bytes(&self) -> usize {
        match self {
            GpuGrid::Dense(b) => b.data_bytes(),
            GpuGrid::Sparse(s) => s.memory_bytes(),
        }
    }
    /// Whether both are the same grid (not a copy).
    pub fn same(&self, other: &GpuGrid) -> bool {
        match (self, other) {
            (GpuGrid::Dense(a), GpuGrid::Dense(b)) => Arc::ptr_eq(a, b),
            (GpuGrid::Sparse(a), GpuGrid::Sparse(b)) => Arc::ptr_eq(a, b),
            _ => false,
        }
    }
}

impl From<Arc<BakedField>> for GpuGrid {
    fn from(f: Arc<BakedField>) -> Self {
        GpuGrid::Dense(f)
    }
}

impl From<Arc<SparseField>> for GpuGrid {
    fn from(f: Arc<SparseField>) -> Self {
        GpuGrid::Sparse(f)
    }
}

/// Upload `field` ([`upload_field`] or [`upload_sparse`]).
pub fn upload(
    ctx: &GpuContext,
    field: DeviceField<'_>,
    params: &mut FrameParams,
) -> Result<FieldTextures, GpuError> {
    match field {
        DeviceField::Dense(b) => upload_field(ctx, b, params),
        DeviceField::Sparse(s) => upload_sparse(ctx, s, params),
    }
}

/// Texels per row and rows per layer of a sparse field's linear texture (field.wgsl's
/// `SPARSE_ROW`).
pub const SPARSE_ROW: usize = 256;
/// Layers of the sparse field's texture written at a time (64 MiB of f32 texels, 32 MiB
/// of rgba16snorm ones).
const SPARSE_UPLOAD_LAYERS: usize = 64;

/// Upload a sparse bake (layout in shaders/shared/field.wgsl): its voxels in one linear
/// 3D texture, as rgba16snorm texels where they are i16 and the device has the format
/// ([`GpuContext::has_snorm16`]: 8 bytes a voxel, scaled per brick in the shader), else as
/// f32 (16 bytes); its brick table as the macro-cell texture, one rgba32float texel per
/// top-grid brick (cells, 0 where empty, so that a ray flies over empty bricks with the
/// macro-cell threshold 1/2), followed where the voxels are i16 by a block of the bricks'
/// scales.
pub fn upload_sparse(
    ctx: &GpuContext,
    sparse: &SparseField,
    params: &mut FrameParams,
) -> Result<FieldTextures, GpuError> {
    let top = sparse.top();
    let table = sparse.table();
    let bricks = sparse.bricks();
    // The table's scale block doubles its depth: f32 texels where that would not fit.
    let snorm = matches!(sparse.pool(), Pool::I16(_))
        && ctx.has_snorm16()
        && 2 * top.dims[2] as u64 <= u64::from(ctx.limits().max_texture_dimension_3d);
    // The table's blocks: the entries, then for snorm voxels the scales.
    let blocks: u32 = if snorm { 2 } else { 1 };
    let table_bytes = top.brick_count() as u64 * FIELD_TEXEL_BYTES * u64::from(blocks);
    let mdims = dims_u32(top.dims, "sparse top grid")?;
    let table_dims = [mdims[0], mdims[1], mdims[2] * blocks];
    check_dims(ctx, "sparse brick table", table_dims)?;
    let (format, texel_bytes) = field_texels(snorm);
    let voxels = sparse.pool().len();
    let layer = SPARSE_ROW * SPARSE_ROW;
    let depth = voxels.div_ceil(layer).max(1);
    let dims = dims_u32([SPARSE_ROW, SPARSE_ROW, depth], "sparse field")?;
    check_dims(ctx, "sparse field", dims)?;
    let bytes = (layer * depth) as u64 * texel_bytes;
    let max_buffer = ctx.limits().max_buffer_size;
    if bytes.max(table_bytes) > max_buffer {
        return Err(GpuError::TooLarge {
            what: format!(
                "sparse field of {} bricks in a top grid of {}",
                bricks.len(),
                top.brick_count()
            ),
            needed: format!("{} bytes", bytes.max(table_bytes)),
            limit: format!("{max_buffer} bytes (max_buffer_size)"),
            adapter: ctx.adapter_name(),
        });
    }
    let field = ctx.scoped("uploading the sparse field texture", || {
        ctx.device.create_texture(&wgpu::TextureDescriptor {
            label: Some("sparse field"),
            size: wgpu::Extent3d {
                width: dims[0],
                height: dims[1],
                depth_or_array_layers: dims[2],
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D3,
            format,
            usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            view_formats: &[],
        })
    })?;
    match sparse.pool() {
        Pool::I16(p) if snorm => {
            upload_linear(ctx, &field, dims, |t| p.get(t).copied().unwrap_or_default())?
        }
        _ => {
            // The brick holding the last texel asked for: `upload_linear` asks for the
            // texels in order, so the brick only moves on.
            let mut brick = 0;
            upload_linear(ctx, &field, dims, |v| {
                if v >= voxels {
                    return [0.0; 4];
                }
                debug_assert!(bricks[brick].offset <= v, "texels asked for in order");
                while brick + 1 < bricks.len() && bricks[brick + 1].offset <= v {
                    brick += 1;
                }
                sparse.voxel_f32(&bricks[brick], v)
            })?
        }
    }
    let entries = table.iter().enumerate().map(|(t, &e)| {
        let near = f32::from(sparse.near_cells_at(t));
        match bricks.get(e as usize) {
            None => [0.0, 0.0, 0.0, near],
            Some(b) => [
                b.cells() as f32,
                (b.offset / 65536) as f32,
                (b.offset % 65536) as f32,
                near,
            ],
        }
    });
    // An snorm texel reads as q / 32767: the shader's scale puts the 32767 back.
    let scales = table.iter().map(|&e| match bricks.get(e as usize) {
        Some(b) if snorm => [
            b.scale[0] * f32::from(i16::MAX),
            b.scale[1] * f32::from(i16::MAX),
            0.0,
            0.0,
        ],
        _ => [0.0; 4],
    });
    let texels: Vec<[f32; 4]> = if snorm {
        entries.chain(scales).collect()
    } else {
        entries.collect()
    };
    let macro_cells = texture_3d(
        ctx,
        "sparse brick table",
        table_dims,
        wgpu::TextureFormat::Rgba32Float,
        FIELD_TEXEL_BYTES as u32,
        bytemuck::cast_slice(&texels),
    )?;
    params.grid_origin = top.origin.as_vec3().to_array();
    params.grid_inv_spacing = [(1.0 / top.edge) as f32; 3];
    params.grid_dims = mdims.map(|d| d + 1);
    params.macro_dims = mdims;
    params.macro_cell_voxels = 1;
    params.macro_threshold = 0.5;
    params.n_uncertainty = grin_field::IndexField::n_uncertainty(sparse) as f32;
    params.flags |= FLAG_OUTSIDE_AMBIENT | FLAG_SPARSE;
    // Bricks with an apron are sampled tricubically (Catmull-Rom), their (cells + 3)^3
    // nodes from the first voxel.
    if sparse.apron() > 0 {
        params.flags |= FLAG_TRICUBIC;
        // The nodes' delta_n range, which a sample is clamped to.
        let (lo, hi) = sparse.delta_range();
        params.field_scale = [lo, hi, 0.0, 0.0];
        if sparse.gradient_of_n() {
            params.flags |= FLAG_GRADIENT_OF_N;
        }
    }
    if snorm {
        params.flags |= FLAG_FIELD_SNORM;
    }
    // The macro-cell test stays on where no brick is empty (it then flies only outside
    // the top grid): a sequence's frames, some with empty bricks and some without, share
    // one compiled pipeline (the flags are pipeline constants).
    Ok(FieldTextures {
        field,
        macro_cells,
        bytes: bytes + texels.len() as u64 * FIELD_TEXEL_BYTES,
        dims,
    })
}

/// Write `texture` (a linear one, `dims` of `SPARSE_ROW` x `SPARSE_ROW` x layers), texel
/// `t` being `texel(t)` (asked for in order), a slab of layers at a time: each slab's
/// texels are made just before and its staging flushed by a submission, so host memory
/// holds one slab, not a copy of the whole field.
fn upload_linear<T: bytemuck::Pod>(
    ctx: &GpuContext,
    texture: &wgpu::Texture,
    dims: [u32; 3],
    mut texel: impl FnMut(usize) -> T,
) -> Result<(), GpuError> {
    let layer = SPARSE_ROW * SPARSE_ROW;
    let depth = dims[2] as usize;
    let mut slab = Vec::new();
    let mut z = 0;
    while z < depth {
        let layers = SPARSE_UPLOAD_LAYERS.min(depth - z);
        let first = z * layer;
        slab.clear();
        slab.extend((first..first + layers * layer).map(&mut texel));
        ctx.scoped("uploading the sparse field texture", || {
            ctx.queue.write_texture(
                wgpu::TexelCopyTextureInfo {
                    texture,
                    mip_level: 0,
                    origin: wgpu::Origin3d {
                        x: 0,
                        y: 0,
                        z: z as u32,
                    },
                    aspect: wgpu::TextureAspect::All,
                },
                bytemuck::cast_slice(&slab),
                wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(dims[0] * std::mem::size_of::<T>() as u32),
                    rows_per_image: Some(dims[1]),
                },
                wgpu::Extent3d {
                    width: dims[0],
                    height: dims[1],
                    depth_or_array_layers: layers as u32,
                },
            );
            ctx.queue.submit(None);
        })?;
        z += layers;
    }
    Ok(())
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
    params.grid_inv_spacing = [1.0; 3];
    params.grid_dims = [2, 2, 2];
    params.macro_dims = [1, 1, 1];
    params.macro_cell_voxels = 8;
    Ok(FieldTextures {
        field,
        macro_cells,
        bytes: 0,
        dims: [2, 2, 2],
    })
}
