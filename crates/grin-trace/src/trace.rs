//! The per-ray loop: enter the medium (refracting at its surface), step through it with
//! the chosen integrator and step policy, find where the ray leaves, refract out (Fresnel
//! weight, total internal reflection sends it back in), and account for the optical path.
//!
//! One concept, one file: the parts of a ray's march share its state and compensated sums.

use glam::DVec3;
use grin_field::{Bounds, FieldSample, IndexField, Real, Vec3Like};
use grin_scene::ExitMethod;

use grin_render::settings::TraceSettings;

use crate::boundary::{
    EXCURSION_SLACK_TOLS, Interface, MAX_BISECTIONS, Segment, exit_tolerance, project_to_surface,
    refract, refraction_uncertainty,
};
use crate::estimate::{CROSSING_FACTOR, ErrorEstimate};
use crate::exit_search::{ExitFound, ExitSearch, Phase};
use crate::integrate::{self, RayState, is_finite_v};
use crate::step::{StepController, Taken};

/// A macro-cell span shorter than this fraction of the bounds' radius is not worth a
/// straight flight (and could otherwise stall a ray at a cell face).
pub const MIN_SPAN_REL: f64 = 1e-9;

/// A straight flight shorter than this fraction of the field's grid spacing is not taken
/// (an integration step is, just as straight in a homogeneous cell). In f32 a ray on a
/// macro-cell face can get a span of a few ulps that does not move it once rounded: without
/// this floor such rays repeated zero-length flights until `max_steps` (the f32 runs of the
/// bench's baked plume: ~1M flights, 20-60 ms a ray). The GPU's twin is older (heat haze).
pub const MIN_FLIGHT_VOXELS: f64 = 1e-3;

/// Newton refinements of the Hermite exit on the integrator's own state (each one
/// re-step): the cubic's root is accurate to O(h^4), two steps of Newton to the
/// integrator's order at any step length the controllers choose.
pub const EXIT_NEWTON_ITERATIONS: u32 = 3;

/// Units of roundoff (times the coordinates' size) an entry point that rounds to outside
/// the bounds is moved inside.
pub const ENTRY_NUDGE_EPS: f64 = 4.0;
/// Below this cosine of the refracted ray to the inward normal, the entry nudge goes along
/// the normal (along the ray it would run far along the surface).
pub const ENTRY_NUDGE_MIN_COS: f64 = 0.01;

fn len_scale_of(bounds: &Bounds) -> f64 {
    bounds.radius()
}

/// How a ray's trace ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, strum::IntoStaticStr)]
#[strum(serialize_all = "snake_case")]
pub enum RayStatus {
    /// Never met the medium.
    Missed,
    /// Left the medium (position and direction are where and how).
    Exited,
    /// Stopped inside the medium by the caller (e.g. it hit an object there).
    Absorbed,
    /// Ran out of steps (`TraceSettings::max_steps`) inside the medium.
    MaxSteps,
    /// Bad input (zero or non-finite direction, non-finite origin) or the field failed
    /// (non-finite state, n <= 0).
    Error,
    /// Left the medium (position and direction as for `Exited`), but the ray's own error
    /// estimate ([`crate::estimate`]) is above what it is held to
    /// (`TraceSettings::estimate_limit`), or a bake's n error at its crossings could be
    /// above [`crate::estimate::CROSSING_FACTOR`] x the accuracy asked for: an answer
    /// grin does not vouch for.
    Degraded,
}

impl RayStatus {
    pub const ALL: [RayStatus; 6] = [
        RayStatus::Missed,
        RayStatus::Exited,
        RayStatus::Absorbed,
        RayStatus::MaxSteps,
        RayStatus::Error,
        RayStatus::Degraded,
    ];

    /// Left the medium: `exited`, or `degraded`.
    pub fn left(self) -> bool {
        matches!(self, RayStatus::Exited | RayStatus::Degraded)
    }

    /// The name used in ray tables.
    pub fn name(self) -> &'static str {
        self.into()
    }
}

