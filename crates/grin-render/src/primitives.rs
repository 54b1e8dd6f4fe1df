//! Ray-primitive intersection for scene objects: spheres, planes, boxes.
//! Keep in sync with shaders' `intersect_sphere` / `intersect_plane` / `intersect_box`.

use glam::DVec3;

/// A primitive in world space.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Primitive {
    Sphere {
        center: DVec3,
        radius: f64,
    },
    /// Plane through `point` with unit `normal`.
    Plane {
        point: DVec3,
        normal: DVec3,
    },
    Box {
        min: DVec3,
        max: DVec3,
    },
}

/// The nearest intersection of a ray with a primitive or the scene.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Ray parameter (world length along a unit direction).
    pub t: f64,
    pub point: DVec3,
    /// Unit normal facing against the ray.
    pub normal: DVec3,
    /// True if the ray hit the outside of the surface (geometric normal opposes it).
    pub front_face: bool,
    /// Index of the object in the scene.
    pub object: usize,
}

impl Primitive {
    pub fn from_shape(shape: &grin_scene::Shape) -> Self {
        match *shape {
            grin_scene::Shape::Sphere { center, radius } => Primitive::Sphere {
                center: DVec3::from_array(center),
                radius,
            },
            grin_scene::Shape::Plane { point, normal } => Primitive::Plane {
                point: DVec3::from_array(point),
                normal: DVec3::from_array(normal)
                    .try_normalize()
                    .unwrap_or(DVec3::Y),
            },
            grin_scene::Shape::Box { min, max } => Primitive::Box {
                min: DVec3::from_array(min),
                max: DVec3::from_array(max),
            },
        }
    }

    /// Whether the surface can pass within `radius` of `centre` (conservative: a false
    /// answer means no point of the surface lies in that ball). The GPU lists the objects
    /// a chord inside the medium can meet with it.
    pub fn may_meet_ball(&self, centre: DVec3, radius: f64) -> bool {
        match *self {
            Primitive::Sphere { center, radius: r } => {
                let d = center.distance(centre);
                d <= r + radius && d >= r - radius
            }
            Primitive::Plane { point, normal } => (centre - point).dot(normal).abs() <= radius,
            Primitive::Box { min, max } => {
                let nearest = centre.clamp(min, max);
                nearest.distance(centre) <= radius
            }
        }
    }

    /// Nearest hit of `o + t d` (unit `d`) with t in (t_min, t_max): (t, outward normal).
    pub fn intersect(&self, o: DVec3, d: DVec3, t_min: f64, t_max: f64) -> Option<(f64, DVec3)> {
        match *self {
            Primitive::Sphere { center, radius } => {
                intersect_sphere(center, radius, o, d, t_min, t_max)
            }
            Primitive::Plane { point, normal } => {
                intersect_plane(point, normal, o, d, t_min, t_max)
            }
            Primitive::Box { min, max } => intersect_box(min, max, o, d, t_min, t_max),
        }
    }
}

/// Sphere: roots of |o + t d - c|^2 = r^2 (unit d), nearest inside (t_min, t_max).
pub fn intersect_sphere(
    c: DVec3,
    r: f64,
    o: DVec3,
    d: DVec3,
    t_min: f64,
    t_max: f64,
) -> Option<(f64, DVec3)> {
    let oc = o - c;
    let b = oc.dot(d);
    let cc = oc.length_squared() - r * r;
    // b^2 - cc from the offset perpendicular to the (unit) ray: no cancellation for far
    // rays (Ray Tracing Gems, ch. 7); roots in the stable q form.
    let perp = oc - d * b;
    let disc = r * r - perp.length_squared();
    if disc < 0.0 {
        return None;
    }
    let sq = disc.sqrt();
    let q = -b - if b >= 0.0 { sq } else { -sq };
    let (t0, t1) = if q == 0.0 {
        (0.0, 0.0)
    } else {
        let (x, y) = (q, cc / q);
        (x.min(y), x.max(y))
    };
    let t = if t0 > t_min && t0 < t_max {
        t0
    } else if t1 > t_min && t1 < t_max {
        t1
    } else {
        return None;
    };
    Some((t, (o + d * t - c) / r))
}

