//! [`SparseField`]: a baked field kept only where the index differs from ambient, each part
//! at the resolution its own content needs.
//!
//! Layout. The medium's box is cut into a top grid of cubic *bricks* of world edge `edge`
//! (brick (a, b, c) covers `origin + edge * [a, a+1] x [b, b+1] x [c, c+1]`, x fastest in
//! the `table`). A brick the field leaves at ambient is empty (`table` holds [`EMPTY`]); an
//! active brick holds a dense grid of `m = cells + 1 + 2 apron` nodes per edge, `cells =
//! LEVEL_CELLS[level]` (a ladder of ratio ~1.25 from 4 to 256, so a brick is at most 25%
//! finer per axis than its content needs), node (i, j, k) at `brick origin + (edge /
//! cells) (i - apron, j - apron, k - apron)`, voxel `i + m * (j + m * k)`, channels
//! `[delta_n, dn/dx, dn/dy, dn/dz]` as in a dense bake; `apron` is 0 (trilinear) or 1
//! (Catmull-Rom, below).
//! Each brick's voxels start at its `offset` in one shared pool (an atlas).
//!
//! Every brick owns the nodes on its faces (what trilinear reads need), so a sample reads
//! one brick only. Where bricks of different levels meet, their faces interpolate the same
//! source at different spacings: the jump there is at most the coarser brick's
//! interpolation error, inside the budget the bake measured. i16 storage keeps a scale per
//! brick (delta_n, and one for the gradient's components).
//!
//! Two samplings, one a field: trilinear (C0, second order), or tricubic Catmull-Rom (C1,
//! third order: exact for quadratics), which reads 4 nodes an axis around the cell. A
//! Catmull-Rom brick stores an *apron*: one more layer of nodes beyond each face, baked
//! from the source at the brick's own spacing (`cells + 3` nodes an edge, node (i, j, k)
//! at `brick origin + edge / cells * (i - 1, j - 1, k - 1)`), so its reads stay in the
//! brick as trilinear ones do. Catmull-Rom needs no prefilter (it interpolates the nodes
//! as they are), so a brick is baked on its own; a smooth field needs far fewer nodes
//! than trilinear for the same error. Its negative weights ring past a sharp edge, so a
//! sample's delta_n is clamped to the range of all the field's nodes, with a zero
//! gradient where clamped (as grin's Catmull-Rom sampling of a VDB grid is: a bake on that
//! grid's own lattice then interpolates exactly what the grid does).
//!
//! One concept a file: the field and its sampling here, the bake in `bake`, the file in
//! `file`.

pub mod bake;
pub mod file;
#[cfg(test)]
mod tests;

use glam::{DVec3, Vec4};

use crate::baked::{BakeProvenance, Interp, MacroGrid, Storage};
use crate::bounds::Bounds;
use crate::field::{FieldSample, IndexField};

/// `table` entry of an empty brick.
pub const EMPTY: u32 = u32::MAX;
/// Cells per brick edge at each level: steps of ~1.25 (a power-of-two ladder overshot
/// what a brick needs by up to 2x per axis, 8x in memory).
pub const LEVEL_CELLS: [usize; 19] = [
    4, 5, 6, 8, 10, 12, 16, 20, 24, 32, 40, 48, 64, 80, 96, 128, 160, 192, 256,
];
/// Cells per brick edge at level 0.
pub const BASE_CELLS: usize = LEVEL_CELLS[0];
/// Finest level (256 cells a brick edge).
pub const MAX_LEVEL: u8 = (LEVEL_CELLS.len() - 1) as u8;

/// Cells per brick edge at `level` (at most [`MAX_LEVEL`]).
pub fn cells_of(level: u8) -> usize {
    LEVEL_CELLS[usize::from(level)]
}

