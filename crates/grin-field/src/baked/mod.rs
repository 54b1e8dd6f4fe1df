//! [`BakedField`]: a dense grid of (delta_n, grad n) with its world transform, sampled by
//! trilinear interpolation or a tricubic B-spline, plus a macro-cell grid for straight
//! flights. It implements [`IndexField`], so every tracer runs on baked fields unchanged.
//!
//! Data layout (shared with the GPU and the `.grinf` file): nodes at grid coordinates
//! (i, j, k), world = origin + spacing * (i, j, k); one voxel = 4 channels
//! `[delta_n, dn/dx, dn/dy, dn/dz]` (delta_n = n - ambient, gradient in index units per
//! world unit); voxel index `i + nx * (j + ny * k)` (x fastest). Storage is f32, or i16
//! with a per-channel scale (value = q * scale[c]).
//!
//! One concept, one file: the sampler's hot path reads the grid's private layout directly.

pub mod bspline;
mod layout;
pub mod macrocell;

use glam::{DMat4, DVec3, Vec4};
use rayon::prelude::*;

use crate::bounds::Bounds;
use crate::field::{FieldError, FieldSample, IndexField};
use layout::Bricks;
pub use macrocell::MacroGrid;

/// How voxels are stored.
#[derive(Debug, Clone, Copy, PartialEq, Eq, strum::IntoStaticStr)]
#[strum(serialize_all = "lowercase")]
pub enum Storage {
    F32,
    /// Signed 16-bit with a per-channel scale.
    I16,
}

impl Storage {
    pub fn bytes_per_voxel(self) -> usize {
        match self {
            Storage::F32 => 16,
            Storage::I16 => 8,
        }
    }
    pub fn name(self) -> &'static str {
        self.into()
    }
}

/// How the grid is sampled between nodes.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, strum::IntoStaticStr, strum::EnumString, strum::VariantNames,
)]
#[strum(serialize_all = "lowercase")]
pub enum Interp {
    /// Trilinear interpolation of delta_n and of the stored grad n (C0; 2nd order).
    Trilinear,
    /// Interpolating cubic B-spline of each channel (prefiltered; C2; 4th order).
    Tricubic,
}

impl Interp {
    pub fn name(self) -> &'static str {
        self.into()
    }
    /// Parse `trilinear` | `tricubic`.
    pub fn parse(s: &str) -> Option<Self> {
        s.parse().ok()
    }
}

impl From<grin_scene::Interpolation> for Interp {
    /// A scene's `interpolation` key.
    fn from(i: grin_scene::Interpolation) -> Self {
        match i {
            grin_scene::Interpolation::Trilinear => Interp::Trilinear,
            grin_scene::Interpolation::Tricubic => Interp::Tricubic,
        }
    }
}

/// What the field is beyond the grid's nodes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, strum::IntoStaticStr)]
#[strum(serialize_all = "lowercase")]
pub enum Outside {
    /// The value at the nearest node (the grid covers the whole medium plus a margin).
    Clamp,
    /// Ambient index, zero gradient (the grid is cropped to where the field is active).
    Ambient,
}

/// Voxel storage.
#[derive(Debug, Clone, PartialEq)]
pub enum Voxels {
    F32(Vec<[f32; 4]>),
    I16 {
        data: Vec<[i16; 4]>,
        scale: [f32; 4],
    },
}

