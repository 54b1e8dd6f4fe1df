//! VDB-sourced fields: an OpenVDB scalar grid (temperature, density or index) mapped to a
//! refractive index n(r) in world space, through vdb-sys.
//!
//! Mapping (scene `map`), applied to every voxel before interpolation:
//! - `index`: n = value, or n = n_ambient + value with `delta = true`;
//! - `linear`: n = n_ambient + k * value;
//! - `gladstone-dale` (air): T_K = T_ambient + scale_k * value, rho = P / (R_s T_K),
//!   n = 1 + K rho (docs/physics.md, Air; defaults K = 2.26e-4 m^3/kg, P = 101325 Pa,
//!   R_s = 287.05 J/(kg K)).
//!
//! World space: world (scene metres) = `units` * (A * ijk + t), where `[A | t]` is the
//! grid's affine index-to-world transform (voxel size, rotation, offset). Non-linear
//! (frustum) transforms are rejected. Integer index coordinates are voxel centres.
//!
//! Interpolation: tricubic Catmull-Rom on the mapped delta_n = n - n_ambient, with the
//! gradient the exact derivative of that interpolant. It passes through the voxel values,
//! reproduces quadratics and is C1, so grad n is continuous (no kinks for the
//! integrators); the interpolation error of a smooth field is O(h^3) in n and O(h^2) in
//! grad n (h = voxel size). For the Gaussian of `data/vdb/test/gaussian.vdb` (width
//! s = 10 voxels, f32 storage) tests/vdb.rs measures max |n error| = 1.2e-4 of the
//! amplitude, max |grad n error| = 6.6e-3 of max |grad n|, and ray exit directions within
//! 0.25 % of the rays' bend (asserted: 5e-4, 2e-2 and 1 %). The unit test
//! `catmull_rom_converges_at_third_order_in_n_and_second_in_grad` measures the orders:
//! 3.0 in n and 1.9 in grad n (s/h = 8 -> 16).
//! At a voxel centre the gradient equals the central difference of the mapped values.
//! The interpolant is clamped to the range of the mapped values (background included),
//! with a zero gradient where clamped: at a sharp edge Catmull-Rom rings past the data
//! (n above ambient beside a hot plume, a voxel outside a blob 1e-5 off ambient where
//! OpenVDB's own sampler gives ambient), and the clamp keeps every sample, and so every
//! bake, within what the mapping produces (`interpolant_stays_in_the_mapped_range`).
//! Smooth data away from its extreme voxels is unchanged (the orders below hold).
//! Outside the grid's data box the field is the mapped background value.
//!
//! Storage: the data box is read a brick of 32^3 voxels at a time (OpenVDB's copyToDense
//! of the brick) and only the bricks with a voxel whose index differs from the background
//! are kept ([`Bricks`]): memory follows the data, not its box (two blocks 300 voxels
//! apart: 0.5 MB kept where the dense copy took 344 MB; 32 voxels a side: smaller bricks
//! sent more samples across brick edges, 16 made fire-haze's bake 1.33 -> 1.7 s). `max_bytes` caps the bricks
//! kept, and the box itself at one voxel a byte (reading costs time for every voxel).
//!
//! The module holds one concept a file: [`VdbField`] and its sampling here, loading in
//! `load`, the value mapping in `mapping`, the scene placement in `placement`, the brick
//! store in `bricks`, the data box in `locate`, sequence checks in `sequence` and the
//! Catmull-Rom interpolant in `catmull_rom`.

mod bricks;
pub(crate) mod catmull_rom;
mod load;
mod locate;
mod mapping;
mod placement;
mod sequence;
#[cfg(test)]
mod tests;

use std::path::{Path, PathBuf};

use glam::{DAffine3, DVec3};
use vdb_sys::IndexBox;

use crate::bounds::Bounds;
use crate::field::{FieldSample, IndexField};
use bricks::Bricks;

pub use load::VdbFieldParams;
pub use locate::{DATA_FRACTION, DataBox, locate_data};
pub use mapping::{GladstoneDale, Mapping};
pub use placement::{IDENTITY, affine_from_rows, placement};
pub use sequence::check_sequence;

/// Default cap on the memory of a grid's voxels as loaded (the stored bricks of mapped
/// delta_n): 2 GiB.
pub const DEFAULT_MAX_DENSE_BYTES: u64 = 2 << 30;
/// Voxels of background read around the active box, so the 4-tap stencil near the edge
/// of the data reads real (background) values.
pub const PAD_VOXELS: i32 = 2;
/// Largest allowed |n(background) - ambient_index|: a larger jump would refract every
/// ray at the invisible medium boundary (heat haze itself is ~1e-5).
pub const AMBIENT_MATCH_TOLERANCE: f64 = 1e-6;

