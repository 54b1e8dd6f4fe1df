//! `step = { auto = RAD }` resolved by pilot rays: before a render or a ray table, a few
//! of its own rays are traced with error control at a hundredth of the asked error (the
//! pilots' reference), then with the per-length error control an unresolved `auto` runs
//! (tightened by 10 while it misses), then with fixed steps of each candidate integrator,
//! jumping by the measured order (at least halving) until the worst pilot's exit
//! direction is within [`PILOT_TARGET`] of the asked error, then bisecting back towards
//! the last miss. The cheapest candidate that meets it on every pilot traces the rest,
//! its rays held to a limit on their own estimates that the pilots calibrate
//! ([`Candidate::calibration`]); if none does, the closest, and the choice says so
//! (`met`).
//!
//! Why: error control pays six evaluations a dopri step and keeps its steps short enough
//! for the worst place in the field everywhere; on a weak field a low-order method with
//! long fixed steps meets the same error at a fraction of the cost, and which one does is
//! a property of the field and the rays, which the pilots measure (docs/accuracy.md).
//! The pilots see only the rays they are given: a render's secondary rays and pixels
//! between the pilots are assumed no harder than the worst pilot.
//!
//! Over 600 lines: one concept, the pilots, the candidates and the choice between them.

use glam::DVec3;
use grin_field::{IndexField, Real};
use grin_scene::{IntegratorKind, StepSpec};
use rayon::prelude::*;

use crate::trace::{RayResult, RayStatus, trace_ray};
use grin_render::settings::TraceSettings;

/// The pilots' reference runs error control at this fraction of the asked error
/// (tighter costs much more on baked grids, whose interpolant is only C2: at 1e-5 of
/// 1e-6 rad the reference through a tricubic Luneburg bake ran into max_steps).
pub const REFERENCE_FRACTION: f64 = 0.01;
/// A candidate must meet this fraction of the asked error on every pilot (the rays
/// between the pilots may be a little harder than the worst of them).
pub const PILOT_TARGET: f64 = 0.7;
/// Error control per length is tried at the asked error and this many times tighter
/// by 10 at most.
pub const CONTROL_TRIES: u32 = 3;
/// Fixed steps tried per integrator at most.
pub const MAX_TRIES: u32 = 10;
/// The first fixed step tried, as a fraction of the medium's radius (the tracer's
/// feature and length-scale caps shorten it where the field needs).
pub const FIRST_STEP_REL: f64 = 0.5;
/// Bisections of the steps between a candidate's last miss and its first met step.
pub const REFINE_TRIES: u32 = 2;
/// Steps closer than this ratio are not bisected (the cost differs by less).
pub const REFINE_RATIO: f64 = 1.25;
/// No fixed step shorter than this fraction of the radius is tried: error control is
/// cheaper long before.
pub const SHORTEST_STEP_REL: f64 = 1.0 / 4096.0;

/// Rays a job traces per pilot ray before pilots pay: the pilots trace a reference at a
/// hundredth of the asked error and 10-30 candidates, 18-35x what the method they choose
/// costs a ray (measured: a narrow bump in an expression, 5,400 evaluations a pilot for
/// 300 a ray; a Luneburg lens, 1,100 for 31), so they are under ~20 % of a job with 200x
/// their rays.
pub const JOB_RAYS_PER_PILOT: usize = 200;
/// Fewer pilots than this say too little: the job runs error control instead.
pub const MIN_PILOTS: usize = 8;

/// What an evaluation costs in ray packets (crate::packet), against one in the one-ray
/// tracer, for fixed-step RK4: measured 0.37-0.38 on the expression GRIN rod and on a
/// Luneburg lens (f64, one thread), taken a little above so a packet candidate wins only
/// where it clearly does.
pub const PACKET_EVAL_COST: f64 = 0.4;
/// ... and for dopri under error control: measured 0.41-0.53 on the rod (auto 1e-6 and
/// 1e-9, f64, one thread).
pub const PACKET_EVAL_COST_DOPRI: f64 = 0.5;

/// What an evaluation of a trace with `settings` in precision `R` costs, against one of
/// the one-ray tracer: [`PACKET_EVAL_COST`] or [`PACKET_EVAL_COST_DOPRI`] where a ray
/// table (`table`) traces them in packets, else 1.
pub fn eval_cost<R: Real>(settings: &TraceSettings, table: bool) -> f64 {
    if !(table && crate::packet::traced_in_packets::<R>(settings)) {
        return 1.0;
    }
    match settings.integrator {
        IntegratorKind::Adaptive => PACKET_EVAL_COST_DOPRI,
        _ => PACKET_EVAL_COST,
    }
}

/// The pilot rays a job of `job_rays` rays affords, at most `wanted`: 0 where even
/// [`MIN_PILOTS`] would cost more than ~20 % of the job (then `auto` runs error control
/// per length, which keeps its word without pilots).
pub fn affordable_pilots(wanted: usize, job_rays: usize) -> usize {
    let n = (job_rays / JOB_RAYS_PER_PILOT).min(wanted);
    if n < MIN_PILOTS { 0 } else { n }
}

