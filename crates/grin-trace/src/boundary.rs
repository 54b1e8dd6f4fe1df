//! The medium surface: Snell refraction with Fresnel reflectance and total internal
//! reflection, projection onto the bounds, and finding where a step leaves the medium
//! (bisection on the step length, or the root of the step's cubic Hermite dense output).

use glam::DVec3;
use grin_field::Bounds;
use grin_field::Real;

/// What happens to a ray meeting an index step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Interface {
    /// Refracted into the other side with unit `dir`; `reflectance` is the Fresnel
    /// fraction reflected (unpolarized), so the ray carries 1 - reflectance.
    Transmitted { dir: DVec3, reflectance: f64 },
    /// Total internal reflection: the ray stays on its side with unit `dir`.
    Reflected { dir: DVec3 },
}

/// Mirror unit `d` about the plane of unit normal `normal`.
pub fn reflect(d: DVec3, normal: DVec3) -> DVec3 {
    d - normal * (2.0 * d.dot(normal))
}

/// Unpolarized Fresnel reflectance for light going from index `n1` into `n2` with
/// cos(incidence) `cos_i` and cos(refraction) `cos_t` (mean of the s and p powers).
pub fn fresnel(n1: f64, n2: f64, cos_i: f64, cos_t: f64) -> f64 {
    let rs = (n1 * cos_i - n2 * cos_t) / (n1 * cos_i + n2 * cos_t);
    let rp = (n1 * cos_t - n2 * cos_i) / (n1 * cos_t + n2 * cos_i);
    0.5 * (rs * rs + rp * rp)
}

/// Snell's law at a surface with unit normal `normal` (either orientation) for unit `d`
/// travelling from index `n1` into `n2`: the refracted direction and Fresnel reflectance,
/// or total internal reflection.
pub fn refract(d: DVec3, normal: DVec3, n1: f64, n2: f64) -> Interface {
    // Orient the normal against the incident direction.
    let nrm = if d.dot(normal) > 0.0 { -normal } else { normal };
    let cos_i = (-d.dot(nrm)).clamp(0.0, 1.0);
    let eta = n1 / n2;
    let sin2_t = eta * eta * (1.0 - cos_i * cos_i);
    if sin2_t >= 1.0 {
        return Interface::Reflected {
            dir: reflect(d, nrm),
        };
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    let dir = (d * eta + nrm * (eta * cos_i - cos_t)).normalize();
    Interface::Transmitted {
        dir,
        reflectance: fresnel(n1, n2, cos_i, cos_t),
    }
}

/// Direction error (rad) a refraction at the bounds adds when the field's n there is
/// uncertain by `dn` (`IndexField::n_uncertainty`): the refracted angle moves by
/// dn tan(theta_t) / n_field (either side's index), so a grazing crossing amplifies an
/// index error that is harmless at normal incidence. Infinite where `dn` could change
/// transmission into total reflection or back. `d` the incident unit direction, `n1` ->
/// `n2` the crossing, `n_field` the field's side.
pub fn refraction_uncertainty(
    d: DVec3,
    normal: DVec3,
    n1: f64,
    n2: f64,
    n_field: f64,
    dn: f64,
) -> f64 {
    if dn.is_nan() || dn <= 0.0 {
        return 0.0;
    }
    let cos_i = d.dot(normal).abs().min(1.0);
    let sin2_t = (n1 / n2).powi(2) * (1.0 - cos_i * cos_i);
    // d(sin^2 theta_t) / dn is 2 sin^2 theta_t / n for either index.
    if (1.0 - sin2_t).abs() <= 2.0 * sin2_t * dn / n_field {
        return f64::INFINITY;
    }
    if sin2_t >= 1.0 {
        return 0.0;
    }
    let tan_t = (sin2_t / (1.0 - sin2_t)).sqrt();
    dn * tan_t / n_field
}

/// The point of the bounds' surface nearest to `p` (radially for the sphere, along the
/// nearest face's normal for the box).
pub fn project_to_surface(bounds: &Bounds, p: DVec3) -> DVec3 {
    match *bounds {
        Bounds::Sphere { center, radius } => {
            let d = p - center;
            let len = d.length();
            if len > 0.0 {
                center + d * (radius / len)
            } else {
                p
            }
        }
        Bounds::Box { min, max } => {
            let normal = bounds.normal(p);
            let mut q = p.clamp(min, max);
            for axis in 0..3 {
                if normal[axis] > 0.0 {
                    q[axis] = max[axis];
                } else if normal[axis] < 0.0 {
                    q[axis] = min[axis];
                }
            }
            q
        }
    }
}

/// Cubic Hermite dense output of one step over t in [0, h]: positions r0, r1 and their
/// t-derivatives T0, T1 (all in world units, f64).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment {
    pub r0: DVec3,
    pub t0: DVec3,
    pub r1: DVec3,
    pub t1: DVec3,
    /// Step length in t (world length = integral of n dt).
    pub h: f64,
}

