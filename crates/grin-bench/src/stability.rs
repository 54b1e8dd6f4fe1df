//! `grin bench stability`: hard cases x methods. Each case is a field and a few rays with
//! a known right outcome (an exact exit, or "trapped", or "the field is invalid there");
//! each cell runs one method on the case's rays and is classified:
//!
//! - **converged**: every ray ends as the truth says, within the case's tolerance;
//! - **degraded**: every status right, but the worst error is above the tolerance (the
//!   error is given);
//! - **failed**: a status other than the truth's (`max_steps`, `error`, `missed`), or NaN
//!   anywhere in the result;
//! - and, across all three, **silent**: a ray grin reported `exited` that is wrong by
//!   more than [`WRONG_FACTOR`] times the accuracy the cell asked for (its `auto` value;
//!   for the other policies the default, 1e-4 rad) in direction or [`WRONG_POS`] of the
//!   scale in position, or reported `exited` where the
//!   truth is that it never leaves or meets an invalid field. A silent cell is a confident
//!   wrong answer: the thing this matrix exists to find.
//!
//! One concept, one file: the hard cases are data, and their classification sees them all.

use std::sync::Arc;
use std::time::{Duration, Instant};

use glam::DVec3;
use grin_field::IndexField;
use grin_scene::{ExitMethod, IntegratorKind};
use grin_trace::{RayResult, RayStatus};
use rayon::prelude::*;

use crate::accuracy::{angle, choose_auto, trace};
use crate::cases::{Exit, medium, rod_exit};
use crate::methods::{Method, Policy, Precision};

/// An `exited` ray off by more than this many times the accuracy asked for (rad) is a
/// wrong answer grin vouched for, not a degraded one.
pub const WRONG_FACTOR: f64 = 10.0;
/// ... or off by more than this fraction of the scale in position.
pub const WRONG_POS: f64 = 1e-2;

/// What the right outcome of a ray is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Truth {
    /// Leaves the medium this way.
    Exits(Exit),
    /// Never leaves (a trapped orbit): `max_steps` is the right status.
    Trapped,
}

/// One hard case.
#[derive(Debug, Clone)]
pub struct StabilityCase {
    pub name: &'static str,
    /// Why the case is hard: one sentence for the matrix.
    pub why: &'static str,
    pub field: Arc<dyn IndexField>,
    pub rays: Vec<(DVec3, DVec3, Truth)>,
    /// Error (rad, and of the scale in position) within which a ray has converged.
    pub tol: f64,
    pub scale: f64,
    /// Cells of this case run with this step cap (trapped rays end there).
    pub max_steps: u32,
    /// What grin itself says about the case before any ray is traced (a bake that reports
    /// its budget unmet): wrong answers in such a case were warned of, not silent.
    pub warning: Option<String>,
}

/// Converged within 1e-4 (rad, and of the scale in position) unless a case says.
const DEFAULT_TOL: f64 = 1e-4;
/// Step cap of a cell unless a case says (trapped rays end there).
const DEFAULT_MAX_STEPS: u32 = 1 << 18;

impl StabilityCase {
    /// A case with the default tolerance and step cap and no warning.
    fn new(
        name: &'static str,
        why: &'static str,
        field: Arc<dyn IndexField>,
        rays: Vec<(DVec3, DVec3, Truth)>,
        scale: f64,
    ) -> Self {
        StabilityCase {
            name,
            why,
            field,
            rays,
            tol: DEFAULT_TOL,
            scale,
            max_steps: DEFAULT_MAX_STEPS,
            warning: None,
        }
    }

    fn with_tol(mut self, tol: f64) -> Self {
        self.tol = tol;
        self
    }

    fn with_max_steps(mut self, max_steps: u32) -> Self {
        self.max_steps = max_steps;
        self
    }

    fn with_warning(mut self, warning: Option<String>) -> Self {
        self.warning = warning;
        self
    }
}

