//! Step policies: how long the next step is. Lengths are world lengths ds; the tracer
//! converts them to the t parameter by h = ds / n at the step start. Fixed, the paper's
//! gradient heuristic, and error control (the adaptive pair's embedded estimate, or step
//! doubling with Richardson's error estimate for the fixed-order integrators).

use glam::DVec3;
use grin_field::{FieldSample, IndexField, Real, Vec3Like};
use grin_scene::{IntegratorKind, StepSpec};

use crate::integrate::{self, RayState, Step};

/// Error-controlled steps never grow beyond this fraction of the bounds' radius, so the
/// step that leaves the medium stays short enough for a well-conditioned exit search.
pub const ADAPTIVE_MAX_DS_REL: f64 = 0.25;
/// ... nor shrink below this fraction (then the step is taken anyway: no endless loop).
pub const ADAPTIVE_MIN_DS_REL: f64 = 1e-12;
/// In precision R the smallest step is also >= this many units of roundoff (times the
/// radius): below it r + ds rounds back to r in f32 and the ray would stall.
pub const ADAPTIVE_MIN_DS_EPS: f64 = 1e3;
/// Tolerances are raised to at least this many units of roundoff (times the radius): an
/// f32 trace cannot resolve 1e-10, and step doubling would shrink the steps to nothing.
/// The roundoff is the trace's or the field's samples' (`IndexField::sample_eps`: a baked
/// grid's f32), whichever is coarser.
pub const ADAPTIVE_TOL_FLOOR_EPS: f64 = 2.0;
/// Default first error-controlled step, as a fraction of the bounds' radius.
pub const ADAPTIVE_INITIAL_DS_REL: f64 = 0.01;
/// Safety factor and growth limits of the step-size controller (Hairer, Norsett & Wanner, II.4).
pub const SAFETY: f64 = 0.9;
pub const MAX_GROWTH: f64 = 5.0;
pub const MIN_SHRINK: f64 = 0.2;
/// Rejections allowed for one step before it is taken at the smallest size.
pub const MAX_REJECTIONS: u32 = 60;
/// Every step (fixed, heuristic or error-controlled) is at most this fraction of the
/// field's local length scale n / |grad n| at the step's start. Where n is small the t
/// step h = ds / n grows like 1/n while T = n d shrinks: without the cap one step can
/// reverse T and "reflect" a ray (n -> 0 on axis: pi rad off, reported `exited`). In air
/// the scale is ~10^2 m and the cap never acts.
pub const LENGTH_SCALE_STEP_FRACTION: f64 = 0.5;
/// Steps of every policy are at most this many of the field's feature size
/// (`IndexField::feature_size`): a step that long still puts several of a Runge-Kutta
/// step's stages inside any feature it crosses (a plume of width s = 0.01 R: dopri at
/// tolerance 1e-9 passed over it, 8e-2 rad off, before this cap).
pub const FEATURE_STEP_FRACTION: f64 = 1.0;

/// What an error-controlled step's error (world length) is held to.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Tolerance {
    /// At most this much per step (`step = { adaptive = ... }`).
    PerStep(f64),
    /// At most this much per unit of path length (`step = { auto = ... }`): the errors
    /// of all steps then add up to at most this times the path, whatever the
    /// integrator's order, so an asked exit-direction error maps to one number.
    PerLength(f64),
}

impl Tolerance {
    /// What a step of length `ds` is held to (before the floor).
    pub(crate) fn for_step(self, ds: f64) -> f64 {
        match self {
            Tolerance::PerStep(t) => t,
            Tolerance::PerLength(t) => t * ds,
        }
    }
}

/// The factor on the next error-controlled step after one of error `err` held to `tol`
/// (Hairer, Norsett & Wanner, II.4; `exponent` 1 / (the lower order + 1)).
pub(crate) fn step_factor(err: f64, tol: f64, exponent: f64) -> f64 {
    if err > 0.0 && err.is_finite() {
        (SAFETY * (tol / err).powf(exponent)).clamp(MIN_SHRINK, MAX_GROWTH)
    } else if err == 0.0 {
        MAX_GROWTH
    } else {
        MIN_SHRINK
    }
}