impl Segment {
    /// Position at t = tau in [0, h].
    #[inline]
    pub fn point(&self, tau: f64) -> DVec3 {
        if self.h == 0.0 {
            return self.r0;
        }
        let u = tau / self.h;
        let u2 = u * u;
        let u3 = u2 * u;
        let h00 = 2.0 * u3 - 3.0 * u2 + 1.0;
        let h10 = u3 - 2.0 * u2 + u;
        let h01 = -2.0 * u3 + 3.0 * u2;
        let h11 = u3 - u2;
        self.r0 * h00 + self.t0 * (h10 * self.h) + self.r1 * h01 + self.t1 * (h11 * self.h)
    }

    /// The smallest tau in [0, h] where `f(point(tau))` ~ 0 changes sign from <= 0 to > 0,
    /// given f(r1) > 0: scanned on [`HERMITE_SCAN`] sub-intervals, then refined on the
    /// bracket by the Illinois method (regula falsi that halves the value kept at a
    /// stuck end: superlinear, fewer evaluations than bisection's ~50 in f64) until the
    /// bracket is one ulp wide, or at a point that reads exactly on the surface. (Also
    /// stopping once |f| fell below the exit tolerance changed the f32 GPU twin's paths,
    /// +5% mean steps on the grin-rod scene, cause not pinned down; without that stop
    /// both twins match.)
    pub fn first_crossing(&self, f: impl Fn(DVec3) -> f64) -> f64 {
        let (mut lo, mut f_lo) = (0.0, f64::NAN);
        let (mut hi, mut f_hi) = (self.h, f64::NAN);
        for k in 1..=HERMITE_SCAN {
            let tau = self.h * f64::from(k) / f64::from(HERMITE_SCAN);
            let v = f(self.point(tau));
            if v > 0.0 {
                (hi, f_hi) = (tau, v);
                break;
            }
            (lo, f_lo) = (tau, v);
        }
        if lo == 0.0 {
            f_lo = f(self.r0);
        }
        // After total internal reflection the start sits on the surface and may read a
        // hair outside: no sign change to interpolate, so bisect there.
        let secant = f_lo <= 0.0 && f_hi > 0.0;
        let mut stuck = 0_i8;
        for _ in 0..MAX_BISECTIONS {
            let mid = 0.5 * (lo + hi);
            let m = if secant {
                let m = hi - f_hi * (hi - lo) / (f_hi - f_lo);
                if m > lo && m < hi { m } else { mid }
            } else {
                mid
            };
            if m <= lo || m >= hi {
                break;
            }
            let v = f(self.point(m));
            if v == 0.0 {
                // On the surface: the bracket's end at m would stay at 0 (the secant
                // then falls back to halving for the last ~50 bits).
                return m;
            }
            if v > 0.0 {
                (hi, f_hi) = (m, v);
                if stuck > 0 {
                    f_lo *= 0.5;
                }
                stuck = 1;
            } else {
                (lo, f_lo) = (m, v);
                if stuck < 0 {
                    f_hi *= 0.5;
                }
                stuck = -1;
            }
        }
        // The re-step lands on (or a hair off) the surface, then projects.
        0.5 * (lo + hi)
    }
}

/// Sub-intervals scanned for the first crossing of the surface by a step's dense output
/// (a step that starts on the surface after total internal reflection begins at f ~ 0).
pub const HERMITE_SCAN: u32 = 8;