/// The outcome of tracing one ray through the medium.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RayResult {
    pub status: RayStatus,
    /// Where the ray leaves the medium (or stops; the origin for missed rays).
    pub position: DVec3,
    /// Unit direction there (after refraction out of the medium).
    pub direction: DVec3,
    /// Optical path length inside the medium, integral of n ds.
    pub opl: f64,
    /// Geometric length inside the medium.
    pub length: f64,
    /// The integral of the unit direction u over the length, ∫ u ds: where the length
    /// and the directions alone would take the ray (its chord, but for the integrator's
    /// drift of |T| from n). The OPD is taken with it (opl - n_amb (swept . d0 + lag)),
    /// as the GPU takes it from small parts that f32 keeps (shaders' MarchStats).
    pub swept: DVec3,
    /// Steps taken (straight macro-cell flights count as steps).
    pub steps: u32,
    /// Field evaluations, including rejected adaptive attempts and exit searches.
    pub evals: u64,
    /// Product of the Fresnel transmittances at the surface crossings.
    pub transmittance: f64,
    /// The ray's own estimate of its exit-direction error from the integration (rad,
    /// [`crate::estimate`]), infinite where the exit itself is uncertain (a grazing exit
    /// within the position error).
    pub error_estimate: f64,
    /// The exit-direction error (rad) the field's n uncertainty (a bake's error against
    /// its source) could add at the ray's crossings of the bounds, amplified by tan of
    /// the refracted angle: a bound that ignores the cancelling of entry and exit.
    pub crossing_uncertainty: f64,
}

impl RayResult {
    /// A ray that ended with `status` at `position`, heading `direction`, before any
    /// step: no path, full transmittance, no error.
    pub fn at(status: RayStatus, position: DVec3, direction: DVec3) -> RayResult {
        RayResult {
            status,
            position,
            direction,
            opl: 0.0,
            length: 0.0,
            swept: DVec3::ZERO,
            steps: 0,
            evals: 0,
            transmittance: 1.0,
            error_estimate: 0.0,
            crossing_uncertainty: 0.0,
        }
    }
}

/// Tell the tracer to keep going after a segment, or to stop the ray there (`absorbed`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Control {
    Continue,
    Stop,
}

/// How far [`nudge_inside`] moves a point on the surface at `start` inwards: a few ulps
/// of the medium's size and the point's coordinates in precision `R`.
fn entry_nudge<R: Real>(bounds: &Bounds, start: DVec3) -> f64 {
    ENTRY_NUDGE_EPS * R::EPS.to_f64() * (len_scale_of(bounds) + start.abs().max_element())
}

/// The entry point `start` rounded to R and, when that lands outside the bounds (the
/// first step would then "exit" where the ray entered), moved inside by a few units of R's
/// roundoff: along the refracted ray `d_in` (its own line; a move along the normal
/// shifts the ray sideways and bends its exit by as much), returning the length skipped,
/// over which the caller adds the field's pull to the direction; along the normal, with no
/// skip, where the ray all but grazes the surface. WGSL twin: `nudge_inside`.
fn nudge_inside<R: Real>(bounds: &Bounds, start: DVec3, d_in: DVec3) -> (R::V3, f64) {
    let r = R::V3::from_dvec3(start);
    if bounds.signed_distance(r.to_dvec3()) < 0.0 {
        return (r, 0.0);
    }
    let nudge = entry_nudge::<R>(bounds, start);
    let normal = bounds.normal(start);
    let cos_in = -d_in.dot(normal);
    if cos_in > ENTRY_NUDGE_MIN_COS {
        let skip = nudge / cos_in;
        let along = R::V3::from_dvec3(start + d_in * skip);
        if bounds.signed_distance(along.to_dvec3()) < 0.0 {
            return (along, skip);
        }
    }
    (R::V3::from_dvec3(start - normal * nudge), 0.0)
}

/// Trace one ray from `origin` along `dir` (any length) through `field`, integrating in
/// precision `R` (f64: the reference; f32: what the GPU does). Surface geometry and the
/// accumulated sums are f64.
pub fn trace_ray<R: Real>(
    field: &dyn IndexField,
    settings: &TraceSettings,
    origin: DVec3,
    dir: DVec3,
) -> RayResult {
    trace_ray_observed::<R>(field, settings, origin, dir, &mut |_| Control::Continue)
}

