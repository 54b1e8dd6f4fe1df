//! The path loop of one pixel sample: an explicit loop with a throughput (no recursion),
//! medium crossings, material events, direct light with shadow rays, and the primary
//! ray's AOVs. Keep in sync with shaders' `trace_path`.

use glam::DVec3;
use grin_scene::{Light, Material};

use super::materials::{
    checker_is_a, fresnel_dielectric, fresnel_schlick, reflect_dir, refract_dir,
};
use super::medium::{CpuMedium, MarchEnd, MarchStats, SURFACE_EPS};
use super::primitives::{Hit, intersect_scene};
use super::rng::Rng;
use super::surface::{dot_intensity, surface_coords, texture_uv};
use super::{RenderScene, SceneMedium};
use crate::trace::RayStatus;

/// Fraction of the sky's radiance (seen along the normal) added to diffuse surfaces as a
/// crude ambient term, so that shadowed ground is not black. Purely cosmetic.
pub const AMBIENT_SKY_WEIGHT: f64 = 0.2;

/// Loop iterations allowed per unit of max_depth: each bounce may also pass through the
/// medium without counting as a bounce.
pub const EVENTS_PER_DEPTH: u32 = 3;

/// The `status` AOV value of a ray status (the order of `RayStatus::ALL`: missed 0,
/// exited 1, absorbed 2, max_steps 3, error 4, degraded 5).
pub fn status_code(status: RayStatus) -> u8 {
    match status {
        RayStatus::Missed => 0,
        RayStatus::Exited => 1,
        RayStatus::Absorbed => 2,
        RayStatus::MaxSteps => 3,
        RayStatus::Error => 4,
        RayStatus::Degraded => 5,
    }
}

/// The AOVs of one pixel sample: the camera ray's first passage through the medium,
/// plus steps and field evaluations summed over the whole path.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PrimaryAov {
    /// Angle between the direction entering the medium and the direction leaving it.
    pub deflection_deg: f64,
    /// Unit direction after leaving the medium (the camera ray's direction if it missed).
    pub exit_dir: DVec3,
    /// Where the ray left the medium or stopped in it (the camera if it missed).
    pub exit_pos: DVec3,
    /// Optical path inside the medium minus ambient n times the straight chord of the
    /// undeflected ray through the bounds (0 for rays stopped inside).
    pub opd: f64,
    /// `opd` with both paths taken on to the plane through the straight ray's exit,
    /// normal to it ([`opd_tail`]): the interferometric OPD.
    pub opd_plane: f64,
    pub steps: u32,
    pub evals: u64,
    pub status: RayStatus,
}

/// The geometric length from where a ray left the medium (`exit`, along `dir`) to the
/// plane through `straight_exit` normal to `entry_dir` (where the straight ray would
/// leave). Taken on to that plane, the OPD is stationary in the ray's deflection (Fermat
/// with a free end on a surface normal to the ray); measured to the medium's face it has a
/// first-order term wherever the ray leaves a face obliquely. 0 past a 90 degree turn.
pub fn opd_tail(straight_exit: DVec3, entry_dir: DVec3, exit: DVec3, dir: DVec3) -> f64 {
    let cos = dir.dot(entry_dir);
    if cos <= 1e-12 {
        return 0.0;
    }
    (straight_exit - exit).dot(entry_dir) / cos
}

/// Radiance and AOVs of one pixel sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathSample {
    pub rgb: DVec3,
    pub aov: PrimaryAov,
}

/// What the ray met next.
enum Event {
    Sky(DVec3),
    Surface {
        hit: Hit,
        dir: DVec3,
    },
    /// The ray reaches the medium (or starts inside it) before any object.
    Medium,
}

/// The CPU's view of a [`RenderScene`]: the path loop's methods (the scene itself is
/// grin-render's, shared with the GPU).
#[derive(Debug, Clone, Copy)]
pub struct CpuScene<'a>(pub &'a RenderScene);

impl std::ops::Deref for CpuScene<'_> {
    type Target = RenderScene;
    fn deref(&self) -> &RenderScene {
        self.0
    }
}

