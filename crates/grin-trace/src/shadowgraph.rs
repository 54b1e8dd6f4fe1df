//! Shadowgraph: a collimated beam along the camera's view through the medium onto a
//! screen; the image is the ray density on the screen, 1 where nothing deflects. Each
//! screen bin of the undisturbed beam gets `rays_per_pixel` rays on a k x k grid, traced
//! with the scene's integrator and carried straight from where they leave the medium to
//! the screen. What leaves the screen is counted (energy bookkeeping). The beam's rays
//! are the pixel centres of an orthographic camera ([`Beam::camera`]), so either
//! backend can trace them: [`shadowgraph`] here in f64, or the GPU marcher's frame of
//! that camera binned by [`Beam::collect`].

use glam::DVec3;
use rayon::prelude::*;

use grin_field::{Bounds, IndexField};
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

/// The collimated beam: `k` x `k` rays per screen bin, starting on a plane before the
/// medium, and the screen they land on (`width` x `height` bins).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Beam {
    pub width: u32,
    pub height: u32,
    pub k: u32,
    /// Where the central ray starts (before the medium's bounding ball).
    pub start: DVec3,
    pub forward: DVec3,
    pub right: DVec3,
    pub up: DVec3,
    /// Screen (and beam) size in world units, and the screen's centre.
    pub size: [f64; 2],
    pub centre: DVec3,
}

impl Beam {
    /// The beam of `screen` through a medium in `bounds`, along `cam`'s view, binned at
    /// its image size.
    pub fn new(bounds: &Bounds, cam: &PinholeCamera, screen: &Screen) -> Beam {
        let (w, h) = (cam.width, cam.height);
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
        Beam {
            width: w,
            height: h,
            k: (f64::from(screen.rays_per_pixel).sqrt().round() as u32).max(1),
            start: middle - cam.forward * (radius * 1.01 + 1e-9),
            forward: cam.forward,
            right: cam.right,
            up: cam.up,
            size,
            centre: middle + cam.forward * screen.distance,
        }
    }

    /// The orthographic camera whose pixel centres, (`width` k) x (`height` k) of them,
    /// are the beam's rays: pixel (i k + a, j k + b) is ray (a, b) of bin (i, j).
    pub fn camera(&self) -> PinholeCamera {
        PinholeCamera {
            origin: self.start,
            forward: self.forward,
            right: self.right,
            up: self.up,
            tan_half_fov_y: 1.0,
            width: self.width * self.k,
            height: self.height * self.k,
            lens_radius: 0.0,
            focus_distance: 1.0,
            ortho: Some([0.5 * self.size[0], 0.5 * self.size[1]]),
        }
    }

    /// Where a ray leaving the medium at `p` along `d` meets the screen's plane, in bins
    /// from the screen's centre (right, up); `None` going away from it.
    pub fn landing_bins(&self, p: DVec3, d: DVec3) -> Option<[f64; 2]> {
        let den = d.dot(self.forward);
        if den.is_nan() || den <= 0.0 {
            return None;
        }
        let r = p + d * ((self.centre - p).dot(self.forward) / den) - self.centre;
        Some([
            r.dot(self.right) * f64::from(self.width) / self.size[0],
            r.dot(self.up) * f64::from(self.height) / self.size[1],
        ])
    }

    /// The bin (index, row 0 at the top) where a ray leaving the medium at `p` along
    /// `d` meets the screen; `None` off the screen or going away from it.
    pub fn bin(&self, p: DVec3, d: DVec3) -> Option<usize> {
        let den = d.dot(self.forward);
        if den <= 0.0 {
            return None;
        }
        let q = p + d * ((self.centre - p).dot(self.forward) / den);
        let (bw, bh) = (
            self.size[0] / f64::from(self.width),
            self.size[1] / f64::from(self.height),
        );
        let sx = (q - self.centre).dot(self.right) + 0.5 * self.size[0];
        let sy = 0.5 * self.size[1] - (q - self.centre).dot(self.up);
        let (bi, bj) = ((sx / bw).floor(), (sy / bh).floor());
        (bi >= 0.0 && bj >= 0.0 && bi < f64::from(self.width) && bj < f64::from(self.height))
            .then(|| (bj as u32 * self.width + bi as u32) as usize)
    }

    /// Count one ray as it left the medium into `tally`: `Some((p, d))` for a ray that
    /// exited at p along d (or missed it: its start and `forward`), `None` for one
    /// stopped inside.
    pub fn count(&self, tally: &mut Tally, end: Option<(DVec3, DVec3)>) {
        match end {
            Some((p, d)) => {
                if let Some(b) = self.bin(p, d) {
                    tally.counts[b] += 1;
                    tally.landed += 1;
                }
            }
            None => tally.stopped += 1,
        }
    }

    /// An empty tally of this beam's screen.
    pub fn tally(&self) -> Tally {
        Tally {
            counts: vec![0; (self.width * self.height) as usize],
            landed: 0,
            stopped: 0,
        }
    }

    /// The shadowgraph of a finished tally.
    pub fn finish(&self, tally: Tally) -> Shadowgraph {
        let per = f64::from(self.k * self.k);
        Shadowgraph {
            width: self.width,
            height: self.height,
            intensity: tally.counts.iter().map(|&c| c as f64 / per).collect(),
            launched: u64::from(self.width) * u64::from(self.height) * u64::from(self.k * self.k),
            landed: tally.landed,
            stopped: tally.stopped,
            size: self.size,
            centre: self.centre,
        }
    }

    /// The shadowgraph of the beam's rays as they left the medium (see [`Beam::count`]).
    pub fn collect(&self, ends: impl Iterator<Item = Option<(DVec3, DVec3)>>) -> Shadowgraph {
        let mut tally = self.tally();
        for end in ends {
            self.count(&mut tally, end);
        }
        self.finish(tally)
    }
}

/// Rays landed per screen bin, landed in all, and stopped in the medium.
#[derive(Debug, Clone, PartialEq)]
pub struct Tally {
    counts: Vec<u64>,
    landed: u64,
    stopped: u64,
}

impl Tally {
    /// The sum of two tallies of one screen.
    fn merge(mut self, other: Tally) -> Tally {
        for (a, b) in self.counts.iter_mut().zip(other.counts) {
            *a += b;
        }
        self.landed += other.landed;
        self.stopped += other.stopped;
        self
    }
}

/// Trace the beam through `field` on the CPU (f64; view axes from `cam`, bins `width` x
/// `height`).
pub fn shadowgraph(
    field: &dyn IndexField,
    settings: &TraceSettings,
    cam: &PinholeCamera,
    screen: &Screen,
) -> Shadowgraph {
    let beam = Beam::new(&field.bounds(), cam, screen);
    let view = beam.camera();
    // One tally per rayon job, summed at the end (no ray's end is kept).
    let tally = (0..view.height)
        .into_par_iter()
        .fold(
            || beam.tally(),
            |mut tally, py| {
                for px in 0..view.width {
                    let (o, d) = view.camera_ray(px, py, 0.5, 0.5);
                    let r = trace_ray::<f64>(field, settings, o, d);
                    let end = match r.status {
                        RayStatus::Exited | RayStatus::Degraded => Some((r.position, r.direction)),
                        RayStatus::Missed => Some((o, d)),
                        _ => None,
                    };
                    beam.count(&mut tally, end);
                }
                tally
            },
        )
        .reduce(|| beam.tally(), Tally::merge);
    beam.finish(tally)
}