/// One candidate the pilots measured.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Candidate {
    pub integrator: &'static str,
    /// Fixed step (world length); `None`: per-length error control.
    pub fixed_step: Option<f64>,
    /// Worst error over the pilots, in the choice's unit (infinite: a pilot ended with
    /// another status than the reference's).
    pub error: f64,
    /// The largest of the pilots' own integration error estimates (rad,
    /// `RayResult::error_estimate`) where they left the medium.
    pub estimate: f64,
    pub evals_per_ray: f64,
    /// What the candidate costs a ray, in field evaluations of the one-ray tracer: its
    /// evaluations, times [`eval_cost`] (less than 1 where a ray table traces it in
    /// packets).
    /// The choice is the cheapest by this.
    pub cost_per_ray: f64,
    /// How pessimistic the pilots' own estimates were: the least, over the pilots, of a
    /// pilot's estimate over its measured error (that error taken at least at the
    /// reference's own accuracy), within 1 ..= [`MAX_CALIBRATION`]. A chosen candidate
    /// that met the request holds its rays to [`VOUCH_FACTOR`] x this x the asked error.
    pub calibration: f64,
}

/// What a pilot's error is measured in: the knob's unit for this output.
#[derive(Debug, Clone)]
pub enum Metric {
    /// The exit direction, radians (images, schlieren, the shadowgraph).
    Direction,
    /// A ray table's: the exit direction, radians, and the optical path to the exit in
    /// world length over the medium's radius (the table's `opl` column held to the
    /// asked radians times the radius, the mapping [`Metric::Waves`] makes for error
    /// control).
    Table { radius: f64 },
    /// Where the ray lands on `plane` (at infinity: its direction) as `cam` sees it, in
    /// image pixels: what displacement, ST maps and BOS are made of.
    Pixels {
        cam: Box<grin_render::camera::PinholeCamera>,
        plane: Option<grin_render::optics::Plane>,
    },
    /// The optical path difference, in waves of `wavelength` (metres), taken on to a
    /// plane normal to the ray's entry direction beyond the medium (stationary in the
    /// deflection, as the interferogram's).
    Waves { wavelength: f64 },
    /// Where the ray lands on the shadowgraph's screen, in its bins (the image's
    /// pixels): what the shadowgraph's ray density is made of. The pilots are then the
    /// beam's rays ([`crate::shadowgraph::Beam::camera`]).
    Screen(Box<crate::shadowgraph::Beam>),
}

impl Metric {
    /// The unit's name in summaries.
    pub fn unit(&self) -> &'static str {
        match self {
            Metric::Direction | Metric::Table { .. } => "rad",
            Metric::Pixels { .. } | Metric::Screen(_) => "px",
            Metric::Waves { .. } => "waves",
        }
    }

    /// An exit-direction error (rad) for error control that keeps this metric's `asked`:
    /// a pixel's angle as the camera sees it (a direction error at the medium moves the
    /// landing point by less than that across the image), or the OPD over the medium's
    /// `radius` (an OPL error accumulates along the path).
    fn as_radians(&self, asked: f64, radius: f64) -> f64 {
        match self {
            Metric::Direction | Metric::Table { .. } => asked,
            Metric::Pixels { cam, .. } => {
                asked * 2.0 * cam.tan_half_fov_y.atan() / f64::from(cam.height.max(1))
            }
            Metric::Waves { wavelength } => asked * wavelength / radius.max(f64::MIN_POSITIVE),
            // A direction error at the medium moves the landing point by the distance
            // on to the screen times it (from where the beam starts: the longest).
            Metric::Screen(beam) => {
                let bin = (beam.size[0] / f64::from(beam.width.max(1)))
                    .min(beam.size[1] / f64::from(beam.height.max(1)));
                let reach = (beam.centre - beam.start).dot(beam.forward);
                asked * bin / reach.max(f64::MIN_POSITIVE)
            }
        }
    }

    /// How large the output itself is for the pilot `(origin, dir)` traced as
    /// `reference`, in this metric's unit: the landing point's displacement in pixels
    /// (`None` for the other metrics, and where the ray does not land).
    fn size(&self, reference: &RayResult, pilot: (DVec3, DVec3)) -> Option<f64> {
        let a = self.landing(reference.position, reference.direction)??;
        let b = self.landing(pilot.0, pilot.1)??;
        Some(px_distance(a, b))
    }

    /// Where a ray leaving at `p` along `d` lands, in pixels (the image's, or the
    /// shadowgraph screen's bins): `Some(None)` where it does not land, `None` for the
    /// metrics not made of a landing point.
    fn landing(&self, p: DVec3, d: DVec3) -> Option<Option<[f64; 2]>> {
        match self {
            Metric::Pixels { cam, plane } => {
                Some(grin_render::optics::landing_px(cam, plane.as_ref(), p, d))
            }
            Metric::Screen(beam) => Some(beam.landing_bins(p, d)),
            Metric::Direction | Metric::Table { .. } | Metric::Waves { .. } => None,
        }
    }

    /// The error of `run` against `reference` for the pilot `(origin, dir)`, in this
    /// metric's unit (infinite where it cannot be measured).
    fn error(
        &self,
        run: &RayResult,
        reference: &RayResult,
        pilot: (DVec3, DVec3),
        far: f64,
        n_amb: f64,
    ) -> f64 {
        match self {
            Metric::Direction => angle(run.direction, reference.direction),
            Metric::Table { radius } => {
                let path = (run.opl - reference.opl).abs() / radius.max(f64::MIN_POSITIVE);
                // A path that cannot be compared fails the pilot (max would drop a NaN).
                let path = if path.is_nan() { f64::INFINITY } else { path };
                angle(run.direction, reference.direction).max(path)
            }
            Metric::Pixels { .. } | Metric::Screen(_) => {
                let seen = |r: &RayResult| self.landing(r.position, r.direction).flatten();
                match (seen(run), seen(reference)) {
                    (Some(a), Some(b)) => px_distance(a, b),
                    (None, None) => 0.0,
                    _ => f64::INFINITY,
                }
            }
            Metric::Waves { wavelength } => {
                // Each path on to the plane through origin + far d0, normal to d0:
                // opl + n_amb lag / c, lag the exit's distance to that plane along d0. The
                // exit position of an f32 trace is rounded to ~1e-7 of its size, a fifth
                // of a wave: the lag is taken from the path's own length instead (its
                // `swept` projection, summed in f64; the part common to both runs of a
                // pilot drops out of their difference), and the position enters only
                // times 1/c - 1, as the GPU takes the OPD.
                let (o, d0) = (pilot.0, pilot.1.normalize_or_zero());
                let to_plane = |r: &RayResult| {
                    let c = r.direction.dot(d0);
                    if c <= 1e-12 {
                        return f64::NAN;
                    }
                    let lag = (o + d0 * far - r.position).dot(d0);
                    let w = r.direction - d0;
                    r.opl - n_amb * r.swept.dot(d0) + n_amb * lag * (0.5 * w.dot(w)) / c
                };
                (to_plane(run) - to_plane(reference)).abs() / wavelength
            }
        }
    }
}