/// [`trace_ray`], calling `observer` with each step's segment (cubic Hermite dense
/// output) inside the medium; `Control::Stop` ends the ray there as `absorbed`.
pub fn trace_ray_observed<R: Real>(
    field: &dyn IndexField,
    settings: &TraceSettings,
    origin: DVec3,
    dir: DVec3,
    observer: &mut dyn FnMut(&Segment) -> Control,
) -> RayResult {
    trace_ray_jittered::<R>(field, settings, origin, dir, 1.0, observer)
}

/// [`trace_ray_observed`] with the first fixed or heuristic step scaled by
/// `first_step_scale` in (0, 1]: the renderer's per-pixel jitter (GPU twin: the
/// `jitter` of `step_controller_new` in shaders/shared/step.wgsl).
pub fn trace_ray_jittered<R: Real>(
    field: &dyn IndexField,
    settings: &TraceSettings,
    origin: DVec3,
    dir: DVec3,
    first_step_scale: f64,
    observer: &mut dyn FnMut(&Segment) -> Control,
) -> RayResult {
    match March::<R>::begin(field, settings, origin, dir, first_step_scale) {
        Err(done) => done,
        Ok(mut march) => loop {
            if let Some(done) = march.advance(field, settings, observer) {
                return done;
            }
        },
    }
}

/// What every ray's march through one field, with one set of settings and in one
/// precision, starts from: the packets ask it of the field once per chunk of a table;
/// [`March::begin`] asks it for its one ray.
#[derive(Debug, Clone)]
pub(crate) struct MarchStart {
    bounds: Bounds,
    /// No crossing yet.
    surface: Surface,
    /// Not jittered.
    ctrl: StepController,
    estimate: ErrorEstimate,
    exit_tol: f64,
    min_flight: f64,
}

impl MarchStart {
    /// For rays through `field` with `settings`, in precision `R`.
    pub(crate) fn new<R: Real>(field: &dyn IndexField, settings: &TraceSettings) -> Self {
        let bounds = field.bounds();
        MarchStart {
            bounds,
            surface: Surface {
                n_amb: field.ambient_index(),
                dn: field.n_uncertainty(),
                error: 0.0,
                accuracy: settings.accuracy,
                estimate_limit: settings.estimate_limit,
            },
            ctrl: StepController::new(settings.step, settings.integrator, field)
                .with_opl_control(settings.opl_control),
            estimate: ErrorEstimate::for_integrator(settings.integrator),
            exit_tol: exit_tolerance::<R>(&bounds),
            min_flight: (MIN_SPAN_REL * bounds.radius())
                .max(MIN_FLIGHT_VOXELS * field.source_spacing().unwrap_or(0.0)),
        }
    }
}

/// A ray on its way through the medium: everything the step loop carries from one step
/// to the next. [`March::begin`] enters the medium, [`March::advance`] takes one step (or
/// straight flight) and says when the ray is done; the packet tracer
/// (crate::packet) takes the plain steps inside of several rays at once between them.
#[derive(Debug, Clone)]
pub struct March<R: Real> {
    pub(crate) res: RayResult,
    pub(crate) state: RayState<R>,
    pub(crate) s0: FieldSample<R>,
    /// Roundoff of the state updates not yet added in (compensated summation, reset at
    /// every jump of the state: straight flights, surface hits, reflections).
    pub(crate) comp: RayState<R>,
    pub(crate) ctrl: StepController,
    pub(crate) estimate: ErrorEstimate,
    surface: Surface,
    pub(crate) bounds: Bounds,
    exit_tol: f64,
    pub(crate) min_flight: f64,
}

impl<R: Real> March<R> {
    /// Enter the medium: the march inside, or the finished result of a ray that never
    /// gets there (missed, bad input, reflected at the entry).
    // `Err` is the ray's result (as large as any result), not an error value to box.
    #[allow(clippy::result_large_err)]
    pub fn begin(
        field: &dyn IndexField,
        settings: &TraceSettings,
        origin: DVec3,
        dir: DVec3,
        first_step_scale: f64,
    ) -> Result<Self, RayResult> {
        let init = MarchStart::new::<R>(field, settings);
        Self::begin_from(&init, field, settings, origin, dir, first_step_scale)
    }

