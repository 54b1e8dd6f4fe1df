//! A ray's own estimate of its exit-direction error, for every integrator and step
//! policy, from what the march computes anyway: no extra evaluation.
//!
//! The local error of each step comes from
//! - the step itself where it has one: the adaptive pair's embedded estimate (every
//!   policy), Richardson's of a doubled step (error control of the other integrators);
//! - the fourth-order steps at fixed or heuristic lengths (rk4, sharma): their
//!   third-order companion, which swaps the last stage's D for D at the new point (the
//!   next step's first sample): e_T = h/6 (D(r1) - D_last) (`Step::check`);
//! - the low-order steps at fixed or heuristic lengths (euler: order 1; verlet: order 2):
//!   C h^(p+1) |D^(p)| with D = n grad n (T' = D), the p-th derivative from differences
//!   of D at consecutive step ends. Order 1: h/2 |D1 - D0|. Order 2: h^3/12 |D''| with D''
//!   from the last three samples;
//! - symplectic-euler, whose T after a step is the leapfrog's T half a step back (its
//!   positions are the leapfrog's): verlet's formula, plus the half kick h/2 |D| it is off
//!   by where a sequence of steps starts and where the ray leaves (0 where the field is
//!   flat there: on a plume at 1e-4 rad it delivered 1.8e-6 rad where the first-order
//!   formula estimated ~1e-3).
//!
//! The local errors across the ray are summed as vectors (divided by n): a method's
//! leading error terms are differences of D along the ray, which telescope (euler's
//! h/2 (D1 - D0) sum to h/2 (D_end - D_start): a weak plume's ray, which enters and
//! leaves where D is 0, keeps none of them; summed as magnitudes they came to a third of
//! the ray's whole bending, and the pilots passed over methods that were right); an
//! embedded or companion estimate is the lower-order member's, so larger still. To that
//! the position errors' feedback is added in magnitude, and the larger of the sum and the
//! drift of |T| from n at the exit (|T| = n holds for the exact ray) is the estimate. A ray that leaves with an estimate above the
//! accuracy asked for (`TraceSettings::accuracy`) ends `degraded`, not `exited`: its
//! answer is not one grin vouches for (docs/accuracy.md: the stability matrix's silent
//! wrong answers were methods at coarse steps over features they could not resolve).

use glam::DVec3;

/// A ray is `degraded` where the field's n uncertainty amplified at its crossings of the
/// bounds (`RayResult::crossing_uncertainty`) is above this many times the accuracy asked
/// for. That term is a bound on a bake's error against its source, not the integration's,
/// and it ignores the cancelling of entry and exit: through the GPU's 100^3 bake of the
/// Luneburg lens (n 1.5e-4 below the source on average at the surface) it bounds rays at
/// impact 0.2-0.95 R by 1e-4-1.6e-3 rad where they are 2.6e-6-4.4e-4 off. At 1x it
/// degraded 1,413 of the example lens's 1,449 pixels on the GPU; at 10x, as the pilots'
/// slack ([`crate::auto::VOUCH_FACTOR`]), no exited ray is more than 10x off.
pub const CROSSING_FACTOR: f64 = 10.0;

/// The position error bar of the exit checks is this many times the estimate (the
/// estimate itself can be off by a factor of ~2; an exit just outside the bar went
/// through on the error's side of it: the turning-point cases of the stability matrix).
pub const POSITION_SAFETY: f64 = 4.0;