/// The Luneburg lens ray from `r0` along `t0` (T = n d, inside): exact exit, from the
/// harmonic solution r(t) = r0 cos(t/R) + R T0 sin(t/R), by a fine scan and bisection.
fn luneburg_exit(r0: DVec3, t0: DVec3, radius: f64) -> Exit {
    let at = |t: f64| r0 * (t / radius).cos() + t0 * (radius * (t / radius).sin());
    let g = |t: f64| at(t).length() - radius;
    let (mut lo, mut hi) = (0.0, 0.0);
    let dt = 1e-4 * radius;
    let mut t = dt;
    while t < 10.0 * radius {
        if g(t) > 0.0 {
            lo = t - dt;
            hi = t;
            break;
        }
        t += dt;
    }
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if g(mid) > 0.0 {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    let t = 0.5 * (lo + hi);
    let v = -r0 / radius * (t / radius).sin() + t0 * (t / radius).cos();
    Exit {
        position: at(t),
        direction: v.normalize(),
        opl: None,
    }
}

/// The hard cases.
pub fn cases() -> anyhow::Result<Vec<StabilityCase>> {
    let mut v = Vec::new();

    // 1. A steep, narrow plume: a = 0.05 over s = 0.01 in a unit box.
    {
        let field = medium(
            "bounds = { box = { min = [-1.0, -1.0, -1.0], max = [1.0, 1.0, 1.0] } }\nfield = { kind = \"plume\", plumes = [ { a = 0.05, center = [0.0, 0.0, 0.0], s = 0.01 } ] }",
        )?;
        let reference = fine_reference(field.clone());
        let rays = parallel_rays(&reference, &[(0.0, 0.003), (0.0, 0.007), (0.0, 0.012)]);
        v.push(
            StabilityCase::new("steep narrow plume", "a plume 1% of the box wide (a = 0.05, s = 0.01) deflects rays by ~0.1 rad; a step longer than it can pass over it between samples", field, rays, 3f64.sqrt()),
        );
    }

    // 2. An index jump inside a baked grid: a glass ball baked into a box.
    {
        let source = medium(
            "bounds = { box = { min = [-1.0, -1.0, -1.0], max = [1.0, 1.0, 1.0] } }\nfield = { kind = \"expr\", n = \"1.25 - 0.25*tanh((x*x+y*y+z*z - 0.25)/0.002)\" }",
        )?;
        let reference = fine_reference(source.clone());
        let opts = grin_field::bake::BakeOptions {
            resolution: Some(48),
            error_points: 1000,
            ..Default::default()
        };
        let (baked, warning) = bake_case(source.as_ref(), &opts)?;
        let rays = parallel_rays(&reference, &[(0.0, 0.1), (0.0, 0.25), (0.0, 0.4)]);
        v.push(
            StabilityCase::new("index jump in a baked grid", "a 0.5 jump in n over 0.2% of the box, baked at 48^3: the grid smears the interface over a voxel", Arc::new(baked), rays, 3f64.sqrt())
                .with_tol(1e-3)
                .with_warning(warning),
        );
    }

    // 3. Grazing incidence on the Luneburg lens.
    {
        let field = medium(
            "bounds = { sphere = { center = [0.0, 0.0, 0.0], radius = 1.0 } }\nfield = { kind = \"luneburg\" }",
        )?;
        let rays = [0.99, 0.999, 0.9999]
            .iter()
            .map(|&p: &f64| {
                let s = p;
                let exit = Exit {
                    position: DVec3::new(0.0, 0.0, 1.0),
                    direction: DVec3::new(-s, 0.0, (1.0 - s * s).sqrt()),
                    opl: None,
                };
                (DVec3::new(p, 0.0, -2.0), DVec3::Z, Truth::Exits(exit))
            })
            .collect();
        v.push(
            StabilityCase::new("grazing incidence", "Luneburg rays entering at 0.99-0.9999 R meet the surface almost tangentially, enter and leave in a short arc", field, rays, 1.0),
        );
    }

    // 4. Tangent to the bounds from inside.
    {
        let field = medium(
            "bounds = { sphere = { center = [0.0, 0.0, 0.0], radius = 1.0 } }\nfield = { kind = \"luneburg\" }",
        )?;
        let rays = [0.999, 0.9999]
            .iter()
            .map(|&r: &f64| {
                let r0 = DVec3::new(r, 0.0, 0.0);
                let n = (2.0 - r * r).sqrt();
                let t0 = DVec3::Y * n;
                (r0, DVec3::Y, Truth::Exits(luneburg_exit(r0, t0, 1.0)))
            })
            .collect();
        v.push(
            StabilityCase::new("tangent from inside", "a ray starting just inside the surface, tangent to it: its orbit crosses r = R after a short arc", field, rays, 1.0),
        );
    }

    // 5. A turning point just below a face (tunnelling).
    {
        // n^2 = 1 + k y in the box y in [0, 1]; ambient n(0) = 1 (no refraction at y = 0).
        let k = 0.02;
        let field = medium(
            "bounds = { box = { min = [-1.0, 0.0, -1.0], max = [1.0, 1.0, 1.0] } }\nfield = { kind = \"linear-n2\", n0 = 1.0049875621, k = 0.02, axis = \"y\" }",
        )?;
        // linear-n2 is relative to the bounds' centre (y = 0.5): n^2 = n0^2 + k (y - 0.5),
        // n0^2 = 1 + 0.5 k puts n^2 = 1 + k y.
        let mut rays = Vec::new();
        for dip in [1e-6, 1e-5, 1e-4] {
            let y0: f64 = 0.01;
            // Ray inside from (-0.95, y0, 0): T0 = n(y0) (cos a, -sin a, 0) with the
            // turning point y0 - T0y^2 / k = -dip.
            let n = (1.0 + k * y0).sqrt();
            let ty = -((y0 + dip) * k).sqrt();
            let tx = (n * n - ty * ty).sqrt();
            let r0 = DVec3::new(-0.95, y0, 0.0);
            let t0 = DVec3::new(tx, ty, 0.0);
            // y(t) = y0 + ty t + k t^2 / 4 = 0: first root.
            let disc = ty * ty - k * y0;
            let t = (-ty - disc.sqrt()) / (0.5 * k);
            let pos = DVec3::new(r0.x + tx * t, 0.0, 0.0);
            let vel = DVec3::new(tx, ty + 0.5 * k * t, 0.0);
            rays.push((
                r0,
                t0.normalize(),
                Truth::Exits(Exit {
                    position: pos,
                    direction: vel.normalize(),
                    opl: None,
                }),
            ));
        }
        v.push(
            StabilityCase::new("turning point below a face", "a mirage ray whose turning point dips 1e-6..1e-4 below the bottom face: it must leave there, not tunnel through between step ends", field, rays, 3f64.sqrt()),
        );
    }

    // 6. A trapped orbit: total internal reflection forever inside a glass ball.
    {
        let field = medium(
            "bounds = { sphere = { center = [0.0, 0.0, 0.0], radius = 1.0 } }\nfield = { kind = \"uniform\", n = 1.5 }",
        )?;
        let rays = vec![
            (DVec3::new(0.0, -0.9, 0.0), DVec3::X, Truth::Trapped),
            (
                DVec3::new(0.0, 0.0, -0.8),
                DVec3::new(1.0, 0.2, 0.0).normalize(),
                Truth::Trapped,
            ),
        ];
        v.push(
            StabilityCase::new("trapped orbit", "inside n = 1.5 at incidence beyond the critical angle the ray reflects forever: `max_steps` is the truth", field, rays, 1.0)
                .with_max_steps(4096),
        );
    }

    // 7. n approaching 0 along an on-axis ray.
    {
        // n^2 = 1 - 0.99 (z + 1) / 2 from z = -1 (n = 1) to z = +1 (n = 0.1).
        let field = medium(
            "bounds = { box = { min = [-0.5, -0.5, -1.0], max = [0.5, 0.5, 1.0] } }\nambient_index = 1.0\nfield = { kind = \"linear-n2\", n0 = 0.71063352, k = -0.495, axis = \"z\" }",
        )?;
        let rays = [0.0, 0.1]
            .iter()
            .map(|&x| {
                let o = DVec3::new(x, 0.0, -1.5);
                // On-axis: straight through; leaving n = 0.1 into 1 along the normal.
                let exit = Exit {
                    position: DVec3::new(x, 0.0, 1.0),
                    direction: DVec3::Z,
                    opl: None,
                };
                (o, DVec3::Z, Truth::Exits(exit))
            })
            .collect();
        v.push(
            StabilityCase::new("n approaching 0", "n falls to 0.1 along the ray: a step of fixed length is a long step in t = s/n and can reverse T", field, rays, 1.2),
        );
    }

    // (A spike of n <= 0 between the load check's grid points was case 8: an `expr`
    // field with one is now refused at load by interval bounds, grin_field::interval;
    // `refused_at_load` records that it still is.)

    // 8. The GRIN rod in f32 at tight tolerances (roundoff floor).
    {
        let field = medium(
            "bounds = { box = { min = [-0.5, -0.5, -1.0], max = [0.5, 0.5, 1.0] } }\nfield = { kind = \"grin-rod\", n0 = 1.5, a = 0.8, axis = \"z\" }",
        )?;
        let rays = [(0.1, 0.05), (0.2, -0.1)]
            .iter()
            .map(|&(x, y)| {
                let e = DVec3::new(x, y, -1.0);
                let d = DVec3::new(0.05, -0.03, 1.0).normalize();
                let o = e - d * (0.5 / d.z);
                (o, d, Truth::Exits(rod_exit(e, d, 1.5, 0.8, 1.0)))
            })
            .collect();
        v.push(
            StabilityCase::new("GRIN rod (exact)", "a smooth field with an exact solution: every method should converge; f32 at tight tolerances hits its roundoff floor", field, rays, 1.5),
        );
    }

    // 9. Noise finer than the grid: fBm whose finest octave (1/32 of the sphere) is a
    // third of the bake's node spacing.
    {
        let source = medium(
            "bounds = { sphere = { center = [0.0, 0.0, 0.0], radius = 1.0 } }\nambient_index = 1.0003\nfield = { kind = \"noise\", noise = \"fbm\", octaves = 3, frequency = 8.0, amplitude = 2e-3, seed = 11 }",
        )?;
        let reference = fine_reference(source.clone());
        let opts = grin_field::bake::BakeOptions {
            resolution: Some(24),
            ..Default::default()
        };
        let (baked, warning) = bake_case(source.as_ref(), &opts)?;
        let rays = parallel_rays(&reference, &[(0.05, 0.1), (-0.3, 0.2), (0.4, -0.35)]);
        v.push(
            StabilityCase::new("noise finer than the grid", "fBm with features of 0.03 R baked at 24 nodes (0.087 R apart): the grid cannot hold the field, and the bake must say so", Arc::new(baked), rays, 1.0)
                .with_warning(warning),
        );
    }

    // 10, 11. A heat-haze plume (delta_n 1e-5) stored as i16 and as f32: quantisation
    // must keep a deflection of ~1e-5 rad to 1 %. Voxels hold delta_n = n - ambient, not
    // n (n ~ 1.0003 in f32 would keep only 1.2e-7, 1 % of the plume), and i16 scales each
    // channel to its own largest value.
    for (storage, name, why) in [
        (
            grin_field::baked::Storage::I16,
            "1e-5 delta_n in i16 storage",
            "a plume of delta_n 1e-5 baked into 16-bit integers: each channel is scaled to its own largest value, so delta_n keeps 3e-10 steps",
        ),
        (
            grin_field::baked::Storage::F32,
            "1e-5 delta_n in f32 storage",
            "the same plume in f32: delta_n = n - ambient is stored, not n, so it keeps 7 digits where n ~ 1.0003 would keep 1 % of the plume",
        ),
    ] {
        let source = medium(
            "bounds = { box = { min = [-1.0, -1.0, -1.0], max = [1.0, 1.0, 1.0] } }\nambient_index = 1.000293\nfield = { kind = \"plume\", plumes = [ { a = 1.0e-5, center = [0.0, 0.0, 0.0], s = 0.25 } ] }",
        )?;
        let reference = fine_reference(source.clone());
        let opts = grin_field::bake::BakeOptions {
            resolution: Some(64),
            interp: grin_field::baked::Interp::Tricubic,
            storage: Some(storage),
            ..Default::default()
        };
        let (baked, warning) = bake_case(source.as_ref(), &opts)?;
        let rays = parallel_rays(&reference, &[(0.0, 0.15), (0.1, 0.25), (-0.2, 0.4)]);
        v.push(
            StabilityCase::new(name, why, Arc::new(baked), rays, 3f64.sqrt())
                .with_tol(WEAK_FIELD_TOL)
                .with_warning(warning),
        );
    }

    // 12. A feature narrower than any default step in a formula (which, unlike a plume,
    // names no scale of its own): a tall bump 1/100 of the box wide, off the axis.
    v.push(expr_case(
        "narrow bump in an expression",
        "a bump 1/100 of the box wide (a = 0.05) in an `expr` formula, which names no feature size: only the formula's own interval bounds say a step must not pass over it",
        "1 + 0.05*exp(-((x-0.3)^2 + (y+0.2)^2 + (z-0.1)^2)/0.0001)",
        &[(0.3, -0.2), (0.305, -0.195), (0.29, -0.21), (0.312, -0.2)],
    )?);

    // 13. A pocket where n falls near 0 (0.05), off the axis, in a formula.
    v.push(expr_case(
        "near-zero pocket",
        "a pocket 0.1 wide where n falls to 0.05: a fixed world step is a long step in t = s/n there, and the ray bends hard around it",
        "1 - 0.95*exp(-((x-0.2)^2 + (y-0.1)^2 + z^2)/0.01)",
        &[(0.2, 0.1), (0.25, 0.1), (0.3, 0.15), (0.1, 0.0)],
    )?);
    Ok(v)
}

/// A case of the `expr` formula `n` in the box [-1, 1]^3, rays along +z at `offsets`
/// against a fine RK4 reference on the same field.
fn expr_case(
    name: &'static str,
    why: &'static str,
    n: &str,
    offsets: &[(f64, f64)],
) -> anyhow::Result<StabilityCase> {
    let field = medium(&format!(
        "bounds = {{ box = {{ min = [-1.0, -1.0, -1.0], max = [1.0, 1.0, 1.0] }} }}\nfield = {{ kind = \"expr\", n = \"{n}\" }}"
    ))?;
    let reference = fine_reference(field.clone());
    let rays = parallel_rays(&reference, offsets);
    Ok(StabilityCase::new(name, why, field, rays, 3f64.sqrt()))
}

/// Converged for the 1e-5 plume: 1 % of its rays' deflection (1.0e-5 .. 1.4e-5 rad).
const WEAK_FIELD_TOL: f64 = 1e-7;

/// `source` baked with `opts`, and the warning grin gives where the bake misses its budget.
fn bake_case(
    source: &dyn IndexField,
    opts: &grin_field::bake::BakeOptions,
) -> anyhow::Result<(grin_field::baked::BakedField, Option<String>)> {
    let (baked, report) = grin_field::bake::bake(source, opts, &|_, _, _| {})?;
    let warning = (!report.meets_budget).then(|| {
        format!(
            "the bake reports relative error {:.1e} over its budget {:.0e}",
            report.relative_error, report.budget
        )
    });
    Ok((baked, warning))
}

/// Rays along +z from z = -1.5 at the (x, y) offsets, with `reference`'s exits as truth.
fn parallel_rays(
    reference: &impl Fn(DVec3, DVec3) -> Exit,
    offsets: &[(f64, f64)],
) -> Vec<(DVec3, DVec3, Truth)> {
    offsets
        .iter()
        .map(|&(x, y)| {
            let o = DVec3::new(x, y, -1.5);
            (o, DVec3::Z, Truth::Exits(reference(o, DVec3::Z)))
        })
        .collect()
}

/// A reference that resolves any feature: RK4 at a fixed step of 1e-4 of the box radius
/// in f64 with the bisection exit.
fn fine_reference(field: Arc<dyn IndexField>) -> impl Fn(DVec3, DVec3) -> Exit {
    let scale = field.bounds().radius();
    let settings = Method {
        integrator: IntegratorKind::Rk4,
        policy: Policy::Fixed,
        exit: ExitMethod::Bisection,
        precision: Precision::F64,
    }
    .settings(1e-4, scale);
    move |o, d| {
        let r = grin_trace::trace_ray::<f64>(field.as_ref(), &settings, o, d);
        Exit {
            position: r.position,
            direction: r.direction,
            opl: None,
        }
    }
}

/// A method and parameter of a matrix column.
#[derive(Debug, Clone, Copy)]
pub struct Column {
    pub method: Method,
    pub param: f64,
}

impl Column {
    pub fn label(&self) -> String {
        let p = match self.method.policy {
            Policy::Adaptive | Policy::PerLength | Policy::Auto => format!("{:.0e}", self.param),
            _ => format!("R/{}", (1.0 / self.param).round()),
        };
        if self.method.policy == Policy::Auto {
            return format!("auto {p} {}", self.method.precision.name());
        }
        format!(
            "{} {} {} {}",
            self.method.integrator_label(),
            self.method.policy.name(),
            p,
            self.method.precision.name()
        )
    }
}

/// The columns: every integrator with three fixed steps (R/4, R/16, R/256), the heuristic, and
/// error control at 1e-6 (f64) and 1e-9 (f64 and f32).
pub fn columns(quick: bool) -> Vec<Column> {
    let mut v = Vec::new();
    for &integrator in &IntegratorKind::ALL {
        let mut add = |policy, param, precision| {
            v.push(Column {
                method: Method {
                    integrator,
                    policy,
                    exit: ExitMethod::Hermite,
                    precision,
                },
                param,
            })
        };
        add(Policy::Fixed, 1.0 / 16.0, Precision::F64);
        if !quick {
            // Coarse: a quarter of the radius a step, where the fourth- and fifth-order
            // methods step over features (they must then say `degraded`).
            add(Policy::Fixed, 1.0 / 4.0, Precision::F64);
            add(Policy::Fixed, 1.0 / 256.0, Precision::F64);
            add(Policy::Heuristic, 1.0 / 16.0, Precision::F64);
        }
        add(Policy::Adaptive, 1e-6, Precision::F64);
        if !quick {
            add(Policy::Adaptive, 1e-9, Precision::F64);
        }
        add(Policy::Adaptive, 1e-9, Precision::F32);
    }
    // The default: `auto` at 1e-4 rad, the pilot rays (the case's own) choosing the
    // integrator and step, in both precisions.
    for precision in [Precision::F64, Precision::F32] {
        v.push(Column {
            method: Method {
                integrator: IntegratorKind::Adaptive,
                policy: Policy::Auto,
                exit: ExitMethod::Hermite,
                precision,
            },
            param: grin_scene::DEFAULT_AUTO_ACCURACY,
        });
    }
    v
}

/// The GPU's columns (the full matrix only): the render kernel marching each case's
/// field as `grin render --backend gpu` bakes it, with a fixed step, tight f32 error
/// control and the default.
pub fn gpu_columns() -> Vec<Column> {
    let gpu = |integrator, policy, param| Column {
        method: Method {
            integrator,
            policy,
            exit: ExitMethod::Hermite,
            precision: Precision::Gpu,
        },
        param,
    };
    vec![
        gpu(IntegratorKind::Rk4, Policy::Fixed, 1.0 / 16.0),
        gpu(IntegratorKind::Adaptive, Policy::Adaptive, 1e-9),
        gpu(
            IntegratorKind::Adaptive,
            Policy::Auto,
            grin_scene::DEFAULT_AUTO_ACCURACY,
        ),
    ]
}

/// A cell's class.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Outcome {
    Converged,
    Degraded,
    Failed,
}