    /// [`Self::begin`] from what every ray of the trace starts with (`init`, made for
    /// this `field`, these `settings` and precision `R`).
    #[allow(clippy::result_large_err)]
    pub(crate) fn begin_from(
        init: &MarchStart,
        field: &dyn IndexField,
        settings: &TraceSettings,
        origin: DVec3,
        dir: DVec3,
        first_step_scale: f64,
    ) -> Result<Self, RayResult> {
        let mut res = RayResult::at(RayStatus::Error, origin, DVec3::ZERO);
        // A direction whose squared length overflows (1e308) or underflows (1e-320) is
        // scaled to its largest component first; any other is used as given.
        let len2 = dir.length_squared();
        let big = dir.abs().max_element();
        let dir =
            if (len2.is_infinite() || len2 < f64::MIN_POSITIVE) && big.is_finite() && big > 0.0 {
                dir / big
            } else {
                dir
            };
        let len2 = dir.length_squared();
        if !origin.is_finite() || !dir.is_finite() || len2 == 0.0 || !len2.is_finite() {
            res.direction = if dir.is_finite() && len2 > 0.0 {
                dir.normalize()
            } else {
                DVec3::ZERO
            };
            return Err(res);
        }
        let d = dir / len2.sqrt();
        res.direction = d;
        let bounds = init.bounds;
        // Direction error the crossings of the bounds add (the field's n uncertainty,
        // amplified at grazing angles): the entry's here, the exit's in `leave`.
        let mut surface = init.surface;
        let n_amb = surface.n_amb;
        // Entry (the field sampled where the ray enters is the march's first sample).
        let (start, d_in, s_entry) = if bounds.signed_distance(origin) < 0.0 {
            (origin, d, None)
        } else {
            let Some((s_in, s_out)) = bounds.intersect(origin, d) else {
                res.status = RayStatus::Missed;
                return Err(res);
            };
            if s_out < 0.0 || s_out <= s_in {
                res.status = RayStatus::Missed;
                return Err(res);
            }
            // `origin + d s_in` is off the surface by the rounding of the origin's
            // coordinates: from far away (1e-10 from 1e6 away) by more than the entry
            // nudge's few ulps of the medium can bring inside, and a ray begun outside
            // would leave at once. Such a point is put on the surface.
            let p = origin + d * s_in.max(0.0);
            let p = if bounds.signed_distance(p) > entry_nudge::<R>(&bounds, p) {
                project_to_surface(&bounds, p)
            } else {
                p
            };
            let entry = R::sample_field(field, R::V3::from_dvec3(p));
            let n_in = entry.n.to_f64();
            res.evals += 1;
            if !(n_in.is_finite() && n_in > 0.0) {
                res.position = p;
                return Err(res);
            }
            let normal = bounds.normal(p);
            surface.error += refraction_uncertainty(d, normal, n_amb, n_in, n_in, surface.dn);
            match refract(d, normal, n_amb, n_in) {
                Interface::Transmitted { dir, reflectance } => {
                    res.transmittance *= 1.0 - reflectance;
                    (p, dir, Some(entry))
                }
                Interface::Reflected { dir } => {
                    res.crossing_uncertainty = surface.error;
                    res.status = if surface.error > CROSSING_FACTOR * settings.accuracy {
                        RayStatus::Degraded
                    } else {
                        RayStatus::Exited
                    };
                    res.position = p;
                    res.direction = dir;
                    return Err(res);
                }
            }
        };

        let (r, skip) = if s_entry.is_some() {
            nudge_inside::<R>(&bounds, start, d_in)
        } else {
            (R::V3::from_dvec3(start), 0.0)
        };
        let s0 = match s_entry {
            Some(s) => s,
            None => {
                res.evals += 1;
                R::sample_field(field, r)
            }
        };
        // The field's pull over the skipped length (one Euler step of dT/ds = grad n).
        let state = RayState {
            r,
            t: R::V3::from_dvec3(d_in) * s0.n + s0.grad_n * R::from_f64(skip),
        };
        Ok(March {
            res,
            state,
            s0,
            comp: RayState::<R>::zero(),
            ctrl: init.ctrl.clone().with_jitter(first_step_scale),
            estimate: init.estimate,
            surface,
            bounds,
            exit_tol: init.exit_tol,
            min_flight: init.min_flight,
        })
    }

