//! The brick store ([`Bricks`]): a grid's voxels in bricks of [`BRICK`]^3, only the
//! bricks that hold a non-zero value kept.

use vdb_sys::IndexBox;

use super::locate::DataBox;
use crate::field::FieldError;

/// Reads the values of an index box (x fastest) into the vector: a grid's brick.
pub(super) type ReadBrick<'a, E = FieldError> =
    dyn FnMut(IndexBox, &mut Vec<f32>) -> Result<(), E> + 'a;
/// Edge of a brick of the loaded voxels ([`Bricks`]), in voxels.
pub(super) const BRICK: usize = 32;
/// Voxels in a brick.
const BRICK_VOXELS: usize = BRICK * BRICK * BRICK;

/// Voxel values (delta_n) over an index box in bricks of [`BRICK`]^3 (x fastest within a
/// brick), only the bricks with a non-zero value stored: a cache's data box is mostly
/// background (smoke in one corner of it, a shell), and a dense copy of the box was most
/// of the memory a load used.
#[derive(Debug, Clone)]
pub(super) struct Bricks {
    /// Index of the store's first voxel.
    origin: [i32; 3],
    /// Voxels along each axis.
    dims: [usize; 3],
    /// Bricks along each axis.
    counts: [usize; 3],
    bricks: Vec<Option<Box<[f64]>>>,
    /// max |value| of each stored brick (0 where none is stored).
    maxes: Vec<f64>,
}

impl Bricks {
    /// An empty store (every value 0) over `bbox`.
    fn new(bbox: IndexBox) -> Self {
        let dims = bbox
            .dims()
            .map(|d| usize::try_from(d).unwrap_or(usize::MAX));
        let counts = dims.map(|d| d.div_ceil(BRICK));
        Bricks {
            origin: bbox.min,
            dims,
            counts,
            bricks: vec![None; counts.iter().product()],
            maxes: vec![0.0; counts.iter().product()],
        }
    }

    /// The store over `bbox`, read a brick at a time by `read` (the brick's box -> its
    /// values, x fastest). A brick all at `background` is skipped (most bricks of a sparse
    /// cache); the others keep `voxel(index, value)` of each voxel and are stored where one
    /// of those is not 0. An error of `read` or `voxel`, or `over_cap()` once the store
    /// holds more than `max_bytes`, ends the read.
    pub(super) fn read<E>(
        bbox: IndexBox,
        background: f64,
        max_bytes: u64,
        read: &mut ReadBrick<'_, E>,
        mut voxel: impl FnMut([i32; 3], f32) -> Result<f64, E>,
        over_cap: impl Fn() -> E,
    ) -> Result<Self, E> {
        let mut store = Bricks::new(bbox);
        let mut values = Vec::new();
        for b in store.brick_indices() {
            let part = store.brick_box(b);
            read(part, &mut values)?;
            if values.iter().all(|&v| f64::from(v) == background) {
                continue;
            }
            let mut brick = vec![0.0f64; BRICK_VOXELS].into_boxed_slice();
            let mut it = values.iter();
            for k in part.min[2]..=part.max[2] {
                for j in part.min[1]..=part.max[1] {
                    for i in part.min[0]..=part.max[0] {
                        let Some(&v) = it.next() else { break };
                        brick[store.local_offset([i, j, k])] = voxel([i, j, k], v)?;
                    }
                }
            }
            store.put(b, brick);
            if store.stored_bytes() > max_bytes {
                return Err(over_cap());
            }
        }
        Ok(store)
    }

    /// Every brick's position in the brick grid, x fastest.
    fn brick_indices(&self) -> impl Iterator<Item = [usize; 3]> + use<> {
        let c = self.counts;
        (0..c[2]).flat_map(move |k| (0..c[1]).flat_map(move |j| (0..c[0]).map(move |i| [i, j, k])))
    }

    /// The index box of brick `b`, clipped to the store.
    fn brick_box(&self, b: [usize; 3]) -> IndexBox {
        IndexBox {
            min: std::array::from_fn(|a| self.origin[a] + (b[a] * BRICK) as i32),
            max: std::array::from_fn(|a| {
                self.origin[a] + ((b[a] * BRICK + BRICK).min(self.dims[a]) - 1) as i32
            }),
        }
    }

    fn slot(&self, b: [usize; 3]) -> usize {
        b[0] + self.counts[0] * (b[1] + self.counts[1] * b[2])
    }

