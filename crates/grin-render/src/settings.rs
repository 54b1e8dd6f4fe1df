//! The tracer's settings, as both backends read them: integrator, step policy, exit
//! method, step cap, straight flights; checked against the medium they will march.

use grin_field::Bounds;
use grin_scene::{ExitMethod, IntegratorKind, RenderSettings, StepSpec};

/// What the tracer needs from a scene's `[render]` settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TraceSettings {
    pub integrator: IntegratorKind,
    pub step: StepSpec,
    /// Per-ray cap on steps (accepted steps and straight flights).
    pub max_steps: u32,
    pub exit: ExitMethod,
    /// Fly straight where `IndexField::homogeneous_span` says the field is constant.
    pub macro_cells: bool,
    /// The exit-direction error (rad) the trace is asked for: the `auto` value, or what
    /// the pilots resolved an output's accuracy to; for a step the scene fixed,
    /// [`grin_scene::DEFAULT_AUTO_ACCURACY`]. A ray ends `degraded`, not `exited`, where
    /// its own integration error estimate is above `estimate_limit`, or where the bake's
    /// n error amplified at its crossings of the bounds could be above
    /// `grin_trace::estimate::CROSSING_FACTOR` x this (`grin_trace::estimate`).
    pub accuracy: f64,
    /// The integration error estimate (rad) above which a ray is `degraded`: `accuracy`,
    /// or, where the pilots chose the method and measured it within `accuracy`,
    /// `grin_trace::auto::VOUCH_FACTOR` x `accuracy`.
    pub estimate_limit: f64,
    /// dopri's error control also holds each step's optical-path error to its tolerance
    /// (ray tables, whose `opl` column is an output; an image's pixels are not made of
    /// the path, so its steps are not shortened for it).
    pub opl_control: bool,
}

/// Settings that cannot drive a trace.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TraceError {
    #[error("step: {0}")]
    Step(String),
    #[error("max_steps must be in 1..=1073741824 (2^30), got {0}")]
    MaxSteps(u32),
}

/// Smallest step accepted, as a fraction of the medium's radius: a smaller step needs
/// more than 10^9 steps (beyond [`grin_scene::MAX_STEPS`]) to cross the medium, and near
/// 1e-16 of the coordinates it no longer moves the ray at all in f64.
pub const MIN_STEP_FRACTION: f64 = 1e-9;

impl TraceSettings {
    pub fn from_render(render: &RenderSettings) -> Self {
        TraceSettings {
            integrator: render.integrator(),
            step: render.step,
            max_steps: render.max_steps,
            exit: render.exit,
            macro_cells: render.macro_cells,
            accuracy: render.accuracy(),
            estimate_limit: render.estimate_limit(),
            opl_control: false,
        }
    }

    /// Check that step lengths and tolerances are positive and finite.
    pub fn validate(&self) -> Result<(), TraceError> {
        let pos = |x: f64| x.is_finite() && x > 0.0;
        if !pos(self.accuracy) || !pos(self.estimate_limit) {
            return Err(TraceError::Step(format!(
                "accuracy {} and estimate limit {} must be positive exit-direction errors in radians",
                self.accuracy, self.estimate_limit
            )));
        }
        match self.step {
            StepSpec::Fixed(ds) if !pos(ds) => {
                return Err(TraceError::Step(format!(
                    "fixed step {ds} must be positive and finite"
                )));
            }
            StepSpec::Heuristic {
                min,
                max,
                amplitude,
            } => {
                if !pos(min) || !pos(max) || min > max {
                    return Err(TraceError::Step(format!(
                        "heuristic needs 0 < min <= max, got min {min}, max {max}"
                    )));
                }
                if let Some(a) = amplitude
                    && !pos(a)
                {
                    return Err(TraceError::Step(format!(
                        "heuristic amplitude {a} must be positive"
                    )));
                }
            }
            StepSpec::Adaptive { tolerance, initial } => {
                if !pos(tolerance) {
                    return Err(TraceError::Step(format!(
                        "adaptive tolerance {tolerance} must be positive"
                    )));
                }
                if let Some(i) = initial
                    && !pos(i)
                {
                    return Err(TraceError::Step(format!(
                        "adaptive initial step {i} must be positive"
                    )));
                }
            }
            StepSpec::Auto(a) => {
                if !(pos(a) && a < 1.0) {
                    return Err(TraceError::Step(format!(
                        "auto accuracy {a} must be an exit-direction error in (0, 1) radians"
                    )));
                }
            }
            StepSpec::Fixed(_) => {}
        }
        if !(1..=grin_scene::MAX_STEPS).contains(&self.max_steps) {
            return Err(TraceError::MaxSteps(self.max_steps));
        }
        Ok(())
    }

    /// [`TraceSettings::validate`], and no step shorter than [`MIN_STEP_FRACTION`] of
    /// the medium's radius.
    pub fn validate_for(&self, bounds: &Bounds) -> Result<(), TraceError> {
        self.validate()?;
        let floor = MIN_STEP_FRACTION * bounds.radius();
        let shortest = match self.step {
            StepSpec::Fixed(ds) => Some(("fixed step", ds)),
            StepSpec::Heuristic { min, .. } => Some(("heuristic min step", min)),
            StepSpec::Adaptive { initial, .. } => initial.map(|i| ("adaptive initial step", i)),
            StepSpec::Auto(_) => None,
        };
        if let Some((what, ds)) = shortest
            && ds < floor
        {
            return Err(TraceError::Step(format!(
                "{what} {ds:e} is shorter than {MIN_STEP_FRACTION:e} of the medium's radius \
                 ({:e}): a ray would need more than 10^9 steps to cross it",
                bounds.radius()
            )));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steps_below_the_medium_s_resolution_are_refused() {
        let ball = Bounds::Sphere {
            center: glam::DVec3::ZERO,
            radius: 2.0,
        };
        let mut s = TraceSettings::from_render(&RenderSettings::default());
        s.step = StepSpec::Fixed(1e-17);
        let e = s.validate_for(&ball).expect_err("1e-17").to_string();
        assert_eq!(
            e,
            "step: fixed step 1e-17 is shorter than 1e-9 of the medium's radius (2e0): a ray \
             would need more than 10^9 steps to cross it"
        );
        s.step = StepSpec::Fixed(2.1e-9);
        s.validate_for(&ball).expect("just above the floor");
        s.max_steps = u32::MAX;
        assert_eq!(s.validate_for(&ball), Err(TraceError::MaxSteps(u32::MAX)));
    }
}