/// One cell of the matrix.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Cell {
    pub case: &'static str,
    pub method: String,
    pub outcome: Outcome,
    /// A ray reported `exited` with a wrong answer (see the module docs) and nothing
    /// warned of it.
    pub silent: bool,
    /// The case's warning applies (grin said before tracing that results are off).
    pub warned: bool,
    /// Worst direction error (rad) over the rays that exited where the truth does.
    pub err_dir: f64,
    /// Worst position error / scale over the same rays.
    pub err_pos: f64,
    /// Statuses of the rays, in order (`exited`, `max_steps`, ...).
    pub statuses: String,
    /// Any NaN in a result.
    pub nan: bool,
    pub evals_per_ray: f64,
    pub seconds: f64,
}

fn has_nan(r: &RayResult) -> bool {
    r.position.is_nan() || r.direction.is_nan() || r.opl.is_nan() || r.length.is_nan()
}

/// The cell's tracer settings on `field` (the case's, or the GPU's bake of it): `auto`
/// resolved on the case's own rays as pilots.
fn cell_settings(
    case: &StabilityCase,
    col: &Column,
    field: &dyn IndexField,
) -> grin_render::settings::TraceSettings {
    let mut settings = col.method.settings(col.param, case.scale);
    settings.max_steps = case.max_steps;
    if col.method.policy == Policy::Auto {
        let pilots: Vec<(DVec3, DVec3)> = case.rays.iter().map(|&(o, d, _)| (o, d)).collect();
        if let Some(c) = choose_auto(field, &settings, col.method.precision, &pilots) {
            settings = c.settings;
        }
    }
    settings
}

