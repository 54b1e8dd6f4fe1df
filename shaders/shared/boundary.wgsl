// The medium's surface: the exit tolerance, Snell refraction with the Fresnel weight and
// its uncertainty, the projection onto the bounds, and a step's cubic Hermite segment
// (where it first crosses out; where it dips outside between two ends inside).
// CPU twin: grin_trace::boundary (exit_tolerance, refraction_uncertainty, refract,
// project_to_surface, Segment::{point, first_crossing, bend, excursion}).

// boundary::MAX_BISECTIONS, HERMITE_SCAN.
const MAX_BISECTIONS: u32 = 64u;
const HERMITE_SCAN: u32 = 8u;
// boundary::EXIT_TOL_REL (unreachable in f32: the bisection stops when the step
// fraction runs out of bits, then projects onto the surface, as the CPU's f32 path does).
const EXIT_TOL_REL: f32 = 1e-14;
const F32_EPSILON: f32 = 1.1920929e-7;
// boundary::EXIT_TOL_EPS: the tolerance is at least this much roundoff times the
// bounds' largest coordinate.
const EXIT_TOL_EPS: f32 = 4.0;

// boundary::exit_tolerance in f32.
fn exit_tolerance() -> f32 {
    var coordinates = max_element(abs(params.bounds_center)) + params.bounds_radius;
    if bounds_is_box() {
        coordinates = max_element(max(abs(params.box_min), abs(params.box_max)));
    }
    return max(EXIT_TOL_REL * bounds_radius(), EXIT_TOL_EPS * F32_EPSILON * coordinates);
}

// boundary::refraction_uncertainty: the direction error a refraction at the bounds adds
// when the field's n is uncertain by dn (amplified by tan of the refracted angle);
// UNSURE_ESTIMATE where dn could turn transmission into total reflection or back.
fn refraction_uncertainty(d: vec3<f32>, normal: vec3<f32>, n1: f32, n2: f32, n_field: f32, dn: f32) -> f32 {
    if !(dn > 0.0) {
        return 0.0;
    }
    let cos_i = min(abs(dot(d, normal)), 1.0);
    let eta = n1 / n2;
    let sin2_t = eta * eta * (1.0 - cos_i * cos_i);
    if abs(1.0 - sin2_t) <= 2.0 * sin2_t * dn / n_field {
        return UNSURE_ESTIMATE;
    }
    if sin2_t >= 1.0 {
        return 0.0;
    }
    return dn * sqrt(sin2_t / (1.0 - sin2_t)) / n_field;
}

// Snell's law at a surface with unit normal (either orientation), from n1 into n2.
struct Interface {
    transmitted: bool,
    dir: vec3<f32>,
    reflectance: f32,
}

fn fresnel(n1: f32, n2: f32, cos_i: f32, cos_t: f32) -> f32 {
    let rs = (n1 * cos_i - n2 * cos_t) / (n1 * cos_i + n2 * cos_t);
    let rp = (n1 * cos_t - n2 * cos_i) / (n1 * cos_t + n2 * cos_i);
    return 0.5 * (rs * rs + rp * rp);
}

fn refract(d: vec3<f32>, normal: vec3<f32>, n1: f32, n2: f32) -> Interface {
    let nrm = select(normal, -normal, dot(d, normal) > 0.0);
    let cos_i = clamp(-dot(d, nrm), 0.0, 1.0);
    let eta = n1 / n2;
    let sin2_t = eta * eta * (1.0 - cos_i * cos_i);
    if sin2_t >= 1.0 {
        return Interface(false, reflect_dir(d, nrm), 1.0);
    }
    let cos_t = sqrt(1.0 - sin2_t);
    let dir = normalize(d * eta + nrm * (eta * cos_i - cos_t));
    return Interface(true, dir, fresnel(n1, n2, cos_i, cos_t));
}

fn project_to_surface(p: vec3<f32>) -> vec3<f32> {
    if bounds_is_box() {
        let bmin = params.box_min;
        let bmax = params.box_max;
        let normal = bounds_normal(p);
        var q = clamp(p, bmin, bmax);
        for (var axis = 0; axis < 3; axis++) {
            if normal[axis] > 0.0 {
                q[axis] = bmax[axis];
            } else if normal[axis] < 0.0 {
                q[axis] = bmin[axis];
            }
        }
        return q;
    }
    let c = params.bounds_center;
    let d = p - c;
    let len = length(d);
    if len > 0.0 {
        return c + d * (params.bounds_radius / len);
    }
    return p;
}

// Cubic Hermite dense output of one step over t in [0, h].
struct Segment {
    r0: vec3<f32>,
    t0: vec3<f32>,
    r1: vec3<f32>,
    t1: vec3<f32>,
    h: f32,
}

fn segment_point(seg: Segment, tau: f32) -> vec3<f32> {
    if seg.h == 0.0 {
        return seg.r0;
    }
    let u = tau / seg.h;
    let u2 = u * u;
    let u3 = u2 * u;
    let h00 = 2.0 * u3 - 3.0 * u2 + 1.0;
    let h10 = u3 - 2.0 * u2 + u;
    let h01 = -2.0 * u3 + 3.0 * u2;
    let h11 = u3 - u2;
    return seg.r0 * h00 + seg.t0 * (h10 * seg.h) + seg.r1 * h01 + seg.t1 * (h11 * seg.h);
}