impl Voxels {
    pub fn len(&self) -> usize {
        match self {
            Voxels::F32(v) => v.len(),
            Voxels::I16 { data, .. } => data.len(),
        }
    }
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    pub fn storage(&self) -> Storage {
        match self {
            Voxels::F32(_) => Storage::F32,
            Voxels::I16 { .. } => Storage::I16,
        }
    }
    /// Per-channel scale (all 1 for f32).
    pub fn scale(&self) -> [f32; 4] {
        match self {
            Voxels::F32(_) => [1.0; 4],
            Voxels::I16 { scale, .. } => *scale,
        }
    }
    /// Voxel `idx` decoded to f32 channels.
    #[inline]
    pub fn get(&self, idx: usize) -> [f32; 4] {
        match self {
            Voxels::F32(v) => v[idx],
            Voxels::I16 { data, scale } => {
                let q = data[idx];
                [
                    f32::from(q[0]) * scale[0],
                    f32::from(q[1]) * scale[1],
                    f32::from(q[2]) * scale[2],
                    f32::from(q[3]) * scale[3],
                ]
            }
        }
    }
    /// Quantize f32 voxels to i16 with a per-channel scale (delta_n alone, gradient
    /// components sharing one scale so the vector keeps its direction).
    pub fn quantize(v: &[[f32; 4]]) -> Voxels {
        let (data, scale) = quantize_i16(v);
        Voxels::I16 { data, scale }
    }
    /// All voxels decoded to f32 (for upload as an rgba32float texture).
    pub fn to_f32(&self) -> Vec<[f32; 4]> {
        match self {
            Voxels::F32(v) => v.clone(),
            Voxels::I16 { .. } => (0..self.len()).map(|i| self.get(i)).collect(),
        }
    }
}

/// i16 voxels with a per-channel scale (delta_n alone, gradient components sharing one
/// scale so the vector keeps its direction): [`Voxels::quantize`]'s, and each sparse
/// brick's.
pub(crate) fn quantize_i16(v: &[[f32; 4]]) -> (Vec<[i16; 4]>, [f32; 4]) {
    let mut max = [0.0f32; 2];
    for x in v {
        max[0] = max[0].max(x[0].abs());
        max[1] = max[1].max(x[1].abs()).max(x[2].abs()).max(x[3].abs());
    }
    let s = max.map(|m| {
        if m > 0.0 {
            m / f32::from(i16::MAX)
        } else {
            1.0
        }
    });
    let scale = [s[0], s[1], s[1], s[1]];
    let data = v
        .iter()
        .map(|x| {
            let q = |c: usize| {
                (x[c] / scale[c])
                    .round()
                    .clamp(-f32::from(i16::MAX), f32::from(i16::MAX)) as i16
            };
            [q(0), q(1), q(2), q(3)]
        })
        .collect();
    (data, scale)
}

/// The grid's placement: node (i, j, k) sits at world `origin + spacing * (i, j, k)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GridGeometry {
    pub dims: [usize; 3],
    pub origin: DVec3,
    pub spacing: DVec3,
}

impl GridGeometry {
    pub fn voxel_count(&self) -> usize {
        self.dims[0] * self.dims[1] * self.dims[2]
    }
    #[inline]
    pub fn index(&self, i: usize, j: usize, k: usize) -> usize {
        i + self.dims[0] * (j + self.dims[1] * k)
    }
    #[inline]
    pub fn node_world(&self, i: usize, j: usize, k: usize) -> DVec3 {
        self.origin + self.spacing * DVec3::new(i as f64, j as f64, k as f64)
    }
    #[inline]
    pub fn grid_from_world_point(&self, p: DVec3) -> DVec3 {
        (p - self.origin) / self.spacing
    }
    /// Largest grid coordinate per axis (dims - 1).
    pub fn grid_max(&self) -> DVec3 {
        DVec3::new(
            (self.dims[0] - 1) as f64,
            (self.dims[1] - 1) as f64,
            (self.dims[2] - 1) as f64,
        )
    }
    /// World corners (first node, last node).
    pub fn world_box(&self) -> (DVec3, DVec3) {
        (self.origin, self.origin + self.spacing * self.grid_max())
    }
    pub fn world_from_grid(&self) -> DMat4 {
        DMat4::from_translation(self.origin) * DMat4::from_scale(self.spacing)
    }
    pub fn grid_from_world(&self) -> DMat4 {
        self.world_from_grid().inverse()
    }
}

/// What the bake measured and where the field came from (stored in the file header).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct BakeProvenance {
    /// `describe()` of the source field.
    pub source: String,
    /// Max and RMS |n_baked - n_source| on random points inside the medium.
    pub max_err_n: f64,
    pub rms_err_n: f64,
    /// Max and RMS |grad_baked - grad_source|.
    pub max_err_grad: f64,
    pub rms_err_grad: f64,
}