/// One active brick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Brick {
    /// Top-grid coordinates.
    pub at: [u32; 3],
    /// `LEVEL_CELLS[level]` cells per edge.
    pub level: u8,
    /// First voxel in the pool.
    pub offset: usize,
    /// i16 storage: the scale of delta_n and of the gradient's components (1 for f32).
    pub scale: [f32; 2],
    /// Layers of nodes beyond each face: 0 (trilinear) or 1 (Catmull-Rom), the same for
    /// every brick of a field.
    pub apron: u8,
}

/// The apron a sampling needs beyond each brick face (see the module docs).
pub fn apron_of(interp: Interp) -> u8 {
    match interp {
        Interp::Trilinear => 0,
        Interp::Tricubic => 1,
    }
}

/// Nodes a brick edge of `cells` cells stores with `apron` layers beyond each face.
pub fn nodes_of(cells: usize, apron: u8) -> usize {
    cells + 1 + 2 * usize::from(apron)
}

/// The sum of |Catmull-Rom weights| along an axis is at most 1.25 (at t = 1/2), so an
/// interpolated gradient lies within (1.25^3 - 1) / 2 of its nodes' range beyond that
/// range (delta_n itself is clamped to its nodes' range: see the module docs).
pub const CATMULL_ROM_OVERSHOOT: f64 = (1.25 * 1.25 * 1.25 - 1.0) / 2.0;

/// Catmull-Rom weights at fraction t of the cell between the middle two of 4 nodes, in
/// f32 as on the GPU (the shader's `catmull_rom_weights`).
#[inline]
pub fn catmull_rom_weights(t: f32) -> [f32; 4] {
    crate::vdb::catmull_rom::catmull_rom_weights(t)
}

/// d/dt of [`catmull_rom_weights`], f32 as on the GPU (the shader's
/// `catmull_rom_derivatives`).
pub fn catmull_rom_derivatives(t: f32) -> [f32; 4] {
    crate::vdb::catmull_rom::catmull_rom_weight_derivatives(t)
}

impl Brick {
    pub fn cells(&self) -> usize {
        cells_of(self.level)
    }
    /// Nodes per edge (the apron's included).
    pub fn nodes(&self) -> usize {
        nodes_of(self.cells(), self.apron)
    }
    pub fn voxel_count(&self) -> usize {
        self.nodes().pow(3)
    }
    /// The voxels (pool indices) of the brick's own `(cells + 1)^3` nodes, those on and
    /// inside its faces, x fastest: all of them, or all but the apron.
    pub fn inner_voxels(&self) -> impl Iterator<Item = usize> + use<> {
        let (m, a, inner) = (self.nodes(), usize::from(self.apron), self.cells() + 1);
        let offset = self.offset;
        (0..inner.pow(3)).map(move |v| {
            let (i, j, k) = (
                v % inner + a,
                (v / inner) % inner + a,
                v / (inner * inner) + a,
            );
            offset + i + m * (j + m * k)
        })
    }
}

/// Voxels of every brick, one after another.
#[derive(Debug, Clone, PartialEq)]
pub enum Pool {
    F32(Vec<[f32; 4]>),
    I16(Vec<[i16; 4]>),
}

impl Pool {
    pub fn len(&self) -> usize {
        match self {
            Pool::F32(v) => v.len(),
            Pool::I16(v) => v.len(),
        }
    }
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    pub fn storage(&self) -> Storage {
        match self {
            Pool::F32(_) => Storage::F32,
            Pool::I16(_) => Storage::I16,
        }
    }
}

/// The top grid: where the bricks sit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TopGrid {
    pub origin: DVec3,
    /// World edge of a brick.
    pub edge: f64,
    /// Bricks per axis.
    pub dims: [usize; 3],
}

