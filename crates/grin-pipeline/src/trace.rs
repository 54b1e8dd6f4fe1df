//! One way from a scene to traced rays: the medium's field, the trace settings with the
//! caller's overrides, and `step = { auto = ... }`'s pilots (some of the rays themselves).
//! `grin trace` streams a table through a [`TracePlan`]; the Python package traces arrays.

use std::path::Path;
use std::sync::Arc;

use anyhow::{Context, bail};
use glam::DVec3;
use grin_field::IndexField;
use grin_render::settings::TraceSettings;
use grin_scene::{ExitMethod, IntegratorKind, Scene, StepSpec};
use grin_trace::RayResult;
use grin_trace::table::RayRow;

/// What a caller overrides of the scene's `[render]` trace settings.
#[derive(Debug, Clone, Copy, Default)]
pub struct TraceOverrides {
    pub integrator: Option<IntegratorKind>,
    /// `StepSpec::Auto(rad)` also asks for `rad`: rays above it are `degraded`.
    pub step: Option<StepSpec>,
    pub max_steps: Option<u32>,
    pub exit: Option<ExitMethod>,
    /// Integrate in f32 (what the GPU does) instead of f64.
    pub f32: bool,
}

/// A scene's medium ready to trace rays through: its field and the settings the pilots
/// chose.
pub struct TracePlan {
    pub field: Arc<dyn IndexField>,
    pub settings: TraceSettings,
    pub f32: bool,
    /// `step = { auto = ... }`: what the pilot rays chose.
    pub auto: Option<grin_trace::auto::AutoChoice>,
    /// `step = { auto = ... }` resolved without pilots (too few rays for them): why.
    pub auto_note: Option<String>,
}

impl std::fmt::Debug for TracePlan {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TracePlan")
            .field("field", &self.field.describe())
            .field("settings", &self.settings)
            .field("f32", &self.f32)
            .finish_non_exhaustive()
    }
}

impl TracePlan {
    /// The plan for tracing `rays` (or the first batch of a longer table, whose rays are
    /// the pilots) through `scene`'s medium (read from `scene_dir`; `label` names the scene
    /// in errors).
    pub fn new(
        scene: &Scene,
        scene_dir: &Path,
        label: &str,
        overrides: &TraceOverrides,
        rays: &[RayRow],
    ) -> anyhow::Result<Self> {
        let Some(medium) = scene.medium.as_ref() else {
            bail!("{label}: the scene has no [medium] to trace rays through");
        };
        let field = grin_field::build_field(medium, scene_dir)
            .with_context(|| format!("{label}: [medium]"))?;
        let mut settings = TraceSettings::from_render(&scene.render);
        // The table's opl column is an output: dopri holds its error as the position's.
        settings.opl_control = true;
        if let Some(k) = overrides.integrator {
            settings.integrator = k;
        }
        if let Some(s) = overrides.step {
            settings.step = s;
            if let StepSpec::Auto(a) = s {
                // As a scene asking `auto = a` is held to it (the pilots, where they run,
                // set the limit they vouch for).
                settings.accuracy = a;
                settings.estimate_limit = a;
            }
        }
        if let Some(m) = overrides.max_steps {
            settings.max_steps = m;
        }
        if let Some(e) = overrides.exit {
            settings.exit = e;
        }
        let overridden = overrides.step.is_some() || overrides.max_steps.is_some();
        settings.validate_for(&field.bounds()).with_context(|| {
            if overridden {
                format!("{label}: [render] as the command line sets it")
            } else {
                format!("{label}: [render]")
            }
        })?;
        // `step = { auto = ... }`: pilot rays (some of the table's own) choose the method.
        // A small table pays for few pilots: at most ~20 % of its work (none below
        // MIN_PILOTS: error control per length then keeps the asked error on its own).
        let free_integrator = scene.render.integrator.is_none() && overrides.integrator.is_none();
        let pilots: Vec<_> = rays.iter().map(|r| (r.origin, r.dir)).collect();
        let wanted = scene.render.pilot_rays as usize;
        let afforded = grin_trace::auto::affordable_pilots(wanted, rays.len());
        let pilots = grin_trace::auto::spread(&pilots, afforded);
        let auto_note = match settings.step {
            StepSpec::Auto(rad) if afforded == 0 && wanted > 0 => Some(format!(
                "auto {rad:.0e} rad: error control per length, no pilot rays (a table of {} \
                 rays: pilots pay from {} rays on)",
                rays.len(),
                grin_trace::auto::MIN_PILOTS * grin_trace::auto::JOB_RAYS_PER_PILOT
            )),
            _ => None,
        };
        let auto = if pilots.is_empty() {
            None
        } else if overrides.f32 {
            grin_trace::auto::choose_for_table::<f32>(
                field.as_ref(),
                &settings,
                free_integrator,
                &pilots,
            )
        } else {
            grin_trace::auto::choose_for_table::<f64>(
                field.as_ref(),
                &settings,
                free_integrator,
                &pilots,
            )
        };
        if let Some(a) = &auto {
            settings = a.settings;
        }
        Ok(Self {
            field,
            settings,
            f32: overrides.f32,
            auto,
            auto_note,
        })
    }

