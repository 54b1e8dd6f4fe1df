// The path loop of one pixel sample: an explicit loop with a throughput, medium
// crossings, material events, direct light with shadow rays, and the primary ray's AOVs.
// CPU twin: grin_trace::render::shade (trace_path, scatter, shade_diffuse,
// shadow_transmittance) and grin_trace::render::RenderScene::render_pixel.

// Fraction of the sky's radiance along the normal added to diffuse surfaces
// (AMBIENT_SKY_WEIGHT).
const AMBIENT_SKY_WEIGHT: f32 = 0.2;
// Loop iterations per unit of max_depth (EVENTS_PER_DEPTH).
const EVENTS_PER_DEPTH: u32 = 3u;

const EVENT_SKY: u32 = 0u;
const EVENT_SURFACE: u32 = 1u;
const EVENT_MEDIUM: u32 = 2u;

struct PrimaryAov {
    deflection_deg: f32,
    exit_dir: vec3<f32>,
    opd: f32,
    steps: u32,
    evals: u32,
    status: u32,
    // Where the ray left the medium or stopped in it (the camera if it missed).
    exit_pos: vec3<f32>,
    // opd taken on to the plane through the straight exit, normal to the ray (CPU twin:
    // opd_tail; here summed from MarchStats' small parts).
    opd_plane: f32,
}

// In PASS_FIRST a path that reaches the medium stops and the pixel is traced again by
// PASS_MEDIUM (in rounds: render.wgsl); the march is compiled out of PASS_FIRST.
fn defer_medium() -> bool {
    return PASS == PASS_FIRST;
}

// Only PASS_MEDIUM runs in rounds (render.wgsl): the other passes' kernels leave out the
// code that suspends and resumes a path (lavapipe's compile time grows with it).
fn resumable() -> bool {
    return PASS == PASS_MEDIUM;
}

struct Event {
    kind: u32,
    hit: Hit,
    dir: vec3<f32>,
}

fn has_medium() -> bool {
    return (FLAGS & FLAG_HAS_MEDIUM) != 0u;
}

// Index of the space at p: the medium's n inside the bounds, else ambient. -1 inside
// the bounds in PASS_FIRST, which leaves such paths to PASS_MEDIUM.
fn index_at(p: vec3<f32>) -> f32 {
    if has_medium() {
        if bounds_contains(p) {
            if defer_medium() {
                return -1.0;
            }
            return sample_field(p).n;
        }
        return ambient_index();
    }
    return 1.0;
}

// Nearest event along a straight ray from o outside the medium.
fn next_event_outside(o: vec3<f32>, d: vec3<f32>) -> Event {
    var hit = no_hit();
    if (FLAGS & FLAG_HAS_OBJECTS) != 0u {
        hit = intersect_scene(o, d, SURFACE_EPS, INF);
    }
    if has_medium() {
        let b = bounds_intersect(o, d);
        if b.found && b.s_in > SURFACE_EPS && (!hit.found || b.s_in < hit.t) {
            return Event(EVENT_MEDIUM, hit, d);
        }
    }
    if hit.found {
        return Event(EVENT_SURFACE, hit, d);
    }
    return Event(EVENT_SKY, hit, d);
}

// Angle between two directions in degrees (atan2 form: accurate for tiny angles in f32).
fn angle_between_deg(a: vec3<f32>, b: vec3<f32>) -> f32 {
    return atan2(length(cross(a, b)), dot(a, b)) * (180.0 / PI);
}

// A pixel sample's path between loop passes: all a march split over dispatches keeps
// while the path waits for the next (render.wgsl's PixelCarryStored holds it there).
struct PathState {
    origin: vec3<f32>,
    dir: vec3<f32>,
    throughput: vec3<f32>,
    radiance: vec3<f32>,
    aov: PrimaryAov,
    primary: bool,
    inside: bool,
    bounces: u32,
    // The event loop's pass.
    event: u32,
    // In the middle of a march through the medium (`march`, `stats`, and the entry
    // direction and straight exit the AOVs are measured from).
    marching: bool,
    march: MarchCarry,
    stats: MarchStats,
    entry_dir: vec3<f32>,
    straight_exit: vec3<f32>,
}

// path_run's outcomes: the path is done, left to PASS_MEDIUM, or out of budget (its
// state kept in the PathState, to be run on).
const PATH_DONE: u32 = 0u;
const PATH_DEFERRED: u32 = 1u;
const PATH_SUSPENDED: u32 = 2u;