/// Run one cell on the CPU.
pub fn run_cell(case: &StabilityCase, col: &Column) -> Cell {
    let settings = cell_settings(case, col, case.field.as_ref());
    let start = Instant::now();
    let results: Vec<RayResult> = case
        .rays
        .iter()
        .map(|&(o, d, _)| trace(case.field.as_ref(), &settings, col.method.precision, o, d))
        .collect();
    let seconds = start.elapsed().as_secs_f64();
    let wrong_dir = WRONG_FACTOR * settings.accuracy;
    classify(
        case,
        col,
        &results,
        seconds,
        case.warning.is_some(),
        wrong_dir,
    )
}

/// Run one cell on the GPU, through `gpu` holding the case's field as the GPU bakes it;
/// `warned`: the case's or that bake's warning applies.
pub fn run_gpu_cell(
    gpu: &mut grin_gpu::GpuRayTracer,
    baked: &Arc<grin_field::baked::BakedField>,
    case: &StabilityCase,
    col: &Column,
    warned: bool,
) -> anyhow::Result<Cell> {
    gpu.set_field(Arc::clone(baked))?;
    let settings = cell_settings(case, col, baked.as_ref());
    let rays: Vec<(DVec3, DVec3)> = case.rays.iter().map(|&(o, d, _)| (o, d)).collect();
    let (out, seconds) = gpu.trace(&settings, &rays, 1)?;
    let results: Vec<RayResult> = out.iter().map(crate::accuracy::gpu_result).collect();
    let wrong_dir = WRONG_FACTOR * settings.accuracy;
    Ok(classify(case, col, &results, seconds, warned, wrong_dir))
}