/// A dopri controller's constants ([`StepController::dopri_control`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct DopriControl {
    /// `None`: fixed steps of `ds_max`.
    pub tol: Option<Tolerance>,
    pub ds_max: f64,
    pub len_scale: f64,
    /// The optical path's error is in the norm ([`StepController::with_opl_control`]).
    pub opl: bool,
}

/// Chooses step lengths along one ray (error control keeps its state between steps).
#[derive(Debug, Clone)]
pub struct StepController {
    spec: StepSpec,
    kind: IntegratorKind,
    /// Length scale of the medium (bounds radius): the error norm weighs direction errors
    /// by it, and it bounds adaptive steps.
    len_scale: f64,
    /// Heuristic amplitude (|grad n| at which the step is the minimum).
    amplitude: f64,
    /// [`FEATURE_STEP_FRACTION`] of the field's feature size (infinite without one):
    /// no step of any policy is longer, so no feature is stepped over whole.
    feature_cap: f64,
    /// Longest error-controlled step: [`ADAPTIVE_MAX_DS_REL`] of the radius, or the
    /// feature cap when that is shorter.
    ds_max: f64,
    /// Current error-controlled step (world length).
    ds_adapt: f64,
    /// Factor on the next fixed or heuristic step (the renderer's per-pixel jitter of a
    /// passage's first step, then 1).
    jitter: f64,
    /// dopri's error control also holds the optical path's embedded error to the
    /// tolerance (where the output has the path: ray tables).
    weigh_opl: bool,
}

/// An accepted step with the t-length it covered.
#[derive(Debug, Clone, Copy)]
pub struct Taken<R: Real> {
    pub step: Step<R>,
    pub h: R,
    /// Field evaluations made, including rejected attempts.
    pub evals: u32,
}

impl StepController {
    pub fn new(spec: StepSpec, kind: IntegratorKind, field: &dyn IndexField) -> Self {
        let len_scale = field.bounds().radius();
        let amplitude = match spec {
            StepSpec::Heuristic {
                amplitude: Some(a), ..
            } => a,
            StepSpec::Heuristic {
                amplitude: None, ..
            } => field.max_grad_n(),
            _ => 0.0,
        };
        let ds_adapt = match spec {
            StepSpec::Adaptive {
                initial: Some(ds), ..
            } => ds,
            _ => ADAPTIVE_INITIAL_DS_REL * len_scale,
        };
        let feature_cap = field
            .feature_size()
            .filter(|f| f.is_finite() && *f > 0.0)
            .map_or(f64::INFINITY, |f| FEATURE_STEP_FRACTION * f);
        let ds_max = feature_cap.min(ADAPTIVE_MAX_DS_REL * len_scale);
        StepController {
            spec,
            kind,
            len_scale,
            amplitude,
            feature_cap,
            ds_max,
            ds_adapt,
            jitter: 1.0,
            weigh_opl: false,
        }
    }

    /// Hold the optical path's error, as well as the position's and direction's, to
    /// dopri's tolerance (`TraceSettings::opl_control`).
    pub fn with_opl_control(mut self, on: bool) -> Self {
        self.weigh_opl = on;
        self
    }

    /// Scale the first fixed or heuristic step by `jitter` in (0, 1] (turns the banding
    /// of synchronised steps into noise; adaptive steps are not jittered).
    pub fn with_jitter(mut self, jitter: f64) -> Self {
        self.jitter = jitter;
        self
    }

    /// Start error control at step `ds` (world length) instead of the policy's first
    /// step: the state a controller has after some steps (the GPU stage tests set both
    /// backends' controllers to the same one).
    pub fn with_current_ds(mut self, ds: f64) -> Self {
        self.ds_adapt = ds;
        self
    }

    /// The fixed step (world length) the next [`Self::take`] takes before its caps, when
    /// the policy is a fixed step and the first step's jitter is spent.
    pub(crate) fn fixed_ds(&self) -> Option<f64> {
        match self.spec {
            StepSpec::Fixed(ds) if self.jitter == 1.0 => Some(ds),
            _ => None,
        }
    }

    /// No step is longer than this ([`FEATURE_STEP_FRACTION`] of the field's feature
    /// size; infinite without one).
    pub(crate) fn feature_cap(&self) -> f64 {
        self.feature_cap
    }

    /// The error-controlled step the next [`Self::take`] tries first.
    pub fn current_ds(&self) -> f64 {
        self.ds_adapt
    }