    /// One step (or straight flight) of the march; the finished result when the ray is
    /// done (left, stopped, failed).
    pub fn advance(
        &mut self,
        field: &dyn IndexField,
        settings: &TraceSettings,
        observer: &mut dyn FnMut(&Segment) -> Control,
    ) -> Option<RayResult> {
        let (bounds, exit_tol, min_flight) = (self.bounds, self.exit_tol, self.min_flight);
        let (mut state, mut s0, mut comp) = (self.state, self.s0, self.comp);
        let res = &mut self.res;
        let ctrl = &mut self.ctrl;
        let estimate = &mut self.estimate;
        let surface = &mut self.surface;
        let out = 'step: {
            let r = state.r;
            res.position = r.to_dvec3();
            res.direction = Vec3Like::to_dvec3(state.t).normalize_or_zero();
            let n_ok = s0.n.is_finite() && s0.n > R::zero();
            if !is_finite_v::<R>(r) || !is_finite_v::<R>(state.t) || !n_ok {
                res.status = RayStatus::Error;
                break 'step Some(*res);
            }
            if res.steps >= settings.max_steps {
                res.status = RayStatus::MaxSteps;
                break 'step Some(*res);
            }

            // Straight flight through a homogeneous macro cell.
            if settings.macro_cells
                && let Some(span) = field.homogeneous_span(res.position, res.direction)
                && span > min_flight
            {
                let p = res.position;
                let dir_w = res.direction;
                let to_exit = bounds
                    .intersect(p, dir_w)
                    .map_or(0.0, |(_, s_out)| s_out.max(0.0));
                let fly = span.min(to_exit);
                let exits = span >= to_exit;
                let mut p1 = p + dir_w * fly;
                if exits {
                    p1 = project_to_surface(&bounds, p1);
                }
                let n = s0.n.to_f64();
                res.length += fly;
                res.opl += n * fly;
                res.swept += dir_w * fly;
                res.steps += 1;
                let seg = Segment {
                    r0: p,
                    t0: dir_w * n,
                    r1: p1,
                    t1: dir_w * n,
                    h: fly / n,
                };
                if observer(&seg) == Control::Stop {
                    res.status = RayStatus::Absorbed;
                    res.position = p1;
                    break 'step Some(*res);
                }
                state.r = R::V3::from_dvec3(p1);
                comp = RayState::zero();
                s0 = R::sample_field(field, state.r);
                res.evals += 1;
                estimate.break_sequence();
                if exits {
                    // Reflected totally: the march goes on from the surface (below, the
                    // state written back).
                    if let Some(done) = leave(&bounds, res, &mut state, &s0, p1, estimate, surface)
                    {
                        break 'step Some(done);
                    }
                }
                break 'step None;
            }

            let mut taken: Taken<R> = ctrl.take(field, state, &s0);
            res.evals += u64::from(taken.evals);
            let mut outside = bounds.signed_distance(taken.step.state.r.to_dvec3()) > 0.0;
            if !outside
                && let Some(cut) = excursion_step(field, settings, &bounds, state, &s0, &taken)
            {
                // The step left the medium and came back between its ends: cut it where it
                // is outside, so the exit search below finds the first crossing (no tunnel).
                res.evals += u64::from(cut.evals);
                taken = cut;
                outside = true;
            }
            let mut next = integrate::add_compensated(state, taken.step.delta, &mut comp);
            let mut h = taken.h;
            let mut quad = taken.step.quad;
            if outside && is_finite_v::<R>(next.r) {
                let (exit_state, exit_h, evals, exit_quad) =
                    exit_medium(field, settings, &bounds, state, &s0, &taken, exit_tol);
                res.evals += u64::from(evals);
                next = exit_state;
                h = exit_h;
                quad = exit_quad;
                comp = RayState::zero();
            }
            let s1 = match taken.step.end {
                Some(e) if !outside => e,
                _ => {
                    res.evals += 1;
                    R::sample_field(field, next.r)
                }
            };
            self.state = state;
            self.s0 = s0;
            self.comp = comp;
            return self.record_step(
                observer,
                StepTaken {
                    next,
                    s1,
                    h,
                    quad,
                    error: taken.step.error,
                    check: taken.step.check,
                    outside,
                },
            );
        };
        self.state = state;
        self.s0 = s0;
        self.comp = comp;
        out
    }

    /// Finish a step that left the medium, its exit found on the surface by the packet
    /// tracer (crate::packet) as [`exit_medium`] finds it: the sample there, then what
    /// [`March::advance`] records of a step that leaves.
    pub(crate) fn finish_exit(
        &mut self,
        field: &dyn IndexField,
        observer: &mut dyn FnMut(&Segment) -> Control,
        exit: ExitFound<R>,
    ) -> Option<RayResult> {
        self.comp = RayState::zero();
        self.res.evals += 1;
        let s1 = R::sample_field(field, exit.next.r);
        self.record_step(
            observer,
            StepTaken {
                next: exit.next,
                s1,
                h: exit.h,
                quad: exit.quad,
                error: exit.error,
                check: None,
                outside: true,
            },
        )
    }

    /// Record the step from the march's state to `step.next`: its length, optical path
    /// and swept vector, the ray's error estimate, the observer's say; then the march
    /// stands at the step's end, and a step that left refracts out (or reflects back).
    fn record_step(
        &mut self,
        observer: &mut dyn FnMut(&Segment) -> Control,
        step: StepTaken<R>,
    ) -> Option<RayResult> {
        let StepTaken {
            next,
            s1,
            h,
            quad,
            error,
            check,
            outside,
        } = step;
        let (state, s0, bounds) = (self.state, self.s0, self.bounds);
        let res = &mut self.res;
        let estimate = &mut self.estimate;
        let seg = accumulate(res, state, &s0, next, &s1, h, quad);
        // The ray's own error estimate: the step's reported local error, a fourth-order
        // step's companion against D at its end (not where the step was cut at the
        // surface: D there is not where its companion ends), or the low orders' formulas.
        let d1 = s1.n_grad_n().to_dvec3();
        let h64 = h.to_f64();
        let reported = match (error, check) {
            (Some((er, et)), _) => Some((er.to_dvec3(), et.to_dvec3())),
            (None, Some(check)) if !outside => {
                let et = (d1 - check.to_dvec3()) * (h64 / 6.0);
                Some((et * (0.5 * h64), et))
            }
            _ => None,
        };
        estimate.step(
            state.t.to_dvec3(),
            next.t.to_dvec3(),
            s0.n_grad_n().to_dvec3(),
            d1,
            h64,
            s0.n.to_f64(),
            reported,
        );
        if !outside {
            let p = next.r.to_dvec3();
            estimate.check_approach(
                -bounds.signed_distance(p),
                || bounds.normal(p),
                next.t.to_dvec3(),
                s1.n.to_f64(),
                d1,
                h64,
            );
        }
        res.steps += 1;
        if observer(&seg) == Control::Stop {
            res.status = RayStatus::Absorbed;
            res.position = seg.r1;
            res.direction = seg.t1.normalize_or_zero();
            return Some(*res);
        }
        self.state = next;
        self.s0 = s1;
        if outside {
            let p = next.r.to_dvec3();
            return leave(
                &bounds,
                res,
                &mut self.state,
                &s1,
                p,
                estimate,
                &mut self.surface,
            );
        }
        None
    }
}