// Smallest tau in [0, h] where the dense output crosses out of the bounds: an
// 8-point scan, then the Illinois method on the bracket until it is one ulp wide or a
// point reads exactly on the surface (bisection when the start reads outside, after
// total reflection).
fn first_crossing(seg: Segment) -> f32 {
    var lo = 0.0;
    var f_lo = 0.0;
    var hi = seg.h;
    var f_hi = 0.0;
    var found = false;
    for (var k = 1u; k <= HERMITE_SCAN; k++) {
        let tau = seg.h * f32(k) / f32(HERMITE_SCAN);
        let v = bounds_signed_distance(segment_point(seg, tau));
        if v > 0.0 {
            hi = tau;
            f_hi = v;
            found = true;
            break;
        }
        lo = tau;
        f_lo = v;
    }
    if lo == 0.0 {
        f_lo = bounds_signed_distance(seg.r0);
    }
    let secant = found && f_lo <= 0.0 && f_hi > 0.0;
    var stuck = 0;
    for (var i = 0u; i < MAX_BISECTIONS; i++) {
        let mid = 0.5 * (lo + hi);
        var m = mid;
        if secant {
            m = hi - f_hi * (hi - lo) / (f_hi - f_lo);
            if !(m > lo && m < hi) {
                m = mid;
            }
        }
        if m <= lo || m >= hi {
            break;
        }
        let v = bounds_signed_distance(segment_point(seg, m));
        if v == 0.0 {
            // On the surface (Segment::first_crossing).
            return m;
        }
        if v > 0.0 {
            hi = m;
            f_hi = v;
            if stuck > 0 {
                f_lo *= 0.5;
            }
            stuck = 1;
        } else {
            lo = m;
            f_lo = v;
            if stuck < 0 {
                f_hi *= 0.5;
            }
            stuck = -1;
        }
    }
    return 0.5 * (lo + hi);
}

// boundary::EXCURSION_ITERATIONS, EXCURSION_SLACK_TOLS.
const EXCURSION_ITERATIONS: u32 = 40u;
const EXCURSION_SLACK_TOLS: f32 = 8.0;
const INV_PHI: f32 = 0.618034;

struct Excursion {
    found: bool,
    tau: f32,
}

// Segment::bend: how far the cubic can bend off the chord between two of its points
// len apart, M len^2 / 8 with M = max |r''| (linear in t: its larger end value).
fn segment_bend(seg: Segment, len: f32) -> f32 {
    if !(seg.h > 0.0) {
        return 0.0;
    }
    let d = seg.r1 - seg.r0;
    let a0 = length(6.0 * d - 4.0 * seg.h * seg.t0 - 2.0 * seg.h * seg.t1);
    let a1 = length(-6.0 * d + 2.0 * seg.h * seg.t0 + 4.0 * seg.h * seg.t1);
    let u = len / seg.h;
    return max(a0, a1) / 8.0 * u * u;
}

// For a step whose ends are both inside: where its dense output goes farthest outside,
// if it leaves and comes back between them (Segment::excursion): a scan, then golden
// section around the largest sample; either stops with "none" once the samples and the
// cubic's bend prove the segment (or the bracket) inside by `slack` (the bounds' signed
// distance is convex and 1-Lipschitz). A ray running along the surface then spends no
// loop iterations here: lavapipe caps them per invocation.
fn segment_excursion(seg: Segment, slack: f32) -> Excursion {
    if !(seg.h > 0.0) {
        return Excursion(false, 0.0);
    }
    let f0 = bounds_signed_distance(seg.r0);
    let f1 = bounds_signed_distance(seg.r1);
    let bend = segment_bend(seg, seg.h);
    if max(f0, f1) + bend + slack < 0.0 {
        return Excursion(false, 0.0);
    }
    // Segment::starts_inside: an end on the surface, the other deep inside.
    if f0 <= 0.0 && f1 <= 0.0 && min(f0, f1) + 4.0 * bend + slack < 0.0 {
        return Excursion(false, 0.0);
    }
    var best_k = 1u;
    var best_v = -INF;
    for (var k = 1u; k < HERMITE_SCAN; k++) {
        let tau = seg.h * f32(k) / f32(HERMITE_SCAN);
        let v = bounds_signed_distance(segment_point(seg, tau));
        if v > 0.0 {
            return Excursion(true, tau);
        }
        if v > best_v {
            best_k = k;
            best_v = v;
        }
    }
    if max(best_v, max(f0, f1)) + segment_bend(seg, seg.h / f32(HERMITE_SCAN)) + slack < 0.0 {
        return Excursion(false, 0.0);
    }
    var a = seg.h * f32(best_k - 1u) / f32(HERMITE_SCAN);
    var b = seg.h * f32(min(best_k + 1u, HERMITE_SCAN)) / f32(HERMITE_SCAN);
    var c = b - (b - a) * INV_PHI;
    var d = a + (b - a) * INV_PHI;
    var fa = bounds_signed_distance(segment_point(seg, a));
    var fb = bounds_signed_distance(segment_point(seg, b));
    var fc = bounds_signed_distance(segment_point(seg, c));
    var fd = bounds_signed_distance(segment_point(seg, d));
    for (var i = 0u; i < EXCURSION_ITERATIONS; i++) {
        if fc > 0.0 {
            return Excursion(true, c);
        }
        if fd > 0.0 {
            return Excursion(true, d);
        }
        if max(max(fa, fb), max(fc, fd)) + segment_bend(seg, b - a) + slack < 0.0 {
            return Excursion(false, 0.0);
        }
        if fc > fd {
            b = d;
            fb = fd;
            d = c;
            fd = fc;
            c = b - (b - a) * INV_PHI;
            fc = bounds_signed_distance(segment_point(seg, c));
        } else {
            a = c;
            fa = fc;
            c = d;
            fc = fd;
            d = a + (b - a) * INV_PHI;
            fd = bounds_signed_distance(segment_point(seg, d));
        }
    }
    return Excursion(false, 0.0);
}
