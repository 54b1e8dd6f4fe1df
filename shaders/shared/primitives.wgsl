// Ray-primitive intersection for scene objects and the medium bounds.
// CPU twins: grin_trace::render::primitives, grin_field::Bounds::{intersect, normal,
// signed_distance}.

struct PrimHit {
    found: bool,
    t: f32,
    outward: vec3<f32>,
}

struct Hit {
    found: bool,
    t: f32,
    point: vec3<f32>,
    normal: vec3<f32>,   // facing against the ray
    front_face: bool,
    object: u32,
}

fn no_prim_hit() -> PrimHit {
    return PrimHit(false, 0.0, vec3<f32>(0.0));
}

fn intersect_sphere(c: vec3<f32>, r: f32, o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32) -> PrimHit {
    let oc = o - c;
    let b = dot(oc, d);
    let cc = dot(oc, oc) - r * r;
    // Twin of intersect_sphere in primitives.rs: the perpendicular-offset discriminant
    // and the stable q form of the roots.
    let perp = oc - d * b;
    let disc = r * r - dot(perp, perp);
    if disc < 0.0 {
        return no_prim_hit();
    }
    let sq = sqrt(disc);
    let q = -b - select(-sq, sq, b >= 0.0);
    var t0 = 0.0;
    var t1 = 0.0;
    if q != 0.0 {
        t0 = min(q, cc / q);
        t1 = max(q, cc / q);
    }
    var t: f32;
    if t0 > t_min && t0 < t_max {
        t = t0;
    } else if t1 > t_min && t1 < t_max {
        t = t1;
    } else {
        return no_prim_hit();
    }
    return PrimHit(true, t, (o + d * t - c) / r);
}

fn intersect_plane(p: vec3<f32>, n: vec3<f32>, o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32) -> PrimHit {
    let denom = dot(n, d);
    if abs(denom) < 1e-12 {
        return no_prim_hit();
    }
    let t = dot(p - o, n) / denom;
    if t > t_min && t < t_max {
        return PrimHit(true, t, n);
    }
    return no_prim_hit();
}

fn max_element(v: vec3<f32>) -> f32 {
    return max(v.x, max(v.y, v.z));
}

fn min_element(v: vec3<f32>) -> f32 {
    return min(v.x, min(v.y, v.z));
}

fn intersect_box(bmin: vec3<f32>, bmax: vec3<f32>, o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32) -> PrimHit {
    let inv = 1.0 / d;
    let a = (bmin - o) * inv;
    let b = (bmax - o) * inv;
    let near = min(a, b);
    let far = max(a, b);
    let t_near = max_element(near);
    let t_far = min_element(far);
    if t_near > t_far {
        return no_prim_hit();
    }
    var t: f32;
    var slab: vec3<f32>;
    if t_near > t_min && t_near < t_max {
        t = t_near;
        slab = near;
    } else if t_far > t_min && t_far < t_max {
        t = t_far;
        slab = far;
    } else {
        return no_prim_hit();
    }
    var axis = 2u;
    if slab.x == t {
        axis = 0u;
    } else if slab.y == t {
        axis = 1u;
    }
    var normal = vec3<f32>(0.0);
    let centre = (bmin + bmax) * 0.5;
    normal[axis] = sign_nonzero(o[axis] + d[axis] * t - centre[axis]);
    return PrimHit(true, t, normal);
}

// Rust's f64::signum: +1 for +0.
fn sign_nonzero(x: f32) -> f32 {
    return select(-1.0, 1.0, x >= 0.0);
}

fn intersect_object(obj: GpuObject, o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32) -> PrimHit {
    switch obj.shape {
        case SHAPE_SPHERE: {
            return intersect_sphere(obj.a, obj.radius, o, d, t_min, t_max);
        }
        case SHAPE_PLANE: {
            return intersect_plane(obj.a, obj.b, o, d, t_min, t_max);
        }
        default: {
            return intersect_box(obj.a, obj.b, o, d, t_min, t_max);
        }
    }
}

// Nearest hit among the scene objects along o + t d, t in (t_min, t_max).
fn intersect_scene(o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32) -> Hit {
    return intersect_objects(0u, params.object_count, o, d, t_min, t_max);
}