    /// Set the error-controlled step the next [`Self::take`] tries first (the packets
    /// write back what their steps left).
    pub(crate) fn set_current_ds(&mut self, ds: f64) {
        self.ds_adapt = ds;
    }

    /// How [`Self::take`] chooses a dopri step, where the integrator is dopri and the
    /// policy error control or a fixed step (its jitter spent): the tolerance (`None`
    /// for a fixed step), the step (the fixed one, or the longest error-controlled one
    /// before the local caps), and the medium's length scale (the error norm's).
    pub(crate) fn dopri_control(&self) -> Option<DopriControl> {
        if self.kind != IntegratorKind::Adaptive {
            return None;
        }
        let (tol, ds_max) = match self.spec {
            StepSpec::Adaptive { tolerance, .. } => {
                (Some(Tolerance::PerStep(tolerance)), self.ds_max)
            }
            StepSpec::Auto(accuracy) => (
                Some(Tolerance::PerLength(
                    grin_scene::AUTO_TOL_PER_RAD * accuracy,
                )),
                self.ds_max,
            ),
            StepSpec::Fixed(ds) if self.jitter == 1.0 => (None, ds),
            _ => return None,
        };
        Some(DopriControl {
            tol,
            ds_max,
            len_scale: self.len_scale,
            opl: self.weigh_opl,
        })
    }

    /// The jitter factor for this step; later steps get 1.
    fn take_jitter(&mut self) -> f64 {
        std::mem::replace(&mut self.jitter, 1.0)
    }

    /// The paper's heuristic: lerp(min, max, clamp(1 - |dir . grad n| / amplitude, 0, 1)).
    pub fn heuristic_ds(min: f64, max: f64, amplitude: f64, dir: DVec3, grad_n: DVec3) -> f64 {
        let w = if amplitude > 0.0 {
            (1.0 - dir.dot(grad_n).abs() / amplitude).clamp(0.0, 1.0)
        } else {
            1.0
        };
        min + (max - min) * w
    }

    /// Take one step from `s` (field sample `s0` there), choosing its length by the policy.
    /// Error-controlled policies retry rejected steps.
    pub fn take<R: Real>(
        &mut self,
        field: &dyn IndexField,
        s: RayState<R>,
        s0: &FieldSample<R>,
    ) -> Taken<R> {
        let n0 = s0.n.to_f64();
        let d0 = s0.n_grad_n();
        let mut cap =
            Self::length_scale_cap(n0, s0.grad_n.to_dvec3().length()).min(self.feature_cap);
        // The field's own local cap (an `expr` formula's feature map), looked up over the
        // reach of the step the policy would take.
        let reach = match self.spec {
            StepSpec::Fixed(ds) => ds * self.jitter,
            StepSpec::Heuristic { max, .. } => max * self.jitter,
            _ => self.ds_adapt.min(self.ds_max),
        }
        .min(cap);
        cap = cap.min(field.step_cap(s.r.to_dvec3(), reach));
        match self.spec {
            StepSpec::Fixed(ds) => {
                let h = R::from_f64((ds * self.take_jitter()).min(cap) / n0);
                let step = integrate::step(self.kind, field, s, d0, h);
                Taken {
                    evals: step.evals,
                    step,
                    h,
                }
            }
            StepSpec::Heuristic { min, max, .. } => {
                let dir = s.t.to_dvec3().normalize_or_zero();
                let ds = Self::heuristic_ds(min, max, self.amplitude, dir, s0.grad_n.to_dvec3());
                let h = R::from_f64((ds * self.take_jitter()).min(cap) / n0);
                let step = integrate::step(self.kind, field, s, d0, h);
                Taken {
                    evals: step.evals,
                    step,
                    h,
                }
            }
            StepSpec::Adaptive { tolerance, .. } => {
                self.take_adaptive(field, s, s0, Tolerance::PerStep(tolerance), cap)
            }
            StepSpec::Auto(accuracy) => self.take_adaptive(
                field,
                s,
                s0,
                Tolerance::PerLength(grin_scene::AUTO_TOL_PER_RAD * accuracy),
                cap,
            ),
        }
    }