/// The distance between two points of an image, in its pixels.
fn px_distance(a: [f64; 2], b: [f64; 2]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt()
}

/// A ray traced with the pilots' choice is vouched for while its own error estimate is
/// at most this many times the asked error (rad): the pilots measured the choice's real
/// error within the asked one, and the estimates are bounds (errors summed without
/// cancelling, the lower-order member's error for the embedded and companion estimates),
/// so a ray whose real error is over 10x the asked one says `degraded`. At 1x, on a plume
/// at 1e-4 rad, euler's pilots measured 3.8e-5 rad while estimating up to 2.6e-4 (the
/// pilots paid 3x for a method with a tighter estimate); holding rays to the largest
/// estimate the pilots showed degraded 235 of a schlieren example's 6,400 pixels whose
/// verlet estimates were ~4,000x their pilots' measured errors.
pub const VOUCH_FACTOR: f64 = 10.0;

/// The most the pilots' calibration ([`Candidate::calibration`]) raises the limit a ray's
/// estimate is held to. The estimates of the fourth-order methods are their third-order
/// companions' errors, pessimistic by a factor that grows as the step shrinks: at 1e-8 rad
/// on Maxwell's fish-eye, sharma's pilots estimated up to 4e-7 rad, so only error control
/// (1.85x the cost of the cheapest step that met it) could be vouched for. Where every
/// pilot's estimate is at least P times its real error, a ray is flagged when its estimate
/// says it is over 10x the asked error at that pessimism; the cap bounds how far over a
/// ray less pessimistic than every pilot can pass.
pub const MAX_CALIBRATION: f64 = 30.0;

/// A pixel output's accuracy is at most this fraction of the largest displacement the
/// pilots' reference shows: heat haze that moves the background by a hundredth of a pixel
/// is measured to 1e-5 px, not to the 0.01 px asked of a visible distortion.
pub const RELATIVE_OUTPUT_ACCURACY: f64 = 1e-3;

/// What the pilots chose.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct AutoChoice {
    /// The error asked for, in `unit`.
    pub asked: f64,
    /// `rad` (exit direction), `px` (landing point), `waves` (optical path difference).
    pub unit: &'static str,
    /// The exit-direction error the error-control candidates were held to for it, rad.
    pub asked_rad: f64,
    #[serde(skip)]
    pub settings: TraceSettings,
    /// Rays whose own error estimate is above this (rad) end `degraded`:
    /// [`VOUCH_FACTOR`] x `asked_rad`, times the chosen candidate's calibration where it
    /// met the request.
    pub vouched_to: f64,
    /// The chosen candidate (its error and cost on the pilots).
    pub chosen: Candidate,
    /// Whether the chosen candidate met the asked error on every pilot (false: none
    /// did, and this is the closest one; the renderer warns).
    pub met: bool,
    /// Pilot rays that met the medium.
    pub pilot_rays: usize,
    /// Field evaluations the choice cost (reference and every candidate).
    pub spent_evals: u64,
    /// Every candidate measured, in the order tried.
    pub tried: Vec<Candidate>,
}