/// A baked index field.
#[derive(Debug, Clone)]
pub struct BakedField {
    geometry: GridGeometry,
    voxels: Voxels,
    interp: Interp,
    outside: Outside,
    bounds: Bounds,
    ambient: f64,
    provenance: BakeProvenance,
    n_range: (f64, f64),
    max_grad: f64,
    /// B-spline coefficients of the 4 channels (tricubic only).
    coeffs: Option<Vec<[f32; 4]>>,
    macro_grid: MacroGrid,
    /// Largest grid coordinate per axis (dims - 1), cached for `sample`.
    gmax: DVec3,
    /// 1 / spacing: the sampler multiplies (as the GPU does) instead of dividing.
    inv_spacing: DVec3,
    /// Where node (i, j, k) sits in the sampling copies below (4x4x4 bricks).
    bricks: Bricks,
    /// The voxels (trilinear) or spline coefficients (tricubic, as f32) in brick order:
    /// the same numbers as `voxels` / `coeffs`, only laid out so that a sample's taps
    /// share cache lines and pages whatever the ray direction.
    sampled: Voxels,
}

/// Largest |n - n_ambient| a baked voxel may hold: no physical medium comes near it (the
/// Eaton lens's baked core is far below); larger values are a corrupt or crafted file.
pub const MAX_BAKED_DELTA_N: f64 = 1e3;

impl BakedField {
    /// Assemble a baked field; checks that the voxel count matches the dims.
    pub fn new(
        geometry: GridGeometry,
        voxels: Voxels,
        interp: Interp,
        outside: Outside,
        bounds: Bounds,
        ambient: f64,
        provenance: BakeProvenance,
    ) -> Result<Self, FieldError> {
        if geometry.dims.iter().any(|&d| d < 2) {
            return Err(FieldError::Other(format!(
                "baked grid {:?} needs at least 2 nodes per axis",
                geometry.dims
            )));
        }
        if voxels.len() != geometry.voxel_count() {
            return Err(FieldError::Other(format!(
                "baked grid {:?} needs {} voxels, got {}",
                geometry.dims,
                geometry.voxel_count(),
                voxels.len()
            )));
        }
        if !(geometry.spacing.min_element() > 0.0
            && geometry.spacing.is_finite()
            && geometry.origin.is_finite())
        {
            return Err(FieldError::Other(format!(
                "baked grid spacing {} / origin {} must be positive and finite",
                geometry.spacing, geometry.origin
            )));
        }
        let (_, far) = geometry.world_box();
        let limit = grin_scene::MAX_WORLD_COORDINATE;
        if geometry.origin.abs().max_element() > limit || far.abs().max_element() > limit {
            return Err(FieldError::Other(format!(
                "baked grid {} .. {far} reaches beyond ±{limit:e} world units",
                geometry.origin
            )));
        }
        let (blo, bhi) = bounds.aabb();
        if !(blo.is_finite() && bhi.is_finite() && blo.cmplt(bhi).all())
            || blo.abs().max_element() > limit
            || bhi.abs().max_element() > limit
        {
            return Err(FieldError::Other(format!(
                "baked field bounds {blo} .. {bhi} are empty, not finite or beyond ±{limit:e}"
            )));
        }
        if !(ambient.is_finite() && ambient > 0.0) {
            return Err(FieldError::Other(format!(
                "baked field ambient index {ambient} must be positive"
            )));
        }
        let (mut lo, mut hi, mut g2) = (f32::INFINITY, f32::NEG_INFINITY, 0.0f32);
        for i in 0..voxels.len() {
            let v = voxels.get(i);
            if !v.iter().all(|x| x.is_finite()) {
                return Err(FieldError::Other(format!(
                    "baked voxel {i} is not finite: {v:?}"
                )));
            }
            let n = ambient + f64::from(v[0]);
            if !(n > 0.0 && f64::from(v[0]).abs() <= MAX_BAKED_DELTA_N) {
                return Err(FieldError::Other(format!(
                    "baked voxel {i} has n = {n} (delta_n {}): n must be positive and \
                     |delta_n| at most {MAX_BAKED_DELTA_N}",
                    v[0]
                )));
            }
            let gi = v[1] * v[1] + v[2] * v[2] + v[3] * v[3];
            if !gi.is_finite() {
                return Err(FieldError::Other(format!(
                    "baked voxel {i} has a gradient too large for f32: {v:?}"
                )));
            }
            lo = lo.min(v[0]);
            hi = hi.max(v[0]);
            g2 = g2.max(gi);
        }
        if outside == Outside::Ambient {
            lo = lo.min(0.0);
            hi = hi.max(0.0);
        }
        let mut field = BakedField {
            geometry,
            voxels,
            interp,
            outside,
            bounds,
            ambient,
            provenance,
            n_range: (ambient + f64::from(lo), ambient + f64::from(hi)),
            max_grad: f64::from(g2.sqrt()),
            coeffs: None,
            macro_grid: MacroGrid::unbuilt(),
            gmax: geometry.grid_max(),
            inv_spacing: geometry.spacing.recip(),
            bricks: Bricks::new(geometry.dims),
            sampled: Voxels::F32(Vec::new()),
        };
        field.prepare();
        Ok(field)
    }