/// A step as [`March::record_step`] records it: the state it reached and the sample
/// there, its t-length, its quadrature where it has one, its reported local errors or
/// its fourth-order companion's D, and whether it left the medium.
struct StepTaken<R: Real> {
    next: RayState<R>,
    s1: FieldSample<R>,
    h: R,
    quad: Option<integrate::Quad>,
    error: Option<(R::V3, R::V3)>,
    check: Option<R::V3>,
    outside: bool,
}

/// The medium's surface as a ray crosses it: the ambient index, the field's n
/// uncertainty there, and the direction error the crossings so far added.
#[derive(Debug, Clone, Copy)]
struct Surface {
    n_amb: f64,
    dn: f64,
    error: f64,
    /// The accuracy asked for (rad) and the integration estimate's limit
    /// (`TraceSettings`).
    accuracy: f64,
    estimate_limit: f64,
}

/// At the surface point `p` with the inside state `state`: refract out (returns the
/// finished result: `exited`, or `degraded` where the error `estimate` or the
/// crossings' uncertainty is above its limit) or reflect totally back inside (updates
/// `state`, returns None).
fn leave<R: Real>(
    bounds: &Bounds,
    res: &mut RayResult,
    state: &mut RayState<R>,
    s: &FieldSample<R>,
    p: DVec3,
    estimate: &mut ErrorEstimate,
    surface: &mut Surface,
) -> Option<RayResult> {
    let n_in = s.n.to_f64();
    let n_amb = surface.n_amb;
    let d_in = state.t.to_dvec3().normalize_or_zero();
    // A total reflection the index error could have turned into a transmission (or the
    // reverse) makes the rest of the ray uncertain too: it is kept in `surface.error`.
    let normal = bounds.normal(p);
    surface.error += refraction_uncertainty(d_in, normal, n_in, n_amb, n_in, surface.dn);
    match refract(d_in, normal, n_in, n_amb) {
        Interface::Transmitted { dir, reflectance } => {
            res.transmittance *= 1.0 - reflectance;
            res.error_estimate =
                estimate.value(state.t.to_dvec3(), n_in, normal, s.n_grad_n().to_dvec3());
            res.crossing_uncertainty = surface.error;
            res.status = if res.error_estimate > surface.estimate_limit
                || surface.error > CROSSING_FACTOR * surface.accuracy
            {
                RayStatus::Degraded
            } else {
                RayStatus::Exited
            };
            res.position = p;
            res.direction = dir;
            Some(*res)
        }
        Interface::Reflected { .. } => {
            estimate.break_sequence();
            // Mirror T itself (not n times the unit direction), so |T| and the components
            // along the surface are kept exactly.
            let normal = R::V3::from_dvec3(normal);
            state.t = state.t - normal * (R::from_f64(2.0) * state.t.dot(normal));
            None
        }
    }
}