impl AutoChoice {
    /// `verlet, fixed ds 0.0625 (worst of 64 pilots: 3.1e-5 rad, 18 evals/ray)`.
    pub fn describe(&self) -> String {
        let c = &self.chosen;
        let how = match (c.fixed_step, self.settings.step) {
            (Some(ds), _) => format!("fixed ds {ds:.4}"),
            (None, StepSpec::Auto(tol)) if tol < self.asked_rad || self.unit != "rad" => {
                format!("error control per length at {tol:.0e} rad")
            }
            (None, _) => "error control per length".into(),
        };
        let packets = if c.cost_per_ray < c.evals_per_ray {
            ", in ray packets"
        } else {
            ""
        };
        format!(
            "{}, {how} (worst of {} pilots: {:.1e} {}, {:.0} evals/ray{packets})",
            c.integrator, self.pilot_rays, c.error, self.unit, c.evals_per_ray
        )
    }
}

impl AutoChoice {
    /// The line `grin render` and `grin trace` print: `auto 1e-4 rad: <describe>, chosen
    /// by pilot rays for N field evals`.
    pub fn summary_line(&self) -> String {
        format!(
            "auto {:.0e} {}: {}, chosen by pilot rays for {} field evals; a ray whose own error estimate is above {:.1e} rad ends `degraded`",
            self.asked,
            self.unit,
            self.describe(),
            self.spent_evals,
            self.vouched_to
        )
    }

    /// The warning when no candidate met the asked error (`None` when one did);
    /// `verb`: what the closest one is used for (`rendering`, `tracing`).
    pub fn unmet_warning(&self, verb: &str) -> Option<String> {
        (!self.met).then(|| {
            format!(
                "auto {:.0e} {}: no method met it on the pilot rays within the steps tried; \
                 {verb} with the closest, {}",
                self.asked,
                self.unit,
                self.describe()
            )
        })
    }
}

/// Worst error (in `metric`) of the exits of `runs` against `reference` (infinite where
/// a status differs) and the mean evaluations per ray.
fn measure(
    runs: &[RayResult],
    reference: &[RayResult],
    rays: &[(DVec3, DVec3)],
    metric: &Metric,
    (far, n_amb): (f64, f64),
    (to_rad, floor_rad): (f64, f64),
) -> (f64, f64, f64) {
    let mut worst: f64 = 0.0;
    let mut evals = 0u64;
    // The least pessimism seen (infinite: no pilot left with a finite estimate).
    let mut least = f64::INFINITY;
    for ((r, e), ray) in runs.iter().zip(reference).zip(rays) {
        evals += r.evals;
        // A ray the reference vouches for that this run cannot (a bake's n error
        // amplified at its crossings) does not meet it; a `degraded` ray left as a
        // degraded reference did: its error is measured.
        let unvouched = r.status == RayStatus::Degraded && e.status == RayStatus::Exited;
        if unvouched || (r.status != e.status && !(r.status.left() && e.status.left())) {
            worst = f64::INFINITY;
            continue;
        }
        if r.status.left() {
            let err = metric.error(r, e, *ray, far, n_amb);
            worst = worst.max(if err.is_nan() { f64::INFINITY } else { err });
            if r.error_estimate.is_finite() {
                // A ray's own estimate is of its direction: a table's is calibrated
                // against the direction's error alone.
                let estimated = match metric {
                    Metric::Table { .. } => angle(r.direction, e.direction),
                    _ => err,
                };
                let real = (estimated * to_rad).max(floor_rad);
                least = least.min(r.error_estimate / real);
            }
        }
    }
    // No pilot to measure it on: no calibration.
    let calibration = if least.is_finite() {
        least.clamp(1.0, MAX_CALIBRATION)
    } else {
        1.0
    };
    (worst, evals as f64 / runs.len().max(1) as f64, calibration)
}

/// Angle between two directions (accurate for tiny angles: atan2 of |a x b| and a . b).
pub fn angle(a: DVec3, b: DVec3) -> f64 {
    let (a, b) = (a.normalize_or_zero(), b.normalize_or_zero());
    a.cross(b).length().atan2(a.dot(b))
}

fn trace_all<R: Real>(
    field: &dyn IndexField,
    settings: &TraceSettings,
    rays: &[(DVec3, DVec3)],
) -> Vec<RayResult> {
    rays.par_iter()
        .map(|&(o, d)| trace_ray::<R>(field, settings, o, d))
        .collect()
}