/// The running estimate along one ray.
#[derive(Debug, Clone, Copy)]
pub struct ErrorEstimate {
    /// The integrator's order (the difference formulas for 1 and 2).
    order: u32,
    /// Symplectic Euler: T is staggered half a step from r (`staggered_half`: h/2 D at
    /// the last step end, what T is off by there).
    staggered: bool,
    staggered_half: DVec3,
    /// The position errors' feedback on the direction, summed so far (rad; the local
    /// direction errors are in `vsum`).
    pub(crate) sum: f64,
    /// The ray's bending so far, integral of |D across T| / n dt (rad).
    pub(crate) bend: f64,
    /// The position error so far (world length): each step's own, plus the direction
    /// error so far carried over the step's length.
    pub(crate) pos: f64,
    /// The path came closer to the surface than its position error without leaving (a
    /// near miss), or a step turned T by more than a right angle: where it leaves is
    /// uncertain, wherever that is.
    pub(crate) near_miss: bool,
    /// D and the t-step of the previous step (order 2), while the samples are a smooth
    /// sequence (reset at flights and reflections).
    prev: Option<(DVec3, f64)>,
    /// The last local errors (direction across the ray, position) a step reported: a
    /// step that reports none (a fourth-order step cut at the surface, whose companion
    /// needs D where the uncut step would have ended) is counted as the one before it.
    pub(crate) last: (DVec3, f64),
    /// The local direction errors so far, summed as vectors (over n): a method's leading
    /// error terms along a weakly bending ray are differences of D that telescope (euler's
    /// h/2 (D1 - D0) sums to h/2 (D_end - D_start)), which a sum of magnitudes counts as
    /// if each added.
    pub(crate) vsum: DVec3,
}

impl ErrorEstimate {
    /// For `kind`.
    pub fn for_integrator(kind: grin_scene::IntegratorKind) -> Self {
        let mut e = Self::new(crate::integrate::order(kind));
        if kind == grin_scene::IntegratorKind::SymplecticEuler {
            e.order = 2;
            e.staggered = true;
        }
        e
    }

    /// For an integrator of `order` (the difference formulas of orders 1 and 2 where a
    /// step reports no error of its own).
    pub fn new(order: u32) -> Self {
        ErrorEstimate {
            order,
            staggered: false,
            staggered_half: DVec3::ZERO,
            sum: 0.0,
            bend: 0.0,
            pos: 0.0,
            near_miss: false,
            prev: None,
            last: (DVec3::ZERO, 0.0),
            vsum: DVec3::ZERO,
        }
    }

