//! A ray's own estimate of its exit-direction error, for the low-order integrators
//! (euler, symplectic-euler: order 1; verlet: order 2), from the field samples the march
//! takes anyway: no extra evaluation.
//!
//! The local error in T of an order-p step of length h (in t) is about
//! C h^(p+1) |D^(p)| with D = n grad n (T' = D); the p-th derivative comes from
//! differences of D at consecutive step ends. Order 1: h/2 |D1 - D0|. Order 2:
//! h^3/12 |D''| with D'' from the last three samples. Summed over the steps and divided
//! by n, it bounds the direction error if errors add without cancelling; the larger of
//! it and the drift of |T| from n at the exit (|T| = n holds for the exact ray) is the
//! estimate. A ray that leaves with an estimate above [`DEGRADED_RAD`] ends `degraded`,
//! not `exited`: its answer is not one grin vouches for (the stability matrix's silent
//! wrong answers were all these methods at coarse steps, docs/accuracy.md).
//!
//! The fourth- and fifth-order methods carry no estimate: the matrix found no silent
//! cell for them, and the difference formulas would need five samples.

use glam::DVec3;

/// A ray leaving with an estimated exit-direction error above this (rad) is `degraded`.
pub const DEGRADED_RAD: f64 = 3e-3;

/// The position error bar of the exit checks is this many times the estimate (the
/// estimate itself can be off by a factor of ~2; an exit just outside the bar went
/// through on the error's side of it: the turning-point cases of the stability matrix).
pub const POSITION_SAFETY: f64 = 4.0;

/// The running estimate along one ray.
#[derive(Debug, Clone, Copy)]
pub struct ErrorEstimate {
    /// 1, 2, or 0 (no estimate: higher-order integrators).
    order: u32,
    /// The direction error summed so far (rad).
    sum: f64,
    /// The ray's bending so far, integral of |D across T| / n dt (rad).
    bend: f64,
    /// The position error so far (world length): each step's own, plus the direction
    /// error so far carried over the step's length.
    pos: f64,
    /// The path came closer to the surface than its position error without leaving (a
    /// near miss), or a step turned T by more than a right angle: where it leaves is
    /// uncertain, wherever that is.
    near_miss: bool,
    /// D and the t-step of the previous step (order 2), while the samples are a smooth
    /// sequence (reset at flights and reflections).
    prev: Option<(DVec3, f64)>,
}

impl ErrorEstimate {
    /// For an integrator of `order` (none above 2).
    pub fn new(order: u32) -> Self {
        ErrorEstimate {
            order: if order <= 2 { order } else { 0 },
            sum: 0.0,
            bend: 0.0,
            pos: 0.0,
            near_miss: false,
            prev: None,
        }
    }

    /// Whether this integrator carries an estimate (order 1 or 2).
    pub fn is_active(&self) -> bool {
        self.order != 0
    }

    /// A step of t-length `h` from D = `d0` (index `n0`) to D = `d1`.
    pub fn step(&mut self, t0: DVec3, t1: DVec3, d0: DVec3, d1: DVec3, h: f64, n0: f64) {
        if self.order == 0 || h.is_nan() || h <= 0.0 || n0.is_nan() || n0 <= 0.0 {
            return;
        }
        // A step that turns T by more than a right angle is no approximation of a ray
        // (where n is small, a long t-step can reverse T along itself: a "reflection"
        // the across-the-ray terms below cannot see).
        if t0.dot(t1) <= 0.0 {
            self.near_miss = true;
        }
        // Only the part of an error in T across the ray turns its direction (the part
        // along it is an error of |T|, counted by the drift at the exit).
        let u = t0.normalize_or_zero();
        let across = |v: DVec3| (v - u * v.dot(u)).length();
        let local = match self.order {
            1 => 0.5 * h * across(d1 - d0),
            _ => match self.prev {
                Some((dp, hp)) if hp > 0.0 => {
                    let second = 2.0 * ((d1 - d0) / h - (d0 - dp) / hp) / (h + hp);
                    h * h * h / 12.0 * across(second)
                }
                _ => 0.0,
            },
        };
        self.bend += across(d0) * h / n0;
        let local_r = match self.order {
            1 => 0.5 * h * h * across(d0),
            _ => h * h / 6.0 * across(d1 - d0),
        };
        // A position error e_r turns the ray too: D is sampled e_r off, which changes T
        // by |dD/dr| e_r h, with |dD/dr| ~ |D1 - D0| / (h n) over the step.
        let feedback = (d1 - d0).length() * self.pos / n0;
        if local.is_finite() && local_r.is_finite() && feedback.is_finite() {
            self.pos += local_r + self.sum * h * n0;
            self.sum += (local + feedback) / n0;
        }
        self.prev = Some((d0, h));
    }

    /// At a step end inside, `depth` (>= 0) from the surface of unit outward `normal`,
    /// with T = `t`, index `n`, D = `d`: if the path heads for the surface and bends
    /// away from it, its closest approach is about depth - v^2 / (2 kappa_n) (v the
    /// direction's normal component, kappa_n the curvature away from the surface); within
    /// the position error of the surface it is a near miss.
    pub fn check_approach(&mut self, depth: f64, normal: DVec3, t: DVec3, n: f64, d: DVec3) {
        if self.order == 0 || self.near_miss || n.is_nan() || n <= 0.0 {
            return;
        }
        let v = t.normalize_or_zero().dot(normal);
        let kappa = -d.dot(normal) / (n * n);
        if v > 0.0 && kappa > 0.0 {
            let closest = depth - v * v / (2.0 * kappa);
            if closest.abs() < POSITION_SAFETY * self.pos {
                self.near_miss = true;
            }
        }
    }