/// Plane through `p` with unit normal `n`; the outward normal is `n` itself.
pub fn intersect_plane(
    p: DVec3,
    n: DVec3,
    o: DVec3,
    d: DVec3,
    t_min: f64,
    t_max: f64,
) -> Option<(f64, DVec3)> {
    let denom = n.dot(d);
    if denom.abs() < 1e-12 {
        return None;
    }
    let t = (p - o).dot(n) / denom;
    (t > t_min && t < t_max).then_some((t, n))
}

/// Axis-aligned box by slabs; the normal is the axis of the face hit.
pub fn intersect_box(
    min: DVec3,
    max: DVec3,
    o: DVec3,
    d: DVec3,
    t_min: f64,
    t_max: f64,
) -> Option<(f64, DVec3)> {
    let inv = d.recip();
    let a = (min - o) * inv;
    let b = (max - o) * inv;
    let near = a.min(b);
    let far = a.max(b);
    let t_near = near.max_element();
    let t_far = far.min_element();
    if t_near > t_far {
        return None;
    }
    let (t, slab) = if t_near > t_min && t_near < t_max {
        (t_near, near)
    } else if t_far > t_min && t_far < t_max {
        (t_far, far)
    } else {
        return None;
    };
    // The face hit is the slab whose bound equals t.
    let axis = if slab.x == t {
        0
    } else if slab.y == t {
        1
    } else {
        2
    };
    let mut normal = DVec3::ZERO;
    let centre = (min + max) * 0.5;
    normal[axis] = (o[axis] + d[axis] * t - centre[axis]).signum();
    Some((t, normal))
}

/// Nearest hit among `objects` along `o + t d`, t in (t_min, t_max).
pub fn intersect_scene(
    objects: &[Primitive],
    o: DVec3,
    d: DVec3,
    t_min: f64,
    t_max: f64,
) -> Option<Hit> {
    let mut best: Option<(f64, DVec3, usize)> = None;
    let mut t_best = t_max;
    for (i, prim) in objects.iter().enumerate() {
        if let Some((t, n)) = prim.intersect(o, d, t_min, t_best) {
            t_best = t;
            best = Some((t, n, i));
        }
    }
    best.map(|(t, outward, object)| {
        let front_face = outward.dot(d) < 0.0;
        Hit {
            t,
            point: o + d * t,
            normal: if front_face { outward } else { -outward },
            front_face,
            object,
        }
    })
}

