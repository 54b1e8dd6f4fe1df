//! Analytic index profiles with exact gradients, exact n ranges and, where they exist,
//! exact ray solutions (docs/physics.md, Exact solutions).
//!
//! Every profile is a struct implementing [`IndexField`](crate::IndexField). Unless a
//! profile says otherwise its coordinates are relative to the centre of the medium's
//! bounds. `sample` may be called a little outside the bounds: each profile returns its
//! formula's smooth extension where the formula stays positive and otherwise clamps n^2
//! to [`N2_FLOOR`] with a zero gradient, so no sample is ever NaN.
//!
//! Exact solutions are in the t-parameter form of the ray equation used everywhere in
//! grin: dr/dt = T, dT/dt = n grad n, with |T| = n.

/// The part of [`IndexField`](crate::IndexField) every profile here shares: the bounds
/// and ambient index it stores, and no local step limits (a formula has no empty cells
/// to fly over and no features to cap a step at).
macro_rules! analytic_basics {
    () => {
        fn bounds(&self) -> Bounds {
            self.bounds
        }
        fn ambient_index(&self) -> f64 {
            self.ambient
        }
        fn has_local_step_limits(&self) -> bool {
            false
        }
    };
}

pub mod eaton;
pub mod exponential_atmosphere;
pub mod grin_rod;
pub mod linear_n2;
pub mod luneburg;
pub mod maxwell_fish_eye;
pub mod plume;
pub mod uniform;

pub use eaton::Eaton;
pub use exponential_atmosphere::ExponentialAtmosphere;
pub use grin_rod::GrinRod;
pub use linear_n2::LinearN2;
pub use luneburg::Luneburg;
pub use maxwell_fish_eye::MaxwellFishEye;
pub use plume::Plume;
pub use uniform::Uniform;

use glam::DVec3;
use grin_scene::Axis;

use crate::bounds::Bounds;
use crate::field::{FieldError, FieldSample};

/// Smallest n^2 a profile's extension returns outside its domain of validity (n = 0.1):
/// far enough from 0 that n grad n stays tame, only ever reached well outside the bounds.
pub const N2_FLOOR: f64 = 1e-2;

/// Unit vector of a coordinate axis.
pub fn axis_vector(axis: Axis) -> DVec3 {
    match axis {
        Axis::X => DVec3::X,
        Axis::Y => DVec3::Y,
        Axis::Z => DVec3::Z,
    }
}

/// A parameter as a description prints it: as written for ordinary magnitudes, in
/// exponent form beyond 1e-4 ..= 1e6 (1e-300 printed as 300 digits).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Num(pub f64);

impl std::fmt::Display for Num {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let a = self.0.abs();
        if a != 0.0 && a.is_finite() && !(1e-4..1e6).contains(&a) {
            write!(f, "{:e}", self.0)
        } else {
            write!(f, "{}", self.0)
        }
    }
}

/// Name of an axis as written in scene files.
pub(crate) fn axis_name(axis: Axis) -> &'static str {
    axis.into()
}

/// n and grad n from n^2 and grad(n^2), clamping n^2 to [`N2_FLOOR`] (zero gradient there).
#[inline]
pub(crate) fn from_n2(n2: f64, grad_n2: DVec3) -> FieldSample<f64> {
    if n2 >= N2_FLOOR {
        let n = n2.sqrt();
        FieldSample {
            n,
            grad_n: grad_n2 / (2.0 * n),
        }
    } else {
        FieldSample {
            n: N2_FLOOR.sqrt(),
            grad_n: DVec3::ZERO,
        }
    }
}

/// Largest distance from the bounds' centre to a point of the bounds.
pub(crate) fn max_radius(bounds: &Bounds) -> f64 {
    match *bounds {
        Bounds::Sphere { radius, .. } => radius,
        Bounds::Box { min, max } => ((max - min) * 0.5).length(),
    }
}

/// Half-extent of the bounds along a unit coordinate axis (from the centre).
pub(crate) fn half_extent_along(bounds: &Bounds, axis: DVec3) -> f64 {
    match *bounds {
        Bounds::Sphere { radius, .. } => radius,
        Bounds::Box { min, max } => ((max - min) * 0.5).dot(axis.abs()),
    }
}

/// Largest distance from the line through the bounds' centre along `axis`.
pub(crate) fn max_axis_distance(bounds: &Bounds, axis: DVec3) -> f64 {
    match *bounds {
        Bounds::Sphere { radius, .. } => radius,
        Bounds::Box { min, max } => {
            let h = (max - min) * 0.5;
            (h - axis.abs() * h.dot(axis.abs())).length()
        }
    }
}

/// A `FieldError::Param` for profile `field`.
pub(crate) fn param_error(field: &str, param: &str, message: impl Into<String>) -> FieldError {
    FieldError::Param {
        field: field.to_owned(),
        param: param.to_owned(),
        message: message.into(),
    }
}

