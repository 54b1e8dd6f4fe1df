//! GRIN rod (SELFOC fibre): n^2 = n0^2 (1 - a^2 rho^2), rho the distance from the rod's
//! axis (the line through the bounds' centre along `axis`).
//!
//! In t-form the transverse motion is harmonic with angular frequency n0 a while the
//! axial component beta = T . axis (= n dz/ds) is invariant, so the exact ray is a helix
//! or sinusoid ([`exact_path`]) of z-period 2 pi beta / (n0 a) ([`z_period`]); the
//! paraxial pitch (beta -> n0) is 2 pi / a. The formula is smooth for rho < 1 / a.

use glam::DVec3;
use grin_scene::Axis;

use super::{
    Num, axis_name, axis_vector, from_n2, max_axis_distance, param_error, require_positive,
};
use crate::bounds::Bounds;
use crate::field::{FieldError, FieldSample, IndexField};

/// n^2 = n0^2 (1 - a^2 rho^2), grad n = -n0^2 a^2 rho_vec / n.
#[derive(Debug, Clone)]
pub struct GrinRod {
    bounds: Bounds,
    ambient: f64,
    center: DVec3,
    n0: f64,
    a: f64,
    axis: Axis,
    axis_v: DVec3,
    rho_max: f64,
}

impl GrinRod {
    /// Requires n0 > 0, a > 0 and a rho < 1 over the bounds.
    pub fn new(
        bounds: Bounds,
        ambient: f64,
        n0: f64,
        a: f64,
        axis: Axis,
    ) -> Result<Self, FieldError> {
        require_positive("grin-rod", "n0", n0)?;
        require_positive("grin-rod", "a", a)?;
        let axis_v = axis_vector(axis);
        let rho_max = max_axis_distance(&bounds, axis_v);
        if a * rho_max >= 1.0 {
            return Err(param_error(
                "grin-rod",
                "a",
                format!(
                    "n^2 = n0^2 (1 - a^2 rho^2) <= 0 inside the bounds (a = {a}, bounds reach rho = {rho_max}; need a rho < 1)"
                ),
            ));
        }
        Ok(GrinRod {
            bounds,
            ambient,
            center: bounds.center(),
            n0,
            a,
            axis,
            axis_v,
            rho_max,
        })
    }

    /// A point on the rod's axis (world).
    pub fn center(&self) -> DVec3 {
        self.center
    }

    /// Unit axis direction.
    pub fn axis(&self) -> DVec3 {
        self.axis_v
    }

    /// z-period of a ray with axial invariant `beta` (see [`z_period`]).
    pub fn z_period(&self, beta: f64) -> f64 {
        z_period(self.n0, self.a, beta)
    }

    /// Exact ray from world point `r0` with T0 = n(r0) * unit direction, after `t`.
    pub fn exact_path(&self, r0: DVec3, t0: DVec3, t: f64) -> (DVec3, DVec3) {
        let (r, tt) = exact_path(r0 - self.center, t0, self.n0, self.a, self.axis_v, t);
        (r + self.center, tt)
    }

    fn rho_vec(&self, d: DVec3) -> DVec3 {
        d - self.axis_v * d.dot(self.axis_v)
    }
}

/// Axial distance per transverse oscillation: 2 pi beta / (n0 a), beta = T . axis.
pub fn z_period(n0: f64, a: f64, beta: f64) -> f64 {
    2.0 * std::f64::consts::PI * beta / (n0 * a)
}

/// Exact GRIN-rod ray in t-form, coordinates relative to a point on the axis: with
/// w = n0 a, the transverse part rho(t) = rho0 cos(w t) + (T0_perp / w) sin(w t) and the
/// axial part z(t) = z0 + beta t. Returns (r, T).
pub fn exact_path(r0: DVec3, t0: DVec3, n0: f64, a: f64, axis: DVec3, t: f64) -> (DVec3, DVec3) {
    let w = n0 * a;
    let (s, c) = (w * t).sin_cos();
    let z0 = axis * r0.dot(axis);
    let beta = t0.dot(axis);
    let rho0 = r0 - z0;
    let tp0 = t0 - axis * beta;
    let rho = rho0 * c + tp0 * (s / w);
    let tp = -rho0 * (w * s) + tp0 * c;
    (z0 + axis * (beta * t) + rho, axis * beta + tp)
}

