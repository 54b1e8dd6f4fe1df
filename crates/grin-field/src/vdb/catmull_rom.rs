//! Tricubic Catmull-Rom interpolation of the mapped voxels: the tap weights, their
//! derivatives, and delta_n with its index-space gradient at a point.

use std::ops::{Add, Mul, Neg, Sub};

use super::VdbField;

impl VdbField {
    /// delta_n and its index-space gradient at fractional index coordinates `u`
    /// (relative to the dense box's minimum corner).
    pub(super) fn catmull_rom(&self, u: [f64; 3]) -> (f64, [f64; 3]) {
        let base: [f64; 3] = u.map(f64::floor);
        let t = [u[0] - base[0], u[1] - base[1], u[2] - base[2]];
        let w = t.map(catmull_rom_weights);
        let dw = t.map(catmull_rom_weight_derivatives::<f64>);
        // Far outside the box (also NaN/huge coordinates): background, flat.
        let far = base
            .iter()
            .zip(self.dims.iter())
            .any(|(&b, &d)| !(b >= -3.0 && b <= d as f64 + 2.0));
        if far {
            return (0.0, [0.0; 3]);
        }
        let m = self.bbox.min.map(i64::from);
        let taps = self
            .voxels
            .stencil(std::array::from_fn(|a| base[a] as i64 - 1 + m[a]));
        let (mut v, mut gx, mut gy, mut gz) = (0.0, 0.0, 0.0, 0.0);
        for c in 0..4 {
            for bj in 0..4 {
                let mut row_v = 0.0;
                let mut row_dx = 0.0;
                for a in 0..4 {
                    let f = taps[a + 4 * (bj + 4 * c)];
                    row_v += w[0][a] * f;
                    row_dx += dw[0][a] * f;
                }
                let wyz = w[1][bj] * w[2][c];
                v += wyz * row_v;
                gx += wyz * row_dx;
                gy += dw[1][bj] * w[2][c] * row_v;
                gz += w[1][bj] * dw[2][c] * row_v;
            }
        }
        (v, [gx, gy, gz])
    }
}

/// Catmull-Rom weights of the taps at offsets -1, 0, 1, 2 for fraction `t`, in the
/// precision of `t` (f64 here; f32 for a sparse bake, as on the GPU, whose shader's
/// `catmull_rom_weights` is the same arithmetic).
pub(crate) fn catmull_rom_weights<T>(t: T) -> [T; 4]
where
    T: Copy + From<f32> + Add<Output = T> + Sub<Output = T> + Mul<Output = T> + Neg<Output = T>,
{
    let c = |v: f32| T::from(v);
    let t2 = t * t;
    let t3 = t2 * t;
    [
        c(0.5) * (-t3 + c(2.0) * t2 - t),
        c(0.5) * (c(3.0) * t3 - c(5.0) * t2 + c(2.0)),
        c(0.5) * (-(c(3.0) * t3) + c(4.0) * t2 + t),
        c(0.5) * (t3 - t2),
    ]
}

/// d/dt of [`catmull_rom_weights`], in the precision of `t` (the shader's
/// `catmull_rom_derivatives` is the same arithmetic).
pub(crate) fn catmull_rom_weight_derivatives<T>(t: T) -> [T; 4]
where
    T: Copy + From<f32> + Add<Output = T> + Sub<Output = T> + Mul<Output = T> + Neg<Output = T>,
{
    let c = |v: f32| T::from(v);
    let t2 = t * t;
    [
        c(0.5) * (-(c(3.0) * t2) + c(4.0) * t - c(1.0)),
        c(0.5) * (c(9.0) * t2 - c(10.0) * t),
        c(0.5) * (-(c(9.0) * t2) + c(8.0) * t + c(1.0)),
        c(0.5) * (c(3.0) * t2 - c(2.0) * t),
    ]
}