fn path_start(start: vec3<f32>, d: vec3<f32>) -> PathState {
    var p: PathState;
    p.origin = start;
    p.dir = d;
    p.throughput = vec3<f32>(1.0);
    p.radiance = vec3<f32>(0.0);
    p.aov = PrimaryAov(0.0, d, 0.0, 0u, 0u, STATUS_MISSED, start, 0.0);
    p.primary = true;
    p.inside = has_medium() && bounds_signed_distance(start) < 0.0;
    p.bounces = 0u;
    p.event = 0u;
    p.marching = false;
    return p;
}

// One pixel sample (CPU twin: trace_path): the camera ray path_start began, through the
// medium and the objects, up to max_depth bounces; `jitter` scales the first step of the
// camera ray's passage. Runs the path in `p` on until it is done (PATH_DONE, its
// radiance and AOVs in `p`), left to PASS_MEDIUM (PATH_DEFERRED), or until its marches
// have taken `budget` steps and flights (PATH_SUSPENDED: `p` runs on from there, the
// same steps in the same arithmetic as one whole run). `budget` is decreased by the
// steps taken, unless it is MARCH_UNBOUNDED.
fn path_run(p: ptr<function, PathState>, jitter: f32, rng: ptr<function, u32>, budget: ptr<function, u32>) -> u32 {
    var origin = (*p).origin;
    var dir = (*p).dir;
    var throughput = (*p).throughput;
    var radiance = (*p).radiance;
    var aov = (*p).aov;
    var primary = (*p).primary;
    var inside = (*p).inside;
    var bounces = (*p).bounces;
    // Resumed in the middle of a march: its state is read where the march runs on (kept
    // out of the loop's own variables, which every pass would carry).
    var resuming = (*p).marching;
    let max_events = EVENTS_PER_DEPTH * (params.max_depth + 1u);
    for (var ev_i = (*p).event; ev_i < max_events; ev_i++) {
        var hit = no_hit();
        var hit_dir = dir;
        let resumed = resumable() && resuming;
        resuming = false;
        var crossing = resumed;
        if !resumed {
            var event: Event;
            if inside {
                event = Event(EVENT_MEDIUM, no_hit(), dir);
            } else {
                event = next_event_outside(origin, dir);
            }
            if event.kind == EVENT_SKY {
                radiance += throughput * sky_radiance(event.dir);
                break;
            }
            hit = event.hit;
            hit_dir = event.dir;
            crossing = event.kind == EVENT_MEDIUM;
        }
        if crossing {
            if defer_medium() {
                (*p).radiance = radiance;
                (*p).aov = aov;
                return PATH_DEFERRED;
            }
            var end: MarchEnd;
            var ended = false;
            var march: MarchCarry;
            var stats: MarchStats;
            var entry_dir: vec3<f32>;
            var straight_exit: vec3<f32>;
            if resumed {
                march = (*p).march;
                stats = (*p).stats;
                entry_dir = (*p).entry_dir;
                straight_exit = (*p).straight_exit;
            } else {
                stats = march_stats_new(dir);
                let b = bounds_intersect(origin, dir);
                straight_exit = origin;
                if b.found {
                    straight_exit = origin + dir * max(b.s_out, 0.0);
                }
                entry_dir = dir;
                let begun = march_begin(origin, dir, select(1.0, jitter, primary), &stats);
                if begun.done {
                    end = begun.end;
                    ended = true;
                } else {
                    march = begun.carry;
                }
            }
            if !ended {
                let before = stats.steps;
                end = march_run(&march, &stats, *budget);
                if *budget != MARCH_UNBOUNDED {
                    *budget -= min(*budget, stats.steps - before);
                }
                if resumable() && end.kind == END_SUSPENDED {
                    *p = PathState(origin, dir, throughput, radiance, aov, primary, inside, bounces, ev_i, true, march, stats, entry_dir, straight_exit);
                    return PATH_SUSPENDED;
                }
            }
            aov.steps += stats.steps;
            aov.evals += stats.evals;
            inside = false;
            var status = end.status;
            var has_hit = false;
            switch end.kind {
                case END_EXITED: {
                    throughput *= end.transmittance;
                    origin = end.point;
                    dir = end.dir;
                }
                case END_OBJECT: {
                    throughput *= end.transmittance;
                    dir = end.dir;
                    has_hit = true;
                    hit = end.hit;
                    hit_dir = end.dir;
                }
                case END_MISSED: {
                    // Grazing the bounds: continue as a straight ray past them.
                    origin += dir * SURFACE_EPS;
                }
                default: {
                    dir = end.dir;
                }
            }
            if primary && status != STATUS_MISSED {
                aov.status = status;
                aov.exit_dir = dir;
                aov.exit_pos = end.point;
                aov.deflection_deg = angle_between_deg(entry_dir, dir);
                if status == STATUS_EXITED || status == STATUS_DEGRADED {
                    // opl - n_amb * straight, from its small parts (MarchStats): the path's
                    // excess index, its length off the entry direction, and its lag
                    // behind the straight exit along that direction. On to the plane the
                    // lag is weighed by 1/cos - 1, so the positions' roundoff drops out.
                    let n_amb = ambient_index();
                    let lag = dot(straight_exit - end.point, entry_dir);
                    aov.opd = stats.excess + n_amb * (stats.geo - lag);
                    let c = dot(dir, entry_dir);
                    if c > 1e-12 {
                        aov.opd_plane = stats.excess + n_amb * (stats.geo + lag * off_axis(dir, entry_dir) / c);
                    } else {
                        aov.opd_plane = aov.opd;
                    }
                } else {
                    aov.opd = 0.0;
                }
            }
            if !has_hit {
                if status == STATUS_EXITED || status == STATUS_DEGRADED || status == STATUS_MISSED {
                    continue;
                }
                // max_steps or error: the path ends here, black.
                break;
            }
        }
        // A surface (never reached without objects: the flag lets the compiler drop
        // the surface code, which lavapipe would otherwise run under a mask).
        if (FLAGS & FLAG_HAS_OBJECTS) == 0u {
            break;
        }
        primary = false;
        if bounces >= params.max_depth {
            break;
        }
        bounces += 1u;
        let obj = objects[hit.object];
        let cos_i = -dot(hit_dir, hit.normal);
        var next = vec3<f32>(0.0);
        var weight = vec3<f32>(1.0);
        switch obj.material {
            case MATERIAL_DIFFUSE: {
                radiance += throughput * shade_diffuse(hit, obj.color_a);
            }
            case MATERIAL_CHECKER: {
                var albedo = obj.color_b;
                if checker_is_a(hit.point, hit.normal, obj.param) {
                    albedo = obj.color_a;
                }
                radiance += throughput * shade_diffuse(hit, albedo);
            }
            case MATERIAL_TEXTURE, MATERIAL_DOTS: {
                var rgb: vec3<f32>;
                if obj.material == MATERIAL_TEXTURE {
                    rgb = texture_colour(obj, hit.point, hit.normal);
                } else {
                    rgb = dots_colour(obj, hit.point, hit.normal);
                }
                if (obj.surface_flags & SURFACE_EMISSIVE) != 0u {
                    radiance += throughput * rgb;
                } else {
                    radiance += throughput * shade_diffuse(hit, rgb);
                }
            }
            case MATERIAL_MIRROR: {
                next = reflect_dir(hit_dir, hit.normal);
                weight = obj.color_a;
            }
            case MATERIAL_METAL: {
                next = reflect_dir(hit_dir, hit.normal);
                weight = fresnel_schlick(cos_i, obj.color_a);
            }
            default: {
                // Glass: Fresnel chooses reflection or refraction at random.
                let ior = obj.param;
                let side = select(-1.0, 1.0, hit.front_face);
                let n_outside = index_at(hit.point + hit.normal * (SURFACE_EPS * side));
                if n_outside < 0.0 {
                    (*p).radiance = radiance;
                    (*p).aov = aov;
                    return PATH_DEFERRED;
                }
                var n1 = ior;
                var n2 = n_outside;
                if hit.front_face {
                    n1 = n_outside;
                    n2 = ior;
                }
                let f = fresnel_dielectric(cos_i, n1, n2);
                let u = rng_next_f32(rng);
                let t = refract_dir(hit_dir, hit.normal, n1, n2);
                if t.w > 0.5 && u >= f {
                    next = t.xyz;
                    weight = obj.color_a;
                } else {
                    next = reflect_dir(hit_dir, hit.normal);
                }
            }
        }
        if obj.material == MATERIAL_DIFFUSE || obj.material == MATERIAL_CHECKER
            || obj.material == MATERIAL_TEXTURE || obj.material == MATERIAL_DOTS {
            // Diffuse and emissive surfaces end the path (direct light only).
            break;
        }
        throughput *= weight;
        let side = select(-1.0, 1.0, dot(next, hit.normal) >= 0.0);
        origin = hit.point + hit.normal * (side * SURFACE_EPS);
        dir = next;
        inside = has_medium() && bounds_signed_distance(origin) < 0.0;
    }
    (*p).radiance = radiance;
    (*p).aov = aov;
    return PATH_DONE;
}