    /// A copy of this field sampled with `interp`: the nodes are copied and only what
    /// `interp` samples is built (`clone().with_interp(..)` would copy this field's spline
    /// coefficients and sampling copies too, only to replace them).
    pub fn to_interp(&self, interp: Interp) -> Self {
        let mut field = BakedField {
            voxels: self.voxels.clone(),
            interp,
            provenance: self.provenance.clone(),
            coeffs: None,
            macro_grid: MacroGrid::unbuilt(),
            bricks: Bricks::new(self.geometry.dims),
            sampled: Voxels::F32(Vec::new()),
            ..*self
        };
        field.prepare();
        field
    }

    /// The same field sampled with `interp`.
    pub fn with_interp(mut self, interp: Interp) -> Self {
        if interp != self.interp {
            self.interp = interp;
            self.prepare();
        }
        self
    }

    /// Spline coefficients (tricubic) and the macro-cell grid for the current interp.
    fn prepare(&mut self) {
        let dims = self.geometry.dims;
        let idx = |i: usize, j: usize, k: usize| i + dims[0] * (j + dims[1] * k);
        self.coeffs = match self.interp {
            Interp::Trilinear => None,
            Interp::Tricubic => Some(prefilter(&self.voxels, dims)),
        };
        let (reach, grads): (usize, Vec<f32>) = match &self.coeffs {
            None => (
                1,
                (0..self.voxels.len())
                    .map(|i| {
                        let v = self.voxels.get(i);
                        (v[1] * v[1] + v[2] * v[2] + v[3] * v[3]).sqrt()
                    })
                    .collect(),
            ),
            // The spline's gradient channels are convex combinations of the coefficients.
            Some(c) => (
                2,
                c.iter()
                    .map(|v| v[1].abs() + v[2].abs() + v[3].abs())
                    .collect(),
            ),
        };
        self.macro_grid =
            MacroGrid::build(dims, reach, self.max_grad, |i, j, k| grads[idx(i, j, k)]);
        self.sampled = match (&self.coeffs, &self.voxels) {
            (Some(c), _) => Voxels::F32(self.bricks.reorder(dims, c)),
            (None, Voxels::F32(v)) => Voxels::F32(self.bricks.reorder(dims, v)),
            (None, Voxels::I16 { data, scale }) => Voxels::I16 {
                data: self.bricks.reorder(dims, data),
                scale: *scale,
            },
        };
    }

