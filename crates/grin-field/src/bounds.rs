//! Medium bounds: a sphere or an axis-aligned box, with ray intersection.

use glam::DVec3;

use crate::real::{Real, Vec3Like};
use grin_scene::BoundsSpec;

/// The region of space a medium occupies.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Bounds {
    Sphere { center: DVec3, radius: f64 },
    Box { min: DVec3, max: DVec3 },
}

impl Bounds {
    pub fn from_spec(spec: &BoundsSpec) -> Self {
        match *spec {
            BoundsSpec::Sphere { center, radius } => Bounds::Sphere {
                center: DVec3::from_array(center),
                radius,
            },
            BoundsSpec::Box { min, max } => Bounds::Box {
                min: DVec3::from_array(min),
                max: DVec3::from_array(max),
            },
        }
    }

    pub fn center(&self) -> DVec3 {
        match *self {
            Bounds::Sphere { center, .. } => center,
            Bounds::Box { min, max } => (min + max) * 0.5,
        }
    }

    /// Radius of a sphere, or half the smallest box extent: the length that profiles
    /// given "relative to the bounds" scale by.
    pub fn radius(&self) -> f64 {
        match *self {
            Bounds::Sphere { radius, .. } => radius,
            Bounds::Box { min, max } => ((max - min) * 0.5).min_element(),
        }
    }

    /// Whether the box [lo, hi] comes within `margin` of the bounds.
    pub fn meets_box(&self, lo: DVec3, hi: DVec3, margin: f64) -> bool {
        match *self {
            Bounds::Sphere { center, radius } => {
                center.clamp(lo, hi).distance(center) <= radius + margin
            }
            Bounds::Box { min, max } => {
                (lo - max).max_element() <= margin && (min - hi).max_element() <= margin
            }
        }
    }

    /// Axis-aligned box enclosing the bounds.
    pub fn aabb(&self) -> (DVec3, DVec3) {
        match *self {
            Bounds::Sphere { center, radius } => {
                (center - DVec3::splat(radius), center + DVec3::splat(radius))
            }
            Bounds::Box { min, max } => (min, max),
        }
    }

    /// Signed distance-like function: negative inside, zero on the surface, positive outside.
    /// Exact distance for the sphere; for the box, exact outside and the (negative) distance
    /// to the nearest face inside.
    #[inline]
    pub fn signed_distance(&self, p: DVec3) -> f64 {
        self.signed_distance_in::<f64>(p)
    }

    /// [`Self::signed_distance`] computed in precision `R`, as the GPU kernel computes it
    /// in f32 (`bounds_signed_distance`): the f32 trace's exit search then stops where
    /// the kernel's does.
    #[inline]
    pub fn signed_distance_in<R: Real>(&self, p: R::V3) -> f64 {
        match *self {
            Bounds::Sphere { center, radius } => {
                ((p - R::V3::from_dvec3(center)).length() - R::from_f64(radius)).to_f64()
            }
            Bounds::Box { min, max } => {
                let (lo, hi) = (R::V3::from_dvec3(min), R::V3::from_dvec3(max));
                let half = R::from_f64(0.5);
                let c = (lo + hi) * half;
                let h = (hi - lo) * half;
                let d = p - c;
                let q = [
                    d.x().abs() - h.x(),
                    d.y().abs() - h.y(),
                    d.z().abs() - h.z(),
                ];
                let zero = R::zero();
                let outside = R::V3::new(q[0].max(zero), q[1].max(zero), q[2].max(zero)).length();
                let inside = q[0].max(q[1]).max(q[2]).min(zero);
                (outside + inside).to_f64()
            }
        }
    }

    #[inline]
    pub fn contains(&self, p: DVec3) -> bool {
        self.signed_distance(p) <= 0.0
    }

    /// Outward unit normal of the surface nearest to `p`.
    #[inline]
    pub fn normal(&self, p: DVec3) -> DVec3 {
        match *self {
            Bounds::Sphere { center, .. } => (p - center).normalize(),
            Bounds::Box { min, max } => {
                let c = (min + max) * 0.5;
                let h = (max - min) * 0.5;
                let d = p - c;
                let q = d.abs() - h;
                let axis = if q.x >= q.y && q.x >= q.z {
                    0
                } else if q.y >= q.z {
                    1
                } else {
                    2
                };
                let mut n = DVec3::ZERO;
                n[axis] = d[axis].signum();
                n
            }
        }
    }

    /// Ray `o + s d` against the bounds: the parameter interval (s_in, s_out) inside, if
    /// the ray meets them at s_out >= 0. `d` need not be unit length; s is in units of |d|.
    pub fn intersect(&self, o: DVec3, d: DVec3) -> Option<(f64, f64)> {
        match *self {
            Bounds::Sphere { center, radius } => {
                let oc = o - center;
                let a = d.length_squared();
                if a == 0.0 {
                    return None;
                }
                let b = oc.dot(d);
                let c = oc.length_squared() - radius * radius;
                // b^2 - a c from the ray's offset perpendicular to d (Ray Tracing Gems,
                // ch. 7): the plain form cancels catastrophically for a ray from far away
                // (a ray from 1e8 missed a unit sphere it points at).
                let perp = oc - d * (b / a);
                let disc = a * (radius * radius - perp.length_squared());
                if disc < 0.0 {
                    return None;
                }
                let sq = disc.sqrt();
                // Numerically stable roots.
                let q = -(b + b.signum() * sq);
                let (mut s0, mut s1) = if q != 0.0 { (q / a, c / q) } else { (0.0, 0.0) };
                if s0 > s1 {
                    std::mem::swap(&mut s0, &mut s1);
                }
                (s1 >= 0.0).then_some((s0, s1))
            }
            Bounds::Box { min, max } => {
                let inv = d.recip();
                let t0 = (min - o) * inv;
                let t1 = (max - o) * inv;
                let s_in = t0.min(t1).max_element();
                let s_out = t0.max(t1).min_element();
                (s_out >= s_in.max(0.0) && s_out.is_finite()).then_some((s_in, s_out))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rays from far away still meet the sphere they point at, at the right distance
    /// (the plain b^2 - a c form lost all of the discriminant at 1e8).
    #[test]
    fn far_rays_meet_the_sphere() {
        let ball = Bounds::Sphere {
            center: DVec3::new(0.0, 0.5, 0.0),
            radius: 1.0,
        };
        for far in [1e4, 1e6, 1e8, 1e10] {
            for (y, d) in [(0.5, DVec3::Z), (1.2, DVec3::Z * 3.0)] {
                let o = DVec3::new(0.0, y, -far);
                let (s0, s1) = ball.intersect(o, d).expect("meets");
                let half = (1.0 - (y - 0.5f64).powi(2)).sqrt();
                let len = d.length();
                assert!(
                    ((s0 * len) - (far - half)).abs() <= 1e-15 * far + 1e-12,
                    "{far} {y}"
                );
                assert!(
                    ((s1 * len) - (far + half)).abs() <= 1e-15 * far + 1e-12,
                    "{far} {y}"
                );
            }
            assert!(
                ball.intersect(DVec3::new(0.0, 1.6, -far), DVec3::Z)
                    .is_none()
            );
        }
    }
}