impl IndexField for GrinRod {
    analytic_basics!();
    fn sample(&self, p: DVec3) -> FieldSample<f64> {
        let rho = self.rho_vec(p - self.center);
        let n02 = self.n0 * self.n0;
        let a2 = self.a * self.a;
        from_n2(
            n02 * (1.0 - a2 * rho.length_squared()),
            rho * (-2.0 * n02 * a2),
        )
    }
    fn n_range(&self) -> (f64, f64) {
        let ar = self.a * self.rho_max;
        (self.n0 * (1.0 - ar * ar).sqrt(), self.n0)
    }
    fn max_grad_n(&self) -> f64 {
        // |grad n| = n0^2 a^2 rho / n(rho) grows with rho.
        self.n0 * self.n0 * self.a * self.a * self.rho_max / self.n_range().0
    }
    fn describe(&self) -> String {
        format!(
            "grin-rod n0={} a={} axis={}",
            Num(self.n0),
            Num(self.a),
            axis_name(self.axis)
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analytic::test_util::*;

    fn rod() -> GrinRod {
        let b = Bounds::Box {
            min: DVec3::new(-0.5, -0.5, -3.0),
            max: DVec3::new(0.5, 0.5, 3.0),
        };
        GrinRod::new(b, 1.0, 1.6, 0.8, Axis::Z).expect("valid")
    }

    #[test]
    fn gradient_and_ranges() {
        let f = rod();
        assert_gradient_matches(&f, 1e-6, 1e-6);
        assert_range_bounds(&f, 0.05);
        let b = Bounds::Sphere {
            center: DVec3::new(0.0, 1.0, 0.0),
            radius: 1.0,
        };
        let f = GrinRod::new(b, 1.0, 1.5, 0.5, Axis::X).expect("valid");
        assert_gradient_matches(&f, 1e-6, 1e-6);
        assert_range_bounds(&f, 0.05);
    }

    #[test]
    fn exact_path_is_periodic_with_z_period_and_conserves_invariants() {
        let f = rod();
        let r0 = f.center() + DVec3::new(0.2, -0.1, -2.5);
        let t0 = DVec3::new(0.1, 0.25, 1.0).normalize() * f.n(r0);
        let beta = t0.z;
        let period_t = 2.0 * std::f64::consts::PI / (1.6 * 0.8);
        for i in 1..=20 {
            let t = period_t * i as f64 / 20.0;
            let (r, tt) = f.exact_path(r0, t0, t);
            assert!((tt.length() - f.n(r)).abs() < 1e-12, "|T| != n at t = {t}");
            assert!((tt.z - beta).abs() < 1e-15);
        }
        let (r, tt) = f.exact_path(r0, t0, period_t);
        let dz = f.z_period(beta);
        assert!(
            (r - (r0 + DVec3::Z * dz)).length() < 1e-12,
            "after one period: {r}"
        );
        assert!((tt - t0).length() < 1e-12);
        // Paraxial limit: pitch 2 pi / a.
        assert!((z_period(1.6, 0.8, 1.6) - 2.0 * std::f64::consts::PI / 0.8).abs() < 1e-14);
    }

    #[test]
    fn rejects_rod_too_wide_for_a() {
        let b = Bounds::Sphere {
            center: DVec3::ZERO,
            radius: 1.0,
        };
        let e = GrinRod::new(b, 1.0, 1.5, 1.2, Axis::Z).expect_err("a rho > 1");
        assert!(e.to_string().contains("need a rho < 1"), "{e}");
    }
}