impl TopGrid {
    pub fn brick_count(&self) -> usize {
        self.dims[0] * self.dims[1] * self.dims[2]
    }
    pub fn index(&self, at: [usize; 3]) -> usize {
        at[0] + self.dims[0] * (at[1] + self.dims[1] * at[2])
    }
    /// The position of brick number `index` (the inverse of [`Self::index`]).
    pub fn at(&self, index: usize) -> [usize; 3] {
        [
            index % self.dims[0],
            (index / self.dims[0]) % self.dims[1],
            index / (self.dims[0] * self.dims[1]),
        ]
    }
    /// The brick holding top-grid point `g` (world point minus origin, over the edge):
    /// the nearest brick where `g` is beyond the grid (saturating casts: NaN and negatives
    /// to the first, past the end to the last; the far face belongs to the last brick).
    ///
    /// A float's `as usize` is its floor for the non-negative ones and saturates (NaN and
    /// negatives to 0), so no floor is called (a libm call on baseline x86-64).
    #[inline]
    pub fn brick_holding(&self, g: DVec3) -> [usize; 3] {
        std::array::from_fn(|a| (g[a] as usize).min(self.dims[a] - 1))
    }
    /// World box of brick `at`.
    pub fn brick_box(&self, at: [usize; 3]) -> (DVec3, DVec3) {
        let lo = self.origin + self.edge * DVec3::new(at[0] as f64, at[1] as f64, at[2] as f64);
        (lo, lo + DVec3::splat(self.edge))
    }
}

/// The cell of a brick with `cells` cells a side holding cell coordinates `u` (clamped to
/// the brick), and `u`'s fractions in it: what a trilinear read of the brick blends.
#[inline]
pub(crate) fn cell_of(u: DVec3, cells: usize) -> ([usize; 3], [f64; 3]) {
    let mut i = [0usize; 3];
    let mut t = [0.0f64; 3];
    for a in 0..3 {
        let x = u[a].clamp(0.0, cells as f64);
        i[a] = (x as usize).min(cells - 1);
        t[a] = x - i[a] as f64;
    }
    (i, t)
}

/// A sparse, multi-resolution baked field (see the module docs).
#[derive(Debug, Clone)]
pub struct SparseField {
    top: TopGrid,
    table: Vec<u32>,
    bricks: Vec<Brick>,
    pool: Pool,
    bounds: Bounds,
    ambient: f64,
    provenance: BakeProvenance,
    // Derived on construction.
    n_range: (f64, f64),
    max_grad: f64,
    macro_grid: MacroGrid,
    /// Per top-grid brick: the most cells a side of the active bricks among it and its 26
    /// neighbours (0: none active), the local step cap's feature.
    near_cells: Vec<u16>,
    /// The finest level of any active brick (`None` when none is).
    finest_level: Option<u8>,
    /// 1 / the top grid's edge: top-grid coordinates are a product, as on the GPU.
    inv_edge: f64,
    /// The nodes' delta_n range, as f32 (what the GPU compares with): a Catmull-Rom
    /// sample's delta_n is clamped to it.
    delta_range: (f32, f32),
    /// Apron layers of every brick (0 trilinear, 1 Catmull-Rom): the bricks', or for a
    /// field with none what it was baked with ([`Self::with_apron`]).
    apron: u8,
    /// Catmull-Rom bricks whose gradient is the derivative of their interpolated delta_n
    /// (the stored gradient channels unused): a bake on a source's own lattice, whose
    /// source's gradient is that derivative ([`Self::with_gradient_of_n`]).
    gradient_of_n: bool,
}

