//! Uniform medium: n = `n` everywhere inside the bounds (a constant-index ball or box).
//! Rays go straight inside; all bending happens by Snell's law at the surface.

use glam::DVec3;

use super::{Num, require_positive};
use crate::bounds::Bounds;
use crate::field::{FieldError, FieldSample, IndexField};

/// n(r) = n1 (constant), grad n = 0.
#[derive(Debug, Clone)]
pub struct Uniform {
    bounds: Bounds,
    ambient: f64,
    n: f64,
}

impl Uniform {
    /// A uniform medium of index `n` > 0.
    pub fn new(bounds: Bounds, ambient: f64, n: f64) -> Result<Self, FieldError> {
        require_positive("uniform", "n", n)?;
        Ok(Uniform { bounds, ambient, n })
    }

    /// The constant index.
    pub fn index(&self) -> f64 {
        self.n
    }
}

impl IndexField for Uniform {
    analytic_basics!();
    fn sample(&self, _p: DVec3) -> FieldSample<f64> {
        FieldSample {
            n: self.n,
            grad_n: DVec3::ZERO,
        }
    }
    fn n_range(&self) -> (f64, f64) {
        (self.n, self.n)
    }
    fn max_grad_n(&self) -> f64 {
        0.0
    }
    fn describe(&self) -> String {
        format!("uniform n={}", Num(self.n))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constant_and_rejects_nonpositive() {
        let b = Bounds::Sphere {
            center: DVec3::ZERO,
            radius: 1.0,
        };
        let f = Uniform::new(b, 1.0, 1.5).expect("valid");
        let s = f.sample(DVec3::new(0.3, -0.2, 0.1));
        assert_eq!(s.n, 1.5);
        assert_eq!(s.grad_n, DVec3::ZERO);
        assert_eq!(f.n_range(), (1.5, 1.5));
        let e = Uniform::new(b, 1.0, -1.0).expect_err("n < 0");
        assert_eq!(
            e.to_string(),
            "uniform: invalid parameter `n`: must be finite and > 0, got -1"
        );
    }
}
