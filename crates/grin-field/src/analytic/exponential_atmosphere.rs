//! Stratified exponential atmosphere: n = 1 + e exp(-h / H), h = p . axis - base the
//! height above `base` along `axis` in world coordinates (not relative to the bounds).
//!
//! e > 0 is an ordinary atmosphere (index falls with height, rays bend down and the
//! horizon lifts, e ~ 2.9e-4 for air at sea level with H ~ 8 km). e < 0 is a hot layer
//! over the ground: the index *increases* with height, rays bend up and a ground-grazing
//! view shows the sky below the horizon (an inferior mirage), e ~ -5e-5 over hot
//! asphalt with H of a few centimetres to decimetres. There is no closed-form path, but
//! for a flat stratified field the horizontal part of T = n dr/ds is invariant
//! (n cos(elevation) is conserved), so turning points are where n = |T_horizontal|.

use glam::DVec3;
use grin_scene::Axis;

use super::{N2_FLOOR, Num, axis_name, axis_vector, param_error, require_finite, require_positive};
use crate::bounds::Bounds;
use crate::field::{FieldError, FieldSample, IndexField};

/// n = 1 + e exp(-(p . axis - base) / H), grad n = -(e / H) exp(-h / H) axis.
#[derive(Debug, Clone)]
pub struct ExponentialAtmosphere {
    bounds: Bounds,
    ambient: f64,
    e: f64,
    scale_height: f64,
    base: f64,
    axis: Axis,
    axis_v: DVec3,
    h_range: (f64, f64),
}

impl ExponentialAtmosphere {
    /// Requires H > 0 and n > 0 over the bounds.
    pub fn new(
        bounds: Bounds,
        ambient: f64,
        e: f64,
        scale_height: f64,
        base: f64,
        axis: Axis,
    ) -> Result<Self, FieldError> {
        require_finite("exponential-atmosphere", "e", e)?;
        require_positive("exponential-atmosphere", "scale_height", scale_height)?;
        require_finite("exponential-atmosphere", "base", base)?;
        let axis_v = axis_vector(axis);
        let (lo, hi) = bounds.aabb();
        let h_range = (lo.dot(axis_v) - base, hi.dot(axis_v) - base);
        let f = ExponentialAtmosphere {
            bounds,
            ambient,
            e,
            scale_height,
            base,
            axis,
            axis_v,
            h_range,
        };
        let n_min = f.n_range().0;
        if !(n_min > 0.0 && n_min.is_finite()) {
            return Err(param_error(
                "exponential-atmosphere",
                "e",
                format!(
                    "n = {n_min} at the bottom of the bounds (h = {}); n must be positive",
                    h_range.0
                ),
            ));
        }
        let n_max = f.n_range().1;
        if n_max.is_nan() || n_max > grin_scene::MAX_INDEX {
            return Err(param_error(
                "exponential-atmosphere",
                "scale_height",
                format!(
                    "n = 1 + e exp(-h / H) reaches {n_max:e} at the bottom of the bounds (h = {:e}, H = {scale_height:e}); n must be at most {:e}: a larger H, or a base at the bottom of the medium",
                    h_range.0,
                    grin_scene::MAX_INDEX
                ),
            ));
        }
        Ok(f)
    }

    /// The index at height h above the base (no clamping).
    pub fn n_at_height(&self, h: f64) -> f64 {
        1.0 + self.e * (-h / self.scale_height).exp()
    }

    /// Height above the base where a ray with horizontal invariant `beta` = |T - (T . axis)
    /// axis| turns (n(h) = beta), if the profile reaches that index (see [`turning_height`]).
    pub fn turning_height(&self, beta: f64) -> Option<f64> {
        turning_height(self.e, self.scale_height, beta)
    }

    /// Unit "up" axis.
    pub fn axis(&self) -> DVec3 {
        self.axis_v
    }
}

/// Height h where n(h) = 1 + e exp(-h / H) equals `beta`: h = -H ln((beta - 1) / e).
/// A ray whose horizontal invariant is beta turns there (its vertical T component
/// vanishes); `None` when (beta - 1) / e <= 0, i.e. no height has that index.
pub fn turning_height(e: f64, scale_height: f64, beta: f64) -> Option<f64> {
    let ratio = (beta - 1.0) / e;
    (ratio > 0.0 && ratio.is_finite()).then(|| -scale_height * ratio.ln())
}