/// Why a sparse field's parts do not fit together.
pub fn check_parts(
    top: &TopGrid,
    table: &[u32],
    bricks: &[Brick],
    pool_len: usize,
) -> Result<(), String> {
    if !(top.edge.is_finite() && top.edge > 0.0 && top.origin.is_finite()) {
        return Err(format!(
            "brick edge {} and origin {} must be finite (edge positive)",
            top.edge, top.origin
        ));
    }
    let count = top
        .dims
        .iter()
        .try_fold(1usize, |a, &d| a.checked_mul(d).filter(|_| d > 0));
    if count != Some(table.len()) {
        return Err(format!(
            "a top grid of {:?} bricks does not match a table of {} entries",
            top.dims,
            table.len()
        ));
    }
    let mut seen = vec![false; bricks.len()];
    let mut at_end = 0usize;
    let apron = bricks.first().map_or(0, |b| b.apron);
    for (i, b) in bricks.iter().enumerate() {
        if b.apron > 1 || b.apron != apron {
            return Err(format!(
                "brick {i} has an apron of {} node layers where brick 0 has {apron} (0 or 1, the same for all)",
                b.apron
            ));
        }
        if b.level > MAX_LEVEL {
            return Err(format!(
                "brick {i} has level {} (at most {MAX_LEVEL})",
                b.level
            ));
        }
        if b.at.iter().zip(top.dims).any(|(&a, d)| a as usize >= d) {
            return Err(format!(
                "brick {i} at {:?} lies outside the top grid {:?}",
                b.at, top.dims
            ));
        }
        if b.offset != at_end {
            return Err(format!(
                "brick {i} starts at voxel {} where the previous brick ends at {at_end}",
                b.offset
            ));
        }
        if !b.scale.iter().all(|s| s.is_finite() && *s > 0.0) {
            return Err(format!(
                "brick {i} has scale {:?} (must be positive)",
                b.scale
            ));
        }
        at_end += b.voxel_count();
        let at = b.at.map(|a| a as usize);
        if table[top.index(at)] != i as u32 {
            return Err(format!(
                "brick {i} at {:?} is not the table's entry there",
                b.at
            ));
        }
    }
    if at_end != pool_len {
        return Err(format!(
            "the bricks hold {at_end} voxels but the pool has {pool_len}"
        ));
    }
    for &e in table {
        if e == EMPTY {
            continue;
        }
        match seen.get_mut(e as usize) {
            Some(s) if !*s => *s = true,
            Some(_) => return Err(format!("brick {e} appears twice in the table")),
            None => {
                return Err(format!("the table names brick {e} of {}", bricks.len()));
            }
        }
    }
    Ok(())
}

impl SparseField {
    /// Assemble a sparse field; refuses parts that do not fit together (a crafted file)
    /// and non-finite voxels.
    pub fn new(
        top: TopGrid,
        table: Vec<u32>,
        bricks: Vec<Brick>,
        pool: Pool,
        bounds: Bounds,
        ambient: f64,
        provenance: BakeProvenance,
    ) -> Result<Self, String> {
        check_parts(&top, &table, &bricks, pool.len())?;
        let bricks_apron = bricks.first().map_or(0, |b| b.apron);
        if !(ambient.is_finite() && ambient > 0.0) {
            return Err(format!("ambient index {ambient} must be positive"));
        }
        let mut field = SparseField {
            top,
            table,
            bricks,
            pool,
            bounds,
            ambient,
            provenance,
            n_range: (ambient, ambient),
            max_grad: 0.0,
            macro_grid: MacroGrid {
                cell: 1,
                dims: top.dims,
                max_grad: Vec::new(),
                threshold: 0.5,
            },
            near_cells: Vec::new(),
            finest_level: None,
            inv_edge: 1.0 / top.edge,
            delta_range: (0.0, 0.0),
            apron: bricks_apron,
            gradient_of_n: false,
        };
        field.near_cells = field.neighbourhood_cells();
        field.finest_level = field.bricks.iter().map(|b| b.level).max();
        let (mut lo, mut hi, mut g) = (0.0f64, 0.0f64, 0.0f64);
        for (bi, b) in field.bricks.iter().enumerate() {
            for v in b.offset..b.offset + b.voxel_count() {
                let x = field.voxel(b, v);
                if !x.iter().all(|c| c.is_finite()) {
                    return Err(format!("brick {bi} holds a non-finite voxel {x:?}"));
                }
                lo = lo.min(x[0]);
                hi = hi.max(x[0]);
                g = g.max(DVec3::new(x[1], x[2], x[3]).length());
            }
        }
        if ambient + lo <= 0.0 {
            return Err(format!("n = {} <= 0 in the stored voxels", ambient + lo));
        }
        // delta_n stays in its nodes' range (Catmull-Rom's is clamped there); its
        // interpolated gradient may reach past the nodes' largest.
        let over = match field.interp() {
            Interp::Trilinear => 0.0,
            Interp::Tricubic => CATMULL_ROM_OVERSHOOT,
        };
        field.n_range = (ambient + lo, ambient + hi);
        field.max_grad = g * (1.0 + 2.0 * over);
        field.delta_range = (lo as f32, hi as f32);
        // Straight flights over empty bricks: one macro cell a brick, homogeneous (0)
        // where empty.
        field.macro_grid.max_grad = field
            .table
            .iter()
            .map(|&e| if e == EMPTY { 0.0 } else { 1.0 })
            .collect();
        Ok(field)
    }

