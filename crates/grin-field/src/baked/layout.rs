//! The brick order a [`super::BakedField`] samples from: nodes grouped in 4x4x4 bricks so
//! that the 8 (trilinear) or 64 (tricubic) taps of a sample, and the samples of a ray
//! marching along any axis, share cache lines and memory pages. Only the sampler uses it;
//! the `.grinf` file and the GPU keep the plain x-fastest order.

/// Nodes per brick edge.
const EDGE: usize = 4;
/// Nodes per brick.
const BRICK: usize = EDGE * EDGE * EDGE;

/// Separable brick index: node (i, j, k) sits at `x(i) + y(j) + z(k)`.
#[derive(Debug, Clone)]
pub(crate) struct Bricks {
    xs: Vec<usize>,
    ys: Vec<usize>,
    zs: Vec<usize>,
    len: usize,
}

impl Bricks {
    pub(crate) fn new(dims: [usize; 3]) -> Self {
        let b = dims.map(|n| n.div_ceil(EDGE));
        // Offset of node n along an axis whose brick stride is `brick` and whose
        // in-brick stride is `inner`.
        let table = |n: usize, brick: usize, inner: usize| -> Vec<usize> {
            (0..n)
                .map(|a| (a / EDGE) * brick + (a % EDGE) * inner)
                .collect()
        };
        Bricks {
            xs: table(dims[0], BRICK, 1),
            ys: table(dims[1], BRICK * b[0], EDGE),
            zs: table(dims[2], BRICK * b[0] * b[1], EDGE * EDGE),
            len: BRICK * b[0] * b[1] * b[2],
        }
    }

    #[inline]
    pub(crate) fn x(&self, i: usize) -> usize {
        self.xs[i]
    }
    #[inline]
    pub(crate) fn y(&self, j: usize) -> usize {
        self.ys[j]
    }
    #[inline]
    pub(crate) fn z(&self, k: usize) -> usize {
        self.zs[k]
    }

    /// `v` (x fastest, `dims`) copied into brick order; padding nodes are `T::default()`
    /// and never read.
    pub(crate) fn reorder<T: Copy + Default>(&self, dims: [usize; 3], v: &[T]) -> Vec<T> {
        let mut out = vec![T::default(); self.len];
        let mut src = v.iter();
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                let row = self.y(j) + self.z(k);
                for (&x, value) in self.xs.iter().zip(src.by_ref().take(dims[0])) {
                    out[row + x] = *value;
                }
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every node gets its own slot, inside the buffer, and the copy is a permutation.
    #[test]
    fn brick_order_is_a_permutation() {
        let dims = [5, 9, 6];
        let b = Bricks::new(dims);
        let v: Vec<u32> = (1..=(5 * 9 * 6) as u32).collect();
        let out = b.reorder(dims, &v);
        assert_eq!(out.len(), 64 * 2 * 3 * 2);
        let mut seen = std::collections::HashSet::new();
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    let at = b.x(i) + b.y(j) + b.z(k);
                    assert!(seen.insert(at), "slot {at} used twice");
                    assert_eq!(out[at], v[i + dims[0] * (j + dims[1] * k)]);
                }
            }
        }
        assert_eq!(out.iter().filter(|&&x| x != 0).count(), v.len());
    }

    /// A trilinear cell's 8 corners inside one brick span one 512-byte block of 8-byte
    /// voxels.
    #[test]
    fn a_cell_inside_a_brick_is_compact() {
        let b = Bricks::new([16, 16, 16]);
        let lo = b.x(1) + b.y(1) + b.z(1);
        let hi = b.x(2) + b.y(2) + b.z(2);
        assert!(hi - lo < BRICK);
        assert_eq!(lo / BRICK, hi / BRICK);
    }
}