    /// [`LENGTH_SCALE_STEP_FRACTION`] of n / |grad n| (infinite where grad n = 0).
    pub fn length_scale_cap(n: f64, grad_n: f64) -> f64 {
        if grad_n > 0.0 && grad_n.is_finite() {
            LENGTH_SCALE_STEP_FRACTION * n.abs() / grad_n
        } else {
            f64::INFINITY
        }
    }

    fn take_adaptive<R: Real>(
        &mut self,
        field: &dyn IndexField,
        s: RayState<R>,
        s0: &FieldSample<R>,
        tol: Tolerance,
        cap: f64,
    ) -> Taken<R> {
        let n0 = s0.n.to_f64();
        let d0 = s0.n_grad_n();
        let p = integrate::order(self.kind);
        // Error of the lower-order member: the exponent of the controller is 1/(p_low + 1).
        let exponent = 1.0 / p as f64;
        let eps = R::EPS.to_f64();
        let ds_min = ADAPTIVE_MIN_DS_REL.max(ADAPTIVE_MIN_DS_EPS * eps) * self.len_scale;
        // The floor is the trace's roundoff or the field's own, whichever is coarser.
        let tol_floor = ADAPTIVE_TOL_FLOOR_EPS * eps.max(field.sample_eps()) * self.len_scale;
        let ds_max = self.ds_max.min(cap).max(ds_min);
        let mut evals = 0;
        let mut rejections = 0;
        loop {
            let ds = self.ds_adapt.clamp(ds_min, ds_max);
            let h = R::from_f64(ds / n0);
            let (step, err) = if self.kind == IntegratorKind::Adaptive {
                let st = integrate::dopri_step(field, s, d0, h);
                let err = st.error.map_or(0.0, |(er, et)| self.norm::<R>(er, et, n0));
                let err = match st.quad {
                    Some(q) if self.weigh_opl => {
                        err.max(q.opl_error_with_start(n0, h.to_f64()).abs())
                    }
                    _ => err,
                };
                (st, err)
            } else {
                self.doubled(field, s, d0, h, p)
            };
            evals += step.evals;
            let tol = tol.for_step(ds).max(tol_floor);
            let accept = err <= tol || ds <= ds_min || rejections >= MAX_REJECTIONS;
            self.ds_adapt = (ds * step_factor(err, tol, exponent)).clamp(ds_min, ds_max);
            if accept {
                return Taken { step, h, evals };
            }
            rejections += 1;
        }
    }

    /// Step doubling: one step of h and two of h/2; the two half steps are kept and their
    /// difference to the full step, / (2^p - 1), estimates their error (Richardson).
    fn doubled<R: Real>(
        &self,
        field: &dyn IndexField,
        s: RayState<R>,
        d0: R::V3,
        h: R,
        p: u32,
    ) -> (Step<R>, f64) {
        let half = h * R::from_f64(0.5);
        let big = integrate::step(self.kind, field, s, d0, h);
        let first = integrate::step(self.kind, field, s, d0, half);
        let (mid, mid_evals) = match first.end {
            Some(e) => (e, 0),
            None => (R::sample_field(field, first.state.r), 1),
        };
        let second = integrate::step(self.kind, field, first.state, mid.n_grad_n(), half);
        let scale = R::from_f64(1.0 / ((1u32 << p) as f64 - 1.0));
        let er = (second.state.r - big.state.r) * scale;
        let et = (second.state.t - big.state.t) * scale;
        let err = self.norm::<R>(er, et, mid.n.to_f64());
        // The increments from `s`: the first half step as rounded (the second started
        // there), then the second's.
        let delta = RayState {
            r: (first.state.r - s.r) + second.delta.r,
            t: (first.state.t - s.t) + second.delta.t,
        };
        let step = Step {
            evals: big.evals + first.evals + mid_evals + second.evals,
            delta,
            error: Some((er, et)),
            check: None,
            quad: None,
            ..second
        };
        (step, err)
    }

    /// Error norm in world length: the position error, or the direction error carried
    /// across the medium (|e_T| / n times its radius), whichever is larger.
    fn norm<R: Real>(&self, er: R::V3, et: R::V3, n: f64) -> f64 {
        let pos = er.length().to_f64();
        let dir = et.length().to_f64() / n.abs().max(f64::MIN_POSITIVE) * self.len_scale;
        pos.max(dir)
    }
}
