//! Luneburg lens: n^2 = 2 - (r/R)^2, r the distance from the bounds' centre and R the
//! lens radius (default: the bounds' radius, so n = 1 on a spherical surface).
//!
//! In t-form r'' = n grad n = -r / R^2: a harmonic oscillator, so every ray is an
//! ellipse about the centre ([`exact_path`]); a parallel beam entering the lens focuses
//! on the antipodal surface point at t = pi R / 2. The formula is its own smooth
//! extension up to r < sqrt(2) R.

use glam::DVec3;

use super::{Num, from_n2, max_radius, param_error, require_positive};
use crate::bounds::Bounds;
use crate::field::{FieldError, FieldSample, IndexField};

/// n^2 = 2 - |p - c|^2 / R^2, grad n = -(p - c) / (R^2 n).
#[derive(Debug, Clone)]
pub struct Luneburg {
    bounds: Bounds,
    ambient: f64,
    center: DVec3,
    radius: f64,
    r_max: f64,
}

impl Luneburg {
    /// `radius` defaults to the bounds' radius. The bounds must lie inside r < sqrt(2) R.
    pub fn new(bounds: Bounds, ambient: f64, radius: Option<f64>) -> Result<Self, FieldError> {
        let radius = require_positive(
            "luneburg",
            "radius",
            radius.unwrap_or_else(|| bounds.radius()),
        )?;
        let r_max = max_radius(&bounds);
        if 2.0 - (r_max / radius).powi(2) <= 0.0 {
            return Err(param_error(
                "luneburg",
                "radius",
                format!(
                    "n^2 = 2 - (r/R)^2 <= 0 inside the bounds (R = {radius}, bounds reach r = {r_max})"
                ),
            ));
        }
        Ok(Luneburg {
            bounds,
            ambient,
            center: bounds.center(),
            radius,
            r_max,
        })
    }

    /// The lens radius R.
    pub fn radius(&self) -> f64 {
        self.radius
    }

    /// The lens centre (world).
    pub fn center(&self) -> DVec3 {
        self.center
    }

    /// Exact ray from world point `r0` with T0 = n(r0) * unit direction after parameter
    /// `t`, in world coordinates. Returns (r, T).
    pub fn exact_path(&self, r0: DVec3, t0: DVec3, t: f64) -> (DVec3, DVec3) {
        let (r, tt) = exact_path(r0 - self.center, t0, self.radius, t);
        (r + self.center, tt)
    }
}

/// Exact Luneburg ray in t-form, coordinates relative to the lens centre:
/// r(t) = r0 cos(t/R) + R T0 sin(t/R), T(t) = -(r0/R) sin(t/R) + T0 cos(t/R).
/// Returns (r, T).
pub fn exact_path(r0: DVec3, t0: DVec3, radius: f64, t: f64) -> (DVec3, DVec3) {
    let (s, c) = (t / radius).sin_cos();
    (r0 * c + t0 * (radius * s), -r0 * (s / radius) + t0 * c)
}

impl IndexField for Luneburg {
    analytic_basics!();
    fn sample(&self, p: DVec3) -> FieldSample<f64> {
        let d = p - self.center;
        let inv_r2 = 1.0 / (self.radius * self.radius);
        from_n2(2.0 - d.length_squared() * inv_r2, d * (-2.0 * inv_r2))
    }
    fn n_range(&self) -> (f64, f64) {
        let n_min = (2.0 - (self.r_max / self.radius).powi(2)).sqrt();
        (n_min, std::f64::consts::SQRT_2)
    }
    fn max_grad_n(&self) -> f64 {
        // |grad n| = r / (R^2 n(r)) grows with r: largest at the farthest point.
        let n_min = self.n_range().0;
        self.r_max / (self.radius * self.radius * n_min)
    }
    fn describe(&self) -> String {
        format!("luneburg R={}", Num(self.radius))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analytic::test_util::*;

    fn lens() -> Luneburg {
        let b = Bounds::Sphere {
            center: DVec3::new(0.2, 0.5, -0.3),
            radius: 0.6,
        };
        Luneburg::new(b, 1.0, None).expect("valid")
    }

    #[test]
    fn gradient_and_ranges() {
        let f = lens();
        assert_gradient_matches(&f, 1e-6, 1e-6);
        assert_range_bounds(&f, 0.05);
        let b = Bounds::Box {
            min: DVec3::splat(-1.0),
            max: DVec3::splat(1.0),
        };
        let f = Luneburg::new(b, 1.0, Some(1.3)).expect("valid box");
        assert_gradient_matches(&f, 1e-6, 1e-6);
        assert_range_bounds(&f, 0.05);
    }

    #[test]
    fn n_is_one_on_the_surface_and_sqrt2_at_the_centre() {
        let f = lens();
        for dir in [DVec3::X, DVec3::new(1.0, -2.0, 0.5).normalize(), -DVec3::Z] {
            let n = f.n(f.center() + dir * 0.6);
            assert!((n - 1.0).abs() < 1e-14, "n = {n} on the surface");
        }
        assert!((f.n(f.center()) - std::f64::consts::SQRT_2).abs() < 1e-15);
    }

    #[test]
    fn extension_outside_is_finite() {
        let f = lens();
        for r in [0.61, 0.8, 0.84, 0.85, 2.0, 1e6] {
            let s = f.sample(f.center() + DVec3::new(r, 0.0, 0.0));
            assert!(
                s.n.is_finite() && s.n > 0.0 && s.grad_n.is_finite(),
                "r = {r}: {s:?}"
            );
        }
        // Smooth extension just outside: still the formula.
        let p = f.center() + DVec3::new(0.66, 0.0, 0.0);
        assert!((f.n(p) - (2.0f64 - 1.21).sqrt()).abs() < 1e-14);
    }

    #[test]
    fn parallel_beam_focuses_on_the_antipode_at_quarter_period() {
        let f = lens();
        let r_lens = f.radius();
        for h in [0.0, 0.2, 0.45, 0.59] {
            // Enter at the surface point with height h along y, travelling +x (n = 1 there).
            let x0 = -(r_lens * r_lens - h * h).sqrt();
            let r0 = f.center() + DVec3::new(x0, h, 0.0);
            let t0 = DVec3::X * f.n(r0);
            let (r, tt) = f.exact_path(r0, t0, std::f64::consts::FRAC_PI_2 * r_lens);
            let focus = f.center() + DVec3::new(r_lens, 0.0, 0.0);
            assert!(
                (r - focus).length() < 1e-12,
                "h = {h}: reached {r}, focus {focus}"
            );
            assert!((tt.length() - f.n(r)).abs() < 1e-12);
        }
    }
}