    /// [`Self::near_cells`] of every top-grid brick, in table order.
    fn neighbourhood_cells(&self) -> Vec<u16> {
        let cells_at = |at: [usize; 3]| match self.table[self.top.index(at)] {
            EMPTY => 0,
            e => self.bricks[e as usize].cells() as u16,
        };
        let dims = self.top.dims;
        (0..self.table.len())
            .map(|i| {
                let at = self.top.at(i);
                let range = |a: usize| at[a].saturating_sub(1)..=(at[a] + 1).min(dims[a] - 1);
                let mut most = 0;
                for z in range(2) {
                    for y in range(1) {
                        for x in range(0) {
                            most = most.max(cells_at([x, y, z]));
                        }
                    }
                }
                most
            })
            .collect()
    }

    /// The most cells a side of the active bricks in and next to the top-grid brick
    /// holding `p` (the nearest brick where `p` is beyond the grid; 0 where none is
    /// active). A step no longer than two of those cells cannot leave that neighbourhood
    /// (bricks have at least 4 cells a side), so it cannot pass over a finer brick's
    /// features unseen: the local step cap ([`IndexField::step_cap`]), the GPU's too
    /// (the table texel's fourth channel).
    pub fn near_cells(&self, p: DVec3) -> u16 {
        let at = self.top.brick_holding(self.top_coords(p));
        self.near_cells[self.top.index(at)]
    }

    /// World point `p` in top-grid coordinates (bricks from the origin).
    #[inline]
    fn top_coords(&self, p: DVec3) -> DVec3 {
        (p - self.top.origin) * self.inv_edge
    }

    /// The near-cells of table entry `i` (what the GPU upload stores).
    pub fn near_cells_at(&self, i: usize) -> u16 {
        self.near_cells[i]
    }