// The nearest hit among objects[first .. first + count] (hit.object: the scene index).
fn intersect_objects(first: u32, count: u32, o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32) -> Hit {
    var best = Hit(false, 0.0, vec3<f32>(0.0), vec3<f32>(0.0), false, 0u);
    var t_best = t_max;
    var outward = vec3<f32>(0.0);
    for (var i = first; i < first + count; i++) {
        let obj = objects[i];
        let h = intersect_object(obj, o, d, t_min, t_best);
        if h.found {
            t_best = h.t;
            best.found = true;
            best.t = h.t;
            best.object = obj.scene_index;
            outward = h.outward;
        }
    }
    if best.found {
        best.front_face = dot(outward, d) < 0.0;
        best.point = o + d * best.t;
        best.normal = select(-outward, outward, best.front_face);
    }
    return best;
}

// ---- The medium's bounds (sphere or box) ----

fn bounds_is_box() -> bool {
    return BOUNDS_BOX;
}

fn bounds_signed_distance(p: vec3<f32>) -> f32 {
    if bounds_is_box() {
        let bmin = params.box_min;
        let bmax = params.box_max;
        let c = (bmin + bmax) * 0.5;
        let h = (bmax - bmin) * 0.5;
        let q = abs(p - c) - h;
        return length(max(q, vec3<f32>(0.0))) + min(max_element(q), 0.0);
    }
    return length(p - params.bounds_center) - params.bounds_radius;
}

fn bounds_contains(p: vec3<f32>) -> bool {
    return bounds_signed_distance(p) <= 0.0;
}

fn bounds_normal(p: vec3<f32>) -> vec3<f32> {
    if bounds_is_box() {
        let bmin = params.box_min;
        let bmax = params.box_max;
        let c = (bmin + bmax) * 0.5;
        let h = (bmax - bmin) * 0.5;
        let d = p - c;
        let q = abs(d) - h;
        var axis = 2u;
        if q.x >= q.y && q.x >= q.z {
            axis = 0u;
        } else if q.y >= q.z {
            axis = 1u;
        }
        var n = vec3<f32>(0.0);
        n[axis] = sign_nonzero(d[axis]);
        return n;
    }
    return normalize(p - params.bounds_center);
}

// (s_in, s_out) of o + s d inside a box; found if s_out >= max(s_in, 0).
struct Interval {
    found: bool,
    s_in: f32,
    s_out: f32,
}

fn box_interval(bmin: vec3<f32>, bmax: vec3<f32>, o: vec3<f32>, d: vec3<f32>) -> Interval {
    let inv = 1.0 / d;
    let t0 = (bmin - o) * inv;
    let t1 = (bmax - o) * inv;
    let s_in = max_element(min(t0, t1));
    let s_out = min_element(max(t0, t1));
    return Interval(s_out >= max(s_in, 0.0) && s_out < INF, s_in, s_out);
}

fn bounds_intersect(o: vec3<f32>, d: vec3<f32>) -> Interval {
    if bounds_is_box() {
        return box_interval(params.box_min, params.box_max, o, d);
    }
    let oc = o - params.bounds_center;
    let r = params.bounds_radius;
    let a = dot(d, d);
    if a == 0.0 {
        return Interval(false, 0.0, 0.0);
    }
    let b = dot(oc, d);
    let c = dot(oc, oc) - r * r;
    // Twin of Bounds::intersect: the perpendicular-offset discriminant.
    let perp = oc - d * (b / a);
    let disc = a * (r * r - dot(perp, perp));
    if disc < 0.0 {
        return Interval(false, 0.0, 0.0);
    }
    let sq = sqrt(disc);
    let q = -(b + sign_nonzero(b) * sq);
    var s0 = 0.0;
    var s1 = 0.0;
    if q != 0.0 {
        s0 = q / a;
        s1 = c / q;
    }
    if s0 > s1 {
        let tmp = s0;
        s0 = s1;
        s1 = tmp;
    }
    return Interval(s1 >= 0.0, s0, s1);
}