    /// Offset of index `ijk` (inside the store) within its brick.
    fn local_offset(&self, ijk: [i32; 3]) -> usize {
        let l: [usize; 3] = std::array::from_fn(|a| (ijk[a] - self.origin[a]) as usize % BRICK);
        l[0] + BRICK * (l[1] + BRICK * l[2])
    }

    /// Keep brick `b`'s values unless every one is 0.
    fn put(&mut self, b: [usize; 3], values: Box<[f64]>) {
        if values.iter().any(|&v| v != 0.0) {
            let slot = self.slot(b);
            self.maxes[slot] = values.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            self.bricks[slot] = Some(values);
        }
    }

    /// An upper bound on |value| over the index box [`lo`, `hi`]: the largest max of the
    /// stored bricks it meets (0 where it meets none).
    pub(super) fn max_abs_in(&self, lo: [i64; 3], hi: [i64; 3]) -> f64 {
        let mut range = [(0usize, 0usize); 3];
        for a in 0..3 {
            let l = lo[a] - i64::from(self.origin[a]);
            let h = hi[a] - i64::from(self.origin[a]);
            if h < 0 || l >= self.dims[a] as i64 || l > h {
                return 0.0;
            }
            range[a] = (
                l.max(0) as usize / BRICK,
                (h.min(self.dims[a] as i64 - 1) as usize) / BRICK,
            );
        }
        let mut m = 0.0f64;
        for k in range[2].0..=range[2].1 {
            for j in range[1].0..=range[1].1 {
                for i in range[0].0..=range[0].1 {
                    m = m.max(self.maxes[self.slot([i, j, k])]);
                }
            }
        }
        m
    }

    /// The value at index `ijk`: 0 outside the store or in a brick not stored.
    pub(super) fn get(&self, ijk: [i64; 3]) -> f64 {
        let mut l = [0usize; 3];
        for a in 0..3 {
            let r = ijk[a] - i64::from(self.origin[a]);
            if r < 0 || r >= self.dims[a] as i64 {
                return 0.0;
            }
            l[a] = r as usize;
        }
        match &self.bricks[self.slot(l.map(|v| v / BRICK))] {
            Some(v) => v[l[0] % BRICK + BRICK * (l[1] % BRICK + BRICK * (l[2] % BRICK))],
            None => 0.0,
        }
    }

    /// The 4x4x4 values from index `min` on (x fastest): straight from one brick when the
    /// block lies in it (most samples), else value by value.
    pub(super) fn stencil(&self, min: [i64; 3]) -> [f64; 64] {
        let mut out = [0.0; 64];
        let r: [i64; 3] = std::array::from_fn(|a| min[a] - i64::from(self.origin[a]));
        let one_brick = (0..3).all(|a| {
            r[a] >= 0
                && r[a] + 3 < self.dims[a] as i64
                && r[a] as usize / BRICK == (r[a] as usize + 3) / BRICK
        });
        if one_brick {
            let r = r.map(|v| v as usize);
            if let Some(v) = &self.bricks[self.slot(r.map(|x| x / BRICK))] {
                let l = r.map(|x| x % BRICK);
                for c in 0..4 {
                    for j in 0..4 {
                        let at = l[0] + BRICK * (l[1] + j + BRICK * (l[2] + c));
                        out[4 * (j + 4 * c)..4 * (j + 4 * c) + 4].copy_from_slice(&v[at..at + 4]);
                    }
                }
            }
            return out;
        }
        // Across bricks: each axis's 4 taps as (brick, offset in it), or outside.
        let axis = |a: usize| -> [Option<(usize, usize)>; 4] {
            std::array::from_fn(|t| {
                let v = r[a] + t as i64;
                (v >= 0 && v < self.dims[a] as i64)
                    .then_some((v as usize / BRICK, v as usize % BRICK))
            })
        };
        let (ax, ay, az) = (axis(0), axis(1), axis(2));
        for (c, z) in az.iter().enumerate() {
            let Some((bz, lz)) = *z else { continue };
            for (j, y) in ay.iter().enumerate() {
                let Some((by, ly)) = *y else { continue };
                for (i, x) in ax.iter().enumerate() {
                    let Some((bx, lx)) = *x else { continue };
                    if let Some(v) = &self.bricks[self.slot([bx, by, bz])] {
                        out[i + 4 * (j + 4 * c)] = v[lx + BRICK * (ly + BRICK * lz)];
                    }
                }
            }
        }
        out
    }