/// An OpenVDB grid mapped to n, sampled by tricubic Catmull-Rom interpolation.
#[derive(Debug, Clone)]
pub struct VdbField {
    label: String,
    bounds: Bounds,
    ambient: f64,
    /// delta_n = n - ambient at the voxels read (0 where not stored: the background is
    /// the ambient, see `from_bricks`).
    voxels: Bricks,
    /// The box of the voxels that change the index, plus [`PAD_VOXELS`]: delta_n is 0
    /// outside it.
    bbox: IndexBox,
    dims: [usize; 3],
    /// index = grid_from_world * (p, 1), p in scene metres.
    grid_from_world: DAffine3,
    /// world = world_from_grid * (ijk, 1), in scene metres.
    world_from_grid: DAffine3,
    n_range: (f64, f64),
    max_grad: f64,
    non_finite_replaced: u64,
    mapping: Mapping,
    /// Where the data lies against the bounds (cut by them, or changing nothing).
    warnings: Vec<String>,
}

impl VdbField {
    /// NaN/Inf voxels replaced by the ambient index (policy `ambient`).
    pub fn non_finite_replaced(&self) -> u64 {
        self.non_finite_replaced
    }

    /// Bytes of the voxels kept (the stored bricks and their table).
    pub fn voxel_bytes(&self) -> u64 {
        self.voxels.stored_bytes()
    }

    /// The dense box (index space) the field holds.
    pub fn index_box(&self) -> IndexBox {
        self.bbox
    }

    /// World (scene metres) position of index coordinates.
    pub fn world_from_index(&self, ijk: DVec3) -> DVec3 {
        self.world_from_grid.transform_point3(ijk)
    }

    /// Fractional index coordinates of a world point.
    pub fn index_from_world(&self, p: DVec3) -> DVec3 {
        self.grid_from_world.transform_point3(p)
    }

    /// World-space axis-aligned box around the dense data.
    pub fn world_aabb(&self) -> (DVec3, DVec3) {
        let mut lo = DVec3::splat(f64::INFINITY);
        let mut hi = DVec3::splat(f64::NEG_INFINITY);
        for c in 0..8 {
            let pick = |a: usize| {
                if c >> a & 1 == 0 {
                    f64::from(self.bbox.min[a])
                } else {
                    f64::from(self.bbox.max[a])
                }
            };
            let w = self.world_from_index(DVec3::new(pick(0), pick(1), pick(2)));
            lo = lo.min(w);
            hi = hi.max(w);
        }
        (lo, hi)
    }

    /// delta_n at index (i, j, k) relative to the box's minimum corner (0 outside it).
    fn node(&self, i: i64, j: i64, k: i64) -> f64 {
        let d = &self.dims;
        if i < 0 || j < 0 || k < 0 || i >= d[0] as i64 || j >= d[1] as i64 || k >= d[2] as i64 {
            return 0.0;
        }
        let m = self.bbox.min.map(i64::from);
        self.voxels.get([i + m[0], j + m[1], k + m[2]])
    }

    /// Gradient (world) from index-space derivatives: grad_world = A^-T grad_index.
    fn grad_to_world(&self, g: [f64; 3]) -> DVec3 {
        self.grid_from_world
            .matrix3
            .transpose_mul_vec3(DVec3::from_array(g))
    }

    /// The largest |grad n| of the voxels' central differences: over the stored bricks
    /// and the voxels next to them (elsewhere every difference is 0).
    fn max_node_gradient(&self) -> f64 {
        let d = self.dims.map(|v| v as i64);
        let m = self.bbox.min.map(i64::from);
        let mut max2: f64 = 0.0;
        for part in self.voxels.stored_boxes() {
            let lo: [i64; 3] = std::array::from_fn(|a| (i64::from(part.min[a]) - 1 - m[a]).max(0));
            let hi: [i64; 3] =
                std::array::from_fn(|a| (i64::from(part.max[a]) + 1 - m[a]).min(d[a] - 1));
            for k in lo[2]..=hi[2] {
                for j in lo[1]..=hi[1] {
                    for i in lo[0]..=hi[0] {
                        let g = [
                            0.5 * (self.node(i + 1, j, k) - self.node(i - 1, j, k)),
                            0.5 * (self.node(i, j + 1, k) - self.node(i, j - 1, k)),
                            0.5 * (self.node(i, j, k + 1) - self.node(i, j, k - 1)),
                        ];
                        max2 = max2.max(self.grad_to_world(g).length_squared());
                    }
                }
            }
        }
        max2.sqrt()
    }
}