/// Golden-section iterations refining the largest excursion of a segment outside the
/// bounds (each a cubic evaluation, no field sample): brackets shrink by 0.618 each, so
/// 40 resolve a turning point to 1e-8 of a step.
pub const EXCURSION_ITERATIONS: u32 = 40;

/// The excursion search stops as soon as the segment is proven inside by this many exit
/// tolerances (its samples and the cubic's bend between them: [`Segment::bend`]), so that
/// rounding in the samples cannot be what proves it.
pub const EXCURSION_SLACK_TOLS: f64 = 8.0;

impl Segment {
    /// How far the cubic can bend off the chord between two of its points `len` apart
    /// (in t): M len^2 / 8, M = max |r''| over the segment. r'' is linear in t, so M is
    /// its larger end value: r''(0) = (6 (r1 - r0) - 4 h T0 - 2 h T1) / h^2 and r''(h) =
    /// (-6 (r1 - r0) + 2 h T0 + 4 h T1) / h^2.
    pub fn bend(&self, len: f64) -> f64 {
        if self.h <= 0.0 {
            return 0.0;
        }
        let (d, h) = (self.r1 - self.r0, self.h);
        let a0 = (6.0 * d - 4.0 * h * self.t0 - 2.0 * h * self.t1).length();
        let a1 = (-6.0 * d + 2.0 * h * self.t0 + 4.0 * h * self.t1).length();
        a0.max(a1) / 8.0 * (len / h) * (len / h)
    }

    /// Whether the segment with both ends inside (`f0`, `f1` <= 0) stays inside by at
    /// least `slack` times the fraction of the way from its nearer end to the surface:
    /// along the chord the distance is at most (1 - u) f0 + u f1 (convex), and the cubic
    /// is at most M h^2 u (1 - u) / 2 <= 4 [`Self::bend`]`(h)` u off it (its deviation
    /// from the chord vanishes at both ends, with second derivative r''), so with the
    /// deeper end at least 4 bend + slack inside, every point but the end on the surface
    /// is inside.
    pub fn starts_inside(&self, f0: f64, f1: f64, slack: f64) -> bool {
        f0 <= 0.0 && f1 <= 0.0 && f0.min(f1) + 4.0 * self.bend(self.h) + slack < 0.0
    }

    /// For a step whose both ends are inside (`f <= 0`): the parameter where its cubic
    /// goes farthest outside (`f > 0`) if it leaves and comes back between the ends (a
    /// turning point just past a face, a grazing orbit), else `None`. Scans
    /// [`HERMITE_SCAN`] points, then maximises `f` by golden section around the largest.
    ///
    /// `f` is the signed distance of a convex set (the bounds): convex along a line and
    /// 1-Lipschitz, so between two points of the cubic `len` apart it is at most the
    /// larger of its two values plus [`Self::bend`]`(len)`. The search stops with `None`
    /// as soon as that proves the segment (or the bracket still searched) inside by
    /// `slack`: where the full search would have found nothing, without its 8 + 40
    /// evaluations (a ray running along the surface needs none; the GPU twin, whose loop
    /// iterations lavapipe caps per invocation, runs the same test).
    ///
    /// A step that starts (or ends) on the surface, as the first step after entering
    /// does, is proven inside by [`Self::starts_inside`] instead: the bound above is
    /// then never below the end on the surface.
    pub fn excursion(&self, f: impl Fn(DVec3) -> f64, slack: f64) -> Option<f64> {
        if self.h <= 0.0 {
            return None;
        }
        let proven_inside = |fmax: f64, len: f64| fmax + self.bend(len) + slack < 0.0;
        let (f0, f1) = (f(self.r0), f(self.r1));
        if proven_inside(f0.max(f1), self.h) || self.starts_inside(f0, f1, slack) {
            return None;
        }
        let n = HERMITE_SCAN;
        let at = |k: u32| self.h * f64::from(k) / f64::from(n);
        let (mut best_k, mut best_v) = (0, f64::NEG_INFINITY);
        for k in 1..n {
            let v = f(self.point(at(k)));
            if v > 0.0 {
                return Some(at(k));
            }
            if v > best_v {
                (best_k, best_v) = (k, v);
            }
        }
        if proven_inside(best_v.max(f0).max(f1), at(1)) {
            return None;
        }
        let (mut a, mut b) = (at(best_k.saturating_sub(1)), at((best_k + 1).min(n)));
        const INV_PHI: f64 = 0.618_033_988_749_895;
        let mut c = b - (b - a) * INV_PHI;
        let mut d = a + (b - a) * INV_PHI;
        let (mut fa, mut fb) = (f(self.point(a)), f(self.point(b)));
        let (mut fc, mut fd) = (f(self.point(c)), f(self.point(d)));
        for _ in 0..EXCURSION_ITERATIONS {
            if fc > 0.0 {
                return Some(c);
            }
            if fd > 0.0 {
                return Some(d);
            }
            if proven_inside(fa.max(fb).max(fc).max(fd), b - a) {
                return None;
            }
            if fc > fd {
                (b, fb) = (d, fd);
                (d, fd) = (c, fc);
                c = b - (b - a) * INV_PHI;
                fc = f(self.point(c));
            } else {
                (a, fa) = (c, fc);
                (c, fc) = (d, fd);
                d = a + (b - a) * INV_PHI;
                fd = f(self.point(d));
            }
        }
        None
    }
}