    /// A step of t-length `h` from D = `d0` (index `n0`) to D = `d1`, with the local
    /// error (e_r, e_T) the step reported (`None`: the difference formulas of orders 1
    /// and 2, or for a higher order the last step's).
    #[allow(clippy::too_many_arguments)]
    pub fn step(
        &mut self,
        t0: DVec3,
        t1: DVec3,
        d0: DVec3,
        d1: DVec3,
        h: f64,
        n0: f64,
        reported: Option<(DVec3, DVec3)>,
    ) {
        if h.is_nan() || h <= 0.0 || n0.is_nan() || n0 <= 0.0 {
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
        let across_v = |v: DVec3| v - u * v.dot(u);
        let across = |v: DVec3| across_v(v).length();
        let (local, local_r) = match (reported, self.order) {
            (Some((er, et)), _) => (across_v(et), across(er)),
            (None, 1) => (0.5 * h * across_v(d1 - d0), 0.5 * h * h * across(d0)),
            (None, 2) => {
                let local = match self.prev {
                    Some((dp, hp)) if hp > 0.0 => {
                        let second = 2.0 * ((d1 - d0) / h - (d0 - dp) / hp) / (h + hp);
                        h * h * h / 12.0 * across_v(second)
                    }
                    // Symplectic Euler's first kick of a sequence is a whole one where the
                    // leapfrog's is half.
                    _ if self.staggered => 0.5 * h * across_v(d0),
                    _ => DVec3::ZERO,
                };
                (local, h * h / 6.0 * across(d1 - d0))
            }
            (None, _) => self.last,
        };
        self.last = (local, local_r);
        self.staggered_half = d1 * (0.5 * h);
        self.bend += across(d0) * h / n0;
        // A position error e_r across the ray turns it too: D is sampled e_r off, which
        // changes T by |dD/dr| e_r h, with |dD/dr| ~ |D1 - D0| / (h n) over the step;
        // only the change across the ray turns it (along a ray on the axis of a
        // symmetric field, D changes fast but only along the ray).
        let feedback = across(d1 - d0) * self.pos / n0;
        if local.is_finite() && local_r.is_finite() && feedback.is_finite() {
            self.pos += local_r + self.direction() * h * n0;
            self.vsum += local / n0;
            self.sum += feedback / n0;
        }
        self.prev = Some((d0, h));
    }

    /// The direction error so far (rad): the local errors' vector sum and the position
    /// errors' feedback.
    fn direction(&self) -> f64 {
        self.vsum.length() + self.sum
    }

    /// At a step end inside, `depth` (>= 0) from the surface of unit outward `normal`,
    /// with T = `t`, index `n`, D = `d`, after a step of length `h`: if the path heads for
    /// the surface and bends away from it, its closest approach is about
    /// depth - v^2 / (2 kappa_n) (v the direction's normal component, kappa_n the
    /// curvature away from the surface); within the position error of the surface it is a
    /// near miss. The parabola is the path's Taylor expansion, so it is trusted only where
    /// it turns within a step (v / kappa_n <= h): from deeper in, it extrapolates over a
    /// length the path's curvature changes on (every Luneburg ray heads out and bends
    /// back towards the centre, and half way out its parabola "grazed" the surface the ray
    /// crosses at 58 degrees; the step ends near the surface decide).
    ///
    /// The test needs 0 < v <= kappa |h|, so v^2 / (2 kappa) <= |h| v / 2 <= |h| / 2 (v a
    /// cosine): deeper than |h| past the position error's margin it cannot hold, and the
    /// normal is not asked for (a NaN depth fails that test and is checked as before).
    #[inline]
    pub fn check_approach(
        &mut self,
        depth: f64,
        normal: impl FnOnce() -> DVec3,
        t: DVec3,
        n: f64,
        d: DVec3,
        h: f64,
    ) {
        if self.near_miss || n.is_nan() || n <= 0.0 || depth - h.abs() > POSITION_SAFETY * self.pos
        {
            return;
        }
        let normal = normal();
        let v = t.normalize_or_zero().dot(normal);
        let kappa = -d.dot(normal) / (n * n);
        if v > 0.0 && kappa > 0.0 && v <= kappa * h.abs() {
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
    /// Besides the direction error, what the position error does to where the path
    /// crosses the surface, and what the drift of |T| from n does to the bending, a
    /// grazing exit is only as sure
    /// as the path's sagitta over the surface, cos^2 / (2 kappa) (kappa = |D| / n^2, the
    /// ray's curvature), exceeds the position error: where it does not, the exact ray may
    /// turn back before the surface (or leave where this one did not: the exit point may
    /// be anywhere), and the estimate is infinite.
    pub fn value(&self, t: DVec3, n: f64, normal: DVec3, d: DVec3) -> f64 {
        if n.is_nan() || n <= 0.0 {
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
        // The position error across the ray moves the crossing along the path by
        // pos / cos, where the path has turned by curvature times that (a Luneburg ray
        // leaving at cos 0.014 after steps of R/4: 1.6e-3 rad of error, 2e-5 of it in T).
        let shift = if cos > 0.0 {
            curvature * self.pos / cos
        } else {
            f64::INFINITY
        };
        // Symplectic Euler's T at the exit is the leapfrog's half a kick back.
        let offset = if self.staggered {
            (self.staggered_half - u * self.staggered_half.dot(u)).length() / n
        } else {
            0.0
        };
        (self.direction() + shift + offset).max(drift).max(grazing)
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
            None,
        );
        e.step(
            DVec3::Z,
            DVec3::Z,
            DVec3::new(0.02, 0.0, 0.0),
            DVec3::new(0.04, 0.0, 0.0),
            0.1,
            1.0,
            None,
        );
        assert!(
            (e.value(DVec3::Z, 1.0, DVec3::Z, DVec3::ZERO) - 2.0 * 0.5 * 0.1 * 0.02).abs() < 1e-15
        );
    }

    #[test]
    fn leading_errors_that_telescope_are_not_counted_twice() {
        // Euler across a bump of D (along x, 0 -> 0.04 -> 0): each step's h/2 (D1 - D0)
        // is 2e-3 one way, then back; they sum to h/2 (D_end - D_start) = 0, where the
        // magnitudes would add to 4e-3.
        let mut e = ErrorEstimate::new(1);
        let d = [0.0, 0.04, 0.0].map(|x| DVec3::new(x, 0.0, 0.0));
        for k in 0..2 {
            e.step(DVec3::Z, DVec3::Z, d[k], d[k + 1], 0.1, 1.0, None);
        }
        let v = e.value(DVec3::Z, 1.0, DVec3::Z, DVec3::ZERO);
        // What is left is the position error's feedback (h^2/2 |D| |dD|: 1e-5 and less).
        assert!(v < 1e-4, "{v}");
    }

    #[test]
    fn second_order_estimate_grows_with_the_second_derivative_of_d() {
        // Verlet's estimate after five steps of h = 0.1 along +z, D = d(t) along x.
        let after_five = |d: fn(f64) -> DVec3| {
            let mut e = ErrorEstimate::new(2);
            for k in 0..5 {
                let t = f64::from(k) * 0.1;
                e.step(DVec3::Z, DVec3::Z, d(t), d(t + 0.1), 0.1, 1.0, None);
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
        e.step(DVec3::Y, DVec3::Y, DVec3::X, DVec3::X, 0.1, 1.0, None);
        let d = DVec3::X;
        let grazing = DVec3::new(0.05f64, (1.0f64 - 0.0025).sqrt(), 0.0);
        assert_eq!(e.value(grazing, 1.0, DVec3::X, d), f64::INFINITY);
        // ... its error is the position error carried along the path to the crossing:
        // curvature (|D| across the ray: sin 60 degrees) x 5e-3 / 0.5.
        let steep = DVec3::new(0.5f64, 0.75f64.sqrt(), 0.0);
        let v = e.value(steep, 1.0, DVec3::X, d);
        assert!((v - 0.75f64.sqrt() * 1e-2).abs() < 1e-12, "{v}");
    }

    #[test]
    fn higher_orders_sum_the_reported_errors_and_drift_of_t_counts() {
        // A fourth-order step reports (e_r, e_T); only e_T across the ray turns it. A step
        // that reports nothing (cut at the surface) counts as the last one did.
        let mut e = ErrorEstimate::new(4);
        let reported = Some((DVec3::X * 1e-9, DVec3::new(3e-6, 0.0, 5.0)));
        e.step(
            DVec3::Z,
            DVec3::Z,
            DVec3::ZERO,
            DVec3::X,
            1.0,
            1.0,
            reported,
        );
        e.step(DVec3::Z, DVec3::Z, DVec3::X, DVec3::X, 1.0, 1.0, None);
        let v = e.value(DVec3::Z, 1.0, DVec3::Z, DVec3::ZERO);
        assert!((v - 6e-6).abs() < 1e-8, "{v}");
        // |T| 1 % off after bending by 0.1 rad: 2 x 0.01 x 0.1.
        let mut e = ErrorEstimate::new(1);
        e.step(DVec3::Z, DVec3::Z, DVec3::X, DVec3::X, 0.1, 1.0, None);
        let v = e.value(DVec3::Z * 1.01, 1.0, DVec3::Z, DVec3::ZERO);
        assert!((v - 2e-3).abs() < 1e-12, "{v}");
        // Along the ray, |T| may be off without turning it: no estimate.
        let mut e = ErrorEstimate::new(1);
        e.step(DVec3::Z, DVec3::Z, DVec3::Z, DVec3::Z * 2.0, 0.1, 1.0, None);
        assert_eq!(e.value(DVec3::Z * 1.5, 1.0, DVec3::Z, DVec3::ZERO), 0.0);
    }
}
