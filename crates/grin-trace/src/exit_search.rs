//! The Hermite exit search of a step that left the medium: the root of the step's cubic,
//! then Newton re-steps on the integrator's own state (g = signed distance, g' = normal .
//! T), each kept only if closer to the surface. One search, driven two ways: one ray's
//! re-steps in a loop ([`crate::trace::exit_medium`]), and a packet lane's re-steps as
//! packet steps beside the other lanes' (crate::packet), so both find the same exit bit
//! for bit; the march then records the step ([`crate::trace::March`]'s `finish_exit`
//! for the packets).

use grin_field::{Bounds, Real, Vec3Like};

use crate::boundary::{Segment, project_to_surface};
use crate::integrate::{Quad, RayState};
use crate::trace::EXIT_NEWTON_ITERATIONS;

/// Where an exit search stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Phase {
    /// No search (a packet lane that steps inside, or waits for its march).
    Idle,
    /// A re-step at [`ExitSearch::trial`] is due.
    Search,
    /// The exit is found.
    Found,
}

/// One step's exit search, in precision `R`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct ExitSearch<R: Real> {
    pub(crate) phase: Phase,
    /// The t-length of the step that left: the re-steps stay within it.
    h_max: f64,
    /// The t-length of the re-step kept, and of the one due.
    tau: f64,
    pub(crate) trial: f64,
    /// Re-steps taken: the first at the cubic's root, then Newton's.
    resteps: u32,
    kept: RayState<R>,
    quad: Option<Quad>,
    /// The local errors (position, T) the step that left reported (dopri).
    error: Option<(R::V3, R::V3)>,
}

/// A step that left the medium, cut on the surface by its [`ExitSearch`]: the state there
/// (projected onto the surface), the t-length that reaches it, the quadrature of the
/// re-step that reached it, and the local errors the step that left reported.
#[derive(Debug, Clone, Copy)]
pub(crate) struct ExitFound<R: Real> {
    pub(crate) next: RayState<R>,
    pub(crate) h: R,
    pub(crate) quad: Option<Quad>,
    pub(crate) error: Option<(R::V3, R::V3)>,
}

impl<R: Real> ExitSearch<R> {
    /// No search.
    pub(crate) fn idle() -> Self {
        ExitSearch {
            phase: Phase::Idle,
            h_max: 0.0,
            tau: 0.0,
            trial: 0.0,
            resteps: 0,
            kept: RayState::zero(),
            quad: None,
            error: None,
        }
    }

    /// The search for the step `seg` (from the ray's state, over `seg.h`), which ended
    /// outside: its first re-step is due at the cubic's first crossing of the surface.
    #[inline]
    pub(crate) fn begin(bounds: &Bounds, seg: Segment, error: Option<(R::V3, R::V3)>) -> Self {
        let tau = seg.first_crossing(|p| bounds.signed_distance(p));
        ExitSearch {
            phase: Phase::Search,
            h_max: seg.h,
            tau,
            trial: tau,
            error,
            ..ExitSearch::idle()
        }
    }

    /// The re-step due reached `state` (with the quadrature `quad`): the first is kept,
    /// a Newton re-step only where it is closer to the surface (else the search ends);
    /// then the next Newton re-step is due, unless the point kept is within `tol` of the
    /// surface, the ray runs along or into it there, or the iterations are spent. The
    /// distances are the trace's own precision's (what the GPU computes in f32).
    #[inline]
    pub(crate) fn restepped(
        &mut self,
        bounds: &Bounds,
        tol: f64,
        state: RayState<R>,
        quad: Option<Quad>,
    ) {
        let sd = |p: R::V3| bounds.signed_distance_in::<R>(p);
        // Kept only if closer: a NaN distance is not closer, and ends the search.
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
        let slope = bounds.normal(state.r.to_dvec3()).dot(state.t.to_dvec3());
        if self.resteps > EXIT_NEWTON_ITERATIONS || g.abs() <= tol || slope.is_nan() || slope <= 0.0
        {
            self.phase = Phase::Found;
            return;
        }
        self.trial = (self.tau - g / slope).clamp(0.0, self.h_max);
    }

    /// The exit the search found: the point kept, projected onto the surface.
    pub(crate) fn found(&self, bounds: &Bounds) -> ExitFound<R> {
        let mut next = self.kept;
        next.r = R::V3::from_dvec3(project_to_surface(bounds, next.r.to_dvec3()));
        ExitFound {
            next,
            h: R::from_f64(self.tau),
            quad: self.quad,
            error: self.error,
        }
    }

    /// The exit found, if the search is over; no search after.
    pub(crate) fn take_found(&mut self, bounds: &Bounds) -> Option<ExitFound<R>> {
        if self.phase != Phase::Found {
            return None;
        }
        let found = self.found(bounds);
        *self = ExitSearch::idle();
        Some(found)
    }
}