impl IndexField for ExponentialAtmosphere {
    analytic_basics!();
    fn sample(&self, p: DVec3) -> FieldSample<f64> {
        let h = p.dot(self.axis_v) - self.base;
        let x = self.e * (-h / self.scale_height).exp();
        let n = 1.0 + x;
        if n >= N2_FLOOR.sqrt() && n.is_finite() {
            FieldSample {
                n,
                grad_n: self.axis_v * (-x / self.scale_height),
            }
        } else {
            // Only far below the bounds with e < 0: clamp, never NaN.
            FieldSample {
                n: N2_FLOOR.sqrt(),
                grad_n: DVec3::ZERO,
            }
        }
    }
    fn n_range(&self) -> (f64, f64) {
        let a = self.n_at_height(self.h_range.0);
        let b = self.n_at_height(self.h_range.1);
        (a.min(b), a.max(b))
    }
    fn max_grad_n(&self) -> f64 {
        (self.e / self.scale_height).abs() * (-self.h_range.0 / self.scale_height).exp()
    }
    fn describe(&self) -> String {
        format!(
            "exponential-atmosphere e={} H={} base={} axis={}",
            Num(self.e),
            Num(self.scale_height),
            Num(self.base),
            axis_name(self.axis)
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analytic::test_util::*;

    #[test]
    fn gradient_and_ranges() {
        let b = Bounds::Box {
            min: DVec3::new(-5.0, 0.0, -5.0),
            max: DVec3::new(5.0, 1.0, 5.0),
        };
        for e in [2.9e-4, -5e-5] {
            let f = ExponentialAtmosphere::new(b, 1.0, e, 0.3, 0.0, Axis::Y).expect("valid");
            assert_gradient_matches(&f, 1e-4, 1e-6);
            assert_range_bounds(&f, 0.05);
        }
    }

    #[test]
    fn negative_e_increases_with_height() {
        let b = Bounds::Box {
            min: DVec3::new(-1.0, 0.0, -1.0),
            max: DVec3::new(1.0, 1.0, 1.0),
        };
        let f = ExponentialAtmosphere::new(b, 1.0, -5e-5, 0.1, 0.0, Axis::Y).expect("valid");
        assert!((f.n(DVec3::ZERO) - (1.0 - 5e-5)).abs() < 1e-15);
        assert!(f.sample(DVec3::new(0.0, 0.2, 0.0)).grad_n.y > 0.0);
        assert!(f.n(DVec3::new(0.0, 0.9, 0.0)) > f.n(DVec3::new(0.0, 0.1, 0.0)));
    }

    #[test]
    fn turning_height_is_where_n_equals_the_horizontal_invariant() {
        let b = Bounds::Box {
            min: DVec3::new(-1.0, 0.0, -1.0),
            max: DVec3::new(1.0, 1.0, 1.0),
        };
        let f = ExponentialAtmosphere::new(b, 1.0, -2.5e-3, 0.15, 0.0, Axis::Y).expect("valid");
        // A ray at height 0.3 heading 0.1 degrees down: beta = n(0.3) cos(0.1 deg).
        let beta = f.n_at_height(0.3) * 0.1f64.to_radians().cos();
        let h = f.turning_height(beta).expect("turns above the ground");
        assert!(h > 0.0 && h < 0.3, "h = {h}");
        assert!((f.n_at_height(h) - beta).abs() < 1e-15);
        // Steeper than the layer can bend: the turning height is below the ground.
        let beta = f.n_at_height(0.3) * 5f64.to_radians().cos();
        assert!(f.turning_height(beta).is_some_and(|h| h < 0.0));
        // n < 1 everywhere when e < 0: no height has index 1.001.
        assert_eq!(f.turning_height(1.001), None);
    }

    #[test]
    fn rejects_nonpositive_index() {
        let b = Bounds::Box {
            min: DVec3::new(-1.0, 0.0, -1.0),
            max: DVec3::new(1.0, 1.0, 1.0),
        };
        let e = ExponentialAtmosphere::new(b, 1.0, -2.0, 0.1, 0.0, Axis::Y)
            .expect_err("n < 0 at ground");
        assert!(e.to_string().contains("n must be positive"), "{e}");
    }
}
