//! Gaussian hot-air plumes (heat haze): n = n_amb - sum_i a_i exp(-|p - c_i|^2 / s_i^2)
//! in world coordinates, n_amb the medium's ambient index. a_i > 0 is hotter (lower n)
//! air; at 20 C a 30 K excess lowers n by about 2.5e-5 (docs/physics.md, Air).

use glam::DVec3;
use grin_scene::PlumeBlob;

use super::{param_error, require_finite, require_positive};
use crate::bounds::Bounds;
use crate::field::{FieldError, FieldSample, IndexField};

/// One blob in world coordinates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Blob {
    pub a: f64,
    pub center: DVec3,
    pub s: f64,
}

/// Sum of Gaussian blobs below the ambient index.
#[derive(Debug, Clone)]
pub struct Plume {
    bounds: Bounds,
    ambient: f64,
    blobs: Vec<Blob>,
}

impl Plume {
    /// Requires s_i > 0 and finite a_i, c_i, and n > 0 everywhere (checked on the bound
    /// n_amb - sum of positive a_i).
    pub fn new(bounds: Bounds, ambient: f64, blobs: &[PlumeBlob]) -> Result<Self, FieldError> {
        let mut out = Vec::with_capacity(blobs.len());
        for (i, b) in blobs.iter().enumerate() {
            require_finite("plume", &format!("plumes[{i}].a"), b.a)?;
            require_positive("plume", &format!("plumes[{i}].s"), b.s)?;
            if !b.center.iter().all(|c| c.is_finite()) {
                return Err(param_error(
                    "plume",
                    &format!("plumes[{i}].center"),
                    "must be finite",
                ));
            }
            out.push(Blob {
                a: b.a,
                center: DVec3::from_array(b.center),
                s: b.s,
            });
        }
        let f = Plume {
            bounds,
            ambient,
            blobs: out,
        };
        let n_min = f.n_range().0;
        if n_min <= 0.0 {
            return Err(param_error(
                "plume",
                "plumes",
                format!("amplitudes can drive n to {n_min} <= 0; n must stay positive"),
            ));
        }
        Ok(f)
    }

    /// The blobs.
    pub fn blobs(&self) -> &[Blob] {
        &self.blobs
    }
}

impl IndexField for Plume {
    analytic_basics!();
    fn sample(&self, p: DVec3) -> FieldSample<f64> {
        let mut n = self.ambient;
        let mut grad_n = DVec3::ZERO;
        for b in &self.blobs {
            let d = p - b.center;
            let inv_s2 = 1.0 / (b.s * b.s);
            let g = b.a * (-d.length_squared() * inv_s2).exp();
            n -= g;
            grad_n += d * (2.0 * g * inv_s2);
        }
        FieldSample { n, grad_n }
    }
    /// A bound, exact for a single blob centred in the bounds: overlapping blobs at most
    /// add their amplitudes.
    fn n_range(&self) -> (f64, f64) {
        let hot: f64 = self.blobs.iter().map(|b| b.a.max(0.0)).sum();
        let cold: f64 = self.blobs.iter().map(|b| (-b.a).max(0.0)).sum();
        (self.ambient - hot, self.ambient + cold)
    }
    /// A bound: each blob's |grad| peaks at |p - c| = s / sqrt(2) with value
    /// sqrt(2) |a| exp(-1/2) / s; the sum bounds the total.
    fn max_grad_n(&self) -> f64 {
        self.blobs
            .iter()
            .map(|b| std::f64::consts::SQRT_2 * b.a.abs() * (-0.5f64).exp() / b.s)
            .sum()
    }
    fn describe(&self) -> String {
        format!("plume ({} blobs)", self.blobs.len())
    }
    /// The narrowest blob's width s.
    fn feature_size(&self) -> Option<f64> {
        self.blobs.iter().map(|b| b.s).reduce(f64::min)
    }
    /// Each blob's |a| exp(-d^2 / s^2) at the box's point nearest its centre, summed.
    fn delta_bound(&self, lo: DVec3, hi: DVec3) -> Option<f64> {
        Some(
            self.blobs
                .iter()
                .map(|b| {
                    let d2 = b.center.clamp(lo, hi).distance_squared(b.center);
                    b.a.abs() * (-d2 / (b.s * b.s)).exp()
                })
                .sum(),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analytic::test_util::*;

    fn haze() -> Plume {
        let b = Bounds::Box {
            min: DVec3::new(-2.0, 0.0, -2.0),
            max: DVec3::new(2.0, 1.0, 2.0),
        };
        let blobs = [
            PlumeBlob {
                a: 3e-5,
                center: [0.0, 0.0, 0.0],
                s: 0.4,
            },
            PlumeBlob {
                a: 2e-5,
                center: [0.7, 0.3, -0.4],
                s: 0.25,
            },
            PlumeBlob {
                a: -1e-5,
                center: [-1.0, 0.6, 0.5],
                s: 0.5,
            },
        ];
        Plume::new(b, 1.000293, &blobs).expect("valid")
    }

    #[test]
    fn gradient_and_ranges() {
        let f = haze();
        assert_gradient_matches(&f, 1e-4, 1e-6);
        // Conservative bounds: checked as bounds, not for tightness.
        assert_range_bounds(&f, 1.0);
    }

    #[test]
    fn single_centred_blob_has_exact_range_and_peak() {
        let b = Bounds::Sphere {
            center: DVec3::ZERO,
            radius: 1.0,
        };
        let f = Plume::new(
            b,
            1.0,
            &[PlumeBlob {
                a: 0.01,
                center: [0.0; 3],
                s: 0.3,
            }],
        )
        .expect("valid");
        assert_eq!(f.n(DVec3::ZERO), 0.99);
        assert!(
            (f.n(DVec3::new(0.3, 0.0, 0.0)) - (1.0 - 0.01 / std::f64::consts::E)).abs() < 1e-15
        );
        let peak = f
            .sample(DVec3::new(0.0, 0.3 / std::f64::consts::SQRT_2, 0.0))
            .grad_n
            .length();
        assert!((peak - f.max_grad_n()).abs() < 1e-12 * peak);
        // Hot air lowers n: the gradient points away from the blob centre.
        assert!(f.sample(DVec3::new(0.1, 0.0, 0.0)).grad_n.x > 0.0);
    }

    #[test]
    fn rejects_bad_width() {
        let b = Bounds::Sphere {
            center: DVec3::ZERO,
            radius: 1.0,
        };
        let e = Plume::new(
            b,
            1.0,
            &[PlumeBlob {
                a: 0.01,
                center: [0.0; 3],
                s: 0.0,
            }],
        )
        .expect_err("s = 0");
        assert_eq!(
            e.to_string(),
            "plume: invalid parameter `plumes[0].s`: must be finite and > 0, got 0"
        );
    }
}