    pub fn geometry(&self) -> &GridGeometry {
        &self.geometry
    }
    pub fn dims(&self) -> [usize; 3] {
        self.geometry.dims
    }
    pub fn world_from_grid(&self) -> DMat4 {
        self.geometry.world_from_grid()
    }
    pub fn grid_from_world(&self) -> DMat4 {
        self.geometry.grid_from_world()
    }
    pub fn voxels(&self) -> &Voxels {
        &self.voxels
    }
    pub fn storage(&self) -> Storage {
        self.voxels.storage()
    }
    pub fn interp(&self) -> Interp {
        self.interp
    }
    pub fn outside(&self) -> Outside {
        self.outside
    }
    pub fn provenance(&self) -> &BakeProvenance {
        &self.provenance
    }
    pub fn set_provenance(&mut self, p: BakeProvenance) {
        self.provenance = p;
    }
    /// Cubic B-spline coefficients of the 4 channels, same layout as the voxels (tricubic
    /// only): a GPU evaluates the spline from these with 8 trilinear fetches.
    pub fn spline_coefficients(&self) -> Option<&[[f32; 4]]> {
        self.coeffs.as_deref()
    }
    pub fn macro_grid(&self) -> &MacroGrid {
        &self.macro_grid
    }
    /// False when [`IndexField::homogeneous_span`] is `None` at every point of the
    /// bounds (within a voxel): no macro cell reaching into them is homogeneous, and none
    /// of them lies beyond an ambient-outside grid. A marcher may then skip the
    /// macro-cell test at every step. (Homogeneous cells wholly outside the bounds, such
    /// as the corners of a sphere's grid, hold no ray.)
    pub fn may_fly(&self) -> bool {
        let mg = &self.macro_grid;
        let margin = self.geometry.spacing.max_element();
        let gmax = self.geometry.grid_max();
        let cell = mg.cell as f64;
        for ck in 0..mg.dims[2] {
            for cj in 0..mg.dims[1] {
                for ci in 0..mg.dims[0] {
                    if !mg.homogeneous([ci, cj, ck]) {
                        continue;
                    }
                    let c = DVec3::new(ci as f64, cj as f64, ck as f64) * cell;
                    let lo = self.geometry.origin + self.geometry.spacing * c.min(gmax);
                    let hi = self.geometry.origin + self.geometry.spacing * (c + cell).min(gmax);
                    if self.bounds.meets_box(lo, hi, margin) {
                        return true;
                    }
                }
            }
        }
        if self.outside == Outside::Clamp {
            return false;
        }
        let (lo, hi) = self.geometry.world_box();
        let (b_lo, b_hi) = self.bounds.aabb();
        !(lo.cmple(b_lo).all() && hi.cmpge(b_hi).all())
    }
    /// Bytes of voxel data.
    pub fn data_bytes(&self) -> usize {
        self.voxels.len() * self.storage().bytes_per_voxel()
    }

    /// [delta_n, grad n] at grid point g, clamped onto the grid (so g >= 0 below and
    /// `as usize` is floor, with no libm call).
    #[inline]
    fn interpolate(&self, g: DVec3) -> [f64; 4] {
        let g = g.clamp(DVec3::ZERO, self.gmax);
        match (self.interp, &self.sampled) {
            (Interp::Tricubic, Voxels::F32(c)) => self.tricubic(c, g),
            (_, v) => self.trilinear(v, g),
        }
    }

    #[inline]
    fn trilinear(&self, voxels: &Voxels, g: DVec3) -> [f64; 4] {
        // One match per sample, not per tap: i16 voxels are interpolated as integers and
        // scaled once. The 4 channels are one SIMD vector of f32, as on the GPU: the
        // rounding this adds (~1e-7 relative) is below the f32 (and far below the i16)
        // storage step of the voxels themselves.
        let q = match voxels {
            Voxels::F32(v) => trilinear_in(&self.geometry, &self.bricks, g, |i| Vec4::from(v[i])),
            Voxels::I16 { data, scale } => {
                let q = trilinear_in(&self.geometry, &self.bricks, g, |i| {
                    let [a, b, c, d] = data[i];
                    Vec4::new(f32::from(a), f32::from(b), f32::from(c), f32::from(d))
                });
                q * Vec4::from(*scale)
            }
        };
        q.as_dvec4().to_array()
    }

