//! Linear-n^2 slab: n^2 = n0^2 + k u, u the coordinate along `axis` relative to the
//! bounds' centre. In t-form the ray equation has constant acceleration
//! r'' = n grad n = (k/2) axis, so every ray is an exact parabola ([`exact_path`]); any
//! integrator of order >= 2 reproduces it to round-off (a plumbing and units test).

use glam::DVec3;
use grin_scene::Axis;

use super::{
    Num, axis_name, axis_vector, from_n2, half_extent_along, param_error, require_finite,
    require_positive,
};
use crate::bounds::Bounds;
use crate::field::{FieldError, FieldSample, IndexField};

/// n^2 = n0^2 + k (p - c) . axis, grad n = k axis / (2n).
#[derive(Debug, Clone)]
pub struct LinearN2 {
    bounds: Bounds,
    ambient: f64,
    center: DVec3,
    n0: f64,
    k: f64,
    axis: Axis,
    axis_v: DVec3,
    n_min: f64,
    n_max: f64,
}

impl LinearN2 {
    /// Requires n0 > 0 and n^2 > 0 over the whole bounds.
    pub fn new(
        bounds: Bounds,
        ambient: f64,
        n0: f64,
        k: f64,
        axis: Axis,
    ) -> Result<Self, FieldError> {
        require_positive("linear-n2", "n0", n0)?;
        require_finite("linear-n2", "k", k)?;
        let axis_v = axis_vector(axis);
        let h = half_extent_along(&bounds, axis_v);
        let n2_min = n0 * n0 - k.abs() * h;
        if n2_min <= 0.0 {
            return Err(param_error(
                "linear-n2",
                "k",
                format!(
                    "n^2 = n0^2 - |k| h = {n2_min} <= 0 at the bounds' edge (h = {h}); reduce |k| or the bounds"
                ),
            ));
        }
        Ok(LinearN2 {
            bounds,
            ambient,
            center: bounds.center(),
            n0,
            k,
            axis,
            axis_v,
            n_min: n2_min.sqrt(),
            n_max: (n0 * n0 + k.abs() * h).sqrt(),
        })
    }

    /// The centre the coordinate u is measured from.
    pub fn center(&self) -> DVec3 {
        self.center
    }

    /// Exact ray through world point `r0` with T0 = n(r0) * unit direction, after
    /// parameter `t` (see [`exact_path`]).
    pub fn exact_path(&self, r0: DVec3, t0: DVec3, t: f64) -> (DVec3, DVec3) {
        exact_path(r0, t0, self.k, self.axis_v, t)
    }
}

/// Exact ray of a linear-n^2 field in t-form (r'' = (k/2) axis):
/// r(t) = r0 + T0 t + (k/4) axis t^2, T(t) = T0 + (k/2) axis t. Returns (r, T).
/// Frame-independent: r0 may be world or centre-relative.
pub fn exact_path(r0: DVec3, t0: DVec3, k: f64, axis: DVec3, t: f64) -> (DVec3, DVec3) {
    let a = axis * (0.5 * k);
    (r0 + t0 * t + a * (0.5 * t * t), t0 + a * t)
}

impl IndexField for LinearN2 {
    analytic_basics!();
    fn sample(&self, p: DVec3) -> FieldSample<f64> {
        let u = (p - self.center).dot(self.axis_v);
        from_n2(self.n0 * self.n0 + self.k * u, self.axis_v * self.k)
    }
    fn n_range(&self) -> (f64, f64) {
        (self.n_min, self.n_max)
    }
    fn max_grad_n(&self) -> f64 {
        self.k.abs() / (2.0 * self.n_min)
    }
    fn describe(&self) -> String {
        format!(
            "linear-n2 n0={} k={} axis={}",
            Num(self.n0),
            Num(self.k),
            axis_name(self.axis)
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analytic::test_util::*;

    fn slab() -> LinearN2 {
        let b = Bounds::Box {
            min: DVec3::new(-1.0, 0.0, -2.0),
            max: DVec3::new(1.0, 1.0, 2.0),
        };
        LinearN2::new(b, 1.0, 1.3, -0.4, Axis::Y).expect("valid")
    }

    #[test]
    fn gradient_and_ranges() {
        let f = slab();
        assert_gradient_matches(&f, 1e-5, 1e-6);
        assert_range_bounds(&f, 0.05);
        // u is measured from the centre: n = n0 at y = 0.5.
        assert!((f.n(DVec3::new(0.3, 0.5, 1.0)) - 1.3).abs() < 1e-15);
    }

    #[test]
    fn exact_path_satisfies_ray_equation() {
        let f = slab();
        let r0 = DVec3::new(-0.9, 0.2, 0.0);
        let t0 = DVec3::new(1.0, 0.4, 0.1).normalize() * f.n(r0);
        for &t in &[0.1, 0.3, 0.6] {
            let (r, tt) = f.exact_path(r0, t0, t);
            // |T| = n is conserved along the exact ray.
            assert!(
                (tt.length() - f.n(r)).abs() < 1e-12,
                "|T| = {} vs n = {}",
                tt.length(),
                f.n(r)
            );
            // dT/dt = n grad n: compare with a central difference of T.
            let (_, tp) = f.exact_path(r0, t0, t + 1e-4);
            let (_, tm) = f.exact_path(r0, t0, t - 1e-4);
            let d = (tp - tm) / 2e-4;
            assert!((d - f.sample(r).n_grad_n()).length() < 1e-9);
        }
    }

    #[test]
    fn rejects_nonpositive_n2() {
        let b = Bounds::Sphere {
            center: DVec3::ZERO,
            radius: 1.0,
        };
        let e = LinearN2::new(b, 1.0, 1.0, 2.0, Axis::Y).expect_err("n^2 < 0 inside");
        assert!(
            e.to_string().contains("linear-n2: invalid parameter `k`"),
            "{e}"
        );
    }
}
