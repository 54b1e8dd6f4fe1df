//! Load-time checks shared by every field kind: n must be finite and > 0 (and grad n
//! finite) everywhere inside the medium, verified on a sample grid over the bounds.

use glam::DVec3;

use crate::field::{FieldError, IndexField};

/// Samples per axis of the check grid over the bounds' bounding box (24^3 = 13 824
/// samples: catches any negative region wider than ~4% of the medium in well under a
/// millisecond for analytic fields).
pub const CHECK_RESOLUTION: usize = 24;

/// What the check grid saw: n range and largest |grad n| over the samples inside.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SampleStats {
    pub n_min: f64,
    pub n_max: f64,
    pub max_grad_n: f64,
    /// Number of grid points inside the bounds that were sampled.
    pub samples: usize,
}

/// Points of the check grid inside the bounds: cell centres of a `res`^3 grid over the
/// bounds' axis-aligned box, plus the bounds' centre.
pub fn check_points(field: &dyn IndexField, res: usize) -> impl Iterator<Item = DVec3> + '_ {
    let bounds = field.bounds();
    let (lo, hi) = bounds.aabb();
    let res = res.max(1);
    let cells = (0..res * res * res).map(move |i| {
        let ijk = DVec3::new(
            (i % res) as f64,
            ((i / res) % res) as f64,
            (i / (res * res)) as f64,
        );
        lo + (hi - lo) * ((ijk + 0.5) / res as f64)
    });
    std::iter::once(bounds.center())
        .chain(cells)
        .filter(move |p| bounds.contains(*p))
}

/// Sample `field` on the check grid; fails on the first point where n <= 0 or n or
/// grad n is not finite, naming `label`, the point and the value.
pub fn sample_stats(
    field: &dyn IndexField,
    label: &str,
    res: usize,
) -> Result<SampleStats, FieldError> {
    let mut stats = SampleStats {
        n_min: f64::INFINITY,
        n_max: f64::NEG_INFINITY,
        max_grad_n: 0.0,
        samples: 0,
    };
    for p in check_points(field, res) {
        let s = field.sample(p);
        if !s.n.is_finite() {
            return Err(FieldError::NonFinite {
                field: label.to_owned(),
                n: s.n,
                x: p.x,
                y: p.y,
                z: p.z,
            });
        }
        if s.n <= 0.0 {
            return Err(FieldError::NonPositive {
                field: label.to_owned(),
                n: s.n,
                x: p.x,
                y: p.y,
                z: p.z,
            });
        }
        if s.n > grin_scene::MAX_INDEX {
            return Err(FieldError::Other(format!(
                "{label}: n = {:e} at ({}, {}, {}) inside the medium is above the largest index grin takes, {:e}",
                s.n,
                p.x,
                p.y,
                p.z,
                grin_scene::MAX_INDEX
            )));
        }
        if !s.grad_n.is_finite() {
            return Err(FieldError::Other(format!(
                "{label}: grad n is not finite ({}) at ({}, {}, {})",
                s.grad_n, p.x, p.y, p.z
            )));
        }
        stats.n_min = stats.n_min.min(s.n);
        stats.n_max = stats.n_max.max(s.n);
        stats.max_grad_n = stats.max_grad_n.max(s.grad_n.length());
        stats.samples += 1;
    }
    Ok(stats)
}

/// Fail unless n is finite and > 0 (and grad n finite) at every check-grid point inside
/// the medium. Every field kind goes through this after it is built.
pub fn check_positive(field: &dyn IndexField, label: &str) -> Result<(), FieldError> {
    sample_stats(field, label, CHECK_RESOLUTION).map(|_| ())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analytic::Uniform;
    use crate::bounds::Bounds;
    use crate::field::FieldSample;

    /// n = 1 + x: negative for x < -1.
    #[derive(Debug)]
    struct Ramp(Bounds);
    impl IndexField for Ramp {
        fn sample(&self, p: DVec3) -> FieldSample<f64> {
            FieldSample {
                n: 1.0 + p.x,
                grad_n: DVec3::X,
            }
        }
        fn bounds(&self) -> Bounds {
            self.0
        }
        fn ambient_index(&self) -> f64 {
            1.0
        }
        fn n_range(&self) -> (f64, f64) {
            (0.0, 2.0)
        }
        fn max_grad_n(&self) -> f64 {
            1.0
        }
        fn describe(&self) -> String {
            "ramp".into()
        }
    }

    #[test]
    fn accepts_positive_field_and_counts_inside_points_only() {
        let b = Bounds::Sphere {
            center: DVec3::ZERO,
            radius: 1.0,
        };
        let f = Uniform::new(b, 1.0, 1.2).expect("valid");
        let s = sample_stats(&f, "uniform", 24).expect("positive");
        // Fraction of a cube's cell centres inside the inscribed ball: ~ pi/6.
        let frac = s.samples as f64 / 24f64.powi(3);
        assert!((frac - std::f64::consts::PI / 6.0).abs() < 0.01, "{frac}");
        assert_eq!((s.n_min, s.n_max, s.max_grad_n), (1.2, 1.2, 0.0));
    }

    #[test]
    fn names_the_point_where_n_is_not_positive() {
        let f = Ramp(Bounds::Box {
            min: DVec3::new(-2.0, 0.0, 0.0),
            max: DVec3::new(0.0, 1.0, 1.0),
        });
        let e = check_positive(&f, "ramp").expect_err("n < 0 for x < -1");
        let FieldError::NonPositive { n, x, .. } = &e else {
            panic!("wrong error {e}")
        };
        assert!(*n <= 0.0 && (*n - (1.0 + *x)).abs() < 1e-15);
        assert!(e.to_string().starts_with("ramp: n = "), "{e}");
        assert!(e.to_string().contains("inside the medium"), "{e}");
        // Restricted to x > -1 the same field passes.
        let f = Ramp(Bounds::Box {
            min: DVec3::new(-0.9, 0.0, 0.0),
            max: DVec3::new(0.0, 1.0, 1.0),
        });
        check_positive(&f, "ramp").expect("positive for x > -1");
    }
}