    pub fn top(&self) -> &TopGrid {
        &self.top
    }
    pub fn table(&self) -> &[u32] {
        &self.table
    }
    pub fn bricks(&self) -> &[Brick] {
        &self.bricks
    }
    pub fn pool(&self) -> &Pool {
        &self.pool
    }
    pub fn storage(&self) -> Storage {
        self.pool.storage()
    }
    /// How the field is sampled: trilinear, or tricubic Catmull-Rom where its bricks hold
    /// an apron (see the module docs).
    pub fn interp(&self) -> Interp {
        match self.apron {
            0 => Interp::Trilinear,
            _ => Interp::Tricubic,
        }
    }
    /// Layers of apron nodes beyond each brick face (0 or 1).
    pub fn apron(&self) -> u8 {
        self.apron
    }
    /// The field with `apron` (0 or 1) as its sampling's: what a field with no active brick
    /// keeps of how it was baked (an all-ambient medium baked Catmull-Rom stays one). A
    /// field with bricks must already have it.
    pub fn with_apron(mut self, apron: u8) -> Result<Self, String> {
        if apron > 1 || (!self.bricks.is_empty() && apron != self.apron) {
            return Err(format!(
                "an apron of {apron} node layers for bricks with {}",
                self.apron
            ));
        }
        self.apron = apron;
        // Trilinear sampling has no gradient of its n (nor a file code for one).
        self.gradient_of_n &= apron == 1;
        Ok(self)
    }
    /// Whether the gradient is the derivative of the interpolated delta_n (see the field
    /// `gradient_of_n`).
    pub fn gradient_of_n(&self) -> bool {
        self.gradient_of_n
    }
    /// The field sampling its gradient as the derivative of its Catmull-Rom delta_n
    /// (`on`), or from its gradient channels: the first only for a Catmull-Rom field.
    pub fn with_gradient_of_n(mut self, on: bool) -> Result<Self, String> {
        if on && self.apron == 0 {
            return Err("a gradient of n for trilinear bricks (Catmull-Rom only)".into());
        }
        self.gradient_of_n = on;
        Ok(self)
    }
    /// The nodes' delta_n range (f32) a Catmull-Rom sample is clamped to.
    pub fn delta_range(&self) -> (f32, f32) {
        self.delta_range
    }
    pub fn provenance(&self) -> &BakeProvenance {
        &self.provenance
    }
    pub fn set_provenance(&mut self, p: BakeProvenance) {
        self.provenance = p;
    }
    /// Bytes of voxel data (what the file stores after its table).
    pub fn data_bytes(&self) -> usize {
        self.pool.len() * self.storage().bytes_per_voxel()
    }
    /// Bytes in memory: voxels, the table and the brick records.
    pub fn memory_bytes(&self) -> usize {
        self.data_bytes() + 4 * self.table.len() + std::mem::size_of::<Brick>() * self.bricks.len()
    }
    /// Node spacing of a brick at `level`.
    pub fn spacing(&self, level: u8) -> f64 {
        self.top.edge / cells_of(level) as f64
    }
    /// The finest spacing any brick has (the top grid's edge when none is active).
    pub fn finest_spacing(&self) -> f64 {
        self.finest_level.map_or(self.top.edge, |l| self.spacing(l))
    }
    /// Active bricks per level.
    pub fn level_counts(&self) -> [usize; MAX_LEVEL as usize + 1] {
        let mut out = [0; MAX_LEVEL as usize + 1];
        for b in &self.bricks {
            out[b.level as usize] += 1;
        }
        out
    }

    /// Voxel `v` of brick `b` decoded to f64 channels.
    #[inline]
    fn voxel(&self, b: &Brick, v: usize) -> [f64; 4] {
        match &self.pool {
            Pool::F32(p) => p[v].map(f64::from),
            Pool::I16(p) => {
                let q = p[v];
                let (sd, sg) = (f64::from(b.scale[0]), f64::from(b.scale[1]));
                [
                    f64::from(q[0]) * sd,
                    f64::from(q[1]) * sg,
                    f64::from(q[2]) * sg,
                    f64::from(q[3]) * sg,
                ]
            }
        }
    }

    /// Voxel `v` (a pool index) of brick `b` decoded to f32 channels (what a GPU upload
    /// holds).
    pub fn voxel_f32(&self, b: &Brick, v: usize) -> [f32; 4] {
        match &self.pool {
            Pool::F32(p) => p[v],
            Pool::I16(p) => {
                let q = p[v];
                [
                    f32::from(q[0]) * b.scale[0],
                    f32::from(q[1]) * b.scale[1],
                    f32::from(q[2]) * b.scale[1],
                    f32::from(q[3]) * b.scale[1],
                ]
            }
        }
    }

    /// The brick holding world point `p` and `p`'s coordinates in its cells, or `None`
    /// where `p` is beyond the top grid or in an empty brick.
    #[inline]
    fn locate(&self, p: DVec3) -> Option<(&Brick, DVec3)> {
        let g = self.top_coords(p);
        for a in 0..3 {
            if !(g[a] >= 0.0 && g[a] <= self.top.dims[a] as f64) {
                return None;
            }
        }
        let at = self.top.brick_holding(g);
        let e = self.table[self.top.index(at)];
        if e == EMPTY {
            return None;
        }
        let b = &self.bricks[e as usize];
        let corner = DVec3::new(at[0] as f64, at[1] as f64, at[2] as f64);
        Some((b, (g - corner) * b.cells() as f64))
    }

