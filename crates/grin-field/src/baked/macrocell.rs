//! The macro-cell grid of a baked field: max |grad n| per block of voxels, so a tracer can
//! fly straight through blocks where the field is homogeneous (the paper's "infinite step").

use glam::DVec3;
use rayon::prelude::*;

/// Voxels per macro cell along each axis.
pub const MACRO_CELL_VOXELS: usize = 8;

/// A cell is homogeneous when its max |grad n| is at most this fraction of the field's
/// max |grad n|: a ray flying straight for length L through it then deviates by at most
/// 1e-6 * max|grad n| * L^2 / 2, below the 1e-6 exit-ray tolerance for unit-size scenes.
pub const HOMOGENEOUS_GRAD_FRACTION: f64 = 1e-6;

/// Coarse grid of max |grad n| over blocks of `cell` voxels.
///
/// Cell (ci, cj, ck) covers grid coordinates [ci*cell, (ci+1)*cell] (and likewise in y, z);
/// its value bounds |grad n| of every interpolated sample in that range (it includes the
/// taps that interpolation reads). Layout: x fastest, `index = ci + cx * (cj + cy * ck)`.
#[derive(Debug, Clone)]
pub struct MacroGrid {
    pub cell: usize,
    pub dims: [usize; 3],
    pub max_grad: Vec<f32>,
    /// Cells with `max_grad <= threshold` are homogeneous.
    pub threshold: f64,
}

impl MacroGrid {
    /// One cell, never homogeneous: what a field holds until `BakedField::prepare` builds
    /// its grid.
    pub(crate) fn unbuilt() -> Self {
        MacroGrid {
            cell: 1,
            dims: [1; 3],
            max_grad: vec![0.0],
            threshold: 0.0,
        }
    }

    /// Build from per-node |grad| bounds `node_grad(i, j, k)` of a grid with `node_dims`;
    /// `reach` is how many nodes beyond a cell the interpolation reads (1 trilinear, 2 tricubic).
    pub fn build(
        node_dims: [usize; 3],
        reach: usize,
        field_max_grad: f64,
        node_grad: impl Fn(usize, usize, usize) -> f32 + Sync,
    ) -> Self {
        let cell = MACRO_CELL_VOXELS;
        let dims = node_dims.map(|n| (n.saturating_sub(1)).div_ceil(cell).max(1));
        let range = |c: usize, n: usize| {
            let lo = (c * cell).saturating_sub(reach);
            let hi = ((c + 1) * cell + reach).min(n - 1);
            lo..=hi
        };
        // One z layer of cells per task (cells overlap by `reach` nodes: each reads its own).
        let max_grad: Vec<f32> = (0..dims[2])
            .into_par_iter()
            .flat_map_iter(|ck| {
                let node_grad = &node_grad;
                (0..dims[1]).flat_map(move |cj| {
                    (0..dims[0]).map(move |ci| {
                        let mut m = 0.0f32;
                        for k in range(ck, node_dims[2]) {
                            for j in range(cj, node_dims[1]) {
                                for i in range(ci, node_dims[0]) {
                                    m = m.max(node_grad(i, j, k));
                                }
                            }
                        }
                        m
                    })
                })
            })
            .collect();
        MacroGrid {
            cell,
            dims,
            max_grad,
            threshold: HOMOGENEOUS_GRAD_FRACTION * field_max_grad,
        }
    }

    pub(crate) fn homogeneous(&self, c: [usize; 3]) -> bool {
        f64::from(self.max_grad[c[0] + self.dims[0] * (c[1] + self.dims[1] * c[2])])
            <= self.threshold
    }

    /// Fraction of cells that are homogeneous.
    pub fn homogeneous_fraction(&self) -> f64 {
        let h = self
            .max_grad
            .iter()
            .filter(|&&m| f64::from(m) <= self.threshold)
            .count();
        h as f64 / self.max_grad.len() as f64
    }

    /// From grid point `g` along grid-space direction `dg` (grid units per world unit of a
    /// unit world direction): the world length to the end of the run of homogeneous cells
    /// starting at g's cell, or `None` if that cell varies. Stops at the grid's edge.
    pub fn span(&self, g: DVec3, dg: DVec3, node_dims: [usize; 3]) -> Option<f64> {
        let cell = self.cell as f64;
        let gmax = DVec3::new(
            (node_dims[0] - 1) as f64,
            (node_dims[1] - 1) as f64,
            (node_dims[2] - 1) as f64,
        );
        let gc = g.clamp(DVec3::ZERO, gmax) * cell.recip();
        let mut c = [0usize; 3];
        for a in 0..3 {
            // gc >= 0: truncation is floor (no libm call).
            c[a] = (gc[a] as usize).min(self.dims[a] - 1);
        }
        if !self.homogeneous(c) {
            return None;
        }
        // Amanatides-Woo walk over cells, in world length s along the ray.
        let mut s_next = [f64::INFINITY; 3];
        let mut s_delta = [f64::INFINITY; 3];
        let mut step = [0isize; 3];
        for a in 0..3 {
            if dg[a] > 0.0 {
                step[a] = 1;
                s_next[a] = ((c[a] + 1) as f64 * cell).min(gmax[a]).max(g[a]) - g[a];
                s_next[a] /= dg[a];
                s_delta[a] = cell / dg[a];
            } else if dg[a] < 0.0 {
                step[a] = -1;
                s_next[a] = (g[a] - c[a] as f64 * cell).max(0.0) / -dg[a];
                s_delta[a] = cell / -dg[a];
            }
        }
        let max_cells = self.dims[0] + self.dims[1] + self.dims[2];
        for _ in 0..max_cells {
            let a = if s_next[0] <= s_next[1] && s_next[0] <= s_next[2] {
                0
            } else if s_next[1] <= s_next[2] {
                1
            } else {
                2
            };
            let s = s_next[a];
            if !s.is_finite() {
                return None;
            }
            let next = c[a] as isize + step[a];
            if next < 0 {
                return Some(s);
            }
            if next >= self.dims[a] as isize {
                // The last cell may be partial: stop at the grid's last node.
                return Some(s.min((gmax[a] - g[a]).max(0.0) / dg[a]));
            }
            c[a] = next as usize;
            if !self.homogeneous(c) {
                return Some(s);
            }
            s_next[a] += s_delta[a];
        }
        None
    }
}