/// Resolve `settings` (whose step is `auto`) on `pilots`, tracing in precision `R`.
/// `free`: the scene named no integrator, so every one is a candidate; else
/// only `settings.integrator`. `None` when the step is not `auto` or no pilot meets the
/// medium (then the tracer's error control runs: it needs no pilots).
pub fn choose<R: Real>(
    field: &dyn IndexField,
    settings: &TraceSettings,
    free: bool,
    pilots: &[(DVec3, DVec3)],
) -> Option<AutoChoice> {
    let metric = Metric::Direction;
    choose_with::<R>(field, settings, free, pilots, &metric, None, false)
}

/// [`choose`] for an error of `asked` in `metric`'s unit (the step's own `auto` value is
/// then not used; it must still be `auto`).
pub fn choose_in<R: Real>(
    field: &dyn IndexField,
    settings: &TraceSettings,
    free: bool,
    pilots: &[(DVec3, DVec3)],
    metric: &Metric,
    asked: f64,
) -> Option<AutoChoice> {
    choose_with::<R>(field, settings, free, pilots, metric, Some(asked), false)
}

/// [`choose`] for a ray table: the job traces in packets where the candidate's settings
/// and the precision allow ([`crate::packet::traced_in_packets`]), so such a candidate
/// costs [`eval_cost`] an evaluation.
pub fn choose_for_table<R: Real>(
    field: &dyn IndexField,
    settings: &TraceSettings,
    free: bool,
    pilots: &[(DVec3, DVec3)],
) -> Option<AutoChoice> {
    let metric = Metric::Table {
        radius: field.bounds().radius(),
    };
    // A table's path is an output: its error control holds it too (the pilots trace as
    // the table will).
    let settings = TraceSettings {
        opl_control: true,
        ..*settings
    };
    choose_with::<R>(field, &settings, free, pilots, &metric, None, true)
}