/// Classify a cell from its rays' results.
fn classify(
    case: &StabilityCase,
    col: &Column,
    results: &[RayResult],
    seconds: f64,
    warned: bool,
    wrong_dir: f64,
) -> Cell {
    let mut cell = Cell {
        case: case.name,
        method: col.label(),
        outcome: Outcome::Converged,
        silent: false,
        warned,
        err_dir: 0.0,
        err_pos: 0.0,
        statuses: results
            .iter()
            .map(|r| r.status.name())
            .collect::<Vec<_>>()
            .join(" "),
        nan: results.iter().any(has_nan),
        evals_per_ray: results.iter().map(|r| r.evals as f64).sum::<f64>() / results.len() as f64,
        seconds,
    };
    let mut failed = cell.nan;
    for (r, &(_, _, truth)) in results.iter().zip(&case.rays) {
        match truth {
            Truth::Exits(e) => {
                if !r.status.left() {
                    failed = true;
                    continue;
                }
                let ed = angle(r.direction, e.direction);
                let ep = (r.position - e.position).length() / case.scale;
                let (ed, ep) = (nan_inf(ed), nan_inf(ep));
                cell.err_dir = cell.err_dir.max(ed);
                cell.err_pos = cell.err_pos.max(ep);
                // A `degraded` ray said it cannot be vouched for: not silent.
                if r.status == RayStatus::Exited && (ed > wrong_dir || ep > WRONG_POS) {
                    cell.silent = true;
                }
            }
            Truth::Trapped => match r.status {
                RayStatus::MaxSteps | RayStatus::Absorbed => {}
                RayStatus::Exited => {
                    cell.silent = true;
                    failed = true;
                }
                _ => failed = true,
            },
        }
    }
    if cell.warned {
        cell.silent = false;
    }
    cell.outcome = if failed {
        Outcome::Failed
    } else if cell.err_dir > case.tol || cell.err_pos > case.tol {
        Outcome::Degraded
    } else {
        Outcome::Converged
    };
    cell
}