/// A scene-relative path resolved against the scene's directory.
pub fn resolve(base_dir: &Path, path: &str) -> PathBuf {
    let p = Path::new(path);
    if p.is_absolute() {
        p.to_path_buf()
    } else {
        base_dir.join(p)
    }
}

impl IndexField for VdbField {
    fn warnings(&self) -> Vec<String> {
        self.warnings.clone()
    }

    fn sample(&self, p: DVec3) -> FieldSample<f64> {
        let idx = self.index_from_world(p);
        let u = [
            idx.x - f64::from(self.bbox.min[0]),
            idx.y - f64::from(self.bbox.min[1]),
            idx.z - f64::from(self.bbox.min[2]),
        ];
        let (dn, g) = self.catmull_rom(u);
        let n = self.ambient + dn;
        // Clamped to what the mapping produced: Catmull-Rom rings at a sharp edge (air
        // colder than ambient beside a hot plume, n past every voxel's); flat where
        // clamped.
        let (lo, hi) = self.n_range;
        if n > hi || n < lo {
            return FieldSample {
                n: n.clamp(lo, hi),
                grad_n: DVec3::ZERO,
            };
        }
        FieldSample {
            n,
            grad_n: self.grad_to_world(g),
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

    /// From the stored bricks the box's stencils reach (2 voxels around it in index
    /// space): their largest |delta_n| times 1.25^3 (Catmull-Rom's weights sum to at most
    /// 1.25 in absolute value a axis), and never past the clamp to the mapped range.
    fn delta_bound(&self, lo: DVec3, hi: DVec3) -> Option<f64> {
        let mut ilo = DVec3::splat(f64::INFINITY);
        let mut ihi = DVec3::splat(f64::NEG_INFINITY);
        for c in 0..8 {
            let corner = DVec3::new(
                if c & 1 == 0 { lo.x } else { hi.x },
                if c & 2 == 0 { lo.y } else { hi.y },
                if c & 4 == 0 { lo.z } else { hi.z },
            );
            let i = self.index_from_world(corner);
            ilo = ilo.min(i);
            ihi = ihi.max(i);
        }
        if !(ilo.is_finite() && ihi.is_finite()) {
            return None;
        }
        let reach = |v: f64, d: f64| (v + d).clamp(-1e15, 1e15) as i64;
        let local = self.voxels.max_abs_in(
            [0, 1, 2].map(|a| reach(ilo[a].floor(), -2.0)),
            [0, 1, 2].map(|a| reach(ihi[a].ceil(), 2.0)),
        );
        let global = (self.n_range.0 - self.ambient)
            .abs()
            .max((self.n_range.1 - self.ambient).abs());
        Some((local * 1.25f64.powi(3)).min(global))
    }

    /// Two voxels.
    fn feature_size(&self) -> Option<f64> {
        self.source_spacing().map(|h| 2.0 * h)
    }

    /// The voxel size: the shortest column of the grid-to-world transform.
    fn source_spacing(&self) -> Option<f64> {
        let m = &self.world_from_grid.matrix3;
        let voxel = [m.x_axis, m.y_axis, m.z_axis]
            .iter()
            .map(|c| c.length())
            .fold(f64::INFINITY, f64::min);
        (voxel > 0.0 && voxel.is_finite()).then_some(voxel)
    }
    /// The grid's voxel centres where its transform is a uniform scale and an offset.
    fn source_lattice(&self) -> Option<(DVec3, f64)> {
        let m = &self.world_from_grid.matrix3;
        let h = m.x_axis.x;
        let diagonal = m.x_axis == DVec3::new(h, 0.0, 0.0)
            && m.y_axis == DVec3::new(0.0, h, 0.0)
            && m.z_axis == DVec3::new(0.0, 0.0, h);
        (diagonal && h > 0.0 && h.is_finite()).then_some((self.world_from_grid.translation, h))
    }
    fn max_grad_n(&self) -> f64 {
        self.max_grad
    }

    fn describe(&self) -> String {
        let mut s = format!(
            "{} ({}x{}x{} voxels, {})",
            self.label,
            self.dims[0],
            self.dims[1],
            self.dims[2],
            self.mapping.describe()
        );
        if self.non_finite_replaced > 0 {
            s.push_str(&format!(
                ", {} NaN/Inf voxels replaced by ambient",
                self.non_finite_replaced
            ));
        }
        s
    }
    fn has_local_step_limits(&self) -> bool {
        false
    }
}