    /// Trilinear [delta_n, grad n] at cell coordinates `u` in brick `b`: the 8 taps as one
    /// f32 vector each (as the GPU and the dense grid interpolate), the storage matched
    /// once a sample; i16 taps are blended as integers and scaled once.
    #[inline]
    fn trilinear(&self, b: &Brick, u: DVec3) -> [f64; 4] {
        let cells = b.cells();
        let m = b.nodes();
        let (i, t) = cell_of(u, cells);
        let t = t.map(|t| t as f32);
        let a = usize::from(b.apron);
        let base = b.offset + (i[0] + a) + m * ((i[1] + a) + m * (i[2] + a));
        let offsets = [0, 1, m, m + 1, m * m, m * m + 1, m * m + m, m * m + m + 1];
        let blend = |c: [Vec4; 8]| {
            let x00 = c[0].lerp(c[1], t[0]);
            let x10 = c[2].lerp(c[3], t[0]);
            let x01 = c[4].lerp(c[5], t[0]);
            let x11 = c[6].lerp(c[7], t[0]);
            x00.lerp(x10, t[1]).lerp(x01.lerp(x11, t[1]), t[2])
        };
        let v = match &self.pool {
            Pool::F32(p) => blend(offsets.map(|o| Vec4::from(p[base + o]))),
            Pool::I16(p) => {
                let q = blend(offsets.map(|o| {
                    let q = p[base + o];
                    Vec4::new(
                        f32::from(q[0]),
                        f32::from(q[1]),
                        f32::from(q[2]),
                        f32::from(q[3]),
                    )
                }));
                q * Vec4::new(b.scale[0], b.scale[1], b.scale[1], b.scale[1])
            }
        };
        v.to_array().map(f64::from)
    }

    /// Tricubic Catmull-Rom [delta_n, grad n] at cell coordinates `u` in brick `b` (which
    /// holds an apron): the 4 x 4 x 4 nodes around the cell, weights in f32, each line of
    /// 4 along x weighted and then scaled by its y-z weight, z outer (the shader's order);
    /// i16 taps are scaled once at the end.
    #[inline]
    fn catmull_rom(&self, b: &Brick, u: DVec3) -> [f64; 4] {
        let cells = b.cells();
        let m = b.nodes();
        let (i, t) = cell_of(u, cells);
        let [wx, wy, wz] = t.map(|t| catmull_rom_weights(t as f32));
        // Node i - 1 of the cell is stored at i (the apron shifts every index by one).
        let base = b.offset + i[0] + m * (i[1] + m * i[2]);
        let tap = |v: usize| -> Vec4 {
            match &self.pool {
                Pool::F32(p) => Vec4::from(p[v]),
                Pool::I16(p) => {
                    let q = p[v];
                    Vec4::new(
                        f32::from(q[0]),
                        f32::from(q[1]),
                        f32::from(q[2]),
                        f32::from(q[3]),
                    )
                }
            }
        };
        let mut out = Vec4::ZERO;
        if self.gradient_of_n {
            // delta_n and its derivatives in cell units, from the delta_n channel alone
            // (the shader's sparse_cr_plane_n, in its order).
            let [dx, dy, dz] = t.map(|t| catmull_rom_derivatives(t as f32));
            for k in 0..4 {
                for j in 0..4 {
                    let row = base + m * (j + m * k);
                    let f = [tap(row).x, tap(row + 1).x, tap(row + 2).x, tap(row + 3).x];
                    let v = f[0] * wx[0] + f[1] * wx[1] + f[2] * wx[2] + f[3] * wx[3];
                    let d = f[0] * dx[0] + f[1] * dx[1] + f[2] * dx[2] + f[3] * dx[3];
                    out += Vec4::new(v, d, v, v)
                        * Vec4::new(wz[k] * wy[j], wz[k] * wy[j], wz[k] * dy[j], dz[k] * wy[j]);
                }
            }
            if let Pool::I16(_) = &self.pool {
                out *= b.scale[0];
            }
            // Cell units to world: a cell is edge / cells.
            let per_cell = cells as f32 * self.inv_edge as f32;
            out *= Vec4::new(1.0, per_cell, per_cell, per_cell);
            return out.to_array().map(f64::from);
        }
        for (k, w_k) in wz.iter().enumerate() {
            for (j, w_j) in wy.iter().enumerate() {
                let row = base + m * (j + m * k);
                let mut line = tap(row) * wx[0];
                line += tap(row + 1) * wx[1];
                line += tap(row + 2) * wx[2];
                line += tap(row + 3) * wx[3];
                out += line * (w_k * w_j);
            }
        }
        if let Pool::I16(_) = &self.pool {
            out *= Vec4::new(b.scale[0], b.scale[1], b.scale[1], b.scale[1]);
        }
        out.to_array().map(f64::from)
    }
}