/// The choice for an error of `asked` in `metric`'s unit (`None`: the step's own `auto`
/// value), for a ray table or not.
fn choose_with<R: Real>(
    field: &dyn IndexField,
    settings: &TraceSettings,
    free_integrator: bool,
    pilots: &[(DVec3, DVec3)],
    metric: &Metric,
    asked: Option<f64>,
    table: bool,
) -> Option<AutoChoice> {
    let StepSpec::Auto(own) = settings.step else {
        return None;
    };
    let asked = asked.unwrap_or(own);
    let radius = field.bounds().radius();
    let asked_rad = metric.as_radians(asked, radius);
    // The reference flags only rays whose own estimate is above VOUCH_FACTOR x the asked
    // error (the candidates below flag none; the chosen one is held to the calibrated
    // limit).
    let held_to = |asked_rad: f64| TraceSettings {
        accuracy: asked_rad,
        estimate_limit: VOUCH_FACTOR * asked_rad,
        ..*settings
    };
    let base = held_to(asked_rad);
    let settings = &base;
    // The OPD's plane: beyond the medium along each pilot's entry direction.
    let far = (pilots
        .iter()
        .map(|p| p.0.distance(field.bounds().center()))
        .fold(0.0, f64::max)
        + 2.0 * radius)
        .max(radius);
    let geometry = (far, field.ambient_index());
    let reference_settings = TraceSettings {
        integrator: IntegratorKind::Adaptive,
        step: StepSpec::Auto(asked_rad * REFERENCE_FRACTION),
        max_steps: settings.max_steps.min(grin_scene::DEFAULT_MAX_STEPS),
        ..*settings
    };
    let reference = trace_all::<f64>(field, &reference_settings, pilots);
    let mut spent: u64 = reference.iter().map(|r| r.evals).sum();
    // Only the pilots that cross the medium say anything about how to: not those that
    // miss it, nor those the reference could not finish (trapped, or beyond its steps).
    let (rays, reference): (Vec<(DVec3, DVec3)>, Vec<RayResult>) = pilots
        .iter()
        .zip(reference)
        .filter(|(_, r)| r.status.left())
        .map(|(p, r)| (*p, r))
        .unzip();
    if rays.is_empty() {
        return None;
    }
    // A displacement far under a pixel is asked to a fraction of itself.
    let largest = rays
        .iter()
        .zip(&reference)
        .filter_map(|(ray, r)| metric.size(r, *ray))
        .filter(|v| v.is_finite())
        .fold(0.0f64, f64::max);
    let (asked, asked_rad, reference) =
        if largest > 0.0 && RELATIVE_OUTPUT_ACCURACY * largest < asked {
            let tighter = RELATIVE_OUTPUT_ACCURACY * largest;
            let asked_rad = asked_rad * tighter / asked;
            // The reference again, a hundredth of the tighter error.
            let again = TraceSettings {
                step: StepSpec::Auto(asked_rad * REFERENCE_FRACTION),
                ..reference_settings
            };
            let reference = trace_all::<f64>(field, &again, &rays);
            spent += reference.iter().map(|r| r.evals).sum::<u64>();
            (tighter, asked_rad, reference)
        } else {
            (asked, asked_rad, reference)
        };
    // The candidates flag nothing on their own estimates: the pilots measure their real
    // errors (a ray the reference vouches for and a candidate misses fails it) and how
    // pessimistic their estimates are; the chosen one is held to the calibrated limit.
    let base = TraceSettings {
        estimate_limit: f64::INFINITY,
        ..held_to(asked_rad)
    };
    let settings = &base;
    // A pilot's error in rad, and the least real error the reference can tell.
    let scale = (asked_rad / asked, REFERENCE_FRACTION * asked_rad);
    let mut tried = Vec::new();
    let mut run = |s: &TraceSettings, fixed_step: Option<f64>| {
        let out = trace_all::<R>(field, s, &rays);
        spent += out.iter().map(|r| r.evals).sum::<u64>();
        let (error, evals_per_ray, calibration) =
            measure(&out, &reference, &rays, metric, geometry, scale);
        let estimate = out
            .iter()
            .filter(|r| r.status.left())
            .map(|r| r.error_estimate)
            .fold(0.0, f64::max);
        let cost = eval_cost::<R>(s, table);
        let c = Candidate {
            integrator: label(s.integrator),
            fixed_step,
            error,
            estimate,
            evals_per_ray,
            cost_per_ray: evals_per_ray * cost,
            calibration,
        };
        tried.push(c);
        c
    };
    let target = PILOT_TARGET * asked;
    // The first fixed step is measured against the medium's longest half-extent (a box's
    // `radius` is its shortest: a rod 2 long and 1 wide was first tried at a quarter of
    // the step that met its request).
    let (lo, hi) = field.bounds().aabb();
    let reach = (0.5 * (hi - lo)).max_element();
    // Error control per length (what an unresolved `auto` runs), tightened by 10 while
    // the pilots say it misses (rays whose exit is ill-conditioned: grazing ones).
    let mut best: Option<(Candidate, TraceSettings)> = None;
    let mut closest: Option<(Candidate, TraceSettings)> = None;
    let mut keep_closest = |c: Candidate, s: TraceSettings| {
        if closest.as_ref().is_none_or(|(b, _)| c.error < b.error) {
            closest = Some((c, s));
        }
    };
    let mut tol = asked_rad;
    // While nothing meets the target, fixed steps costing more than this are not tried
    // (twice the tightest error control's cost: beyond it no step is worth its cost).
    let mut bound: f64 = 0.0;
    for _ in 0..CONTROL_TRIES {
        let s = TraceSettings {
            step: StepSpec::Auto(tol),
            ..*settings
        };
        let c = run(&s, None);
        keep_closest(c, s);
        bound = bound.max(2.0 * c.cost_per_ray);
        if c.error <= target {
            best = Some((c, s));
            break;
        }
        tol *= 0.1;
    }
    let kinds: Vec<IntegratorKind> = if free_integrator {
        IntegratorKind::ALL.to_vec()
    } else {
        vec![settings.integrator]
    };
    for kind in kinds {
        let order = f64::from(crate::integrate::order(kind));
        let mut ds = FIRST_STEP_REL * reach;
        // The longest step that missed the target (a met step below it is refined).
        let mut missed: Option<f64> = None;
        for _ in 0..MAX_TRIES {
            let s = TraceSettings {
                integrator: kind,
                step: StepSpec::Fixed(ds),
                ..*settings
            };
            let c = run(&s, Some(ds));
            keep_closest(c, s);
            let limit = best.as_ref().map_or(bound, |(b, _)| b.cost_per_ray);
            if c.cost_per_ray >= limit {
                break; // shorter steps only cost more
            }
            if c.error <= target {
                best = Some((c, s));
                // The jump that met it was at least a halving: the steps between the
                // last miss and it are bisected (geometrically) while a bisection is
                // cheaper than what is met (a jump of 2 in step is 2x in cost).
                let mut met = ds;
                if let Some(mut miss) = missed {
                    for _ in 0..REFINE_TRIES {
                        if miss < REFINE_RATIO * met {
                            break;
                        }
                        let mid = (miss * met).sqrt();
                        let s = TraceSettings {
                            step: StepSpec::Fixed(mid),
                            ..s
                        };
                        let c = run(&s, Some(mid));
                        keep_closest(c, s);
                        let cheaper = best
                            .as_ref()
                            .is_none_or(|(b, _)| c.cost_per_ray < b.cost_per_ray);
                        if c.error <= target && cheaper {
                            best = Some((c, s));
                            met = mid;
                        } else {
                            miss = mid;
                        }
                    }
                }
                break;
            }
            missed = Some(ds);
            // Jump by the measured order (a little past, so the next try is likely to
            // meet the target), at least halving, at most by 8.
            let factor = if c.error.is_finite() && c.error > 0.0 {
                (0.8 * (target / c.error).powf(1.0 / order)).clamp(0.125, 0.5)
            } else {
                0.5
            };
            ds *= factor;
            if ds < SHORTEST_STEP_REL * radius {
                break;
            }
        }
    }
    // Nothing met it: the closest candidate, and the choice says so.
    let met = best.is_some();
    let (chosen, chosen_settings) = best.or(closest)?;
    let chosen_settings = TraceSettings {
        estimate_limit: VOUCH_FACTOR * asked_rad * if met { chosen.calibration } else { 1.0 },
        ..chosen_settings
    };
    Some(AutoChoice {
        asked,
        unit: metric.unit(),
        asked_rad,
        vouched_to: chosen_settings.estimate_limit,
        settings: chosen_settings,
        chosen,
        met,
        pilot_rays: rays.len(),
        spent_evals: spent,
        tried,
    })
}