fn shade_diffuse(hit: Hit, albedo: vec3<f32>) -> vec3<f32> {
    var irradiance = ambient_radiance(hit.normal) * (AMBIENT_SKY_WEIGHT * PI);
    let p = hit.point + hit.normal * SURFACE_EPS;
    let count = params.light_count;
    for (var i = 0u; i < count; i++) {
        let light = lights[i];
        var to_light: vec3<f32>;
        var dist: f32;
        var intensity: vec3<f32>;
        if light.kind == LIGHT_KIND_POINT {
            let v = light.position - p;
            dist = length(v);
            to_light = v / dist;
            intensity = light.intensity / (dist * dist);
        } else {
            to_light = -normalize(light.position);
            dist = INF;
            intensity = light.intensity;
        }
        let cos = dot(hit.normal, to_light);
        if cos <= 0.0 {
            continue;
        }
        let visibility = shadow_transmittance(p, to_light, dist);
        irradiance += intensity * visibility * cos;
    }
    return albedo * irradiance / PI;
}

// Transmittance of a straight segment through the objects; w = 0 if blocked.
fn straight_transmittance(o: vec3<f32>, d: vec3<f32>, dist: f32) -> vec4<f32> {
    var t = vec3<f32>(1.0);
    let count = params.object_count;
    for (var i = 0u; i < count; i++) {
        let obj = objects[i];
        if intersect_object(obj, o, d, SURFACE_EPS, dist).found {
            if obj.material == MATERIAL_GLASS {
                let r0 = fresnel_dielectric(1.0, 1.0, obj.param);
                t *= obj.color_a * (1.0 - r0) * (1.0 - r0);
            } else {
                return vec4<f32>(0.0);
            }
        }
    }
    return vec4<f32>(t, 1.0);
}