    /// Trace `rows` in parallel (rayon), in the plan's precision.
    pub fn trace(&self, rows: &[RayRow]) -> Vec<RayResult> {
        let mut out = Vec::new();
        self.trace_into(rows, &mut out);
        out
    }

    /// [`Self::trace`] into `out` (one result a row after): a table traced batch by
    /// batch reuses one vector.
    pub fn trace_into(&self, rows: &[RayRow], out: &mut Vec<RayResult>) {
        let (field, settings) = (self.field.as_ref(), &self.settings);
        if self.f32 {
            grin_trace::table::trace_rows_into::<f32>(field, settings, rows, out);
        } else {
            grin_trace::table::trace_rows_into::<f64>(field, settings, rows, out);
        }
    }
}

/// Rays as table rows (line numbers from 1, no extra columns).
pub fn rows(rays: impl Iterator<Item = (DVec3, DVec3)>) -> Vec<RayRow> {
    rays.enumerate()
        .map(|(i, (origin, dir))| RayRow {
            line: i + 1,
            origin,
            dir,
            extra: Vec::new(),
        })
        .collect()
}

/// An integrator by name (`rk4`, `dopri`, ...), as `--integrator` takes it.
pub fn parse_integrator(s: &str) -> Result<IntegratorKind, String> {
    IntegratorKind::from_name(s).ok_or_else(|| {
        let names = <IntegratorKind as strum::VariantNames>::VARIANTS.join(", ");
        format!("unknown integrator `{s}`; expected one of {names}")
    })
}

/// A step policy as `--step` takes it: fixed=DS | heuristic=MIN,MAX[,AMPLITUDE] |
/// adaptive=TOL | auto=RAD.
pub fn parse_step(s: &str) -> Result<StepSpec, String> {
    let usage = "expected fixed=DS, heuristic=MIN,MAX[,AMPLITUDE], adaptive=TOL or auto=RAD";
    let (kind, values) = s.split_once('=').ok_or_else(|| format!("`{s}`: {usage}"))?;
    let nums = values
        .split(',')
        .map(|v| {
            v.trim()
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite() && *x > 0.0)
                .ok_or_else(|| format!("`{s}`: `{v}` is not a positive number"))
        })
        .collect::<Result<Vec<f64>, String>>()?;
    match (kind.trim(), nums.as_slice()) {
        ("fixed", [ds]) => Ok(StepSpec::Fixed(*ds)),
        ("heuristic", [min, max]) | ("heuristic", [min, max, _]) if min <= max => {
            Ok(StepSpec::Heuristic {
                min: *min,
                max: *max,
                amplitude: nums.get(2).copied(),
            })
        }
        ("heuristic", [_, _]) | ("heuristic", [_, _, _]) => {
            Err(format!("`{s}`: heuristic needs MIN <= MAX"))
        }
        ("adaptive", [tol]) => Ok(StepSpec::Adaptive {
            tolerance: *tol,
            initial: None,
        }),
        ("auto", [rad]) if *rad < 1.0 => Ok(StepSpec::Auto(*rad)),
        ("auto", [_]) => Err(format!(
            "`{s}`: auto takes an exit-direction error in radians, below 1"
        )),
        _ => Err(format!("`{s}`: {usage}")),
    }
}
