//! Eaton lens: n^2 = 2R/r - 1 (r the distance from the bounds' centre, R the lens radius,
//! default the bounds' radius): every ray entering the lens turns through 180 degrees and
//! leaves anti-parallel to how it came (a retro-reflector).
//!
//! n -> infinity at the centre, so the core r < r_c = core * R is replaced by the
//! parabolic cap n^2 = A - B r^2 with B = R / r_c^3 and A = 3R / r_c - 1, which matches
//! n^2 and d(n^2)/dr at r_c: n and grad n stay finite and continuous (C1 in n^2), the
//! largest index is sqrt(A) at the centre and the largest |grad n| is at r = r_c. Rays
//! through the cap (impact parameter below about r_c) are no longer exactly
//! retro-reflected. The formula is positive up to r < 2R.

use glam::DVec3;

use super::{Num, from_n2, max_radius, param_error, require_positive};
use crate::bounds::Bounds;
use crate::field::{FieldError, FieldSample, IndexField};

/// Eaton lens with a smooth parabolic core cap (see the module doc).
#[derive(Debug, Clone)]
pub struct Eaton {
    bounds: Bounds,
    ambient: f64,
    center: DVec3,
    radius: f64,
    core: f64,
    r_core: f64,
    cap_a: f64,
    cap_b: f64,
    r_max: f64,
}

impl Eaton {
    /// `radius` defaults to the bounds' radius; `core` (fraction of R) must be in (0, 1).
    pub fn new(
        bounds: Bounds,
        ambient: f64,
        radius: Option<f64>,
        core: f64,
    ) -> Result<Self, FieldError> {
        let radius =
            require_positive("eaton", "radius", radius.unwrap_or_else(|| bounds.radius()))?;
        if !(core > 0.0 && core < 1.0) {
            return Err(param_error(
                "eaton",
                "core",
                format!("must be in (0, 1), got {core}"),
            ));
        }
        let r_max = max_radius(&bounds);
        if r_max >= 2.0 * radius {
            return Err(param_error(
                "eaton",
                "radius",
                format!(
                    "n^2 = 2R/r - 1 <= 0 inside the bounds (R = {radius}, bounds reach r = {r_max}; need r < 2R)"
                ),
            ));
        }
        let r_core = core * radius;
        Ok(Eaton {
            bounds,
            ambient,
            center: bounds.center(),
            radius,
            core,
            r_core,
            cap_a: 3.0 * radius / r_core - 1.0,
            cap_b: radius / (r_core * r_core * r_core),
            r_max,
        })
    }

    /// The lens centre (world).
    pub fn center(&self) -> DVec3 {
        self.center
    }

    /// The lens radius R.
    pub fn radius(&self) -> f64 {
        self.radius
    }

    /// The core radius r_c = core * R inside which the cap replaces the formula.
    pub fn core_radius(&self) -> f64 {
        self.r_core
    }

    /// n^2 and d(n^2)/dr at distance r from the centre.
    fn n2_and_slope(&self, r: f64) -> (f64, f64) {
        if r < self.r_core {
            (self.cap_a - self.cap_b * r * r, -2.0 * self.cap_b * r)
        } else {
            (2.0 * self.radius / r - 1.0, -2.0 * self.radius / (r * r))
        }
    }

    /// |grad n| = |d(n^2)/dr| / (2n) at distance r.
    fn grad_at(&self, r: f64) -> f64 {
        let (n2, slope) = self.n2_and_slope(r);
        slope.abs() / (2.0 * n2.sqrt())
    }
}

impl IndexField for Eaton {
    analytic_basics!();
    fn sample(&self, p: DVec3) -> FieldSample<f64> {
        let d = p - self.center;
        let r = d.length();
        if r < self.r_core {
            from_n2(self.cap_a - self.cap_b * r * r, d * (-2.0 * self.cap_b))
        } else {
            from_n2(
                2.0 * self.radius / r - 1.0,
                d * (-2.0 * self.radius / (r * r * r)),
            )
        }
    }
    fn n_range(&self) -> (f64, f64) {
        // n decreases monotonically with r.
        (self.n2_and_slope(self.r_max).0.sqrt(), self.cap_a.sqrt())
    }
    fn max_grad_n(&self) -> f64 {
        // |grad n| rises through the cap, falls from r_c to 1.5 R, then rises again.
        self.grad_at(self.r_core.min(self.r_max))
            .max(self.grad_at(self.r_max))
    }
    fn describe(&self) -> String {
        format!("eaton R={} core={}", Num(self.radius), Num(self.core))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analytic::test_util::*;

    #[test]
    fn gradient_and_ranges() {
        let b = Bounds::Sphere {
            center: DVec3::new(0.0, 1.0, 0.0),
            radius: 1.0,
        };
        // A fat core so the lattice samples it; the thin default core is tested below.
        let f = Eaton::new(b, 1.0, None, 0.3).expect("valid");
        assert_gradient_matches(&f, 1e-7, 1e-6);
        assert_range_bounds(&f, 0.1);
        let f = Eaton::new(b, 1.0, None, 0.02).expect("valid");
        assert_gradient_matches(&f, 1e-7, 1e-6);
    }

    #[test]
    fn core_cap_is_c1_and_finite() {
        let b = Bounds::Sphere {
            center: DVec3::ZERO,
            radius: 2.0,
        };
        let f = Eaton::new(b, 1.0, None, 0.02).expect("valid");
        let rc = f.core_radius();
        let dir = DVec3::new(1.0, 2.0, -2.0) / 3.0;
        let inside = f.sample(dir * (rc * (1.0 - 1e-12)));
        let outside = f.sample(dir * (rc * (1.0 + 1e-12)));
        assert!((inside.n - outside.n).abs() < 1e-9 * inside.n);
        assert!((inside.grad_n - outside.grad_n).length() < 1e-8 * inside.grad_n.length());
        let c = f.sample(DVec3::ZERO);
        assert!(c.n.is_finite() && c.grad_n == DVec3::ZERO);
        assert!((c.n - f.n_range().1).abs() < 1e-15);
        // Outside the core it is the Eaton formula; n = 1 on the surface r = R.
        assert!((f.n(dir * 2.0) - 1.0).abs() < 1e-14);
        assert!((f.n(dir * 0.5) - (2.0 * 2.0 / 0.5 - 1.0f64).sqrt()).abs() < 1e-14);
        // The largest gradient is at the core boundary.
        assert!((f.max_grad_n() - outside.grad_n.length()).abs() < 1e-6 * f.max_grad_n());
        // Beyond r = 2R the formula would be negative: clamped, finite.
        let far = f.sample(dir * 5.0);
        assert!(far.n > 0.0 && far.grad_n.is_finite());
    }
}
