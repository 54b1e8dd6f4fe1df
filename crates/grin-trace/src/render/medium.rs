//! The renderer's passage through the medium: `trace_ray_jittered` (the tracer's
//! integrators, step policies, exit search and Snell/Fresnel at the surface) with an
//! observer that tests each step's straight chord against the scene objects (the paper's
//! step 4) and stops the ray on the first one. Keep in sync with shaders' `march_medium`.

use glam::DVec3;

use super::SceneMedium;
use super::primitives::{Hit, Primitive, intersect_scene};
use crate::boundary::Segment;
use crate::trace::{Control, RayStatus, trace_ray_jittered};

/// Length by which a ray is pushed off a surface it starts on (world units).
pub const SURFACE_EPS: f64 = 1e-6;

/// How a passage through the medium ended.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MarchEnd {
    /// Left the medium at `point` along unit `dir` (after refraction), carrying the
    /// Fresnel transmittance of the surface crossings.
    Exited {
        point: DVec3,
        dir: DVec3,
        transmittance: f64,
        /// The tracer's status was `degraded` (its error estimate is above the limit).
        degraded: bool,
    },
    /// A step's chord met a scene object inside the medium; `dir` is the chord direction.
    Object {
        hit: Hit,
        dir: DVec3,
        transmittance: f64,
    },
    /// The ray never entered the medium (it started outside and missed the bounds).
    Missed,
    /// The per-ray step cap was reached, or the field failed.
    Stopped {
        status: RayStatus,
        point: DVec3,
        dir: DVec3,
    },
}

/// What a passage accumulated.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MarchStats {
    pub steps: u32,
    pub evals: u64,
    /// Optical path length inside the medium, up to the exit or the object.
    pub opl: f64,
    /// Geometric length inside the medium.
    pub length: f64,
    /// ∫ u ds over that length ([`crate::trace::RayResult::swept`]).
    pub swept: DVec3,
}

/// The first object met by a step's chord r0 -> r1.
pub fn chord_hit(objects: &[Primitive], seg: &Segment) -> Option<(Hit, DVec3)> {
    let chord = seg.r1 - seg.r0;
    let len = chord.length();
    if len == 0.0 {
        return None;
    }
    let dir = chord / len;
    intersect_scene(objects, seg.r0, dir, 0.0, len).map(|hit| (hit, dir))
}

/// The CPU's view of a [`SceneMedium`]: the march (the medium itself is grin-render's).
#[derive(Debug, Clone, Copy)]
pub struct CpuMedium<'a>(pub &'a SceneMedium);

impl std::ops::Deref for CpuMedium<'_> {
    type Target = SceneMedium;
    fn deref(&self) -> &SceneMedium {
        self.0
    }
}

impl CpuMedium<'_> {
    /// Trace from `origin` (outside: the tracer finds the entry and refracts; inside:
    /// it starts marching) along unit `dir` until the ray leaves the medium, meets an
    /// object, or stops. `jitter` in (0, 1] scales the first step (1: none).
    pub fn march_medium(
        &self,
        objects: &[Primitive],
        origin: DVec3,
        dir: DVec3,
        jitter: f64,
        stats: &mut MarchStats,
    ) -> MarchEnd {
        let mut met: Option<(Hit, DVec3, f64, f64)> = None;
        let mut observer = |seg: &Segment| match chord_hit(objects, seg) {
            Some((hit, d)) => {
                met = Some((hit, d, seg.r0.distance(seg.r1), seg.h));
                Control::Stop
            }
            None => Control::Continue,
        };
        let res = trace_ray_jittered::<f64>(
            self.field.as_ref(),
            &self.trace,
            origin,
            dir,
            jitter,
            &mut observer,
        );
        stats.steps += res.steps;
        stats.evals += res.evals;
        stats.opl += res.opl;
        stats.length += res.length;
        stats.swept += res.swept;
        match res.status {
            RayStatus::Missed => MarchEnd::Missed,
            RayStatus::Exited | RayStatus::Degraded => MarchEnd::Exited {
                point: res.position,
                dir: res.direction,
                transmittance: res.transmittance,
                degraded: res.status == RayStatus::Degraded,
            },
            RayStatus::Absorbed => match met {
                Some((hit, d, chord_len, _)) => {
                    // The tracer counted the whole last step; keep only the part up to the hit.
                    let cut = (chord_len - hit.t).max(0.0);
                    let n = self.field.n(hit.point);
                    stats.length -= cut;
                    stats.opl -= n * cut;
                    stats.swept -= d * cut;
                    MarchEnd::Object {
                        hit,
                        dir: d,
                        transmittance: res.transmittance,
                    }
                }
                None => MarchEnd::Stopped {
                    status: RayStatus::Error,
                    point: res.position,
                    dir: res.direction,
                },
            },
            status => MarchEnd::Stopped {
                status,
                point: res.position,
                dir: res.direction,
            },
        }
    }
}