/// Add one step's length, optical path and swept vector (n, n^2 and n u integrated over t
/// by the step's own quadrature where it has one (dopri: [`integrate::Quad`]), else by the
/// cubic Hermite rule: h/2 (f0 + f1) + h^2/12 (f0' - f1'), f' from n' = grad n . T and
/// u' = grad n - u (u . grad n)) and return its segment.
fn accumulate<R: Real>(
    res: &mut RayResult,
    a: RayState<R>,
    sa: &FieldSample<R>,
    b: RayState<R>,
    sb: &FieldSample<R>,
    h: R,
    quad: Option<integrate::Quad>,
) -> Segment {
    let h = h.to_f64();
    let (n0, n1) = (sa.n.to_f64(), sb.n.to_f64());
    let (t0, t1) = (a.t.to_dvec3(), b.t.to_dvec3());
    let segment = Segment {
        r0: a.r.to_dvec3(),
        t0,
        r1: b.r.to_dvec3(),
        t1,
        h,
    };
    if let Some(q) = quad {
        let (opl, length, swept) = q.with_start(n0, t0, h);
        res.opl += opl;
        res.length += length;
        res.swept += swept;
        return segment;
    }
    let dn0 = sa.grad_n.to_dvec3().dot(t0);
    let dn1 = sb.grad_n.to_dvec3().dot(t1);
    let h2 = h * h / 12.0;
    res.length += 0.5 * h * (n0 + n1) + h2 * (dn0 - dn1);
    res.opl += 0.5 * h * (n0 * n0 + n1 * n1) + h2 * 2.0 * (n0 * dn0 - n1 * dn1);
    let (g0, g1) = (sa.grad_n.to_dvec3(), sb.grad_n.to_dvec3());
    let (u0, u1) = (t0.normalize_or_zero(), t1.normalize_or_zero());
    let d_swept = |n: f64, dn: f64, u: DVec3, g: DVec3| u * dn + (g - u * u.dot(g)) * n;
    res.swept += (u0 * n0 + u1 * n1) * (0.5 * h)
        + (d_swept(n0, dn0, u0, g0) - d_swept(n1, dn1, u1, g1)) * h2;
    segment
}

/// The step from `s` that `taken` made, as a segment (its Hermite cubic in f64).
fn segment_of_step<R: Real>(s: RayState<R>, taken: &Taken<R>) -> Segment {
    Segment {
        r0: s.r.to_dvec3(),
        t0: s.t.to_dvec3(),
        r1: taken.step.state.r.to_dvec3(),
        t1: taken.step.state.t.to_dvec3(),
        h: taken.h.to_f64(),
    }
}