    /// `coeffs` in brick order (`self.sampled`).
    #[inline]
    fn tricubic(&self, coeffs: &[[f32; 4]], g: DVec3) -> [f64; 4] {
        let d = self.geometry.dims;
        let fl = DVec3::new(
            (g.x as usize) as f64,
            (g.y as usize) as f64,
            (g.z as usize) as f64,
        );
        let (wx, wy, wz) = (
            bspline::weights(g.x - fl.x),
            bspline::weights(g.y - fl.y),
            bspline::weights(g.z - fl.z),
        );
        let (bi, bj, bk) = (fl.x as isize - 1, fl.y as isize - 1, fl.z as isize - 1);
        let b = &self.bricks;
        let ix: [usize; 4] = std::array::from_fn(|a| b.x(bspline::mirror(bi + a as isize, d[0])));
        // The 4 channels as one f32 SIMD vector (as on the GPU), weights in f32.
        let (wx, wy, wz) = (
            wx.map(|w| w as f32),
            wy.map(|w| w as f32),
            wz.map(|w| w as f32),
        );
        let mut out = Vec4::ZERO;
        for (c_k, w_k) in wz.iter().enumerate() {
            let k = b.z(bspline::mirror(bk + c_k as isize, d[2]));
            for (c_j, w_j) in wy.iter().enumerate() {
                let row = b.y(bspline::mirror(bj + c_j as isize, d[1])) + k;
                let wjk = w_k * w_j;
                let mut line = Vec4::ZERO;
                for (a, w_i) in wx.iter().enumerate() {
                    line += Vec4::from(coeffs[row + ix[a]]) * *w_i;
                }
                out += line * wjk;
            }
        }
        out.as_dvec4().to_array()
    }

    /// Is grid point g beyond the nodes (where `Outside::Ambient` applies)?
    #[inline]
    fn beyond_grid(&self, g: DVec3) -> bool {
        g.cmplt(DVec3::ZERO).any() || g.cmpgt(self.gmax).any()
    }
}

/// Trilinear interpolation of the 4 channels of `fetch(voxel index in brick order)` at
/// grid point g (inside [0, dims - 1], so truncation is floor).
#[inline]
fn trilinear_in(
    geometry: &GridGeometry,
    bricks: &Bricks,
    g: DVec3,
    fetch: impl Fn(usize) -> Vec4,
) -> Vec4 {
    let d = geometry.dims;
    let base = |x: f64, n: usize| -> (usize, f64) {
        let i = (x as usize).min(n - 2);
        (i, x - i as f64)
    };
    let (i, tx) = base(g.x, d[0]);
    let (j, ty) = base(g.y, d[1]);
    let (k, tz) = base(g.z, d[2]);
    let (tx, ty, tz) = (tx as f32, ty as f32, tz as f32);
    let (x0, x1) = (bricks.x(i), bricks.x(i + 1));
    let mut out = Vec4::ZERO;
    for (dk, wz) in [(0, 1.0 - tz), (1, tz)] {
        let z = bricks.z(k + dk);
        for (dj, wy) in [(0, 1.0 - ty), (1, ty)] {
            let row = bricks.y(j + dj) + z;
            let (a, b) = (fetch(row + x0), fetch(row + x1));
            let w = wy * wz;
            out += a * (w * (1.0 - tx)) + b * (w * tx);
        }
    }
    out
}