/// True if anything in `objects` blocks `o + t d` for t in (t_min, t_max).
pub fn occluded(objects: &[Primitive], o: DVec3, d: DVec3, t_min: f64, t_max: f64) -> bool {
    objects
        .iter()
        .any(|p| p.intersect(o, d, t_min, t_max).is_some())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn may_meet_ball_is_true_exactly_when_the_surface_reaches_in() {
        let c = DVec3::new(1.0, 2.0, 3.0);
        let sphere = |center: DVec3, radius| Primitive::Sphere { center, radius };
        // A sphere meets the ball unless it lies wholly outside it or wholly around it.
        assert!(sphere(c + DVec3::X * 1.4, 0.5).may_meet_ball(c, 1.0));
        assert!(!sphere(c + DVec3::X * 1.6, 0.5).may_meet_ball(c, 1.0));
        assert!(!sphere(c, 3.0).may_meet_ball(c, 1.0));
        assert!(sphere(c, 0.2).may_meet_ball(c, 1.0));
        let plane = |y: f64| Primitive::Plane {
            point: DVec3::new(0.0, y, 0.0),
            normal: DVec3::Y,
        };
        assert!(plane(2.9).may_meet_ball(c, 1.0));
        assert!(plane(1.0).may_meet_ball(c, 1.0));
        assert!(!plane(0.9).may_meet_ball(c, 1.0));
        let cube = |lo: DVec3| Primitive::Box {
            min: lo,
            max: lo + DVec3::ONE,
        };
        assert!(cube(c + DVec3::splat(0.5)).may_meet_ball(c, 1.0));
        // Corner at distance sqrt(3) * 0.7 = 1.21 > 1.
        assert!(!cube(c + DVec3::splat(0.7)).may_meet_ball(c, 1.0));
    }

    #[test]
    fn sphere_hit_from_outside_and_inside() {
        let (t, n) = intersect_sphere(
            DVec3::ZERO,
            1.0,
            DVec3::new(0.0, 0.0, -3.0),
            DVec3::Z,
            1e-6,
            f64::INFINITY,
        )
        .expect("hit");
        assert!((t - 2.0).abs() < 1e-12);
        assert!((n + DVec3::Z).length() < 1e-12);
        let (t, n) = intersect_sphere(DVec3::ZERO, 1.0, DVec3::ZERO, DVec3::X, 1e-6, f64::INFINITY)
            .expect("hit");
        assert!((t - 1.0).abs() < 1e-12 && (n - DVec3::X).length() < 1e-12);
    }

    #[test]
    fn plane_and_box() {
        let (t, _) = intersect_plane(
            DVec3::ZERO,
            DVec3::Y,
            DVec3::new(0.0, 2.0, 0.0),
            -DVec3::Y,
            1e-6,
            10.0,
        )
        .expect("hit");
        assert!((t - 2.0).abs() < 1e-12);
        assert!(intersect_plane(DVec3::ZERO, DVec3::Y, DVec3::Y, DVec3::X, 1e-6, 10.0).is_none());
        let d = DVec3::new(1.0, 0.5, 0.0).normalize();
        let (t, n) = intersect_box(
            DVec3::splat(-1.0),
            DVec3::splat(1.0),
            DVec3::new(-3.0, 0.0, 0.0),
            d,
            1e-6,
            10.0,
        )
        .expect("hit");
        assert!((n + DVec3::X).length() < 1e-12);
        assert!(((DVec3::new(-3.0, 0.0, 0.0) + d * t).x + 1.0).abs() < 1e-12);
    }

    #[test]
    fn scene_returns_nearest_and_faces_the_ray() {
        let objs = [
            Primitive::Sphere {
                center: DVec3::new(0.0, 0.0, 5.0),
                radius: 1.0,
            },
            Primitive::Sphere {
                center: DVec3::new(0.0, 0.0, 2.0),
                radius: 0.5,
            },
        ];
        let h = intersect_scene(&objs, DVec3::ZERO, DVec3::Z, 1e-6, f64::INFINITY).expect("hit");
        assert_eq!(h.object, 1);
        assert!((h.t - 1.5).abs() < 1e-12 && h.front_face);
        assert!(h.normal.dot(DVec3::Z) < 0.0);
        assert!(occluded(&objs, DVec3::ZERO, DVec3::Z, 1e-6, 1.6));
        assert!(!occluded(&objs, DVec3::ZERO, DVec3::Z, 1e-6, 1.4));
    }

    #[test]
    fn far_rays_hit_small_spheres() {
        let c = DVec3::new(0.3, 0.0, 0.0);
        for far in [1e3, 1e6, 1e8] {
            let o = DVec3::new(0.3, 0.005, -far);
            let (t, n) = intersect_sphere(c, 0.01, o, DVec3::Z, 0.0, f64::INFINITY)
                .expect("hit from far away");
            let want = far - (1e-4f64 - 0.005f64.powi(2)).sqrt();
            assert!(
                (t - want).abs() <= 1e-15 * far + 1e-12,
                "{far}: {t} vs {want}"
            );
            assert!(
                (n.length() - 1.0).abs() < 1e-6 * far.max(1.0).sqrt(),
                "{far}: {n}"
            );
        }
    }
}