impl CpuScene<'_> {
    /// Index of the space at `p`: the medium's n inside the bounds, else ambient.
    fn index_at(&self, p: DVec3) -> f64 {
        match &self.medium {
            Some(m) if m.bounds.contains(p) => m.field.n(p),
            Some(m) => m.ambient,
            None => 1.0,
        }
    }

    /// Nearest event along a straight ray from `o` outside the medium.
    fn next_event_outside(&self, o: DVec3, d: DVec3) -> Event {
        let hit = intersect_scene(&self.objects, o, d, SURFACE_EPS, f64::INFINITY);
        if let Some(m) = &self.medium
            && let Some((s_in, _)) = m.bounds.intersect(o, d)
            && s_in > SURFACE_EPS
            && hit.is_none_or(|h| s_in < h.t)
        {
            return Event::Medium;
        }
        match hit {
            Some(hit) => Event::Surface { hit, dir: d },
            None => Event::Sky(d),
        }
    }

    /// One pixel sample: follow the camera ray from `start` along `d` (the camera's
    /// origin, or a point on its lens) through the medium and the objects, up to
    /// max_depth bounces. `jitter` in (0, 1] scales the first step of the camera ray's
    /// passage through the medium (1: none).
    pub fn trace_path(&self, start: DVec3, d: DVec3, jitter: f64, rng: &mut Rng) -> PathSample {
        let mut origin = start;
        let mut dir = d;
        let mut throughput = DVec3::ONE;
        let mut radiance = DVec3::ZERO;
        let mut aov = PrimaryAov {
            deflection_deg: 0.0,
            exit_dir: d,
            exit_pos: start,
            opd: 0.0,
            opd_plane: 0.0,
            steps: 0,
            evals: 0,
            status: RayStatus::Missed,
        };
        let mut primary = true; // still on the camera ray, before any surface event
        let mut inside = self
            .medium
            .as_ref()
            .is_some_and(|m| m.bounds.signed_distance(origin) < 0.0);
        let mut bounces = 0;
        for _ in 0..EVENTS_PER_DEPTH * (self.settings.max_depth + 1) {
            let event = if inside {
                Event::Medium
            } else {
                self.next_event_outside(origin, dir)
            };
            let (hit, hit_dir) = match event {
                Event::Sky(d) => {
                    radiance += throughput * self.sky.sky_radiance(d);
                    break;
                }
                Event::Surface { hit, dir } => (hit, dir),
                Event::Medium => {
                    let Some(m) = &self.medium else { break };
                    let mut stats = MarchStats::default();
                    let chord = m.bounds.intersect(origin, dir);
                    let straight_exit =
                        origin + dir * chord.map_or(0.0, |(_, s_out)| s_out.max(0.0));
                    let entry_dir = dir;
                    let end = CpuMedium(m).march_medium(
                        &self.objects,
                        origin,
                        dir,
                        if primary { jitter } else { 1.0 },
                        &mut stats,
                    );
                    aov.steps += stats.steps;
                    aov.evals += stats.evals;
                    inside = false;
                    let mut stopped_at = origin;
                    let (status, next) = match end {
                        MarchEnd::Exited {
                            point,
                            dir: out,
                            transmittance,
                            degraded,
                        } => {
                            throughput *= transmittance;
                            origin = point;
                            stopped_at = point;
                            dir = out;
                            let status = if degraded {
                                RayStatus::Degraded
                            } else {
                                RayStatus::Exited
                            };
                            (status, None)
                        }
                        MarchEnd::Object {
                            hit,
                            dir: chord,
                            transmittance,
                        } => {
                            throughput *= transmittance;
                            dir = chord;
                            stopped_at = hit.point;
                            (RayStatus::Absorbed, Some(hit))
                        }
                        MarchEnd::Missed => {
                            // Grazing the bounds: continue as a straight ray past them.
                            origin += dir * SURFACE_EPS;
                            (RayStatus::Missed, None)
                        }
                        MarchEnd::Stopped {
                            status,
                            point,
                            dir: last,
                        } => {
                            dir = last;
                            stopped_at = point;
                            (status, None)
                        }
                    };
                    if primary && status != RayStatus::Missed {
                        aov.status = status;
                        aov.exit_dir = dir;
                        aov.exit_pos = stopped_at;
                        aov.deflection_deg = entry_dir.angle_between(dir).to_degrees();
                        // opl - n_amb * straight, with the length that of the path's
                        // own positions (swept . d0 and its lag behind the straight exit),
                        // as the GPU takes it (shaders/shared/shade.wgsl).
                        aov.opd = if status.left() {
                            let lag = (straight_exit - stopped_at).dot(entry_dir);
                            stats.opl - m.ambient * (stats.swept.dot(entry_dir) + lag)
                        } else {
                            0.0
                        };
                        aov.opd_plane = if status.left() {
                            aov.opd
                                + m.ambient * opd_tail(straight_exit, entry_dir, stopped_at, dir)
                        } else {
                            0.0
                        };
                    }
                    match (status, next) {
                        (_, Some(hit)) => (hit, dir),
                        (RayStatus::Exited | RayStatus::Degraded | RayStatus::Missed, None) => {
                            continue;
                        }
                        // max_steps or error: the path ends here, black.
                        _ => break,
                    }
                }
            };
            primary = false;
            if bounces >= self.settings.max_depth {
                break;
            }
            bounces += 1;
            match self.scatter(&hit, hit_dir, rng) {
                Scatter::Emit(rgb) => {
                    radiance += throughput * rgb;
                    break;
                }
                Scatter::Continue { dir: next, weight } => {
                    throughput *= weight;
                    // Leave the surface on the side the new direction points to.
                    let side = if next.dot(hit.normal) >= 0.0 {
                        1.0
                    } else {
                        -1.0
                    };
                    origin = hit.point + hit.normal * (side * SURFACE_EPS);
                    dir = next;
                    inside = self
                        .medium
                        .as_ref()
                        .is_some_and(|m| m.bounds.signed_distance(origin) < 0.0);
                }
            }
        }
        PathSample { rgb: radiance, aov }
    }

    /// The material's response at `hit` for a ray arriving along `d`.
    fn scatter(&self, hit: &Hit, d: DVec3, rng: &mut Rng) -> Scatter {
        let cos_i = -d.dot(hit.normal);
        match self.materials[hit.object] {
            Material::Diffuse { color } => {
                Scatter::Emit(self.shade_diffuse(hit, DVec3::from_array(color)))
            }
            Material::Checker {
                color_a,
                color_b,
                scale,
            } => {
                let albedo = if checker_is_a(hit.point, hit.normal, scale) {
                    color_a
                } else {
                    color_b
                };
                Scatter::Emit(self.shade_diffuse(hit, DVec3::from_array(albedo)))
            }
            Material::Texture {
                repeat,
                border,
                color,
                emissive,
                size,
                center,
                ..
            } => {
                let (coords, face) = surface_coords(
                    &self.objects[hit.object],
                    hit.point,
                    hit.normal,
                    center.map(DVec3::from_array),
                );
                let image = &self.images[self.object_images[hit.object].unwrap_or_default()];
                let texel = image
                    .at_uv(texture_uv(coords, size, face), repeat)
                    .unwrap_or(DVec3::from_array(border));
                self.surface_colour(hit, texel * DVec3::from_array(color), emissive)
            }
            Material::Dots {
                diameter,
                density,
                seed,
                color,
                background,
                center,
                emissive,
            } => {
                let (coords, _) = surface_coords(
                    &self.objects[hit.object],
                    hit.point,
                    hit.normal,
                    center.map(DVec3::from_array),
                );
                let a = dot_intensity(diameter, density, seed, coords);
                let albedo = DVec3::from_array(background).lerp(DVec3::from_array(color), a);
                self.surface_colour(hit, albedo, emissive)
            }
            Material::Mirror { color } => Scatter::Continue {
                dir: reflect_dir(d, hit.normal),
                weight: DVec3::from_array(color),
            },
            Material::Metal { color } => Scatter::Continue {
                dir: reflect_dir(d, hit.normal),
                weight: fresnel_schlick(cos_i, DVec3::from_array(color)),
            },
            Material::Glass { ior, color } => {
                let n_outside = self.index_at(
                    hit.point + hit.normal * SURFACE_EPS * if hit.front_face { 1.0 } else { -1.0 },
                );
                let (n1, n2) = if hit.front_face {
                    (n_outside, ior)
                } else {
                    (ior, n_outside)
                };
                let f = fresnel_dielectric(cos_i, n1, n2);
                let u = f64::from(rng.next_f32());
                match refract_dir(d, hit.normal, n1, n2) {
                    Some(t) if u >= f => Scatter::Continue {
                        dir: t,
                        weight: DVec3::from_array(color),
                    },
                    _ => Scatter::Continue {
                        dir: reflect_dir(d, hit.normal),
                        weight: DVec3::ONE,
                    },
                }
            }
        }
    }

    /// An image or pattern's colour: shown as it is when `emissive`, else lit as a
    /// diffuse albedo.
    fn surface_colour(&self, hit: &Hit, rgb: DVec3, emissive: bool) -> Scatter {
        Scatter::Emit(if emissive {
            rgb
        } else {
            self.shade_diffuse(hit, rgb)
        })
    }

    /// Lambertian surface: direct light from every light (with shadow rays) plus the
    /// ambient sky term.
    fn shade_diffuse(&self, hit: &Hit, albedo: DVec3) -> DVec3 {
        let mut irradiance =
            self.sky.ambient_radiance(hit.normal) * AMBIENT_SKY_WEIGHT * std::f64::consts::PI;
        let p = hit.point + hit.normal * SURFACE_EPS;
        for light in &self.lights {
            let (to_light, dist, intensity) = match *light {
                Light::Point {
                    position,
                    intensity,
                } => {
                    let v = DVec3::from_array(position) - p;
                    let dist = v.length();
                    (v / dist, dist, DVec3::from_array(intensity) / (dist * dist))
                }
                Light::Directional {
                    direction,
                    intensity,
                } => (
                    -DVec3::from_array(direction).normalize(),
                    f64::INFINITY,
                    DVec3::from_array(intensity),
                ),
            };
            let cos = hit.normal.dot(to_light);
            if cos <= 0.0 {
                continue;
            }
            let visibility = self.shadow_transmittance(p, to_light, dist);
            irradiance += intensity * visibility * cos;
        }
        albedo * irradiance / std::f64::consts::PI
    }

    /// Light reaching `p` from direction `l` over distance `dist`: 0 behind an opaque
    /// object; glass passes its colour times the normal-incidence transmission of its two
    /// surfaces (no refraction of shadow rays). Straight through the medium unless
    /// `bend_shadow_rays` is set, which traces the shadow ray through it.
    pub fn shadow_transmittance(&self, p: DVec3, l: DVec3, dist: f64) -> DVec3 {
        if self.settings.bend_shadow_rays
            && let Some(m) = &self.medium
            && let Some(t) = self.bent_shadow_transmittance(m, p, l, dist)
        {
            return t;
        }
        self.straight_transmittance(p, l, dist)
            .unwrap_or(DVec3::ZERO)
    }

    /// The shadow ray traced through the medium: straight to the bounds, through the
    /// medium with the tracer (an object inside blocks it), straight again from the exit
    /// along the bent direction for the remaining distance. `None` if the shadow ray
    /// does not meet the medium.
    fn bent_shadow_transmittance(
        &self,
        m: &SceneMedium,
        p: DVec3,
        l: DVec3,
        dist: f64,
    ) -> Option<DVec3> {
        let to_entry = if m.bounds.signed_distance(p) < 0.0 {
            0.0
        } else {
            m.bounds
                .intersect(p, l)
                .map(|(s_in, _)| s_in)
                .filter(|&s| s > 0.0 && s < dist)?
        };
        let Some(before) = self.straight_transmittance(p, l, to_entry) else {
            return Some(DVec3::ZERO);
        };
        let mut stats = MarchStats::default();
        match CpuMedium(m).march_medium(&self.objects, p, l, 1.0, &mut stats) {
            MarchEnd::Exited {
                point,
                dir,
                transmittance,
                ..
            } => {
                let remaining = (dist - to_entry - stats.length).max(0.0);
                let after = self
                    .straight_transmittance(point, dir, remaining)
                    .unwrap_or(DVec3::ZERO);
                Some(before * after * transmittance)
            }
            MarchEnd::Missed => None,
            _ => Some(DVec3::ZERO),
        }
    }

    /// Transmittance of a straight segment through the objects; `None` if blocked.
    fn straight_transmittance(&self, o: DVec3, d: DVec3, dist: f64) -> Option<DVec3> {
        let mut t = DVec3::ONE;
        for (prim, material) in self.objects.iter().zip(&self.materials) {
            if prim.intersect(o, d, SURFACE_EPS, dist).is_some() {
                match *material {
                    Material::Glass { ior, color } => {
                        let r0 = fresnel_dielectric(1.0, 1.0, ior);
                        t *= DVec3::from_array(color) * (1.0 - r0) * (1.0 - r0);
                    }
                    _ => return None,
                }
            }
        }
        Some(t)
    }
}

/// A material event's result.
enum Scatter {
    /// The path ends here with this radiance.
    Emit(DVec3),
    /// The path continues along `dir`, throughput scaled by `weight`.
    Continue { dir: DVec3, weight: DVec3 },
}