    /// Bytes held: the stored bricks and the brick table.
    pub(super) fn stored_bytes(&self) -> u64 {
        let stored = self.bricks.iter().filter(|b| b.is_some()).count() as u64;
        stored * (BRICK_VOXELS * 8) as u64 + self.bricks.len() as u64 * 16
    }

    /// The index boxes of the stored bricks.
    pub(super) fn stored_boxes(&self) -> Vec<IndexBox> {
        self.brick_indices()
            .filter(|&b| self.bricks[self.slot(b)].is_some())
            .map(|b| self.brick_box(b))
            .collect()
    }

    /// `f(index, value)` for every voxel of the stored bricks.
    fn each_stored(&self, mut f: impl FnMut([i64; 3], f64)) {
        for part in self.stored_boxes() {
            for k in part.min[2]..=part.max[2] {
                for j in part.min[1]..=part.max[1] {
                    for i in part.min[0]..=part.max[0] {
                        let ijk = [i64::from(i), i64::from(j), i64::from(k)];
                        f(ijk, self.get(ijk));
                    }
                }
            }
        }
    }

    /// The box of the voxels whose |value| is above `fraction` of the largest (0: every
    /// voxel that is not 0); `None` when every value is 0.
    pub(super) fn data_box(&self, fraction: f64) -> Option<DataBox> {
        let mut peak = 0.0f64;
        self.each_stored(|_, d| {
            if d.is_finite() {
                peak = peak.max(d.abs());
            }
        });
        if peak == 0.0 {
            return None;
        }
        let (mut lo, mut hi) = ([i64::MAX; 3], [i64::MIN; 3]);
        self.each_stored(|ijk, d| {
            if d.abs() > fraction * peak {
                for a in 0..3 {
                    lo[a] = lo[a].min(ijk[a]);
                    hi[a] = hi[a].max(ijk[a]);
                }
            }
        });
        (lo[0] != i64::MAX).then_some(DataBox { min: lo, max: hi })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The brick store returns what was put, 0 in bricks not stored (all-zero ones are
    /// dropped), and its 4x4x4 stencil equals value-by-value reads on and across brick
    /// edges and the store's own edges.
    #[test]
    fn bricks_hold_what_was_put_and_stencils_match_reads() {
        let e = BRICK as i32;
        let bbox = IndexBox {
            min: [-5, 3, 0],
            max: [e + 2, e + 8, e + 4],
        };
        let mut store = Bricks::new(bbox);
        let f = |ijk: [i32; 3]| {
            // Zero in the second layer of bricks along z (not stored).
            if ijk[2] >= e {
                0.0
            } else {
                f64::from(ijk[0]) + 100.0 * f64::from(ijk[1]) + 1e4 * f64::from(ijk[2]) + 0.5
            }
        };
        for b in store.brick_indices().collect::<Vec<_>>() {
            let part = store.brick_box(b);
            let mut values = vec![0.0; BRICK_VOXELS].into_boxed_slice();
            for k in part.min[2]..=part.max[2] {
                for j in part.min[1]..=part.max[1] {
                    for i in part.min[0]..=part.max[0] {
                        values[store.local_offset([i, j, k])] = f([i, j, k]);
                    }
                }
            }
            store.put(b, values);
        }
        let stored = store.stored_boxes().len();
        assert_eq!(
            stored,
            2 * 2,
            "the second layer along z is all zero: not stored"
        );
        for k in -1..=e + 6 {
            for j in 2..=e + 10 {
                for i in -6..=e + 4 {
                    let inside = (-5..=e + 2).contains(&i)
                        && (3..=e + 8).contains(&j)
                        && (0..=e + 4).contains(&k);
                    let want = if inside { f([i, j, k]) } else { 0.0 };
                    let ijk = [i64::from(i), i64::from(j), i64::from(k)];
                    assert_eq!(store.get(ijk), want, "{ijk:?}");
                    let taps = store.stencil(ijk);
                    for c in 0..4 {
                        for b in 0..4 {
                            for a in 0..4 {
                                let at = [ijk[0] + a, ijk[1] + b, ijk[2] + c];
                                assert_eq!(taps[(a + 4 * (b + 4 * c)) as usize], store.get(at));
                            }
                        }
                    }
                }
            }
        }
    }
}