/// The integrator as charts and summaries name it (`adaptive` is the Dormand-Prince pair).
pub fn label(kind: IntegratorKind) -> &'static str {
    match kind {
        IntegratorKind::Adaptive => "dopri",
        k => k.name(),
    }
}

/// Up to `count` of `rays`, spread over the list: the j-th is ray j k + (j mod k)
/// (k = len / count), so a list that is a grid row by row is sampled in every column,
/// not in every k-th one only.
pub fn spread(rays: &[(DVec3, DVec3)], count: usize) -> Vec<(DVec3, DVec3)> {
    if count == 0 || rays.is_empty() {
        return Vec::new();
    }
    let k = rays.len().div_ceil(count);
    (0..count)
        .map(|j| j * k + j % k)
        .take_while(|&i| i < rays.len())
        .map(|i| rays[i])
        .collect()
}

/// Pilot rays of a camera: the centres of a coarse grid of pixels (about `count`, in
/// the image's aspect ratio).
pub fn camera_pilots(
    camera: &grin_render::camera::PinholeCamera,
    count: usize,
) -> Vec<(DVec3, DVec3)> {
    if count == 0 {
        return Vec::new();
    }
    let (w, h) = (camera.width.max(1) as f64, camera.height.max(1) as f64);
    let nx = ((count as f64 * w / h).sqrt().round() as u32).clamp(1, camera.width.max(1));
    let ny = ((count as f64 / f64::from(nx)).round() as u32).clamp(1, camera.height.max(1));
    let mut out = Vec::with_capacity((nx * ny) as usize);
    for j in 0..ny {
        for i in 0..nx {
            let px = ((f64::from(i) + 0.5) / f64::from(nx) * w) as u32;
            let py = ((f64::from(j) + 0.5) / f64::from(ny) * h) as u32;
            out.push(camera.camera_ray(px, py, 0.5, 0.5));
        }
    }
    out
}

/// Pilot rays for a medium seen from nowhere in particular (a camera whose view misses
/// it: secondary rays may still cross it): `count` rays from a sphere of three radii
/// around it towards points spread over its inner half, directions on a Fibonacci
/// sphere.
pub fn generic_pilots(bounds: &grin_field::Bounds, count: usize) -> Vec<(DVec3, DVec3)> {
    let center = bounds.center();
    let radius = bounds.radius();
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..count)
        .map(|i| {
            let f = (i as f64 + 0.5) / count as f64;
            let z = 1.0 - 2.0 * f;
            let rho = (1.0 - z * z).max(0.0).sqrt();
            let phi = golden * i as f64;
            let dir = DVec3::new(rho * phi.cos(), rho * phi.sin(), z);
            // Aim off the centre by up to half the radius, across the direction.
            let side = dir.any_orthonormal_vector();
            let aim = center + side * (0.5 * radius * f);
            (aim - dir * 3.0 * radius, dir)
        })
        .collect()
}

/// Fewer camera pilots than this meeting the medium, and generic ones are added.
pub const MIN_CAMERA_PILOTS: usize = 8;

/// Camera rays tried per pilot wanted: the pilots are picked among them, those whose
/// straight path crosses a varying part of the medium first.
pub const PILOT_CANDIDATES_PER_PILOT: usize = 8;
/// Points sampled along a candidate's straight path through the bounds.
const PILOT_PATH_SAMPLES: usize = 32;

/// A path crosses variation where n differs from ambient by more than this fraction of
/// the field's largest difference (a Gaussian's tail differs everywhere, by 1e-100).
const VARIATION_FRACTION: f64 = 1e-3;

/// Whether the straight ray `(o, d)` crosses a part of `field` where n varies (a sample
/// off the ambient index by more than [`VARIATION_FRACTION`] of the field's range, at
/// [`PILOT_PATH_SAMPLES`] points).
fn crosses_variation(field: &dyn IndexField, o: DVec3, d: DVec3) -> bool {
    let Some((s_in, s_out)) = field.bounds().intersect(o, d) else {
        return false;
    };
    let (a, b) = (s_in.max(0.0), s_out.max(0.0));
    let ambient = field.ambient_index();
    let (lo, hi) = field.n_range();
    let threshold = VARIATION_FRACTION * (ambient - lo).abs().max((hi - ambient).abs());
    (0..PILOT_PATH_SAMPLES).any(|k| {
        let p = o + d * (a + (b - a) * (k as f64 + 0.5) / PILOT_PATH_SAMPLES as f64);
        (field.n(p) - ambient).abs() > threshold
    })
}

