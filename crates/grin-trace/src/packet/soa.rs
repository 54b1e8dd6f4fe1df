//! The lanes' march state as lane vectors, and its moves to and from a ray's march.

use grin_field::FieldSample;

use super::LANES;
use super::lanes::{L, V};
use crate::exit_search::{ExitSearch, Phase};
use crate::trace::March;

/// The lanes' march state as lane vectors.
#[derive(Debug, Clone, Copy)]
pub(super) struct Soa {
    pub(super) r: V,
    pub(super) t: V,
    pub(super) comp_r: V,
    pub(super) comp_t: V,
    pub(super) n0: L,
    pub(super) g0: V,
    pub(super) opl: L,
    pub(super) length: L,
    pub(super) swept: V,
    // The error estimate (crate::estimate::ErrorEstimate): the parts a fourth-order
    // integrator's estimate reads (`prev` and `staggered_half` are read only for the
    // second-order and staggered integrators, which packets do not take).
    pub(super) near_miss: [bool; LANES],
    pub(super) last_local: V,
    pub(super) last_r: L,
    pub(super) bend: L,
    pub(super) pos: L,
    pub(super) vsum: V,
    pub(super) sum: L,
    pub(super) steps: [u32; LANES],
    pub(super) evals: [u64; LANES],
    // Error control (dopri packets): the step the next attempt tries, and the take under
    // way (an accepted step may need its march after all: the lane then goes back to
    // where its take began, so the march takes it again from there, the same way).
    pub(super) ds_adapt: L,
    pub(super) in_take: [bool; LANES],
    pub(super) take_ds: L,
    pub(super) take_evals: [u64; LANES],
    pub(super) take_cap: L,
    pub(super) rejections: [u32; LANES],
    // The exit search of lanes whose step left the medium (its re-steps are packet
    // steps too).
    pub(super) exits: [ExitSearch<f64>; LANES],
}

impl Soa {
    #[inline]
    pub(super) fn new() -> Soa {
        Soa {
            r: V::zero(),
            t: V::zero(),
            comp_r: V::zero(),
            comp_t: V::zero(),
            n0: L::splat(1.0),
            g0: V::zero(),
            opl: L::splat(0.0),
            length: L::splat(0.0),
            swept: V::zero(),
            near_miss: [true; LANES],
            last_local: V::zero(),
            last_r: L::splat(0.0),
            bend: L::splat(0.0),
            pos: L::splat(0.0),
            vsum: V::zero(),
            sum: L::splat(0.0),
            steps: [0; LANES],
            evals: [0; LANES],
            ds_adapt: L::splat(0.0),
            in_take: [false; LANES],
            take_ds: L::splat(0.0),
            take_evals: [0; LANES],
            take_cap: L::splat(0.0),
            rejections: [0; LANES],
            exits: [ExitSearch::idle(); LANES],
        }
    }

    /// Whether lane `i`, not searching for its exit, may take a step as the one-ray tracer
    /// would (`March::advance`'s first tests): a finite state, n > 0, steps left.
    #[inline(always)]
    pub(super) fn may_step(&self, i: usize, max_steps: u32) -> bool {
        let n0 = self.n0.0[i];
        self.exits[i].phase == Phase::Idle
            && self.r.finite(i)
            && self.t.finite(i)
            && n0.is_finite()
            && n0 > 0.0
            && self.steps[i] < max_steps
    }

    /// Move march `m`'s state into lane `i`.
    #[inline]
    pub(super) fn load(&mut self, i: usize, m: &March<f64>) {
        let s = self;
        s.r.set(i, m.state.r);
        s.t.set(i, m.state.t);
        s.comp_r.set(i, m.comp.r);
        s.comp_t.set(i, m.comp.t);
        s.n0.0[i] = m.s0.n;
        s.g0.set(i, m.s0.grad_n);
        s.opl.0[i] = m.res.opl;
        s.length.0[i] = m.res.length;
        s.swept.set(i, m.res.swept);
        s.steps[i] = m.res.steps;
        s.evals[i] = m.res.evals;
        let e = &m.estimate;
        s.near_miss[i] = e.near_miss;
        s.last_local.set(i, e.last.0);
        s.last_r.0[i] = e.last.1;
        s.bend.0[i] = e.bend;
        s.pos.0[i] = e.pos;
        s.vsum.set(i, e.vsum);
        s.sum.0[i] = e.sum;
        s.ds_adapt.0[i] = m.ctrl.current_ds();
        s.in_take[i] = false;
        s.exits[i] = ExitSearch::idle();
    }

    /// Write lane `i` back into its march. The march's reported position and direction
    /// are left to [`March::advance`], which sets them from the state first thing.
    #[inline]
    pub(super) fn store(&self, i: usize, m: &mut March<f64>) {
        m.state.r = self.r.lane(i);
        m.state.t = self.t.lane(i);
        m.comp.r = self.comp_r.lane(i);
        m.comp.t = self.comp_t.lane(i);
        m.s0 = FieldSample {
            n: self.n0.0[i],
            grad_n: self.g0.lane(i),
        };
        m.res.opl = self.opl.0[i];
        m.res.length = self.length.0[i];
        m.res.swept = self.swept.lane(i);
        m.res.steps = self.steps[i];
        m.res.evals = self.evals[i];
        let e = &mut m.estimate;
        e.near_miss = self.near_miss[i];
        e.last = (self.last_local.lane(i), self.last_r.0[i]);
        e.bend = self.bend.0[i];
        e.pos = self.pos.0[i];
        e.vsum = self.vsum.lane(i);
        e.sum = self.sum.0[i];
        m.ctrl.set_current_ds(self.ds_adapt.0[i]);
    }
}
