//! A grid's affine index-to-world [`Transform`].

/// An affine index-to-world transform: world = A * ijk + t.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Transform {
    /// Row-major 3x4 `[A | t]`.
    pub world_from_index: [[f64; 4]; 3],
}

impl Transform {
    /// Uniform voxel size `h` with index (0,0,0) at world `origin`.
    pub fn uniform(h: f64, origin: [f64; 3]) -> Self {
        Transform {
            world_from_index: [
                [h, 0.0, 0.0, origin[0]],
                [0.0, h, 0.0, origin[1]],
                [0.0, 0.0, h, origin[2]],
            ],
        }
    }

    pub(crate) fn from_flat(m: &[f64; 12]) -> Self {
        Transform {
            world_from_index: std::array::from_fn(|r| std::array::from_fn(|c| m[r * 4 + c])),
        }
    }

    pub(crate) fn to_flat(self) -> [f64; 12] {
        std::array::from_fn(|i| self.world_from_index[i / 4][i % 4])
    }

    /// World position of (fractional) index coordinates.
    pub fn index_to_world(&self, ijk: [f64; 3]) -> [f64; 3] {
        let m = &self.world_from_index;
        std::array::from_fn(|r| m[r][0] * ijk[0] + m[r][1] * ijk[1] + m[r][2] * ijk[2] + m[r][3])
    }

    /// The inverse transform (index from world), `None` if A is singular.
    pub fn inverse(&self) -> Option<Transform> {
        let m = &self.world_from_index;
        let a = |r: usize, c: usize| m[r][c];
        let det = a(0, 0) * (a(1, 1) * a(2, 2) - a(1, 2) * a(2, 1))
            - a(0, 1) * (a(1, 0) * a(2, 2) - a(1, 2) * a(2, 0))
            + a(0, 2) * (a(1, 0) * a(2, 1) - a(1, 1) * a(2, 0));
        if !det.is_finite() || det.abs() < f64::MIN_POSITIVE {
            return None;
        }
        let inv_det = 1.0 / det;
        let cof = |r: usize, c: usize| {
            // Inverse entry (r, c) = cofactor(c, r) / det.
            let (r0, r1) = ((c + 1) % 3, (c + 2) % 3);
            let (c0, c1) = ((r + 1) % 3, (r + 2) % 3);
            (a(r0, c0) * a(r1, c1) - a(r0, c1) * a(r1, c0)) * inv_det
        };
        let inv: [[f64; 3]; 3] = std::array::from_fn(|r| std::array::from_fn(|c| cof(r, c)));
        let t = [m[0][3], m[1][3], m[2][3]];
        let mut out = [[0.0; 4]; 3];
        for r in 0..3 {
            out[r][..3].copy_from_slice(&inv[r]);
            out[r][3] = -(inv[r][0] * t[0] + inv[r][1] * t[1] + inv[r][2] * t[2]);
        }
        Some(Transform {
            world_from_index: out,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn transform_inverse_roundtrips() {
        let t = Transform {
            world_from_index: [
                [0.05, 0.01, 0.0, -1.2],
                [0.0, 0.04, 0.02, 0.3],
                [0.01, 0.0, 0.06, 2.5],
            ],
        };
        let inv = t.inverse().expect("invertible");
        let p = [3.0, -7.5, 11.25];
        let w = t.index_to_world(p);
        let back = inv.index_to_world(w);
        for a in 0..3 {
            assert!((back[a] - p[a]).abs() < 1e-12, "{back:?} vs {p:?}");
        }
    }
}
