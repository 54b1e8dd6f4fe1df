//! Maxwell fish-eye: n = n0 / (1 + (r/a)^2), r the distance from the bounds' centre.
//! Every ray is a circle; all rays from a point p meet again at its image
//! -a^2 p / |p|^2 ([`image_point`]). Defined and smooth everywhere.

use glam::DVec3;

use super::{Num, max_radius, require_positive};
use crate::bounds::Bounds;
use crate::field::{FieldError, FieldSample, IndexField};

/// n = n0 / (1 + |p - c|^2 / a^2), grad n = -2 n (p - c) / (a^2 (1 + |p - c|^2 / a^2)).
#[derive(Debug, Clone)]
pub struct MaxwellFishEye {
    bounds: Bounds,
    ambient: f64,
    center: DVec3,
    n0: f64,
    a: f64,
    r_max: f64,
}

impl MaxwellFishEye {
    pub fn new(bounds: Bounds, ambient: f64, n0: f64, a: f64) -> Result<Self, FieldError> {
        require_positive("maxwell-fish-eye", "n0", n0)?;
        require_positive("maxwell-fish-eye", "a", a)?;
        Ok(MaxwellFishEye {
            bounds,
            ambient,
            center: bounds.center(),
            n0,
            a,
            r_max: max_radius(&bounds),
        })
    }

    /// The centre (world).
    pub fn center(&self) -> DVec3 {
        self.center
    }

    /// The scale length a.
    pub fn a(&self) -> f64 {
        self.a
    }

    /// World image of world point `p` (see [`image_point`]).
    pub fn image_of(&self, p: DVec3) -> DVec3 {
        self.center + image_point(p - self.center, self.a)
    }
}

/// Image of point `p` (relative to the centre) in a fish-eye of scale `a`:
/// -a^2 p / |p|^2. Every ray through p passes through it.
pub fn image_point(p: DVec3, a: f64) -> DVec3 {
    -p * (a * a / p.length_squared())
}

impl IndexField for MaxwellFishEye {
    analytic_basics!();
    fn sample(&self, p: DVec3) -> FieldSample<f64> {
        let d = p - self.center;
        let q = 1.0 + d.length_squared() / (self.a * self.a);
        let n = self.n0 / q;
        FieldSample {
            n,
            grad_n: d * (-2.0 * n / (self.a * self.a * q)),
        }
    }
    fn n_range(&self) -> (f64, f64) {
        let u = self.r_max / self.a;
        (self.n0 / (1.0 + u * u), self.n0)
    }
    fn max_grad_n(&self) -> f64 {
        // |grad n| = (2 n0 / a) u / (1 + u^2)^2 with u = r/a peaks at u = 1/sqrt(3).
        let u = (self.r_max / self.a).min(1.0 / 3f64.sqrt());
        2.0 * self.n0 / self.a * u / (1.0 + u * u).powi(2)
    }
    fn describe(&self) -> String {
        format!("maxwell-fish-eye n0={} a={}", Num(self.n0), Num(self.a))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analytic::test_util::*;

    #[test]
    fn gradient_and_ranges() {
        for (radius, a) in [(1.0, 1.0), (1.0, 3.0), (0.5, 0.2)] {
            let b = Bounds::Sphere {
                center: DVec3::new(1.0, 0.0, 2.0),
                radius,
            };
            let f = MaxwellFishEye::new(b, 1.0, 2.0, a).expect("valid");
            assert_gradient_matches(&f, 1e-6, 1e-6);
            assert_range_bounds(&f, 0.05);
        }
    }

    #[test]
    fn image_point_is_an_involution_on_the_inversion_sphere() {
        let a = 0.7;
        let p = DVec3::new(0.3, -0.2, 0.1);
        let q = image_point(p, a);
        assert!((p.length() * q.length() - a * a).abs() < 1e-15);
        assert!((image_point(q, a) - p).length() < 1e-15);
        assert!(p.dot(q) < 0.0);
    }

    #[test]
    fn rays_are_circles_of_constant_curvature() {
        // A ray's curvature is |grad n - (grad n . u) u| / n. In a fish-eye the ray from p
        // along u is the circle tangent to u at p through the image of p.
        let b = Bounds::Sphere {
            center: DVec3::ZERO,
            radius: 1.0,
        };
        let f = MaxwellFishEye::new(b, 1.0, 1.0, 1.0).expect("valid");
        let p = DVec3::new(0.4, 0.0, 0.0);
        let u = DVec3::new(0.0, 1.0, 0.0);
        let s = f.sample(p);
        let kappa = (s.grad_n - u * s.grad_n.dot(u)).length() / s.n;
        // The circle through p tangent to u and through image(p) = (-2.5, 0, 0) has its
        // centre on the x axis at the midpoint x = (0.4 - 2.5) / 2, radius (0.4 + 2.5) / 2.
        let radius = (0.4 + 2.5) / 2.0;
        assert!(
            (kappa - 1.0 / radius).abs() < 1e-12,
            "curvature {kappa} vs {}",
            1.0 / radius
        );
    }
}