/// Prefilter every channel along x, y, z into cubic B-spline coefficients.
///
/// Each axis is filtered a block of nodes at a time ([`bspline::prefilter_blocks`]): x lines
/// node by node, y lines a row of x at a time within each z slab, z lines a piece of the
/// x-y plane at a time, the pieces on rayon's threads.
fn prefilter(voxels: &Voxels, dims: [usize; 3]) -> Vec<[f32; 4]> {
    let [nx, ny, nz] = dims;
    let mut data: Vec<[f64; 4]> = (0..voxels.len())
        .into_par_iter()
        .map(|i| voxels.get(i).map(f64::from))
        .collect();
    data.par_chunks_mut(nx).for_each(|line| {
        let mut nodes: Vec<&mut [[f64; 4]]> = line.chunks_mut(1).collect();
        bspline::prefilter_blocks(&mut nodes);
    });
    data.par_chunks_mut(nx * ny).for_each(|slab| {
        let mut rows: Vec<&mut [[f64; 4]]> = slab.chunks_mut(nx).collect();
        bspline::prefilter_blocks(&mut rows);
    });
    // z: the plane cut into pieces of columns; piece p of every plane is one block list.
    let plane = nx * ny;
    let piece = plane
        .div_ceil(4 * rayon::current_num_threads().max(1))
        .max(64);
    let mut pieces: Vec<Vec<&mut [[f64; 4]]>> = Vec::new();
    for layer in data.chunks_mut(plane) {
        for (p, part) in layer.chunks_mut(piece).enumerate() {
            if p == pieces.len() {
                pieces.push(Vec::with_capacity(nz));
            }
            pieces[p].push(part);
        }
    }
    pieces
        .into_par_iter()
        .for_each(|mut planes| bspline::prefilter_blocks(&mut planes));
    data.into_par_iter().map(|v| v.map(|x| x as f32)).collect()
}

impl IndexField for BakedField {
    fn as_baked(&self) -> Option<&BakedField> {
        Some(self)
    }

    fn sample_eps(&self) -> f64 {
        f64::from(f32::EPSILON)
    }

    fn n_uncertainty(&self) -> f64 {
        let e = self.provenance.max_err_n;
        if e.is_finite() && e > 0.0 { e } else { 0.0 }
    }

    fn sample(&self, p: DVec3) -> FieldSample<f64> {
        let g = (p - self.geometry.origin) * self.inv_spacing;
        if self.outside == Outside::Ambient && self.beyond_grid(g) {
            return FieldSample {
                n: self.ambient,
                grad_n: DVec3::ZERO,
            };
        }
        let v = self.interpolate(g);
        FieldSample {
            n: self.ambient + v[0],
            grad_n: DVec3::new(v[1], v[2], v[3]),
        }
    }

    fn bounds(&self) -> Bounds {
        self.bounds
    }

    fn ambient_index(&self) -> f64 {
        self.ambient
    }

    fn n_range(&self) -> (f64, f64) {
        self.n_range
    }

    /// Two grid spacings: nothing narrower is represented.
    fn feature_size(&self) -> Option<f64> {
        Some(2.0 * self.geometry.spacing.min_element())
    }

    fn source_spacing(&self) -> Option<f64> {
        Some(self.geometry.spacing.min_element())
    }
    fn max_grad_n(&self) -> f64 {
        self.max_grad
    }

    fn describe(&self) -> String {
        let [nx, ny, nz] = self.geometry.dims;
        format!(
            "baked {nx}x{ny}x{nz} {} {} of [{}]",
            self.interp.name(),
            self.storage().name(),
            self.provenance.source
        )
    }

    fn homogeneous_span(&self, p: DVec3, dir: DVec3) -> Option<f64> {
        let g = (p - self.geometry.origin) * self.inv_spacing;
        let dg = dir * self.inv_spacing;
        if self.beyond_grid(g) {
            if self.outside == Outside::Clamp {
                return None;
            }
            // Ambient outside a cropped grid: straight to the grid box (or out of the medium).
            let (lo, hi) = self.geometry.world_box();
            let to_grid = Bounds::Box { min: lo, max: hi }
                .intersect(p, dir)
                .map(|(s_in, _)| s_in.max(0.0));
            let to_exit = self
                .bounds
                .intersect(p, dir)
                .map(|(_, s_out)| s_out.max(0.0));
            return match (to_grid, to_exit) {
                (Some(a), Some(b)) => Some(a.min(b)),
                (Some(a), None) => Some(a),
                (None, b) => b,
            }
            .filter(|&s| s > 0.0);
        }
        self.macro_grid
            .span(g, dg, self.geometry.dims)
            .filter(|&s| s > 0.0)
    }
}

#[cfg(test)]
mod tests;