/// A step from `s` that ended inside: if its cubic dense output goes outside between the
/// ends (checked only when an end is within the step's length of the surface), the step
/// re-taken to the point farthest out, when the integrator agrees that point is outside.
pub fn excursion_step<R: Real>(
    field: &dyn IndexField,
    settings: &TraceSettings,
    bounds: &Bounds,
    s: RayState<R>,
    s0: &FieldSample<R>,
    taken: &Taken<R>,
) -> Option<Taken<R>> {
    let r0 = s.r.to_dvec3();
    let r1 = taken.step.state.r.to_dvec3();
    let h = taken.h.to_f64();
    let reach = h * s
        .t
        .to_dvec3()
        .length()
        .max(taken.step.state.t.to_dvec3().length());
    let sd = |p: DVec3| bounds.signed_distance(p);
    if !(reach.is_finite() && r1.is_finite()) || (sd(r0) < -reach && sd(r1) < -reach) {
        return None;
    }
    let slack = EXCURSION_SLACK_TOLS * exit_tolerance::<R>(bounds);
    let tau = segment_of_step(s, taken).excursion(sd, slack)?;
    let hm = R::from_f64(tau);
    let step = integrate::step(settings.integrator, field, s, s0.n_grad_n(), hm);
    (sd(step.state.r.to_dvec3()) > 0.0).then_some(Taken {
        evals: step.evals,
        step,
        h: hm,
    })
}

/// The step from `s` ended outside the bounds: find where it crosses the surface.
/// Returns the state on the surface (projected onto it for the Hermite method), the step
/// length in t that reaches it, the field evaluations spent, and the quadrature of the
/// step that reaches the surface where the integrator has one (the Hermite search's last
/// re-step).
pub fn exit_medium<R: Real>(
    field: &dyn IndexField,
    settings: &TraceSettings,
    bounds: &Bounds,
    s: RayState<R>,
    s0: &FieldSample<R>,
    taken: &Taken<R>,
    tol: f64,
) -> (RayState<R>, R, u32, Option<integrate::Quad>) {
    let kind = settings.integrator;
    let d0 = s0.n_grad_n();
    // The stopping tests in the trace's own precision (what the GPU computes in f32).
    let sd_r = |p: R::V3| bounds.signed_distance_in::<R>(p);
    match settings.exit {
        ExitMethod::Bisection => {
            let mut lo = 0.0;
            let mut hi = taken.h.to_f64();
            let mut evals = 0;
            let mut best = (s, R::zero());
            for _ in 0..MAX_BISECTIONS {
                let mid = 0.5 * (lo + hi);
                let hm = R::from_f64(mid);
                let st = integrate::step(kind, field, s, d0, hm);
                evals += st.evals;
                let dist = sd_r(st.state.r);
                if dist <= 0.0 {
                    best = (st.state, hm);
                }
                if dist.abs() <= tol {
                    return (st.state, hm, evals, st.quad);
                }
                if dist > 0.0 {
                    hi = mid;
                } else {
                    lo = mid;
                }
                if hi - lo <= mid * R::EPS.to_f64() {
                    break;
                }
            }
            // Precision exhausted (f32): the last point inside, on the surface.
            let (mut st, hm) = best;
            st.r = R::V3::from_dvec3(project_to_surface(bounds, st.r.to_dvec3()));
            (st, hm, evals, None)
        }
        ExitMethod::Hermite => {
            // The cubic's root is O(h^4) off the integrator's own crossing; Newton steps
            // on the integrator's state bring it to the integrator's order. Each costs
            // one re-step; kept only if closer (ExitSearch, the packets' search too).
            let mut search = ExitSearch::<R>::begin(bounds, segment_of_step(s, taken), None);
            let mut evals = 0;
            while search.phase == Phase::Search {
                let st = integrate::step(kind, field, s, d0, R::from_f64(search.trial));
                evals += st.evals;
                search.restepped(bounds, tol, st.state, st.quad);
            }
            let exit = search.found(bounds);
            (exit.next, exit.h, evals, exit.quad)
        }
    }
}
