//! The exit search of a packet lane whose step left the medium: [`exit_medium`]'s
//! Hermite method (the root of the step's cubic, then Newton re-steps on the integrator's
//! own state, each kept only if closer to the surface), its re-steps taken in the packet
//! beside the other lanes' steps. The arithmetic per lane is the one-ray tracer's, so
//! the exit found is the same bit for bit; the march then records the step
//! ([`March::finish_exit`]).
//!
//! [`exit_medium`]: crate::trace::exit_medium
//! [`March::finish_exit`]: crate::trace::March

use glam::DVec3;
use grin_field::Bounds;

use crate::boundary::{Segment, project_to_surface};
use crate::integrate::{Quad, RayState};
use crate::trace::{EXIT_NEWTON_ITERATIONS, ExitFound};

/// Where a lane's exit search stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Phase {
    /// No search: the lane steps inside (or waits for its march).
    Idle,
    /// A re-step at [`LaneExit::trial`] is due.
    Search,
    /// The exit is found: the lane's march records the step.
    Found,
}

/// One lane's exit search.
#[derive(Debug, Clone, Copy)]
pub(super) struct LaneExit {
    pub(super) phase: Phase,
    /// The t-length of the step that left: the re-steps stay within it.
    h_max: f64,
    /// The t-length of the re-step kept, and of the one due.
    tau: f64,
    pub(super) trial: f64,
    /// Re-steps taken: the first at the cubic's root, then Newton's.
    resteps: u32,
    kept: RayState<f64>,
    quad: Option<Quad>,
    /// The local errors (position, T) the step that left reported (dopri).
    error: Option<(DVec3, DVec3)>,
}

impl LaneExit {
    pub(super) const IDLE: LaneExit = LaneExit {
        phase: Phase::Idle,
        h_max: 0.0,
        tau: 0.0,
        trial: 0.0,
        resteps: 0,
        kept: RayState {
            r: DVec3::ZERO,
            t: DVec3::ZERO,
        },
        quad: None,
        error: None,
    };

    /// The search for the step `seg` (from the lane's state, over `seg.h`), which ended
    /// outside: its first re-step is due at the cubic's first crossing of the surface.
    pub(super) fn begin(bounds: &Bounds, seg: Segment, error: Option<(DVec3, DVec3)>) -> Self {
        let tau = seg.first_crossing(|p| bounds.signed_distance(p));
        LaneExit {
            phase: Phase::Search,
            h_max: seg.h,
            tau,
            trial: tau,
            error,
            ..LaneExit::IDLE
        }
    }

    /// The re-step due reached `state` (with the quadrature `quad`): the first is kept,
    /// a Newton re-step only where it is closer to the surface (else the search ends);
    /// then the next Newton re-step is due, unless the point kept is within `tol` of the
    /// surface, the ray runs along or into it there, or the iterations are spent.
    pub(super) fn restepped(
        &mut self,
        bounds: &Bounds,
        tol: f64,
        state: RayState<f64>,
        quad: Option<Quad>,
    ) {
        let sd = |p: DVec3| bounds.signed_distance_in::<f64>(p);
        // Kept only if closer (exit_medium's test): a NaN distance is not closer, and
        // ends the search there as here.
        let closer = sd(state.r).abs() < sd(self.kept.r).abs();
        if self.resteps > 0 && !closer {
            self.phase = Phase::Found;
            return;
        }
        self.tau = self.trial;
        self.kept = state;
        self.quad = quad;
        self.resteps += 1;
        let g = sd(state.r);
        let slope = bounds.normal(state.r).dot(state.t);
        if self.resteps > EXIT_NEWTON_ITERATIONS || g.abs() <= tol || slope.is_nan() || slope <= 0.0
        {
            self.phase = Phase::Found;
            return;
        }
        self.trial = (self.tau - g / slope).clamp(0.0, self.h_max);
    }

    /// The exit found (the point kept, projected onto the surface), if the search is
    /// over; the lane is idle after.
    pub(super) fn take_found(&mut self, bounds: &Bounds) -> Option<ExitFound<f64>> {
        if self.phase != Phase::Found {
            return None;
        }
        let done = std::mem::replace(self, LaneExit::IDLE);
        let mut next = done.kept;
        next.r = project_to_surface(bounds, next.r);
        Some(ExitFound {
            next,
            h: done.tau,
            quad: done.quad,
            error: done.error,
        })
    }
}