/// Check that a parameter is finite and > 0.
pub(crate) fn require_positive(field: &str, param: &str, value: f64) -> Result<f64, FieldError> {
    if value.is_finite() && value > 0.0 {
        Ok(value)
    } else {
        Err(param_error(
            field,
            param,
            format!("must be finite and > 0, got {value}"),
        ))
    }
}

/// Check that a parameter is finite.
pub(crate) fn require_finite(field: &str, param: &str, value: f64) -> Result<f64, FieldError> {
    if value.is_finite() {
        Ok(value)
    } else {
        Err(param_error(
            field,
            param,
            format!("must be finite, got {value}"),
        ))
    }
}

#[cfg(test)]
pub(crate) mod test_util {
    //! Shared checks for the profile tests: gradient against central differences, and
    //! n_range / max_grad_n as bounds of sampled values.
    use glam::DVec3;

    use crate::field::IndexField;

    /// Deterministic points inside the bounds (a jittered lattice), n^3 candidates.
    pub fn points_inside(field: &dyn IndexField, n: usize) -> Vec<DVec3> {
        let b = field.bounds();
        let (lo, hi) = b.aabb();
        // The centre, and the corners, edge and face centres of the box (or the matching
        // points on the sphere): where the extremes of the profiles sit.
        let c = b.center();
        let mut out = Vec::new();
        for i in 0..27 {
            let u = DVec3::new(
                (i % 3) as f64 - 1.0,
                ((i / 3) % 3) as f64 - 1.0,
                (i / 9) as f64 - 1.0,
            );
            let p = match b {
                crate::Bounds::Box { .. } => c + (hi - lo) * 0.5 * u,
                crate::Bounds::Sphere { radius, .. } => c + u.normalize_or_zero() * radius,
            };
            // Pull surface points in by a hair so they are strictly inside.
            out.push(c + (p - c) * (1.0 - 1e-12));
        }
        for i in 0..n {
            for j in 0..n {
                for k in 0..n {
                    // Irrational offsets keep points off symmetry planes and the centre.
                    let f = |m: usize, o: f64| ((m as f64 + 0.5 + 0.37 * o) / n as f64).min(0.999);
                    let u = DVec3::new(f(i, 0.618), f(j, 0.414), f(k, 0.732));
                    let p = lo + (hi - lo) * u;
                    if b.contains(p) {
                        out.push(p);
                    }
                }
            }
        }
        out
    }

    /// grad n matches the central difference of n to relative `rel` (against |grad n|,
    /// plus the difference's round-off and 1e-3 max_grad_n where the gradient vanishes).
    pub fn assert_gradient_matches(field: &dyn IndexField, h: f64, rel: f64) {
        let pts = points_inside(field, 9);
        assert!(pts.len() > 50, "too few test points: {}", pts.len());
        // Round-off of the central difference: a few ulps of n over 2h.
        let (_, n_hi) = field.n_range();
        let round_off = 4.0 * f64::EPSILON * n_hi / h;
        let g_floor = 1e-3 * field.max_grad_n();
        for p in pts {
            let s = field.sample(p);
            let mut fd = DVec3::ZERO;
            for a in 0..3 {
                let mut e = DVec3::ZERO;
                e[a] = h;
                fd[a] = (field.n(p + e) - field.n(p - e)) / (2.0 * h);
            }
            let err = (fd - s.grad_n).length();
            let scale = s.grad_n.length();
            assert!(
                err <= rel * (scale + g_floor) + round_off,
                "{}: grad n at {p} = {} but central difference = {fd} (rel err {:.3e})",
                field.describe(),
                s.grad_n,
                err / scale.max(1e-300)
            );
            assert!((s.n - field.n(p)).abs() == 0.0);
        }
    }

    /// n_range and max_grad_n bound every sampled value, and are attained to within `tight`.
    pub fn assert_range_bounds(field: &dyn IndexField, tight: f64) {
        let (lo, hi) = field.n_range();
        let gmax = field.max_grad_n();
        let (mut smin, mut smax, mut sg) = (f64::INFINITY, f64::NEG_INFINITY, 0.0f64);
        for p in points_inside(field, 24) {
            let s = field.sample(p);
            assert!(
                s.n >= lo - 1e-12 && s.n <= hi + 1e-12,
                "{}: n = {} at {p} outside n_range ({lo}, {hi})",
                field.describe(),
                s.n
            );
            let g = s.grad_n.length();
            assert!(
                g <= gmax * (1.0 + 1e-9) + 1e-15,
                "{}: |grad n| = {g} at {p} > max_grad_n {gmax}",
                field.describe()
            );
            smin = smin.min(s.n);
            smax = smax.max(s.n);
            sg = sg.max(g);
        }
        let span = (hi - lo).max(1e-300);
        assert!(
            (smin - lo) <= tight * span + 1e-15 && (hi - smax) <= tight * span + 1e-15,
            "{}: n_range ({lo}, {hi}) not attained: sampled ({smin}, {smax})",
            field.describe()
        );
        assert!(
            gmax - sg <= tight * gmax + 1e-15,
            "{}: max_grad_n {gmax} not attained: sampled {sg}",
            field.describe()
        );
    }
}