    /// A straight flight or a reflection: the next differences start afresh.
    pub fn break_sequence(&mut self) {
        self.prev = None;
    }

    /// The estimate at an exit through a surface of unit `normal` with T = `t`, where
    /// the index is `n` and D = n grad n is `d`.
    ///
    /// Besides the direction error and what the drift of |T| from n does to the bending,
    /// a grazing exit is only as sure
    /// as the path's sagitta over the surface, cos^2 / (2 kappa) (kappa = |D| / n^2, the
    /// ray's curvature), exceeds the position error: where it does not, the exact ray may
    /// turn back before the surface (or leave where this one did not: the exit point may
    /// be anywhere), and the estimate is infinite.
    pub fn value(&self, t: DVec3, n: f64, normal: DVec3, d: DVec3) -> f64 {
        if self.order == 0 || n.is_nan() || n <= 0.0 {
            return 0.0;
        }
        // A relative error e of |T| = n bends the ray by (1 + e)^-2 of what it should:
        // about 2 e of its bending so far.
        let drift = (t.length() - n).abs() / n * 2.0 * self.bend;
        let u = t.normalize_or_zero();
        let cos = u.dot(normal).abs();
        let curvature = (d - u * d.dot(u)).length() / (n * n);
        let reach = 2.0 * curvature * POSITION_SAFETY * self.pos;
        let grazing = if reach > cos * cos || self.near_miss {
            f64::INFINITY
        } else {
            0.0
        };
        self.sum.max(drift).max(grazing)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_order_estimate_is_half_the_step_times_the_change_of_d() {
        let mut e = ErrorEstimate::new(1);
        e.step(
            DVec3::Z,
            DVec3::Z,
            DVec3::ZERO,
            DVec3::new(0.02, 0.0, 0.0),
            0.1,
            1.0,
        );
        e.step(
            DVec3::Z,
            DVec3::Z,
            DVec3::new(0.02, 0.0, 0.0),
            DVec3::new(0.04, 0.0, 0.0),
            0.1,
            1.0,
        );
        assert!(
            (e.value(DVec3::Z, 1.0, DVec3::Z, DVec3::ZERO) - 2.0 * 0.5 * 0.1 * 0.02).abs() < 1e-15
        );
    }

    #[test]
    fn second_order_estimate_grows_with_the_second_derivative_of_d() {
        // Verlet's estimate after five steps of h = 0.1 along +z, D = d(t) along x.
        let after_five = |d: fn(f64) -> DVec3| {
            let mut e = ErrorEstimate::new(2);
            for k in 0..5 {
                let t = f64::from(k) * 0.1;
                e.step(DVec3::Z, DVec3::Z, d(t), d(t + 0.1), 0.1, 1.0);
            }
            e.value(DVec3::Z, 1.0, DVec3::Z, DVec3::ZERO)
        };
        // D = t x: D'' = 0, verlet's local error term is zero (what is left is the
        // position error's feedback, h^2/6 |dD| |dD|/h per step, small).
        let linear = after_five(|t| DVec3::X * t);
        // D = t^2 x: D'' = 2, each step after the first adds h^3/12 * 2 (and feedback).
        let quadratic = after_five(|t| DVec3::X * t * t);
        let want = 4.0 * 1e-3 / 12.0 * 2.0;
        assert!(linear < 0.3 * want, "{linear}");
        assert!(quadratic >= want && quadratic < 2.0 * want, "{quadratic}");
    }

    #[test]
    fn a_grazing_exit_is_as_sure_as_its_sagitta() {
        // Euler, one step of h = 0.1 with |D| = 1 (n = 1): position error h^2/2 = 5e-3,
        // curvature 1: an exit at cos 0.05 (sagitta 1.25e-3, within 4 x 5e-3) is not
        // sure, the same exit at cos 0.5 (sagitta 0.125) is.
        let mut e = ErrorEstimate::new(1);
        e.step(DVec3::Y, DVec3::Y, DVec3::X, DVec3::X, 0.1, 1.0);
        let d = DVec3::X;
        let grazing = DVec3::new(0.05f64, (1.0f64 - 0.0025).sqrt(), 0.0);
        assert_eq!(e.value(grazing, 1.0, DVec3::X, d), f64::INFINITY);
        let steep = DVec3::new(0.5f64, 0.75f64.sqrt(), 0.0);
        assert!(e.value(steep, 1.0, DVec3::X, d) < 1e-12);
    }

    #[test]
    fn higher_orders_carry_no_estimate_and_drift_of_t_counts() {
        let mut e = ErrorEstimate::new(4);
        e.step(DVec3::Z, DVec3::Z, DVec3::ZERO, DVec3::X, 1.0, 1.0);
        assert_eq!(e.value(DVec3::Z * 2.0, 1.0, DVec3::Z, DVec3::ZERO), 0.0);
        // |T| 1 % off after bending by 0.1 rad: 2 x 0.01 x 0.1.
        let mut e = ErrorEstimate::new(1);
        e.step(DVec3::Z, DVec3::Z, DVec3::X, DVec3::X, 0.1, 1.0);
        let v = e.value(DVec3::Z * 1.01, 1.0, DVec3::Z, DVec3::ZERO);
        assert!((v - 2e-3).abs() < 1e-12, "{v}");
        // Along the ray, |T| may be off without turning it: no estimate.
        let mut e = ErrorEstimate::new(1);
        e.step(DVec3::Z, DVec3::Z, DVec3::Z, DVec3::Z * 2.0, 0.1, 1.0);
        assert_eq!(e.value(DVec3::Z * 1.5, 1.0, DVec3::Z, DVec3::ZERO), 0.0);
    }
}