/// Bisection cap: 2^-64 of a step is far below f64 resolution of its end points.
pub const MAX_BISECTIONS: u32 = 64;

/// Exit tolerance of the bisection method, as a fraction of the bounds' radius: |signed
/// distance| of the exit point to the surface. 1e-14 R is ~45 ulp of the coordinates in
/// f64, a Newton re-step or two more than 1e-12 R, and takes the exit point off the error
/// floor: at 1e-12 R it left exit directions ~1e-12 rad off on the fish-eye (a curved ray
/// ends 1e-12 R early or late), which hid two halvings of the step from the order fits of
/// `grin bench accuracy`.
pub const EXIT_TOL_REL: f64 = 1e-14;
/// ... and at least this many units of the precision's roundoff times the largest
/// coordinate of the bounds: in f32 a point on the surface is known to no better, so an
/// exit search held to 1e-12 R only spends re-steps that cannot move the point (the GPU
/// stage tests found the CPU's f32 path taking 2 Newton re-steps more per exit than the
/// kernel, which computes the distance in f32 and stops when it rounds to 0).
pub const EXIT_TOL_EPS: f64 = 4.0;

/// The exit search's tolerance (|signed distance| of the exit point) in precision `R`.
pub fn exit_tolerance<R: Real>(bounds: &Bounds) -> f64 {
    let coordinates = match *bounds {
        Bounds::Sphere { center, radius } => center.abs().max_element() + radius,
        Bounds::Box { min, max } => min.abs().max(max.abs()).max_element(),
    };
    (EXIT_TOL_REL * bounds.radius()).max(EXIT_TOL_EPS * R::EPS.to_f64() * coordinates)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The arc of a circle about `center` of radius `rho` from angle `a0` to `a0 + phi`,
    /// as the Hermite segment of a step (unit speed: h = rho phi).
    fn arc(center: DVec3, rho: f64, a0: f64, phi: f64) -> Segment {
        let p = |a: f64| center + rho * DVec3::new(a.cos(), a.sin(), 0.0);
        let t = |a: f64| DVec3::new(-a.sin(), a.cos(), 0.0);
        Segment {
            r0: p(a0),
            t0: t(a0),
            r1: p(a0 + phi),
            t1: t(a0 + phi),
            h: rho * phi,
        }
    }

    /// The unit sphere and the excursion search's slack on it.
    fn unit_sphere() -> (Bounds, f64) {
        let sphere = Bounds::Sphere {
            center: DVec3::ZERO,
            radius: 1.0,
        };
        (
            sphere,
            EXCURSION_SLACK_TOLS * exit_tolerance::<f64>(&sphere),
        )
    }

    /// For a segment with both ends inside, the full excursion search's result, checked
    /// to be the search's with its early stops; `None` where an end is outside.
    fn full_search_agrees(
        seg: &Segment,
        sd: impl Fn(DVec3) -> f64 + Copy,
        slack: f64,
    ) -> Option<Option<f64>> {
        if sd(seg.r0) > 0.0 || sd(seg.r1) > 0.0 {
            return None;
        }
        let full = seg.excursion(sd, f64::INFINITY);
        assert_eq!(seg.excursion(sd, slack), full, "{seg:?}");
        Some(full)
    }

    /// The search's early stop gives the full search's answer: over arcs that bulge out
    /// of a unit sphere by -0.02 .. 0.02 R between ends inside it, and straight chords,
    /// the result with the stop equals the one with it disabled (infinite slack); a step
    /// running along the surface 1e-4 inside costs 2 distance evaluations, not 50.
    #[test]
    fn the_excursion_search_stops_early_only_where_it_would_find_nothing() {
        let (sphere, slack) = unit_sphere();
        let sd = |p: DVec3| sphere.signed_distance(p);
        let mut compared = 0;
        let mut found = 0;
        for i in 0..400 {
            let x = f64::from(i) / 400.0;
            let bulge = -0.02 + 0.04 * x;
            let rho = 0.3 + 0.4 * (x * 37.0).fract();
            let phi = 0.2 + 1.2 * (x * 11.0).fract();
            let center = DVec3::new(1.0 + bulge - rho, 0.0, 0.0);
            let bent = arc(center, rho, -0.5 * phi, phi);
            let h = bent.h;
            let chord = Segment {
                r0: DVec3::new(0.99 - 0.1 * x, -0.5 * h, 0.0),
                t0: DVec3::Y,
                r1: DVec3::new(0.99 - 0.1 * x, 0.5 * h, 0.0),
                t1: DVec3::Y,
                h,
            };
            for seg in [chord, bent] {
                let Some(full) = full_search_agrees(&seg, sd, slack) else {
                    continue;
                };
                compared += 1;
                found += usize::from(full.is_some());
            }
        }
        assert!(
            compared > 400 && found > 50 && found < compared - 300,
            "{compared} compared, {found} found"
        );

        let calls = std::cell::Cell::new(0);
        let counted = |p: DVec3| {
            calls.set(calls.get() + 1);
            sd(p)
        };
        let along = arc(DVec3::ZERO, 1.0 - 1e-4, 0.0, 0.01);
        assert_eq!(along.excursion(counted, slack), None);
        assert_eq!(calls.get(), 2);
        calls.set(0);
        assert_eq!(along.excursion(counted, f64::INFINITY), None);
        assert!(calls.get() > 40, "{} evaluations", calls.get());
    }

    /// A step that starts on the surface heading in (the first step after entering) is
    /// proven inside at once by the chord and its bend (2 distance evaluations, not the
    /// full search's ~50), and the proof never hides an excursion: over arcs that start
    /// on a unit sphere and bulge out of it by up to 0.02 R or stay inside, the search
    /// with the proof finds what the full search finds.
    #[test]
    fn a_step_from_the_surface_inwards_is_proven_inside_at_once() {
        let (sphere, slack) = unit_sphere();
        let sd = |p: DVec3| sphere.signed_distance(p);
        let calls = std::cell::Cell::new(0);
        let counted = |p: DVec3| {
            calls.set(calls.get() + 1);
            sd(p)
        };
        // Straight in along -x from the surface point (1, 0, 0).
        let inwards = Segment {
            r0: DVec3::new(1.0, 0.0, 0.0),
            t0: DVec3::new(-1.0, 0.001, 0.0),
            r1: DVec3::new(0.7, 0.0003, 0.0),
            t1: DVec3::new(-1.0, 0.001, 0.0),
            h: 0.3,
        };
        assert!(sd(inwards.r0).abs() < 1e-15 && sd(inwards.r1) < -0.2);
        assert!(inwards.starts_inside(sd(inwards.r0), sd(inwards.r1), slack));
        assert_eq!(inwards.excursion(counted, slack), None);
        assert_eq!(calls.get(), 2);
        calls.set(0);
        assert_eq!(inwards.excursion(counted, f64::INFINITY), None);
        assert!(calls.get() > 40, "{} evaluations", calls.get());

        // Arcs of radius rho tangent to (or crossing) the sphere near their start.
        let (mut compared, mut found, mut proven) = (0, 0, 0);
        for i in 0..400 {
            let x = f64::from(i) / 400.0;
            let rho = 0.2 + 0.6 * (x * 37.0).fract();
            let phi = 0.1 + 1.0 * (x * 11.0).fract();
            let tilt = -0.3 + 0.6 * (x * 7.0).fract();
            // An arc starting at (1, 0, 0) on the surface, its centre inside.
            let start = DVec3::X;
            let center = start - rho * DVec3::new(tilt.cos(), tilt.sin(), 0.0);
            let a0 = tilt;
            let seg = arc(center, rho, a0, phi);
            let seg = Segment { r0: start, ..seg };
            let Some(full) = full_search_agrees(&seg, sd, slack) else {
                continue;
            };
            compared += 1;
            found += usize::from(full.is_some());
            proven += usize::from(seg.starts_inside(sd(seg.r0), sd(seg.r1), slack));
        }
        assert!(
            compared > 200 && found > 20 && proven > 50,
            "{compared} compared, {found} found, {proven} proven at once"
        );
    }

    /// The exit search ends at a point that reads exactly on the surface instead of
    /// halving the rest of the bracket (a chord across a face: the secant lands on the
    /// face): a handful of distance evaluations, the crossing to 1e-15.
    #[test]
    fn the_exit_search_stops_on_the_surface() {
        let slab = Bounds::Box {
            min: DVec3::new(-2.0, -2.0, 0.0),
            max: DVec3::new(2.0, 2.0, 10.0),
        };
        for z0 in [9.8123, 9.9317, 9.7071, 9.6001] {
            let (tz, h) = (1.6, 0.4 / 1.6);
            let seg = Segment {
                r0: DVec3::new(0.3, 0.1, z0),
                t0: DVec3::new(0.01, 0.02, tz),
                r1: DVec3::new(0.3025, 0.105, z0 + 0.4),
                t1: DVec3::new(0.01, 0.02, tz),
                h,
            };
            let calls = std::cell::Cell::new(0);
            let tau = seg.first_crossing(|p| {
                calls.set(calls.get() + 1);
                slab.signed_distance(p)
            });
            let exact = (10.0 - z0) / tz;
            assert!((tau - exact).abs() < 1e-15, "z0 {z0}: {tau} vs {exact}");
            assert!(calls.get() <= 12, "z0 {z0}: {} evaluations", calls.get());
        }
    }

    #[test]
    fn refraction_uncertainty_grows_as_tan_theta_and_is_unsure_near_critical() {
        let nrm = DVec3::Z;
        let at = |deg: f64| DVec3::new(deg.to_radians().sin(), 0.0, -deg.to_radians().cos());
        // Index matched (1 -> 1.0001), dn = 1e-4: normal incidence adds nothing, 60 deg
        // adds dn tan 60, 89.2 deg (impact 0.9999 R) ~70 dn.
        assert_eq!(
            refraction_uncertainty(at(0.0), nrm, 1.0, 1.0001, 1.0001, 1e-4),
            0.0
        );
        let e60 = refraction_uncertainty(at(60.0), nrm, 1.0, 1.0001, 1.0001, 1e-4);
        assert!(
            (e60 / (1e-4 * 60f64.to_radians().tan()) - 1.0).abs() < 1e-3,
            "{e60}"
        );
        let e89 = refraction_uncertainty(at(89.2), nrm, 1.0, 1.0001, 1.0001, 1e-4);
        assert!(e89 > 3e-3 && e89.is_finite(), "{e89}");
        // Within dn of total reflection the outcome itself is uncertain.
        let c = refraction_uncertainty(at(89.9), nrm, 1.0001, 1.0, 1.0001, 1e-4);
        assert!(c.is_infinite());
        // No uncertainty, nothing added.
        assert_eq!(
            refraction_uncertainty(at(89.9), nrm, 1.0, 1.0001, 1.0001, 0.0),
            0.0
        );
    }
}