// The shadow ray traced through the medium (bend_shadow_rays): straight to the bounds,
// through the medium (an object inside blocks it), straight again along the bent exit
// direction for the remaining distance. w = 0 when it does not meet the medium.
fn bent_shadow_transmittance(p: vec3<f32>, l: vec3<f32>, dist: f32) -> vec4<f32> {
    var to_entry = 0.0;
    if bounds_signed_distance(p) >= 0.0 {
        let b = bounds_intersect(p, l);
        if !(b.found && b.s_in > 0.0 && b.s_in < dist) {
            return vec4<f32>(0.0);
        }
        to_entry = b.s_in;
    }
    let before = straight_transmittance(p, l, to_entry);
    if before.w < 0.5 {
        return vec4<f32>(0.0, 0.0, 0.0, 1.0);
    }
    var stats = march_stats_new(l);
    let end = march_medium(p, l, 1.0, &stats);
    if end.kind == END_EXITED {
        let remaining = max(dist - to_entry - stats.length, 0.0);
        let after = straight_transmittance(end.point, end.dir, remaining);
        return vec4<f32>(before.xyz * after.xyz * after.w * end.transmittance, 1.0);
    }
    if end.kind == END_MISSED {
        return vec4<f32>(0.0);
    }
    return vec4<f32>(0.0, 0.0, 0.0, 1.0);
}

fn shadow_transmittance(p: vec3<f32>, l: vec3<f32>, dist: f32) -> vec3<f32> {
    // (render.rs does not split a frame whose shadow rays bend: they march.)
    if (FLAGS & FLAG_BEND_SHADOWS) != 0u && has_medium() && !defer_medium() {
        let t = bent_shadow_transmittance(p, l, dist);
        if t.w > 0.5 {
            return t.xyz;
        }
    }
    let s = straight_transmittance(p, l, dist);
    return s.xyz * s.w;
}