fn nan_inf(x: f64) -> f64 {
    if x.is_nan() { f64::INFINITY } else { x }
}

/// The whole matrix.
#[derive(Debug, Clone)]
pub struct Matrix {
    /// (name, why, grin's own warning) per case.
    pub cases: Vec<(&'static str, &'static str, Option<String>)>,
    /// Hard cases grin refuses before tracing: (name, grin's error). A field that loads
    /// instead is recorded as `None` (a defect the tests catch).
    pub refused: Vec<(&'static str, Option<String>)>,
    pub columns: Vec<String>,
    pub cells: Vec<Cell>,
    /// The GPU columns' adapter, or why there are none (`None`: not asked for).
    pub gpu: Option<String>,
    /// Cases whose GPU bake reports its error budget unmet: (name, the warning).
    pub gpu_warnings: Vec<(&'static str, String)>,
    pub seconds: f64,
}

/// Longest a single cell may take before the run reports it (a hang would be a defect).
pub const CELL_TIME_LIMIT: Duration = Duration::from_secs(60);

/// Run every case against every column; with `gpu` (and not `quick`) the GPU's columns
/// too, each case's field baked as `grin render --backend gpu` bakes it.
pub fn run(quick: bool, gpu: bool, progress: &(dyn Fn(u64, u64) + Sync)) -> anyhow::Result<Matrix> {
    let start = Instant::now();
    let cases = cases()?;
    let mut cols = columns(quick);
    let gpu_cols = if gpu && !quick {
        gpu_columns()
    } else {
        Vec::new()
    };
    let jobs: Vec<(usize, usize)> = (0..cases.len())
        .flat_map(|c| (0..cols.len()).map(move |k| (c, k)))
        .collect();
    let total = (jobs.len() + cases.len() * gpu_cols.len()) as u64;
    let done = std::sync::atomic::AtomicU64::new(0);
    let tick = || {
        let d = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
        progress(d, total);
    };
    let mut cells: Vec<Cell> = jobs
        .par_iter()
        .map(|&(c, k)| {
            let cell = run_cell(&cases[c], &cols[k]);
            tick();
            cell
        })
        .collect();
    let mut gpu_note = None;
    let mut gpu_warnings = Vec::new();
    if !gpu_cols.is_empty() {
        match grin_gpu::GpuContext::new_headless() {
            Err(e) => gpu_note = Some(format!("no GPU columns: no adapter ({e})")),
            Ok(ctx) => {
                gpu_note = Some(format!("GPU columns on {}", ctx.adapter_name()));
                let mut tracer = None;
                for case in &cases {
                    let (baked, warning) = gpu_field(case)?;
                    if let Some(w) = &warning {
                        gpu_warnings.push((case.name, w.clone()));
                    }
                    let gpu = match &mut tracer {
                        Some(t) => t,
                        None => {
                            tracer.insert(grin_gpu::GpuRayTracer::new(&ctx, Arc::clone(&baked))?)
                        }
                    };
                    let warned = case.warning.is_some() || warning.is_some();
                    for col in &gpu_cols {
                        cells.push(run_gpu_cell(gpu, &baked, case, col, warned)?);
                        tick();
                    }
                }
                cols.extend(gpu_cols);
            }
        }
    }
    Ok(Matrix {
        cases: cases
            .iter()
            .map(|c| (c.name, c.why, c.warning.clone()))
            .collect(),
        columns: cols.iter().map(Column::label).collect(),
        cells,
        refused: refused_at_load(),
        gpu: gpu_note,
        gpu_warnings,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// The case's field as the GPU marches it: its own grid when it is baked, else baked as
/// `grin render --backend gpu` bakes it (`bake_for_gpu_auto`), with that bake's warning.
fn gpu_field(
    case: &StabilityCase,
) -> anyhow::Result<(Arc<grin_field::baked::BakedField>, Option<String>)> {
    if let Some(b) = case.field.as_baked() {
        return Ok((Arc::new(b.clone()), None));
    }
    let (baked, report) = grin_field::bake::device::bake_for_gpu_auto(case.field.as_ref())?;
    Ok((
        Arc::new(baked),
        grin_field::bake::device::bake_warning(&report),
    ))
}

/// A spike of n <= 0 (n dips to -2 in a ball of radius ~0.02, between the load check's
/// grid nodes): once a matrix case whose rays had to turn or stop, now refused at load.
pub const SPIKE_MEDIUM: &str = "bounds = { box = { min = [-1.0, -1.0, -1.0], max = [1.0, 1.0, 1.0] } }\nfield = { kind = \"expr\", n = \"1 - 3*exp(-((x-0.0833)^2 + (y-0.0833)^2 + (z-0.0833)^2)/0.0004)\" }";

/// The hard cases grin must refuse before any ray is traced, and what it says.
fn refused_at_load() -> Vec<(&'static str, Option<String>)> {
    vec![(
        "n <= 0 spike between the check grid's nodes",
        medium(SPIKE_MEDIUM).err().map(|e| format!("{e:#}")),
    )]
}

/// The cell's short text: `ok`, `1.2e-3`, `FAIL max_steps`, with `!` for silent.
pub fn cell_text(c: &Cell) -> String {
    let base = match c.outcome {
        Outcome::Converged => "ok".to_string(),
        Outcome::Degraded => format!("~{:.0e}", c.err_dir.max(c.err_pos)),
        Outcome::Failed => {
            let bad: Vec<&str> = c.statuses.split(' ').filter(|s| *s != "exited").collect();
            if c.nan {
                "FAIL NaN".into()
            } else if bad.is_empty() {
                "FAIL exited".into()
            } else {
                format!("FAIL {}", bad[0])
            }
        }
    };
    if c.silent {
        format!("**{base} (silent)**")
    } else if c.warned && c.outcome != Outcome::Converged {
        format!("{base} (warned)")
    } else {
        base
    }
}

/// The matrix as Markdown: one row per case (with why), one column per method.
pub fn markdown(m: &Matrix, command: &str) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    let _ = writeln!(s, "# grin bench stability\n");
    let _ = writeln!(
        s,
        "`{command}` — {} cells in {:.1} s. `ok` converged; `~e` degraded with worst error e (rad or of the scale); `FAIL s` a ray ended `s` against the truth; **(silent)** a ray reported `exited` more than 10x the accuracy asked for off (the `auto` value; 1e-4 rad for the other policies) or 1e-2 of the scale, or where it never leaves, and nothing warned of it; (warned) grin said so before tracing. A ray that ends with the status `degraded` (its own error estimate above the accuracy asked for: the integrator's, or a bake's n error amplified at a grazing crossing) is measured like an exited one but never silent.\n",
        m.cells.len(),
        m.seconds
    );
    for (case, why, warning) in &m.cases {
        match warning {
            Some(w) => {
                let _ = writeln!(s, "- **{case}**: {why}. grin warns: {w}.");
            }
            None => {
                let _ = writeln!(s, "- **{case}**: {why}.");
            }
        }
    }
    for (case, refused) in &m.refused {
        match refused {
            Some(e) => {
                let _ = writeln!(s, "- **{case}**: refused at load, no ray traced: {e}");
            }
            None => {
                let _ = writeln!(
                    s,
                    "- **{case}**: LOADED (a defect: grin must refuse this field)"
                );
            }
        }
    }
    if let Some(note) = &m.gpu {
        let _ = writeln!(
            s,
            "\n{note}: the `gpu` rows run the render kernel's own march on each case's field as `grin render --backend gpu` bakes it (the cases baked by the matrix itself: their own grids), so their errors include that bake's."
        );
        for (case, w) in &m.gpu_warnings {
            let _ = writeln!(s, "- GPU bake of **{case}** warns: {w}.");
        }
    }
    let _ = writeln!(s);
    let _ = write!(s, "| method |");
    for (case, _, _) in &m.cases {
        let _ = write!(s, " {case} |");
    }
    let _ = writeln!(s);
    let _ = write!(s, "|---|");
    for _case in &m.cases {
        let _ = write!(s, "---|");
    }
    let _ = writeln!(s);
    for col in &m.columns {
        let _ = write!(s, "| {col} |");
        for (case, _, _) in &m.cases {
            let text = m
                .cells
                .iter()
                .find(|c| c.case == *case && &c.method == col)
                .map_or_else(|| "-".into(), cell_text);
            let _ = write!(s, " {text} |");
        }
        let _ = writeln!(s);
    }
    let silent = m.cells.iter().filter(|c| c.silent).count();
    let _ = writeln!(
        s,
        "\n{silent} of {} cells are silent wrong answers.",
        m.cells.len()
    );
    s
}
