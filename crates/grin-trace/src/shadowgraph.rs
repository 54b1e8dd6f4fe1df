//! Shadowgraph: a collimated beam along the camera's view through the medium onto a
//! screen; the image is the ray density on the screen, 1 where nothing deflects. Each
//! screen bin of the undisturbed beam gets `rays_per_pixel` rays on a k x k grid, traced
//! with the scene's integrator (f64) and carried straight from where they leave the
//! medium to the screen. What leaves the screen is counted (energy bookkeeping).

use glam::DVec3;
use rayon::prelude::*;

use grin_field::IndexField;
use grin_render::camera::PinholeCamera;
use grin_render::settings::TraceSettings;
use grin_scene::Screen;

use crate::trace::{RayStatus, trace_ray};

/// A shadowgraph and its bookkeeping.
#[derive(Debug, Clone, PartialEq)]
pub struct Shadowgraph {
    pub width: u32,
    pub height: u32,
    /// Rays landed per bin over rays launched per bin (row 0 at the top).
    pub intensity: Vec<f64>,
    /// Rays launched, landed on the screen, and stopped in the medium (max_steps,
    /// error, absorbed).
    pub launched: u64,
    pub landed: u64,
    pub stopped: u64,
    /// Screen size (world units) and its centre.
    pub size: [f64; 2],
    pub centre: DVec3,
}

/// Trace the beam through `field` (view axes from `cam`, bins `width` x `height`).
pub fn shadowgraph(
    field: &dyn IndexField,
    settings: &TraceSettings,
    cam: &PinholeCamera,
    screen: &Screen,
) -> Shadowgraph {
    let (w, h) = (cam.width, cam.height);
    let bounds = field.bounds();
    let (lo, hi) = bounds.aabb();
    let middle = (lo + hi) * 0.5;
    let radius = (hi - lo).length() * 0.5;
    let across = |axis: DVec3| {
        // The bounding box's extent along a view axis.
        let e = (hi - lo) * 0.5;
        2.0 * (e.x * axis.x.abs() + e.y * axis.y.abs() + e.z * axis.z.abs())
    };
    let size = screen.size.unwrap_or([
        across(cam.right),
        across(cam.right) * f64::from(h) / f64::from(w),
    ]);
    let centre = middle + cam.forward * screen.distance;
    let start = middle - cam.forward * (radius * 1.01 + 1e-9);
    let k = (f64::from(screen.rays_per_pixel).sqrt().round() as u32).max(1);
    let (bw, bh) = (size[0] / f64::from(w), size[1] / f64::from(h));
    let empty = || (vec![0u64; (w * h) as usize], 0u64, 0u64);
    // One histogram per rayon job, summed at the end.
    let (counts, landed, stopped) = (0..h)
        .into_par_iter()
        .fold(empty, |(mut counts, mut landed, mut stopped), j| {
            for i in 0..w {
                for a in 0..k {
                    for b in 0..k {
                        let x = (f64::from(i) + (f64::from(a) + 0.5) / f64::from(k)) * bw
                            - 0.5 * size[0];
                        let y = 0.5 * size[1]
                            - (f64::from(j) + (f64::from(b) + 0.5) / f64::from(k)) * bh;
                        let o = start + cam.right * x + cam.up * y;
                        let r = trace_ray::<f64>(field, settings, o, cam.forward);
                        let (p, d) = match r.status {
                            RayStatus::Exited => (r.position, r.direction),
                            RayStatus::Missed => (o, cam.forward),
                            _ => {
                                stopped += 1;
                                continue;
                            }
                        };
                        let den = d.dot(cam.forward);
                        if den <= 0.0 {
                            continue;
                        }
                        let q = p + d * ((centre - p).dot(cam.forward) / den);
                        let sx = (q - centre).dot(cam.right) + 0.5 * size[0];
                        let sy = 0.5 * size[1] - (q - centre).dot(cam.up);
                        let (bi, bj) = ((sx / bw).floor(), (sy / bh).floor());
                        if bi >= 0.0 && bj >= 0.0 && bi < f64::from(w) && bj < f64::from(h) {
                            counts[(bj as u32 * w + bi as u32) as usize] += 1;
                            landed += 1;
                        }
                    }
                }
            }
            (counts, landed, stopped)
        })
        .reduce(empty, |(mut a, la, sa), (b, lb, sb)| {
            for (x, y) in a.iter_mut().zip(b) {
                *x += y;
            }
            (a, la + lb, sa + sb)
        });
    let per = f64::from(k * k);
    Shadowgraph {
        width: w,
        height: h,
        intensity: counts.iter().map(|&c| c as f64 / per).collect(),
        launched: u64::from(w) * u64::from(h) * u64::from(k * k),
        landed,
        stopped,
        size,
        centre,
    }
}