/// The pilots of a render: camera rays that meet the medium (`[render] pilot_rays` of
/// them at most), picked from a grid [`PILOT_CANDIDATES_PER_PILOT`] times denser with the
/// rays that cross where the index varies first (a cache whose smoke fills a corner of
/// its bounds: a coarse grid of pilots saw mostly ambient air, measured a method on it,
/// and the smoke's pixels got 2.3x the asked error), topped up with [`generic_pilots`]
/// when the view barely sees the medium.
pub fn scene_pilots(rs: &grin_render::scene::RenderScene) -> Vec<(DVec3, DVec3)> {
    let count = render_pilot_budget(rs);
    let Some(m) = &rs.medium else {
        return Vec::new();
    };
    let candidates: Vec<(DVec3, DVec3)> =
        camera_pilots(&rs.camera, count * PILOT_CANDIDATES_PER_PILOT)
            .into_iter()
            .filter(|&(o, d)| m.bounds.contains(o) || m.bounds.intersect(o, d).is_some())
            .collect();
    let (varying, flat): (Vec<_>, Vec<_>) = candidates
        .iter()
        .partition(|&&(o, d)| crosses_variation(m.field.as_ref(), o, d));
    // Spread over the varying ones; flat ones fill what is left, spread too.
    let mut pilots = spread(&varying, count);
    pilots.extend(spread(&flat, count.saturating_sub(pilots.len())));
    if count > 0 && pilots.len() < MIN_CAMERA_PILOTS.min(count) {
        pilots.extend(generic_pilots(&m.bounds, count));
    }
    pilots
}

/// The camera rays a render of `rs` traces (pixels x samples; its secondary rays are
/// not counted).
fn render_rays(rs: &grin_render::scene::RenderScene) -> usize {
    let s = &rs.settings;
    (u64::from(s.width) * u64::from(s.height) * u64::from(s.spp.max(1)))
        .try_into()
        .unwrap_or(usize::MAX)
}

/// The pilot rays a render of `rs` affords ([`affordable_pilots`] of `[render]
/// pilot_rays` for its camera rays): 0 for a render too small for them to pay.
pub fn render_pilot_budget(rs: &grin_render::scene::RenderScene) -> usize {
    affordable_pilots(rs.settings.pilot_rays as usize, render_rays(rs))
}

/// Why `auto` runs error control per length without pilots on `rs` (a render too small
/// for them), for the summary; `None` where pilots run or `auto` is not asked.
pub fn render_pilot_note(rs: &grin_render::scene::RenderScene) -> Option<String> {
    let StepSpec::Auto(rad) = rs.settings.step else {
        return None;
    };
    (rs.medium.is_some() && rs.settings.pilot_rays > 0 && render_pilot_budget(rs) == 0).then(|| {
        format!(
            "auto {rad:.0e} rad: error control per length, no pilot rays (a render of {} camera \
             rays: pilots pay from {} on)",
            render_rays(rs),
            MIN_PILOTS * JOB_RAYS_PER_PILOT
        )
    })
}

/// Resolve the `auto` step of `rs` (pilot rays from its camera, traced in precision
/// `R`: f32 for the GPU) into its medium's tracer settings and its `[render]` settings,
/// so both backends run the choice. `None`: nothing to resolve (no medium, another
/// step policy, `pilot_rays = 0`, or no pilot met the medium); an unresolved `auto`
/// runs error control per length.
pub fn resolve_scene<R: Real>(rs: &mut grin_render::scene::RenderScene) -> Option<AutoChoice> {
    resolve_scene_in::<R>(rs, None)
}

/// [`resolve_scene`] for an error of `asked` in `metric`'s unit (an optical output's),
/// or in radians with `None`.
pub fn resolve_scene_in<R: Real>(
    rs: &mut grin_render::scene::RenderScene,
    metric: Option<(Metric, f64)>,
) -> Option<AutoChoice> {
    let pilots = scene_pilots(rs);
    let m = rs.medium.as_ref()?;
    if pilots.is_empty() {
        return None;
    }
    let choice = match metric {
        Some((metric, asked)) => choose_in::<R>(
            m.field.as_ref(),
            &m.trace,
            rs.settings.integrator.is_none(),
            &pilots,
            &metric,
            asked,
        ),
        None => choose::<R>(
            m.field.as_ref(),
            &m.trace,
            rs.settings.integrator.is_none(),
            &pilots,
        ),
    }?;
    apply(rs, &choice.settings);
    Some(choice)
}

/// Put resolved tracer settings into `rs` (its medium's and its `[render]`'s).
pub fn apply(rs: &mut grin_render::scene::RenderScene, settings: &TraceSettings) {
    if let Some(m) = &mut rs.medium {
        m.trace = *settings;
    }
    rs.settings.integrator = Some(settings.integrator);
    rs.settings.step = settings.step;
    rs.settings.resolved_accuracy = Some(settings.accuracy);
    rs.settings.resolved_estimate_limit = Some(settings.estimate_limit);
}

#[cfg(test)]
mod tests;