impl IndexField for SparseField {
    fn sample(&self, p: DVec3) -> FieldSample<f64> {
        match self.locate(p) {
            None => FieldSample {
                n: self.ambient,
                grad_n: DVec3::ZERO,
            },
            Some((b, u)) => {
                let x = if b.apron == 0 {
                    self.trilinear(b, u)
                } else {
                    let x = self.catmull_rom(b, u);
                    let (lo, hi) = self.delta_range;
                    let (lo, hi) = (f64::from(lo), f64::from(hi));
                    if x[0] < lo || x[0] > hi {
                        // Rings past the nodes: flat at their range.
                        [x[0].clamp(lo, hi), 0.0, 0.0, 0.0]
                    } else {
                        x
                    }
                };
                FieldSample {
                    n: self.ambient + x[0],
                    grad_n: DVec3::new(x[1], x[2], x[3]),
                }
            }
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
    fn max_grad_n(&self) -> f64 {
        self.max_grad
    }
    fn describe(&self) -> String {
        let sampling = match self.interp() {
            Interp::Trilinear => "",
            Interp::Tricubic => ", Catmull-Rom",
        };
        format!(
            "sparse bake ({} of {} bricks{sampling}) of {}",
            self.bricks.len(),
            self.table.len(),
            self.provenance.source
        )
    }
    /// Empty bricks are exactly ambient: a ray in one flies straight to the next active
    /// brick (the top grid is the macro-cell grid).
    fn homogeneous_span(&self, p: DVec3, dir: DVec3) -> Option<f64> {
        let g = self.top_coords(p);
        let d = DVec3::new(
            self.top.dims[0] as f64,
            self.top.dims[1] as f64,
            self.top.dims[2] as f64,
        );
        if !(g.cmpge(DVec3::ZERO).all() && g.cmple(d).all()) {
            return None;
        }
        let node_dims = self.top.dims.map(|n| n + 1);
        self.macro_grid.span(g, dir * self.inv_edge, node_dims)
    }
    /// Twice the spacing of the finest brick in and next to the brick holding `p`
    /// ([`SparseField::near_cells`]): a step that long passes over no node of a finer
    /// brick unseen, and coarse bricks far from fine ones take long steps. One brick edge
    /// where none is active: the step ends in an empty neighbour at the farthest.
    fn step_cap(&self, p: DVec3, _reach: f64) -> f64 {
        match self.near_cells(p) {
            0 => self.top.edge,
            cells => 2.0 * self.top.edge / f64::from(cells),
        }
    }
    fn source_spacing(&self) -> Option<f64> {
        Some(self.finest_spacing())
    }
    fn n_uncertainty(&self) -> f64 {
        self.provenance.max_err_n
    }
    fn sample_eps(&self) -> f64 {
        f64::from(f32::EPSILON)
    }
    fn as_sparse(&self) -> Option<&SparseField> {
        Some(self)
    }
}
